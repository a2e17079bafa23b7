"""The paper's scenario step by step: manifolds, trigger, new contact, one regrasp, the plan.

A five-finger hand holds a hexagonal prism; the prism turns like a knob. This script
walks through the pipeline with the public API, one stage at a time (Figs. 1-4, 8, 9
of the paper), then plans the whole motion and writes ``out/examples/plan.json``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from regrasp_pin import (
    build_manifold,
    choose_new_contact,
    make_scenario,
    plan_manipulation,
    plan_regrasp,
    track_contact,
)
from regrasp_pin.planner import holding_hand


def main(out: Path = Path("out/examples")) -> None:
    scen = make_scenario("five_finger", "hexagon", angle_deg=-100)
    hand, obj, motion, grasp = scen.hand, scen.obj, scen.motion, scen.grasp
    print(scen.description)

    # 1. the surface seen from each finger's joint space (Fig. 2)
    sample = obj.sample_surface(0.002)
    times = np.linspace(motion.t_start, motion.t_end, 69)
    fingers = scen.params.fingers
    manifolds = {n: build_manifold(hand.fingers[n], sample, motion, times) for n in fingers}
    for n, m in manifolds.items():
        print(f"{n:7} feasible surface points at t=0: {int(m.feasible[0].sum())}")

    # 2. follow the index contact until it meets a boundary plane (the trigger)
    grid = np.arange(motion.t_start, motion.t_end, 0.01)
    track = track_contact(
        hand,
        "index",
        obj,
        motion,
        grid,
        grasp.points_object["index"],
        grasp.normals_object["index"],
        grasp.q["index"],
    )
    t_trig, why = track.trigger()
    print(f"index triggers at t={t_trig} s: {why}")
    if t_trig is None:
        return

    # 3. the new contact Q: inside the limits on arrival, inside longest afterwards
    duration = scen.params.regrasp.duration_s
    others = {n: (grasp.points_object[n], grasp.normals_object[n]) for n in fingers if n != "index"}
    q_hand_at = holding_hand(hand, motion, grasp, fingers, "index")
    new = choose_new_contact(
        hand,
        obj,
        manifolds["index"],
        sample,
        t_trig + duration,
        P_object=grasp.points_object["index"],
        n_P_object=grasp.normals_object["index"],
        others=others,
        q_hand_arrive=q_hand_at(np.array([t_trig + duration]))[0],
    )
    print(f"Q = {np.round(1e3 * new.p_object, 1)} mm, inside until t={new.exit_time_s:.2f} s")

    # 4. one verified regrasp: inflated surface, grid path, Hopfield waypoints, IK, Coal
    i0 = int(np.searchsorted(grid, t_trig - 0.02))
    result = plan_regrasp(
        hand,
        obj,
        motion,
        "index",
        float(grid[i0]),
        grasp.points_object["index"],
        grasp.normals_object["index"],
        new.p_object,
        new.n_object,
        track.q[i0],
        q_hand_at,
        params=scen.params.regrasp,
    )
    print(
        f"regrasp verified: {result.waypoints_object.shape[0]} waypoints, path "
        f"{1e3 * result.path_length_m:.1f} mm, "
        f"min clearance {1e3 * result.min_clearance_m:.2f} mm, "
        f"{result.planning_ms:.0f} ms"
    )

    # 5. the whole hand over the whole motion
    plan = plan_manipulation(hand, obj, motion, grasp=grasp, params=scen.params)
    print(f"{len(plan.regrasps)} regrasps by {sorted({r.finger for r in plan.regrasps})}")
    print(f"plan written to {plan.plan.save(out / 'plan.json')}")


if __name__ == "__main__":
    main()
