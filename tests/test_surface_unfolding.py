"""Containment in the unfolded plane and the way back to the surface
(regrasp_pin.surface.unfolding).

Box of 60 x 40 x 40 mm: its top face unfolded alone is a 60 x 40 mm rectangle, so
depths and containment have closed forms.
"""

from __future__ import annotations

import numpy as np
import pytest

from regrasp_pin.exceptions import GeometryError
from regrasp_pin.model.objects import Box, ConvexMesh, Prism
from regrasp_pin.surface.unfolding import (
    depths,
    lift,
    polygons_overlap,
    segments_inside,
    unfold_faces,
)
from tests.conftest import assert_close, face_with_normal


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


def test_depth_is_the_distance_to_the_nearest_edge(box):
    (top,) = unfold_faces(box, [face_with_normal(box, [0, 0, 1])])
    centre = top.polygon_uv.mean(axis=0)
    rng = np.random.default_rng(0)
    uv = centre + rng.uniform([-0.03, -0.02], [0.03, 0.02], (200, 2))
    # the rectangle's axes in the unfolded plane: along its first edge and across it
    e1 = top.polygon_uv[1] - top.polygon_uv[0]
    e2 = top.polygon_uv[2] - top.polygon_uv[1]
    a, b = e1 / np.linalg.norm(e1), e2 / np.linalg.norm(e2)
    assert_close(a @ b, 0.0, atol=1e-12)  # a rectangle
    along, across = np.abs((uv - centre) @ a), np.abs((uv - centre) @ b)
    expected = np.minimum(np.linalg.norm(e1) / 2 - along, np.linalg.norm(e2) / 2 - across)
    inside = expected >= 0
    assert_close(depths(uv, [top])[inside, 0], expected[inside], atol=1e-12)
    assert np.all(depths(uv, [top])[~inside, 0] < 0)


def test_segments_inside_the_region_and_across_a_hinge(box):
    top_id, side_id = face_with_normal(box, [0, 0, 1]), face_with_normal(box, [1, 0, 0])
    top, side = unfold_faces(box, [top_id, side_id])
    a = top.polygon_uv.mean(axis=0)[None]
    b = side.polygon_uv.mean(axis=0)[None]
    # from the top's centre to the unfolded side's centre: through their shared edge
    assert segments_inside(a, b, [top, side]).tolist() == [True]
    # the same segment is not inside the top alone
    assert segments_inside(a, b, [top]).tolist() == [False]
    # far beyond the side: outside
    assert segments_inside(a, b + 10 * (b - a), [top, side]).tolist() == [False]


def test_polygons_overlap_but_not_when_they_only_touch():
    sq = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    assert polygons_overlap(sq, sq + [0.5, 0.5])
    assert not polygons_overlap(sq, sq + [1.0, 0.0])  # shared edge only
    assert not polygons_overlap(sq, sq + [2.0, 0.0])


@pytest.mark.parametrize("obj", [Box((0.06, 0.04, 0.04)), Prism(6, 0.03, 0.05)])
def test_lift_maps_unfolded_points_back_onto_their_faces(obj):
    """Unfold a face and each neighbour; points inside each unfolded polygon lifted back
    lie on the object's surface, on that face, where the face's own map puts them."""
    root = 0
    neighbours = sorted(
        a.face_b if a.face_a == root else a.face_a
        for a in obj.face_adjacency
        if root in (a.face_a, a.face_b)
    )
    pieces = unfold_faces(obj, [root, *neighbours], [None] + [root] * len(neighbours))
    rng = np.random.default_rng(1)
    for k, piece in enumerate(pieces):
        w = rng.dirichlet(np.ones(piece.polygon_uv.shape[0]), size=20)
        uv = w @ piece.polygon_uv
        points, normals, face_ids = lift(pieces, uv, np.full(uv.shape[0], k))
        assert np.all(face_ids == piece.face_id)
        assert_close(np.abs(obj.signed_distance(points)).max(), 0.0, atol=1e-12)
        assert_close(points, piece.to_object(uv), atol=1e-15)
        assert_close(
            normals, np.broadcast_to(obj.normals[piece.face_id], normals.shape), atol=1e-15
        )


@pytest.mark.parametrize("name", ["box", "prism", "mesh"])
def test_unfolding_across_each_edge_preserves_the_geodesic(name, request):
    """Two points on faces sharing an edge: their unfolded distance is the length of the
    straight surface line across the edge, hypot(a_p + a_q, alpha_p - alpha_q), where a is
    the distance to the edge line and alpha the coordinate along it."""
    obj = request.getfixturevalue(name)
    rng = np.random.default_rng(1)
    for adj in obj.face_adjacency:
        fa, fb = obj.faces[adj.face_a], obj.faces[adj.face_b]
        unf_a, unf_b = unfold_faces(obj, [adj.face_a, adj.face_b])
        p, q = _random_in_face(fa, rng, 5), _random_in_face(fb, rng, 5)
        e0 = adj.edge[0]
        e = (adj.edge[1] - adj.edge[0]) / np.linalg.norm(adj.edge[1] - adj.edge[0])
        alpha_p, alpha_q = (p - e0) @ e, (q - e0) @ e
        a_p = np.linalg.norm(p - e0 - alpha_p[:, None] * e, axis=1)
        a_q = np.linalg.norm(q - e0 - alpha_q[:, None] * e, axis=1)
        expected = np.hypot(a_p + a_q, alpha_p - alpha_q)
        got = np.linalg.norm(
            unf_a.to_unfolded(fa.to_uv(p)) - unf_b.to_unfolded(fb.to_uv(q)), axis=1
        )
        assert_close(got, expected, atol=1e-12, what=f"faces {adj.face_a}-{adj.face_b}")
        # The shared edge lands at the same place from both faces, and the round trip
        # unfolded -> object is exact.
        assert_close(unf_b.to_unfolded(fb.to_uv(adj.edge)), unf_b.hinge_uv, atol=1e-12)
        assert_close(unf_b.to_object(unf_b.to_unfolded(fb.to_uv(q))), q, atol=1e-12)


def test_unfold_rejects_faces_that_share_no_edge(box):
    top, bottom = face_with_normal(box, [0, 0, 1]), face_with_normal(box, [0, 0, -1])
    with pytest.raises(GeometryError, match="share no edge"):
        unfold_faces(box, [top, bottom])
