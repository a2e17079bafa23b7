"""regrasp_pin: regrasp planning for multi-fingered robot hands.

When one finger's contact drifts to its joint limits while the object moves, the
finger lifts off, travels around the object without touching it or the other
fingers, and lands on a better contact, while the other fingers keep holding.
Kinematics by Pinocchio, exact distances by Coal.

``import regrasp_pin`` never imports meshcat or matplotlib: the viewer lives in
``regrasp_pin.viz`` and the figures in ``regrasp_pin.plotting``.
"""

from __future__ import annotations

from . import exceptions
from .backups import GraspBackup, plan_scenario
from .exceptions import (
    ContactError,
    GeometryError,
    InputError,
    MissingExtraError,
    ModelFileError,
    PlanningError,
    RegraspError,
    UnfoldError,
    UnknownNameError,
    VerificationError,
)
from .grasp.choice import NewContact, choose_new_contact, exit_times
from .grasp.contact import ContactModel
from .grasp.holding import holding_hand
from .grasp.initial import Grasp, initial_grasp
from .grasp.manifold import Manifold, build_manifold
from .grasp.quality import contact_wrenches, ferrari_canny_epsilon, is_force_closure
from .grasp.tracking import ContactTrack, track_contact
from .model.clearance import FingerClearance, LinkClearance
from .model.hand import Finger, Hand
from .model.ik import IKResult
from .model.kinematics import FingerChain
from .model.motion import ObjectMotion
from .model.objects import (
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
from .placing import Placement, candidate_placements
from .plan import ContactPhase, Plan, RegraspPhase
from .planning.planner import ManipulationPlan, PlannerParams, plan_manipulation
from .planning.regrasp import RegraspParams, RegraspResult, plan_regrasp
from .planning.setup import PlanSetup, plan_setup
from .planning.transfer import Transfer, plan_transfer
from .polygon.approximate import PolygonResult, approximate_polygon
from .polygon.deviation import deviation_matrix
from .scenarios import GraspSearch, Scenario, make_scenario, scenario_for_hand
from .surface.grid import SurfaceGrid, build_surface_grid
from .surface.inflation import TipPath, grid_inflation, inflate_path, inflation_height
from .surface.path import GridPath, shortest_grid_path
from .verify.finger_motion import Failure, VerificationReport, densify, verify_finger_motion

__version__ = "0.1.0"

__all__ = [
    "Box",
    "ContactError",
    "ContactModel",
    "ContactPhase",
    "ContactTrack",
    "ConvexMesh",
    "ConvexObject",
    "ExtrudedPolygon",
    "Face",
    "FaceAdjacency",
    "Failure",
    "Finger",
    "FingerChain",
    "FingerClearance",
    "GeometryError",
    "Grasp",
    "GraspBackup",
    "GraspSearch",
    "GridPath",
    "Hand",
    "IKResult",
    "InputError",
    "LinkClearance",
    "ManipulationPlan",
    "Manifold",
    "MissingExtraError",
    "ModelFileError",
    "NewContact",
    "ObjectMotion",
    "Plan",
    "PlanSetup",
    "PlannerParams",
    "PlanningError",
    "PolygonResult",
    "Prism",
    "RegraspError",
    "RegraspParams",
    "RegraspPhase",
    "RegraspResult",
    "Scenario",
    "SurfaceGrid",
    "SurfaceSample",
    "TipPath",
    "Transfer",
    "UnfoldError",
    "UnknownNameError",
    "VerificationError",
    "VerificationReport",
    "__version__",
    "approximate_polygon",
    "build_manifold",
    "build_surface_grid",
    "choose_new_contact",
    "contact_wrenches",
    "densify",
    "deviation_matrix",
    "exceptions",
    "exit_times",
    "ferrari_canny_epsilon",
    "grid_inflation",
    "holding_hand",
    "inflate_path",
    "inflation_height",
    "initial_grasp",
    "is_force_closure",
    "make_scenario",
    "scenario_for_hand",
    "candidate_placements",
    "Placement",
    "object_from_params",
    "plan_manipulation",
    "plan_setup",
    "plan_regrasp",
    "plan_scenario",
    "plan_transfer",
    "shortest_grid_path",
    "track_contact",
    "verify_finger_motion",
]
