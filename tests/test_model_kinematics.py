"""Batched finger kinematics against Pinocchio and finite differences, on both hands."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from conftest import assert_close

from regrasp_pin import Hand
from regrasp_pin.model.kinematics import FingerChain


@pytest.fixture(scope="module", params=["five_finger", "allegro"])
def hand(request):
    return Hand.five_finger() if request.param == "five_finger" else Hand.allegro()


def _pin_reference(hand, finger, q):
    """Tip position, rotation and 3 x k Jacobian from Pinocchio, one point at a time."""
    model, data = hand.model, hand.model.createData()
    fid = model.getFrameId(finger.tip_frame)
    vidx = [model.joints[int(j)].idx_v for j in finger.chain.joint_ids]
    P, R, J = [], [], []
    for qi in q:
        qf = hand.to_full(finger.name, qi)
        pin.forwardKinematics(model, data, qf)
        pin.updateFramePlacements(model, data)
        Jf = pin.computeFrameJacobian(model, data, qf, fid, pin.LOCAL_WORLD_ALIGNED)
        P.append(data.oMf[fid].translation.copy())
        R.append(data.oMf[fid].rotation.copy())
        J.append(Jf[:3, vidx])
    return np.array(P), np.array(R), np.array(J)


def test_fk_rotation_jacobian_match_pinocchio(hand):
    rng = np.random.default_rng(0)
    for finger in hand.fingers.values():
        q = rng.uniform(finger.lower, finger.upper, (40, finger.k))
        p_ref, R_ref, J_ref = _pin_reference(hand, finger, q)
        # the kernel's own cos/sin (model.trig) and Pinocchio's: the same to rounding
        assert_close(finger.fk(q), p_ref, atol=1e-12, what=f"{finger.name} FK")
        p, J = finger.jacobian(q)
        assert_close(J, J_ref, atol=1e-9, what=f"{finger.name} Jacobian")
        R, _ = finger.tip_poses(q)
        assert_close(R, R_ref, atol=1e-9, what=f"{finger.name} tip rotation")


def test_jacobian_matches_finite_differences(hand):
    rng = np.random.default_rng(1)
    h = 1e-6
    for finger in hand.fingers.values():
        q = rng.uniform(finger.lower + 0.01, finger.upper - 0.01, (10, finger.k))
        _, J = finger.jacobian(q)
        for c in range(finger.k):
            dq = np.zeros(finger.k)
            dq[c] = h
            fd = (finger.fk(q + dq) - finger.fk(q - dq)) / (2 * h)
            assert_close(J[:, :, c], fd, atol=1e-8, what=f"{finger.name} column {c}")


def test_single_configuration_shapes_and_values(hand):
    finger = next(iter(hand.fingers.values()))
    q = finger.q_mid
    p = finger.fk(q)
    assert p.shape == (3,)
    assert_close(p, finger.fk(q[None])[0], atol=0.0)


def test_each_points_result_depends_on_that_point_alone(hand):
    # bit for bit: a point's position, rotation and Jacobian are the same whatever
    # batch it is in and wherever in it (no BLAS product rounds by batch position)
    rng = np.random.default_rng(11)
    for finger in hand.fingers.values():
        q = np.ascontiguousarray(rng.uniform(finger.lower, finger.upper, (257, finger.k)).T)
        p, W, J = finger.chain.forward_soa(q, True)
        for a, b in ((0, 1), (3, 4), (5, 38), (101, 257), (0, 200)):
            p_s, W_s, J_s = finger.chain.forward_soa(q[:, a:b].copy(), True)
            assert np.array_equal(p_s, p[:, a:b])
            assert np.array_equal(W_s, W[:, :, a:b])
            assert np.array_equal(J_s, J[:, :, a:b])
        R, _ = finger.chain.poses(q.T)
        one = np.array([finger.chain.poses(q.T[i : i + 1])[0][0] for i in (0, 17, 256)])
        assert np.array_equal(one, R[[0, 17, 256]])


def test_mimic_dip_follows_pip_in_pinocchio_and_kernel():
    hand = Hand.five_finger()
    model, data = hand.model, hand.model.createData()
    finger = hand.fingers["index"]
    q = np.array([0.1, 0.4, 1.2])
    pin.forwardKinematics(model, data, hand.to_full("index", q))
    jp, jd = model.getJointId("index_pip"), model.getJointId("index_dip")
    rel = data.oMi[jp].inverse() * data.oMi[jd]
    # DIP's relative rotation about -y is 0.75 * PIP (the URDF <mimic> multiplier)
    angle = pin.log3(rel.rotation) @ np.array([0.0, -1.0, 0.0])
    assert angle == pytest.approx(0.75 * 1.2, abs=1e-12)
    # and the finger has 3 independent joints although 4 joints are on its chain
    assert finger.k == 3
    assert len(finger.chain.path_axes) == 4


def test_chain_rejects_non_revolute_joint(tmp_path):
    urdf = tmp_path / "slider.urdf"
    urdf.write_text(
        """<robot name="s"><link name="base"/><link name="a"/><link name="b"/>
        <joint name="j1" type="prismatic"><parent link="base"/><child link="a"/>
        <axis xyz="1 0 0"/><limit lower="0" upper="1" effort="1" velocity="1"/></joint>
        <joint name="tipj" type="fixed"><parent link="a"/><child link="b"/></joint></robot>"""
    )
    model = pin.buildModelFromUrdf(str(urdf))
    from regrasp_pin.exceptions import InputError

    with pytest.raises(InputError, match="not revolute"):
        FingerChain(model, "b")


def test_linear_products_are_the_written_out_sums_bit_for_bit():
    # _linear skips what _combine skips (zero terms, unit factors) and copies nothing;
    # its sums are _combine's, term by term, including the sign of zeros
    from regrasp_pin.model.kinematics import _combine, _linear, _terms

    rng = np.random.default_rng(21)
    cols = [rng.normal(size=(3, 40)) for _ in range(3)]
    cols[1][:, :5] = -0.0
    choices = np.array([0.0, -0.0, 1.0, -1.0, 0.37, -2.5])
    for coef in [rng.choice(choices, 3) for _ in range(60)] + [np.zeros(3), np.eye(3)[1]]:
        ref = _combine(coef, cols, np.empty((3, 40)))
        got = _linear(_terms(coef), cols)
        got = np.zeros((3, 40)) if got is None else got
        assert ref.tobytes() == np.broadcast_to(got, ref.shape).tobytes(), coef


def test_jacobian_in_one_batch_equals_the_joint_loop_bit_for_bit(hand):
    # few points take the batched Jacobian, many the loop over joints: the same bits
    rng = np.random.default_rng(22)
    for finger in hand.fingers.values():
        chain = finger.chain
        q = np.ascontiguousarray(rng.uniform(finger.lower, finger.upper, (60, finger.k)).T)
        q[:, :3] = 0.0
        p, _, J_loop = chain.forward_soa(np.repeat(q, 6, axis=1), True)  # 360 > 256 points
        p_few, J_few = chain.tip_soa(q, True)
        assert np.array_equal(p_few, p[:, ::6])
        assert J_few.tobytes() == np.ascontiguousarray(J_loop[:, :, ::6]).tobytes()
        _, _, J_ref = _pin_reference(hand, finger, q.T[:10])
        assert_close(np.moveaxis(J_few[:, :, :10], 2, 0), J_ref, atol=1e-12, what="Jacobian")


def test_attached_frames_one_kernel_per_finger_and_pointwise(hand, monkeypatch):
    # every collision geometry of the fingers (links on the way to the tips) against
    # its chain's own poses composed with its offset; one kernel run per finger; each
    # point's bits independent of the batch
    from regrasp_pin.model.distances import _geometry
    from regrasp_pin.model.kinematics import attached_placements, attached_points

    geoms = [_geometry(hand, g) for f in hand.fingers.values() for g in f.geometry_ids]
    chains = [g.chain for g in geoms]
    R_off = np.array([g.R_frame_geom for g in geoms])
    p_off = np.array([g.p_frame_geom for g in geoms])
    rng = np.random.default_rng(5)
    lo, hi = hand.model.lowerPositionLimit, hand.model.upperPositionLimit
    q = rng.uniform(lo, hi, (300, hand.model.nq))
    runs = []
    kernel = FingerChain._kernel
    monkeypatch.setattr(
        FingerChain, "_kernel", lambda self, *a: runs.append(self) or kernel(self, *a)
    )
    R, p = attached_placements(chains, R_off, p_off, q)
    assert len(runs) == len(hand.fingers) < len({id(c) for c in chains})
    for j, c in enumerate(chains):
        R_t, p_t = c.poses(q[:, c.q_indices])
        assert_close(R[:, j], R_t @ R_off[j], atol=1e-14, what="rotation")
        assert_close(p[:, j], p_t + R_t @ p_off[j], atol=1e-15, what="origin")
    assert attached_points(chains, p_off, q).tobytes() == p.tobytes()  # origins alone
    R_sub, p_sub = attached_placements(chains, R_off, p_off, q[7:19])
    assert R_sub.tobytes() == R[7:19].tobytes() and p_sub.tobytes() == p[7:19].tobytes()
