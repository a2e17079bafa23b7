"""The regrasp pipeline on the four-finger Allegro hand from example-robot-data.

Loads the Allegro right hand offline. A 50 mm cube turns at 20 deg/s in front of the
palm; the index finger's surface manifold is built, its contact P is followed to its
trigger, the new contact Q is chosen by the paper's rule (inside the limits on
arrival, inside longest afterwards), and the regrasp P -> Q is planned on the inflated
surface, reduced to Hopfield waypoints, synchronized with the motion and verified by
Coal. The other fingers are bent back, out of the way.

(The whole-hand plan with the Allegro's own fingers holding is not yet found for this
object by the bundled scenarios; see ``regrasp-pin demo --hand allegro``.)
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from regrasp_pin import (
    Box,
    Hand,
    LinkClearance,
    ObjectMotion,
    RegraspError,
    RegraspResult,
    build_manifold,
    exit_times,
    plan_regrasp,
    track_contact,
)


def main(out: Path = Path("out/examples")) -> RegraspResult:
    """Plan one verified regrasp of the Allegro index finger; return it."""
    hand = Hand.allegro()
    finger = hand.fingers["index"]
    q_rest = hand.neutral()
    for name, f in hand.fingers.items():
        if name != "index":  # bent back, away from the cube
            q_rest[f.q_indices] = f.lower
            if name != "thumb":
                q_rest[f.q_indices[0]] = 0.0
    cube = Box((0.05, 0.05, 0.05))
    T0 = np.eye(4)
    T0[:3, 3] = [0.07, 0.05, 0.04]
    motion = ObjectMotion.constant_twist(
        T0, axis_palm=[0, 1, 0], point_palm=T0[:3, 3], rate_rad_s=np.radians(20), duration_s=2.0
    )
    sample = cube.sample_surface(0.002)
    times = np.linspace(0.0, 2.0, 41)
    manifold = build_manifold(finger, sample, motion, times)
    links = LinkClearance(hand, "index", cube)

    def clear(k: int, idx: np.ndarray) -> np.ndarray:
        q_full = hand.to_full("index", manifold.q[k, idx], q_rest)
        return links(q_full, manifold.T_palm_object[k]) >= 0.003

    # P: the usable contact at t = 0 with the largest joint margin
    usable = manifold.usable(0.08)
    idx = np.flatnonzero(usable[0])
    idx = idx[clear(0, idx)]
    p = int(idx[np.argmax(manifold.margin_rad[0, idx])])
    grid = np.arange(0.0, 2.0, 0.01)
    track = track_contact(
        hand, "index", cube, motion, grid, sample.points[p], sample.normals[p], manifold.q[0, p]
    )
    t_trig, why = track.trigger()
    print(
        f"index holds P={np.round(1e3 * sample.points[p], 1)} mm until "
        f"{'the end' if t_trig is None else f't={t_trig:.2f} s ({why})'}"
    )

    # Q: inside the limits on arrival, and inside longest afterwards (the paper's rule)
    t0 = 0.3 if t_trig is None else max(0.0, min(t_trig, 1.4) - 0.05)
    duration = 0.5
    k = manifold.time_index(t0 + duration)
    cand = np.flatnonzero(
        usable[k] & (np.linalg.norm(sample.points - sample.points[p], axis=1) > 0.02)
    )
    cand = cand[clear(k, cand)]
    t_exit = exit_times(usable[:, cand], manifold.times_s, k)
    order = np.lexsort((-manifold.margin_rad[k, cand], -t_exit))
    i0 = int(np.searchsorted(grid, t0))
    for j in order[:5]:
        q = int(cand[j])
        try:
            result = plan_regrasp(
                hand,
                cube,
                motion,
                "index",
                float(grid[i0]),
                sample.points[p],
                sample.normals[p],
                sample.points[q],
                sample.normals[q],
                track.q[i0],
                lambda t: np.broadcast_to(q_rest, (len(t), q_rest.size)).copy(),
            )
        except RegraspError as exc:  # report it and try the next candidate
            print(f"Q={np.round(1e3 * sample.points[q], 1)} mm: {exc}")
            continue
        print(
            f"regrasp at t={grid[i0]:.2f} s to Q={np.round(1e3 * sample.points[q], 1)} mm "
            f"(inside until t={t_exit[j]:.2f} s): {result.waypoints_object.shape[0]} waypoints, "
            f"verified by Coal ({result.report.n_samples} samples), min clearance "
            f"{1e3 * result.min_clearance_m:.2f} mm, {result.planning_ms:.0f} ms"
        )
        return result
    raise RuntimeError("no verified regrasp for the five best new contacts")


if __name__ == "__main__":
    main()
