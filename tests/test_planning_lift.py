"""Tests of backing off from a contact (regrasp_pin.planning.lift).

The contacts are made from the five-finger hand's index finger itself: a configuration
with one joint at a limit, and a contact whose outward normal is the direction in which
only that joint, moving past its limit, would take the fingertip. Along that normal the
IK cannot follow; a tilted direction can, and the fingertip then rises exactly as high
above the contact's tangent plane as asked (forward kinematics of the result).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from regrasp_pin.exceptions import FailureKind, PlanningError
from regrasp_pin.model.hand import Hand
from regrasp_pin.planning import lift

IK_TOL_M = 1e-5
OFFSETS = 0.005 * np.linspace(0.0, 1.0, 11) ** 2  # [m], the lift's minimum-jerk-like rise


@pytest.fixture(scope="module")
def index():
    return Hand.five_finger().finger("index")


def poses(n: int, turn_deg: float, about: np.ndarray) -> np.ndarray:
    """``(n, 4, 4)`` object poses in the palm frame: a turn of up to ``turn_deg`` about
    the palm's z axis through ``about`` (the object frame is the palm frame at s=0)."""
    T = np.repeat(np.eye(4)[None], n, axis=0)
    R = Rotation.from_euler("z", np.linspace(0.0, turn_deg, n)[:, None], degrees=True).as_matrix()
    T[:, :3, :3] = R
    T[:, :3, 3] = about - np.einsum("nij,j->ni", R, about)
    return T


def contacts_past_a_limit(f, seed: int = 0, tries: int = 400):
    """Yield ``(q, contact)``: ``q`` with one joint at a limit, the contact's normal the
    direction only that joint moving past the limit gives the fingertip."""
    rng = np.random.default_rng(seed)
    for _ in range(tries):
        q = rng.uniform(f.lower, f.upper)
        j, upper = int(rng.integers(f.k)), bool(rng.integers(2))
        q[j] = f.upper[j] if upper else f.lower[j]
        p, J = f.jacobian(q)
        v = J[:, j] if upper else -J[:, j]
        if np.linalg.norm(v) < 1e-3:
            continue
        n = v / np.linalg.norm(v)
        yield q, (p - f.tip_radius * n, n)


def heights_above(f, q: np.ndarray, T: np.ndarray, contact) -> np.ndarray:
    """The fingertip centre's height above the contact's tangent plane minus the tip
    radius, object frame [m] (forward kinematics)."""
    tips_palm = f.fk(q)
    tips_obj = np.einsum("nji,nj->ni", T[:, :3, :3], tips_palm - T[:, :3, 3])
    return (tips_obj - contact[0]) @ contact[1] - f.tip_radius


def test_where_the_normal_is_out_of_reach_a_tilted_back_off_rises_as_asked(index):
    f, T = index, poses(len(OFFSETS), 3.0, np.array([0.0, 0.05, 0.1]))
    rescued = 0
    for q, contact in contacts_past_a_limit(f):
        with pytest.raises(PlanningError):
            lift.along(f, T, contact, contact[1], OFFSETS, q, IK_TOL_M)
        try:
            qs = lift.back_off(f, T, contact, OFFSETS, q, IK_TOL_M)
        except PlanningError as exc:
            assert exc.kind == FailureKind.IK_UNREACHABLE
            continue
        rescued += 1
        np.testing.assert_allclose(heights_above(f, qs, T, contact), OFFSETS, atol=2 * IK_TOL_M)
        assert np.all(f.within_limits(qs, 1e-9))
        # the fingertip left along one of the tilted directions (object frame)
        tips = np.einsum("nji,nj->ni", T[:, :3, :3], f.fk(qs) - T[:, :3, 3])
        d = tips[-1] - (contact[0] + f.tip_radius * contact[1])
        tilt = np.degrees(np.arccos(d @ contact[1] / np.linalg.norm(d)))
        assert min(abs(tilt - t) for t in lift.TILTS_DEG) < 0.1
        if rescued == 3:
            break
    assert rescued == 3


