"""The regrasp search: when a finger lifts off, where it lands, how long it flies.

Takes a hand, an object, its motion and the fingers that hold; returns verified
regrasps (:class:`~regrasp_pin.regrasp.RegraspResult`) or a typed
:class:`~regrasp_pin.exceptions.PlanningError` that carries every failed attempt.

- :mod:`.schedule`: the lift-off window of a finger and the start times tried in it.
- :mod:`.search`: one finger's regrasp as a search over start times, new contacts Q
  and durations (:mod:`regrasp_pin.timing`), with a budget.
- :mod:`.outcomes`: the dominant cause of a list of failed attempts.
"""

from .outcomes import dominant_kind, failure_summary
from .schedule import LiftOffWindow, lift_off_window, start_times
from .search import RegraspSearch, SearchBudget

__all__ = [
    "LiftOffWindow",
    "RegraspSearch",
    "SearchBudget",
    "dominant_kind",
    "failure_summary",
    "lift_off_window",
    "start_times",
]
