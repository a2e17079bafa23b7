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