def test_where_nothing_can_be_followed_the_failure_is_the_normals(index):
    f, T = index, poses(len(OFFSETS), 0.0, np.zeros(3))
    q = f.q_mid.copy()
    p = f.fk(q)
    n = p / np.linalg.norm(p)  # away from the palm: out of reach 1 m up
    contact = (p - f.tip_radius * n, n)
    far = OFFSETS * 200.0
    with pytest.raises(PlanningError) as normal:
        lift.along(f, T, contact, n, far, q, IK_TOL_M)
    with pytest.raises(PlanningError) as exc:
        lift.back_off(f, T, contact, far, q, IK_TOL_M)
    assert exc.value.kind == FailureKind.IK_UNREACHABLE
    assert exc.value.measured == pytest.approx(normal.value.measured)
    assert exc.value.required == IK_TOL_M


def test_tilted_directions_leave_the_surface_at_the_tilts(index):
    f = index
    for q, contact in list(contacts_past_a_limit(f, seed=1))[:5]:
        dirs = lift.tilted_directions(f, np.eye(4), contact, q, 0.005)
        n = contact[1]
        assert len(dirs) == lift.MAX_TILTED
        np.testing.assert_allclose(np.linalg.norm(dirs, axis=1), 1.0)
        tilts = np.degrees(np.arccos(np.clip(dirs @ n, -1.0, 1.0)))
        assert all(min(abs(t - s) for s in lift.TILTS_DEG) < 1e-6 for t in tilts)


def test_with_every_direction_in_reach_the_ties_go_to_the_small_tilt_towards_the_goal(index):
    """Far from limits and singularities the finger follows every direction to first
    order (all shares 1): the tilted ones come in the order smaller tilt first, the
    first of them leaning towards ``toward``."""
    f = index
    q = 0.5 * (f.lower + f.upper)
    p = f.fk(q)
    n = np.array([0.0, 0.0, 1.0])
    contact = (p - f.tip_radius * n, n)
    goal = contact[0] + np.array([0.01, 0.02, 0.0])
    dirs = lift.tilted_directions(f, np.eye(4), contact, q, 1e-4, toward=goal)
    tilts = np.degrees(np.arccos(dirs @ n))
    np.testing.assert_allclose(tilts, min(lift.TILTS_DEG), atol=1e-6)
    lean = dirs[0] - (dirs[0] @ n) * n
    along = (goal - contact[0]) / np.linalg.norm(goal - contact[0])
    np.testing.assert_allclose(lean / np.linalg.norm(lean), along, atol=1e-9)


