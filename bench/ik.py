"""Batched finger IK against a per-point Pinocchio loop, on the same targets in one run.

Prints solves per second for:
- the batched DLS IK (each backend available: numpy, and numba when installed)
  warm-started (targets near the previous solution, as along a
  trajectory: each joint moved by N(0, 0.02 rad));
- the batched IK cold-started from the middle of the joint box (random reachable
  targets, FK of uniform random configurations);
- the baseline: a per-point Python loop over Pinocchio calls (forwardKinematics +
  updateFramePlacement + computeFrameJacobian + the same DLS step and clamping),
  warm-started on the same targets;
and the ratios. Usage: ``python bench/ik.py [--n N] [--hand five_finger|allegro]``.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import pinocchio as pin
from machine import machine_line

from regrasp_pin import Hand
from regrasp_pin.model.ik import IK_BACKENDS, ik_backend, set_ik_backend
from regrasp_pin.model.ik_numba import available


def loop_ik(hand, finger, targets, q_init, tol_m=1e-5, max_iter=40):
    """Reference per-point loop: one Pinocchio FK + Jacobian + DLS step per iteration."""
    model, data = hand.model, hand.model.createData()
    fid = model.getFrameId(finger.tip_frame)
    vidx = [model.joints[int(j)].idx_v for j in finger.chain.joint_ids]
    qfull = hand.neutral()
    out = np.empty_like(q_init)
    ok = np.zeros(len(targets), bool)
    for i, (target, q0) in enumerate(zip(targets, q_init, strict=True)):
        q = q0.copy()
        for _ in range(max_iter + 1):
            qfull[finger.q_indices] = q
            pin.forwardKinematics(model, data, qfull)
            pin.updateFramePlacement(model, data, fid)
            e = target - data.oMf[fid].translation
            err2 = e @ e
            if err2 <= tol_m * tol_m:
                ok[i] = True
                break
            J = pin.computeFrameJacobian(model, data, qfull, fid, pin.LOCAL_WORLD_ALIGNED)[:3, vidx]
            lam = 1e-8 + 1e-2 * err2
            dq = J.T @ np.linalg.solve(J @ J.T + lam * np.eye(3), e)
            q = np.clip(q + dq, finger.lower, finger.upper)
        out[i] = q
    return out, ok


def best_time(fn, repeats):
    best = np.inf
    result = None
    for _ in range(repeats):
        t0 = time.perf_counter()
        result = fn()
        best = min(best, time.perf_counter() - t0)
    return best, result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=100_000, help="targets per finger")
    parser.add_argument("--n-loop", type=int, default=2000, help="targets for the loop")
    parser.add_argument("--hand", default="five_finger", choices=("five_finger", "allegro"))
    parser.add_argument("--finger", default="index")
    args = parser.parse_args()
    print(machine_line())

    hand = Hand.five_finger() if args.hand == "five_finger" else Hand.allegro()
    finger = hand.finger(args.finger)
    rng = np.random.default_rng(0)
    q_prev = rng.uniform(finger.lower, finger.upper, (args.n, finger.k))
    q_next = np.clip(q_prev + rng.normal(0.0, 0.02, q_prev.shape), finger.lower, finger.upper)
    warm_targets = finger.fk(q_next)
    cold_targets = finger.fk(rng.uniform(finger.lower, finger.upper, (args.n, finger.k)))

    default = ik_backend()
    backends = [b for b in IK_BACKENDS if b == "numpy" or available()]
    rates = {}
    rows = []
    for backend in backends:
        set_ik_backend(backend)
        finger.ik(warm_targets[:10], q_prev[:10])  # numba: load (or compile) the kernel
        t_warm, r_warm = best_time(lambda: finger.ik(warm_targets, q_prev), 3)
        t_cold, r_cold = best_time(lambda: finger.ik(cold_targets), 3)
        rates[backend] = (args.n / t_warm, args.n / t_cold)
        rows.append((f"batched DLS {backend}, warm start", args.n, rates[backend][0], r_warm))
        rows.append((f"batched DLS {backend}, cold start", args.n, rates[backend][1], r_cold))
    set_ik_backend(default)
    m = args.n_loop
    t_loop, (_, ok_loop) = best_time(lambda: loop_ik(hand, finger, warm_targets[:m], q_prev[:m]), 1)
    loop_rate = m / t_loop

    print(f"hand {hand.name}, finger {finger.name} (k={finger.k}), tol 1e-5 m")
    if not available():
        print("numba not installed: numpy backend only (pip install regrasp-pin[fast])")
    print(f"{'solver':34} {'targets':>8} {'solves/s':>12} {'us/solve':>9} {'success':>8}")
    for name, n, rate, res in rows:
        print(f"{name:34} {n:8d} {rate:12,.0f} {1e6 / rate:9.2f} {res.success_rate:8.2%}")
    name = "per-point Pinocchio loop, warm"
    print(f"{name:34} {m:8d} {loop_rate:12,.0f} {1e6 / loop_rate:9.2f} {ok_loop.mean():8.2%}")
    for backend, (warm_rate, cold_rate) in rates.items():
        print(f"{backend:5} warm batched / loop: {warm_rate / loop_rate:6.1f}x (target >= 80x)")
        print(f"{backend:5} cold batched / loop: {cold_rate / loop_rate:6.1f}x")


if __name__ == "__main__":
    main()
