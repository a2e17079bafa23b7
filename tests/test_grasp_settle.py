"""Tests of settling a redundant finger's fingertip link off the face (regrasp_pin.grasp.settle).

The Allegro's fingers have four joints for a three-coordinate tip centre. Contacts are
made from random configurations, with the surface normal tilted 2-8 deg from the pad:
many make the distal box reach past the plane the tip sphere rests on, some by less than
``SETTLE_WITHIN_M`` (those are the ones settled). Settled
configurations are checked by forward kinematics (the tip centre stays on its target)
and by Coal (the distance of the fingertip link to the half-space behind the plane,
``test_model_tip_reach._reference_overshoot``).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from test_model_tip_reach import _reference_overshoot

from regrasp_pin.grasp.settle import SETTLE_WITHIN_M, settle_tip_link
from regrasp_pin.model.hand import Hand

IK_TOL_M = 1e-5
N = 60


@pytest.fixture(scope="module")
def allegro() -> Hand:
    return Hand.allegro()


def contacts(f, seed: int):
    """Configurations ``(N, k)`` 0.15 rad inside the limits, their tip centres ``(N, 3)``
    and inward normals ``(N, 3)`` (palm frame) tilted 2-8 deg from the pad."""
    rng = np.random.default_rng(seed)
    q = rng.uniform(f.lower + 0.15, f.upper - 0.15, (N, f.k))
    R, tips = f.tip_poses(q)
    pad = R @ f.pad_axis_tip
    axis = np.cross(pad, rng.normal(size=(N, 3)))
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    turn = Rotation.from_rotvec(axis * np.radians(rng.uniform(2.0, 8.0, N))[:, None])
    return q, tips, np.einsum("nij,nj->ni", turn.as_matrix(), pad)


def overshoot(f, q, u_palm):
    R, _ = f.tip_poses(q)
    return f.tip_reach.overshoot(np.einsum("nji,nj->ni", R, u_palm))


@pytest.mark.parametrize("name", ["thumb", "index"])
def test_settling_turns_the_fingertip_link_off_the_face_with_the_tip_kept(allegro, name):
    f = allegro.finger(name)
    q, tips, u = contacts(f, seed=5)
    before = overshoot(f, q, u)
    sinking = (before > 0.0) & (before <= SETTLE_WITHIN_M)
    assert sinking.sum() >= 6
    settled = settle_tip_link(f, q, tips, -u, ik_tol_m=IK_TOL_M)
    after = overshoot(f, settled, u)
    # the tip centre stays where it was, within the limits; nothing got worse
    assert np.linalg.norm(f.fk(settled) - tips, axis=1).max() <= IK_TOL_M
    assert np.all(f.within_limits(settled))
    assert np.all(after <= before + 1e-12)
    # only the ones sinking in a little move (those further in are left), each joint at
    # most its allowance
    np.testing.assert_array_equal(settled[~sinking], q[~sinking])
    assert np.abs(settled - q).max() <= 0.2 + 1e-12
    # at least a third of the sinking ones are lifted off, as Coal measures it
    off = sinking & (after <= 0.0)
    assert off.sum() >= sinking.sum() / 3
    for i in np.flatnonzero(off)[:5]:
        assert _reference_overshoot(allegro, name, settled[i], u[i]) <= 1e-9
        assert _reference_overshoot(allegro, name, q[i], u[i]) > 0.0


def test_a_small_allowance_bounds_every_joints_move(allegro):
    f = allegro.finger("middle")
    q, tips, u = contacts(f, seed=6)
    settled = settle_tip_link(f, q, tips, -u, ik_tol_m=IK_TOL_M, max_change_rad=0.01)
    assert np.abs(settled - q).max() <= 0.01 + 1e-12
    assert np.any(settled != q)
    assert np.linalg.norm(f.fk(settled) - tips, axis=1).max() <= IK_TOL_M


def test_a_finger_without_spare_joints_is_left_as_it_is():
    f = Hand.five_finger().finger("index")
    q, tips, u = contacts(f, seed=7)
    assert np.any(overshoot(f, q, u) > 0.0)
    np.testing.assert_array_equal(settle_tip_link(f, q, tips, -u, ik_tol_m=IK_TOL_M), q)
