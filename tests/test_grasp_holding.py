"""Tests of holding fingers (regrasp_pin.grasp.holding), on the scene of
tests/test_grasp_tracking.py: each finger holds a contact of the turning box.

A holding finger is placed by IK wherever its contact is held, which forward
kinematics checks against the contact's tip-centre target; after the contact is lost
(where its track stops), it stays where it lost it.
"""

from __future__ import annotations

import numpy as np
from test_grasp_tracking import CONTACT, TIMES, scene  # noqa: F401 (the fixture)

from regrasp_pin.grasp.holding import holding_q, start_holding


def test_a_holding_finger_reaches_its_contact_then_stays_where_it_lost_it(scene):  # noqa: F811
    hand, box, motion, contacts = scene
    lost = 0
    for name, (p, n, q0) in contacts.items():
        h = start_holding(hand, box, motion, TIMES, name, p, n, q0, 0.0, CONTACT)
        f = hand.finger(name)
        t = np.linspace(0.0, 3.0, 241)
        q = holding_q(hand, motion, name, h, t, CONTACT.ik_tol_m)
        k = h.track.n_followed
        # held up to the track's last time before the loss (the contact may be lost
        # anywhere between that time and the next)
        before = t <= h.track.times_s[max(k - 2, 0)] + 1e-9
        T = motion.pose(t[before])
        target = T[:, :3, :3] @ (p + f.tip_radius * n) + T[:, :3, 3]
        err = np.linalg.norm(f.fk(q[before]) - target, axis=1)
        assert np.all(err <= CONTACT.ik_tol_m), name
        after = t > h.track.followed_until_s + 1e-9
        assert np.all(q[after] == h.track.q[k - 1]), name
        lost += int(after.any())
    assert lost >= 1  # the scene has contacts that are lost


def test_the_same_question_is_answered_once(scene, monkeypatch):  # noqa: F811
    """A hold asked at the same times again returns the same bits without solving IK;
    other times, another tolerance or a copy of the hold with its end set behave as
    before (the copy shares the answers)."""
    from dataclasses import replace

    hand, box, motion, contacts = scene
    name, (p, n, q0) = next(iter(contacts.items()))
    h = start_holding(hand, box, motion, TIMES, name, p, n, q0, 0.0, CONTACT)
    f = hand.finger(name)
    t = np.linspace(0.1, 0.9, 17)
    first = holding_q(hand, motion, name, h, t, CONTACT.ik_tol_m)
    calls = []
    solve = type(f).ik
    monkeypatch.setattr(
        type(f), "ik", lambda self, *a, **k: calls.append(1) or solve(self, *a, **k)
    )
    again = holding_q(hand, motion, name, h, t, CONTACT.ik_tol_m)
    ended = holding_q(hand, motion, name, replace(h, t_to=0.5), t, CONTACT.ik_tol_m)
    assert calls == []
    assert np.array_equal(again, first) and np.array_equal(ended, first)
    again[:] = 0.0  # the caller's copy: the kept answer is not changed
    assert np.array_equal(holding_q(hand, motion, name, h, t, CONTACT.ik_tol_m), first)
    other = holding_q(hand, motion, name, h, t[:-1], CONTACT.ik_tol_m)
    assert len(calls) == 1 and other.shape == first[:-1].shape
    holding_q(hand, motion, name, h, t, 10 * CONTACT.ik_tol_m)
    assert len(calls) == 2


def test_rest_configuration_is_the_grid_posture_clearest_of_the_object(scene):  # noqa: F811
    """The idle finger's rest posture is the exhaustive answer: every posture of the
    grid measured by Coal at every pose, the first strictly clearest (by 1e-6 m) kept;
    the other fingers stay at the middle of their limits."""
    from regrasp_pin.grasp.holding import rest_configuration
    from regrasp_pin.model.clearance import LinkClearance

    hand, box, motion, _ = scene
    for name in ("index", "thumb"):
        f = hand.finger(name)
        got = rest_configuration(hand, box, motion, [name])
        T = motion.pose(np.linspace(motion.t_start, motion.t_end, 7))
        fr = np.array([0.0, 0.25, 0.5, 0.75, 1.0])
        grid = np.stack(np.meshgrid(*[fr] * f.k, indexing="ij"), -1).reshape(-1, f.k)
        lc = LinkClearance(hand, name, box, include_tip=True)
        best, best_d = f.q_mid, -np.inf
        for qf in f.lower + grid * (f.upper - f.lower):
            full = hand.to_full(name, qf)
            d = float(lc(np.repeat(full[None], len(T), 0), T).min())
            if d > best_d + 1e-6:
                best, best_d = qf, d
        np.testing.assert_array_equal(got[f.q_indices], best)
        others = np.setdiff1d(np.arange(hand.model.nq), f.q_indices)
        np.testing.assert_array_equal(got[others], hand.neutral()[others])
