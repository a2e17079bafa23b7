"""Unfolded surface grid (regrasp_pin.surface.grid).

Box of 60 x 40 x 40 mm: x in [-30, 30] mm, y and z in [-20, 20] mm. Geodesics across
box edges are checked against the unfolded straight line computed by hand.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from regrasp_pin.exceptions import InputError, UnfoldError
from regrasp_pin.model.objects import Box, ConvexMesh, Prism
from regrasp_pin.surface.grid import build_surface_grid
from regrasp_pin.surface.path import shortest_grid_path
from tests.conftest import assert_close, face_with_normal

SPACING = 0.002


@pytest.fixture(scope="module")
def box() -> Box:
    return Box((0.06, 0.04, 0.04))


@pytest.fixture(scope="module")
def mesh() -> ConvexMesh:
    return ConvexMesh(np.random.default_rng(7).normal(size=(30, 3)) * 0.03)


@pytest.fixture(scope="module")
def prism() -> Prism:
    return Prism(6, 0.03, 0.05)


def _random_in_face(face, rng, n) -> np.ndarray:
    """Random points of a convex face: convex combinations of its vertices."""
    w = rng.dirichlet(np.ones(face.polygon.shape[0]), size=n)
    return w @ face.polygon


# ---------------------------------------------------------------------- region + grid
def test_top_to_side_geodesic_is_the_unfolded_straight_line(box):
    """P on the top, Q on the +x side 20 mm below the top edge: unfolding the side about
    the top's +x edge puts Q at (30 + 20, -10) mm, so the geodesic is hypot(50, 15) mm."""
    P, Q = np.array([0.0, 0.005, 0.02]), np.array([0.03, -0.01, 0.0])
    grid = build_surface_grid(box, P, Q, spacing_m=SPACING)
    expected = math.hypot(0.05, 0.015)
    top, side = face_with_normal(box, [0, 0, 1]), face_with_normal(box, [1, 0, 0])
    assert grid.face_chain == (top, side)
    assert_close(
        np.linalg.norm(grid.uv[grid.q_index] - grid.uv[grid.p_index]),
        expected,
        atol=1e-12,
        what="unfolded P-Q distance",
    )
    assert_close(grid.geodesic_m, expected, atol=1e-12)
    path = shortest_grid_path(grid)
    assert expected - 1e-12 <= path.length_m <= 1.03 * expected
    assert path.face_ids[0] == top and path.face_ids[-1] == side


def test_top_to_bottom_goes_over_the_nearest_side(box):
    """P and Q 10 mm from the +x end on top and bottom: over the +x face the route is
    10 + 40 + 10 = 60 mm (over a y face it would be 20 + 40 + 20 = 80 mm)."""
    P, Q = np.array([0.02, 0.0, 0.02]), np.array([0.02, 0.0, -0.02])
    grid = build_surface_grid(box, P, Q, spacing_m=SPACING)
    assert grid.face_chain[1] == face_with_normal(box, [1, 0, 0])
    assert_close(grid.geodesic_m, 0.06, atol=1e-12)
    path = shortest_grid_path(grid)
    assert 0.06 - 1e-12 <= path.length_m <= 1.03 * 0.06
    with pytest.raises(UnfoldError, match="region cannot be unfolded"):
        build_surface_grid(box, P, Q, spacing_m=SPACING, max_faces=2)


def test_point_on_an_edge_may_use_either_face(box):
    """P on the top/+x edge and Q on the +x face share the +x face: one face, straight."""
    P, Q = np.array([0.03, 0.0, 0.02]), np.array([0.03, 0.01, -0.01])
    grid = build_surface_grid(box, P, Q, spacing_m=SPACING)
    assert grid.face_chain == (face_with_normal(box, [1, 0, 0]),)
    assert_close(grid.geodesic_m, np.linalg.norm(Q - P), atol=1e-12)


