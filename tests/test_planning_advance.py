"""One step of the plan (regrasp_pin.planning.advance): what a regrasp must land by."""

from __future__ import annotations

from types import SimpleNamespace

import pytest

from regrasp_pin.exceptions import PlanningError
from regrasp_pin.planning import advance, planner, recovery
from regrasp_pin.planning.advance import _others_lost_by
from regrasp_pin.planning.state import Trigger
from regrasp_pin.suite import neighbour_specs
from regrasp_pin.suite.build import build_scenario

T_END = 5.0
DT = 0.01


def _ctx():
    return SimpleNamespace(
        scene=SimpleNamespace(motion=SimpleNamespace(t_end=T_END)),
        params=SimpleNamespace(dt_s=DT),
    )


def _state(holding, held_to_end=()):
    return SimpleNamespace(
        holding=dict.fromkeys(holding, object()),
        held_to_end=dict.fromkeys(held_to_end, "held"),
    )


def _trigger(finger, lost_s, lost_near=None):
    return Trigger(time_s=0.5, finger=finger, reason="test", lost_s=lost_s, lost_near=lost_near)


def test_a_regrasp_lands_before_any_other_hold_is_lost():
    """The earliest loss of another holding finger's hold bounds the landing: that
    finger could not let go while this one is in the air."""
    triggers = [_trigger("index", 1.0), _trigger("ring", 2.5), _trigger("middle", 1.8)]
    state = _state(["index", "ring", "middle"])
    assert _others_lost_by(_ctx(), state, "index", triggers) == pytest.approx(1.8)
    assert _others_lost_by(_ctx(), state, "middle", triggers) == pytest.approx(1.0)


def test_holds_that_do_not_bound_the_landing():
    """Not a bound: a hold lost because the finger itself comes near (its landing
    elsewhere changes that), a hold kept to the end, a finger not holding, and a hold
    that lasts to the motion's last step."""
    triggers = [
        _trigger("ring", 1.2, lost_near="index"),
        _trigger("middle", 1.5),
        _trigger("little", 0.9),
        _trigger("thumb", T_END - DT),
    ]
    state = _state(["ring", "middle", "thumb"], held_to_end=["middle"])
    assert _others_lost_by(_ctx(), state, "index", triggers) is None
    # the same ring hold bounds another finger's landing
    assert _others_lost_by(_ctx(), state, "thumb", triggers) == pytest.approx(1.2)


def test_no_regrasp_of_a_plan_lands_after_another_hold_is_lost(monkeypatch):
    """The Allegro turning the hexagon 180 deg at 40 deg/s: a regrasp of the ring,
    stretched for the velocity limits, used to land at 2.52 s while the middle finger's
    hold was lost at 2.39 s (its fingertip link sinking in), and the search went on
    from there, the middle holding past its loss. Every regrasp the plan takes (backing up
    included) now lands by the earliest loss of another finger's hold, as the triggers
    of the state it starts from give them."""
    spec = next(s for s in neighbour_specs(("allegro",)) if s.name.endswith("+180deg-40dps"))
    scen = build_scenario(spec)
    late, landed = [], []
    step = advance.advance

    def checked(ctx, state, trig, triggers, steps, **kw):
        after = step(ctx, state, trig, triggers, steps, **kw)
        if len(after.regrasps) > len(state.regrasps):
            t_end = after.regrasps[-1].t_end
            landed.append(t_end)
            bound = _others_lost_by(ctx, state, trig.finger, triggers)
            if bound is not None and t_end > bound + 1e-9:
                late.append((trig.finger, t_end, bound))
        return after

    monkeypatch.setattr(planner, "advance", checked)
    monkeypatch.setattr(recovery, "advance", checked)
    try:
        planner.plan_manipulation(
            scen.hand, scen.obj, scen.motion, grasp=scen.grasp, params=scen.params
        )
    except PlanningError:
        pass  # failing or not, no regrasp taken may land late
    assert len(landed) >= 5
    assert late == []
