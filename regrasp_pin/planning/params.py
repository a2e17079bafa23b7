"""The parameters of the whole-hand planner (:func:`~.planner.plan_manipulation`)."""

from __future__ import annotations

from dataclasses import dataclass, field, replace

from .._validate import positive, positive_int
from ..exceptions import InputError
from ..grasp.contact import ContactModel
from ..grasp.quality import holding_fingers
from .regrasp import RegraspParams
from .timing import checked_time_law

__all__ = ["PlannerParams"]


@dataclass(frozen=True)
class PlannerParams:
    """Parameters of the whole-hand planner.

    Attributes:
        dt_s: Time step of the holding phases [s].
        manifold_dt_s: Time step of the joint-space manifolds used to choose Q [s].
        sample_spacing_m: Surface sampling spacing for the manifolds [m].
        lead_s: A regrasp preferably starts this long before its trigger [s].
        min_holding: Fewest fingers that must hold while one is in the air; None (the
            default): the fewest that can be in force closure under the contact model,
            3 for point contacts and 2 with torsional friction (``contact.torsion_m``,
            a pinch); read it as :attr:`fewest_holding`.
        mu: Friction coefficient for force closure.
        candidates: How many new contacts Q to try per lift-off time.
        start_step_s: Spacing of the lift-off times tried in a finger's window [s].
        max_starts: Most lift-off times tried per regrasp.
        max_backtracks: Most times the planner backs up (another finger first, a
            neighbour making room, an earlier regrasp planned again) before the plan
            gets further in time than it ever got; each new furthest time gets as
            many again (``max_steps`` bounds the whole search). With 8, the
            recoveries of the suites' crowded turns were cut before their options
            ran out; 16 and 32 plan the same default suite (docs/findings.md).
        max_steps: The search budget of the whole call, in steps (a new contact
            chosen, a regrasp planned, a release or a join tried; see
            :class:`~.search.SearchBudget`): once spent, no new attempt starts and the
            planner stops with a ``budget`` failure and the partial plan. Counted, not
            timed, so that a plan is the same on every machine; on a 2-core machine a
            step takes 12-31 ms on average (2026-12-07: the three random suites' plans
            that spent 300 steps or more, two workers), so 1600 steps take about 50 s
            at most (the slowest plan of those suites took 33 s).
        budget_s: An optional wall-clock limit of the whole call [s] (manifolds and
            tracking included; a setup built before the call, ``setup=``, is not) on
            top of ``max_steps``, with the same effect; None (the default): none, so
            that the outcome never depends on the machine's speed.
        exit_tolerance_s: New contacts whose exit times differ by less than this are
            ties, broken by the shorter move (see
            :func:`~regrasp_pin.grasp.choice.choose_new_contact`).
        fingers: The fingers that take part (default: all). The others stay idle at
            the configuration of :func:`rest_configuration`, as obstacles that every
            regrasp is verified against.
        contact: The contact model (trigger margin, pad cone, tolerances).
        regrasp: Parameters of each regrasp (``duration_s`` is the shortest duration;
            longer ones follow from the joint velocity limits).
        rush_duration_s: When another finger's hold would be lost before a regrasp of
            ``regrasp.duration_s`` could land, a regrasp as short as this [s] is
            searched instead, landing before that hold is lost (the joint velocity
            limits, checked by the search, decide whether it can be that fast); None:
            never.
        release: Let a finger go for the rest of the motion when its hold is lost with
            no verified regrasp, if more than ``min_holding`` others remain to take
            turns, or if the others hold in force closure to the end
            (:mod:`.planning.release`).
        release_back_off_s: Shortest duration of a release's back-off move [s] (longer
            when the joint velocity limits need it).
        threads: Threads that build the fingers' manifolds (the same manifolds on any
            number; see :func:`~regrasp_pin.grasp.manifold.build_manifolds`); None:
            its default (one per core with the numba IK backend, else one).
        prove_infeasible: Fail at once, with kind ``infeasible``, when a finger
            provably cannot hold as long as it must (:mod:`~regrasp_pin.grasp.necessity`),
            and choose the initial grasp with that proof; False: search anyway (the
            partial plan of a failure then reaches as far as the search got).
    """

    dt_s: float = 0.01
    manifold_dt_s: float = 0.05
    sample_spacing_m: float = 0.002
    lead_s: float = 0.02
    min_holding: int | None = None
    mu: float = 0.8
    candidates: int = 6
    start_step_s: float = 0.1
    max_starts: int = 5
    max_backtracks: int = 16
    max_steps: int = 1600
    budget_s: float | None = None
    fingers: tuple[str, ...] | None = None
    exit_tolerance_s: float = 0.25
    contact: ContactModel = field(default_factory=ContactModel)
    regrasp: RegraspParams = field(default_factory=RegraspParams)
    rush_duration_s: float | None = 0.15
    release: bool = True
    release_back_off_s: float = 0.1
    prove_infeasible: bool = True
    threads: int | None = None

    def __post_init__(self) -> None:
        for name in ("dt_s", "manifold_dt_s", "sample_spacing_m", "mu", "start_step_s"):
            positive(getattr(self, name), f"PlannerParams.{name}")
        for name in ("lead_s", "exit_tolerance_s", "release_back_off_s"):
            positive(getattr(self, name), f"PlannerParams.{name}", allow_zero=True)
        if self.min_holding is not None:
            positive_int(self.min_holding, "PlannerParams.min_holding", 1)
        for name, least in (
            ("candidates", 1),
            ("max_starts", 1),
            ("max_backtracks", 0),
            ("max_steps", 1),
        ):
            positive_int(getattr(self, name), f"PlannerParams.{name}", least)
        if self.threads is not None:
            positive_int(self.threads, "PlannerParams.threads", 1)
        if self.budget_s is not None:
            positive(self.budget_s, "PlannerParams.budget_s", allow_zero=True)
        if self.rush_duration_s is not None:
            positive(self.rush_duration_s, "PlannerParams.rush_duration_s")
        for name in ("release", "prove_infeasible"):
            if not isinstance(getattr(self, name), bool):
                raise InputError(
                    f"PlannerParams.{name}", f"is {getattr(self, name)!r}", "True or False"
                )

    @property
    def fewest_holding(self) -> int:
        """The fewest fingers that must hold while one is in the air: ``min_holding``,
        or by the contact model (:func:`~regrasp_pin.grasp.quality.holding_fingers`)."""
        if self.min_holding is not None:
            return self.min_holding
        return holding_fingers(self.contact.torsion_m)


def with_time_law(params: PlannerParams, time_law: str | None) -> PlannerParams:
    """``params`` with its regrasps' ``time_law`` (:data:`~.timing.TIME_LAWS`; None: as
    they are). Raises InputError naming ``time_law`` for another value."""
    if time_law is None:
        return params
    return replace(params, regrasp=replace(params.regrasp, time_law=checked_time_law(time_law)))
