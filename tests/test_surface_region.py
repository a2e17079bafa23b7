"""The region that holds P and Q (regrasp_pin.surface.region).

Box of 60 x 40 x 40 mm: x in [-30, 30] mm, y and z in [-20, 20] mm; geodesics across
its edges are the unfolded straight lines, computed by hand.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from regrasp_pin.exceptions import InputError, UnfoldError
from regrasp_pin.model.objects import Box
from regrasp_pin.surface.region import choose_region
from tests.conftest import assert_close, face_with_normal


@pytest.fixture(scope="module")
def box() -> Box:
    return Box((0.06, 0.04, 0.04))


def test_one_face_with_and_without_its_neighbours(box):
    P, Q = np.array([-0.01, 0.0, 0.02]), np.array([0.02, 0.01, 0.02])
    top = face_with_normal(box, [0, 0, 1])
    alone = choose_region(box, P, Q, max_faces=4, include_neighbours=False)
    assert alone.chain == (top,) and len(alone.pieces) == 1
    assert_close(alone.geodesic_m, float(np.linalg.norm(Q - P)), atol=1e-12)
    assert_close(np.linalg.norm(alone.q_uv - alone.p_uv), np.linalg.norm(Q - P), atol=1e-12)
    star = choose_region(box, P, Q, max_faces=4, include_neighbours=True)
    assert star.chain == (top,)
    assert sorted(p.face_id for p in star.pieces[1:]) == sorted(
        face_with_normal(box, n) for n in ([1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0])
    )


def test_the_chain_with_the_shortest_route_is_chosen(box):
    """P and Q 10 mm from the +x end on top and bottom: over the +x face the route is
    10 + 40 + 10 = 60 mm; over a y face it would be 20 + 40 + 20 = 80 mm."""
    P, Q = np.array([0.02, 0.0, 0.02]), np.array([0.02, 0.0, -0.02])
    region = choose_region(box, P, Q, max_faces=4, include_neighbours=True)
    assert region.chain == (
        face_with_normal(box, [0, 0, 1]),
        face_with_normal(box, [1, 0, 0]),
        face_with_normal(box, [0, 0, -1]),
    )
    assert_close(region.geodesic_m, 0.06, atol=1e-12)
    with pytest.raises(UnfoldError, match="region cannot be unfolded"):
        choose_region(box, P, Q, max_faces=2, include_neighbours=True)


def test_adjacent_faces_unfold_to_the_straight_line(box):
    P, Q = np.array([0.0, 0.005, 0.02]), np.array([0.03, -0.01, 0.0])
    region = choose_region(box, P, Q, max_faces=4, include_neighbours=True)
    assert region.chain == (face_with_normal(box, [0, 0, 1]), face_with_normal(box, [1, 0, 0]))
    assert_close(region.geodesic_m, math.hypot(0.05, 0.015), atol=1e-12)


def test_a_point_off_the_surface_is_named(box):
    with pytest.raises(InputError, match="Q_object"):
        choose_region(box, np.array([0.0, 0.0, 0.02]), np.zeros(3), 4, True)
