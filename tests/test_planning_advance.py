"""One step of the plan (regrasp_pin.planning.advance): what a regrasp must land by, and
when a finger holds on to the end instead."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from regrasp_pin.exceptions import FailureKind, PlanningError
from regrasp_pin.grasp.contact import ContactModel
from regrasp_pin.planning import advance, planner, recovery
from regrasp_pin.planning.advance import _held_to_end, _others_lost_by
from regrasp_pin.planning.state import PlanState, Trigger
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
    that lasts to the motion's end."""
    triggers = [
        _trigger("ring", 1.2, lost_near="index"),
        _trigger("middle", 1.5),
        _trigger("little", 0.9),
        _trigger("thumb", T_END),
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


# ------------------------------------------------------------ holding to the end
def _track(t_end, lost_at=None):
    """A contact track sampled every DT to ``t_end``: reached, inside the limits, pad
    facing, links clear; from ``lost_at`` on outside a joint limit."""
    times = np.arange(0.0, t_end + DT / 2, DT)
    margin = np.full(times.size, 0.01)  # within a trigger margin, not past the limit
    if lost_at is not None:
        margin[times >= lost_at - 1e-9] = -0.01
    return SimpleNamespace(
        times_s=times,
        error_m=np.zeros(times.size),
        margin_rad=margin,
        pad_cos=np.ones(times.size),
        cos_cone=0.5,
        link_clearance_m=np.full(times.size, 0.002),
    )


def _holding_ctx():
    contact = ContactModel()
    return SimpleNamespace(
        scene=SimpleNamespace(motion=SimpleNamespace(t_end=T_END)),
        params=SimpleNamespace(dt_s=DT, contact=contact, regrasp=SimpleNamespace(duration_s=0.25)),
    )


def _holding_state(track):
    return PlanState(
        holding={"ring": SimpleNamespace(track=track)},
        history={},
        phases={},
        regrasps=(),
        now=0.0,
        held_to_end={},
    )


def test_a_hold_that_lasts_to_the_end_needs_no_regrasp():
    """A trigger warns before a hold is lost: a finger whose hold is not lost before
    the motion's end, and whose contact stays reached, inside its limits, pad facing
    and clear to the end, may hold on to the end; one whose contact leaves its limits
    before the end, or whose hold is lost before (at the last sample too: the plan's
    last sample is the re-check's as well), may not."""
    ctx = _holding_ctx()
    lasting = _holding_state(_track(T_END))
    held = _held_to_end(ctx, lasting, _trigger("ring", T_END), "why")
    assert held is not None and held.held_to_end["ring"].endswith(
        "why; held to the end inside the joint limits"
    )
    assert held.holding == lasting.holding and held.now == lasting.now
    # lost (by the trigger) before the motion's end, or only at its last sample
    assert _held_to_end(ctx, lasting, _trigger("ring", T_END - 3 * DT), "why") is None
    assert _held_to_end(ctx, lasting, _trigger("ring", T_END - DT), "why") is None
    # the track leaves the joint limits before the end
    leaving = _holding_state(_track(T_END, lost_at=T_END - 0.5))
    assert _held_to_end(ctx, leaving, _trigger("ring", T_END), "why") is None


@pytest.mark.parametrize("may_hold", [True, False])
def test_a_finger_that_cannot_regrasp_holds_on_if_its_hold_lasts(monkeypatch, may_hold):
    """When no regrasp (nor let-go) is found, a finger whose hold lasts to the end holds
    on instead of failing the plan; not when the regrasp was asked for to move the
    finger (``may_hold`` False: making room), and not when the hold does not last."""
    ctx = _holding_ctx()
    failure = PlanningError("no room", finger="ring", kind=FailureKind.TOO_FEW_FINGERS)

    def fails(*args, **kwargs):
        raise failure

    monkeypatch.setattr(advance, "_advance", fails)
    monkeypatch.setattr(
        advance, "window", lambda ctx, state, trig, triggers: (SimpleNamespace(preferred_s=1.0), "")
    )
    state = _holding_state(_track(T_END))
    trig = _trigger("ring", T_END)
    if may_hold:
        after = advance.advance(ctx, state, trig, [trig], [])
        assert "no regrasp (too-few-fingers)" in after.held_to_end["ring"]
    else:
        with pytest.raises(PlanningError) as err:
            advance.advance(ctx, state, trig, [trig], [], may_hold=False)
        assert err.value is failure
    with pytest.raises(PlanningError):
        advance.advance(ctx, _holding_state(_track(T_END, lost_at=3.0)), trig, [trig], [])


@pytest.mark.parametrize("case", ["lasting", "short", "joined"])
def test_a_finger_the_others_cannot_hold_without_says_whether_any_grasp_could_keep_it(case):
    """The force-closure failure of a finger that must let go (the three others all
    press on one face: no force closure without it) says how long any of its start
    contacts could be held, by its manifold with the contact model's margin: to the
    motion's end, a grasp could have started it there; short of it, every plan must let
    it go, and the object's place is what to change. A finger that joined later did
    not hold from the start: nothing is said of its start contacts."""
    times = np.linspace(0.0, T_END, 11)
    holdable = np.ones((times.size, 3), bool)
    holdable[4:, 0] = False  # the longest-lasting start contact is lost at 2.0 s
    holdable[2:, 1] = False
    holdable[:, 2] = case != "short"
    margins = []

    def read(margin):
        margins.append(margin)
        return holdable

    man = SimpleNamespace(times_s=times, holdable=read)
    top = np.array([0.0, 0.0, 1.0])
    contact = ContactModel()
    ctx = SimpleNamespace(
        scene=SimpleNamespace(
            hand=SimpleNamespace(finger_names=("thumb", "index", "middle", "ring")),
            obj=SimpleNamespace(radius_m=0.03),
            motion=SimpleNamespace(t_end=T_END),
        ),
        params=SimpleNamespace(fewest_holding=3, mu=0.8, contact=contact),
        manifolds={"thumb": man},
        # the fingers of the initial grasp; one that joined later is not among them
        active=("index", "middle", "ring") + (() if case == "joined" else ("thumb",)),
    )
    holding = {
        n: SimpleNamespace(p=np.array([x, y, 0.02]), n=top)
        for n, x, y in [("index", 0.01, 0.0), ("middle", -0.01, 0.01), ("ring", 0.0, -0.01)]
    }
    holding["thumb"] = SimpleNamespace(p=np.array([0.0, 0.0, -0.02]), n=-top)
    state = SimpleNamespace(holding=holding, joined={"thumb": object()} if case == "joined" else {})
    # a finger of the initial grasp that let go and joined again is judged by its start
    if case == "lasting":
        state.joined = {"thumb": object()}
    trig = Trigger(time_s=1.2, finger="thumb", reason="near its limit", lost_s=1.5)
    with pytest.raises(PlanningError) as err:
        advance._fingers_that_stay(ctx, state, trig, SimpleNamespace(preferred_s=1.2))
    assert err.value.kind == FailureKind.FORCE_CLOSURE and err.value.finger == "thumb"
    text = str(err.value)
    assert "the other fingers are not in force closure" in text
    if case == "joined":
        assert margins == [] and "contact" not in text.split("force closure", 1)[1]
        return
    assert margins == [contact.limit_margin_rad]
    if case == "lasting":
        assert "thumb could hold a contact from the start to the end" in text
    else:
        assert "the longest until t=2.00 s, the motion ends at t=5.00 s" in text
        assert "every plan must let thumb go" in text
