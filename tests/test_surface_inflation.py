"""Virtual inflation (regrasp_pin.surface.inflation) and the Fig. 4 plot
(regrasp_pin.plotting.surface).

The tip centre must stay exactly ``tip_radius + h`` from the convex object (checked with
the object's exact signed distance), touch down at P and Q, and move in steps no longer
than ``step_m``, also where it turns about an edge.
"""

from __future__ import annotations

import numpy as np
import pytest

from regrasp_pin.exceptions import InputError
from regrasp_pin.model.objects import Box, ConvexMesh, Prism
from regrasp_pin.surface.grid import build_surface_grid
from regrasp_pin.surface.inflation import grid_inflation, inflate_path, inflation_height
from regrasp_pin.surface.path import shortest_grid_path
from tests.conftest import assert_close

TIP_M = 0.008
CLEARANCE_M = 0.005
STEP_M = 0.001


@pytest.fixture(scope="module")
def box() -> Box:
    return Box((0.06, 0.04, 0.04))


def _path(obj, P, Q, node_cost=None):
    grid = build_surface_grid(obj, np.asarray(P, float), np.asarray(Q, float), spacing_m=0.002)
    return grid, shortest_grid_path(grid, node_cost)


def _cases():
    """(name, object, P, Q): one face, one edge, two edges, a prism and a convex hull."""
    box = Box((0.06, 0.04, 0.04))
    prism = Prism(6, 0.03, 0.05)
    mesh = ConvexMesh(np.random.default_rng(7).normal(size=(30, 3)) * 0.03)
    ps, ms = prism.sample_surface(0.01), mesh.sample_surface(0.01)
    far = np.argmax(
        np.linalg.norm(ps.points - ps.points[0], axis=1)
        * (np.linalg.norm(ps.points - ps.points[0], axis=1) < 0.06)
    )
    d = np.linalg.norm(ms.points - ms.points[0], axis=1)
    near = int(np.argmax(np.where(d < 0.035, d, 0)))
    return [
        ("box one face", box, [-0.025, 0.0, 0.02], [0.025, 0.0, 0.02]),
        ("box top to side", box, [0.0, 0.005, 0.02], [0.03, -0.01, 0.0]),
        ("box top to bottom", box, [0.02, 0.0, 0.02], [0.02, 0.0, -0.02]),
        ("prism", prism, ps.points[0], ps.points[far]),
        ("convex mesh", mesh, ms.points[0], ms.points[near]),
    ]


CASES = _cases()


# ---------------------------------------------------------------------- height field
def test_inflation_height_is_a_smoothstep_from_p_and_q():
    """h = c (3x^2 - 2x^3), x = min(dP, dQ) / taper clipped to [0, 1]."""
    c, taper = 0.004, 0.01
    d = np.array([0.0, 0.0025, 0.005, 0.01, 0.02])
    expected = c * np.array([0.0, 0.15625, 0.5, 1.0, 1.0])  # x = 0, 1/4, 1/2, 1, 2
    assert_close(inflation_height(d, 1.0, clearance_m=c, taper_m=taper), expected, atol=1e-15)
    assert_close(inflation_height(1.0, d, clearance_m=c, taper_m=taper), expected, atol=1e-15)
    x = np.linspace(0, 0.02, 2001)
    h = inflation_height(x, 0.04 - x, clearance_m=c, taper_m=taper)
    assert np.all(np.diff(h[x <= 0.01]) >= 0)
    # Its steepest slope is 1.5 c / taper (at x = 1/2), which bounds the resampling step.
    assert_close(np.max(np.diff(h) / np.diff(x)), 1.5 * c / taper, atol=0, rtol=1e-4)


def test_grid_inflation_is_zero_at_p_and_q_and_full_in_between(box):
    grid, _ = _path(box, [-0.025, 0.0, 0.02], [0.025, 0.0, 0.02])
    h = grid_inflation(grid, CLEARANCE_M, 0.01)
    assert h[grid.p_index] == 0.0 and h[grid.q_index] == 0.0
    d_p = np.linalg.norm(grid.uv - grid.uv[grid.p_index], axis=1)
    d_q = np.linalg.norm(grid.uv - grid.uv[grid.q_index], axis=1)
    assert_close(h[np.minimum(d_p, d_q) >= 0.01], CLEARANCE_M, atol=0)
    assert h.min() >= 0.0 and h.max() <= CLEARANCE_M


