"""Regrasps and the whole hand: the paper's step 5 (section 2.3, Fig. 9) and its test.

Takes a hand, an object, its motion and an initial grasp. Gives verified regrasps and
a whole-hand plan, or a typed :class:`~regrasp_pin.exceptions.PlanningError` that
carries every failed attempt and the partial plan:

- :mod:`.regrasp`: one finger's regrasp from P to Q: surface path
  (:mod:`regrasp_pin.surface`), Hopfield waypoints (:mod:`regrasp_pin.polygon`), a
  timing synchronized with the object (:mod:`.timing`), IK, and the Coal check
  (:mod:`regrasp_pin.verify`); when no surface path passes, :mod:`.transfer`, a
  joint-space fallback verified the same way;
- :mod:`.planner`: the whole hand over the whole motion (:func:`plan_manipulation`):
  which finger lets go when, and backtracking; its parameters in :mod:`.params`;
  what it builds before its search, whatever the grasp, in :mod:`.setup`
  (:func:`plan_setup`, built once to plan from several grasps);
- :mod:`.state`: where a plan stands and the triggers that follow from it;
- :mod:`.letgo`: a finger with no verified regrasp lets go, or hands over to an idle
  finger;
- :mod:`.schedule`: a finger's lift-off window and the start times tried in it;
- :mod:`.search`: one finger's regrasp as a search over start times, new contacts Q
  and durations, with a budget;
- :mod:`.proximity`: holding fingers closing in on each other;
- :mod:`.release`: a finger that lets go for the rest of the motion;
- :mod:`.join`: a finger that took no part so far joins the grasp;
- :mod:`.outcomes`: the dominant cause of a list of failed attempts.
"""

from .outcomes import dominant_kind, failure_summary
from .planner import ManipulationPlan, PlannerParams, plan_manipulation
from .regrasp import RegraspParams, RegraspResult, plan_regrasp
from .schedule import LiftOffWindow, lift_off_window, start_times
from .search import RegraspSearch, SearchBudget
from .setup import PlanSetup, plan_setup
from .transfer import Transfer, plan_transfer

__all__ = [
    "LiftOffWindow",
    "ManipulationPlan",
    "PlanSetup",
    "PlannerParams",
    "RegraspParams",
    "RegraspResult",
    "RegraspSearch",
    "SearchBudget",
    "Transfer",
    "dominant_kind",
    "failure_summary",
    "lift_off_window",
    "plan_manipulation",
    "plan_regrasp",
    "plan_setup",
    "plan_transfer",
    "start_times",
]
