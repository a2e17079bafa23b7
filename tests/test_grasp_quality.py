"""Force closure and the Ferrari-Canny epsilon on known grasps of a box."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import assert_close
from scipy.optimize import linprog
from scipy.spatial import ConvexHull, QhullError

from regrasp_pin.exceptions import InputError
from regrasp_pin.grasp.quality import (
    FORCE_CLOSURE_TOL,
    _checked_epsilon,
    closure_certificate,
    contact_wrenches,
    ferrari_canny_epsilon,
    holding_fingers,
    is_force_closure,
)
from regrasp_pin.model.objects import Box

MU = 0.5
BOX = Box((0.06, 0.04, 0.04))
HALF = np.array([0.03, 0.02, 0.02])  # the box's half sides [m]
SCALE_M = BOX.radius_m

# Thumb on +x opposite two fingers on -x (normals are the box's OUTWARD normals).
TRIPOD_P = np.array([[0.03, 0.0, 0.0], [-0.03, 0.01, 0.01], [-0.03, -0.01, -0.01]])
TRIPOD_N = np.array([[1.0, 0, 0], [-1.0, 0, 0], [-1.0, 0, 0]])
PINCH_P = np.array([[0.03, 0.0, 0.0], [-0.03, 0.0, 0.0]])
PINCH_N = np.array([[1.0, 0, 0], [-1.0, 0, 0]])
# Two fingers on +x, two on -x, crossed.
QUAD_P = np.array([[0.03, 0.01, 0.0], [0.03, -0.01, 0.0], [-0.03, 0.0, 0.01], [-0.03, 0.0, -0.01]])
QUAD_N = np.array([[1.0, 0, 0], [1.0, 0, 0], [-1.0, 0, 0], [-1.0, 0, 0]])


def _resists(wrenches: np.ndarray, target: np.ndarray) -> bool:
    """Whether ``-target`` is a non-negative combination of the wrenches (an LP)."""
    res = linprog(
        np.ones(len(wrenches)), A_eq=wrenches.T, b_eq=-target, bounds=(0, None), method="highs"
    )
    return res.status == 0


def test_primitive_wrenches_push_into_the_object():
    w = contact_wrenches(TRIPOD_P, TRIPOD_N, MU, n_edges=6, torque_scale_m=SCALE_M)
    assert w.shape == (18, 6)
    f = w[:, :3].reshape(3, 6, 3)
    normal_part = -np.einsum("kmi,ki->km", f, TRIPOD_N)
    assert_close(normal_part, np.ones((3, 6)), atol=1e-15, what="unit inward normal force")
    tangential = np.linalg.norm(f + TRIPOD_N[:, None, :], axis=2)
    assert_close(tangential, np.full((3, 6), MU), atol=1e-15, what="on the cone")
    tau = np.cross(np.repeat(TRIPOD_P, 6, axis=0), w[:, :3]) / SCALE_M
    assert_close(w[:, 3:], tau, atol=1e-15, what="torque about the centre of mass")


def test_tripod_on_a_box_is_force_closure():
    eps = ferrari_canny_epsilon(TRIPOD_P, TRIPOD_N, MU, torque_scale_m=SCALE_M)
    assert eps > 0.01
    assert is_force_closure(TRIPOD_P, TRIPOD_N, MU)
    # Independent check by linear programming: any wrench of norm eps can be resisted.
    w = contact_wrenches(TRIPOD_P, TRIPOD_N, MU, torque_scale_m=SCALE_M)
    rng = np.random.default_rng(0)
    dirs = rng.normal(size=(20, 6))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    assert all(_resists(w, d) for d in dirs)


def _in_hull(wrenches: np.ndarray, x: np.ndarray) -> bool:
    """Whether x is a convex combination of the wrenches (an LP)."""
    n = len(wrenches)
    res = linprog(
        np.zeros(n),
        A_eq=np.vstack([wrenches.T, np.ones((1, n))]),
        b_eq=np.append(x, 1.0),
        bounds=(0, None),
        method="highs",
    )
    return res.status == 0


def test_epsilon_is_the_inscribed_ball_radius():
    w = contact_wrenches(QUAD_P, QUAD_N, MU, torque_scale_m=SCALE_M)
    eps = ferrari_canny_epsilon(QUAD_P, QUAD_N, MU, torque_scale_m=SCALE_M)
    # The ball lies inside the hull: the support function max_i w_i . d >= eps in every
    # direction d, and points at radius eps are convex combinations of the wrenches.
    rng = np.random.default_rng(1)
    d = rng.normal(size=(2000, 6))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    assert np.all(np.max(d @ w.T, axis=1) >= eps - 1e-12)
    assert all(_in_hull(w, 0.999 * eps * di) for di in d[:10])
    # And it is the largest such ball: along the nearest facet's normal the support
    # equals eps, so a slightly larger point there is outside the hull.
    hull = ConvexHull(w)
    a = hull.equations[np.argmin(-hull.equations[:, -1]), :6]
    assert_close(np.max(w @ a), eps, atol=1e-12, what="support along the nearest facet")
    assert _in_hull(w, 0.999 * eps * a)
    assert not _in_hull(w, 1.001 * eps * a)


def _merged_hull_epsilon(w: np.ndarray) -> float:
    """Epsilon from qhull's default hull (merged facets), the reference."""
    return max(float(np.min(-ConvexHull(w).equations[:, -1])), 0.0)


