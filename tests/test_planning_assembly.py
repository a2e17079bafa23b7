"""The assembled plan's joint speeds (regrasp_pin.planning.assembly.joint_speed_failure).

The holds are placed by IK at every sample of the assembled plan, so the planner checks
their joint speeds there: a hand configuration trajectory is built here at rest, one
joint of one finger then steps between two samples at a known share of its velocity
limit.
"""

from __future__ import annotations

import numpy as np
import pytest

from regrasp_pin.exceptions import FailureKind
from regrasp_pin.model.hand import Hand
from regrasp_pin.planning.assembly import joint_speed_failure


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