def _contact_in_reach(f, seed: int):
    """``(q, contact)`` with ``q`` inside the joint box and the contact's normal a
    direction the fingertip can move in (the tip's velocity under all joints turning
    alike)."""
    rng = np.random.default_rng(seed)
    q = f.lower + (0.3 + 0.4 * rng.random(f.k)) * (f.upper - f.lower)
    p, J = f.jacobian(q)
    n = J @ np.ones(f.k)
    n = n / np.linalg.norm(n)
    return q, (p - f.tip_radius * n, n)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_directions_apart_lead_away_from_a_neighbour_the_furthest_first(index, seed):
    """A neighbour beside the contact (a point 8 mm along a tangent): no direction
    returned leans towards it, the first leans away, their tops stand further from it
    than the normal's by the gain (forward kinematics), the furthest first, and no
    direction left out ends further than the last one returned."""
    q, (p_palm, n_palm) = _contact_in_reach(index, seed)
    # the contact in an object frame turned and moved from the palm's
    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec([0.3, -0.2, 0.5]).as_matrix()
    T[:3, 3] = [0.004, -0.003, 0.002]
    p, n = T[:3, :3].T @ (p_palm - T[:3, 3]), T[:3, :3].T @ n_palm
    contact = (p, n)
    side = np.cross(n, [1.0, 0.0, 0.0] if abs(n[0]) < 0.9 else [0.0, 1.0, 0.0])
    side /= np.linalg.norm(side)
    neighbour = T[:3, :3] @ (p + 0.008 * side) + T[:3, 3]  # palm frame
    height = 0.004

    def gap(qk: np.ndarray) -> float:
        return float(np.linalg.norm(index.fk(qk[None])[0] - neighbour))

    dirs = lift.directions_apart(index, T, contact, q, height, gap, IK_TOL_M)
    assert 1 <= len(dirs) <= lift.MAX_APART
    assert np.allclose(np.linalg.norm(dirs, axis=1), 1.0)
    assert dirs[0] @ side < 0.0  # the first leans away from the neighbour
    assert np.all(dirs @ side <= 1e-9)  # none towards it

    def top(d: np.ndarray) -> np.ndarray:
        local = p + index.tip_radius * n + height / float(d @ n) * d
        return T[:3, :3] @ local + T[:3, 3]

    def top_gap(d: np.ndarray) -> float:
        res = index.ik(top(d)[None], q, tol_m=IK_TOL_M, restarts=False)
        assert res.error_m[0] <= IK_TOL_M
        return gap(res.q[0])

    gaps = [top_gap(d) for d in dirs]
    assert all(g >= top_gap(n) + lift.APART_GAIN_M - 1e-9 for g in gaps)
    assert gaps == sorted(gaps, reverse=True)
    # every tilt and azimuth of the search: none left out ends further than the last
    e1 = lift._tangent_towards(n, None)
    e2 = np.cross(n, e1)
    for tilt in np.radians(lift.TILTS_DEG):
        for az in 2.0 * np.pi * np.arange(lift.AZIMUTHS) / lift.AZIMUTHS:
            d = np.cos(tilt) * n + np.sin(tilt) * (np.cos(az) * e1 + np.sin(az) * e2)
            if not np.any(np.all(np.isclose(dirs, d), axis=1)):
                res = index.ik(top(d)[None], q, tol_m=IK_TOL_M, restarts=False)
                if res.error_m[0] <= IK_TOL_M:
                    assert gap(res.q[0]) <= gaps[-1] + 1e-9


def test_no_direction_apart_where_the_neighbours_do_not_care(index):
    q, contact = _contact_in_reach(index, 0)
    dirs = lift.directions_apart(index, np.eye(4), contact, q, 0.004, lambda qk: 0.01, IK_TOL_M)
    assert dirs.shape == (0, 3)


def test_directions_apart_beat_the_baseline_given_and_are_within_reach(index):
    """Where the normal's top is out of reach and the caller's back-off was tilted (its
    gap the baseline): only reachable tops count, each beating the baseline by the
    gain; with a baseline above every gap, none."""
    T = np.eye(4)

    def gap(qk: np.ndarray) -> float:
        return 0.01 + float(index.fk(qk[None])[0] @ [1.0, 0.0, 0.0])

    found = 0
    for q, (p, n) in contacts_past_a_limit(index, seed=3):
        normal = index.ik((p + (index.tip_radius + 0.004) * n)[None], q, tol_m=IK_TOL_M,
                          restarts=False)  # fmt: skip
        if normal.error_m[0] <= IK_TOL_M:
            continue
        dirs = lift.directions_apart(index, T, (p, n), q, 0.004, gap, IK_TOL_M, baseline_m=0.0)
        for d in dirs:
            res = index.ik((p + index.tip_radius * n + 0.004 / float(d @ n) * d)[None], q,
                           tol_m=IK_TOL_M, restarts=False)  # fmt: skip
            assert res.error_m[0] <= IK_TOL_M and gap(res.q[0]) >= lift.APART_GAIN_M
        assert lift.directions_apart(
            index, T, (p, n), q, 0.004, gap, IK_TOL_M, baseline_m=1.0
        ).shape == (0, 3)
        found += int(len(dirs) > 0)
        if found == 3:
            break
    assert found == 3
