"""Running one suite spec (regrasp_pin.suite.run): backing up to another initial grasp.

Scenes: scenarios of the default suite (seed 0) whose plans fail at a finger that
still holds the contact it started on:

* s0-034, the five-finger hand, a box turned -71 deg about its own axis: no regrasp of
  the index reaches its new contacts by IK at 0.03 s (ik-unreachable); from a grasp
  with the index elsewhere, the plan fails too;
* s0-008, the five-finger hand, a random convex mesh turned +161 deg about its own
  axis: the thumb cannot let go at 2.0 s (force-closure: the others do not hold
  without it), and no contact of it lasts the turn;
* s0-056, the five-finger hand, a random convex mesh turned +118 deg while drifting:
  the thumb cannot let go at 3.47 s either, but it could hold a contact to the end;
* s0-031, the Allegro hand, a box turned -94 deg about its own axis: no new contact of
  the index at 2.4 s keeps its fingertip link out of the box (object-clearance); from
  a grasp with the index away from where it started, the plan is full.
"""

from __future__ import annotations

import numpy as np
import pytest

from regrasp_pin.exceptions import InputError
from regrasp_pin.grasp.holding import holds_to_end, start_holding
from regrasp_pin.plan import Plan
from regrasp_pin.scenarios import GraspSearch
from regrasp_pin.suite import build_scenario, generate_specs, run_scenario, summarize
from regrasp_pin.verify.plan_check import recheck_plan


def _spec(i, hand):
    spec = generate_specs(i + 1, seed=0)[i]
    assert spec.name.startswith(f"s0-{i:03d}-{hand}")
    return spec


@pytest.fixture(scope="module")
def s034(tmp_path_factory):
    spec = _spec(34, "five_finger")
    out = tmp_path_factory.mktemp("s034")
    return spec, run_scenario(spec, out_dir=out, grasp_backups=0), out


def test_a_failure_on_a_start_contact_backs_up_once_and_keeps_the_first_failure(s034):
    spec, alone, _ = s034
    assert alone.failure_kind == "ik-unreachable" and alone.finger == "index"
    assert alone.n_regrasps == 0 and alone.backups == []
    backed = run_scenario(spec)
    # the result is the first failure's, and the backup is listed with what it avoided
    for name in ("ok", "failure_kind", "finger", "time_s", "failure", "n_regrasps"):
        assert getattr(backed, name) == getattr(alone, name), name
    assert len(backed.backups) == 1
    b = backed.backups[0]
    assert b["after"] == "ik-unreachable" and b["finger"] == "index"
    start = build_scenario(spec).grasp.points_object["index"]
    assert np.array_equal(b["avoid_m"], start)
    assert b["outcome"] not in ("ok", None)
    text = summarize([backed])
    assert "backed up to another initial grasp" in text and "full plans after it: 0" in text


def test_a_failure_records_the_time_of_its_first_plans_stages(s034):
    # the partial plan's summary gives the stages up to the failure, and so does the
    # result: the setup (manifolds, proof) and the search, within the planning's time
    spec, alone, out = s034
    partial = Plan.load(out / f"{spec.name}.partial.json")
    assert partial.summary["stage_s"] == pytest.approx(alone.stage_s, abs=0.0)
    assert {"manifolds", "must hold", "tracking", "regrasps"} <= set(alone.stage_s)
    assert all(v >= 0.0 for v in alone.stage_s.values())
    assert sum(alone.stage_s.values()) <= alone.plan_s


def test_backups_share_the_step_budget(s034):
    # given only the steps the first plan spent, nothing is left for a backup
    spec, _, out = s034
    partial = Plan.load(out / f"{spec.name}.partial.json")
    spent = partial.summary["search_steps"]
    assert 0 < spent < 800
    starved = run_scenario(spec, max_steps=spent)
    assert starved.backups == [] and not starved.ok


def test_a_force_closure_failure_backs_up_only_onto_a_contact_held_through():
    # the others do not hold without the thumb: a backup would start it on a contact
    # it holds to the end, and s0-008's thumb has none (every plan must let it go)
    r = run_scenario(_spec(8, "five_finger"))
    assert r.failure_kind == "force-closure" and r.finger == "thumb"
    assert [(b["how"], b["outcome"]) for b in r.backups] == [("held-through", "none-held-through")]


def test_a_finger_that_cannot_let_go_backs_up_onto_a_contact_it_holds_through(tmp_path):
    """s0-056 (five-finger hand, a mesh turned +118 deg while drifting): the thumb
    cannot let go at 3.47 s (force-closure). It could hold a contact from the start
    to the end; from a grasp that starts it there, the plan is full, and the tracking
    (IK and Coal, not the manifold) holds that contact to the end."""
    spec = _spec(56, "five_finger")
    r = run_scenario(spec, out_dir=tmp_path)
    assert r.ok and [(b["how"], b["outcome"]) for b in r.backups] == [("held-through", "ok")]
    assert r.backups[0]["after"] == "force-closure" and r.backups[0]["finger"] == "thumb"
    # the backup's full plan is the result: no failure, and its plan file only (none of
    # the first failure's partial plan)
    assert r.failure_kind is None and r.finger is None and r.attempts == []
    assert sorted(p.name for p in tmp_path.iterdir()) == [f"{spec.name}.json"]
    plan = Plan.load(tmp_path / f"{spec.name}.json")
    assert recheck_plan(plan).ok
    thumb = plan.phases["thumb"]
    assert [ph.kind for ph in thumb] == ["contact"]  # never lets go
    scen = build_scenario(spec)
    m, c = scen.motion, scen.params.contact
    grid = np.linspace(m.t_start, m.t_end, int(round(m.duration_s / 0.02)) + 1)
    k = int(np.argmin(np.abs(plan.t - m.t_start)))
    q0 = plan.q[k, scen.hand.finger("thumb").q_indices]
    held = start_holding(
        scen.hand, scen.obj, m, grid, "thumb", thumb[0].p_object, thumb[0].n_object, q0,
        m.t_start, c,
    )  # fmt: skip
    assert holds_to_end(held.track, m.t_start, c)
    away = np.linalg.norm(thumb[0].p_object - np.array(r.backups[0]["avoid_m"]))
    assert away > 2 * scen.hand.finger("thumb").tip_radius


def test_bad_arguments_name_themselves():
    spec = _spec(34, "five_finger")
    with pytest.raises(InputError, match="grasp_backups"):
        run_scenario(spec, grasp_backups=-1)
    with pytest.raises(InputError, match="time_law"):
        run_scenario(spec, time_law="linear")
    with pytest.raises(InputError, match="torsion_m"):
        run_scenario(spec, torsion_m=-0.001)


def test_an_error_while_building_a_backup_is_its_outcome(s034, monkeypatch):
    # a bug in the backup's grasp search does not lose the scenario's result
    spec, alone, _ = s034
    choose = GraspSearch.choose

    def broken(self, hand, obj, *, keep=None, avoid=None):
        if avoid is not None or keep is not None:
            raise RuntimeError("broken on purpose")
        return choose(self, hand, obj)

    monkeypatch.setattr(GraspSearch, "choose", broken)
    r = run_scenario(spec)
    assert r.failure_kind == alone.failure_kind and r.time_s == alone.time_s
    assert [b["outcome"] for b in r.backups] == ["exception:RuntimeError: broken on purpose"]
