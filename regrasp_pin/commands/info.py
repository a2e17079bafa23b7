"""``regrasp-pin info``: print a hand's fingers, joint limits, and a solved IK round trip."""

from __future__ import annotations

import argparse
import json

from ._args import HAND_METAVAR, hand_argument

NAME = "info"
HELP = "Show a hand's fingers, joint limits and a solved IK round trip."


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the ``info`` options to ``parser``."""
    parser.add_argument(
        "--hand",
        type=hand_argument,
        default="five_finger",
        metavar=HAND_METAVAR,
        help="a bundled hand or a JSON hand file (e.g. examples/hands/shadow_hand.json)",
    )
    parser.add_argument("--json", action="store_true", help="print one JSON object")


def run(args: argparse.Namespace) -> int:
    """Print the hand's fingers, joints and limits; return the exit status."""
    import numpy as np

    from ..scenarios import hand_model

    hand = hand_model(args.hand)
    rng = np.random.default_rng(0)
    report = {"hand": hand.name, "urdf": str(hand.urdf_path), "nq": hand.model.nq, "fingers": {}}
    for f in hand.fingers.values():
        q_true = rng.uniform(f.lower, f.upper)
        target = f.fk(q_true)
        res = f.ik(target)
        report["fingers"][f.name] = {
            "tip_frame": f.tip_frame,
            "tip_radius_m": f.tip_radius,
            "pad_cone_deg": f.pad_cone_deg,
            "joints": list(f.joint_names),
            "lower_rad": f.lower.round(4).tolist(),
            "upper_rad": f.upper.round(4).tolist(),
            "ik_target_palm_m": target.round(5).tolist(),
            "ik_q_rad": res.q[0].round(4).tolist(),
            "ik_error_m": float(res.error_m[0]),
            "ik_success": bool(res.success[0]),
        }
    if args.json:
        print(json.dumps(report, indent=2))
        return 0
    print(f"{hand.name}: {hand.model.nq} joint variables, URDF {hand.urdf_path}")
    header = f"{'finger':8} {'tip frame':14} {'r [mm]':>6} {'cone':>5}  joints [lower, upper] (deg)"
    print(header)
    for name, fr in report["fingers"].items():
        limits = ", ".join(
            f"{j} [{np.degrees(lo):.0f}, {np.degrees(hi):.0f}]"
            for j, lo, hi in zip(fr["joints"], fr["lower_rad"], fr["upper_rad"], strict=True)
        )
        cone = f"{fr['pad_cone_deg']:.0f}"
        print(f"{name:8} {fr['tip_frame']:14} {fr['tip_radius_m'] * 1e3:6.1f} {cone:>5}  {limits}")
    print("\nIK round trip (random q inside the limits -> FK -> IK from the box centre):")
    for name, fr in report["fingers"].items():
        t = ", ".join(f"{v * 1e3:.1f}" for v in fr["ik_target_palm_m"])
        print(
            f"{name:8} target [{t}] mm -> error {fr['ik_error_m'] * 1e6:.2f} um "
            f"({'ok' if fr['ik_success'] else 'FAILED'})"
        )
    return 0
