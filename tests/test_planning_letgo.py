"""Letting a finger go (regrasp_pin.planning.letgo) inside a whole plan.

A release or a hand-over moves the plan's time on (to the release, or to the joining
finger's landing); every other finger must still hold its contact then. Checked on the
neighbour scenario where a hand-over once landed after two other holds were lost: the
middle finger's IK could no longer reach its contact, yet the plan went on from there.
"""

from __future__ import annotations

import numpy as np

from regrasp_pin import plan_manipulation
from regrasp_pin.exceptions import PlanningError
from regrasp_pin.planning import advance, letgo
from regrasp_pin.planning.release import plan_release
from regrasp_pin.suite import build_scenario
from regrasp_pin.suite.specs import neighbour_specs


def test_a_let_go_leaves_every_other_hold_unlost(monkeypatch):
    name = "five_finger-hexagon--100deg-40dps"
    spec = next(s for s in neighbour_specs(("five_finger",)) if s.name == name)
    scen = build_scenario(spec)
    calls, results = [], []
    real = advance.let_go

    def recorded(ctx, state, trig, win, stay, why):
        calls.append(trig.finger)
        after = real(ctx, state, trig, win, stay, why)
        if after is not None:
            results.append(after)
        return after

    monkeypatch.setattr(advance, "let_go", recorded)
    try:
        plan_manipulation(scen.hand, scen.obj, scen.motion, grasp=scen.grasp, params=scen.params)
    except PlanningError:
        pass  # the outcome is not the point here
    assert calls  # the scenario lets fingers go (or tries to)
    c = scen.params.contact
    for after in results:
        for name, h in after.holding.items():
            if name in after.held_to_end:
                continue
            # every time of the hold up to the new time: the contact is still held
            # (reached, inside the joint limits, pad facing; a trigger, within the margin
            # of a limit, is not a loss), as its track measured it
            tr = h.track
            upto = (tr.times_s >= h.t_from - 1e-9) & (tr.times_s <= after.now + 1e-9)
            held = (tr.error_m <= c.ik_tol_m) & (tr.margin_rad >= 0.0) & (tr.pad_cos >= tr.cos_cone)
            assert np.all(held[upto]), (name, after.now)


class _Forgetful(dict):
    """A ``PlanContext.releases`` that keeps nothing."""

    def __setitem__(self, key, value):
        pass


def _plan_recording_releases(monkeypatch, name, forget):
    spec = next(s for s in neighbour_specs(("five_finger",)) if s.name == name)
    scen = build_scenario(spec)
    planned = []

    def recorded_release(hand, obj, motion, finger, t_r, P, q_r, q_hand, **kw):
        times = np.linspace(t_r, motion.t_end, 20)
        planned.append(
            (finger, round(t_r, 9), kw["q_park"] is None, q_r.tobytes(), q_hand(times).tobytes())
        )
        return plan_release(hand, obj, motion, finger, t_r, P, q_r, q_hand, **kw)

    def let_go(ctx, *args):
        if forget:
            ctx.releases = _Forgetful()
        return letgo.let_go(ctx, *args)

    monkeypatch.setattr(letgo, "plan_release", recorded_release)
    monkeypatch.setattr(advance, "let_go", let_go)
    try:
        plan_manipulation(scen.hand, scen.obj, scen.motion, grasp=scen.grasp, params=scen.params)
    except PlanningError as exc:
        return planned, (exc.kind, exc.finger, exc.time_s, len(exc.partial.regrasps()))
    return planned, "full plan"


def test_a_release_is_planned_once_for_a_plan(monkeypatch):
    """Backing up asks for the same release (the finger, the time, its hold and the
    others' motion) again from other branches: it is planned once. A plan that forgets
    the releases it planned asks for some twice, and ends the same way."""
    name = "five_finger-hexagon--100deg-40dps"
    kept, outcome = _plan_recording_releases(monkeypatch, name, forget=False)
    forgot, outcome_forgot = _plan_recording_releases(monkeypatch, name, forget=True)
    assert kept and len(set(kept)) == len(kept)
    assert len(set(forgot)) < len(forgot)  # the repeats the plan no longer makes
    assert set(forgot) == set(kept)
    assert outcome == outcome_forgot


def _landing_by_choice(needs):
    """A choice is the duration it was made for; the duration it needs is read from a
    table."""
    made = []

    def choose(d):
        made.append(d)
        return d

    return made, choose, lambda c: needs[c]


def test_arrival_choice_lands_the_first_choice_when_it_needs_no_longer():
    made, choose, need = _landing_by_choice({0.25: 0.25})
    choice, chosen_s, needed_s = letgo.arrival_choice(choose, need, 0.25)
    assert made == [0.25] and (choice, chosen_s, needed_s) == (0.25, 0.25, 0.25)
    assert letgo.join_duration_of(chosen_s, needed_s) == 0.25


def test_arrival_choice_chooses_again_for_the_longer_duration_it_needs():
    # the first Q needs 0.55 s; the Q chosen for 0.55 s needs only 0.4 s, so the join
    # takes 0.55 s, the duration that Q was chosen for (the object's pose at landing)
    made, choose, need = _landing_by_choice({0.25: 0.55, 0.55: 0.4})
    choice, chosen_s, needed_s = letgo.arrival_choice(choose, need, 0.25)
    assert made == [0.25, 0.55]
    assert (choice, chosen_s, needed_s) == (0.55, 0.55, 0.4)
    assert letgo.join_duration_of(chosen_s, needed_s) == 0.55


def test_a_settled_join_takes_the_duration_its_choice_needs_not_a_time_difference():
    # within the tolerance the needed value (whole steps) is kept as it is
    assert letgo.join_duration_of(0.25, 0.25 + 1e-12) == 0.25 + 1e-12
    assert letgo.join_duration_of(0.25, 0.25 - 1e-12) == 0.25 - 1e-12


def test_arrival_choice_reports_a_choice_that_never_settles():
    # every longer duration needs longer still: after the rounds, the last choice needs
    # more than it was chosen for and the caller must not land it
    made, choose, need = _landing_by_choice({0.25: 0.5, 0.5: 0.75, 0.75: 1.0})
    choice, chosen_s, needed_s = letgo.arrival_choice(choose, need, 0.25)
    assert made == [0.25, 0.5, 0.75]
    assert choice == chosen_s == 0.75 and needed_s == 1.0
