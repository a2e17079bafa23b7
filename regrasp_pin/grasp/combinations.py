"""The initial grasp's combinations: one candidate contact per finger, the contacts and
the fingers apart.

:class:`CombinationSearch` is a depth-first search over the fingers' ranked candidate
contacts under two pairwise constraints: the contacts ``sep`` apart, and the fingers'
links (Coal, at the candidates' configurations over the first times of the motion)
``min_gap_m`` apart, those distances measured by :class:`PairGaps` (capsule lower
bounds in batches first, Coal only where a bound does not clear the threshold).
:func:`~.initial.initial_grasp` runs it trial by trial and scores what it finds.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from ..model.clearance import FingerClearance
from ..model.distances import capsule_gap
from ..model.hand import Hand
from .choice import apart_threshold

__all__ = ["CombinationSearch", "PairGaps"]

#: A finger pair whose capsule bound is this far above the finger-gap threshold is not
#: measured by Coal: more than Coal's tolerance on the distances the bound may exceed [m].
_CLEAR_SLACK_M = 1e-5


#: Where a refused gap was measured: the refused finger, its candidate (a sample index)
#: and the picked fingers' ``(finger, sample index)`` pairs
_Where = tuple[str, int, tuple[tuple[str, int], ...]]


class CombinationSearch:
    """Depth-first search for one contact per finger under the pairwise constraints.

    Contacts of two fingers must be ``sep`` apart and the two fingers' links
    ``min_gap_m`` apart (:class:`PairGaps`); a finger with no admissible candidate sends
    the search back to the previous finger's next candidate, up to ``max_nodes``
    candidates per call.

    Attributes:
        refused: Dead ends where every spaced candidate was too close to a picked finger.
        closest: The largest finger distance [m] among those refused (-inf: none).
        closest_at: Where it was measured: the refused finger, its candidate (a sample
            index) and the picked fingers' ``(finger, sample index)`` pairs; None with
            ``closest`` -inf (the first of equal distances is kept).
    """

    def __init__(
        self,
        per_finger: Mapping[str, tuple[np.ndarray, np.ndarray]],
        points: np.ndarray,
        sep: float,
        gaps: PairGaps,
        min_gap_m: float,
        max_nodes: int = 2000,
    ):
        self.per_finger, self.sep = per_finger, sep
        self.gaps, self.min_gap_m, self.max_nodes = gaps, min_gap_m, max_nodes
        self.refused, self.closest = 0, -np.inf
        self.closest_at: _Where | None = None
        # which candidates are closer than ``sep``: one table over every finger's
        # candidates (sample index -> row), looked up in the search's inner loops; two
        # exactly ``sep`` apart (the sample's points lie on grids) are apart on every
        # machine, as the choice of a new contact has it (apart_threshold)
        ids = np.unique(np.concatenate([np.asarray(c[0], int) for c in per_finger.values()]))
        self._row = {int(i): r for r, i in enumerate(ids)}
        self._rows = {
            n: np.array([self._row[int(i)] for i in c[0]], int) for n, c in per_finger.items()
        }
        p = np.asarray(points, float)[ids]
        dist = np.linalg.norm(p[:, None, :] - p[None, :, :], axis=-1)
        self._near = dist < apart_threshold(sep)
        # _admissible per (finger, picked): None, or the gaps of its spaced candidates
        self._known: dict[
            tuple[str, tuple[tuple[str, int], ...]], list[tuple[float, int]] | None
        ] = {}
        # subtrees searched to the end without a combination, per (picked, fingers still
        # to pick in their order): (candidates it took, dead ends, closest gap, where)
        self._failed: dict[
            tuple[tuple[tuple[str, int], ...], tuple[str, ...]],
            tuple[int, int, float, _Where | None],
        ] = {}
        self._cuts = 0  # searches cut short by the node budget

    def complete(self, order: list[str], ranks: Mapping[str, np.ndarray]) -> dict[str, int] | None:
        """Candidate positions ``finger -> c`` (fingers in ``order``, candidates in
        ``ranks[finger]`` order), the first admissible combination; None if none is
        found within the node budget."""
        budget = [self.max_nodes]
        return self._extend(order, ranks, {}, {}, budget)

    def _gap(self, name: str, i: int, picked: Mapping[str, int]) -> float | None:
        """Smallest finger distance [m] of ``name`` at point ``i`` to the picked fingers;
        None if the contact is closer than ``sep`` to a picked contact."""
        near = self._near[self._row[i]]
        if any(near[self._row[j]] for j in picked.values()):
            return None
        return self.gaps.smallest(name, i, picked)

    def _dead_end(
        self, name: str, picked: Mapping[str, int], refused: list[tuple[float, int]]
    ) -> None:
        """Record a finger whose spaced candidates (``refused``: their gaps [m] and
        sample indices) were all too close to the ``picked`` fingers."""
        if refused:
            self.refused += 1
            gap, i = max(refused, key=lambda gi: gi[0])  # the first of equals
            if gap > self.closest:  # names as plain strings (a trial's order is numpy's)
                self.closest = gap
                where = tuple(sorted((str(o), int(j)) for o, j in picked.items()))
                self.closest_at = (str(name), int(i), where)

    def closest_pair(self) -> tuple[str, str] | None:
        """The two fingers of :attr:`closest`: the refused finger and the picked finger
        nearest it (of equal distances the first by name); None when none was refused."""
        if self.closest_at is None:
            return None
        name, i, picked = self.closest_at
        other = min(picked, key=lambda oj: (self.gaps.smallest(name, i, dict([oj])), oj[0]))
        return name, other[0]

    def _admissible(self, name: str, picked: Mapping[str, int]) -> bool:
        """Whether some candidate of ``name`` is spaced from and clear of ``picked``."""
        key = (name, tuple(sorted(picked.items())))
        if key not in self._known:
            self._known[key] = self._too_close(name, picked)
        refused = self._known[key]
        if refused is None:
            return True
        self._dead_end(name, picked, refused)
        return False

    def _too_close(self, name: str, picked: Mapping[str, int]) -> list[tuple[float, int]] | None:
        """None if some candidate of ``name`` is spaced from and clear of ``picked``;
        else the finger gaps [m] of its spaced candidates (all too small), each with the
        candidate's sample index.

        One batch over the candidates: the capsule bounds and the distances already
        measured decide most of them; Coal measures the rest, a candidate at a time in
        candidate order, until one is clear (the same gaps as :meth:`PairGaps.smallest`
        candidate by candidate)."""
        ids, rows = self.per_finger[name][0], self._rows[name]
        taken = np.array([self._row[j] for j in picked.values()], int)
        spaced = ~self._near[np.ix_(rows, taken)].any(axis=1)
        lower, exact = self.gaps.columns(name, picked)
        far = lower >= self.gaps.clear_m
        if (spaced & far.all(axis=1)).any():
            return None  # a spaced candidate is clear by its capsule bounds alone
        cand = np.flatnonzero(spaced)
        gaps = np.where(far, lower, exact)[cand].min(axis=1, initial=np.inf)
        unknown = np.isnan(gaps)  # a pair below the bound's threshold not measured yet
        if (gaps[~unknown] >= self.min_gap_m).any():
            return None
        for r in np.flatnonzero(unknown):
            gaps[r] = self.gaps.smallest(name, int(ids[cand[r]]), picked)
            if gaps[r] >= self.min_gap_m:
                return None
        return list(zip(gaps.tolist(), ids[cand].tolist(), strict=True))

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
        # a subtree without a combination has none in any candidate order: every node in
        # it tries all its candidates, so it takes the same candidates and finds the same
        # dead ends whatever the ranks; a later trial that reaches it again is told so
        # (when the budget would not have cut it short)
        key = (tuple(sorted(picked.items())), tuple(order[len(chosen) :]))
        known = self._failed.get(key)
        if known is not None and budget[0] >= known[0]:
            budget[0] -= known[0]
            self.refused += known[1]
            self._merge_closest(known[2], known[3])
            return None
        start = (budget[0], self.refused, self._cuts)
        outer = self.closest, self.closest_at
        self.closest, self.closest_at = -np.inf, None  # this subtree's own, merged after
        found = self._search(order, ranks, chosen, picked, budget)
        mine = self.closest, self.closest_at
        self.closest, self.closest_at = outer
        self._merge_closest(*mine)
        if found is None and self._cuts == start[2]:
            self._failed[key] = (start[0] - budget[0], self.refused - start[1], *mine)
        return found

    def _merge_closest(self, gap: float, at: _Where | None) -> None:
        """Take a subtree's closest refused gap [m] and where it was, if larger."""
        if gap > self.closest:
            self.closest, self.closest_at = gap, at

    def _search(
        self,
        order: list[str],
        ranks: Mapping[str, np.ndarray],
        chosen: dict[str, int],
        picked: dict[str, int],
        budget: list[int],
    ) -> dict[str, int] | None:
        """:meth:`_extend` at one node: its finger's candidates in rank order."""
        name = order[len(chosen)]
        ids = self.per_finger[name][0]
        too_close: list[tuple[float, int]] = []
        for c in ranks[name]:
            if budget[0] <= 0:
                self._cuts += 1
                return None
            budget[0] -= 1
            i = int(ids[c])
            g = self._gap(name, i, picked)
            if g is None or g < self.min_gap_m:
                too_close += [] if g is None else [(g, i)]
                continue
            chosen[name], picked[name] = int(c), i
            # forward check: every finger still to pick keeps an admissible candidate
            if all(self._admissible(r, picked) for r in order[len(chosen) :]):
                found = self._extend(order, ranks, chosen, picked, budget)
                if found is not None:
                    return found
            del chosen[name], picked[name]
        self._dead_end(name, picked, too_close)
        return None


