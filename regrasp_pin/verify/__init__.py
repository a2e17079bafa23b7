"""Exact checks with Coal: nothing is returned that has not passed them.

Takes sampled joint trajectories of the hand and the object's poses. Gives reports in
which every failure is data (kind, time, measured and required values):

- :mod:`.finger_motion`: one finger's motion, densified, against the object and the
  other fingers, and its joint limits (:func:`verify_finger_motion`); what every
  planned regrasp passes before the planner returns it;
- :mod:`.plan_check`: an independent re-check of a whole plan file
  (:func:`recheck_plan`), which reads nothing but the file.
"""

from .finger_motion import Failure, VerificationReport, densify, verify_finger_motion
from .plan_check import JointLimitViolation, PlanCheck, RegraspCheck, recheck_plan

__all__ = [
    "Failure",
    "JointLimitViolation",
    "PlanCheck",
    "RegraspCheck",
    "VerificationReport",
    "densify",
    "recheck_plan",
    "verify_finger_motion",
]
