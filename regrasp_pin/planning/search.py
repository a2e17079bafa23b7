"""One finger's regrasp as a search over start times, new contacts Q and durations.

For each start time of the finger's lift-off window (:mod:`.schedule`), the new
contacts Q are taken in the order of the paper's criterion (condition (b), then the
shorter move; :func:`~regrasp_pin.grasp.choice.choose_new_contact`). For each Q:

1. the duration is computed from the joint velocity limits for the move from the
   lift-off configuration to Q's (:func:`~regrasp_pin.planning.timing.duration_for_move`);
2. :func:`~regrasp_pin.planning.regrasp.plan_regrasp` plans and verifies the path, changing
   its own variants by the kind of each failure, and tries the joint-space fallback
   (:mod:`.transfer`) when no surface path passes for a reason other than speed;
3. a velocity failure stretches the duration by the measured over-speed (time
   scaling, then fitted to the last two tries: :func:`~.timing.next_duration`) and
   plans the same Q again (or the Q the new arrival time prefers); when no longer
   duration is left (stretches used, or it would land after the deadline) the
   joint-space fallback is tried once at the last duration;
4. a verified regrasp is judged by what follows its landing (the caller's
   ``landing_check``: the planner follows the new contact and rejects one that would be
   lost sooner than a regrasp takes);
5. any other failure excludes Q, and only the points within ``exclude_radius_m`` of
   it, from the next choices at this start time.

Every failure is recorded as an :class:`~regrasp_pin.exceptions.Attempt`. The search
ends with the first verified regrasp, or with a :class:`~regrasp_pin.exceptions.
PlanningError` of the dominant kind when the start times, the candidates or the budget
run out.

The searches of one plan keep the regrasps they planned, verified or failed, by
everything a regrasp follows from (the other fingers' motion by its
:attr:`~.state.HandMotion.key`): a recovery that searches again from a state it
revisits gets a regrasp planned before at once, the same result or failure, and
spends its step and records its attempt as before, so the search goes the same way.
"""

from __future__ import annotations

import functools
import hashlib
import logging
import math
import time
from collections import OrderedDict
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from ..exceptions import Attempt, ContactError, FailureKind, PlanningError
from ..grasp.choice import NewContact, Room, choose_new_contact, judging_time
from ..grasp.contact import ContactModel
from ..grasp.manifold import Manifold
from ..grasp.screening import ManifoldClearance, ScreeningEpsilons
from ..model.objects import SurfaceSample
from ..model.scene import Scene
from .outcomes import dominant_kind, failure_summary, nearest_miss
from .proximity import clear_of_fingers
from .regrasp import RegraspParams, RegraspResult, plan_regrasp
from .schedule import TIME_TOL_S
from .timing import duration_for_move, durations_for_moves, next_duration

#: The other fingers' postures (and finger, lift-off time) whose candidates' clearance
#: of them a search keeps (:meth:`RegraspSearch._clear_of_others`).
_LASTING_KEPT = 32
#: The regrasps a plan's searches keep by what they follow from (:meth:`RegraspSearch._plan_once`).
_PLANNED_KEPT = 256
#: A new contact Q must keep the finger this far from the other fingers at landing [m].
LANDING_FINGER_CLEARANCE_M = 0.001

__all__ = ["Found", "RegraspSearch", "SearchBudget"]

log = logging.getLogger(__name__)


