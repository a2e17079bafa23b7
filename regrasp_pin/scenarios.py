"""Ready-made manipulation scenarios: a hand, an object, its motion and a grasp.

The canonical scenario follows the paper's test: the bundled five-finger hand holds a
prismatic object in a fingertip grasp while the object turns far more than any fixed
grasp allows, so the fingers must regrasp. The prism lies with its axis along the
palm x axis, the thumb on its near end face and the fingers on its far end face, and
it is turned like a knob about the axis through the thumb's contact, along the
thumb's contact normal: the thumb pins the object while the fingers walk around it.

How it is built: an initial grasp is chosen for the turn about the prism's own axis
(so that every contact lasts as long as possible), then the turn is placed about the
thumb's contact, which makes the thumb's contact fixed in space.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from ._validate import as_array, choice, positive, positive_int
from .exceptions import (
    Attempt,
    ContactError,
    FailureKind,
    InputError,
    ModelFileError,
    UnknownNameError,
)
from .grasp.choice import exit_times
from .grasp.contact import ContactModel
from .grasp.initial import GAP_HORIZON_S, Grasp, initial_grasp
from .grasp.manifold import Manifold, StartTracking, build_manifold, build_manifolds
from .grasp.necessity import MustHold, must_hold, with_idle_fingers
from .grasp.screening import held_clear
from .model.clearance import palm_clearance
from .model.hand import Hand
from .model.motion import ObjectMotion
from .model.objects import Box, ConvexObject, Prism, SurfaceSample
from .planning.planner import PlannerParams
from .planning.regrasp import RegraspParams
from .planning.timing import checked_time_law

__all__ = [
    "HANDS",
    "OBJECTS",
    "GraspSearch",
    "Scenario",
    "contacts_held_through",
    "describe",
    "grasp_for_motion",
    "hand_label",
    "hand_model",
    "is_hand_file",
    "make_scenario",
    "palm_hit",
    "scenario_for_hand",
    "scenario_params",
    "setup_fingers",
    "setup_pose",
    "setup_time_law",
    "start_poses",
    "turn_about_thumb_contact",
]

HANDS = ("five_finger", "allegro")
#: The grasp that picks a pivot's contact looks at the turn's first second only [s].
_PIVOT_HORIZON_S = 1.0
OBJECTS = ("hexagon", "octagon", "box")


@dataclass(frozen=True)
class GraspSearch:
    """How a scenario's initial grasp was chosen: :func:`grasp_for_motion`'s arguments,
    to choose another start the same way (:func:`~regrasp_pin.backups.plan_scenario`
    backs up to one after a failure).

    Attributes:
        motion: The motion the grasp is chosen for: the scenario's own, or the turn
            about the object's axis from which a turn about the ``pivot``'s contact
            was placed.
        fingers: The fingers that grasp.
        contact: The contact model.
        grasp_dt_s, horizon_s, seed, finger_clearance, must_hold_check, room_fingers,
            room_after_s: As :func:`grasp_for_motion`'s.
        pivot: The finger whose contact places the scenario's motion (its axis passes
            through it), or None. Another start keeps its contact, and so the motion.
    """

    motion: ObjectMotion
    fingers: tuple[str, ...]
    contact: ContactModel
    grasp_dt_s: float = 0.05
    horizon_s: float | None = None
    seed: int = 0
    finger_clearance: Callable[[dict[str, np.ndarray]], float] | None = None
    must_hold_check: bool = False
    room_fingers: tuple[str, ...] = ()
    room_after_s: float = 0.25
    pivot: str | None = None

    def choose(
        self,
        hand: Hand,
        obj: ConvexObject,
        *,
        keep: Mapping[str, int] | None = None,
        avoid: Mapping[str, np.ndarray] | None = None,
    ) -> Grasp:
        """The grasp :func:`grasp_for_motion` chooses with these settings and ``keep``
        and ``avoid`` (its arguments)."""
        return grasp_for_motion(
            hand,
            obj,
            self.motion,
            self.fingers,
            contact=self.contact,
            grasp_dt_s=self.grasp_dt_s,
            horizon_s=self.horizon_s,
            seed=self.seed,
            finger_clearance=self.finger_clearance,
            keep=keep,
            must_hold_check=self.must_hold_check,
            room_fingers=self.room_fingers,
            room_after_s=self.room_after_s,
            avoid=avoid,
        )


@dataclass(frozen=True)
class Scenario:
    """A hand, an object, the object's motion, an initial grasp and planner settings.

    ``grasp_search`` says how the grasp was chosen (None: given, not chosen), so that
    :func:`~regrasp_pin.backups.plan_scenario` can back up to another.
    """

    name: str
    hand: Hand
    obj: ConvexObject
    motion: ObjectMotion
    grasp: Grasp | None
    params: PlannerParams = field(default_factory=PlannerParams)
    description: str = ""
    grasp_search: GraspSearch | None = None


# per hand: object pose in the palm frame, the axis of the turn, the fingers used
_SETUP = {
    "five_finger": {
        "rotation": Rotation.from_euler("y", 90, degrees=True),  # prism axis -> palm x
        "position": (0.055, 0.0, 0.07),
        "fingers": ("thumb", "index", "middle", "ring"),
        "objects": {
            "hexagon": lambda: Prism(6, 0.032, 0.04),
            "octagon": lambda: Prism(8, 0.034, 0.04),
            "box": lambda: Box((0.04, 0.05, 0.05)),
        },
    },
    "allegro": {
        # thumb below, fingers above: the prism axis along the thumb-middle opposition
        "rotation": Rotation.align_vectors([[-0.1, -0.3, 0.94]], [[0.0, 0.0, 1.0]])[0],
        "position": (0.100, 0.010, 0.0),
        "fingers": ("thumb", "index", "middle", "ring"),
        "objects": {
            "hexagon": lambda: Prism(6, 0.045, 0.04),
            "octagon": lambda: Prism(8, 0.046, 0.04),
            "box": lambda: Box((0.05, 0.08, 0.05)),
        },
    },
}


def make_scenario(
    hand: str | Hand = "five_finger",
    obj: str | ConvexObject = "hexagon",
    *,
    angle_deg: float | None = None,
    rate_deg_s: float = 20.0,
    dt_s: float = 0.01,
    seed: int = 0,
    contact: ContactModel | None = None,
) -> Scenario:
    """Build the canonical scenario (see the module docstring).

    With a :class:`~regrasp_pin.model.hand.Hand` or a hand file's path for ``hand``, or
    a :class:`~regrasp_pin.model.objects.ConvexObject` for ``obj``, the scenario is
    built by :func:`scenario_for_hand` (the object placed by a search, turned about the
    thumb's contact), with every finger of a hand given as a ``Hand``.

    Args:
        hand: ``"five_finger"`` (bundled), ``"allegro"`` (example-robot-data), a JSON
            hand file's path, or any :class:`~regrasp_pin.model.hand.Hand`.
        obj: ``"hexagon"``, ``"octagon"`` (prisms), ``"box"``, or any convex object.
        angle_deg: Total turn [deg]; its sign gives the direction. Default 100.
        rate_deg_s: Turning speed [deg/s] (> 0).
        dt_s: Sampling step of the motion [s].
        seed: Seed of the initial-grasp search.
        contact: The contact model of the grasp search and the planner (default
            ``ContactModel()``: each finger's own pad cone).

    Returns:
        The :class:`Scenario`.

    Raises:
        UnknownNameError: unknown hand or object.
        InputError: non-positive rate, zero or non-finite angle.
        ContactError: no initial grasp (should not happen for the bundled setups).
    """
    if isinstance(hand, Hand) or isinstance(obj, ConvexObject) or is_hand_file(hand):
        h = hand if isinstance(hand, Hand) else hand_model(hand)
        names = h.finger_names if isinstance(hand, Hand) else setup_fingers(hand)
        named = setup_objects(
            hand if isinstance(hand, str) and is_hand_file(hand) else "five_finger"
        )
        o = obj if isinstance(obj, ConvexObject) else named[choice(obj, "obj", OBJECTS)]()
        return scenario_for_hand(
            h,
            o,
            fingers=names,
            angle_deg=100.0 if angle_deg is None else angle_deg,
            rate_deg_s=rate_deg_s,
            dt_s=dt_s,
            seed=seed,
            contact=contact,
        )
    assert isinstance(hand, str) and isinstance(obj, str)
    choice(hand, "hand", HANDS)
    choice(obj, "obj", OBJECTS)
    angle = 100.0 if angle_deg is None else angle_deg
    rate_rad, duration = _turn_rate(angle, rate_deg_s)
    h = hand_model(hand)
    o = _SETUP[hand]["objects"][obj]()
    T0 = setup_pose(hand)
    fingers = setup_fingers(hand)
    contact = contact or ContactModel()
    # 1) grasp chosen for the turn about the object's own axis (its z axis)
    axis0, turn0 = _own_axis_turn(T0, rate_rad, duration, dt_s)
    search = GraspSearch(turn0, fingers, contact, grasp_dt_s=0.05, seed=seed, pivot="thumb")
    grasp = search.choose(h, o)
    # 2) the same turn about the thumb's contact, along its normal
    motion = turn_about_thumb_contact(T0, grasp, axis0, rate_rad, duration, dt_s)
    params = scenario_params(fingers, contact)
    return Scenario(
        name=f"{hand}-{obj}",
        hand=h,
        obj=o,
        motion=motion,
        grasp=grasp,
        params=params,
        description=describe(h, o, fingers, float(angle), float(rate_deg_s), f"{o.kind} ({obj})"),
        grasp_search=search,
    )


# ------------------------------------------------------------------ building blocks
def _turn_rate(angle_deg: float, rate_deg_s: float) -> tuple[float, float]:
    """The signed rate [rad/s] and duration [s] of a turn by ``angle_deg`` at
    ``rate_deg_s``; InputError for a rate that is not positive, an angle that is zero
    or not finite."""
    try:
        rate = float(rate_deg_s)
    except (TypeError, ValueError):
        rate = float("nan")
    if not np.isfinite(rate) or rate <= 0:  # a speed: the sign of the angle turns
        raise InputError(
            "rate_deg_s",
            f"{rate_deg_s!r} is not allowed",
            "a speed > 0 [deg/s]; turn the other way with a negative angle_deg",
        )
    angle = float(angle_deg)
    if not np.isfinite(angle) or angle == 0:
        raise InputError("angle_deg", f"{angle_deg!r} is not allowed", "a finite non-zero angle")
    return float(np.sign(angle) * np.radians(rate)), abs(angle) / rate


def _own_axis_turn(
    T0: np.ndarray, rate_rad: float, duration: float, dt_s: float
) -> tuple[np.ndarray, ObjectMotion]:
    """The object's z axis in the palm frame at ``T0``, and the turn about it through
    the object's centre."""
    axis0 = T0[:3, :3] @ np.array([0.0, 0.0, 1.0])
    turn0 = ObjectMotion.constant_twist(
        T0,
        axis_palm=axis0,
        point_palm=T0[:3, 3],
        rate_rad_s=rate_rad,
        duration_s=duration,
        dt_s=dt_s,
    )
    return axis0, turn0


def is_hand_file(hand: object) -> bool:
    """True for a JSON hand file's path (:meth:`~.hand.Hand.from_file`), which the setup
    functions below take besides the bundled hands' names."""
    return isinstance(hand, str) and hand.endswith(".json")


def _check_hand(hand: object) -> str:
    if is_hand_file(hand):
        assert isinstance(hand, str)
        if not Path(hand).is_file():
            raise ModelFileError(hand, "no such hand file")
        return hand
    return choice(hand, "hand", HANDS)


def hand_label(hand: str) -> str:
    """A short name for a bundled hand or a hand file (its stem)."""
    return Path(hand).stem if is_hand_file(hand) else hand


def hand_model(hand: str) -> Hand:
    """A new :class:`~.hand.Hand` for ``"five_finger"``, ``"allegro"`` or a hand file.

    Raises:
        UnknownNameError: unknown hand name.
        ModelFileError: no such hand file.
    """
    hand = _check_hand(hand)
    if is_hand_file(hand):
        return Hand.from_file(hand)
    return Hand.five_finger() if hand == "five_finger" else Hand.allegro()


def setup_pose(hand: str) -> np.ndarray:
    """The hand's canonical object pose ``T_palm_object`` ``(4, 4)`` (prism axis = object z).

    For a hand file it is found once per process: the first pose at which
    :func:`scenario_for_hand` builds a canonical scenario (the hand's canonical objects
    in turn, turned 100 deg at 20 deg/s either way about the thumb's contact).

    Raises:
        UnknownNameError: unknown hand.
        ContactError: a hand file's hand cannot grasp the canonical prism anywhere.
    """
    hand = _check_hand(hand)
    if is_hand_file(hand):
        found = _found_pose(*_file_key(hand))
        if isinstance(found, ContactError):
            raise found.with_traceback(None)  # the cached error, its traceback reset
        return found.copy()
    setup = _SETUP[hand]
    T0 = np.eye(4)
    T0[:3, :3] = setup["rotation"].as_matrix()
    T0[:3, 3] = setup["position"]
    return T0


def _file_key(hand_file: str) -> tuple[str, int]:
    """A hand file's cache key: its resolved path and modification time (an edited
    file is read again)."""
    path = Path(hand_file).resolve()
    return str(path), path.stat().st_mtime_ns


@functools.cache
def _found_pose(hand_file: str, _mtime_ns: int) -> np.ndarray | ContactError:
    """The first canonical object and turn direction (hexagon, octagon, box; +100 then
    -100 deg) for which :func:`scenario_for_hand` finds a start pose, and that pose;
    the ContactError of the last attempt if none does (cached too, not searched again)."""
    h = hand_model(hand_file)
    failure: ContactError | None = None
    for make in setup_objects(hand_file).values():
        for angle in (100.0, -100.0):
            try:
                scen = scenario_for_hand(
                    h, make(), fingers=setup_fingers(hand_file), angle_deg=angle
                )
            except ContactError as exc:
                failure = exc
                continue
            return scen.motion.pose(scen.motion.t_start)
    assert failure is not None
    return failure


def setup_objects(hand: str) -> dict[str, Callable[[], ConvexObject]]:
    """The hand's canonical objects by name, each as a function that builds it.

    A hand file gets the five-finger hand's, scaled by its ``scenario.object_scale``
    (default 1).
    """
    hand = _check_hand(hand)
    if not is_hand_file(hand):
        return dict(_SETUP[hand]["objects"])
    k = _file_scenario(*_file_key(hand))[1]
    return {
        name: functools.partial(_scaled, make, k)
        for name, make in _SETUP["five_finger"]["objects"].items()
    }


def _scaled(make: Callable[[], ConvexObject], k: float) -> ConvexObject:
    """The object ``make()`` with its lengths times ``k`` (a prism or a box)."""
    obj = make()
    if isinstance(obj, Prism):
        p = obj.params
        return Prism(int(p["n_sides"]), k * p["circumradius_m"], k * p["height_m"])
    return Box(tuple(k * np.asarray(obj.params["size"], float)))


def setup_fingers(hand: str) -> tuple[str, ...]:
    """The fingers that take part in the hand's canonical scenario (a hand file: its
    ``scenario.fingers``, default all)."""
    hand = _check_hand(hand)
    if is_hand_file(hand):
        return _file_scenario(*_file_key(hand))[0]
    return tuple(_SETUP[hand]["fingers"])


def setup_time_law(hand: str) -> str:
    """How the regrasps of the hand's ready-made scenarios spread their progress
    (``RegraspParams.time_law``): a hand file's ``scenario.time_law``, else the
    default (minimum jerk). A hand whose regrasps are bound by slow joints may name the
    cruise law (the Shadow Hand's file does; see docs/hands.md)."""
    hand = _check_hand(hand)
    if is_hand_file(hand):
        return _file_scenario(*_file_key(hand))[2]
    return RegraspParams().time_law


@functools.cache
def _file_scenario(hand_file: str, _mtime_ns: int) -> tuple[tuple[str, ...], float, str]:
    """A hand file's ``scenario`` entry: the grasping fingers, the object scale and
    the regrasps' time law."""
    import json

    spec = json.loads(Path(hand_file).read_text())
    entry = spec.get("scenario", {})
    if not isinstance(entry, dict) or set(entry) - {"fingers", "object_scale", "time_law"}:
        raise InputError(
            f"{hand_file}: scenario",
            f"is {entry!r}",
            "{'fingers': [...], 'object_scale': k, 'time_law': law}",
        )
    names = tuple(spec.get("fingers", {}))
    fingers = tuple(entry.get("fingers", names))
    for n in fingers:
        if n not in names:
            raise UnknownNameError(f"{hand_file}: scenario.fingers", n, names)
    scale = positive(entry.get("object_scale", 1.0), f"{hand_file}: scenario.object_scale")
    law = entry.get("time_law", RegraspParams().time_law)
    return fingers, scale, checked_time_law(law, f"{hand_file}: scenario.time_law")


def grasp_for_motion(
    hand: Hand,
    obj: ConvexObject,
    motion: ObjectMotion,
    fingers: tuple[str, ...],
    *,
    contact: ContactModel,
    grasp_dt_s: float = 0.05,
    horizon_s: float | None = None,
    seed: int = 0,
    trials: int = 80,
    finger_clearance: Callable[[dict[str, np.ndarray]], float] | None = None,
    keep: Mapping[str, int] | None = None,
    mu: float = 0.8,
    must_hold_check: bool = False,
    track_start: bool = True,
    room_fingers: Sequence[str] = (),
    room_after_s: float = 0.25,
    avoid: Mapping[str, np.ndarray] | None = None,
) -> Grasp:
    """The initial grasp chosen for ``motion`` (:func:`~regrasp_pin.grasp.initial.initial_grasp`).

    The fingers' joint-space manifolds are built over the surface sampled every 2 mm,
    at ``max(int(duration / grasp_dt_s), 1) + 1`` equally spaced times of the motion
    (of its first ``horizon_s``, if given), so that every contact's lasting time (up
    to the horizon) is known when the grasp is chosen.

    Args:
        hand: The hand.
        obj: The object.
        motion: The motion the grasp should last through.
        fingers: The fingers that grasp.
        contact: The contact model.
        grasp_dt_s: Time step of the manifolds [s] (their cost grows with 1 / step).
        horizon_s: Only the motion's first ``horizon_s`` [s] count (contacts that last
            longer tie); None: the whole motion.
        seed: Seed of the grasp search.
        trials: Randomized combinations tried by the grasp search.
        finger_clearance: Optional ``q_fingers -> distance [m]``; grasps at which it is
            <= 0 are rejected.
        keep: Fingers whose contact is given: finger -> index in the surface sample
            (``Grasp.indices`` of an earlier grasp); that point is their only candidate.
        mu: Friction coefficient of the force-closure tests.
        must_hold_check: Keep, for a finger that cannot let go from the start (no grasp
            of the hand's other fingers, the idle ones too, is in force closure without
            it: :func:`~regrasp_pin.grasp.necessity.must_hold`), only the contacts that
            last that long (over the horizon). Only for a grasp meant for ``motion``
            itself, with regrasps longer than ``grasp_dt_s`` (the proof's assumption).
        track_start: Map into joint space only what the choice reads
            (:class:`~regrasp_pin.grasp.manifold.StartTracking`: every point at the
            start, then the points feasible there through the finger-gap horizon and
            while they last); the same grasp as mapping every entry (False, the
            reference), which ``must_hold_check`` needs and then does.
        room_fingers: Fingers whose room to regrasp ranks the grasps: of the
            force-closure grasps found (and improved one finger at a time), the one
            kept has first the fewest of these fingers' holds that cannot be regrasped
            in turn, one regrasp of ``room_after_s`` after another, then the largest
            smallest room over these fingers (:class:`~regrasp_pin.placing.RegraspRoom`:
            usable contacts at which a finger stays ``contact.finger_trigger_m`` + 0.5
            mm from the other fingers, at the start and ``room_after_s`` later), then
            the best score. Empty (default): the score alone.
        room_after_s: A regrasp's duration [s] (the second time at which the room is
            counted: where a finger that must let go at once lands).
        avoid: Contacts not to start on again: finger -> ``(K, 3)`` points (object
            frame) [m]; the finger's sample points within two of its tip radii of any
            of them are left out (e.g. the start contact of a grasp whose plan failed
            while that finger still held it).

    Returns:
        The :class:`~regrasp_pin.grasp.initial.Grasp` at the motion's start.

    Raises:
        InputError: non-positive ``grasp_dt_s`` or ``horizon_s``, a ``keep`` index or
            ``avoid`` points of the wrong form.
        UnknownNameError: a ``keep`` or ``avoid`` finger that is not in ``fingers``.
        ContactError: no force-closure grasp (kind ``infeasible`` when a finger cannot
            let go longer than any of its contacts lasts).
    """
    step = positive(grasp_dt_s, "grasp_dt_s")
    duration, t_last = motion.duration_s, motion.t_end
    if horizon_s is not None and positive(horizon_s, "horizon_s") < duration:
        duration, t_last = float(horizon_s), motion.t_start + float(horizon_s)
    sample = obj.sample_surface(0.002)
    times = np.linspace(motion.t_start, t_last, max(int(duration / step), 1) + 1)
    # what initial_grasp reads: usable(limit margin) from the start, q over the gap horizon
    track = (
        StartTracking(contact.limit_margin_rad, float(times[0]) + GAP_HORIZON_S)
        if track_start and not must_hold_check
        else None
    )
    manifolds = build_manifolds(hand, fingers, sample, motion, times, contact=contact, track=track)
    runs: list[MustHold] = []
    if must_hold_check:  # on the unrestricted manifolds: what every finger could use
        every = with_idle_fingers(hand, manifolds, sample, motion, contact)
        # up to the motion's end, its last sample included, as the planner's proof
        runs = must_hold(every, sample, obj, mu, list(fingers), torsion_m=contact.torsion_m)
    for name, index in (keep or {}).items():
        if not isinstance(index, (int, np.integer)) or not 0 <= index < len(sample):
            raise InputError(
                f"keep[{name!r}]", f"{index!r}", f"an index into the {len(sample)} samples"
            )
        only = np.zeros(len(sample), bool)
        only[index] = True
        _restrict(manifolds, name, only, "keep")
    for name, points in (avoid or {}).items():
        away = as_array(points, f"avoid[{name!r}]", (None, 3))
        near = np.linalg.norm(sample.points[:, None, :] - away[None, :, :], axis=-1)
        _restrict(
            manifolds, name, ~(near <= 2.0 * hand.finger(name).tip_radius).any(axis=1), "avoid"
        )
    rank = _room_rank(hand, obj, manifolds, sample, room_fingers, room_after_s, contact)
    return initial_grasp(
        hand,
        obj,
        manifolds,
        sample,
        contact=contact,
        mu=mu,
        seed=seed,
        trials=trials,
        finger_clearance=finger_clearance,
        gap_horizon_s=GAP_HORIZON_S,
        must_hold=runs,
        rank=rank,
    )


def contacts_held_through(
    hand: Hand,
    obj: ConvexObject,
    motion: ObjectMotion,
    finger: str,
    *,
    contact: ContactModel,
    grasp_dt_s: float = 0.05,
) -> np.ndarray:
    """The start contacts that ``finger`` holds to the motion's end, best first.

    On the surface sampled every 2 mm and the times of :func:`grasp_for_motion` (the
    indices are those of its ``keep``): usable at the start with the choice margin,
    then, at every time, inside the joint limits with ``contact.limit_margin_rad``, the
    pad facing, the fingertip link not sinking in (the manifold's estimate) and, held
    there, the finger's links clear of the object (Coal:
    :func:`~regrasp_pin.grasp.screening.held_clear`). Ordered by the smallest joint
    margin over the motion, largest first (ties by index). For a finger that cannot
    let go (the others do not hold without it), these are the contacts from which it
    need not.

    Returns:
        ``(K,)`` sample indices (empty if none).

    Raises:
        UnknownNameError: ``finger`` is not one of the hand's.
        InputError: non-positive ``grasp_dt_s``.
    """
    step = positive(grasp_dt_s, "grasp_dt_s")
    f = hand.finger(finger)
    sample = obj.sample_surface(0.002)
    times = np.linspace(motion.t_start, motion.t_end, max(int(motion.duration_s / step), 1) + 1)
    man = build_manifold(f, sample, motion, times, contact=contact)
    start = np.flatnonzero(man.usable(contact.choice_margin_rad)[0])
    lasting = start[man.holdable(contact.limit_margin_rad)[:, start].all(axis=0)]
    if lasting.size == 0:
        return lasting
    lasting = lasting[held_clear(hand, finger, obj, man, lasting, 0, contact)[-1]]
    worst = man.margin_rad[:, lasting].min(axis=0)
    return lasting[np.lexsort((lasting, -np.round(worst, 9)))]


def _restrict(
    manifolds: dict[str, Manifold], name: str, allowed: np.ndarray, argument: str
) -> None:
    """Leave only the sample points ``allowed`` ``(N,)`` to ``name``'s manifold in
    ``manifolds`` (``argument`` names the finger's origin in an error)."""
    if name not in manifolds:
        raise UnknownNameError(argument, name, list(manifolds))
    m = manifolds[name]
    manifolds[name] = replace(m, inside=m.inside & allowed[None, :])


def _room_rank(
    hand: Hand,
    obj: ConvexObject,
    manifolds: Mapping[str, Manifold],
    sample: SurfaceSample,
    fingers: Sequence[str],
    regrasp_s: float,
    contact: ContactModel,
) -> Callable[[Mapping[str, int]], tuple[int, int]] | None:
    """The grasp search's rank of a combination (None without fingers), two integers:

    1. minus the number of ``fingers`` whose holds cannot all be regrasped in turn, one
       regrasp of ``regrasp_s`` after another from the start: with their contacts' exit
       times sorted, the ``j``-th (from 1) must be at least ``j * regrasp_s`` after the
       start (holds that last through the manifolds' times need no regrasp);
    2. the smallest regrasp room over ``fingers``
       (:class:`~regrasp_pin.placing.RegraspRoom`: usable contacts at which a finger
       stays ``contact.finger_trigger_m`` + 0.5 mm from the other grasping fingers,
       clear of the object and of the other contacts as a new contact must be) at
       the manifolds' first time and the first time ``regrasp_s`` later.
    """
    from .placing import RegraspRoom

    if not fingers:
        return None
    for n in fingers:
        if n not in manifolds:
            raise UnknownNameError("room_fingers", n, list(manifolds))
    times = next(iter(manifolds.values())).times_s
    k_after = min(int(np.searchsorted(times, times[0] + regrasp_s - 1e-9)), times.size - 1)
    ks = sorted({0, k_after})
    room = RegraspRoom(
        hand,
        manifolds,
        sample,
        margin_rad=contact.choice_margin_rad,
        clearance_m=contact.finger_trigger_m + 0.0005,
        obj=obj,
        contact=contact,
    )
    held = {n: manifolds[n].usable(contact.limit_margin_rad) for n in fingers}

    def rank(pick: Mapping[str, int]) -> tuple[int, int]:
        ends = [
            float(exit_times(held[n][:, [int(pick[n])]], times, 0)[0]) - float(times[0])
            for n in fingers
            if not held[n][:, int(pick[n])].all()
        ]
        # on the manifolds' grid (multiples of their step): no floating-point ties
        late = sum(t < j * regrasp_s - 1e-9 for j, t in enumerate(sorted(ends), start=1))
        return -late, min(room(pick, fingers, ks).values())

    return rank


def turn_about_thumb_contact(
    T_palm_object: np.ndarray,
    grasp: Grasp,
    axis_palm: np.ndarray,
    rate_rad_s: float,
    duration_s: float,
    dt_s: float,
    *,
    finger: str = "thumb",
) -> ObjectMotion:
    """A turn about the axis through a finger's contact, along its contact normal.

    Args:
        T_palm_object: Object pose at the start ``(4, 4)``.
        grasp: The grasp (its contacts, object frame).
        axis_palm: The reference axis (palm frame); the turn's axis points the same way.
        rate_rad_s: Signed turning rate [rad/s].
        duration_s: Duration [s].
        dt_s: Sampling step [s].
        finger: The finger whose contact is the pivot (default the thumb).

    Returns:
        The motion: that finger's contact point stays fixed in the palm frame.
    """
    R0 = T_palm_object[:3, :3]
    pivot = R0 @ grasp.points_object[finger] + T_palm_object[:3, 3]
    axis = -(R0 @ grasp.normals_object[finger])
    axis *= np.sign(axis @ axis_palm) or 1.0
    return ObjectMotion.constant_twist(
        T_palm_object,
        axis_palm=axis,
        point_palm=pivot,
        rate_rad_s=rate_rad_s,
        duration_s=duration_s,
        dt_s=dt_s,
    )


def scenario_for_hand(
    hand: Hand,
    obj: ConvexObject,
    *,
    fingers: Sequence[str] | None = None,
    angle_deg: float = 100.0,
    rate_deg_s: float = 20.0,
    pivot: str | None = "thumb",
    pose: np.ndarray | None = None,
    dt_s: float = 0.01,
    seed: int = 0,
    attempts: int = 6,
    contact: ContactModel | None = None,
    grasp_dt_s: float = 0.1,
) -> Scenario:
    """A scenario for any hand: the object placed where the fingers can grasp it, turned.

    The object's start pose is ``pose`` or, by default, found in the fingers' common
    workspace (:func:`~regrasp_pin.placing.candidate_placements`, best first). At each
    candidate pose an initial force-closure grasp is chosen for a turn about the
    object's z axis through its centre (:func:`grasp_for_motion`); with a ``pivot``
    finger the turn is then placed about the axis through that finger's contact along
    its normal, as in :func:`make_scenario`, so that the pivot finger pins the object
    while the others walk around it, and the other fingers' contacts are chosen again
    for that turn. Both grasp searches rank their grasps by the room the fingers other
    than the pivot have to regrasp (``grasp_for_motion(room_fingers=...)``), so that
    the pivot's contact, and the others', leave each finger somewhere to land clear of
    its neighbours. The
    first pose (of at most ``attempts``) with a grasp, at which the object also stays
    clear of the palm over the whole motion, is the scenario's.

    Args:
        hand: Any hand (:meth:`~regrasp_pin.model.hand.Hand.from_urdf`).
        obj: The object.
        fingers: The fingers that grasp; default all of the hand's.
        angle_deg: Total turn [deg], signed, non-zero.
        rate_deg_s: Turning speed [deg/s] (> 0).
        pivot: The finger whose contact the turn's axis passes through, or None for the
            axis through the object's centre. The default ``"thumb"`` falls back to None
            when no grasping finger is called so.
        pose: Object pose at the start ``(4, 4)`` (palm frame); default: searched.
        dt_s: Sampling step of the motion [s].
        seed: Seed of the workspace sampling and the grasp search.
        attempts: Most candidate poses given to the grasp search.
        contact: Contact model; default :class:`~regrasp_pin.grasp.contact.ContactModel`.
        grasp_dt_s: Time step of the grasp search's manifolds [s] (the planner's own
            manifolds are 0.1 s apart; :func:`make_scenario` uses 0.05 s).

    Returns:
        The :class:`Scenario`, with :func:`scenario_params` for the fingers.

    Raises:
        InputError: bad angle, rate or pose; a pivot that is not a grasping finger.
        UnknownNameError: an unknown finger.
        ContactError: no candidate pose has a grasp with the object clear of the palm;
            ``attempts`` lists each pose tried and why it failed.
    """
    from .placing import END_FACE_COS

    names = tuple(fingers) if fingers is not None else hand.finger_names
    for n in names:
        hand.finger(n)
    if pivot == "thumb" and "thumb" not in names:
        pivot = None
    if pivot is not None and pivot not in names:
        raise InputError("pivot", f"{pivot!r} is not a grasping finger", f"one of {names} or None")
    rate_rad, duration = _turn_rate(angle_deg, rate_deg_s)
    contact = contact or ContactModel()
    poses = start_poses(
        hand, obj, names, contact, pose=pose, attempts=attempts, pivot=pivot, seed=seed
    )
    # the grasp leaves each finger room to regrasp a regrasp's duration in
    room_after = scenario_params(names, contact).regrasp.duration_s
    failed: list[Attempt] = []
    for i, T0 in enumerate(poses):
        what = f"pose {i} (object at {np.round(T0[:3, 3] * 1e3, 1).tolist()} mm)"
        axis0, turn0 = _own_axis_turn(T0, rate_rad, duration, dt_s)
        # the first grasp only finds the pivot's contact: the turn's first second
        search = GraspSearch(
            turn0,
            names,
            contact,
            grasp_dt_s=grasp_dt_s,
            horizon_s=min(_PIVOT_HORIZON_S, duration) if pivot is not None else None,
            seed=seed,
            room_fingers=tuple(n for n in names if n != pivot),
            room_after_s=room_after,
        )
        try:
            grasp = search.choose(hand, obj)
        except ContactError as exc:
            failed.append(exc.as_attempt(what))
            continue
        if pivot is not None and abs(float(grasp.normals_object[pivot][2])) < END_FACE_COS:
            failed.append(
                Attempt(
                    kind=FailureKind.NO_CANDIDATE,
                    finger=pivot,
                    what=f"{what}: the {pivot} grasps a side, not an end face of the turn",
                )
            )
            continue
        motion = turn0
        if pivot is not None:
            # the turn about the pivot's contact, and the grasp chosen again for it
            motion = turn_about_thumb_contact(
                T0, grasp, axis0, rate_rad, duration, dt_s, finger=pivot
            )
            search = replace(search, motion=motion, horizon_s=None, pivot=pivot)
            try:  # the pivot's contact stays, fixed in space; the others are chosen again
                grasp = search.choose(hand, obj, keep={pivot: grasp.indices[pivot]})
            except ContactError as exc:
                failed.append(exc.as_attempt(f"{what}, about the {pivot}'s contact"))
                continue
        hit = palm_hit(hand, obj, motion, f"{what}: the object hits the palm during the turn")
        if hit is not None:
            failed.append(hit)
            continue
        axis_text = (
            "an axis through its centre"
            if pivot is None
            else f"the axis through the {pivot}'s contact"
        )
        return Scenario(
            name=f"{hand.name}-{obj.kind}",
            hand=hand,
            obj=obj,
            motion=motion,
            grasp=grasp,
            params=scenario_params(names, contact),
            description=describe(
                hand, obj, names, float(angle_deg), float(rate_deg_s), obj.kind, axis_text
            ),
            grasp_search=search,
        )
    raise ContactError(
        f"no start pose of the {obj.kind} lets the {hand.name} hand grasp it ({len(poses)} tried)",
        kind=FailureKind.NO_CANDIDATE,
        attempts=failed,
    )


def start_poses(
    hand: Hand,
    obj: ConvexObject,
    fingers: tuple[str, ...],
    contact: ContactModel,
    *,
    pose: np.ndarray | None,
    attempts: int,
    pivot: str | None,
    seed: int,
) -> list[np.ndarray]:
    """The start poses a scenario search tries: ``[pose]`` if given, else the first
    ``attempts`` of :func:`~regrasp_pin.placing.candidate_placements`, best first."""
    from .placing import candidate_placements

    if pose is not None:
        return [as_array(pose, "pose", (4, 4))]
    found = candidate_placements(hand, obj, fingers, contact=contact, pivot=pivot, seed=seed)
    return [p.T_palm_object for p in found[: positive_int(attempts, "attempts")]]


def palm_hit(hand: Hand, obj: ConvexObject, motion: ObjectMotion, what: str) -> Attempt | None:
    """An ``object-clearance`` attempt (``what`` says where) if the object goes into the
    palm at one of 21 times of ``motion``, else None."""
    samples = motion.pose(np.linspace(motion.t_start, motion.t_end, 21))
    gap = float(palm_clearance(hand, obj, samples).min())
    if gap >= 0.0:
        return None
    return Attempt(kind=FailureKind.OBJECT_CLEARANCE, measured=gap, required=0.0, what=what)


def scenario_params(fingers: tuple[str, ...], contact: ContactModel) -> PlannerParams:
    """The planner settings of the ready-made scenarios: a regrasp takes at least 0.25 s
    (longer when the joint velocity limits need it), 3 mm from the object in flight."""
    return PlannerParams(
        fingers=fingers,
        manifold_dt_s=0.1,
        contact=contact,
        regrasp=RegraspParams(clearance_m=0.003, duration_s=0.25),
    )


def describe(
    hand: Hand,
    obj: ConvexObject,
    fingers: tuple[str, ...],
    angle_deg: float,
    rate_deg_s: float,
    what: str,
    axis: str = "the axis through the thumb's contact",
) -> str:
    """One line that says what a scenario does."""
    idle = [n for n in hand.finger_names if n not in fingers]
    return (
        f"{hand.name} hand turns a {what} by {angle_deg:g} deg at {rate_deg_s:g} deg/s about "
        f"{axis}; fingers {', '.join(fingers)}" + (f" (idle: {', '.join(idle)})" if idle else "")
    )