@pytest.mark.parametrize("name", ["box", "prism", "mesh"])
def test_nodes_and_mapped_points_lie_on_their_faces(name, request):
    obj = request.getfixturevalue(name)
    sample = obj.sample_surface(0.01)
    rng = np.random.default_rng(3)
    for _ in range(3):
        i = rng.integers(len(sample))
        dist = np.linalg.norm(sample.points - sample.points[i], axis=1)
        j = rng.choice(np.flatnonzero((dist > 0.015) & (dist < 0.03)))  # a few faces away
        grid = build_surface_grid(obj, sample.points[i], sample.points[j], spacing_m=SPACING)
        assert np.max(np.abs(obj.signed_distance(grid.points_object))) < 1e-9
        _assert_on_faces(obj, grid.points_object, grid.face_ids)
        assert_close(grid.normals_object, obj.normals[grid.face_ids], atol=0)
        assert_close(grid.to_object(grid.uv, grid.face_ids)[0], grid.points_object, atol=1e-15)
        assert_close(grid.P_object, sample.points[i], atol=1e-12, what="P node")
        assert_close(grid.Q_object, sample.points[j], atol=1e-12, what="Q node")
        # Random points of the unfolded region map onto the surface, on their face.
        lo, hi = grid.uv.min(axis=0), grid.uv.max(axis=0)
        uv = rng.uniform(lo, hi, size=(2000, 2))
        uv = uv[grid.contains(uv)]
        pts, nrm, fid = grid.to_object(uv)
        assert np.max(np.abs(obj.signed_distance(pts))) < 1e-9
        _assert_on_faces(obj, pts, fid)


def _assert_on_faces(obj, pts, face_ids):
    plane = np.einsum("nd,nd->n", pts, obj.normals[face_ids]) - obj.offsets[face_ids]
    assert np.max(np.abs(plane)) < 1e-12
    for f in np.unique(face_ids):
        face = obj.faces[f]
        assert np.all(face.contains_uv(face.to_uv(pts[face_ids == f]), -1e-9))


