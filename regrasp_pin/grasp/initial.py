"""The initial grasp: one contact per finger at the motion's start.

:func:`initial_grasp` searches the fingers' usable contacts at a time index (each
finger's candidates ranked by how long they last, spread over the surface, their links
clear of the object) for combinations in force closure whose contacts and fingers are
apart, and keeps the best by an optional integer rank and then a score (how many fingers
could let go, lasting fractions, epsilons); see its docstring. The new contact Q of a
regrasp is chosen by :mod:`.choice`.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from ..exceptions import ContactError, FailureKind
from ..model.hand import Hand
from ..model.objects import ConvexObject, SurfaceSample
from .choice import DISTANCE_TOL_M, exit_times
from .combinations import CombinationSearch, PairGaps
from .contact import ContactModel
from .manifold import Manifold
from .necessity import MustHold
from .quality import FORCE_CLOSURE_TOL, ferrari_canny_epsilon, holding_fingers
from .screening import (
    ManifoldClearance,
    ScreeningEpsilons,
    held_clear,
    leave_one_out,
    passes_object_clearance,
)

__all__ = ["GAP_HORIZON_S", "Grasp", "initial_grasp"]

#: grasp scores within this relative tolerance tie (the first found is kept): scores
#: sum epsilons whose last bits follow the rounding of the hull computation
SCORE_RTOL = 1e-9
#: initial_grasp measures finger gaps over the first this many seconds [s]
GAP_HORIZON_S = 1.0


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
    surface (two tip radii apart first, then one, then the rest in that order, so that
    a finger whose usable contacts lie in one small patch is not thinned out to two or
    three of them), links clear of the object at the start and held until the next
    manifold time, or, if ``hold`` (a run from the start in which the finger cannot
    let go) is given, only those that last through it: inside the joint limits and,
    held there, with the finger's other links clear of the object and its fingertip
    link not sinking in at every manifold time of the run (as the tracking will
    measure; :func:`held_clear`)."""
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
    # margins on a 1e-9 rad lattice, as the choice of a new contact keys them: margins
    # equal but for the IK's last bits are one key (unless they straddle a lattice
    # boundary, which takes a margin within rounding of one)
    order = np.lexsort((-np.round(man.margin_rad[t_index, idx], 9), -frac))
    # held at least until the next grid time (a contact the tracking loses at once is
    # no start) or, for a finger that cannot let go, for as long as it must hold
    k_held = 1 if hold is None else max(hold.k_to - t_index, 1)
    kept = ManifoldClearance(hand, name, obj, man, contact)  # one store for the candidates
    # clear of the object at the start: every candidate in one batch (Coal only where
    # the bounds do not decide)
    clear = passes_object_clearance(*kept(np.full(idx.size, t_index), idx), contact)

    def link_clear(j: int) -> bool:
        # clear of the object at the start and then held: its other links and
        # fingertip link as the tracking will see them (Coal; the manifold knows only
        # the fingertip link's shape)
        if not clear[j]:
            return False
        ok = held_clear(
            hand, name, obj, man, idx[j : j + 1], t_index, contact, kept, horizon=k_held + 1
        )[:, 0]
        return bool(ok.all())

    chosen = _spread_out(
        pts[idx],
        order,
        (2 * finger.tip_radius, finger.tip_radius, 0.0),
        max_candidates,
        link_clear,
    )
    if not chosen:
        lasting = "" if hold is None else f" that lasts until t={hold.t_to_s:.3f} s"
        raise ContactError(
            f"every usable contact{lasting} makes a link touch the object or is not held "
            "until the next manifold time",
            finger=name,
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


def _trial_ranks(
    per_finger: Mapping[str, tuple[np.ndarray, np.ndarray]],
    order: list[str],
    trial: int,
    rng: np.random.Generator,
) -> dict[str, np.ndarray]:
    """Each finger's candidate order in a trial of the grasp search: the lasting order
    in trial 0 (greedy), later perturbed, still favouring the long-lasting contacts."""
    if trial == 0:
        return {n: np.arange(per_finger[n][0].size) for n in order}
    return {
        n: np.argsort(
            np.arange(per_finger[n][0].size) + rng.uniform(0.0, 4.0, per_finger[n][0].size),
            kind="stable",
        )
        for n in order
    }


def _rank_of(
    pick: Mapping[str, int],
    names: list[str],
    rank: Callable[[Mapping[str, int]], tuple[int, ...]] | None,
    known: dict[tuple[int, ...], tuple[int, ...]],
) -> tuple[int, ...]:
    """The rank of the grasp ``pick`` (``()`` without ``rank``), each grasp ranked once
    (``known``, keyed by its contacts in the order ``names``)."""
    key = tuple(pick[n] for n in names)
    if rank is not None and key not in known:
        known[key] = tuple(int(v) for v in rank(pick))
    return known.get(key, ())


def _grasp_score(
    p: np.ndarray,
    n: np.ndarray,
    fracs: list[float],
    mu: float,
    scale_m: float,
    epsilons: ScreeningEpsilons | None = None,
) -> tuple[float, float] | None:
    """``(score, epsilon)`` of a combination of contacts ``p``, ``n`` ``(F, 3)`` whose
    lasting fractions are ``fracs``; None if it is not in force closure
    (:func:`_closure_score`). Epsilons come from ``epsilons`` if given (the same
    values)."""
    eps = epsilons or ScreeningEpsilons(mu, scale_m)
    e = eps(p, n)
    if e <= FORCE_CLOSURE_TOL:
        return None
    return _closure_score(p, n, fracs, e, eps), e


def _closure_score(
    p: np.ndarray, n: np.ndarray, fracs: list[float], e: float, epsilons: ScreeningEpsilons
) -> float:
    """The score of a combination in force closure with epsilon ``e``: first the fingers
    that can let go with the rest still in force closure (so that fingers can regrasp
    later: four fingers or more, three with torsional friction), then the smallest of
    those leave-one-out epsilons, twice the shortest lasting fraction, the mean one and
    the epsilon."""
    F = p.shape[0]
    fewest = holding_fingers(epsilons.torsion_m)
    loo = (
        leave_one_out(p, n, epsilons.mu, epsilons.scale_m, range(F), epsilons) if F > fewest else []
    )
    removable = [x for x in loo if x > FORCE_CLOSURE_TOL]
    return (
        len(removable)
        + (min(removable) / (min(removable) + 0.05) if removable else 0.0)
        + 2.0 * min(fracs)
        + sum(fracs) / F
        + e / (e + 0.05)
    )


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
    two tip radii apart (covering the surface), then one radius apart, then any (filling
    in: a finger whose usable contacts are few keeps all that clear the object). Each
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
    gap = PairGaps(
        hand,
        {n: manifolds[n].q[ks] for n in names},
        {n: per_finger[n][0] for n in names},
        min_finger_gap_m,
    )
    search = CombinationSearch(per_finger, pts, sep, gap, min_finger_gap_m)
    by_clearance = 0  # combinations refused by the caller's finger_clearance
    # each contact set's hull once
    epsilons = ScreeningEpsilons(mu, obj.radius_m, contact.torsion_m)
    for trial in range(trials):
        # trial 0 is greedy; later trials shuffle the fingers and perturb each finger's
        # ranking, still favouring the long-lasting contacts
        order_f = list(rng.permutation(names)) if trial else names
        chosen_c = search.complete(order_f, _trial_ranks(per_finger, order_f, trial, rng))
        if chosen_c is None:
            continue
        pick = {n: int(per_finger[n][0][c]) for n, c in chosen_c.items()}
        fracs = [float(per_finger[n][1][c]) for n, c in chosen_c.items()]
        ii = np.array([pick[n] for n in names])
        e = epsilons(pts[ii], nrm[ii])
        if e <= FORCE_CLOSURE_TOL:
            continue  # not in force closure
        r = _rank_of(pick, names, rank, ranks_known)
        if best is not None and r < best_rank:
            continue  # a lower rank loses whatever the score: no leave-one-out hulls
        score = _closure_score(pts[ii], nrm[ii], fracs, e, epsilons)
        if (
            best is None
            or r > best_rank
            or (r == best_rank and score > best_score + SCORE_RTOL * max(1.0, abs(best_score)))
        ):
            q_pick = {n: manifolds[n].q[t_index, pick[n]].copy() for n in names}
            if finger_clearance is not None and finger_clearance(q_pick) <= 0.0:
                search.refused += 1
                by_clearance += 1
                continue
            best_score, best_rank, best = score, r, (dict(pick), e, q_pick)
    if rank is not None and best is not None:
        climb = _RankClimb(per_finger, pts, nrm, search, epsilons, ranks_known)
        best, best_rank, best_score = climb.run(
            best, best_rank, best_score, rank, manifolds, t_index, finger_clearance
        )
    if best is None and search.refused:
        raise _too_close(search, by_clearance, min_finger_gap_m)
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
        torsion_m=contact.torsion_m,
    )
    return Grasp(
        points_object={n: pts[pick[n]].copy() for n in names},
        normals_object={n: nrm[pick[n]].copy() for n in names},
        q=q_pick,
        indices={n: pick[n] for n in names},
        epsilon=float(e_full if e_full > 0 else e),
    )


