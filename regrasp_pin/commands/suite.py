"""``regrasp-pin suite``: run the scenario suite on Dask (this machine or a cluster)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ._args import (
    HAND_METAVAR,
    add_grasp_backups,
    add_time_law,
    add_torsion,
    hand_argument,
    output_folder,
)

NAME = "suite"
HELP = (
    "Run the scenario suite, one Dask task per scenario (a local cluster, or --scheduler), "
    "and write results.jsonl and report.html; needs the scale extra."
)

OBJECT_KINDS = ("prism", "box", "mesh")  # regrasp_pin.suite.OBJECT_KINDS (kept light)
MOTION_KINDS = ("object-axis", "contact-axis", "rotate-translate")
EXIT_INTERRUPTED = 130


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the ``suite`` options to ``parser``."""
    what = parser.add_argument_group("which scenarios")
    what.add_argument(
        "--n", type=int, default=100,
        help="scenarios with an initial grasp (default: %(default)s)",
    )  # fmt: skip
    what.add_argument("--seed", type=int, default=0, help="suite seed (default: %(default)s)")
    what.add_argument(
        "--hand", action="append", dest="hands", type=hand_argument, metavar=HAND_METAVAR,
        help="a hand (repeat for several; default: five_finger and allegro)",
    )  # fmt: skip
    what.add_argument(
        "--object", action="append", dest="objects", choices=OBJECT_KINDS,
        help="object kinds to keep (repeat; default: all)",
    )  # fmt: skip
    what.add_argument(
        "--motion", action="append", dest="motions", choices=MOTION_KINDS,
        help="motion kinds to keep (repeat; default: all)",
    )  # fmt: skip
    what.add_argument(
        "--neighbours", action="store_true",
        help="the canonical demo and its neighbours instead (15 per hand)",
    )  # fmt: skip
    where = parser.add_argument_group("where and how")
    where.add_argument("--out", type=Path, help="output folder (required unless --report)")
    where.add_argument(
        "--workers", type=int, default=None,
        help="processes of the local cluster (default: the machine's cores)",
    )  # fmt: skip
    where.add_argument(
        "--scheduler", metavar="ADDRESS", default=None,
        help="an existing Dask scheduler, e.g. tcp://host:8786 (default: a local cluster)",
    )  # fmt: skip
    where.add_argument(
        "--timeout-s", type=float, default=None,
        help="stop a scenario after this many seconds; it counts as a 'timeout' failure "
        "(default: no limit)",
    )  # fmt: skip
    where.add_argument(
        "--resume", action="store_true",
        help="keep the results already in --out and run only the others",
    )  # fmt: skip
    where.add_argument(
        "--max-steps", type=int, default=None,
        help="the planner's search budget in steps (default: PlannerParams.max_steps)",
    )  # fmt: skip
    add_grasp_backups(where)
    add_time_law(where)
    add_torsion(where)
    report = parser.add_argument_group("report")
    report.add_argument(
        "--report", metavar="DIR", type=Path, default=None,
        help="only rebuild DIR/report.html and report.md from DIR/results.jsonl",
    )  # fmt: skip
    report.add_argument(
        "--no-viewer", action="store_true",
        help="no static viewer page per plan (each is ~2 MB and ~1 s)",
    )  # fmt: skip
    parser.add_argument("-q", "--quiet", action="store_true", help="no progress bar or lines")


def _specs(args: argparse.Namespace) -> tuple[list, int, bool, str]:
    from ..scenarios import HANDS
    from ..suite import neighbour_specs, select_specs

    # hand files by absolute path: the workers may run elsewhere than here
    hands = tuple(str(Path(h).resolve()) if h.endswith(".json") else h for h in args.hands or HANDS)
    if args.neighbours:
        specs = neighbour_specs(hands)
        return specs, len(specs), False, f"the demo and its neighbours ({len(specs)})"
    specs = select_specs(
        args.n,
        args.seed,
        hands,
        objects=tuple(args.objects or OBJECT_KINDS),
        motions=tuple(args.motions or MOTION_KINDS),
    )
    return specs, args.n, True, f"suite seed {args.seed}, {args.n} scenarios with an initial grasp"


def run(args: argparse.Namespace) -> int:
    """Run the suite (or rebuild a report); return the exit status."""
    from ..exceptions import InputError

    if args.report is not None:
        from ..suite.pages import write_report

        files = write_report(args.report, viewer_pages=not args.no_viewer)
        print(f"wrote {files.html} and {files.markdown} ({len(files.viewer_pages)} viewer pages)")
        return 0
    if args.out is None:
        raise InputError("--out", "is missing", "an output folder (or --report DIR)")
    output_folder(args.out, "--out")
    from ..suite.cluster import require_scale

    require_scale()  # says which extra to install before anything is started
    from tqdm import tqdm

    from ..suite import ScenarioResult, summarize, time_spent
    from ..suite.cluster import run_suite
    from ..suite.pages import write_report
    from ..suite.report import result_line

    specs, n, skip, what = _specs(args)
    where = args.scheduler or f"a local cluster of {args.workers or 'all cores'} worker(s)"
    if args.torsion_mm > 0.0:
        what += f", soft fingertips (torsion {args.torsion_mm:g} mm)"
    print(f"{what} on {where}, output {args.out}", flush=True)
    from ..suite.cluster import load_run

    kept = len(load_run(args.out)[0]) if args.resume else 0
    bar = tqdm(
        total=n, initial=min(kept, n), unit="scenario",
        disable=True if args.quiet else None, file=sys.stderr,
    )  # fmt: skip

    def progress(r: ScenarioResult, counted: int, total: int) -> None:
        if args.quiet:
            return
        if skip and r.failed_stage == "grasp":
            tqdm.write(f"[skip] {r.name}: no initial grasp", file=sys.stdout)
            return
        bar.update(1)
        tqdm.write(result_line(r, counted, total), file=sys.stdout)

    try:
        done = run_suite(
            specs,
            n,
            out=args.out,
            workers=args.workers,
            scheduler=args.scheduler,
            timeout_s=args.timeout_s,
            resume=args.resume,
            skip_no_grasp=skip,
            max_steps=args.max_steps,
            grasp_backups=args.grasp_backups,
            time_law=args.time_law,
            torsion_m=args.torsion_mm * 1e-3,
            on_result=progress,
        )
    except KeyboardInterrupt:
        bar.close()
        print(
            f"\ninterrupted: the finished results are in {args.out / 'results.jsonl'}; "
            "run the same command with --resume to complete it",
            file=sys.stderr,
        )
        return EXIT_INTERRUPTED
    bar.close()
    text = "\n".join(
        [summarize(done.results), done.describe(), time_spent(done.results, done.skipped)]
    )
    (args.out / "summary.txt").write_text(text + "\n")
    files = write_report(args.out, done.results, viewer_pages=not args.no_viewer)
    print("\n" + text)
    print(f"report: {files.html}")
    return 0
