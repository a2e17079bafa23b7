"""Ready-made manipulation scenarios: a hand, an object, its pose and its motion.

The canonical scenario follows the paper's test: the bundled five-finger hand holds a
prismatic object in a fingertip grasp, and the object turns about an axis through it
by far more than any fixed grasp allows, so the fingers must regrasp. Here the object
is a hexagonal prism held between the thumb (on one end face) and the four fingers
(on the other), turned about its own axis like a knob.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from ._validate import choice, positive
from .hand import Hand
from .motion import ObjectMotion
from .objects import Box, ConvexObject, Prism

__all__ = ["Scenario", "OBJECTS", "HANDS", "make_scenario"]

HANDS = ("five_finger", "allegro")
OBJECTS = ("hexagon", "octagon", "box")


@dataclass(frozen=True)
class Scenario:
    """A hand, an object and the object's motion in the palm frame."""

    name: str
    hand: Hand
    obj: ConvexObject
    motion: ObjectMotion
    description: str


def _object(kind: str, hand: str) -> ConvexObject:
    big = hand == "allegro"
    if kind == "hexagon":
        return Prism(6, 0.038 if big else 0.032, 0.04)
    if kind == "octagon":
        return Prism(8, 0.040 if big else 0.034, 0.04)
    return Box((0.04, 0.06, 0.06) if big else (0.04, 0.05, 0.05))


def make_scenario(
    hand: str = "five_finger",
    obj: str = "hexagon",
    *,
    angle_deg: float = 100.0,
    rate_deg_s: float = 30.0,
    dt_s: float = 0.01,
) -> Scenario:
    """Build the canonical scenario.

    Args:
        hand: ``"five_finger"`` (bundled) or ``"allegro"`` (example-robot-data).
        obj: ``"hexagon"`` or ``"octagon"`` (prisms) or ``"box"``.
        angle_deg: Total rotation of the object [deg]; its sign gives the direction.
        rate_deg_s: Rotation speed [deg/s] (> 0).
        dt_s: Sampling step of the motion [s].

    Returns:
        The :class:`Scenario`.

    Raises:
        UnknownNameError: unknown hand or object.
        InputError: non-positive rate or zero angle.
    """
    choice(hand, "hand", HANDS)
    choice(obj, "obj", OBJECTS)
    rate = positive(rate_deg_s, "rate_deg_s")
    if not np.isfinite(angle_deg) or angle_deg == 0:
        from .exceptions import InputError

        raise InputError("angle_deg", f"{angle_deg!r} is not allowed", "a finite non-zero angle")
    object_ = _object(obj, hand)
    T0 = np.eye(4)
    if hand == "five_finger":
        # prism axis (object z) along the palm x axis: thumb on the near end face,
        # fingers wrapped onto the far end face
        h = Hand.five_finger()
        T0[:3, :3] = Rotation.from_euler("y", 90, degrees=True).as_matrix()
        T0[:3, 3] = [0.065, 0.0, 0.06]
        axis = np.array([1.0, 0.0, 0.0])
    else:
        # Allegro: fingers along palm +z, palm normal +x
        h = Hand.allegro()
        T0[:3, 3] = [0.09, 0.0, 0.10]
        axis = np.array([0.0, 0.0, 1.0])
    sign = 1.0 if angle_deg > 0 else -1.0
    motion = ObjectMotion.constant_twist(
        T0,
        axis_palm=axis,
        point_palm=T0[:3, 3],
        rate_rad_s=sign * np.radians(rate),
        duration_s=abs(angle_deg) / rate,
        dt_s=dt_s,
    )
    desc = (
        f"{h.name} hand turns a {object_.kind} ({obj}) by {angle_deg:g} deg at "
        f"{rate:g} deg/s about the palm {'xyz'[int(np.argmax(np.abs(axis)))]} axis"
    )
    return Scenario(name=f"{hand}-{obj}", hand=h, obj=object_, motion=motion, description=desc)