def _too_close(search: CombinationSearch, by_clearance: int, min_gap_m: float) -> ContactError:
    """The failure of a grasp search whose every grasp put two fingers too close: the
    combination search's closest refusal (its two fingers, their gap [m] against
    ``min_gap_m``), and how many complete grasps the caller's ``finger_clearance``
    refused (``by_clearance``)."""
    pair = search.closest_pair()  # None when only finger_clearance refused
    by_caller = f"finger_clearance refused {by_clearance}" if by_clearance else ""
    if pair is None:
        detail = f" ({by_caller})"
    else:
        detail = (
            f" (the best: {pair[0]} and {pair[1]} {search.closest * 1e3:.3f} mm apart, need "
            f"{min_gap_m * 1e3:.3f} mm" + (f"; {by_caller}" if by_caller else "") + ")"
        )
    return ContactError(
        f"every grasp tried ({search.refused}) puts two fingers too close" + detail,
        finger=None if pair is None else pair[0],
        other=None if pair is None else pair[1],
        kind=FailureKind.FINGER_COLLISION,
        measured=None if pair is None else search.closest,
        required=None if pair is None else min_gap_m,
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
        search: CombinationSearch,
        epsilons: ScreeningEpsilons,
        ranks_known: dict[tuple[int, ...], tuple[int, ...]],
        max_passes: int = 4,
    ) -> None:
        self.per_finger, self.pts, self.nrm, self.search = per_finger, pts, nrm, search
        self.epsilons = epsilons
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
        # force closure (one hull), then the rank: a lower rank loses whatever the
        # score, so its leave-one-out hulls are not needed
        e = self.epsilons(self.pts[ii], self.nrm[ii])
        if e <= FORCE_CLOSURE_TOL:
            return None
        r = _rank_of(pick, names, rank, self.ranks_known)
        if r < best_rank:
            return None
        fracs = [self._frac(n, pick[n]) for n in names]
        score = _closure_score(self.pts[ii], self.nrm[ii], fracs, e, self.epsilons)
        if r > best_rank or (
            r == best_rank and score > best_score + SCORE_RTOL * max(1.0, abs(best_score))
        ):
            return pick, r, score, e
        return None