class PairGaps:
    """Coal distances [m] between two grasping fingers at their candidate contacts, exact
    wherever they are below ``exact_below_m``.

    Each finger's configurations at candidate ``i`` are ``q[finger][:, i]`` (a few
    times); a pair's distance is the smallest over the times where both reach their
    contacts. The others sit at neutral (only the pair is measured). The search only
    compares these distances with ``exact_below_m`` and reports the ones below it, so
    a pair is first bounded from below by capsules, every candidate of both fingers in
    one batch (:func:`~regrasp_pin.model.distances.capsule_gap`, whose bound exceeds
    Coal's distance by at most Coal's tolerance), and measured by Coal only when that
    bound is not above the threshold by :data:`_CLEAR_SLACK_M`. Distances are cached
    per pair of candidates.
    """

    def __init__(
        self,
        hand: Hand,
        q: Mapping[str, np.ndarray],
        candidates: Mapping[str, np.ndarray],
        exact_below_m: float,
    ):
        self.hand, self.q = hand, q
        self._checks: dict[tuple[str, str], FingerClearance] = {}
        self._exact: dict[tuple[str, str], np.ndarray] = {}
        self._neutral = hand.neutral()
        self._cand = {n: np.asarray(c, dtype=np.int64) for n, c in candidates.items()}
        self._row = {n: {int(i): r for r, i in enumerate(c)} for n, c in self._cand.items()}
        self.clear_m = float(exact_below_m) + _CLEAR_SLACK_M
        self._bounds: dict[tuple[str, str], np.ndarray] = {}

    def pair(self, a: str, ia: int, b: str, ib: int) -> float:
        """Distance [m] between finger ``a`` at candidate ``ia`` and ``b`` at ``ib``."""
        if b < a:
            a, ia, b, ib = b, ib, a, ia
        exact, ra, rb = self._exact_of(a, b), self._row[a][ia], self._row[b][ib]
        d = exact[ra, rb]
        if np.isnan(d):
            if (a, b) not in self._checks:
                self._checks[(a, b)] = FingerClearance(self.hand, a, others=[b])
            qa, qb = self.q[a][:, ia], self.q[b][:, ib]
            both = np.isfinite(qa).all(axis=1) & np.isfinite(qb).all(axis=1)
            both[0] = True  # the start always counts
            d = np.inf
            for k in np.flatnonzero(both):
                q = self._neutral.copy()
                q[self.hand.finger(a).q_indices] = qa[k]
                q[self.hand.finger(b).q_indices] = qb[k]
                d = min(d, self._checks[(a, b)](q))
            exact[ra, rb] = d
        return float(d)

    def _exact_of(self, a: str, b: str) -> np.ndarray:
        """The distances of :meth:`pair` measured so far, ``(n_a, n_b)`` for ``a < b``
        (rows and columns in candidate order; NaN: not measured)."""
        exact = self._exact.get((a, b))
        if exact is None:
            shape = (self._cand[a].size, self._cand[b].size)
            exact = self._exact[(a, b)] = np.full(shape, np.nan)
        return exact

    def columns(self, finger: str, picked: Mapping[str, int]) -> tuple[np.ndarray, np.ndarray]:
        """``(lower, exact)``, each ``(n, len(picked))`` [m]: for every candidate of
        ``finger`` (rows, in candidate order) and each picked finger at its contact
        (columns, in ``picked``'s order), the capsule lower bound of :meth:`pair` and
        its distance as measured so far (NaN: not measured)."""
        n = self._cand[finger].size
        lower, exact = np.empty((n, len(picked))), np.empty((n, len(picked)))
        for c, (o, j) in enumerate(picked.items()):
            r = self._row[o][j]
            lower[:, c] = self.bounds(finger, o)[:, r]
            exact[:, c] = (
                self._exact_of(finger, o)[:, r] if finger < o else self._exact_of(o, finger)[r, :]
            )
        return lower, exact

    def bounds(self, a: str, b: str) -> np.ndarray:
        """Capsule lower bounds ``(n_a, n_b)`` [m] on :meth:`pair` for every candidate
        of ``a`` (rows, in candidate order) against every candidate of ``b``, capped
        just above the threshold (the cap is all the search reads of larger ones)."""
        if (a, b) not in self._bounds:
            if (b, a) in self._bounds:
                return self._bounds[(b, a)].T
            self._bounds[(a, b)] = self._capsule_bounds(a, b)
        return self._bounds[(a, b)]

    def _capsule_bounds(self, a: str, b: str) -> np.ndarray:
        fa, fb = self.hand.finger(a), self.hand.finger(b)
        qa, qb = self.q[a][:, self._cand[a]], self.q[b][:, self._cand[b]]  # (T, n, k)
        n_t, n_a, n_b = qa.shape[0], qa.shape[1], qb.shape[1]
        reached_a, reached_b = np.isfinite(qa).all(axis=2), np.isfinite(qb).all(axis=2)
        reached_a[0] = reached_b[0] = True  # the start always counts
        # rows (time, candidate of a, candidate of b); b placed once per (time, candidate)
        q_rows = np.tile(self._neutral, (n_t * n_a * n_b, 1))
        q_rows[:, fa.q_indices] = np.repeat(np.nan_to_num(qa), n_b, axis=1).reshape(-1, fa.k)
        q_b = np.tile(self._neutral, (n_t * n_b, 1))
        q_b[:, fb.q_indices] = np.nan_to_num(qb).reshape(-1, fb.k)
        rows_b = (np.arange(n_t)[:, None, None] * n_b + np.arange(n_b)[None, None, :]).repeat(
            n_a, axis=1
        )
        own = set(fa.geometry_ids)
        lb = capsule_gap(
            self.hand,
            list(fa.geometry_ids),
            [g for g in fb.geometry_ids if g not in own],
            q_rows,
            cap_m=self.clear_m,
            q_b=q_b,
            rows_b=rows_b.reshape(-1),
        ).reshape(n_t, n_a, n_b)
        both = reached_a[:, :, None] & reached_b[:, None, :]
        return np.where(both, lb, np.inf).min(axis=0)

    def _bound(self, a: str, ia: int, b: str, ib: int) -> float:
        return float(self.bounds(a, b)[self._row[a][ia], self._row[b][ib]])

    def smallest(self, finger: str, i: int, picked: Mapping[str, int]) -> float:
        """Smallest distance [m] from ``finger`` at ``i`` to the picked fingers (inf:
        none): exact when below the threshold, else a value at or above it."""
        out = np.inf
        for o, j in picked.items():
            lb = self._bound(finger, i, o, j)
            out = min(out, lb if lb >= self.clear_m else self.pair(finger, i, o, j))
        return out
