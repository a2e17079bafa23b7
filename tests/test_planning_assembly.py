"""The assembled plan's joint speeds and object penetration
(regrasp_pin.planning.assembly.joint_speed_failure, object_penetration_failure).

The holds are placed by IK at every sample of the assembled plan, so the planner checks
their joint speeds there: a hand configuration trajectory is built here at rest, one
joint of one finger then steps between two samples at a known share of its velocity
limit. The whole plan is measured against the object there too: a small box far from
the hand at rest, but for one sample where it reaches into a fingertip.
"""

from __future__ import annotations

import numpy as np
import pytest

from regrasp_pin.exceptions import FailureKind
from regrasp_pin.model.clearance import LinkClearance
from regrasp_pin.model.hand import Hand
from regrasp_pin.model.objects import Box
from regrasp_pin.planning.assembly import joint_speed_failure, object_penetration_failure


@pytest.fixture(scope="module")
def hand():
    return Hand.five_finger()


def _stepped(hand, finger, joint, share, k=5, dt=0.01):
    """Times, and the hand at rest but for ``finger``'s ``joint`` stepping between
    samples ``k`` and ``k + 1`` at ``share`` of its velocity limit."""
    f = hand.fingers[finger]
    times = np.arange(12) * dt
    q = np.broadcast_to(hand.neutral(), (times.size, hand.model.nq)).copy()
    q[k + 1 :, f.q_indices[joint]] += share * f.velocity_limit[joint] * dt
    return times, q


def test_a_plan_within_the_velocity_limits_passes(hand):
    assert joint_speed_failure(hand, *_stepped(hand, "ring", 1, 0.999)) is None


@pytest.mark.parametrize(("finger", "joint"), [("thumb", 0), ("ring", 2)])
def test_the_fastest_joint_over_its_limit_is_named(hand, finger, joint):
    f = hand.fingers[finger]
    times, q = _stepped(hand, finger, joint, 1.5)
    exc = joint_speed_failure(hand, times, q)
    assert exc is not None and exc.kind == FailureKind.VELOCITY
    assert (exc.finger, exc.time_s) == (finger, times[5])
    assert exc.measured == pytest.approx(1.5 * f.velocity_limit[joint], rel=1e-9)
    assert exc.required == f.velocity_limit[joint]
    assert f.joint_names[joint] in exc.reason


def test_a_finger_entering_the_object_at_one_sample_is_named_with_its_depth(hand):
    obj = Box((0.004, 0.004, 0.004))
    times = np.arange(6) * 0.01
    q = np.broadcast_to(hand.neutral(), (times.size, hand.model.nq)).copy()
    f = hand.fingers["index"]
    tip = f.fk(q[0, f.q_indices])
    out = tip / np.linalg.norm(tip)  # away from the palm's origin
    T = np.broadcast_to(np.eye(4), (times.size, 4, 4)).copy()
    T[:, :3, 3] = [0.0, 0.0, 0.5]  # half a metre from the hand
    T[3, :3, 3] = tip + (f.tip_radius + 0.001) * out  # 2 mm half side: into the sphere
    depth = LinkClearance(hand, "index", obj, include_tip=True)(q[3:4], T[3:4])[0]
    assert depth < -1e-4  # Coal: the box reaches into the fingertip
    exc = object_penetration_failure(hand, obj, times, q, T, 5e-5)
    assert exc is not None and exc.kind == FailureKind.OBJECT_CLEARANCE
    assert (exc.finger, exc.time_s) == ("index", times[3])
    assert (exc.measured, exc.required) == (depth, -5e-5)
    # allowed to press in that far, the plan passes
    assert object_penetration_failure(hand, obj, times, q, T, -depth + 1e-6) is None
