"""The same pipeline on the four-finger Allegro hand from example-robot-data.

Loads the Allegro right hand offline, builds its scenario (a hexagonal prism held
between the thumb and three fingers, turned about the thumb's contact), follows every
contact until the first one meets a boundary plane, chooses the new contact Q, and
plans and verifies that regrasp with Coal while the others keep holding.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from regrasp_pin import (
    RegraspError,
    build_manifold,
    choose_new_contact,
    make_scenario,
    plan_regrasp,
    track_contact,
)
from regrasp_pin.planner import holding_hand


def main(out: Path = Path("out/examples")) -> None:
    scen = make_scenario("allegro", "hexagon", angle_deg=60)
    hand, obj, motion, grasp = scen.hand, scen.obj, scen.motion, scen.grasp
    fingers = scen.params.fingers
    print(scen.description)
    grid = np.arange(motion.t_start, motion.t_end, 0.01)
    tracks = {
        n: track_contact(
            hand, n, obj, motion, grid, grasp.points_object[n], grasp.normals_object[n], grasp.q[n]
        )
        for n in fingers
    }
    for n, tr in tracks.items():
        t, why = tr.trigger()
        print(f"{n:7} holds until {'the end' if t is None else f't={t:.2f} s'} {why}")
    sample = obj.sample_surface(0.002)
    times = np.linspace(motion.t_start, motion.t_end, 31)
    duration = scen.params.regrasp.duration_s
    order = sorted((tr.trigger()[0], n) for n, tr in tracks.items() if tr.trigger()[0] is not None)
    last_error = None
    for t_trig, name in order:  # the first finger (in trigger order) with a verified regrasp
        i0 = max(int(np.searchsorted(grid, t_trig)) - 2, 0)
        t0 = float(grid[i0])
        if t0 + duration > motion.t_end:
            continue  # too late: the regrasp would not end before the motion does
        q_hand = holding_hand(hand, motion, grasp, fingers, name)
        manifold = build_manifold(hand.fingers[name], sample, motion, times)
        others = {
            n: (grasp.points_object[n], grasp.normals_object[n]) for n in fingers if n != name
        }
        try:
            new = choose_new_contact(
                hand,
                obj,
                manifold,
                sample,
                t0 + duration,
                P_object=grasp.points_object[name],
                n_P_object=grasp.normals_object[name],
                others=others,
                q_hand_arrive=q_hand(np.array([t0 + duration]))[0],
                finger_clearance_m=0.001,
            )
            result = plan_regrasp(
                hand,
                obj,
                motion,
                name,
                t0,
                grasp.points_object[name],
                grasp.normals_object[name],
                new.p_object,
                new.n_object,
                tracks[name].q[i0],
                q_hand,
                params=scen.params.regrasp,
            )
        except RegraspError as exc:
            print(f"{name}: no verified regrasp at t={t0:.2f} s ({exc})")
            last_error = exc
            continue
        print(
            f"{name} regrasps at t={t0:.2f} s to Q={np.round(1e3 * new.p_object, 1)} mm: "
            f"verified by Coal ({result.report.n_samples} samples), min clearance "
            f"{1e3 * result.min_clearance_m:.2f} mm, {result.planning_ms:.0f} ms"
        )
        return
    raise last_error if last_error is not None else RuntimeError("no finger triggered")


if __name__ == "__main__":
    main()