def test_epsilon_without_merged_facets_is_the_default_hulls():
    # random grasps of 3-5 contacts on a box's faces, point and soft: many sets in force
    # closure, others not, some degenerate (contacts sharing a face)
    rng = np.random.default_rng(7)
    checked = closing = 0
    for _ in range(150):
        k = int(rng.integers(3, 6))
        faces = rng.integers(0, 6, size=k)
        n = np.zeros((k, 3))
        n[np.arange(k), faces // 2] = np.where(faces % 2 == 0, 1.0, -1.0)
        p = rng.uniform(-1.0, 1.0, size=(k, 3)) * HALF
        p[n != 0] = (n * HALF)[n != 0]
        torsion = float(rng.choice([0.0, 0.002]))
        w = contact_wrenches(p, n, MU, torque_scale_m=SCALE_M, torsion_m=torsion)
        eps = ferrari_canny_epsilon(p, n, MU, torque_scale_m=SCALE_M, torsion_m=torsion)
        try:
            ref = _merged_hull_epsilon(w)
        except QhullError:  # the default hull raises on sets of fewer dimensions
            ref = 0.0
        assert_close(eps, ref, rtol=1e-9, atol=1e-15, what="epsilon against the merged hull")
        checked += 1
        closing += ref > FORCE_CLOSURE_TOL
    assert checked == 150 and 30 <= closing <= 140  # both kinds were exercised


def test_a_hull_whose_facet_leaves_a_wrench_outside_is_refused():
    w = contact_wrenches(QUAD_P, QUAD_N, MU, torque_scale_m=SCALE_M)
    hull = ConvexHull(w, qhull_options="Q0")
    eq, simplices = hull.equations.copy(), hull.simplices
    assert _checked_epsilon(w, eq, simplices) == pytest.approx(_merged_hull_epsilon(w), rel=1e-9)
    moved = eq.copy()
    moved[0, -1] -= 1e-9  # the plane pushed 1 nm inwards: its vertices lie outside it
    assert _checked_epsilon(w, moved, simplices) is None
    tilted = eq.copy()
    tilted[0, :6] = -tilted[0, :6]  # a flipped facet: the wrenches on its other side
    assert _checked_epsilon(w, tilted, simplices) is None


def test_antipodal_point_pinch_cannot_resist_torque_about_its_axis():
    """Two point contacts with friction span no torque about the line joining them.

    So a two-finger pinch with POINT contacts is not force closure in 6-D, whatever mu:
    epsilon is 0 (the 16 wrenches span 5 dimensions). With torsional (soft-finger)
    friction it is.
    """
    assert ferrari_canny_epsilon(PINCH_P, PINCH_N, MU) == 0.0
    assert not is_force_closure(PINCH_P, PINCH_N, 2.0)
    w = contact_wrenches(PINCH_P, PINCH_N, MU)
    assert np.linalg.matrix_rank(w) == 5
    assert_close(w[:, 3], np.zeros(len(w)), atol=1e-15, what="no torque about x")
    assert _resists(w, np.array([0, 0.1, 0, 0, 0, 0]))  # it does resist a sideways push
    assert ferrari_canny_epsilon(PINCH_P, PINCH_N, MU, torsion_m=0.005) > 0.01
    assert is_force_closure(PINCH_P, PINCH_N, MU, torsion_m=0.005)


def test_soft_finger_wrenches_lie_within_the_elliptic_limit_surface():
    """With torsional friction each contact adds two pure spins after its cone's edges
    (k * (n_edges + 2) wrenches); every wrench, split into the force's normal and
    tangential parts and the torque about the normal beyond ``p x f``, satisfies the
    soft-finger limit ``|f_t|^2 / mu^2 + tau_n^2 / torsion^2 <= f_n^2`` (an inner
    linearization: a grasp in force closure by it is by the elliptic model too)."""
    rng = np.random.default_rng(3)
    n = rng.normal(size=(4, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    p = -0.03 * n + rng.normal(scale=0.004, size=(4, 3))
    torsion, scale = 0.002, 0.04
    w = contact_wrenches(p, n, MU, n_edges=8, torque_scale_m=scale, torsion_m=torsion)
    assert w.shape == (4 * 10, 6)
    w = w.reshape(4, 10, 6)
    for i in range(4):
        f, tau = w[i, :, :3], w[i, :, 3:] * scale
        f_n = -(f @ n[i])
        f_t = f + f_n[:, None] * n[i]
        spin = (tau - np.cross(p[i], f)) @ n[i]
        assert_close(f_n, np.ones(10), atol=1e-12, what="unit normal force")
        assert_close(
            np.linalg.norm(tau - np.cross(p[i], f) - spin[:, None] * n[i], axis=1),
            np.zeros(10),
            atol=1e-15,
            what="extra torque only about the normal",
        )
        limit = np.linalg.norm(f_t, axis=1) ** 2 / MU**2 + spin**2 / torsion**2
        assert np.all(limit <= f_n**2 + 1e-9)
        assert_close(np.abs(spin[8:]), np.full(2, torsion), atol=1e-15, what="the spins")
    # the point-contact wrenches are the first n_edges of each contact's, unchanged
    point = contact_wrenches(p, n, MU, n_edges=8, torque_scale_m=scale).reshape(4, 8, 6)
    assert_close(w[:, :8], point, atol=0.0, what="cone edges")


def test_a_pinch_holds_by_its_torsion_and_more_torsion_holds_better():
    """Two antipodal soft contacts: epsilon 0 without torsion, positive with it and
    growing with it (the wrench hull only grows); holding_fingers says 3 for point
    contacts and 2 with torsion, and refuses a negative torsion by name."""
    eps = [
        ferrari_canny_epsilon(PINCH_P, PINCH_N, MU, torque_scale_m=0.03, torsion_m=t)
        for t in (0.0, 0.0005, 0.001, 0.002)
    ]
    assert eps[0] == 0.0
    assert 0.0 < eps[1] < eps[2] < eps[3]
    assert holding_fingers(0.0) == 3 and holding_fingers(0.001) == 2
    with pytest.raises(InputError, match="torsion_m"):
        holding_fingers(-0.001)


def test_single_contact_is_not_force_closure():
    assert ferrari_canny_epsilon(PINCH_P[:1], PINCH_N[:1], MU) == 0.0
    assert ferrari_canny_epsilon(PINCH_P[:1], PINCH_N[:1], MU, n_edges=16, torsion_m=0.01) == 0.0
    assert not is_force_closure(PINCH_P[:1], PINCH_N[:1], MU)


def test_frictionless_contacts_are_not_force_closure():
    assert ferrari_canny_epsilon(QUAD_P, QUAD_N, 0.0) == 0.0
    # Four contacts on four different faces, frictionless: still not.
    p = np.array([[0.03, 0.005, 0], [-0.03, -0.005, 0], [0, 0.02, 0.005], [0, -0.02, -0.005]])
    n = np.array([[1.0, 0, 0], [-1.0, 0, 0], [0, 1.0, 0], [0, -1.0, 0]])
    assert not is_force_closure(p, n, 0.0)
    assert is_force_closure(p, n, MU)


def test_contacts_on_one_side_are_not_force_closure():
    p = np.array([[0.03, 0.01, 0.01], [0.03, -0.01, 0.01], [0.03, 0.0, -0.01]])
    n = np.tile([1.0, 0, 0], (3, 1))
    assert ferrari_canny_epsilon(p, n, MU) == 0.0  # nothing pulls back along +x


def test_epsilon_grows_when_contacts_spread_apart():
    eps = [
        ferrari_canny_epsilon(QUAD_P * [1.0, s, s], QUAD_N, MU, torque_scale_m=SCALE_M)
        for s in (0.5, 1.0, 1.5, 2.0)
    ]
    assert np.all(np.diff(eps) > 0), eps


def test_epsilon_grows_with_friction():
    eps = [
        ferrari_canny_epsilon(TRIPOD_P, TRIPOD_N, mu, torque_scale_m=SCALE_M)
        for mu in (0.2, 0.5, 1.0)
    ]
    assert np.all(np.diff(eps) > 0), eps


def test_epsilon_is_invariant_to_permuting_contacts():
    rng = np.random.default_rng(2)
    s = BOX.sample_surface(0.004)
    for _ in range(5):
        idx = rng.choice(len(s), size=5, replace=False)
        p, n = s.points[idx], s.normals[idx]
        perm = rng.permutation(5)
        a = ferrari_canny_epsilon(p, n, MU)
        b = ferrari_canny_epsilon(p[perm], n[perm], MU)
        assert_close(b, a, atol=1e-12, what="permuted contacts")


def test_bad_input():
    cases = [
        (dict(mu=-0.1), "mu"),
        (dict(mu=float("nan")), "mu"),
        (dict(normals_object=TRIPOD_N * 2.0), "normals_object"),
        (dict(normals_object=TRIPOD_N[:2]), "normals_object"),
        (dict(points_object=np.full((3, 3), np.nan)), "points_object"),
        (dict(points_object=np.zeros((0, 3)), normals_object=np.zeros((0, 3))), "points_object"),
        (dict(n_edges=2), "n_edges"),
        (dict(torque_scale_m=0.0), "torque_scale_m"),
    ]
    for change, argument in cases:
        kw = dict(points_object=TRIPOD_P, normals_object=TRIPOD_N, mu=MU) | change
        with pytest.raises(InputError) as info:
            ferrari_canny_epsilon(**kw)
        assert info.value.argument == argument


def test_kept_quality_counts_equal_epsilons_as_kept_whatever_their_last_bits():
    from regrasp_pin.grasp.quality import EPSILON_RTOL, kept_quality

    # a hull facet set by the same contacts comes out 1-2 ulp apart (seen: 0x1.57c3e9b570750p-3
    # and ...751p-3 for one grasp under two BLAS kernels): both orders count as kept
    a = float.fromhex("0x1.57c3e9b570750p-3")
    b = float.fromhex("0x1.57c3e9b570751p-3")
    assert kept_quality(a, b) and kept_quality(b, a)
    # a real loss of quality is not kept; a gain is
    assert not kept_quality(a * (1.0 - 10 * EPSILON_RTOL), a)
    assert kept_quality(a * 1.01, a)
    # at zero quality (a grasp not in force closure) only a non-negative one keeps it
    assert kept_quality(0.0, 0.0) and not kept_quality(-1e-6, 0.0)


def _random_grasps(rng: np.random.Generator, n: int) -> list[tuple[np.ndarray, np.ndarray, float]]:
    """Contacts on the box's faces (2-6 of them, any faces, friction 0-1): some in force
    closure, some barely, many not."""
    out = []
    half = np.array([0.03, 0.02, 0.02])  # BOX's half sides
    for _ in range(n):
        k = int(rng.integers(2, 7))
        axis = rng.integers(0, 3, size=k)
        sign = rng.choice([-1.0, 1.0], size=k)
        p = rng.uniform(-1.0, 1.0, size=(k, 3)) * half
        p[np.arange(k), axis] = sign * half[axis]
        nrm = np.zeros((k, 3))
        nrm[np.arange(k), axis] = sign
        out.append((p, nrm, float(rng.choice([0.0, 0.2, 0.5, 1.0]))))
    return out


def test_closure_certificate_agrees_with_the_hull_where_it_decides():
    """The certificate (NNLS, no hull) gives the hull's answer, epsilon > tol, and decides
    most sets by itself: in force closure with a margin, or a direction outside the
    wrenches' cone."""
    rng = np.random.default_rng(7)
    decided = {True: 0, False: 0}
    for p, n, mu in _random_grasps(rng, 300):
        w = contact_wrenches(p, n, mu, n_edges=6, torque_scale_m=SCALE_M)
        eps = ferrari_canny_epsilon(p, n, mu, n_edges=6, torque_scale_m=SCALE_M)
        certain = closure_certificate(w)
        if certain is not None:
            assert certain == (eps > FORCE_CLOSURE_TOL), (p, n, mu, eps)
            decided[certain] += 1
        assert is_force_closure(p, n, mu, n_edges=6, torque_scale_m=SCALE_M) == (
            eps > FORCE_CLOSURE_TOL
        )
    assert decided[True] >= 30 and decided[False] >= 100, decided
    assert sum(decided.values()) >= 0.95 * 300, decided


def test_closure_certificate_bound_holds_on_known_grasps():
    """On the tripod and the crossed quad (epsilon known from the hull) the certificate
    proves force closure, but never for a tolerance whose 1000 times exceeds epsilon
    (its lower bound never exceeds epsilon), nor refuses it below epsilon."""
    for p, n in ((TRIPOD_P, TRIPOD_N), (QUAD_P, QUAD_N)):
        w = contact_wrenches(p, n, MU, torque_scale_m=SCALE_M)
        eps = ferrari_canny_epsilon(p, n, MU, torque_scale_m=SCALE_M)
        assert closure_certificate(w) is True and closure_certificate(w, tol=0.0) is True
        assert closure_certificate(w, tol=eps / 1e3 * 1.001) is None
        assert closure_certificate(w, tol=0.999 * eps) is None  # not refused either


def test_closure_certificate_refuses_what_cannot_close():
    pinch = contact_wrenches(PINCH_P, PINCH_N, MU)  # 5-D span
    assert closure_certificate(pinch) is False
    assert closure_certificate(contact_wrenches(QUAD_P, QUAD_N, 0.0)) is False  # frictionless
    assert closure_certificate(contact_wrenches(PINCH_P[:1], PINCH_N[:1], MU, n_edges=6)) is False
    with pytest.raises(InputError, match="wrenches"):
        closure_certificate(np.zeros((8, 5)))
    with pytest.raises(InputError, match="tol"):
        closure_certificate(pinch, tol=-1.0)


def test_closure_certificate_proves_nothing_from_an_unfinished_nnls(monkeypatch):
    """An NNLS stopped short of its optimum (a large residual that is not the distance
    to the cone) proves nothing: the hull decides."""
    import regrasp_pin.grasp.quality as quality

    monkeypatch.setattr(quality, "nnls", lambda A, d: (np.zeros(A.shape[1]), 1.0))
    w = contact_wrenches(TRIPOD_P, TRIPOD_N, MU, torque_scale_m=SCALE_M)
    assert closure_certificate(w) is None
    assert is_force_closure(TRIPOD_P, TRIPOD_N, MU, torque_scale_m=SCALE_M)

    def stops(A, d):
        raise RuntimeError("Maximum number of iterations reached.")

    monkeypatch.setattr(quality, "nnls", stops)
    assert closure_certificate(w) is None


def test_closure_certificate_refuses_only_with_an_upper_bound_below_the_tolerance(monkeypatch):
    """An NNLS that stops at a valid but not optimal point, leaving a residual ``y`` of
    5e-5 along the hull's nearest facet normal, must not refuse a grasp in force
    closure: the wrenches reach ``epsilon`` along ``y``, far above the tolerance."""
    from scipy.optimize import nnls as real_nnls

    import regrasp_pin.grasp.quality as quality

    rng = np.random.default_rng(3)
    p = rng.normal(size=(5, 3))
    p /= np.linalg.norm(p, axis=1, keepdims=True)
    n, p = p.copy(), 0.03 * p
    w = contact_wrenches(p, n, MU, n_edges=6, torque_scale_m=100.0)
    eps = ferrari_canny_epsilon(p, n, MU, n_edges=6, torque_scale_m=100.0)
    hull = ConvexHull(w)
    y = 0.99e-9 / eps * hull.equations[np.argmin(-hull.equations[:, -1]), :6]
    assert np.linalg.norm(y) > 1e-6 and eps > 1e-6

    def short_of_the_optimum(A, d):
        lam, _ = real_nnls(A, d - y)  # A lam = d - y: lam >= 0 but not optimal
        return lam, float(np.linalg.norm(A @ lam - d))

    monkeypatch.setattr(quality, "nnls", short_of_the_optimum)
    assert closure_certificate(w) is None
    assert is_force_closure(p, n, MU, n_edges=6, torque_scale_m=100.0)


def test_closure_certificate_at_a_zero_tolerance_keeps_the_hulls_answer():
    """With ``tol=0`` and torques scaled almost away (the hull's rank test zeroes such
    sets), the certificate still gives only the hull's answer."""
    decided = 0
    for seed in range(10):
        rng = np.random.default_rng(seed)
        k = int(rng.integers(4, 7))
        p = rng.normal(size=(k, 3))
        p /= np.linalg.norm(p, axis=1, keepdims=True)
        n = p + rng.normal(0.0, 0.3, (k, 3))
        n /= np.linalg.norm(n, axis=1, keepdims=True)
        p *= 0.03
        for scale in (1.0, 1e3, 1e9, 1e11, 1e12, 1e13):
            w = contact_wrenches(p, n, 1.0, n_edges=6, torque_scale_m=scale)
            eps = ferrari_canny_epsilon(p, n, 1.0, n_edges=6, torque_scale_m=scale)
            certain = closure_certificate(w, tol=0.0)
            if certain is not None:
                assert certain == (eps > 0.0), (seed, scale, eps)
                decided += 1
            assert is_force_closure(p, n, 1.0, n_edges=6, torque_scale_m=scale, tol=0.0) == (
                eps > 0.0
            )
    assert decided >= 10
