"""A flight's joint trajectory along its tip curve (planning.follow.follow_curve)."""

from __future__ import annotations

import numpy as np
import pytest

import regrasp_pin.planning.follow as follow_module
from regrasp_pin import Hand
from regrasp_pin.exceptions import FailureKind, PlanningError
from regrasp_pin.model.hand import Finger, speed_shares
from regrasp_pin.planning.follow import follow_curve

TOL_M = 1e-6
DT_S = 0.01


@pytest.fixture(scope="module")
def flight():
    """The Allegro's index along a smooth joint path (a tenth of its speed limits), the
    object still at the palm's origin: times, poses, tip curve (object frame = palm
    frame), the path."""
    f = Hand.allegro().finger("index")
    n = 40
    t = np.arange(n) * DT_S
    q = 0.5 * (f.lower + f.upper) + np.sin(3.0 * t[:, None] + np.arange(f.k)) * (
        f.velocity_limit / 30.0
    )
    assert np.all(f.within_limits(q))
    return f, t, np.tile(np.eye(4), (n, 1, 1)), f.fk(q), q


def _jump_at(monkeypatch, f, sample):
    """The chunk's IK puts ``sample`` on another branch of its target's solutions (a
    solution far from its neighbours); single-target solves go through as they are."""
    ik = Finger.ik

    def batch(self, targets, q_init=None, **kw):
        res = ik(self, targets, q_init, **kw)
        if np.ndim(targets) == 2 and len(targets) > sample:
            rng = np.random.default_rng(0)
            starts = rng.uniform(self.lower, self.upper, (400, self.k))
            far = ik(self, np.repeat(targets[sample][None], 400, 0), starts, tol_m=TOL_M)
            ok = far.error_m <= TOL_M
            j = np.argmax(np.abs(far.q[ok] - res.q[sample]).max(axis=1))
            res.q[sample], res.error_m[sample] = far.q[ok][j], far.error_m[ok][j]
        return res

    monkeypatch.setattr(Finger, "ik", batch)


def test_a_flight_follows_its_curve_within_the_speed_limits(flight, monkeypatch):
    f, times, T, tip, q_path = flight
    tol = np.full(len(times), 1e-5)
    _jump_at(monkeypatch, f, 12)
    q = follow_curve(f, times, T, tip, q_path[0], tol, TOL_M)
    assert np.all(np.linalg.norm(f.fk(q) - tip, axis=1) <= TOL_M)
    share = speed_shares(np.diff(q, axis=0), np.diff(times), f.velocity_limit)
    assert share.max() <= 1.0
    # without solving again from the sample before, the jump stays in the trajectory
    monkeypatch.setattr(follow_module, "follow_on", lambda *args: 0)
    jumped = follow_curve(f, times, T, tip, q_path[0], tol, TOL_M)
    share = speed_shares(np.diff(jumped, axis=0), np.diff(times), f.velocity_limit)
    assert share.max() > 1.0


def test_a_curve_out_of_reach_is_an_ik_failure(flight):
    f, times, T, tip, q_path = flight
    far = tip.copy()
    far[20:] += [0.5, 0.0, 0.0]  # half a metre away
    with pytest.raises(PlanningError) as failed:
        follow_curve(f, times, T, far, q_path[0], np.full(len(times), 1e-5), TOL_M)
    err = failed.value
    assert err.kind == FailureKind.IK_UNREACHABLE and err.time_s >= times[20]  # the worst
    assert err.measured > 0.4 and err.required == 1e-5
