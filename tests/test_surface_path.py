"""Grid paths (regrasp_pin.surface.path) on the unfolded top of a 60 x 40 x 40 mm box:
lengths against straight lines and detours computed by hand, costs against the sum of
the edge weights."""

from __future__ import annotations

import math

import numpy as np
import pytest

from regrasp_pin.exceptions import InputError, PlanningError
from regrasp_pin.model.objects import Box
from regrasp_pin.surface.grid import build_surface_grid
from regrasp_pin.surface.path import WEIGHT_QUANTUM_M, edge_weights, shortest_grid_path
from tests.conftest import assert_close

SPACING = 0.002


@pytest.fixture(scope="module")
def box() -> Box:
    return Box((0.06, 0.04, 0.04))


# ---------------------------------------------------------------------- paths and costs
WALL_GAP_PATH_M = 2 * math.hypot(0.021, 0.01) + 0.008  # around the wall's corners


def _wall_cost(grid, value, gap=True):
    """Cost ``value`` on a wall |x| < 4 mm, open for y <= -10 mm when ``gap``."""
    x, y = grid.points_object[:, 0], grid.points_object[:, 1]
    wall = (np.abs(x) < 0.004) & ((y > -0.01) if gap else True)
    return np.where(wall, value, 0.0)


@pytest.fixture(scope="module")
def top_grid(box):
    return build_surface_grid(
        box, np.array([-0.025, 0.0, 0.02]), np.array([0.025, 0.0, 0.02]), spacing_m=SPACING
    )


def test_single_face_path_is_the_straight_line(top_grid):
    path = shortest_grid_path(top_grid)
    assert 0.05 - 1e-12 <= path.length_m <= 1.03 * 0.05
    assert path.nodes[0] == top_grid.p_index and path.nodes[-1] == top_grid.q_index
    assert_close(path.arc_length_m[-1], path.length_m, atol=0)
    assert_close(path.cost, path.length_m, atol=1e-15, what="cost without node costs")


def test_forbidden_wall_steers_the_path_through_the_gap(top_grid):
    """With a wall |x| < 4 mm forbidden for y > -10 mm, the shortest route hugs the gap's
    corners (-4, -10) and (4, -10) mm: 2 hypot(21, 10) + 8 = 54.5 mm."""
    cost = _wall_cost(top_grid, np.inf)
    path = shortest_grid_path(top_grid, cost)
    assert np.all(np.isfinite(cost[path.nodes]))
    assert_close(path.length_m, WALL_GAP_PATH_M, atol=0, rtol=0.03)
    in_wall_x = np.abs(path.points_object[:, 0]) < 0.004
    assert np.all(path.points_object[in_wall_x, 1] <= -0.01)
    # A high finite cost steers it the same way; a low one is crossed (the detour is
    # 4.5 mm longer, the band 8 mm wide: crossing costs 8 mm x 0.1 = 0.8 mm extra).
    high = shortest_grid_path(top_grid, _wall_cost(top_grid, 100.0))
    assert_close(high.length_m, WALL_GAP_PATH_M, atol=0, rtol=0.03)
    low = shortest_grid_path(top_grid, _wall_cost(top_grid, 0.1))
    assert_close(low.length_m, 0.05, atol=1e-12)
    assert low.cost > low.length_m


def test_path_cost_is_the_sum_of_the_edge_weights(top_grid):
    rng = np.random.default_rng(5)
    cost = rng.uniform(0.0, 2.0, size=len(top_grid))
    path = shortest_grid_path(top_grid, cost, cost_weight=0.7)
    seg = np.linalg.norm(np.diff(path.uv, axis=0), axis=1)
    expected = np.sum(seg * (1 + 0.7 * 0.5 * (cost[path.nodes[:-1]] + cost[path.nodes[1:]])))
    # the search sums weights rounded to whole quanta: half a quantum per edge at most
    assert_close(path.cost, expected, atol=0.5 * WEIGHT_QUANTUM_M * len(path))
    weights = edge_weights(top_grid, cost, cost_weight=0.7)
    assert np.all(weights >= top_grid.edge_lengths_m)


def test_equal_routes_tie_exactly_whatever_the_rounding(top_grid):
    # without node costs many routes from P to Q are equally long; costs of 1e-12 (what
    # IK noise leaves) move their weights' last bits, which must not pick the winner
    reference = shortest_grid_path(top_grid, np.zeros(len(top_grid)))
    rng = np.random.default_rng(11)
    for _ in range(20):
        noise = 1e-12 * rng.uniform(0.0, 1.0, size=len(top_grid))
        path = shortest_grid_path(top_grid, noise, cost_weight=1.0)
        assert np.array_equal(path.nodes, reference.nodes)


def test_unreachable_q_raises_planning_error(top_grid):
    with pytest.raises(PlanningError, match="unreachable"):
        shortest_grid_path(top_grid, _wall_cost(top_grid, np.inf, gap=False))
    cost = np.zeros(len(top_grid))
    cost[top_grid.q_index] = np.inf
    with pytest.raises(PlanningError, match="Q has an infinite"):
        shortest_grid_path(top_grid, cost)


def test_bad_node_cost_is_refused(top_grid):
    m = len(top_grid)
    for bad, word in (
        (np.full(m, np.nan), "NaN"),
        (-np.ones(m), "negative"),
        (np.zeros(m + 1), "shape"),
    ):
        with pytest.raises(InputError, match=word) as err:
            shortest_grid_path(top_grid, bad)
        assert err.value.argument == "node_cost"
    with pytest.raises(InputError) as err:
        shortest_grid_path(top_grid, np.zeros(m), cost_weight=-1.0)
    assert err.value.argument == "cost_weight"
