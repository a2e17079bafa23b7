"""The screening's contact-set cache (:class:`ScreeningEpsilons`): each set's test or
hull once, the same answers as computing them afresh."""

from __future__ import annotations

import numpy as np

from regrasp_pin.grasp.quality import ferrari_canny_epsilon, is_force_closure
from regrasp_pin.grasp.screening import PLANNER_EDGES, SCREEN_EDGES, ScreeningEpsilons
from regrasp_pin.model.objects import Box

MU = 0.8
BOX = Box((0.06, 0.04, 0.04))


def _on_box(rng: np.random.Generator, k: int) -> tuple[np.ndarray, np.ndarray]:
    """``k`` contacts on random faces of BOX: points and outward normals."""
    half = np.array([0.03, 0.02, 0.02])
    axis = rng.integers(0, 3, size=k)
    sign = rng.choice([-1.0, 1.0], size=k)
    p = rng.uniform(-1.0, 1.0, size=(k, 3)) * half
    p[np.arange(k), axis] = sign * half[axis]
    n = np.zeros((k, 3))
    n[np.arange(k), axis] = sign
    return p, n


def test_the_planners_test_and_epsilon_are_computed_once_per_set():
    """planner_closes and planner_epsilon give is_force_closure and
    ferrari_canny_epsilon with the planner's cone edges (not the screening's, which
    differ on some sets), and a set asked again is not computed again."""
    rng = np.random.default_rng(4)
    eps = ScreeningEpsilons(MU, BOX.radius_m)
    sets = [_on_box(rng, int(rng.integers(3, 6))) for _ in range(60)]
    closing = differ = 0
    first = []
    for p, n in sets:
        fresh = ferrari_canny_epsilon(p, n, MU, n_edges=PLANNER_EDGES, torque_scale_m=BOX.radius_m)
        closes = is_force_closure(p, n, MU, n_edges=PLANNER_EDGES, torque_scale_m=BOX.radius_m)
        first.append((eps.planner_epsilon(p, n), eps.planner_closes(p, n)))
        assert first[-1] == (fresh, closes)
        closing += closes
        screen = ferrari_canny_epsilon(p, n, MU, n_edges=SCREEN_EDGES, torque_scale_m=BOX.radius_m)
        differ += screen != fresh
    assert closing >= 10 and differ >= 10, (closing, differ)
    eps.mu = float("nan")  # a computation now would give NaN or raise: none happens
    assert [(eps.planner_epsilon(p, n), eps.planner_closes(p, n)) for p, n in sets] == first
