"""Scenario specs: plain, JSON-able descriptions of a scenario, and their deterministic draws.

See :mod:`regrasp_pin.suite` for the balance of :func:`generate_specs` and the ranges.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass
from typing import Any, TypeVar

import numpy as np
from scipy.spatial.transform import Rotation

from .._validate import as_array, choice, known_fields, positive, positive_int
from ..exceptions import ContactError, InputError
from ..model.objects import Box, ConvexMesh, ConvexObject, Prism
from ..scenarios import HANDS, hand_label, is_hand_file, setup_objects, setup_pose

__all__ = [
    "MAX_DRAWS_PER_SCENARIO",
    "MOTION_KINDS",
    "OBJECT_KINDS",
    "MotionSpec",
    "ObjectSpec",
    "ScenarioSpec",
    "generate_specs",
    "neighbour_specs",
    "select_specs",
]

OBJECT_KINDS = ("prism", "box", "mesh")
MAX_DRAWS_PER_SCENARIO = 4  # a suite draws at most this many specs per scenario
MOTION_KINDS = ("object-axis", "contact-axis", "rotate-translate")

SIZE_SPREAD = 0.10  # object sizes vary by +-10 % about the canonical ones
ANGLE_RANGE_DEG = (60.0, 270.0)  # |total turn|
RATE_RANGE_DEG_S = (10.0, 45.0)
N_SIDES_RANGE = (3, 8)  # prisms
N_POINTS_RANGE = (12, 20)  # random convex meshes
MESH_JITTER = 0.05  # radial jitter of the mesh points on their ellipsoid (+-5 %)
MAX_POSITION_OFFSET_M = 0.003  # offsets from the canonical position, in a ball
MAX_ROTATION_OFFSET_DEG = 6.0  # about a random axis
MAX_TILT_DEG = 10.0  # object-axis motions: axis tilted from the object's z axis
TRANSLATION_RANGE_M = (0.003, 0.010)  # rotate-translate: total translation
GRASP_STEP_DEG = 2.0  # the grasp search's manifolds sample the turn every ~2 deg ...
GRASP_DT_RANGE_S = (0.05, 0.2)  # ... with a time step in this range ...
GRASP_HORIZON_DEG = 120.0  # ... over its first 120 deg at most
MOTION_DT_S = 0.01
NEIGHBOUR_ANGLES_DEG = (60.0, 100.0, 140.0, 180.0, -100.0)
NEIGHBOUR_RATES_DEG_S = (10.0, 20.0, 40.0)


# ---------------------------------------------------------------------- specs
_T = TypeVar("_T")


def _given(value: _T | None) -> _T:
    """``value``, known not to be None (``ObjectSpec.__post_init__`` checked it)."""
    if value is None:
        raise AssertionError("a field checked in __post_init__ is None")
    return value


def _vec3(value: Any, argument: str) -> tuple[float, float, float]:
    a = as_array(value, argument, (3,))
    return (float(a[0]), float(a[1]), float(a[2]))


@dataclass(frozen=True)
class ObjectSpec:
    """An object, by kind and size.

    Attributes:
        kind: ``"prism"``, ``"box"`` or ``"mesh"``.
        n_sides: Prism: number of sides (>= 3).
        circumradius_m: Prism: distance from the axis to the polygon's vertices [m].
        height_m: Prism: height along the object's z axis [m].
        size_m: Box: side lengths ``(sx, sy, sz)`` [m]. Mesh: full extents of the
            ellipsoid its points lie on [m].
        n_points: Mesh: number of points (>= 4).
        seed: Mesh: seed of the points.
    """

    kind: str
    n_sides: int | None = None
    circumradius_m: float | None = None
    height_m: float | None = None
    size_m: tuple[float, float, float] | None = None
    n_points: int | None = None
    seed: int | None = None

    def __post_init__(self) -> None:
        choice(self.kind, "object.kind", OBJECT_KINDS)
        need = {
            "prism": ("n_sides", "circumradius_m", "height_m"),
            "box": ("size_m",),
            "mesh": ("size_m", "n_points", "seed"),
        }[self.kind]
        for name in ("n_sides", "circumradius_m", "height_m", "size_m", "n_points", "seed"):
            value = getattr(self, name)
            if (value is None) == (name in need):
                what = "is required" if value is None else "is not used"
                raise InputError(f"object.{name}", f"{what} for kind {self.kind!r}")
        if self.size_m is not None:
            size = _vec3(self.size_m, "object.size_m")
            if min(size) <= 0:
                raise InputError("object.size_m", f"{size} has a side <= 0", "sizes > 0 [m]")
            object.__setattr__(self, "size_m", size)
        if self.kind == "prism":
            positive_int(self.n_sides, "object.n_sides", minimum=3)
            positive(_given(self.circumradius_m), "object.circumradius_m")
            positive(_given(self.height_m), "object.height_m")
        if self.kind == "mesh":
            positive_int(self.n_points, "object.n_points", minimum=4)
            positive_int(self.seed, "object.seed", minimum=0)

    @property
    def label(self) -> str:
        """Short name: ``"prism6"``, ``"box"``, ``"mesh"``."""
        return f"prism{self.n_sides}" if self.kind == "prism" else self.kind

    def build(self) -> ConvexObject:
        """The object (its frame at its centre of mass).

        Raises:
            GeometryError: a degenerate mesh (cannot happen for >= 4 jittered points
                on an ellipsoid, but the hull is computed, not assumed).
        """
        if self.kind == "prism":
            return Prism(_given(self.n_sides), _given(self.circumradius_m), _given(self.height_m))
        if self.kind == "box":
            return Box(_given(self.size_m))
        rng = np.random.default_rng(self.seed)
        u = rng.normal(size=(_given(self.n_points), 3))
        u /= np.linalg.norm(u, axis=1, keepdims=True)
        r = rng.uniform(1.0 - MESH_JITTER, 1.0 + MESH_JITTER, (u.shape[0], 1))
        return ConvexMesh(0.5 * np.asarray(self.size_m) * u * r)

    def to_dict(self) -> dict[str, Any]:
        """The spec as JSON-serializable data."""
        return {k: (list(v) if isinstance(v, tuple) else v) for k, v in _fields(self).items()}


@dataclass(frozen=True)
class MotionSpec:
    """How the object moves.

    Attributes:
        kind: ``"object-axis"``: a turn about an axis through the object's centre (the
            object's z axis tilted by ``axis_object``); ``"contact-axis"``: a turn about
            the axis through the thumb's contact along its normal (as
            :func:`~regrasp_pin.scenarios.make_scenario`); ``"rotate-translate"``: the object-axis
            turn plus a constant drift of ``translation_m`` over the whole motion.
        angle_deg: Total turn [deg]; the sign gives the direction (right-hand rule
            about the axis, which points like the object's z axis).
        rate_deg_s: Turning speed [deg/s], > 0.
        axis_object: Object-axis kinds: the turn's axis in the object frame (unit).
        translation_m: Rotate-translate: total translation, palm frame [m].
        dt_s: Sampling step of the motion [s].
    """

    kind: str
    angle_deg: float
    rate_deg_s: float
    axis_object: tuple[float, float, float] = (0.0, 0.0, 1.0)
    translation_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    dt_s: float = MOTION_DT_S

    def __post_init__(self) -> None:
        choice(self.kind, "motion.kind", MOTION_KINDS)
        angle = float(self.angle_deg)
        if not math.isfinite(angle) or angle == 0:
            raise InputError("motion.angle_deg", f"{self.angle_deg!r}", "a finite non-zero angle")
        positive(self.rate_deg_s, "motion.rate_deg_s")
        positive(self.dt_s, "motion.dt_s")
        axis = _vec3(self.axis_object, "motion.axis_object")
        if np.linalg.norm(axis) < 1e-9:
            raise InputError("motion.axis_object", "is zero", "a unit axis")
        object.__setattr__(self, "axis_object", axis)
        object.__setattr__(self, "translation_m", _vec3(self.translation_m, "motion.translation_m"))

    @property
    def duration_s(self) -> float:
        """``|angle_deg| / rate_deg_s`` [s]."""
        return abs(float(self.angle_deg)) / float(self.rate_deg_s)

    def to_dict(self) -> dict[str, Any]:
        """The spec as JSON-serializable data."""
        return {k: (list(v) if isinstance(v, tuple) else v) for k, v in _fields(self).items()}


@dataclass(frozen=True)
class ScenarioSpec:
    """Everything needed to rebuild a scenario (JSON-able with :meth:`to_dict`).

    Attributes:
        name: Unique name in its suite.
        hand: ``"five_finger"``, ``"allegro"`` or the path of a JSON hand file
            (:meth:`~regrasp_pin.model.hand.Hand.from_file`).
        object: The object.
        motion: The motion.
        position_offset_m: Added to the hand's canonical object position, palm frame [m].
        rotation_offset_rotvec: Rotation vector [rad] (palm frame) applied to the
            canonical object orientation, about the object's centre.
        seed: Seed of the initial-grasp search.
        grasp_dt_s: Time step of the manifolds of the grasp search [s]
            (:func:`~regrasp_pin.scenarios.make_scenario` uses 0.05 s).
        grasp_horizon_s: The grasp search looks at the motion's first
            ``grasp_horizon_s`` only [s] (contacts that last longer tie); None: the
            whole motion (as make_scenario).
        grasp_clearance_m: If not None, the initial grasp must keep every finger at
            least this far from the others [m] (checked with Coal, idle fingers at
            their rest posture); None does not check (as make_scenario).
        base_pose: The hand's canonical object pose ``T_palm_object`` that the offsets
            move, row-major 4 x 4 (16 numbers, metres); None:
            :func:`~regrasp_pin.scenarios.setup_pose` of the hand. The generators fill
            it in for a hand file, whose canonical pose is searched (once per process,
            tens of seconds): a spec that carries it saves every process that builds
            it the search.
    """

    name: str
    hand: str
    object: ObjectSpec
    motion: MotionSpec
    position_offset_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rotation_offset_rotvec: tuple[float, float, float] = (0.0, 0.0, 0.0)
    seed: int = 0
    grasp_dt_s: float = 0.05
    grasp_horizon_s: float | None = None
    grasp_clearance_m: float | None = None
    base_pose: tuple[float, ...] | None = None

    def __post_init__(self) -> None:
        if not is_hand_file(self.hand):
            choice(self.hand, "hand", HANDS)
        if not isinstance(self.object, ObjectSpec):
            raise InputError("object", f"is a {type(self.object).__name__}", "an ObjectSpec")
        if not isinstance(self.motion, MotionSpec):
            raise InputError("motion", f"is a {type(self.motion).__name__}", "a MotionSpec")
        object.__setattr__(
            self, "position_offset_m", _vec3(self.position_offset_m, "position_offset_m")
        )
        object.__setattr__(
            self,
            "rotation_offset_rotvec",
            _vec3(self.rotation_offset_rotvec, "rotation_offset_rotvec"),
        )
        positive_int(self.seed, "seed", minimum=0)
        positive(self.grasp_dt_s, "grasp_dt_s")
        if self.grasp_horizon_s is not None:
            positive(self.grasp_horizon_s, "grasp_horizon_s")
        if self.grasp_clearance_m is not None:
            positive(self.grasp_clearance_m, "grasp_clearance_m", allow_zero=True)
        if self.base_pose is not None:
            object.__setattr__(self, "base_pose", _pose16(self.base_pose))

    def to_dict(self) -> dict[str, Any]:
        """The spec as JSON values (:meth:`from_dict` rebuilds it exactly)."""
        d = {k: (list(v) if isinstance(v, tuple) else v) for k, v in _fields(self).items()}
        d["object"] = self.object.to_dict()
        d["motion"] = self.motion.to_dict()
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> ScenarioSpec:
        """Rebuild a spec from :meth:`to_dict`'s output (e.g. after JSON).

        Raises:
            InputError: unknown or missing fields, or values out of range.
        """
        known_fields(d, cls, "spec")
        known_fields(d["object"], ObjectSpec, "object")
        known_fields(d["motion"], MotionSpec, "motion")
        return cls(
            **{
                **d,
                "object": ObjectSpec(**d["object"]),
                "motion": MotionSpec(**d["motion"]),
            }
        )


def _pose16(value: Any) -> tuple[float, ...]:
    """``value`` as 16 floats of a rigid transform (row-major 4 x 4); InputError if it
    is not one (rotation orthonormal to 1e-9, last row 0 0 0 1)."""
    T = as_array(value, "base_pose", (16,)).reshape(4, 4)
    R = T[:3, :3]
    if np.abs(R.T @ R - np.eye(3)).max() > 1e-9 or not np.array_equal(T[3], [0, 0, 0, 1]):
        raise InputError("base_pose", "is not a rigid transform", "a row-major 4 x 4 pose")
    return tuple(float(x) for x in T.ravel())


def _base_pose_of(hand: str) -> tuple[float, ...] | None:
    """What a spec of ``hand`` carries as its ``base_pose``: a hand file's canonical
    pose (searched once per process); None for a bundled hand (a constant), and for a
    hand file without one (building its specs then raises the search's ContactError,
    recorded per spec as before)."""
    if not is_hand_file(hand):
        return None
    try:
        return tuple(float(x) for x in setup_pose(hand).ravel())
    except ContactError:
        return None


def _fields(obj: Any) -> dict[str, Any]:
    return {f.name: getattr(obj, f.name) for f in dataclasses.fields(obj)}


# ---------------------------------------------------------------------- generation
@functools.cache
def _canonical_sizes(hand: str) -> tuple[float, float, tuple[float, ...]]:
    """Centre sizes of the hand's canonical objects (scenarios.setup_objects) [m]: the prisms'
    mean circumradius and height, and the box's sides."""
    objs = setup_objects(hand)
    prisms = [objs[k]().params for k in ("hexagon", "octagon")]
    return (
        float(np.mean([p["circumradius_m"] for p in prisms])),
        float(np.mean([p["height_m"] for p in prisms])),
        tuple(float(x) for x in objs["box"]().params["size"]),
    )


def _unit(rng: np.random.Generator) -> np.ndarray:
    v = rng.normal(size=3)
    return v / np.linalg.norm(v)


def _draw_spec(i: int, seed: int, hands: tuple[str, ...] = HANDS) -> ScenarioSpec:
    """Spec ``i`` of the suite ``seed`` (see the module docstring for the balance)."""
    hand = hands[i % len(hands)]
    kind = OBJECT_KINDS[i % 3]
    motion_kind = MOTION_KINDS[(i + i // 6) % 3]
    sign = 1.0 if (i // 2) % 2 == 0 else -1.0
    rng = np.random.default_rng([seed, i])
    radius, height, box = _canonical_sizes(hand)

    def spread(n: int | None = None) -> Any:
        return rng.uniform(1.0 - SIZE_SPREAD, 1.0 + SIZE_SPREAD, n)

    if kind == "prism":
        obj = ObjectSpec(
            "prism",
            n_sides=int(rng.integers(N_SIDES_RANGE[0], N_SIDES_RANGE[1] + 1)),
            circumradius_m=round(radius * spread(), 4),
            height_m=round(height * spread(), 4),
        )
    elif kind == "box":
        obj = ObjectSpec("box", size_m=tuple(np.round(np.array(box) * spread(3), 4).tolist()))
    else:
        extents = np.array([2 * radius, 2 * radius, height])
        obj = ObjectSpec(
            "mesh",
            size_m=tuple(np.round(extents * spread(3), 4).tolist()),
            n_points=int(rng.integers(N_POINTS_RANGE[0], N_POINTS_RANGE[1] + 1)),
            seed=int(rng.integers(0, 2**31 - 1)),
        )
    angle = sign * round(float(rng.uniform(*ANGLE_RANGE_DEG)), 1)
    rate = round(float(rng.uniform(*RATE_RANGE_DEG_S)), 1)
    axis = (0.0, 0.0, 1.0)
    translation = (0.0, 0.0, 0.0)
    if motion_kind != "contact-axis":
        phi = rng.uniform(0.0, 2 * np.pi)
        tilt = np.radians(rng.uniform(0.0, MAX_TILT_DEG))
        rot = Rotation.from_rotvec(tilt * np.array([np.cos(phi), np.sin(phi), 0.0]))
        axis = tuple(np.round(rot.apply([0.0, 0.0, 1.0]), 6).tolist())
    if motion_kind == "rotate-translate":
        translation = tuple(np.round(_unit(rng) * rng.uniform(*TRANSLATION_RANGE_M), 5).tolist())
    motion = MotionSpec(motion_kind, angle, rate, axis_object=axis, translation_m=translation)
    offset = _unit(rng) * MAX_POSITION_OFFSET_M * rng.uniform() ** (1 / 3)
    rotvec = _unit(rng) * np.radians(rng.uniform(0.0, MAX_ROTATION_OFFSET_DEG))
    grasp_dt = float(np.clip(GRASP_STEP_DEG / rate, *GRASP_DT_RANGE_S))
    horizon = GRASP_HORIZON_DEG / rate
    return ScenarioSpec(
        name=(
            f"s{seed}-{i:03d}-{hand_label(hand)}-{obj.label}-{motion_kind}-{angle:+.0f}deg-"
            f"{rate:.0f}dps"
        ),
        hand=hand,
        object=obj,
        motion=motion,
        position_offset_m=tuple(np.round(offset, 5).tolist()),
        rotation_offset_rotvec=tuple(np.round(rotvec, 5).tolist()),
        seed=int(rng.integers(0, 1000)),
        grasp_dt_s=round(grasp_dt, 3),
        grasp_horizon_s=round(horizon, 3) if horizon < motion.duration_s else None,
        base_pose=_base_pose_of(hand),
    )


def _hands(hands: tuple[str, ...] | list[str]) -> tuple[str, ...]:
    if not hands:
        raise InputError("hands", "is empty", f"names of {HANDS} or hand files")
    for h in hands:
        if not is_hand_file(h):
            choice(h, "hands", HANDS)
    return tuple(hands)


def generate_specs(n: int, seed: int = 0, hands: tuple[str, ...] = HANDS) -> list[ScenarioSpec]:
    """The first ``n`` specs of the suite ``seed`` (deterministic, prefix-stable).

    Args:
        n: How many specs (>= 0).
        seed: Suite seed (>= 0); spec ``i`` is drawn from ``default_rng([seed, i])``.
        hands: The hands, in turn: bundled names or hand files.

    Returns:
        ``n`` specs; hands alternate, object kinds and motion kinds cycle, so every
        prefix is balanced (see the module docstring) for one or two hands. With a
        multiple of three hands each hand would always get the same object kind (the
        kind is ``i % 3``, kept so that the bundled suites stay the same): run such
        hands one or two at a time.

    Raises:
        InputError: negative ``n`` or ``seed``, no hands.
        UnknownNameError: an unknown hand name.
    """
    n = positive_int(n, "n", minimum=0)
    seed = positive_int(seed, "seed", minimum=0)
    hands = _hands(hands)
    return [_draw_spec(i, seed, hands) for i in range(n)]


def select_specs(
    n: int,
    seed: int = 0,
    hands: tuple[str, ...] = HANDS,
    *,
    objects: tuple[str, ...] = OBJECT_KINDS,
    motions: tuple[str, ...] = MOTION_KINDS,
    draws_per_scenario: int = MAX_DRAWS_PER_SCENARIO,
) -> list[ScenarioSpec]:
    """The specs a suite of ``n`` scenarios draws from: those of :func:`generate_specs`
    whose object kind is in ``objects`` and motion kind in ``motions``, enough of them
    (``draws_per_scenario`` per scenario, as if every kind were kept) for ``n`` with an
    initial grasp. The same kinds and seed give the same specs, in the same order.

    Raises:
        InputError: an unknown object or motion kind, or none; bad ``n`` or ``seed``.
    """
    for value, name, known in (
        (objects, "objects", OBJECT_KINDS),
        (motions, "motions", MOTION_KINDS),
    ):
        if not value:
            raise InputError(name, "is empty", f"some of {known}")
        for v in value:
            choice(v, name, known)
    n = positive_int(n, "n", minimum=0)
    want = draws_per_scenario * n
    # object kinds cycle with i % 3 and motion kinds with (i + i // 6) % 3: a kept
    # fraction of len(objects) / 3 x len(motions) / 3 on average
    scale = -(-len(OBJECT_KINDS) // len(objects)) * -(-len(MOTION_KINDS) // len(motions))
    drawn = generate_specs(want * scale, seed, hands)
    kept = [s for s in drawn if s.object.kind in objects and s.motion.kind in motions]
    return kept[:want]


def neighbour_specs(hands: tuple[str, ...] = HANDS) -> list[ScenarioSpec]:
    """The canonical demo and its neighbours, as
    :func:`~regrasp_pin.scenarios.make_scenario` builds them: each hand x the hexagonal
    prism x turns of
    :data:`NEIGHBOUR_ANGLES_DEG` x rates :data:`NEIGHBOUR_RATES_DEG_S`, about the thumb's
    contact, no offsets, grasp seed 0, grasp manifolds every 0.05 s (15 specs a hand)."""
    out = []
    for hand in _hands(hands):
        pose = _base_pose_of(hand)
        p = setup_objects(hand)["hexagon"]().params
        obj = ObjectSpec(
            "prism",
            n_sides=int(p["n_sides"]),
            circumradius_m=float(p["circumradius_m"]),
            height_m=float(p["height_m"]),
        )
        for angle in NEIGHBOUR_ANGLES_DEG:
            for rate in NEIGHBOUR_RATES_DEG_S:
                out.append(
                    ScenarioSpec(
                        name=f"{hand_label(hand)}-hexagon-{angle:+.0f}deg-{rate:.0f}dps",
                        hand=hand,
                        object=obj,
                        motion=MotionSpec("contact-axis", angle, rate),
                        seed=0,
                        grasp_dt_s=0.05,
                        grasp_clearance_m=None,
                        base_pose=pose,
                    )
                )
    return out
