"""The problem every stage reads: a hand, an object and the object's motion.

These three travel together from :func:`~regrasp_pin.plan_manipulation` down to one
regrasp's path and trajectory; :class:`Scene` carries them as one frozen value (as
pink's ``Configuration`` carries model, data and q), so that a stage takes the scene
and only the arguments that are its own.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._validate import hand_scale
from ..exceptions import InputError
from .hand import Hand
from .motion import ObjectMotion
from .objects import ConvexObject

__all__ = ["Scene"]


@dataclass(frozen=True)
class Scene:
    """A hand manipulating a convex object along a motion.

    Raises InputError for a part of the wrong type, or a motion that takes the object
    farther than 1 m from the palm (a length in millimetres by mistake).

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
        # a pose tens of metres from the palm is a length in millimetres by mistake
        far = np.linalg.norm(self.motion.T_palm_object[:, :3, 3], axis=1)
        i = int(np.argmax(far))
        try:
            hand_scale(float(far[i]), "motion")
        except InputError as exc:
            raise InputError(
                "motion",
                f"puts the object {far[i]:g} m from the palm at t={self.motion.times_s[i]:g} s",
                exc.expected,
            ) from None
