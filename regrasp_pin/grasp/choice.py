"""Choosing the new contact Q (the paper's conditions (a) and (b)) and the initial grasp.

Condition (a): Q lies inside the boundary planes (and is feasible) at the time the
finger can arrive, ``t_arrive`` = trigger time + regrasp duration (between two
manifold times, at both: the pad may turn away between them). Condition (b): among
those, Q stays inside longest over the rest of the motion (read from
``Manifold.holdable``: inside the limits, pad facing, and the fingertip link not
reaching past the plane the tip rests on). Ties are broken by the
larger joint margin at arrival, then by the shorter distance from P.

Beyond the paper, the grasp must keep holding: Q must be at least ``min_separation_m``
from the other fingers' contacts, the other contacts plus Q must be in force closure,
and Q should keep or improve the grasp quality (Ferrari-Canny epsilon) that P gave
with the others. Candidates are taken in the order of (b) and tested (and a Coal check
that no other link of the finger touches the object at arrival); among the first four
that pass, Q is the one after which most other fingers could let go with the rest in
force closure (so that a finger that must regrasp later can), then one that keeps the
quality, then the first; the result says whether the quality was kept.

"Distance from P" is the straight-line distance in the object frame (a lower bound of
the surface distance; it is only a tie-breaker).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, replace

import numpy as np

from ..exceptions import ContactError, FailureKind, InputError
from ..model.clearance import FingerClearance, LinkClearance
from ..model.hand import Finger, Hand
from ..model.objects import ConvexObject, SurfaceSample
from .contact import ContactModel
from .manifold import Manifold
from .necessity import MustHold
from .quality import FORCE_CLOSURE_TOL, ferrari_canny_epsilon, kept_quality

__all__ = [
    "Grasp",
    "NewContact",
    "choose_new_contact",
    "exit_times",
    "initial_grasp",
]

SCREEN_EDGES = 6  # friction-cone edges used when screening candidates
#: grasp scores within this relative tolerance tie (the first found is kept): scores
#: sum epsilons whose last bits follow the rounding of the hull computation
SCORE_RTOL = 1e-9
#: initial_grasp measures finger gaps over the first this many seconds [s]
GAP_HORIZON_S = 1.0
_REMOVABLE_WINDOW = 4  # passing candidates compared by how many fingers could let go
_LINK_BATCH = 64  # candidates whose link clearance is measured at once (Coal)


@dataclass(frozen=True)
class NewContact:
    """The chosen new contact Q.

    Attributes:
        finger: Finger name.
        index: Index of Q in the surface sample.
        p_object: Q, object frame ``(3,)`` [m].
        n_object: Outward normal at Q, object frame ``(3,)``.
        q_arrive: ``(k,)`` finger configuration at arrival [rad].
        t_arrive_s: Arrival time [s].
        exit_time_s: First grid time after arrival at which Q stops being usable (the
            motion's end if never) [s].
        margin_rad: Joint margin at arrival [rad].
        distance_from_P_m: Straight distance from P [m].
        epsilon: Ferrari-Canny epsilon of the other contacts plus Q.
        epsilon_with_P: Epsilon of the other contacts plus P (the quality to keep).
        quality_kept: Whether ``epsilon >= epsilon_with_P``.
        n_candidates: Number of candidates that satisfied condition (a).
        rank: Position of Q in the order of condition (b) (0 = the paper's choice).
    """

    finger: str
    index: int
    p_object: np.ndarray
    n_object: np.ndarray
    q_arrive: np.ndarray
    t_arrive_s: float
    exit_time_s: float
    margin_rad: float
    distance_from_P_m: float
    epsilon: float
    epsilon_with_P: float
    quality_kept: bool
    n_candidates: int
    rank: int


def exit_times(usable: np.ndarray, times_s: np.ndarray, start: int) -> np.ndarray:
    """First time at or after grid index ``start`` at which each point is not usable.

    Args:
        usable: ``(T, N)`` boolean.
        times_s: ``(T,)`` grid times [s].
        start: Grid index to start from.

    Returns:
        ``(N,)`` exit times [s]; ``times_s[-1]`` for points usable to the end, and
        ``times_s[start]`` for points not usable at ``start``.
    """
    tail = usable[start:]
    never_leaves = tail.all(axis=0)
    first_bad = np.argmin(tail, axis=0)  # index of the first False
    out = times_s[start + first_bad]
    out[never_leaves] = times_s[-1]
    return out


def choose_new_contact(
    hand: Hand,
    obj: ConvexObject,
    manifold: Manifold,
    sample: SurfaceSample,
    t_arrive_s: float,
    *,
    P_object: np.ndarray,
    n_P_object: np.ndarray,
    others: Mapping[str, tuple[np.ndarray, np.ndarray]],
    contact: ContactModel | None = None,
    mu: float = 0.8,
    min_separation_m: float | None = None,
    link_check: bool = True,
    max_checks: int = 60,
    exclude_radius_m: float = 0.0,
    exclude_points_object: np.ndarray | None = None,
    exclude_points_radius_m: float | None = None,
    q_hand_arrive: np.ndarray | None = None,
    finger_clearance_m: float = 0.002,
    exit_tolerance_s: float = 0.0,
    rerank: int = 12,
    lasting: Callable[[np.ndarray, int], np.ndarray] | None = None,
    reserved: Sequence[tuple[np.ndarray, float]] = (),
) -> NewContact:
    """Choose Q for ``manifold.finger`` (see the module docstring).

    Args:
        hand: The hand.
        obj: The object.
        manifold: The finger's manifold over times that reach the end of the motion.
        sample: The surface sample the manifold was built on.
        t_arrive_s: When the finger can land [s].
        P_object: The contact being released, object frame ``(3,)`` [m].
        n_P_object: Its outward normal.
        others: The contacts that keep holding: finger -> (point, outward normal),
            object frame.
        contact: Contact model (margin for condition (a), link clearance).
        mu: Friction coefficient for the grasp-quality test.
        min_separation_m: Smallest distance from the other contacts [m]; default
            ``2 * tip_radius + 1 mm``.
        link_check: Check with Coal that no other link of the finger touches the
            object at arrival.
        max_checks: Most candidates given the (slower) quality and finger-clearance
            tests, among those whose links clear the object at arrival (tested in
            batches, in the order of the ranking, until enough pass).
        exclude_radius_m: Candidates closer than this to P (and to each of
            ``exclude_points_object``) are ignored [m].
        exclude_points_object: ``(E, 3)`` points to stay away from (e.g. contacts
            for which no verified path was found).
        exclude_points_radius_m: Radius around each of ``exclude_points_object``
            [m]; default ``exclude_radius_m``.
        q_hand_arrive: ``(nq,)`` hand configuration at arrival (the other fingers
            holding); when given, Q must put the finger at least ``finger_clearance_m``
            from the other fingers (Coal).
        finger_clearance_m: See ``q_hand_arrive`` [m].
        exit_tolerance_s: With a positive value, exit times that differ by less than
            this are ties, broken by the shorter distance from P and then the margin
            (instead of the margin first). 0 keeps the paper's order exactly.
        rerank: How many of the first candidates get their exit times cut by what the
            manifold does not model (the finger's other links, ``lasting``) and are
            ranked again.
        lasting: Optional ``(points (C,), ka) -> (K, C)`` bool over the manifold's times
            from index ``ka`` on: False where something else ends the contact (e.g.
            another holding finger comes too near); applied in the re-rank.
        reserved: ``(point, radius)`` pairs, object frame [m]: room kept free for
            another finger's landing; candidates closer than the radius to the point
            are ignored.

    Returns:
        The :class:`NewContact`.

    Raises:
        ContactError: no candidate satisfies condition (a), or none keeps the other
            fingers' grasp in force closure; the message says which finger, when, why.
        InputError: ``t_arrive_s`` is NaN or outside the manifold's times.
    """
    contact = contact or ContactModel()
    finger = hand.finger(manifold.finger)
    sep = 2 * finger.tip_radius + 0.001 if min_separation_m is None else min_separation_m
    ka, kb = _arrival_indices(manifold, t_arrive_s)
    usable = manifold.usable(contact.limit_margin_rad)
    choice = manifold.usable(contact.choice_margin_rad)
    # the landing falls between two manifold times: Q must be usable at both
    cand = choice[ka] & choice[min(kb, ka)]
    pts = sample.points
    cand &= _far_from(pts, [p for p, _ in others.values()], sep)
    if exclude_radius_m > 0:
        cand &= _far_from(pts, [P_object], exclude_radius_m)
    if exclude_points_object is not None:
        r_ex = exclude_radius_m if exclude_points_radius_m is None else exclude_points_radius_m
        ex = np.asarray(exclude_points_object, float).reshape(-1, 3)
        cand &= _far_from(pts, list(ex), max(r_ex, 1e-12))
    for point, radius in reserved:
        cand &= _far_from(pts, [np.asarray(point, float)], float(radius))
    idx = np.flatnonzero(cand)
    if idx.size == 0:
        raise ContactError(
            f"no surface point is inside the joint limits (margin >= "
            f"{contact.choice_margin_rad:.2f} rad), faces the pad and is clear of the other "
            f"contacts at arrival ({int(usable[ka].sum())} usable before the separation test)",
            finger=finger.name,
            time_s=float(manifold.times_s[ka]),
            kind=FailureKind.NO_CANDIDATE,
            measured=float(usable[ka].sum()),
            required=1.0,
        )
    # condition (b) read from the contacts the finger can hold: inside the limits and,
    # as far as the fingertip link's shape tells, without it sinking into the face
    holdable = manifold.holdable(contact.limit_margin_rad)
    ranked = _Ranking(
        t_exit=exit_times(holdable[:, idx], manifold.times_s, ka),
        margin=manifold.margin_rad[ka, idx],
        dist=np.linalg.norm(pts[idx] - P_object, axis=1),
        idx=idx,
        exit_tolerance_s=exit_tolerance_s,
    )
    lasts = holdable[-1, idx].copy()
    order = ranked.order(lasts)
    if link_check and rerank > 0:
        # the manifold knows nothing of the finger's other links: the first candidates'
        # exit times are cut where a link would come within the trigger distance of the
        # object (Coal, at the manifold's times), and those candidates ranked again
        top = order[:rerank]
        t_exit, lasts = ranked.t_exit.copy(), lasts.copy()
        t_exit[top], last = _link_exit(
            hand, finger.name, obj, manifold, idx[top], ka, contact, lasting
        )
        lasts[top] &= last
        ranked = replace(ranked, t_exit=t_exit)
        head = ranked.order(lasts)
        order = np.concatenate([head[np.isin(head, top)], order[rerank:]])
    screen = _Screen(
        hand,
        finger,
        obj,
        manifold,
        sample,
        ka,
        others,
        mu,
        _ObjectClearance(hand, finger.name, obj, contact) if link_check else None,
        q_hand_arrive,
        finger_clearance_m,
    )
    return screen.first(order, ranked, P_object, n_P_object, max_checks)


def _arrival_indices(manifold: Manifold, t_arrive_s: float) -> tuple[int, int]:
    """The manifold's time indices around a landing at ``t_arrive_s`` [s]: the first
    time at or after it and the last time at or before it (raises InputError outside)."""
    t_arrive = float(t_arrive_s)
    t0, t1 = float(manifold.times_s[0]), float(manifold.times_s[-1])
    if not t0 - 1e-9 <= t_arrive <= t1 + 1e-9:  # also rejects NaN
        raise InputError(
            "t_arrive_s",
            f"{t_arrive_s!r} is outside the manifold's times",
            f"a time in [{t0:.6g}, {t1:.6g}] s",
        )
    ka = manifold.time_index(t_arrive)
    kb = max(int(np.searchsorted(manifold.times_s, t_arrive + 1e-9)) - 1, 0)
    return ka, kb


def _far_from(pts: np.ndarray, centres: list[np.ndarray], radius_m: float) -> np.ndarray:
    """``(N,)`` True where a point is at least ``radius_m`` from every centre."""
    ok = np.ones(pts.shape[0], bool)
    for c in centres:
        ok &= np.linalg.norm(pts - c, axis=1) >= radius_m
    return ok


@dataclass(frozen=True)
class _Ranking:
    """The candidates' keys (exit time, margin, distance from P; ``idx``: their sample
    indices) and the order they give."""

    t_exit: np.ndarray
    margin: np.ndarray
    dist: np.ndarray
    idx: np.ndarray
    exit_tolerance_s: float

    def order(self, lasts: np.ndarray) -> np.ndarray:
        """Candidate positions, best first (``lasts``: usable to the end)."""
        # the order must not follow last-bit noise of the IK: keys on a 1e-9 lattice
        t_exit = self.t_exit
        margin_key, dist_key = np.round(self.margin, 9), np.round(self.dist, 9)
        if self.exit_tolerance_s > 0:
            # exit times within the tolerance of each other count as ties; among them the
            # shorter move first (a short move is less likely to cross another finger)
            # (on the 1e-9 lattice too: grid times carry float noise, e.g. 4.800000000000001,
            # and a ratio of exactly 2.0 must not fall into bin 1 or 2 by one ulp)
            bins = np.floor(np.round((t_exit.max() - t_exit) / self.exit_tolerance_s, 9))
            return np.lexsort((self.idx, -margin_key, dist_key, bins))
        # (b), then margin, then distance; a point usable to the end outlasts one that
        # leaves at the last grid time (both have exit time times_s[-1])
        return np.lexsort((self.idx, dist_key, -margin_key, ~lasts, -t_exit))


class _Screen:
    """The slower tests of a ranked candidate: force closure with the other contacts,
    the finger's links clear of the object and of the other fingers at arrival."""

    def __init__(
        self,
        hand: Hand,
        finger: Finger,
        obj: ConvexObject,
        manifold: Manifold,
        sample: SurfaceSample,
        ka: int,
        others: Mapping[str, tuple[np.ndarray, np.ndarray]],
        mu: float,
        link_clear: _ObjectClearance | None,
        q_hand_arrive: np.ndarray | None,
        finger_clearance_m: float,
    ) -> None:
        self.hand, self.finger, self.manifold, self.sample = hand, finger, manifold, sample
        self.ka = ka
        self.other_p = np.array([p for p, _ in others.values()]).reshape(-1, 3)
        self.other_n = np.array([n for _, n in others.values()]).reshape(-1, 3)
        self.mu, self.scale = mu, obj.radius_m
        self.link_clear = link_clear
        self.q_hand_arrive = q_hand_arrive
        self.finger_clear = (
            FingerClearance(hand, finger.name) if q_hand_arrive is not None else None
        )
        self.finger_clearance_m = finger_clearance_m
        self.rejected = {"force closure": 0, "link clearance": 0, "finger clearance": 0}
        self.window = _REMOVABLE_WINDOW

    def eps(self, p: np.ndarray, n: np.ndarray) -> float:
        """Ferrari-Canny epsilon of the other contacts and ``(p, n)``."""
        return ferrari_canny_epsilon(
            np.vstack([self.other_p, p[None]]),
            np.vstack([self.other_n, n[None]]),
            self.mu,
            n_edges=SCREEN_EDGES,
            torque_scale_m=self.scale,
        )

    def links_clear(self, points: np.ndarray) -> np.ndarray:
        """``(C,)`` bool: the finger at the sample ``points`` keeps its links clear of the
        object at arrival (all True without the test)."""
        if self.link_clear is None:
            return np.ones(points.size, bool)
        q_full = self.hand.to_full(self.finger.name, self.manifold.q[self.ka, points])
        return self.link_clear(q_full, self.manifold.T_palm_object[self.ka])

    def rejection(self, i: int, e: float) -> str | None:
        """Why sample point ``i`` (epsilon ``e`` with the others; its links already
        clear of the object) is refused, or None."""
        if e <= FORCE_CLOSURE_TOL:
            return "force closure"
        q_i = self.manifold.q[self.ka, i]
        if self.finger_clear is not None:
            q_all = np.array(self.q_hand_arrive, float)
            q_all[self.finger.q_indices] = q_i
            if self.finger_clear(q_all) < self.finger_clearance_m:
                return "finger clearance"
        return None

    def removable(self, p: np.ndarray, n: np.ndarray) -> int:
        """How many of the other contacts could let go, with ``(p, n)`` landed, the rest
        staying in force closure."""
        k = self.other_p.shape[0]
        if k < 3:
            return 0
        loo = _leave_one_out(
            np.vstack([self.other_p, p[None]]),
            np.vstack([self.other_n, n[None]]),
            self.mu,
            self.scale,
            range(k),
        )
        return sum(e > FORCE_CLOSURE_TOL for e in loo)

    def first(
        self,
        order: np.ndarray,
        ranked: _Ranking,
        P_object: np.ndarray,
        n_P_object: np.ndarray,
        max_checks: int,
    ) -> NewContact:
        """Among the first ``self.window`` candidates in ``order`` that pass, the one
        after which most other fingers could let go, then the first that keeps the grasp
        quality of P, then the first; ContactError (the most frequent rejection) if none
        passes.

        The link clearance is tested first, in batches of ``_LINK_BATCH`` candidates in
        order (Coal); at most ``max_checks`` candidates whose links clear the object get
        the slower tests."""
        pts, normals, idx = self.sample.points, self.sample.normals, ranked.idx
        eps_P = self.eps(np.asarray(P_object, float), np.asarray(n_P_object, float))
        passing: list[tuple[int, bool, int, NewContact]] = []
        best_removable = self.other_p.shape[0] if self.other_p.shape[0] >= 3 else 0
        clear = np.zeros(order.size, bool)
        screened = 0
        for position, j in enumerate(order):
            if screened >= max_checks:
                break
            if position % _LINK_BATCH == 0:
                batch = order[position : position + _LINK_BATCH]
                clear[position : position + batch.size] = self.links_clear(idx[batch])
            if not clear[position]:
                self.rejected["link clearance"] += 1
                continue
            screened += 1
            i = int(idx[j])
            e = self.eps(pts[i], normals[i])
            why = self.rejection(i, e)
            if why is not None:
                self.rejected[why] += 1
                continue
            result = NewContact(
                finger=self.finger.name,
                index=i,
                p_object=pts[i].copy(),
                n_object=normals[i].copy(),
                q_arrive=self.manifold.q[self.ka, i].copy(),
                t_arrive_s=float(self.manifold.times_s[self.ka]),
                exit_time_s=float(ranked.t_exit[j]),
                margin_rad=float(ranked.margin[j]),
                distance_from_P_m=float(ranked.dist[j]),
                epsilon=float(e),
                epsilon_with_P=float(eps_P),
                quality_kept=kept_quality(e, eps_P),
                n_candidates=int(idx.size),
                rank=position,
            )
            r = self.removable(pts[i], normals[i]) if self.window > 1 else 0
            passing.append((r, result.quality_kept, -position, result))
            if (r == best_removable and result.quality_kept) or len(passing) >= self.window:
                break
        if passing:
            return max(passing, key=lambda c: c[:3])[3]
        raise self.failure(screened + self.rejected["link clearance"], idx.size)

    def failure(self, checked: int, n_candidates: int) -> ContactError:
        """The error when none of ``checked`` candidates passes."""
        rejected = self.rejected
        why = ", ".join(f"{n} {k}" for k, n in rejected.items() if n)
        main = max(rejected, key=lambda k: rejected[k])  # dict order breaks ties
        return ContactError(
            f"none of the {checked} best candidates (of {n_candidates}) passes "
            f"(rejected for: {why})",
            finger=self.finger.name,
            time_s=float(self.manifold.times_s[self.ka]),
            kind={
                "force closure": FailureKind.FORCE_CLOSURE,
                "link clearance": FailureKind.OBJECT_CLEARANCE,
                "finger clearance": FailureKind.FINGER_COLLISION,
            }[main],
            measured=float(rejected[main]),
            required=0.0,
        )


@dataclass(frozen=True)
class Grasp:
    """One contact per finger.

    Attributes:
        points_object: finger -> contact point, object frame ``(3,)`` [m].
        normals_object: finger -> outward normal, object frame ``(3,)``.
        q: finger -> ``(k,)`` configuration at the grasp time [rad].
        indices: finger -> index in the surface sample.
        epsilon: Ferrari-Canny epsilon of all contacts.
    """

    points_object: dict[str, np.ndarray]
    normals_object: dict[str, np.ndarray]
    q: dict[str, np.ndarray]
    indices: dict[str, int]
    epsilon: float


def _start_candidates(
    hand: Hand,
    obj: ConvexObject,
    man: Manifold,
    pts: np.ndarray,
    t_index: int,
    contact: ContactModel,
    max_candidates: int,
    hold: MustHold | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """One finger's candidate contacts at ``t_index`` for :func:`initial_grasp`: their
    sample indices and lasting fractions, the longest-lasting first, spread over the
    surface (two tip radii apart first, then one), links clear of the object; only
    those that last through ``hold`` (a run from the start in which the finger cannot
    let go) if it is given: inside the joint limits and, held there, with the finger's
    other links clear of the object and its fingertip link not sinking in at every
    manifold time of the run (as the tracking will measure; :func:`_link_ok`)."""
    name = man.finger
    finger = hand.finger(name)
    usable = man.usable(contact.limit_margin_rad)
    idx = np.flatnonzero(man.usable(contact.choice_margin_rad)[t_index])
    if idx.size == 0:
        raise ContactError(
            "no usable contact at the start (inside the limits with margin, pad facing)",
            finger=name,
            time_s=float(man.times_s[t_index]),
        )
    if hold is not None:
        if not hold.lasting[idx].any():
            raise _cannot_hold(man, hold, idx, t_index, contact)
        # what the planner needs: the trigger margin, up to the next grid time (the
        # run may end anywhere before it); what is proven: margin >= 0 over the run
        k_end = min(hold.k_to + 1, man.times_s.size - 1)
        needed = np.asarray(usable[t_index : k_end + 1].all(axis=0))
        idx = idx[needed[idx]] if needed[idx].any() else idx[hold.lasting[idx]]
    last = exit_times(usable[:, idx], man.times_s, t_index)
    frac = (last - man.times_s[t_index]) / max(man.times_s[-1] - man.times_s[t_index], 1e-9)
    order = np.lexsort((-man.margin_rad[t_index, idx], -frac))
    clear = _ObjectClearance(hand, name, obj, contact)
    q_rows = hand.to_full(name, man.q[t_index, idx])
    T0 = man.T_palm_object[t_index]

    def link_clear(j: int) -> bool:
        # clear of the object at the start and, for a finger that cannot let go, for
        # as long as it must hold: its other links and fingertip link as the tracking
        # will see them (the manifold knows nothing of them)
        if not clear(q_rows[j : j + 1], T0)[0]:
            return False
        if hold is None:
            return True
        ok = _link_ok(hand, name, obj, man, idx[j : j + 1], t_index, contact)[:, 0]
        return bool(ok[: hold.k_to - t_index + 1].all())

    chosen = _spread_out(
        pts[idx],
        order,
        (2 * finger.tip_radius, finger.tip_radius),
        max_candidates,
        link_clear,
    )
    if not chosen:
        lasting = "" if hold is None else f" that lasts until t={hold.t_to_s:.3f} s"
        raise ContactError(
            f"every usable contact{lasting} makes a link touch the object", finger=name
        )
    return idx[chosen], frac[chosen]


def _cannot_hold(
    man: Manifold, hold: MustHold, idx: np.ndarray, t_index: int, contact: ContactModel
) -> ContactError:
    """The error of a finger none of whose starting candidates ``idx`` lasts through
    ``hold``: INFEASIBLE if no contact at all does (with how long the longest-lasting
    one holds), NO_CANDIDATE if some do but lack the choice margin at the start."""
    t0 = float(man.times_s[t_index])
    head = (
        f"it cannot let go until t={hold.t_to_s:.3f} s (until then no grasp without it is in "
        f"force closure), but "
    )
    if hold.possible:
        return ContactError(
            head + f"its contacts that last that long are within "
            f"{contact.choice_margin_rad:.2f} rad of a joint limit at the start",
            finger=man.finger,
            time_s=t0,
            kind=FailureKind.NO_CANDIDATE,
            measured=float(hold.lasting.sum()),
            required=1.0,
        )
    usable = man.usable(0.0)
    last = exit_times(usable[:, usable[t_index]], man.times_s, t_index)
    t_last = float(last.max()) if last.size else t0
    return ContactError(
        head + "none of its contacts stays within its joint limits that long "
        f"(the longest until t={t_last:.3f} s)",
        finger=man.finger,
        time_s=t0,
        kind=FailureKind.INFEASIBLE,
        measured=t_last - t0,
        required=hold.t_to_s - t0,
    )


class _ScreeningEpsilons:
    """The screening epsilon (:data:`SCREEN_EDGES` edges, a fixed torque scale) of
    contact sets, each set computed once: a pure function of the contacts in their
    order (the same bits in, the same hull out), which the grasp search asks for again
    and again (a combination found by several trials, a leave-one-out set shared by
    combinations that differ in the left-out finger)."""

    def __init__(self, mu: float, scale_m: float) -> None:
        self.mu = mu
        self.scale_m = scale_m
        self._known: dict[tuple[bytes, bytes], float] = {}

    def __call__(self, p: np.ndarray, n: np.ndarray) -> float:
        key = (np.ascontiguousarray(p).tobytes(), np.ascontiguousarray(n).tobytes())
        if key not in self._known:
            self._known[key] = ferrari_canny_epsilon(
                p, n, self.mu, n_edges=SCREEN_EDGES, torque_scale_m=self.scale_m
            )
        return self._known[key]


def _leave_one_out(
    p: np.ndarray,
    n: np.ndarray,
    mu: float,
    scale_m: float,
    rows: Iterable[int],
    epsilons: _ScreeningEpsilons | None = None,
) -> list[float]:
    """The screening epsilon of contacts ``p``, ``n`` ``(F, 3)`` with each of ``rows``
    left out in turn (> 0: the others hold without it); from ``epsilons`` if given."""
    eps = epsilons or _ScreeningEpsilons(mu, scale_m)
    return [eps(np.delete(p, j, 0), np.delete(n, j, 0)) for j in rows]


def _grasp_score(
    p: np.ndarray,
    n: np.ndarray,
    fracs: list[float],
    mu: float,
    scale_m: float,
    epsilons: _ScreeningEpsilons | None = None,
) -> tuple[float, float] | None:
    """``(score, epsilon)`` of a combination of contacts ``p``, ``n`` ``(F, 3)`` whose
    lasting fractions are ``fracs``; None if it is not in force closure. The score
    counts first the fingers that can let go with the rest still in force closure (so
    that fingers can regrasp later, with four fingers or more), then the smallest of
    those leave-one-out epsilons, twice the shortest lasting fraction, the mean one and
    the epsilon. Epsilons come from ``epsilons`` if given (the same values)."""
    eps = epsilons or _ScreeningEpsilons(mu, scale_m)
    e = eps(p, n)
    if e <= FORCE_CLOSURE_TOL:
        return None
    F = p.shape[0]
    loo = _leave_one_out(p, n, mu, scale_m, range(F), eps) if F > 3 else []
    removable = [x for x in loo if x > FORCE_CLOSURE_TOL]
    score = (
        len(removable)
        + (min(removable) / (min(removable) + 0.05) if removable else 0.0)
        + 2.0 * min(fracs)
        + sum(fracs) / F
        + e / (e + 0.05)
    )
    return score, e


def initial_grasp(
    hand: Hand,
    obj: ConvexObject,
    manifolds: Mapping[str, Manifold],
    sample: SurfaceSample,
    *,
    t_index: int = 0,
    contact: ContactModel | None = None,
    mu: float = 0.8,
    min_separation_m: float | None = None,
    candidates_per_finger: int = 40,
    trials: int = 80,
    seed: int = 0,
    finger_clearance: Callable[[dict[str, np.ndarray]], float] | None = None,
    min_finger_gap_m: float | None = None,
    gap_horizon_s: float = GAP_HORIZON_S,
    must_hold: Sequence[MustHold] = (),
    rank: Callable[[Mapping[str, int]], tuple[int, ...]] | None = None,
) -> Grasp:
    """Pick one feasible contact per finger: good joint margins, long-lasting, force closure.

    Each finger's candidates are its usable points at ``t_index`` (margin >=
    ``contact.limit_margin_rad``, pad facing, links clear), ranked by how long they stay
    usable and then by margin; up to ``candidates_per_finger`` of them are kept, first
    two tip radii apart (covering the surface), then one radius apart (filling in). Each
    of ``trials`` seeded trials (the first greedy, the others with the fingers shuffled
    and the rankings perturbed) searches depth first, with forward checking, for a
    combination whose contacts are ``min_separation_m`` apart and whose fingers are
    ``min_finger_gap_m`` apart (Coal, pairwise, at up to 5 of the manifolds' times over
    the first ``gap_horizon_s`` [s]; default ``contact.finger_trigger_m`` + 0.5 mm, so
    that no two fingers start close enough to trigger a regrasp; idle fingers are parked
    later and not checked). Among the force-closure combinations found, the one kept
    maximizes first the number of fingers that can let go with the others still in force
    closure (so that fingers can regrasp later), then twice the shortest lasting
    fraction, the smallest of those leave-one-out epsilons, the mean lasting fraction
    and the epsilon.
    ``finger_clearance`` (optional) maps the fingers' configurations to a further
    distance [m]; a grasp where it is <= 0 is refused. ``must_hold`` (from
    :func:`~regrasp_pin.grasp.necessity.must_hold`) keeps, for a finger that cannot let
    go from ``t_index`` on, only the contacts that last through that run: inside its
    joint limits, and with its other links and fingertip link clear of the object as
    the tracking measures them (Coal, at the manifolds' times).
    ``rank`` (optional) maps a combination (finger -> sample index) to integers that
    are compared (in order) before the score: the combination kept has the highest rank, and the
    highest score among those (such as the fingers' room to regrasp,
    :func:`~regrasp_pin.placing.regrasp_room`); the best combination found is then
    improved by changing one finger's contact at a time (fingers and candidates in
    their fixed order, the first change to a higher rank, or to the same rank and a
    higher score, taken) until no change improves it.

    Raises:
        ContactError: a finger has no usable contact (kind ``infeasible`` when none
            lasts through its ``must_hold`` run), or no combination is in force
            closure.
    """
    contact = contact or ContactModel()
    rng = np.random.default_rng(seed)
    names = list(manifolds)
    # finger gaps at a few times over the first ``gap_horizon_s``: two fingers that
    # start apart but close in at once would trigger a regrasp right away
    times = manifolds[names[0]].times_s
    soon = np.flatnonzero(
        (times >= times[t_index] - 1e-9) & (times <= times[t_index] + gap_horizon_s + 1e-9)
    )
    ks = soon[:: max(1, -(-soon.size // 5))]
    gap = _PairGaps(hand, {n: manifolds[n].q[ks] for n in names})
    pts, nrm = sample.points, sample.normals
    hold = {r.finger: r for r in must_hold if r.k_from <= t_index <= r.k_to}
    per_finger = {
        name: _start_candidates(
            hand, obj, manifolds[name], pts, t_index, contact, candidates_per_finger, hold.get(name)
        )
        for name in names
    }

    sep_default = 2 * max(hand.finger(n).tip_radius for n in names) + 0.001
    sep = sep_default if min_separation_m is None else min_separation_m
    best = None
    best_score = -np.inf
    best_rank: tuple[int, ...] = ()
    ranks_known: dict[tuple[int, ...], tuple[int, ...]] = {}
    if min_finger_gap_m is None:
        min_finger_gap_m = contact.finger_trigger_m + 0.0005
    search = _CombinationSearch(per_finger, pts, sep, gap, min_finger_gap_m)
    epsilons = _ScreeningEpsilons(mu, obj.radius_m)  # each contact set's hull once
    for trial in range(trials):
        # trial 0 is greedy; later trials shuffle the fingers and perturb each finger's
        # ranking, still favouring the long-lasting contacts
        order_f = list(rng.permutation(names)) if trial else names
        ranks = {
            n: np.arange(per_finger[n][0].size)
            if trial == 0
            else np.argsort(
                np.arange(per_finger[n][0].size) + rng.uniform(0.0, 4.0, per_finger[n][0].size),
                kind="stable",
            )
            for n in order_f
        }
        chosen_c = search.complete(order_f, ranks)
        if chosen_c is None:
            continue
        pick = {n: int(per_finger[n][0][c]) for n, c in chosen_c.items()}
        fracs = [float(per_finger[n][1][c]) for n, c in chosen_c.items()]
        ii = np.array([pick[n] for n in names])
        scored = _grasp_score(pts[ii], nrm[ii], fracs, mu, obj.radius_m, epsilons)
        if scored is None:
            continue
        score, e = scored
        key = tuple(pick[n] for n in names)
        if rank is not None and key not in ranks_known:
            ranks_known[key] = tuple(int(v) for v in rank(pick))
        r = ranks_known.get(key, ())
        if (
            best is None
            or r > best_rank
            or (r == best_rank and score > best_score + SCORE_RTOL * max(1.0, abs(best_score)))
        ):
            q_pick = {n: manifolds[n].q[t_index, pick[n]].copy() for n in names}
            if finger_clearance is not None and finger_clearance(q_pick) <= 0.0:
                search.refused += 1
                continue
            best_score, best_rank, best = score, r, (dict(pick), e, q_pick)
    if rank is not None and best is not None:
        climb = _RankClimb(per_finger, pts, nrm, search, mu, obj.radius_m, epsilons, ranks_known)
        best, best_rank, best_score = climb.run(
            best, best_rank, best_score, rank, manifolds, t_index, finger_clearance
        )
    closest = search.closest
    if best is None and search.refused:
        known = bool(np.isfinite(closest))
        raise ContactError(
            f"every grasp tried ({search.refused}) puts two fingers too close"
            + (
                f" (the best {closest * 1e3:.2f} mm apart, need {min_finger_gap_m * 1e3:.2f} mm)"
                if known
                else " (finger_clearance refused them)"
            ),
            kind=FailureKind.FINGER_COLLISION,
            measured=closest if known else None,
            required=min_finger_gap_m if known else None,
        )
    if best is None:
        raise ContactError(
            f"no combination of the usable contacts is in force closure (mu={mu}) with the "
            f"contacts {sep * 1e3:.0f} mm apart",
            kind=FailureKind.FORCE_CLOSURE,
        )
    pick, e, q_pick = best
    e_full = ferrari_canny_epsilon(
        pts[[pick[n] for n in names]],
        nrm[[pick[n] for n in names]],
        mu,
        torque_scale_m=obj.radius_m,
    )
    return Grasp(
        points_object={n: pts[pick[n]].copy() for n in names},
        normals_object={n: nrm[pick[n]].copy() for n in names},
        q=q_pick,
        indices={n: pick[n] for n in names},
        epsilon=float(e_full if e_full > 0 else e),
    )


class _RankClimb:
    """Improves a grasp by ``(rank, score)`` one finger's contact at a time (see
    :func:`initial_grasp`): the changed contact passes the combination search's
    separation and finger gaps, and the grasp stays in force closure."""

    def __init__(
        self,
        per_finger: Mapping[str, tuple[np.ndarray, np.ndarray]],
        pts: np.ndarray,
        nrm: np.ndarray,
        search: _CombinationSearch,
        mu: float,
        scale_m: float,
        epsilons: _ScreeningEpsilons,
        ranks_known: dict[tuple[int, ...], tuple[int, ...]],
        max_passes: int = 4,
    ) -> None:
        self.per_finger, self.pts, self.nrm, self.search = per_finger, pts, nrm, search
        self.mu, self.scale_m, self.epsilons = mu, scale_m, epsilons
        self.ranks_known, self.max_passes = ranks_known, max_passes

    def _frac(self, name: str, i: int) -> float:
        ids, fracs = self.per_finger[name]
        return float(fracs[int(np.flatnonzero(ids == i)[0])])

    def run(
        self,
        best: tuple[dict[str, int], float, dict[str, np.ndarray]],
        best_rank: tuple[int, ...],
        best_score: float,
        rank: Callable[[Mapping[str, int]], tuple[int, ...]],
        manifolds: Mapping[str, Manifold],
        t_index: int,
        finger_clearance: Callable[[dict[str, np.ndarray]], float] | None,
    ) -> tuple[tuple[dict[str, int], float, dict[str, np.ndarray]], tuple[int, ...], float]:
        """The improved ``(best, rank, score)``."""
        names = list(manifolds)
        for _ in range(self.max_passes):
            moved = False
            for name in names:
                for i in self.per_finger[name][0]:
                    found = self._try(names, best[0], name, int(i), rank, best_rank, best_score)
                    if found is None:
                        continue
                    pick, r, score, e = found
                    q_pick = {n: manifolds[n].q[t_index, pick[n]].copy() for n in names}
                    if finger_clearance is not None and finger_clearance(q_pick) <= 0.0:
                        continue
                    best, best_rank, best_score, moved = (pick, e, q_pick), r, score, True
            if not moved:
                break
        return best, best_rank, best_score

    def _try(
        self,
        names: list[str],
        current: Mapping[str, int],
        name: str,
        i: int,
        rank: Callable[[Mapping[str, int]], tuple[int, ...]],
        best_rank: tuple[int, ...],
        best_score: float,
    ) -> tuple[dict[str, int], tuple[int, ...], float, float] | None:
        """The grasp ``current`` with ``name`` at ``i`` (fingers in the order ``names``)
        and its rank, score and epsilon, if it is admissible and better; else None."""
        if i == current[name]:
            return None
        others = {n: j for n, j in current.items() if n != name}
        g = self.search._gap(name, i, others)
        if g is None or g < self.search.min_gap_m:
            return None
        pick = {n: int(current[n]) for n in names}
        pick[name] = i
        ii = np.array([pick[n] for n in names])
        fracs = [self._frac(n, pick[n]) for n in names]
        scored = _grasp_score(
            self.pts[ii], self.nrm[ii], fracs, self.mu, self.scale_m, self.epsilons
        )
        if scored is None:
            return None
        key = tuple(int(v) for v in ii)
        if key not in self.ranks_known:
            self.ranks_known[key] = tuple(int(v) for v in rank(pick))
        r = self.ranks_known[key]
        score, e = scored
        if r > best_rank or (
            r == best_rank and score > best_score + SCORE_RTOL * max(1.0, abs(best_score))
        ):
            return pick, r, score, e
        return None


class _ObjectClearance:
    """Whether a finger at a candidate contact clears the object: its other links by
    ``contact.choice_link_clearance_m``, its fingertip link not sunk in by more than
    ``contact.tip_penetration_m`` (Coal)."""

    def __init__(self, hand: Hand, finger: str, obj: ConvexObject, contact: ContactModel):
        self.links = LinkClearance(hand, finger, obj)
        self.tip = LinkClearance(hand, finger, obj, tip_only=True)
        self.contact = contact

    def __call__(self, q_full: np.ndarray, T_palm_object: np.ndarray) -> np.ndarray:
        """``(N,)`` bool for the ``(N, nq)`` configurations at the object pose(s)."""
        c = self.contact
        return (self.links(q_full, T_palm_object) >= c.choice_link_clearance_m) & (
            self.tip(q_full, T_palm_object) >= -c.tip_penetration_m
        )


def _spread_out(
    points: np.ndarray,
    order: np.ndarray,
    spacings: tuple[float, ...],
    limit: int,
    admit: Callable[[int], bool],
) -> list[int]:
    """Up to ``limit`` indices into ``points``, in ``order``, each at least the pass's
    spacing [m] from those chosen before; one pass per spacing (widest first), so the
    first candidates cover the surface and the later ones fill in. ``admit`` filters."""
    chosen: list[int] = []
    refused: set[int] = set()
    for spacing in spacings:
        for j in order:
            j = int(j)
            if len(chosen) == limit:
                return chosen
            if j in refused or j in chosen:
                continue
            if chosen and np.min(np.linalg.norm(points[chosen] - points[j], axis=1)) < spacing:
                continue
            if not admit(j):
                refused.add(j)
                continue
            chosen.append(j)
    return chosen


class _CombinationSearch:
    """Depth-first search for one contact per finger under the pairwise constraints.

    Contacts of two fingers must be ``sep`` apart and the two fingers' links
    ``min_gap_m`` apart (:class:`_PairGaps`); a finger with no admissible candidate sends
    the search back to the previous finger's next candidate, up to ``max_nodes``
    candidates per call.

    Attributes:
        refused: Dead ends where every spaced candidate was too close to a picked finger.
        closest: The largest finger distance [m] among those refused (-inf: none).
    """

    def __init__(
        self,
        per_finger: Mapping[str, tuple[np.ndarray, np.ndarray]],
        points: np.ndarray,
        sep: float,
        gaps: _PairGaps,
        min_gap_m: float,
        max_nodes: int = 2000,
    ):
        self.per_finger, self.points, self.sep = per_finger, points, sep
        self.gaps, self.min_gap_m, self.max_nodes = gaps, min_gap_m, max_nodes
        self.refused, self.closest = 0, -np.inf

    def complete(self, order: list[str], ranks: Mapping[str, np.ndarray]) -> dict[str, int] | None:
        """Candidate positions ``finger -> c`` (fingers in ``order``, candidates in
        ``ranks[finger]`` order), the first admissible combination; None if none is
        found within the node budget."""
        budget = [self.max_nodes]
        return self._extend(order, ranks, {}, {}, budget)

    def _gap(self, name: str, i: int, picked: Mapping[str, int]) -> float | None:
        """Smallest finger distance [m] of ``name`` at point ``i`` to the picked fingers;
        None if the contact is closer than ``sep`` to a picked contact."""
        if any(np.linalg.norm(self.points[i] - self.points[j]) < self.sep for j in picked.values()):
            return None
        return self.gaps.smallest(name, i, picked)

    def _dead_end(self, gaps: list[float]) -> None:
        """Record a finger whose spaced candidates (``gaps`` [m]) were all too close."""
        if gaps:
            self.refused += 1
            self.closest = max(self.closest, max(gaps))

    def _admissible(self, name: str, picked: Mapping[str, int]) -> bool:
        """Whether some candidate of ``name`` is spaced from and clear of ``picked``."""
        too_close = []
        for i in self.per_finger[name][0]:
            g = self._gap(name, int(i), picked)
            if g is not None and g >= self.min_gap_m:
                return True
            if g is not None:
                too_close.append(g)
        self._dead_end(too_close)
        return False

    def _extend(
        self,
        order: list[str],
        ranks: Mapping[str, np.ndarray],
        chosen: dict[str, int],
        picked: dict[str, int],
        budget: list[int],
    ) -> dict[str, int] | None:
        if len(chosen) == len(order):
            return dict(chosen)
        name = order[len(chosen)]
        ids = self.per_finger[name][0]
        too_close = []
        for c in ranks[name]:
            if budget[0] <= 0:
                return None
            budget[0] -= 1
            i = int(ids[c])
            g = self._gap(name, i, picked)
            if g is None or g < self.min_gap_m:
                too_close += [] if g is None else [g]
                continue
            chosen[name], picked[name] = int(c), i
            # forward check: every finger still to pick keeps an admissible candidate
            if all(self._admissible(r, picked) for r in order[len(chosen) :]):
                found = self._extend(order, ranks, chosen, picked, budget)
                if found is not None:
                    return found
            del chosen[name], picked[name]
        self._dead_end(too_close)
        return None


class _PairGaps:
    """Coal distances [m] between two grasping fingers at their candidate contacts.

    Each finger's configurations at candidate ``i`` are ``q[finger][:, i]`` (a few
    times); a pair's distance is the smallest over the times where both reach their
    contacts. The others sit at neutral (only the pair is measured). Distances are
    cached per pair of candidates.
    """

    def __init__(self, hand: Hand, q: Mapping[str, np.ndarray]):
        self.hand, self.q = hand, q
        self._checks: dict[tuple[str, str], FingerClearance] = {}
        self._cache: dict[tuple[str, int, str, int], float] = {}

    def pair(self, a: str, ia: int, b: str, ib: int) -> float:
        """Distance [m] between finger ``a`` at candidate ``ia`` and ``b`` at ``ib``."""
        if b < a:
            a, ia, b, ib = b, ib, a, ia
        key = (a, ia, b, ib)
        if key not in self._cache:
            if (a, b) not in self._checks:
                self._checks[(a, b)] = FingerClearance(self.hand, a, others=[b])
            qa, qb = self.q[a][:, ia], self.q[b][:, ib]
            both = np.isfinite(qa).all(axis=1) & np.isfinite(qb).all(axis=1)
            both[0] = True  # the start always counts
            d = np.inf
            for k in np.flatnonzero(both):
                q = self.hand.neutral()
                q[self.hand.finger(a).q_indices] = qa[k]
                q[self.hand.finger(b).q_indices] = qb[k]
                d = min(d, self._checks[(a, b)](q))
            self._cache[key] = d
        return self._cache[key]

    def smallest(self, finger: str, i: int, picked: Mapping[str, int]) -> float:
        """Smallest distance [m] from ``finger`` at ``i`` to the picked fingers (inf: none)."""
        return min((self.pair(finger, i, o, j) for o, j in picked.items()), default=np.inf)


def _link_exit(
    hand: Hand,
    finger: str,
    obj: ConvexObject,
    manifold: Manifold,
    points: np.ndarray,
    ka: int,
    contact: ContactModel,
    lasting: Callable[[np.ndarray, int], np.ndarray] | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Exit times ``(C,)`` [s] of the manifold points ``points`` from grid index ``ka``,
    cut where another link of the finger comes within ``contact.link_clearance_m`` of the
    object or the fingertip link sinks in by more than ``contact.tip_penetration_m``
    (Coal, at the manifold's times) or ``lasting`` says so, and whether each stays
    usable to the end."""
    ok = _link_ok(hand, finger, obj, manifold, points, ka, contact)
    if lasting is not None:
        ok &= lasting(points, ka)
    return exit_times(ok, manifold.times_s[ka:], 0), np.asarray(ok.all(axis=0))


def _link_ok(
    hand: Hand,
    finger: str,
    obj: ConvexObject,
    manifold: Manifold,
    points: np.ndarray,
    ka: int,
    contact: ContactModel,
) -> np.ndarray:
    """``(K, C)`` bool over the manifold's times from index ``ka``: the points are usable
    (``contact.limit_margin_rad``) and, held there, the finger's other links keep
    ``contact.link_clearance_m`` from the object and its fingertip link sinks in by at
    most ``contact.tip_penetration_m`` (Coal), at that time and every one before it.

    Only the times before a point's first exit from the usable set are measured: what
    comes after cannot change the first False of a column."""
    usable = manifold.usable(contact.limit_margin_rad)[ka:, points]
    still = np.logical_and.accumulate(usable, axis=0)  # (K, C): not left yet
    rows, cols = np.nonzero(still)
    q = manifold.q[ka + rows, points[cols]]  # finite where usable
    full = hand.to_full(finger, q)
    T = manifold.T_palm_object[ka + rows]
    d = LinkClearance(hand, finger, obj)(full, T)
    d_tip = LinkClearance(hand, finger, obj, tip_only=True)(full, T)
    ok = np.zeros_like(still)
    ok[rows, cols] = (d >= contact.link_clearance_m) & (d_tip >= -contact.tip_penetration_m)
    return np.logical_and.accumulate(ok, axis=0)
