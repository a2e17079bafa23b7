"""regrasp_pin: regrasp planning for multi-fingered robot hands.

When one finger's contact drifts to its joint limits while the object moves, the
finger lifts off, travels around the object without touching it or the other
fingers, and lands on a better contact, while the other fingers keep holding.
Kinematics by Pinocchio, exact distances by Coal.

``import regrasp_pin`` never imports meshcat or matplotlib.
"""

from __future__ import annotations

from . import exceptions
from .exceptions import (
    ContactError,
    GeometryError,
    InputError,
    MissingExtraError,
    ModelFileError,
    PlanningError,
    RegraspError,
    UnknownNameError,
    VerificationError,
)
from .grasp_quality import contact_wrenches, ferrari_canny_epsilon, is_force_closure
from .hand import Finger, Hand
from .ik import IKResult
from .kinematics import FingerChain
from .motion import ObjectMotion
from .objects import (
    Box,
    ConvexMesh,
    ConvexObject,
    ExtrudedPolygon,
    Face,
    FaceAdjacency,
    Prism,
    SurfaceSample,
    object_from_params,
)

__version__ = "0.1.0"

__all__ = [
    "Box",
    "ConvexMesh",
    "ConvexObject",
    "ExtrudedPolygon",
    "Face",
    "FaceAdjacency",
    "ObjectMotion",
    "Prism",
    "SurfaceSample",
    "contact_wrenches",
    "ferrari_canny_epsilon",
    "is_force_closure",
    "object_from_params",
    "Finger",
    "FingerChain",
    "Hand",
    "IKResult",
    "ContactError",
    "GeometryError",
    "InputError",
    "MissingExtraError",
    "ModelFileError",
    "PlanningError",
    "RegraspError",
    "UnknownNameError",
    "VerificationError",
    "__version__",
    "exceptions",
]
