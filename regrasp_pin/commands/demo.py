"""``regrasp-pin demo``: the paper's scenario end to end, with a summary and figures."""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ._args import HAND_METAVAR, hand_argument

if TYPE_CHECKING:
    from ..planning.planner import ManipulationPlan
    from ..scenarios import Scenario

NAME = "demo"
HELP = "Plan the canonical regrasping scenario, print a summary, write plan.json and figures."


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the ``demo`` options to ``parser``."""
    parser.add_argument("--out", default="out", help="output folder (default: out/)")
    parser.add_argument(
        "--hand",
        type=hand_argument,
        default="five_finger",
        metavar=HAND_METAVAR,
        help="a bundled hand or a JSON hand file (e.g. examples/hands/shadow_hand.json)",
    )
    parser.add_argument(
        "--fingers",
        type=lambda v: tuple(f for f in v.split(",") if f),
        help="comma-separated fingers that grasp (default: the hand's canonical ones; "
        "all of a hand file's)",
    )
    parser.add_argument(
        "--object", dest="obj", choices=("hexagon", "octagon", "box"), default="hexagon"
    )
    parser.add_argument("--angle", type=float, default=None, help="total rotation [deg]")
    parser.add_argument("--rate", type=float, default=20.0, help="rotation speed [deg/s]")
    parser.add_argument("--json", action="store_true", help="print a machine-readable summary")
    parser.add_argument("--no-plots", action="store_true", help="skip the matplotlib figures")
    parser.add_argument("--meshcat", action="store_true", help="show the plan live in meshcat")
    parser.add_argument("--html", metavar="FILE", help="export the plan as static HTML")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")


def summary_rows(result: ManipulationPlan) -> list[dict]:
    """One row per regrasp: what the demo table prints."""
    rows = []
    for r in result.regrasps:
        ph = next(
            p
            for p in result.plan.regrasps()
            if p.finger == r.finger and abs(p.t_start - r.t_start) < 1e-9
        )
        rows.append(
            {
                "finger": r.finger,
                "trigger_s": ph.extra.get("trigger_time_s", r.t_start),
                "t_start_s": r.t_start,
                "t_end_s": r.t_end,
                "P_object_mm": (1e3 * r.P_object).round(1).tolist(),
                "Q_object_mm": (1e3 * r.Q_object).round(1).tolist(),
                "path_length_mm": 1e3 * r.path_length_m,
                "waypoints": int(r.waypoints_object.shape[0]),
                "min_clearance_mm": 1e3 * r.min_clearance_m,
                "planning_ms": r.planning_ms,
                "verified": bool(r.report.ok),
                "reason": ph.reason,
            }
        )
    return rows


def _scenario(args: argparse.Namespace) -> Scenario:
    from ..scenarios import hand_model, make_scenario, scenario_for_hand, setup_objects

    if not args.fingers:
        return make_scenario(args.hand, args.obj, angle_deg=args.angle, rate_deg_s=args.rate)
    return scenario_for_hand(
        hand_model(args.hand),
        setup_objects(args.hand)[args.obj](),
        fingers=args.fingers,
        angle_deg=100.0 if args.angle is None else args.angle,
        rate_deg_s=args.rate,
    )


def run(args: argparse.Namespace) -> int:
    """Plan the demo scenario, print its table and write the outputs; return the exit status."""
    from ..exceptions import PlanningError
    from ..planning.planner import plan_manipulation

    t0 = time.perf_counter()
    scen = _scenario(args)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    if not args.json:
        print(scen.description)
    bar = None if args.quiet or args.json else _progress_bar(scen.motion.duration_s)

    def progress(t_s: float) -> None:
        if bar is not None:
            bar.update(round(t_s - scen.motion.t_start, 2) - bar.n)

    try:
        result = plan_manipulation(
            scen.hand,
            scen.obj,
            scen.motion,
            grasp=scen.grasp,
            params=scen.params,
            progress=progress,
        )
    except PlanningError as exc:
        if bar is not None:
            bar.close()
        if exc.partial is not None:
            exc.partial.save(out / "partial_plan.json")
            print(f"partial plan written to {out / 'partial_plan.json'}", file=sys.stderr)
        raise
    if bar is not None:
        bar.update(bar.total - bar.n)
        bar.close()
    plan_path = result.plan.save(out / "plan.json")
    elapsed = time.perf_counter() - t0
    rows = summary_rows(result)
    figures = [] if args.no_plots else _figures(result, out)
    summary = {
        "scenario": scen.description,
        "hand": scen.hand.name,
        "object": scen.obj.kind,
        "duration_s": scen.motion.duration_s,
        "regrasps": len(rows),
        "fingers_regrasped": sorted({r["finger"] for r in rows}),
        "all_verified": all(r["verified"] for r in rows),
        "rows": rows,
        "releases": _release_rows(result),
        "joins": [
            {"finger": p.finger, "t_s": p.t_start, "t_end_s": p.t_end, "reason": p.reason}
            for p in result.plan.joins()
        ],
        "stage_s": result.stage_s,
        "total_s": elapsed,
        "plan": str(plan_path),
        "figures": [str(f) for f in figures],
    }
    if args.json:
        print(json.dumps(summary, indent=2))
    else:
        _print_table(rows, summary)
    if args.html or args.meshcat:
        from ..viz import export_html, show_plan_live, wait_until_interrupted

        if args.html:
            print(f"static HTML: {export_html(result.plan, args.html)}")
        if args.meshcat:
            print(f"meshcat: {show_plan_live(result.plan)}  (Ctrl-C to stop)")
            wait_until_interrupted()
    return 0


def _progress_bar(duration_s: float) -> Any:
    """A tqdm bar over the motion's duration [s] on stderr (None without tqdm)."""
    try:
        from tqdm import tqdm
    except ImportError:  # pragma: no cover - tqdm is a dependency
        return None
    return tqdm(
        total=round(duration_s, 2),
        unit="s",
        desc="planning",
        file=sys.stderr,
        bar_format="{l_bar}{bar}| {n:.2f}/{total:.2f} s",
    )


