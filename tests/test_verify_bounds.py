"""The re-check's lower bounds of Coal's signed distance (regrasp_pin.verify._bounds).

Every bound must stay below Coal's distance for any placement, penetrating ones
included (random placements of every pair of the supported shapes, seeded), and be
exact where the geometry says it is (two spheres, two capsules, boxes face to face).
"""

from __future__ import annotations

import numpy as np
import pytest


def _shapes() -> dict:
    """One Coal shape of each kind the bounds know, and a convex mesh (their fallback)."""
    import coal

    rng = np.random.default_rng(3)
    pts = coal.StdVec_Vec3s()
    pts.extend(list(rng.normal(scale=0.02, size=(12, 3))))
    return {
        "sphere": coal.Sphere(0.008),
        "capsule": coal.Capsule(0.006, 0.03),
        "cylinder": coal.Cylinder(0.007, 0.04),
        "box": coal.Box(0.0196, 0.0275, 0.054),
        "convex": coal.Convex.convexHull(pts, False, None),
    }


def _placed(shape, R: np.ndarray, x: np.ndarray):
    """The bounds' description ``(N,)`` of one shape at rotations ``R`` and positions ``x``."""
    from regrasp_pin.verify._bounds import Shapes

    return Shapes.of([shape]).placed(R[:, None], x[:, None])[:, 0]


def _coal(a, Ra, xa, b, Rb, xb) -> np.ndarray:
    """Coal's signed distances ``(N,)`` [m] of two shapes at ``N`` placements."""
    import coal

    return np.array(
        [
            coal.distance(
                a,
                coal.Transform3s(Ra[i], xa[i]),
                b,
                coal.Transform3s(Rb[i], xb[i]),
                coal.DistanceRequest(),
                coal.DistanceResult(),
            )
            for i in range(len(xa))
        ]
    )


def _random_poses(rng, n: int, spread: float) -> tuple[np.ndarray, np.ndarray]:
    from scipy.spatial.transform import Rotation

    return Rotation.random(n, random_state=rng).as_matrix(), rng.uniform(-spread, spread, (n, 3))


PAIRS = [
    (a, b)
    for i, a in enumerate(["sphere", "capsule", "cylinder", "box", "convex"])
    for b in ["sphere", "capsule", "cylinder", "box", "convex"][i:]
]


@pytest.mark.parametrize(("kind_a", "kind_b"), PAIRS)
def test_pair_bounds_are_below_coal(kind_a, kind_b):
    """The sphere bound and the tighter pair bound stay below Coal's signed distance for
    random placements of every pair of shape kinds, penetrating ones included (the
    margin is Coal's tolerance: the bounds without it are below Coal to roundoff)."""
    from regrasp_pin.verify._bounds import BOUND_MARGIN_M, pair_bound, sphere_bound

    shapes = _shapes()
    rng = np.random.default_rng(PAIRS.index((kind_a, kind_b)))
    (Ra, xa), (Rb, xb) = _random_poses(rng, 300, 0.03), _random_poses(rng, 300, 0.03)
    a, b = _placed(shapes[kind_a], Ra, xa), _placed(shapes[kind_b], Rb, xb)
    d = _coal(shapes[kind_a], Ra, xa, shapes[kind_b], Rb, xb)
    assert (d < 0).sum() >= 10 and (d > 0).sum() >= 10  # both sides of contact
    tight, loose = pair_bound(a, b), sphere_bound(a.c, a.rho, b.c, b.rho)
    assert np.all(tight <= d) and np.all(loose <= d)
    assert np.all(tight >= loose)  # the refinement is tighter
    assert np.all(tight + BOUND_MARGIN_M <= d + 1e-6)  # Coal's own tolerance