@dataclass
class SearchBudget:
    """What a search may spend: a number of search steps and, optionally, wall-clock time.

    A step is one attempt of the search: a choice of a new contact, a regrasp planned
    and verified, a release or a join tried. Counting steps makes the budget the same on
    every machine (a slower CPU takes longer, it does not plan less); the wall-clock
    deadline is an optional guard on top, off by default.

    Attributes:
        max_steps: Most steps.
        deadline: ``time.perf_counter()`` value after which no new step starts
            (``inf``: none).
        steps: Steps taken so far.
    """

    max_steps: int = 10_000
    deadline: float = float("inf")
    steps: int = 0

    @classmethod
    def of(cls, max_steps: int, budget_s: float | None = None) -> SearchBudget:
        """A budget of ``max_steps`` steps and, if given, ``budget_s`` [s] of wall-clock
        time from now."""
        deadline = float("inf") if budget_s is None else time.perf_counter() + budget_s
        return cls(max_steps=max_steps, deadline=deadline)

    def spend(self, steps: int = 1) -> None:
        """Count ``steps`` more steps."""
        self.steps += steps

    @property
    def exhausted(self) -> bool:
        """True once ``max_steps`` steps were taken or the deadline has passed."""
        return self.steps >= self.max_steps or time.perf_counter() > self.deadline


@dataclass(frozen=True)
class Found:
    """A verified regrasp and how it was found.

    Attributes:
        result: The verified regrasp.
        choice: The new contact Q.
        attempts: The attempts that failed before it, in order.
    """

    result: RegraspResult
    choice: NewContact
    attempts: tuple[Attempt, ...] = ()


@dataclass
class _Call:
    """One :meth:`RegraspSearch.find` call: what it was given (see there) and what it
    has recorded (``attempts``, ``failed``: the regrasps that failed, by what they were;
    ``out_of_budget``: the budget ran out before a step)."""

    finger: str
    P: tuple[np.ndarray, np.ndarray]
    others: Mapping[str, tuple[np.ndarray, np.ndarray]]
    others_tips: np.ndarray
    q_hand: Callable[[np.ndarray], np.ndarray]
    budget: SearchBudget
    end_by: float
    shortest_s: float
    exclude: list[np.ndarray]
    landing_check: Callable[[RegraspResult], Attempt | None] | None
    reserved: Sequence[Room | tuple[np.ndarray, float]]
    frees: tuple[str, ...] = ()
    attempts: list[Attempt] = field(default_factory=list)
    failed: dict[tuple, PlanningError] = field(default_factory=dict)
    out_of_budget: bool = False