def _release_rows(result: ManipulationPlan) -> list[dict]:
    """One row per release: finger, time [s], smallest clearance [mm]."""
    return [
        {"finger": p.finger, "t_s": p.t_start, "min_clearance_mm": 1e3 * p.min_clearance_m}
        for p in result.plan.releases()
    ]


def _print_table(rows: list[dict], summary: dict) -> None:
    head = (
        f"{'finger':7} {'trigger':>8} {'lift-off':>8} {'P [mm]':>20} {'Q [mm]':>20} "
        f"{'path':>7} {'wp':>3} {'clear':>6} {'plan':>7}"
    )
    print()
    print(head)
    print(f"{'':7} {'[s]':>8} {'[s]':>8} {'(object frame)':>20} {'(object frame)':>20} "
          f"{'[mm]':>7} {'':>3} {'[mm]':>6} {'[ms]':>7}")  # fmt: skip
    print("-" * len(head))
    for r in rows:
        P = ",".join(f"{v:.0f}" for v in r["P_object_mm"])
        Q = ",".join(f"{v:.0f}" for v in r["Q_object_mm"])
        print(
            f"{r['finger']:7} {r['trigger_s']:8.2f} {r['t_start_s']:8.2f} {P:>20} {Q:>20} "
            f"{r['path_length_mm']:7.1f} {r['waypoints']:3d} {r['min_clearance_mm']:6.2f} "
            f"{r['planning_ms']:7.0f}"
        )
    print("-" * len(head))
    n = len(rows)
    if n:
        print(
            f"{n} regrasps by {len(summary['fingers_regrasped'])} fingers "
            f"({', '.join(summary['fingers_regrasped'])}), all verified by Coal: "
            f"{summary['all_verified']}; "
            f"total path {sum(r['path_length_mm'] for r in rows):.0f} mm, "
            f"min clearance {min(r['min_clearance_mm'] for r in rows):.2f} mm, "
            f"planning {sum(r['planning_ms'] for r in rows):.0f} ms"
        )
    for rel in summary["releases"]:
        print(
            f"{rel['finger']} lets go at t={rel['t_s']:.2f} s (no verified regrasp), "
            f"verified by Coal, {rel['min_clearance_mm']:.2f} mm clear after backing off"
        )
    for j in summary["joins"]:
        print(
            f"{j['finger']} joins at t={j['t_s']:.2f}-{j['t_end_s']:.2f} s ({j['reason']}), "
            "verified by Coal"
        )
    stages = ", ".join(f"{k} {v:.2f} s" for k, v in summary["stage_s"].items())
    print(f"stages: {stages}; total {summary['total_s']:.2f} s")
    print(f"plan: {summary['plan']}")
    for f in summary["figures"]:
        print(f"figure: {f}")


def _figures(result: ManipulationPlan, out: Path) -> list[Path]:
    """Fig. 9 (forefinger joint angles), Fig. 2 (one regrasp's manifold), Fig. 8."""
    from ..plotting import require_pyplot

    plt = require_pyplot()
    files = []
    from ..plotting.joints import plot_joint_angles

    taking_part = [f for f, ps in result.plan.phases.items() if ps[0].kind != "idle"]
    forefinger = "index" if "index" in taking_part else taking_part[0]
    fig = plot_joint_angles(result.plan, forefinger)
    files.append(out / "fig9_joint_angles.png")
    fig.savefig(files[-1], dpi=110)
    plt.close(fig)
    if result.regrasps:
        r = next((g for g in result.regrasps if g.finger == forefinger), result.regrasps[0])
        try:
            from ..plotting.manifold import plot_manifold

            man = result.manifolds[r.finger]
            fig = plot_manifold(man, q_new=r.q[-1], trigger_index=man.time_index(r.t_start))
            fig.gca().set_title(
                f"{r.finger}: joint-space manifold (Fig. 2), regrasp at {r.t_start:.2f} s"
            )
            files.append(out / "fig2_manifold.png")
            fig.savefig(files[-1], dpi=110)
            plt.close(fig)
        except ImportError:  # the Fig. 2 module is optional
            pass
        from ..plotting.surface import plot_unfolded_grid
        from ..surface.inflation import grid_inflation

        p = r.params
        height = p.inflation_factor * p.clearance_m
        heights = grid_inflation(r.grid, height, r.tip_path.taper_m)
        fig = plot_unfolded_grid(
            r.grid,
            path=r.grid_path,
            heights=heights,
            polygon_indices=r.polygon.indices,
            tip_path=r.tip_path,
        )
        files.append(out / "fig8_hopfield_path.png")
        fig.savefig(files[-1], dpi=110)
        plt.close(fig)
    return files