# ---------------------------------------------------------------------- tip path
@pytest.mark.parametrize(("name", "obj", "P", "Q"), CASES, ids=[c[0] for c in CASES])
def test_tip_path_stays_exactly_at_radius_plus_height(name, obj, P, Q):
    grid, path = _path(obj, P, Q)
    tip = inflate_path(obj, path, tip_radius_m=TIP_M, clearance_m=CLEARANCE_M, step_m=STEP_M)
    # Exactly tip_radius + h from the object everywhere, on the arcs about edges too.
    dist = obj.signed_distance(tip.points_object)
    assert_close(dist, TIP_M + tip.height_m, atol=1e-9, what=f"{name}: tip distance")
    # Lift-off at P and landing at Q: the tip touches the surface there.
    n_p, n_q = grid.normals_object[grid.p_index], grid.normals_object[grid.q_index]
    assert_close(tip.points_object[0], grid.P_object + TIP_M * n_p, atol=1e-15)
    assert_close(tip.points_object[-1], grid.Q_object + TIP_M * n_q, atol=1e-15)
    assert tip.height_m[0] == 0.0 and tip.height_m[-1] == 0.0
    # Continuous: no step longer than step_m, across edges included.
    steps = np.linalg.norm(np.diff(tip.points_object, axis=0), axis=1)
    assert steps.max() <= STEP_M * (1 + 1e-9)
    # The surface trace is the grid path: same length, arc length running from 0 to it.
    trace = np.linalg.norm(np.diff(tip.surface_points_object, axis=0), axis=1).sum()
    assert_close(trace, path.length_m, atol=1e-12, what=f"{name}: surface length")
    assert np.all(np.diff(tip.arc_length_m) >= 0)
    assert_close(tip.arc_length_m[[0, -1]], [0.0, path.length_m], atol=1e-15)
    # Away from the arcs the offset direction is the face normal.
    on_face = tip.face_ids >= 0
    assert_close(tip.normals_object[on_face], obj.normals[tip.face_ids[on_face]], atol=0)
    # One arc per edge crossed, and the path is long enough to reach full clearance.
    crossings = len(grid.face_chain) - 1
    assert np.count_nonzero(np.diff(tip.face_ids[on_face]) != 0) == crossings
    assert (tip.face_ids < 0).any() == (crossings > 0)
    assert path.length_m > 2 * CLEARANCE_M
    assert_close(tip.height_m.max(), CLEARANCE_M, atol=1e-12)


def test_arc_about_a_box_edge_turns_the_normal_by_90_degrees(box):
    _, path = _path(box, [0.0, 0.005, 0.02], [0.03, -0.01, 0.0])
    tip = inflate_path(box, path, tip_radius_m=TIP_M, clearance_m=CLEARANCE_M, step_m=STEP_M)
    arc = np.flatnonzero(tip.face_ids < 0)
    block = np.arange(arc[0] - 1, arc[-1] + 2)  # the face points on both sides
    assert_close(tip.surface_points_object[block, 0], 0.03, atol=1e-15, what="on the edge")
    assert_close(tip.surface_points_object[block, 2], 0.02, atol=1e-15, what="on the edge")
    angle = np.arccos(np.clip(tip.normals_object[block[0]] @ tip.normals_object[block[-1]], -1, 1))
    assert_close(angle, np.pi / 2, atol=1e-12)
    # The arc's chord steps at radius r + h stay below step_m: ceil(pi/2 (r+h) / step) pieces.
    expected = int(np.ceil(np.pi / 2 * (TIP_M + tip.height_m[arc[0]]) / STEP_M))
    assert block.size == expected + 1


def test_node_costs_route_the_tip_path_too(box):
    grid, _ = _path(box, [-0.025, 0.0, 0.02], [0.025, 0.0, 0.02])
    wall = (np.abs(grid.points_object[:, 0]) < 0.004) & (grid.points_object[:, 1] > -0.01)
    path = shortest_grid_path(grid, np.where(wall, np.inf, 0.0))
    tip = inflate_path(box, path, tip_radius_m=TIP_M, clearance_m=CLEARANCE_M)
    assert_close(box.signed_distance(tip.points_object), TIP_M + tip.height_m, atol=1e-9)
    # Node costs forbid nodes, not the space between them: the lattice runs through
    # x = -25 + 2k mm, y = 2k mm, so the forbidden nodes with |x| <= 3 mm are those with
    # y >= -8 mm. A knight move between allowed nodes, e.g. (-5, -8) -> (-1, -10) mm,
    # passes at most half a step (1 mm) above the gap's edge y = -10 mm.
    middle = np.abs(tip.surface_points_object[:, 0]) <= 0.003 + 1e-12
    assert middle.any()
    assert np.all(tip.surface_points_object[middle, 1] <= -0.01 + 0.001 + 1e-12)
    on_nodes = np.abs(tip.surface_points_object[:, 0]) <= 0.001 + 1e-12
    assert np.all(tip.surface_points_object[on_nodes, 1] <= -0.01 + 1e-12)


