"""The problem every stage reads: a hand, an object and the object's motion.

These three travel together from :func:`~regrasp_pin.plan_manipulation` down to the
verifier; :class:`Scene` carries them as one frozen value (as pink's
``Configuration`` carries model, data and q), so that a stage takes the scene and only
the arguments that are its own.
"""

from __future__ import annotations

from dataclasses import dataclass

from ..exceptions import InputError
from .hand import Hand
from .motion import ObjectMotion
from .objects import ConvexObject

__all__ = ["Scene"]


@dataclass(frozen=True)
class Scene:
    """A hand manipulating a convex object along a motion.

    Attributes:
        hand: The hand (palm frame = the hand model's root frame).
        obj: The object (object frame: origin at its centre of mass).
        motion: The object's pose ``T_palm_object(t)`` over time.
    """

    hand: Hand
    obj: ConvexObject
    motion: ObjectMotion

    def __post_init__(self) -> None:
        for name, value, cls in (
            ("hand", self.hand, Hand),
            ("obj", self.obj, ConvexObject),
            ("motion", self.motion, ObjectMotion),
        ):
            if not isinstance(value, cls):
                raise InputError(name, f"is a {type(value).__name__}", f"a {cls.__name__}")
