"""The hand, the object and its motion: what every stage reads.

Takes a URDF (or a bundled hand), object parameters or points, and the object's poses
over time. Gives:

- :mod:`.hand`: the hand's fingers with batched forward kinematics, Jacobians and IK
  (Pinocchio; :mod:`.kinematics`, :mod:`.ik`), joint limits and collision geometry;
- :mod:`.objects`: convex objects (boxes, prisms, extrusions, hulls of points) with
  their faces (:mod:`.faces`), surface samples and exact signed distances;
- :mod:`.motion`: the object's pose ``T_palm_object(t)`` at any time;
- :mod:`.scene`: the three as one frozen value that the later stages read;
- :mod:`.clearance`: exact Coal distances from a finger to the object and to the
  other fingers at given configurations (Pinocchio's collision pairs);
- :mod:`.distances`: batched distance bounds between the hand's collision geometries
  (capsules, support functions) with exact Coal distances where they decide.
"""

from .clearance import FingerClearance, LinkClearance
from .hand import Finger, Hand, allegro_urdf_path, five_finger_urdf_path
from .ik import IKResult, solve_position_ik
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
from .scene import Scene

__all__ = [
    "Box",
    "ConvexMesh",
    "ConvexObject",
    "ExtrudedPolygon",
    "Face",
    "FaceAdjacency",
    "Finger",
    "FingerChain",
    "FingerClearance",
    "Hand",
    "IKResult",
    "LinkClearance",
    "ObjectMotion",
    "Prism",
    "Scene",
    "SurfaceSample",
    "allegro_urdf_path",
    "five_finger_urdf_path",
    "object_from_params",
    "solve_position_ik",
]