@dataclass
class RegraspSearch:
    """The fixed context of the regrasp searches of one manipulation plan.

    Attributes:
        scene: The hand, the object and its motion.
        manifolds: Joint-space manifolds per finger (to choose Q).
        sample: The surface sample the manifolds are built on.
        regrasp: Parameters of one regrasp (its ``duration_s`` is the shortest).
        contact: The contact model.
        mu: Friction coefficient.
        dt_s: Durations are multiples of this step [s].
        candidates: Most new contacts Q tried per start time.
        exclude_radius_m: A failed Q excludes the points this close to it [m]
            (default: the tip radius / 2).
        exit_tolerance_s: Exit times closer than this are ties (see
            :func:`~regrasp_pin.grasp.choice.choose_new_contact`).
        stretches: Most duration stretches for one Q after velocity failures.
    """

    scene: Scene
    manifolds: Mapping[str, Manifold]
    sample: SurfaceSample
    regrasp: RegraspParams
    contact: ContactModel
    mu: float = 0.8
    dt_s: float = 0.01
    candidates: int = 6
    exclude_radius_m: float | None = None
    exit_tolerance_s: float = 0.25
    stretches: int = 2
    _distances: dict[str, ManifoldClearance] = field(
        default_factory=dict, init=False, repr=False, compare=False
    )
    _lasting: OrderedDict[tuple, tuple[Manifold, dict[int, tuple[int, np.ndarray]]]] = field(
        default_factory=OrderedDict, init=False, repr=False, compare=False
    )
    _epsilons: ScreeningEpsilons | None = field(default=None, init=False, repr=False, compare=False)
    # the regrasps planned, verified or failed, by everything they follow from
    # (:meth:`_planned_key`), the most recently used last
    _planned: OrderedDict[bytes, RegraspResult | PlanningError] = field(
        default_factory=OrderedDict, init=False, repr=False, compare=False
    )

    def find(
        self,
        finger: str,
        P: tuple[np.ndarray, np.ndarray],
        starts: list[float],
        q_start_at: Callable[[float], np.ndarray],
        others: Mapping[str, tuple[np.ndarray, np.ndarray]],
        q_hand: Callable[[np.ndarray], np.ndarray],
        budget: SearchBudget,
        *,
        end_by_s: float | None = None,
        exclude: list[np.ndarray] | None = None,
        landing_check: Callable[[RegraspResult], Attempt | None] | None = None,
        reserved: Sequence[Room | tuple[np.ndarray, float]] = (),
        shortest_s: float | None = None,
        frees: Sequence[str] = (),
    ) -> Found:
        """Search a verified regrasp of ``finger`` (see the module docstring).

        Args:
            finger: The finger that lets go.
            P: Its contact ``(point, outward normal)``, object frame.
            starts: Lift-off times to try, in order [s].
            q_start_at: The finger's configuration holding P at a time [rad].
            others: The contacts that keep holding: finger -> (point, normal).
            q_hand: Maps times ``(S,)`` to hand configurations ``(S, nq)`` with the
                other fingers holding.
            budget: What the search may spend.
            end_by_s: The regrasp must have landed by this time [s] (None: the end of
                the motion).
            exclude: Points (object frame) whose neighbourhood Q must avoid.
            landing_check: Judges a verified regrasp by what follows its landing (e.g.
                how long the new contact is held): an :class:`Attempt` rejects it and
                excludes its Q like any other failure; None accepts it.
            reserved: Rooms (:class:`~regrasp_pin.grasp.choice.Room`, or ``(point,
                radius)`` pairs, object frame [m]) Q must leave
                free for another finger's landing.
            shortest_s: The shortest regrasp [s] (default ``regrasp.duration_s``).
            frees: Fingers of ``others`` that Q must let go (see :meth:`choose`).

        Raises:
            PlanningError: nothing verified; its ``kind`` is the dominant cause, its
                ``attempts`` every failure.
        """
        end_by = (
            self.scene.motion.t_end if end_by_s is None else min(end_by_s, self.scene.motion.t_end)
        )
        d_min = self.regrasp.duration_s if shortest_s is None else float(shortest_s)
        call = _Call(
            finger=finger,
            P=P,
            others=others,
            others_tips=np.array(
                [p + self.scene.hand.finger(n).tip_radius * nn for n, (p, nn) in others.items()]
            ).reshape(-1, 3),
            q_hand=q_hand,
            budget=budget,
            end_by=end_by,
            shortest_s=d_min,
            exclude=list(exclude or []),
            landing_check=landing_check,
            reserved=reserved,
            frees=tuple(frees),
        )
        for start in starts:
            if start + d_min > end_by + TIME_TOL_S:
                call.attempts.append(
                    Attempt(
                        FailureKind.TOO_LATE,
                        finger,
                        start,
                        measured=start + d_min,
                        required=end_by,
                        what=f"start {start:.2f} s",
                    )
                )
                continue
            found = self._at_start(call, start, q_start_at(start))
            if found is not None:
                return found
            if call.out_of_budget:
                return self._fail(finger, starts, call.attempts, budget=True)
        return self._fail(finger, starts, call.attempts, budget=False)

    def _at_start(self, call: _Call, start: float, q0: np.ndarray) -> Found | None:
        """Up to :attr:`candidates` new contacts Q from a lift-off at ``start`` [s] in
        ``q0``: the first verified regrasp, or None."""
        excluded = list(call.exclude)
        for _ in range(self.candidates):
            if call.budget.exhausted:
                call.out_of_budget = True
                return None
            found = self._try_candidate(call, start, q0, excluded)
            if found is None:
                return None  # no candidate left at this start
            if isinstance(found, Found):
                return found
        return None

    def choose(
        self,
        finger: str,
        P: tuple[np.ndarray, np.ndarray],
        t_arrive: float,
        others: Mapping[str, tuple[np.ndarray, np.ndarray]],
        q_hand: Callable[[np.ndarray], np.ndarray],
        excluded: list[np.ndarray],
        reserved: Sequence[Room | tuple[np.ndarray, float]] = (),
        landing: tuple[Callable[[np.ndarray], np.ndarray], float] | None = None,
        frees: Sequence[str] = (),
        absent: Sequence[str] = (),
    ) -> NewContact:
        """The best new contact Q for ``finger`` landing at ``t_arrive`` [s]
        (:func:`~regrasp_pin.grasp.choice.choose_new_contact`: the paper's criterion, Q
        clear of the ``others`` and, while it is held, of their fingers under
        ``q_hand``), away from ``P``, from the ``excluded`` points (object frame) and
        out of the ``reserved`` room. With ``landing`` ``(landing_s, land_by_s)``: only
        a Q whose earliest landing (``landing_s`` of its arrival configurations, e.g.
        :meth:`flight_landing`) is by ``land_by_s`` [s]. With ``frees``: only a Q with
        which the ``others`` without any one of those fingers are in force closure.
        The ``absent`` fingers (not holding) are left out of the finger-clearance test:
        they are supposed elsewhere at arrival.

        Raises:
            ContactError: no candidate (``too-late``: none that lands in time).
        """
        f, m = self.scene.hand.finger(finger), self.manifolds[finger]
        landing_s, land_by_s = landing if landing is not None else (None, math.inf)
        t_judged = judging_time(m, t_arrive)  # the others where they hold then
        return choose_new_contact(
            self.scene.hand,
            self.scene.obj,
            m,
            self.sample,
            t_arrive,
            P_object=P[0],
            n_P_object=P[1],
            others=others,
            contact=self.contact,
            mu=self.mu,
            exclude_radius_m=f.tip_radius,
            exclude_points_object=np.array(excluded) if excluded else None,
            exclude_points_radius_m=self._exclude_radius(finger),
            q_hand_arrive=q_hand(np.array([t_judged]))[0],
            finger_clearance_m=LANDING_FINGER_CLEARANCE_M,
            exit_tolerance_s=self.exit_tolerance_s,
            lasting=functools.partial(self._clear_of_others, finger, list(others), q_hand),
            reserved=reserved,
            distances=self._distances_of(finger),
            epsilons=self._screening_epsilons(),
            landing_s=landing_s,
            land_by_s=land_by_s,
            frees=frees,
            absent=absent,
        )

    def flight_landing(
        self, finger: str, q_from: np.ndarray, start: float, shortest: float, end_by: float
    ) -> tuple[Callable[[np.ndarray], np.ndarray], float]:
        """``landing`` for :meth:`choose`: a regrasp of ``finger`` from ``q_from`` [rad]
        lifting off at ``start`` [s] lands no sooner than its duration within the joint
        velocity limits allows (:func:`~.timing.duration_for_move` by the regrasps' time
        law, at least ``shortest`` [s]), and must land by ``end_by`` [s], as the search
        checks after choosing."""
        vlim = self.scene.hand.finger(finger).velocity_limit
        law = self.regrasp.time_law

        def landing_s(q_to: np.ndarray) -> np.ndarray:
            return start + durations_for_moves(
                q_from, q_to, vlim, minimum_s=shortest, dt_s=self.dt_s, law=law
            )

        return landing_s, end_by + TIME_TOL_S

    # ------------------------------------------------------------------ internals
    def _clear_of_others(
        self,
        finger: str,
        others: list[str],
        q_hand: Callable[[np.ndarray], np.ndarray],
        points: np.ndarray,
        ka: int,
        horizon: np.ndarray,
    ) -> np.ndarray:
        """``(K, C)``: the candidates ``points`` stay clear of the holding fingers (by
        the trigger distance) at the manifold's times from index ``ka`` on, measured
        over the first ``horizon[c]`` times of each (True after them).

        A candidate's column depends on it alone, given the other fingers' postures
        over those times: the columns are kept with the horizon they were measured over,
        for the last :data:`_LASTING_KEPT` ``(finger, others, manifold, ka, postures)``
        asked (the candidates of one lift-off time are ranked again after each failed
        attempt, and other lift-off times, recoveries and backtracking ask again with
        the same holds: about half of the columns asked)."""
        m = self.manifolds[finger]
        postures = q_hand(m.times_s[ka:])
        key = (finger, tuple(others), id(m), ka, postures.shape, postures.tobytes())
        entry = self._lasting.get(key)
        if entry is None or entry[0] is not m:
            entry = self._lasting[key] = (m, {})  # m kept alive: its id stays its own
            while len(self._lasting) > _LASTING_KEPT:
                self._lasting.popitem(last=False)
        self._lasting.move_to_end(key)
        known = entry[1]
        wanted = [int(i) for i in np.asarray(points).reshape(-1)]
        until = dict(zip(wanted, np.asarray(horizon, int).reshape(-1).tolist(), strict=True))
        missing = sorted({i for i in wanted if i not in known or known[i][0] < until[i]})
        if missing:
            reach = np.array([until[i] for i in missing])
            ok = clear_of_fingers(
                self.scene.hand,
                finger,
                m.q[ka:, missing],
                postures,
                others,
                self.contact.finger_trigger_m,
                horizon=reach,
            )
            known.update(zip(missing, zip(reach.tolist(), ok.T, strict=True), strict=True))
        K = m.times_s.size - ka
        return np.stack([known[i][1] for i in wanted], axis=1) if wanted else np.ones((K, 0), bool)

    def _screening_epsilons(self) -> ScreeningEpsilons:
        """The screening epsilons of contact sets, kept for the whole plan."""
        if self._epsilons is None:
            self._epsilons = ScreeningEpsilons(
                self.mu, self.scene.obj.radius_m, self.contact.torsion_m
            )
        return self._epsilons

    def _distances_of(self, finger: str) -> ManifoldClearance:
        """The finger's link-object distances on its manifold, kept for the whole plan
        (measured again for a manifold that replaced it)."""
        m = self.manifolds[finger]
        kept = self._distances.get(finger)
        if kept is None or kept.manifold is not m:
            kept = self._distances[finger] = ManifoldClearance(
                self.scene.hand, finger, self.scene.obj, m, self.contact
            )
        return kept

    def _exclude_radius(self, finger: str) -> float:
        if self.exclude_radius_m is not None:
            return self.exclude_radius_m
        return 0.5 * self.scene.hand.finger(finger).tip_radius

    def _try_candidate(
        self,
        call: _Call,
        start: float,
        q0: np.ndarray,
        excluded: list[np.ndarray],
    ) -> Found | bool | None:
        """One Q at one start time: a Found, False (Q failed, excluded) or None (no Q).

        ``call.failed`` holds the regrasps of this search that failed, by lift-off, Q,
        its arrival configuration, duration and route: one asked for again (a Q given
        up for another at a longer duration comes back as the best of the next round)
        fails as before without being planned, recorded or paid for again."""
        finger, attempts = call.finger, call.attempts
        f = self.scene.hand.finger(finger)
        where = f"start {start:.2f} s"
        try:
            call.budget.spend()
            landing = self.flight_landing(finger, q0, start, call.shortest_s, call.end_by)
            choice = self.choose(
                finger,
                call.P,
                start + call.shortest_s,
                call.others,
                call.q_hand,
                excluded,
                call.reserved,
                landing,
                call.frees,
            )
        except ContactError as exc:
            attempts.append(exc.as_attempt(where))
            return None
        chosen_for = call.shortest_s
        law = self.regrasp.time_law
        duration = duration_for_move(
            q0, choice.q_arrive, f.velocity_limit, minimum_s=chosen_for, dt_s=self.dt_s, law=law
        )
        speeds: list[tuple[float, float]] = []  # (duration, peak speed / limit) of this Q
        stretches, route = 0, "auto"
        while True:
            what = _what(where, choice, duration, route)
            if start + duration > call.end_by + TIME_TOL_S:
                attempts.append(
                    Attempt(
                        FailureKind.TOO_LATE,
                        finger,
                        start,
                        measured=start + duration,
                        required=call.end_by,
                        what=what,
                    )
                )
                break
            if duration > chosen_for + TIME_TOL_S:
                # Q was chosen for an earlier arrival: the arrival time may prefer another
                chosen_for = duration
                try:
                    call.budget.spend()
                    again = self.choose(
                        finger,
                        call.P,
                        start + duration,
                        call.others,
                        call.q_hand,
                        excluded,
                        call.reserved,
                        landing,
                        call.frees,
                    )
                except ContactError as exc:
                    attempts.append(exc.as_attempt(what))
                    break
                if not np.array_equal(again.p_object, choice.p_object):
                    speeds.clear()  # another Q: another path
                choice = again
                what = _what(where, choice, duration, route)
            try:
                result = self._plan_once(call, start, choice, q0, duration, route, what)
            except PlanningError as exc:
                retry = self._after_velocity(
                    exc, speeds, duration, start, call.end_by, stretches, route
                )
                if retry is None:
                    break
                duration, stretches, route = retry
                continue
            rejected = None if call.landing_check is None else call.landing_check(result)
            if rejected is not None:
                attempts.append(rejected)
                break
            return Found(result, choice, tuple(attempts))
        excluded.append(choice.p_object)
        return False

    def _plan_once(
        self,
        call: _Call,
        start: float,
        choice: NewContact,
        q0: np.ndarray,
        duration: float,
        route: str,
        what: str,
    ) -> RegraspResult:
        """:func:`~.regrasp.plan_regrasp` of ``choice`` at ``duration`` by ``route``; a
        failure is recorded in ``call.attempts`` and ``call.failed``, and one already in
        ``call.failed`` is raised again at no cost. A regrasp this plan's searches
        planned before, input for input (:meth:`_planned_key`), is not planned again."""
        finger, failed = call.finger, call.failed
        key = (round(start, 9), choice.index, choice.q_arrive.tobytes(), round(duration, 9), route)
        if key in failed:
            raise failed[key]
        call.budget.spend()
        params = replace(self.regrasp, duration_s=duration)
        try:
            out = self._plan_regrasp(call, start, choice, q0, params, route)
            if isinstance(out, PlanningError):
                # raised as it was first: without the frames of any raise since
                raise out.with_traceback(None)
            return out
        except PlanningError as exc:
            failed[key] = exc
            call.attempts.append(exc.as_attempt(what))
            log.debug("regrasp %s: %s", finger, exc)
            raise

    def _plan_regrasp(
        self,
        call: _Call,
        start: float,
        choice: NewContact,
        q0: np.ndarray,
        params: RegraspParams,
        route: str,
    ) -> RegraspResult | PlanningError:
        """:func:`~.regrasp.plan_regrasp`'s verified regrasp or its failure: the one kept
        if this plan's searches planned it before (:meth:`_planned_key`), else planned
        and kept (the most recent :data:`_PLANNED_KEPT`)."""
        shared = self._planned_key(call, start, choice, q0, params, route)
        if shared is not None and shared in self._planned:
            self._planned.move_to_end(shared)  # the most recently used last
            return self._planned[shared]
        try:
            out: RegraspResult | PlanningError = plan_regrasp(
                self.scene.hand,
                self.scene.obj,
                self.scene.motion,
                call.finger,
                start,
                call.P[0],
                call.P[1],
                choice.p_object,
                choice.n_object,
                q0,
                call.q_hand,
                others_tips_object=call.others_tips,
                params=params,
                q_land=choice.q_arrive,
                route=route,
            )
        except PlanningError as exc:
            out = exc
        if shared is not None:
            self._planned[shared] = out
            while len(self._planned) > _PLANNED_KEPT:
                self._planned.popitem(last=False)
        return out

    @staticmethod
    def _planned_key(
        call: _Call,
        start: float,
        choice: NewContact,
        q0: np.ndarray,
        params: RegraspParams,
        route: str,
    ) -> bytes | None:
        """The digest of everything a regrasp of this plan follows from: the finger, its
        lift-off time, P and Q, its start and landing configurations, the other
        fingers' tips and motion (a :class:`~.state.HandMotion`'s key), the parameters
        and the route; None when the other fingers' motion has no key."""
        hand_key = getattr(call.q_hand, "key", None)
        if not isinstance(hand_key, bytes):
            return None
        digest = hashlib.sha1(f"{call.finger}\0{start!r}\0{route}\0{params!r}".encode())
        digest.update(hand_key)
        for a in (
            call.P[0], call.P[1], choice.p_object, choice.n_object, q0, choice.q_arrive,
            call.others_tips,
        ):  # fmt: skip
            digest.update(np.ascontiguousarray(a, float).tobytes())
        return digest.digest()

    def _after_velocity(
        self,
        exc: PlanningError,
        speeds: list[tuple[float, float]],
        duration: float,
        start: float,
        end_by: float,
        stretches: int,
        route: str,
    ) -> tuple[float, int, str] | None:
        """What to try after a regrasp of one Q at ``duration`` failed with ``exc``:
        ``(duration, stretches so far, route)``, or None (the next Q).

        After a velocity failure (its speed appended to ``speeds``): a longer duration
        (:func:`~.timing.next_duration`) if stretches are left and it lands by
        ``end_by``; else, once, the joint-space fallback at the same duration (a
        velocity failure of the surface path skips it, for a longer duration first).
        """
        if exc.kind != FailureKind.VELOCITY or exc.measured is None or not exc.required:
            return None
        speeds.append((duration, exc.measured / exc.required))
        longer = next_duration(speeds, dt_s=self.dt_s)
        if (
            longer is not None
            and stretches < self.stretches
            and start + longer <= end_by + TIME_TOL_S
        ):
            return longer, stretches + 1, route
        if route == "auto":
            speeds.clear()  # another route: another path
            return duration, stretches, "joint-space"
        return None

    def _fail(
        self, finger: str, starts: list[float], attempts: list[Attempt], *, budget: bool
    ) -> Found:
        kind = FailureKind.BUDGET if budget else dominant_kind(attempts, FailureKind.NO_CANDIDATE)
        # the numbers: for distances the attempt nearest to passing (the message's),
        # else the last attempt of that kind
        last = nearest_miss(attempts, kind) or next(
            (a for a in reversed(attempts) if a.kind == kind), None
        )
        when = starts[0] if starts else None
        span = (
            f"lift-off {starts[0]:.2f}-{max(starts):.2f} s" if starts else "no lift-off time left"
        )
        raise PlanningError(
            f"no verified regrasp ({span}): "
            + ("the search budget ran out; " if budget else "")
            + failure_summary(attempts, kind),
            finger=finger,
            time_s=when,
            kind=kind,
            measured=None if last is None else last.measured,
            required=None if last is None else last.required,
            attempts=attempts,
            other=None if last is None else last.other,
        )


def _what(where: str, choice: NewContact, duration: float, route: str) -> str:
    """An attempt's description: its lift-off, Q, duration [s], and its route when it
    is not the first one tried."""
    what = f"{where}, Q={np.round(choice.p_object, 4).tolist()}, {duration:.2f} s"
    return what + (f" ({route})" if route != "auto" else "")