def test_pair_bounds_are_exact_where_they_should_be():
    """Two spheres or two capsules: the pair bound is Coal's distance (less the margin),
    apart or penetrating; two parallel boxes face to face and two parallel cylinders
    side by side: too."""
    from scipy.spatial.transform import Rotation

    from regrasp_pin.verify._bounds import BOUND_MARGIN_M, pair_bound

    shapes = _shapes()
    rng = np.random.default_rng(5)
    for kind in ("sphere", "capsule"):
        (Ra, xa), (Rb, xb) = _random_poses(rng, 200, 0.03), _random_poses(rng, 200, 0.03)
        d = _coal(shapes[kind], Ra, xa, shapes[kind], Rb, xb)
        assert (d < 0).any() and (d > 0).any()
        bound = pair_bound(_placed(shapes[kind], Ra, xa), _placed(shapes[kind], Rb, xb))
        assert bound + BOUND_MARGIN_M == pytest.approx(d, abs=1e-12)
    # the same rotation, apart along their x by 1 to 10 mm more than their half widths
    n = 50
    R = np.repeat(Rotation.random(random_state=rng).as_matrix()[None], n, axis=0)
    gap = rng.uniform(0.001, 0.010, n)
    slide = rng.uniform(-0.005, 0.005, n)  # along their z (a cylinder's axis)
    zero = np.zeros((n, 3))
    for kind, half_x in (("box", 0.0098), ("cylinder", 0.007)):
        xb = np.einsum("nij,nj->ni", R, np.column_stack([2 * half_x + gap, 0 * gap, slide]))
        shape = shapes[kind]
        d = _coal(shape, R, zero, shape, R, xb)
        bound = pair_bound(_placed(shape, R, zero), _placed(shape, R, xb))
        assert d == pytest.approx(gap, abs=1e-8)
        assert bound + BOUND_MARGIN_M == pytest.approx(gap, abs=1e-12)


def _prism() -> tuple[np.ndarray, object]:
    """A hexagonal prism's vertices ``(12, 3)`` [m] and its Coal convex hull."""
    import coal

    a = np.arange(6) * np.pi / 3
    verts = np.array([[0.03 * np.cos(t), 0.03 * np.sin(t), z] for z in (-0.02, 0.02) for t in a])
    pts = coal.StdVec_Vec3s()
    pts.extend(list(verts))
    return verts, coal.Convex.convexHull(pts, False, None)


@pytest.mark.parametrize("kind", ["sphere", "capsule", "cylinder", "box", "convex"])
def test_object_bounds_are_below_coal(kind):
    """The bound of a geometry against the object (a face plane of its hull) stays
    below Coal's signed distance for random placements of each shape kind and of the
    object, penetrating ones included."""
    from regrasp_pin.verify._bounds import BOUND_MARGIN_M, hull_planes, object_bound

    verts, obj = _prism()
    shape = _shapes()[kind]
    rng = np.random.default_rng(["sphere", "capsule", "cylinder", "box", "convex"].index(kind))
    (R, x), (Ro, xo) = _random_poses(rng, 300, 0.06), _random_poses(rng, 300, 0.01)
    d = _coal(shape, R, x, obj, Ro, xo)
    assert (d < 0).sum() >= 10 and (d > 0).sum() >= 10
    bound = object_bound(_placed(shape, R, x), Ro, xo, hull_planes(verts))
    assert np.all(bound <= d)
    assert np.all(bound + BOUND_MARGIN_M <= d + 1e-6)


def test_object_bound_is_exact_for_a_sphere_over_a_face():
    """A sphere over the middle of a face of the object, apart or sunk in: the bound is
    Coal's distance (less the margin)."""
    from regrasp_pin.verify._bounds import BOUND_MARGIN_M, hull_planes, object_bound

    verts, obj = _prism()
    sphere = _shapes()["sphere"]
    rng = np.random.default_rng(11)
    n = 100
    Ro, xo = _random_poses(rng, n, 0.01)
    height = rng.uniform(-0.004, 0.010, n)  # of the sphere's surface over the top face
    x_obj = np.column_stack([rng.uniform(-0.01, 0.01, (n, 2)), 0.02 + 0.008 + height])
    x = np.einsum("nij,nj->ni", Ro, x_obj) + xo
    R = np.repeat(np.eye(3)[None], n, axis=0)
    d = _coal(sphere, R, x, obj, Ro, xo)
    assert d == pytest.approx(height, abs=1e-6)  # EPA's tolerance when sunk in
    bound = object_bound(_placed(sphere, R, x), Ro, xo, hull_planes(verts))
    assert bound + BOUND_MARGIN_M == pytest.approx(height, abs=1e-12)