def test_lift_off_from_an_edge_into_the_other_face_starts_with_an_arc(box):
    """P on the top/+x edge is assigned to the top; when costs push the path down the
    +x face first, the tip still starts at P + r n_top and turns about the edge."""
    grid = build_surface_grid(box, np.array([0.03, 0.0, 0.02]), np.array([-0.02, 0.0, 0.02]))
    x = grid.points_object
    blocked = (x[:, 0] > 0.02) & (np.abs(x[:, 1]) < 0.01) & (x[:, 2] > 0.02 - 1e-12)
    cost = np.where(blocked, np.inf, 0.0)
    cost[grid.p_index] = 0.0
    path = shortest_grid_path(grid, cost)
    top, side = grid.face_ids[grid.p_index], int(np.argmax(box.normals @ [1.0, 0.0, 0.0]))
    assert path.face_ids[1] == side
    tip = inflate_path(box, path, tip_radius_m=TIP_M, clearance_m=CLEARANCE_M)
    assert_close(tip.points_object[0], grid.P_object + TIP_M * box.normals[top], atol=1e-15)
    assert tip.face_ids[0] == top and tip.face_ids[1] == -1
    assert_close(box.signed_distance(tip.points_object), tip.offset_m, atol=1e-9)
    assert np.max(np.linalg.norm(np.diff(tip.points_object, axis=0), axis=1)) <= STEP_M


def test_taper_defaults_to_the_clearance(box):
    _, path = _path(box, [-0.025, 0.0, 0.02], [0.025, 0.0, 0.02])
    tip = inflate_path(box, path, tip_radius_m=TIP_M, clearance_m=CLEARANCE_M)
    assert tip.taper_m == CLEARANCE_M
    s = tip.arc_length_m
    expected = inflation_height(s, path.length_m - s, clearance_m=CLEARANCE_M, taper_m=CLEARANCE_M)
    assert_close(tip.height_m, expected, atol=0)
    assert_close(tip.offset_m, TIP_M + expected, atol=0)


def test_bad_inflation_inputs_name_the_argument(box):
    _, path = _path(box, [-0.025, 0.0, 0.02], [0.025, 0.0, 0.02])
    good = {"tip_radius_m": TIP_M, "clearance_m": CLEARANCE_M}
    for arg in ("tip_radius_m", "clearance_m", "taper_m", "step_m"):
        for bad in (0.0, -0.001):
            with pytest.raises(InputError) as err:
                inflate_path(box, path, **{**good, arg: bad})
            assert err.value.argument == arg
    with pytest.raises(InputError) as err:
        inflation_height(0.01, 0.01, clearance_m=0.0, taper_m=0.01)
    assert err.value.argument == "clearance_m"
    with pytest.raises(InputError, match="does not lie on obj") as err:
        inflate_path(Box((0.06, 0.04, 0.03)), path, **good)
    assert err.value.argument == "path"


# ---------------------------------------------------------------------- Fig. 4 plot
def test_plot_unfolded_grid_draws_region_path_and_polygon(box):
    pytest.importorskip("matplotlib")
    from regrasp_pin.plotting.surface import plot_unfolded_grid

    grid, path = _path(box, [0.0, 0.005, 0.02], [0.03, -0.01, 0.0])
    tip = inflate_path(box, path, tip_radius_m=TIP_M, clearance_m=CLEARANCE_M)
    heights = grid_inflation(grid, CLEARANCE_M, CLEARANCE_M)
    waypoints = np.linspace(0, len(tip) - 1, 7).astype(int)
    fig = plot_unfolded_grid(grid, path, heights, waypoints, tip)
    ax = fig.axes[0]
    labels = [line.get_label() for line in ax.get_lines()]
    assert any(lb.startswith("grid path") for lb in labels)
    assert any(lb.startswith("polygon (7") for lb in labels)
    dashed = [line for line in ax.get_lines() if line.get_linestyle() == "--"]
    assert len(dashed) == len(grid.hinges_uv) == 1
    assert len(fig.axes) == 2  # the colour bar of the inflation height
    with pytest.raises(InputError) as err:
        plot_unfolded_grid(grid, path, polygon_indices=[0, len(path) + 3])
    assert err.value.argument == "polygon_indices"
    # zoomed (Fig. 8): a square frame around P, Q and the paths, the whole region inset
    fig = plot_unfolded_grid(grid, path, heights, waypoints, tip, zoom=True)
    ax = fig.axes[0]
    (x0, x1), (y0, y1) = ax.get_xlim(), ax.get_ylim()
    assert x1 - x0 == pytest.approx(y1 - y0)
    uv = np.vstack([path.uv, tip.uv]) * 1e3
    assert np.all((uv[:, 0] > x0) & (uv[:, 0] < x1) & (uv[:, 1] > y0) & (uv[:, 1] < y1))
    whole = np.vstack([u.polygon_uv for u in grid.unfoldings]) * 1e3
    assert np.ptp(whole[:, 0]) > x1 - x0  # the frame is a part of the region
    (inset,) = ax.child_axes
    assert inset.get_title() == "whole region"
    import matplotlib.pyplot as plt

    plt.close("all")
