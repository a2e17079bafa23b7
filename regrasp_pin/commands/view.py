"""``regrasp-pin view``: show a plan file in the meshcat viewer (live, or as static HTML)."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

NAME = "view"
HELP = "Show a plan file in the browser (meshcat), live on 127.0.0.1 or as static HTML."


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the ``view`` options to ``parser``."""
    parser.add_argument("plan", help="plan file (JSON, format regrasp_pin.plan/1)")
    parser.add_argument(
        "--port", type=int, default=None,
        help="web port on 127.0.0.1 (default: the first free port from 7000)",
    )  # fmt: skip
    parser.add_argument(
        "--html", metavar="FILE", default=None,
        help="write a self-contained HTML file (opens without a server) and exit",
    )  # fmt: skip
    parser.add_argument("--no-open", action="store_true", help="do not open a browser")
    parser.add_argument(
        "--fps", type=float, default=30.0, help="animation frame rate [1/s] (default: %(default)s)"
    )


def run(args: argparse.Namespace) -> int:
    """Show a plan file in meshcat (or export it); return the exit status."""
    from ..plan import Plan

    plan = Plan.load(args.plan)  # fails early, before the optional imports
    from .. import viz

    if args.html:
        path = viz.export_html(plan, args.html, fps=args.fps)
        size_mb = path.stat().st_size / 1e6
        print(f"wrote {path} ({size_mb:.1f} MB); open it in a browser, no server needed")
        return 0
    url = viz.show_plan_live(plan, port=args.port, open_browser=not args.no_open, fps=args.fps)
    print(f"regrasp-pin view: serving {args.plan} at {url}", flush=True)
    print("press Ctrl-C to stop", flush=True)
    viz.wait_until_interrupted()
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """Run this command on its own: ``python -m regrasp_pin.commands.view plan.json``."""
    from ..exceptions import RegraspError

    parser = argparse.ArgumentParser(prog="regrasp-pin view", description=HELP)
    add_arguments(parser)
    args = parser.parse_args(argv)
    try:
        return run(args)
    except RegraspError as exc:
        print(f"regrasp-pin view: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
