"""Joint-space manifolds and the choice of Q against a per-point IK loop, in one run.

Scene (palm frame: x toward the fingers, z out of the palm): the five-finger hand, a
box 40 x 60 x 40 mm at (65, 0, 60) mm turning about the palm y axis through its centre
at 30 deg/s for 3 s, its surface sampled every 2 mm, 100 object poses. Prints:

- the one-off workspace covers (cached per finger, built on the first manifold);
- the five manifolds (:func:`regrasp_pin.grasp.manifold.build_manifold`), best of 3, on
  each IK backend available (numpy; numba when installed), and how many of their
  flags differ between the backends; with numba, also the fingers on one thread per
  core (:func:`~regrasp_pin.grasp.manifold.build_manifolds`: its kernels release the
  GIL), checked equal to the one-thread manifolds bit for bit;
- the baseline: a per-point loop calling ``Finger.ik`` on one target at a time,
  warm-started from the same point's previous time, on a random subset of the points
  (all 100 times), extrapolated to every point of every finger; and the ratio. Once
  with ``Finger.ik``'s restarts (its default: what the manifold must agree with) and
  once without (cheaper, but a warm start can stay in a local minimum);
- the choice of Q (:func:`regrasp_pin.grasp.choice.choose_new_contact`) for the
  first finger of the initial grasp to trigger, best of 5 (skipped, with the reason,
  when the scene has no initial grasp);
- how many of the manifold's feasible flags differ from the loops' on the subset.

Saves Fig. 1 (object, contacts P and Q) and Fig. 2 (that finger's joint space) into
``--out``. Usage: ``python bench/manifold.py [--subset 12] [--out out/bench]``.
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import numpy as np
from machine import machine_line

from regrasp_pin.exceptions import ContactError
from regrasp_pin.grasp.choice import choose_new_contact
from regrasp_pin.grasp.contact import ContactModel, pad_cosines, tip_targets
from regrasp_pin.grasp.initial import initial_grasp
from regrasp_pin.grasp.manifold import (
    build_manifold,
    build_manifolds,
    forget_first_times,
    workspace_voxels,
)
from regrasp_pin.grasp.tracking import track_contact
from regrasp_pin.model.hand import Hand
from regrasp_pin.model.ik import IK_BACKENDS, ik_backend, set_ik_backend
from regrasp_pin.model.ik_numba import available
from regrasp_pin.model.motion import ObjectMotion
from regrasp_pin.model.objects import Box

REGRASP_S = 0.3  # time from lift-off to landing used for the arrival time of Q


def best_time(fn, repeats):
    best, result = np.inf, None
    for _ in range(repeats):
        t0 = time.perf_counter()
        result = fn()
        best = min(best, time.perf_counter() - t0)
    return best, result


def loop_manifold(finger, targets, normals_palm, contact, restarts):
    """Per-point IK loop: one ``Finger.ik`` call per point and time, warm along time.

    Returns the feasible flags ``(T, n)`` (reached in the limits, pad facing).
    """
    nt, n, _ = targets.shape
    feasible = np.zeros((nt, n), bool)
    for i in range(n):
        q = finger.q_mid
        for t in range(nt):
            res = finger.ik(targets[t, i], q, tol_m=contact.ik_tol_m, restarts=restarts)
            q = res.q[0]
            if res.success[0]:
                cos = pad_cosines(finger, res.q, normals_palm[t, i][None])[0]
                feasible[t, i] = cos >= contact.cos_cone_of(finger)
    return feasible


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--spacing", type=float, default=0.002, help="surface spacing [m]")
    parser.add_argument("--poses", type=int, default=100, help="object poses (grid times)")
    parser.add_argument("--subset", type=int, default=12, help="points per finger in the loop")
    parser.add_argument("--out", type=Path, default=Path("out/bench"), help="figure folder")
    parser.add_argument("--no-figures", action="store_true")
    args = parser.parse_args()
    print(machine_line())

    hand = Hand.five_finger()
    box = Box((0.04, 0.06, 0.04))
    T0 = np.eye(4)
    T0[:3, 3] = [0.065, 0.0, 0.06]
    motion = ObjectMotion.constant_twist(
        T0,
        axis_palm=[0.0, 1.0, 0.0],
        point_palm=T0[:3, 3],
        rate_rad_s=np.radians(30.0),
        duration_s=3.0,
        dt_s=0.01,
    )
    sample = box.sample_surface(args.spacing)
    times = np.linspace(motion.t_start, motion.t_end, args.poses)
    contact = ContactModel()
    names = hand.finger_names

    t_cover, _ = best_time(lambda: [workspace_voxels(hand.finger(n), 0.3) for n in names], 1)

    def build_all():
        forget_first_times()  # each run solves its first times itself
        return {n: build_manifold(hand.finger(n), sample, motion, times) for n in names}

    cores = os.cpu_count() or 1

    def build_threaded():
        forget_first_times()
        return build_manifolds(hand, names, sample, motion, times, threads=cores)

    default = ik_backend()
    t_backend, built = {}, {}
    t_threads, threads_same = None, None
    for backend in [b for b in IK_BACKENDS if b == "numpy" or available()]:
        set_ik_backend(backend)
        build_manifold(hand.finger(names[0]), sample, motion, times[:2])  # numba: load kernel
        t_backend[backend], built[backend] = best_time(build_all, 3)
        if backend == "numba" and cores > 1:
            t_threads, threaded = best_time(build_threaded, 3)
            one = built[backend]
            threads_same = all(
                np.array_equal(getattr(threaded[n], f), getattr(one[n], f), equal_nan=True)
                for n in names
                for f in ("q", "reachable", "inside", "pad_ok", "tip_clear")
            )
    set_ik_backend(default)
    manifolds = built[default]
    t_man = t_backend[default]
    flag_diff = {
        b: sum(
            int((getattr(m, f) != getattr(built["numpy"][n], f)).sum())
            for n, m in ms.items()
            for f in ("reachable", "inside", "pad_ok")
        )
        for b, ms in built.items()
    }

    # baseline on a random subset of the points, every time, every finger
    rng = np.random.default_rng(0)
    subset = rng.choice(len(sample), args.subset, replace=False)
    T_all = motion.pose(times)
    normals_palm = np.einsum("tij,nj->tni", T_all[:, :3, :3], sample.normals[subset])
    t_loop = {True: 0.0, False: 0.0}
    differ = {True: 0, False: 0}
    total = 0
    for n in names:
        f = hand.finger(n)
        targets = tip_targets(sample.points[subset], sample.normals[subset], f.tip_radius, T_all)
        total += targets.shape[0] * targets.shape[1]
        for restarts in (True, False):
            t0 = time.perf_counter()
            feas = loop_manifold(f, targets, normals_palm, contact, restarts)
            t_loop[restarts] += time.perf_counter() - t0
            differ[restarts] += int((feas != manifolds[n].feasible[:, subset]).sum())
    full = {r: t * len(sample) / args.subset for r, t in t_loop.items()}

    n_pts = len(sample)
    total_entries = n_pts * args.poses * len(names)
    print(
        f"five-finger hand, box 40 x 60 x 40 mm every {args.spacing * 1e3:g} mm: {n_pts} "
        f"points x {args.poses} poses x {len(names)} fingers = {total_entries:,} entries"
    )
    if not available():
        print("numba not installed: IK on numpy only (pip install regrasp-pin[fast])")
    print(f"{'step':44} {'time':>10} {'target':>10}")
    rows = [
        ("workspace covers (once per finger, cached)", f"{t_cover:8.2f} s", ""),
        *[
            (f"manifolds, 5 fingers, IK {b} (best of 3)", f"{t:8.2f} s", "<= 1 s")
            for b, t in t_backend.items()
        ],
        *(
            []
            if t_threads is None
            else [
                (
                    f"manifolds, IK numba, {cores} threads (best of 3)",
                    f"{t_threads:8.2f} s",
                    "<= 1 s",
                )
            ]
        ),
        ("per-point Finger.ik loop, restarts (extrap.)", f"{full[True]:8.1f} s", "(~90 s)"),
        (f"  speed-up manifolds ({default}) / loop", f"{full[True] / t_man:8.1f} x", ""),
        ("per-point loop, no restarts (extrap.)", f"{full[False]:8.1f} s", ""),
        (f"  speed-up manifolds ({default}) / loop", f"{full[False] / t_man:8.1f} x", ""),
    ]
    for name, value, target in rows:
        print(f"{name:44} {value:>10} {target:>10}")
    if threads_same is not None:
        print(f"numba on {cores} threads vs one: " + ("bit for bit" if threads_same else "DIFFER"))
    for b, d in flag_diff.items():
        if b != "numpy":
            print(
                f"IK {b} vs numpy: {d} of {3 * total_entries:,} flags differ (reach, inside, pad)"
            )
    print(
        f"loops on {args.subset} random points per finger, all poses ({total} entries); "
        f"feasible flags that differ from the {default} manifolds': {differ[True]} with "
        f"restarts, {differ[False]} without"
    )
    choose_q(args, hand, box, motion, times, sample, contact, manifolds)


def choose_q(args, hand, box, motion, times, sample, contact, manifolds) -> None:
    """Q for the first finger of the initial grasp to trigger, arriving REGRASP_S later."""
    names = hand.finger_names
    try:
        grasp = initial_grasp(hand, box, manifolds, sample)
    except ContactError as exc:
        print(f"choice of Q not timed: no initial grasp on this scene ({exc})")
        return
    tracks = {
        n: track_contact(
            hand,
            n,
            box,
            motion,
            times,
            grasp.points_object[n],
            grasp.normals_object[n],
            grasp.q[n],
            contact=contact,
        )
        for n in names
    }
    trig = {n: tr.trigger()[0] for n, tr in tracks.items() if tr.trigger()[0] is not None}
    finger = min(trig, key=trig.get)
    t_arrive = min(trig[finger] + REGRASP_S, motion.t_end)
    others = {n: (grasp.points_object[n], grasp.normals_object[n]) for n in names if n != finger}

    def choose():
        return choose_new_contact(
            hand,
            box,
            manifolds[finger],
            sample,
            t_arrive,
            P_object=grasp.points_object[finger],
            n_P_object=grasp.normals_object[finger],
            others=others,
            contact=contact,
        )

    t_q, q_new = best_time(choose, 5)
    name = f"choose Q ({finger}, {q_new.n_candidates} candidates, best of 5)"
    print(f"{name:44} {f'{t_q * 1e3:7.1f} ms':>10} {'<= 20 ms':>10}")
    print(
        f"{finger} triggers at {trig[finger]:.2f} s ({tracks[finger].trigger()[1]}); "
        f"Q at {np.round(q_new.p_object * 1e3, 1)} mm, stays until {q_new.exit_time_s:.2f} s, "
        f"rank {q_new.rank}"
    )

    if not args.no_figures:
        from regrasp_pin.plotting.manifold import plot_manifold
        from regrasp_pin.plotting.objects import plot_object

        args.out.mkdir(parents=True, exist_ok=True)
        contacts = np.array([grasp.points_object[n] for n in names] + [q_new.p_object])
        ax = plot_object(  # a coarser sample than the manifolds', to see the contacts
            box,
            box.sample_surface(0.008),
            contacts,
            title=f"Initial grasp and the {finger}'s new contact Q (Fig. 1)",
        )
        ax.figure.savefig(args.out / "fig1_contacts.png", dpi=110)
        fig = plot_manifold(
            manifolds[finger],
            times_idx=np.linspace(0, args.poses - 1, 4).round().astype(int),
            track=tracks[finger],
            q_new=q_new,
        )
        fig.savefig(args.out / "fig2_manifold.png", dpi=110)
        print(f"figures: {args.out / 'fig1_contacts.png'}, {args.out / 'fig2_manifold.png'}")


if __name__ == "__main__":
    main()