def test_edges_stay_inside_the_region_and_use_the_16_stencil(box):
    P, Q = np.array([-0.025, 0.0, 0.02]), np.array([0.025, 0.0, 0.02])
    grid = build_surface_grid(box, P, Q, spacing_m=SPACING)
    assert len(grid.unfoldings) == 5  # the top face and its four neighbours
    a, b = grid.uv[grid.edges[:, 0]], grid.uv[grid.edges[:, 1]]
    assert_close(grid.edge_lengths_m, np.linalg.norm(b - a, axis=1), atol=0)
    for t in np.linspace(0.05, 0.95, 10):
        assert np.all(grid.contains(a + t * (b - a))), f"an edge leaves the region at t={t}"
    lattice = ~np.isin(grid.edges, [grid.q_index]).any(axis=1)
    assert np.max(grid.edge_lengths_m[lattice]) <= math.sqrt(5) * SPACING * (1 + 1e-9)
    assert np.max(grid.edge_lengths_m[~lattice]) <= 2 * SPACING * (1 + 1e-9)
    degree = np.bincount(grid.edges[lattice].ravel(), minlength=len(grid))
    assert degree.max() == 16
    centre = np.argmin(np.linalg.norm(grid.points_object - [0.0, 0.0, 0.02], axis=1))
    assert degree[centre] == 16
    # Edges between faces are surface paths of the edge's length: map 400 points of each
    # back to 3-D and sum the chords (a chord across the 90-degree edge cuts at most
    # 0.3 x 1/400 of the edge).
    cross = np.flatnonzero(grid.face_ids[grid.edges[:, 0]] != grid.face_ids[grid.edges[:, 1]])
    assert cross.size > 50
    t = np.linspace(0.0, 1.0, 401)
    for e in cross[:: max(1, cross.size // 40)]:
        seg = a[e] + t[:, None] * (b[e] - a[e])
        pts = grid.to_object(seg)[0]
        length = np.linalg.norm(np.diff(pts, axis=0), axis=1).sum()
        assert_close(length, grid.edge_lengths_m[e], atol=0, rtol=1e-3, what=f"edge {e}")


def test_no_edge_jumps_the_gap_between_unfolded_neighbours(box):
    """Around the top face the unfolded sides leave empty corner squares: no edge may
    cross one (its midpoint would lie outside every face)."""
    grid = build_surface_grid(box, np.array([0.02, 0.01, 0.02]), np.array([0.025, 0.015, 0.02]))
    mid = 0.5 * (grid.uv[grid.edges[:, 0]] + grid.uv[grid.edges[:, 1]])
    assert np.all(grid.contains(mid))
    corners = np.array([u.polygon_uv for u in grid.unfoldings[:1]])[0]
    # Points just outside a corner of the top face, diagonally, are outside the region.
    out = corners * (1 + 1e-3)
    assert not np.any(grid.contains(out))


def test_geodesic_bounds_on_random_pairs(box, mesh):
    """A surface route is at least the straight 3-D distance; the grid path is at least
    the region's geodesic and within 3 % (plus two steps for the ends) of it."""
    rng = np.random.default_rng(11)
    for obj in (box, mesh):
        sample = obj.sample_surface(0.004)
        for _ in range(8):
            i, j = rng.choice(len(sample), size=2, replace=False)
            P, Q = sample.points[i], sample.points[j]
            try:
                grid = build_surface_grid(obj, P, Q, spacing_m=SPACING)
            except UnfoldError:
                continue  # farther than max_faces faces apart
            assert grid.geodesic_m >= np.linalg.norm(Q - P) - 1e-12
            path = shortest_grid_path(grid)
            assert grid.geodesic_m - 1e-12 <= path.length_m
            assert path.length_m <= 1.03 * grid.geodesic_m + 2 * SPACING


# ---------------------------------------------------------------------- bad input
def test_points_off_the_surface_are_refused(box):
    on = np.array([0.0, 0.0, 0.02])
    with pytest.raises(InputError, match="not on the object surface") as err:
        build_surface_grid(box, np.array([0.0, 0.0, 0.025]), on)
    assert err.value.argument == "P_object" and "0.005" in str(err.value)
    with pytest.raises(InputError, match="not on the object surface") as err:
        build_surface_grid(box, on, np.array([0.0, 0.0, 0.0]))
    assert err.value.argument == "Q_object"
    with pytest.raises(InputError) as err:
        build_surface_grid(box, np.array([0.0, np.nan, 0.02]), on)
    assert err.value.argument == "P_object"


def test_coinciding_points_and_bad_parameters_are_refused(box):
    P = np.array([0.0, 0.0, 0.02])
    with pytest.raises(InputError, match="coincide") as err:
        build_surface_grid(box, P, P + [0.0005, 0.0, 0.0])
    assert err.value.argument == "Q_object"
    Q = np.array([0.01, 0.0, 0.02])
    for bad in (0.0, -0.001, np.nan):
        with pytest.raises(InputError) as err:
            build_surface_grid(box, P, Q, spacing_m=bad)
        assert err.value.argument == "spacing_m"
    with pytest.raises(InputError) as err:
        build_surface_grid(box, P, Q, max_faces=0)
    assert err.value.argument == "max_faces"
    for bad in ((0.5, 0.0), (2.0, -0.01), (2.0, np.inf), 2.0, ("a", 1.0)):
        with pytest.raises(InputError) as err:
            build_surface_grid(box, P, Q, max_detour=bad)
        assert err.value.argument == "max_detour"


@pytest.mark.parametrize(
    ("P", "Q"),
    [((-0.02, -0.01, 0.02), (0.02, 0.015, 0.02)), ((-0.01, 0.0, 0.02), (0.025, 0.02, -0.01))],
)
def test_detour_ellipse_is_the_full_grid_cut_to_it(box, P, Q):
    # the nodes kept are the full grid's nodes within the ellipse, in the same order,
    # with the edges among them; the shortest path is that of the full grid whose
    # nodes outside the ellipse are forbidden
    P, Q = np.array(P), np.array(Q)
    full = build_surface_grid(box, P, Q)
    cut = build_surface_grid(box, P, Q, max_detour=(1.3, 0.004))
    uvP, uvQ = full.uv[full.p_index], full.uv[full.q_index]
    reach = 1.3 * np.linalg.norm(uvQ - uvP) + 0.004
    inside = np.linalg.norm(full.uv - uvP, axis=1) + np.linalg.norm(full.uv - uvQ, axis=1)
    inside = inside <= reach
    assert 10 < inside.sum() < 0.8 * len(full)
    assert np.array_equal(cut.uv, full.uv[inside])
    assert np.array_equal(cut.points_object, full.points_object[inside])
    renumber = np.cumsum(inside) - 1
    kept = inside[full.edges].all(axis=1)
    assert np.array_equal(cut.edges, renumber[full.edges[kept]])
    cost = np.where(inside, 0.0, np.inf)
    a, b = shortest_grid_path(full, cost), shortest_grid_path(cut)
    assert np.array_equal(np.flatnonzero(inside)[b.nodes], a.nodes)
