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

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation

from ._validate import choice, positive
from .contact import ContactModel
from .contact_choice import Grasp, initial_grasp
from .exceptions import InputError
from .hand import Hand
from .manifold import build_manifold
from .motion import ObjectMotion
from .objects import Box, ConvexObject, Prism
from .planner import PlannerParams
from .regrasp import RegraspParams

__all__ = ["HANDS", "OBJECTS", "Scenario", "make_scenario"]

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
        "position": (0.115, 0.035, 0.0),
        "fingers": ("thumb", "index", "middle", "ring"),
        "objects": {
            "hexagon": lambda: Prism(6, 0.045, 0.04),
            "octagon": lambda: Prism(8, 0.046, 0.04),
            "box": lambda: Box((0.05, 0.06, 0.06)),
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
    setup = _SETUP[hand]
    h = Hand.five_finger() if hand == "five_finger" else Hand.allegro()
    o = setup["objects"][obj]()
    T0 = np.eye(4)
    T0[:3, :3] = setup["rotation"].as_matrix()
    T0[:3, 3] = setup["position"]
    fingers = setup["fingers"]
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
    sample = o.sample_surface(0.002)
    times = np.linspace(turn0.t_start, turn0.t_end, max(int(duration / 0.05), 1) + 1)
    manifolds = {
        n: build_manifold(h.fingers[n], sample, turn0, times, contact=contact) for n in fingers
    }
    grasp = initial_grasp(h, o, manifolds, sample, contact=contact, seed=seed)
    # 2) the same turn about the thumb's contact, along its normal
    R0 = T0[:3, :3]
    pivot = R0 @ grasp.points_object["thumb"] + T0[:3, 3]
    axis = -(R0 @ grasp.normals_object["thumb"])
    axis *= np.sign(axis @ axis0) or 1.0
    motion = ObjectMotion.constant_twist(
        T0,
        axis_palm=axis,
        point_palm=pivot,
        rate_rad_s=rate_rad,
        duration_s=duration,
        dt_s=dt_s,
    )
    params = PlannerParams(
        fingers=fingers,
        manifold_dt_s=0.1,
        contact=contact,
        regrasp=RegraspParams(clearance_m=0.003, duration_s=0.4),
    )
    idle = [n for n in h.finger_names if n not in fingers]
    desc = (
        f"{h.name} hand turns a {o.kind} ({obj}) by {angle:g} deg at {rate:g} deg/s about "
        f"the axis through the thumb's contact; fingers {', '.join(fingers)}"
        + (f" (idle: {', '.join(idle)})" if idle else "")
    )
    return Scenario(
        name=f"{hand}-{obj}",
        hand=h,
        obj=o,
        motion=motion,
        grasp=grasp,
        params=params,
        description=desc,
    )
