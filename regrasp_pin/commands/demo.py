"""``regrasp-pin demo``: the paper's scenario end to end, with a summary and figures."""

from __future__ import annotations

import argparse
import json
import sys
import time
from typing import TYPE_CHECKING, Any

from ._args import (
    HAND_METAVAR,
    add_grasp_backups,
    add_time_law,
    add_torsion,
    chosen_time_law,
    hand_argument,
    output_file,
    output_folder,
)
from .summary import plan_summary, print_table, report_failure, write_figures

if TYPE_CHECKING:
    from ..planning.planner import ManipulationPlan
    from ..scenarios import Scenario

NAME = "demo"
HELP = "Plan the canonical regrasping scenario, print a summary, write plan.json and figures."


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the ``demo`` options to ``parser``."""
    parser.add_argument("--out", default="out", help="output folder (default: %(default)s)")
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
        "--object", dest="obj", choices=("hexagon", "octagon", "box"), default="hexagon",
        help="the bundled object (default: %(default)s)",
    )  # fmt: skip
    parser.add_argument(
        "--angle", type=float, default=None,
        help="total rotation [deg], signed (default: 100)",
    )  # fmt: skip
    parser.add_argument(
        "--rate", type=float, default=20.0,
        help="rotation speed [deg/s], > 0 (default: %(default)s)",
    )  # fmt: skip
    parser.add_argument(
        "--json", action="store_true",
        help="print one JSON object on stdout, on success and on failure",
    )  # fmt: skip
    parser.add_argument("--no-plots", action="store_true", help="skip the matplotlib figures")
    parser.add_argument("--meshcat", action="store_true", help="show the plan live in meshcat")
    parser.add_argument("--html", metavar="FILE", help="export the plan as static HTML")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    add_grasp_backups(parser)
    add_time_law(parser)
    add_torsion(parser)


def _scenario(args: argparse.Namespace) -> Scenario:
    from ..grasp.contact import ContactModel
    from ..scenarios import hand_model, make_scenario, scenario_for_hand, setup_objects

    contact = ContactModel(torsion_m=args.torsion_mm * 1e-3)
    if not args.fingers:
        return make_scenario(
            args.hand, args.obj, angle_deg=args.angle, rate_deg_s=args.rate, contact=contact
        )
    return scenario_for_hand(
        hand_model(args.hand),
        setup_objects(args.hand)[args.obj](),
        fingers=args.fingers,
        angle_deg=100.0 if args.angle is None else args.angle,
        rate_deg_s=args.rate,
        contact=contact,
    )


def run(args: argparse.Namespace) -> int:
    """Plan the demo scenario, print its table and write the outputs; return the exit status."""
    from ..backups import plan_scenario
    from ..exceptions import PlanningError
    from ..planning.params import with_time_law

    t0 = time.perf_counter()
    out = output_folder(args.out, "--out")
    if args.html:
        output_file(args.html, "--html")
    scen = _scenario(args)
    if not args.json:
        print(scen.description)
    bar = None if args.quiet or args.json else _progress_bar(scen.motion.duration_s)

    def progress(t_s: float) -> None:
        if bar is None:
            return
        done = round(t_s - scen.motion.t_start, 2)
        if done < bar.n:  # the search backtracks, or a backup plans from the start
            bar.reset(total=bar.total)
        bar.update(done - bar.n)

    def on_backup(finger: str, kind: str) -> None:
        if bar is not None:
            bar.write(f"{finger} failed ({kind}) on its start contact: another initial grasp")

    try:
        result = plan_scenario(
            scen,
            params=with_time_law(scen.params, chosen_time_law(args)),
            grasp_backups=args.grasp_backups,
            progress=progress,
            on_backup=on_backup,
        )
    except PlanningError as exc:
        if bar is not None:
            bar.close()
        return report_failure(scen, exc, out, args.json, time.perf_counter() - t0)
    if bar is not None:
        bar.update(bar.total - bar.n)
        bar.close()
    plan_path = result.plan.save(out / "plan.json")
    figures = [] if args.no_plots else write_figures(result, out)
    summary = plan_summary(scen, result, plan_path, figures, time.perf_counter() - t0)
    if args.json:
        print(json.dumps(summary, indent=2))
    else:
        print_table(summary["rows"], summary)
    _show(args, result)
    return 0


def _show(args: argparse.Namespace, result: ManipulationPlan) -> None:
    """``--html`` and ``--meshcat``."""
    if not (args.html or args.meshcat):
        return
    from ..viz import export_html, show_plan_live, wait_until_interrupted

    if args.html:  # on stderr with --json: stdout holds the JSON alone
        print(
            f"static HTML: {export_html(result.plan, args.html)}",
            file=sys.stderr if args.json else sys.stdout,
        )
    if args.meshcat:
        print(f"meshcat: {show_plan_live(result.plan)}  (Ctrl-C to stop)")
        wait_until_interrupted()


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
