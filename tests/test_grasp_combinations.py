"""Tests of the initial grasp's combination search (regrasp_pin.grasp.combinations).

The search runs on tables of finger distances written here (random contact points, a
random symmetric table, random lower bounds below it) and is checked against a brute
force over every combination; the pair gaps (Coal, on the five-finger hand) against a store
that measured every pair.
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from regrasp_pin.grasp.combinations import CombinationSearch, PairGaps
from regrasp_pin.model.hand import Hand


class _TableGaps:
    """Pairwise finger distances from a table: (finger, point, finger, point) -> [m],
    lower bounds on them (the table less a random slack of up to 2 mm) for the
    search's shortcut (candidates clear of every picked finger by their bounds alone),
    and the distances known without measuring: those of the candidates measured before
    (:meth:`smallest`), NaN for the others."""

    def __init__(self, table, ids, gap_m, seed):
        self.table, self.ids, self.clear_m = table, ids, gap_m
        rng = np.random.default_rng(seed)
        self.slack = {key: rng.uniform(0.0, 0.002) for key in sorted(table)}
        self.measured = set()

    def smallest(self, finger, i, picked):
        # as PairGaps.smallest: a bound at or above the threshold stands for the distance
        self.calls = getattr(self, "calls", 0) + 1
        keys = [(finger, int(i), o, j) for o, j in picked.items()]
        self.measured.update(keys)
        lower = [self.table[k] - self.slack[k] for k in keys]
        return min(
            (
                lb if lb >= self.clear_m else self.table[k]
                for k, lb in zip(keys, lower, strict=True)
            ),
            default=np.inf,
        )

    def columns(self, finger, picked):
        keys = [[(finger, int(i), o, j) for o, j in picked.items()] for i in self.ids[finger]]
        lower = np.array([[self.table[k] - self.slack[k] for k in row] for row in keys])
        exact = np.array(
            [[self.table[k] if k in self.measured else np.nan for k in row] for row in keys]
        )
        shape = (len(self.ids[finger]), len(picked))
        return lower.reshape(shape), exact.reshape(shape)


def _table_problem(rng, n, high_m):
    """Four fingers of ``n`` candidates each, random contact points, and a symmetric table
    of finger distances uniform in [-4 mm, ``high_m``)."""
    names = ["a", "b", "c", "d"]
    ids = {f: np.arange(k * n, (k + 1) * n) for k, f in enumerate(names)}
    per_finger = {f: (ids[f], np.ones(n)) for f in names}
    pts = rng.uniform(-0.04, 0.04, (4 * n, 3))
    table = {}
    for f, g in itertools.permutations(names, 2):
        for i in ids[f]:
            for j in ids[g]:
                table[f, i, g, j] = table.get((g, j, f, i), rng.uniform(-0.004, high_m))
    return names, ids, per_finger, pts, table


@pytest.mark.parametrize("seed", range(6))
def test_combination_search_finds_an_admissible_grasp_whenever_one_exists(seed):
    names, ids, per_finger, pts, table = _table_problem(np.random.default_rng(seed), 6, 0.003)
    n = 6
    gap_m, sep = 0.001, 0.02

    def admissible(combo):
        pairs = itertools.combinations(zip(names, combo, strict=True), 2)
        return all(
            np.linalg.norm(pts[i] - pts[j]) >= sep and table[f, i, g, j] >= gap_m
            for (f, i), (g, j) in pairs
        )

    exists = any(admissible(c) for c in itertools.product(*(ids[f] for f in names)))
    gaps = _TableGaps(table, ids, gap_m, seed)
    search = CombinationSearch(per_finger, pts, sep, gaps, gap_m, max_nodes=10**6)
    found = search.complete(names, {f: np.arange(n) for f in names})
    assert (found is not None) == exists
    if found is not None:
        assert admissible([int(ids[f][found[f]]) for f in names])
    else:
        assert search.refused > 0 and search.closest < gap_m


@pytest.mark.parametrize("seed", range(6))
def test_combination_search_names_the_two_fingers_of_its_closest_refusal(seed):
    """Where no combination is admissible, the closest refused gap is the table's
    distance between the finger refused there and the picked finger nearest it."""
    rng = np.random.default_rng(300 + seed)
    names, ids, per_finger, pts, table = _table_problem(rng, 5, 0.0012)
    gap_m, sep = 0.001, 0.0
    search = CombinationSearch(
        per_finger, pts, sep, _TableGaps(table, ids, gap_m, seed), gap_m, max_nodes=10**6
    )
    assert search.closest_pair() is None  # nothing refused yet
    # few distances reach 1 mm: these tables have no admissible combination (the
    # fingers in a shuffled order, numpy's strings, as initial_grasp's later trials)
    order = list(np.random.default_rng(seed).permutation(names))
    assert search.complete(order, {f: np.arange(5) for f in names}) is None
    name, i, picked = search.closest_at
    by_table = {o: table[name, i, o, j] for o, j in picked}
    assert min(by_table.values()) == search.closest < gap_m
    assert search.closest_pair() == (name, min(by_table, key=lambda o: (by_table[o], o)))
    assert all(type(f) is str for f in search.closest_pair())  # not numpy's strings
    assert name not in dict(picked)


@pytest.mark.parametrize("seed", range(4))
def test_combination_search_a_finger_too_close_in_one_batch_is_the_loop_over_candidates(seed):
    """``_too_close`` decides from the bounds and the distances known, and measures the
    rest: the same answer (None, or every spaced candidate's gap) as measuring each
    spaced candidate in turn, whichever distances were measured before."""
    rng = np.random.default_rng(200 + seed)
    names, ids, per_finger, pts, table = _table_problem(rng, 8, 0.0015)
    sep, gap_m = 0.02, 0.001
    for _ in range(30):
        gaps = _TableGaps(table, ids, gap_m, seed)
        search = CombinationSearch(per_finger, pts, sep, gaps, gap_m)
        name, *others = rng.permutation(names)
        picked = {o: int(rng.choice(ids[o])) for o in others[: rng.integers(1, 4)]}
        for i in rng.choice(ids[name], 3):  # some distances measured before
            gaps.smallest(name, int(i), picked)
        spaced = [
            int(i)
            for i in ids[name]
            if all(np.linalg.norm(pts[i] - pts[j]) >= sep for j in picked.values())
        ]
        reference = _TableGaps(table, ids, gap_m, seed)  # the same bounds, its own memo
        every = [(reference.smallest(name, i, picked), i) for i in spaced]
        expected = None if any(g >= gap_m for g, _ in every) else every
        assert search._too_close(name, picked) == expected


def test_pair_gaps_columns_are_the_bounds_and_the_distances_measured_so_far():
    """``PairGaps.columns``: for each candidate of a finger (rows) and each picked
    finger (columns), the capsule bound of that pair and its Coal distance once
    measured (NaN before), whichever of the two fingers comes first by name and with
    candidate counts that differ per finger (a row and a column swapped would not
    fit). The distances are those of a store that measured every pair."""
    hand = Hand.five_finger()
    rng = np.random.default_rng(12)
    names = ["index", "middle", "thumb"]
    q = {}
    for n in names:
        f = hand.finger(n)
        q[n] = rng.uniform(f.lower, f.upper, (2, 30, f.k))
    cand = {
        n: rng.choice(30, size, replace=False) for n, size in zip(names, (5, 3, 4), strict=True)
    }
    every = PairGaps(hand, q, cand, 0.002)
    for finger in names:
        gaps = PairGaps(hand, q, cand, 0.002)
        picked = {o: int(cand[o][-1]) for o in names if o != finger}
        measured = [(int(i), o) for i in cand[finger][::2] for o in picked]
        for i, o in measured:  # in either order of the two fingers
            if o < finger:
                gaps.pair(o, picked[o], finger, i)
            else:
                gaps.pair(finger, i, o, picked[o])
        lower, exact = gaps.columns(finger, picked)
        assert lower.shape == exact.shape == (cand[finger].size, len(picked))
        for r, i in enumerate(cand[finger]):
            for c, (o, j) in enumerate(picked.items()):
                assert lower[r, c] == gaps._bound(finger, int(i), o, j)
                if (int(i), o) in measured:
                    assert exact[r, c] == every.pair(finger, int(i), o, j)
                else:
                    assert np.isnan(exact[r, c])


def test_combination_search_contacts_exactly_the_separation_apart_are_apart_anywhere():
    # the surface sample's points lie on grids: two candidates exactly ``sep`` apart (5
    # steps of 4 mm) must not be decided by the last bits of where the object lies
    rng = np.random.default_rng(4)
    lattice = 0.004 * np.array([[0.0, 0, 0], [5, 0, 0], [3, 4, 0], [0, 3, 4]])
    ids = {"a": np.array([0]), "b": np.array([1, 2, 3])}  # 1, 2 and 3 all 20 mm from 0
    per_finger = {f: (ids[f], np.ones(len(ids[f]))) for f in ids}
    table = {}
    for j in ids["b"]:
        table["a", 0, "b", j] = table["b", j, "a", 0] = 0.01
    for _ in range(40):
        R = np.linalg.qr(rng.standard_normal((3, 3)))[0]
        pts = lattice @ R.T + rng.uniform(-0.3, 0.3, 3)
        gaps = _TableGaps(table, ids, 0.001, 0)
        search = CombinationSearch(per_finger, pts, 0.02, gaps, 0.001, max_nodes=100)
        assert search.complete(["a", "b"], {"a": np.arange(1), "b": np.arange(3)}) == {
            "a": 0,
            "b": 0,
        }
        search = CombinationSearch(per_finger, pts, 0.02 + 1e-6, gaps, 0.001, max_nodes=100)
        assert search.complete(["a", "b"], {"a": np.arange(1), "b": np.arange(3)}) is None


def test_combination_search_a_separation_below_the_tolerance_still_keeps_fingers_apart():
    # a separation of 0.1 nm (below DISTANCE_TOL_M): two fingers may not share a point
    pts = np.array([[0.0, 0.0, 0.0], [0.01, 0.0, 0.0]])
    ids = {"a": np.array([0]), "b": np.array([0, 1])}
    per_finger = {f: (ids[f], np.ones(len(ids[f]))) for f in ids}
    table = {(f, i, g, j): 0.01 for f in ids for g in ids for i in ids[f] for j in ids[g]}
    gaps = _TableGaps(table, ids, 0.001, 0)
    search = CombinationSearch(per_finger, pts, 1e-10, gaps, 0.001, max_nodes=100)
    found = search.complete(["a", "b"], {"a": np.arange(1), "b": np.arange(2)})
    assert found == {"a": 0, "b": 1}


class _Forgetful(dict):
    """A memo that remembers nothing."""

    def __setitem__(self, key, value):
        pass


@pytest.mark.parametrize("seed", range(4))
def test_combination_search_remembering_dead_subtrees_changes_nothing(seed):
    """Trials in other finger orders and candidate ranks, some with budgets that cut
    them short: the search that skips subtrees it searched to the end without a
    combination gives, trial by trial, the same combination, dead ends and closest gap
    (and where it was measured) as one that searches every subtree again."""
    n = 7
    names, ids, per_finger, pts, table = _table_problem(np.random.default_rng(100 + seed), n, 0.002)
    searches = []
    for remember in (True, False):
        gaps = _TableGaps(table, ids, 0.001, seed)
        search = CombinationSearch(per_finger, pts, 0.02, gaps, 0.001, max_nodes=10**6)
        if not remember:
            search._failed = _Forgetful()
        searches.append(search)
    trial_rng = np.random.default_rng(seed)
    for trial in range(40):
        order = list(trial_rng.permutation(names))
        ranks = {f: trial_rng.permutation(n) for f in names}
        budget = int(trial_rng.choice([10**6, int(trial_rng.integers(1, 300))]))
        out = []
        for search in searches:
            search.max_nodes = budget
            found = search.complete(order, ranks)
            out.append((found, search.refused, search.closest, search.closest_at))
        assert out[0] == out[1], trial
    # the memo was used: fewer candidates measured
    assert searches[0].gaps.calls < searches[1].gaps.calls
