"""The paper's scenario step by step: manifolds, triggers, the whole plan, one regrasp.

A five-finger hand holds a hexagonal prism, which turns like a knob about the thumb's
contact. The script maps the surface into each finger's joint space (Fig. 2), finds
when each held contact meets a boundary plane, plans the whole motion (every regrasp
verified by Coal) and opens up one regrasp: its new contact, surface path, Hopfield
waypoints (Fig. 8) and verification. Writes ``out/examples/plan.json``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from regrasp_pin import build_manifold, make_scenario, plan_manipulation, track_contact


def main(out: Path = Path("out/examples")) -> Path:
    """Walk through the paper's scenario stage by stage; return the saved plan file."""
    scen = make_scenario("five_finger", "hexagon")
    hand, obj, motion, grasp = scen.hand, scen.obj, scen.motion, scen.grasp
    fingers = scen.params.fingers
    print(scen.description)

    # 1. the surface seen from each finger's joint space (Fig. 2)
    sample = obj.sample_surface(0.002)
    times = np.linspace(motion.t_start, motion.t_end, 26)
    for n in fingers:
        m = build_manifold(hand.fingers[n], sample, motion, times)
        print(
            f"{n:7} feasible surface points at t=0: {int(m.feasible[0].sum()):4d}, "
            f"at the end: {int(m.feasible[-1].sum()):4d}"
        )

    # 2. follow each initial contact until it meets a boundary plane (the trigger)
    grid = np.arange(motion.t_start, motion.t_end, 0.01)
    for n in fingers:
        track = track_contact(
            hand, n, obj, motion, grid, grasp.points_object[n], grasp.normals_object[n], grasp.q[n]
        )
        t, why = track.trigger()
        print(f"{n:7} {'holds to the end' if t is None else f'must let go at t={t:.2f} s: {why}'}")

    # 3. the whole hand over the whole motion: holds, triggers, verified regrasps
    result = plan_manipulation(hand, obj, motion, grasp=grasp, params=scen.params)
    print(f"{len(result.regrasps)} regrasps by {sorted({r.finger for r in result.regrasps})}")

    # 4. one regrasp opened up (sections 2.1-2.3)
    r = next(g for g in result.regrasps if g.route == "surface")  # the paper's path
    print(
        f"{r.finger}: P {np.round(1e3 * r.P_object, 1)} -> Q {np.round(1e3 * r.Q_object, 1)} mm, "
        f"grid path {1e3 * r.grid_path.length_m:.1f} mm over faces {r.grid.face_chain}, "
        f"{r.waypoints_object.shape[0]} Hopfield waypoints passed at "
        f"{np.round(r.waypoint_times_s, 2).tolist()} s"
    )
    print(
        f"Coal: {r.report.n_samples} samples, {r.report.n_distance_queries} distance queries, "
        f"min clearance in flight {1e3 * r.min_clearance_m:.2f} mm, closest other finger "
        f"{1e3 * r.report.min_finger_finger_m:.2f} mm"
    )
    path = result.plan.save(out / "plan.json")
    print(f"plan written to {path}")
    return path


if __name__ == "__main__":
    main()