def _spread_out(
    points: np.ndarray,
    order: np.ndarray,
    spacings: tuple[float, ...],
    limit: int,
    admit: Callable[[int], bool],
) -> list[int]:
    """Up to ``limit`` indices into ``points``, in ``order``, each more than the pass's
    spacing [m] from those chosen before (by :data:`~.choice.DISTANCE_TOL_M`: points of
    the sample's grids exactly a spacing apart are near on every machine, and the later
    waits for a narrower pass); one pass per spacing (widest first), so the first
    candidates cover the surface and the later ones fill in. ``admit`` filters."""
    chosen: list[int] = []
    skip: set[int] = set()  # refused by admit, or chosen
    for spacing in spacings:
        near = spacing + DISTANCE_TOL_M if spacing > 0 else 0.0  # 0: any point
        # the points within `near` of a chosen one, kept up to date as points are chosen
        # (the same distances as measured from each point to the chosen ones)
        blocked = np.zeros(len(points), bool)
        if near > 0.0:
            for c in chosen:
                blocked |= np.linalg.norm(points - points[c], axis=1) < near
        for j in order:
            j = int(j)
            if len(chosen) == limit:
                return chosen
            if j in skip or blocked[j]:
                continue
            if not admit(j):
                skip.add(j)
                continue
            chosen.append(j)
            skip.add(j)
            if near > 0.0:
                blocked |= np.linalg.norm(points - points[j], axis=1) < near
    return chosen
