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

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation

from ._validate import choice, positive
from .exceptions import InputError
from .grasp.choice import Grasp, initial_grasp
from .grasp.contact import ContactModel
from .grasp.manifold import build_manifold
from .model.hand import Hand
from .model.motion import ObjectMotion
from .model.objects import Box, ConvexObject, Prism
from .planning.planner import PlannerParams
from .planning.regrasp import RegraspParams

__all__ = [
    "HANDS",
    "OBJECTS",
    "Scenario",
    "describe",
    "grasp_for_motion",
    "hand_model",
    "make_scenario",
    "scenario_params",
    "setup_fingers",
    "setup_pose",
    "turn_about_thumb_contact",
]

HANDS = ("five_finger", "allegro")
OBJECTS = ("hexagon", "octagon", "box")


@dataclass(frozen=True)
class Scenario:
    """A hand, an object, the object's motion, an initial grasp and planner settings."""

    name: str
    hand: Hand
    obj: ConvexObject
    motion: ObjectMotion
    grasp: Grasp | None
    params: PlannerParams = field(default_factory=PlannerParams)
    description: str = ""


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
    hand: str = "five_finger",
    obj: str = "hexagon",
    *,
    angle_deg: float | None = None,
    rate_deg_s: float = 20.0,
    dt_s: float = 0.01,
    seed: int = 0,
) -> Scenario:
    """Build the canonical scenario (see the module docstring).

    Args:
        hand: ``"five_finger"`` (bundled) or ``"allegro"`` (example-robot-data).
        obj: ``"hexagon"``, ``"octagon"`` (prisms) or ``"box"``.
        angle_deg: Total turn [deg]; its sign gives the direction. Default 100.
        rate_deg_s: Turning speed [deg/s] (> 0).
        dt_s: Sampling step of the motion [s].
        seed: Seed of the initial-grasp search.

    Returns:
        The :class:`Scenario`.

    Raises:
        UnknownNameError: unknown hand or object.
        InputError: non-positive rate, zero or non-finite angle.
        ContactError: no initial grasp (should not happen for the bundled setups).
    """
    choice(hand, "hand", HANDS)
    choice(obj, "obj", OBJECTS)
    rate = positive(rate_deg_s, "rate_deg_s")
    angle = 100.0 if angle_deg is None else float(angle_deg)
    if not np.isfinite(angle) or angle == 0:
        raise InputError("angle_deg", f"{angle_deg!r} is not allowed", "a finite non-zero angle")
    h = hand_model(hand)
    o = _SETUP[hand]["objects"][obj]()
    T0 = setup_pose(hand)
    fingers = setup_fingers(hand)
    contact = ContactModel()
    rate_rad = np.sign(angle) * np.radians(rate)
    duration = abs(angle) / rate
    # 1) grasp chosen for the turn about the object's own axis (its z axis)
    axis0 = T0[:3, :3] @ np.array([0.0, 0.0, 1.0])
    turn0 = ObjectMotion.constant_twist(
        T0,
        axis_palm=axis0,
        point_palm=T0[:3, 3],
        rate_rad_s=rate_rad,
        duration_s=duration,
        dt_s=dt_s,
    )
    grasp = grasp_for_motion(h, o, turn0, fingers, contact=contact, grasp_dt_s=0.05, seed=seed)
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
        description=describe(h, o, fingers, angle, rate, f"{o.kind} ({obj})"),
    )


# ------------------------------------------------------------------ building blocks
def hand_model(hand: str) -> Hand:
    """A new :class:`~.hand.Hand` for ``"five_finger"`` or ``"allegro"``.

    Raises:
        UnknownNameError: unknown hand.
    """
    choice(hand, "hand", HANDS)
    return Hand.five_finger() if hand == "five_finger" else Hand.allegro()


def setup_pose(hand: str) -> np.ndarray:
    """The hand's canonical object pose ``T_palm_object`` ``(4, 4)`` (prism axis = object z).

    Raises:
        UnknownNameError: unknown hand.
    """
    setup = _SETUP[choice(hand, "hand", HANDS)]
    T0 = np.eye(4)
    T0[:3, :3] = setup["rotation"].as_matrix()
    T0[:3, 3] = setup["position"]
    return T0


def setup_objects(hand: str) -> dict[str, Callable[[], ConvexObject]]:
    """The hand's canonical objects by name, each as a function that builds it."""
    return dict(_SETUP[choice(hand, "hand", HANDS)]["objects"])


def setup_fingers(hand: str) -> tuple[str, ...]:
    """The fingers that take part in the hand's canonical scenario."""
    return tuple(_SETUP[choice(hand, "hand", HANDS)]["fingers"])


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
) -> Grasp:
    """The initial grasp chosen for ``motion`` (:func:`~.contact_choice.initial_grasp`).

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

    Returns:
        The :class:`~.contact_choice.Grasp` at the motion's start.

    Raises:
        InputError: non-positive ``grasp_dt_s`` or ``horizon_s``.
        ContactError: no force-closure grasp.
    """
    step = positive(grasp_dt_s, "grasp_dt_s")
    duration, t_last = motion.duration_s, motion.t_end
    if horizon_s is not None and positive(horizon_s, "horizon_s") < duration:
        duration, t_last = float(horizon_s), motion.t_start + float(horizon_s)
    sample = obj.sample_surface(0.002)
    times = np.linspace(motion.t_start, t_last, max(int(duration / step), 1) + 1)
    manifolds = {
        n: build_manifold(hand.fingers[n], sample, motion, times, contact=contact) for n in fingers
    }
    return initial_grasp(
        hand,
        obj,
        manifolds,
        sample,
        contact=contact,
        seed=seed,
        trials=trials,
        finger_clearance=finger_clearance,
    )


def turn_about_thumb_contact(
    T_palm_object: np.ndarray,
    grasp: Grasp,
    axis_palm: np.ndarray,
    rate_rad_s: float,
    duration_s: float,
    dt_s: float,
) -> ObjectMotion:
    """A turn about the axis through the thumb's contact, along the thumb's contact normal.

    Args:
        T_palm_object: Object pose at the start ``(4, 4)``.
        grasp: The grasp (its thumb contact, object frame).
        axis_palm: The reference axis (palm frame); the turn's axis points the same way.
        rate_rad_s: Signed turning rate [rad/s].
        duration_s: Duration [s].
        dt_s: Sampling step [s].

    Returns:
        The motion: the thumb's contact point stays fixed in the palm frame.
    """
    R0 = T_palm_object[:3, :3]
    pivot = R0 @ grasp.points_object["thumb"] + T_palm_object[:3, 3]
    axis = -(R0 @ grasp.normals_object["thumb"])
    axis *= np.sign(axis @ axis_palm) or 1.0
    return ObjectMotion.constant_twist(
        T_palm_object,
        axis_palm=axis,
        point_palm=pivot,
        rate_rad_s=rate_rad_s,
        duration_s=duration_s,
        dt_s=dt_s,
    )


def scenario_params(fingers: tuple[str, ...], contact: ContactModel) -> PlannerParams:
    """The planner settings of the ready-made scenarios."""
    return PlannerParams(
        fingers=fingers,
        manifold_dt_s=0.1,
        contact=contact,
        regrasp=RegraspParams(clearance_m=0.003, duration_s=0.4),
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
