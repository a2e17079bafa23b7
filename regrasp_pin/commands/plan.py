"""``regrasp-pin plan``: plan a user's own problem (hand, object, motion) end to end."""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ._args import (
    HAND_METAVAR,
    add_grasp_backups,
    add_time_law,
    add_torsion,
    chosen_time_law,
    hand_argument,
    output_folder,
)

if TYPE_CHECKING:
    from ..model.objects import ConvexObject
    from ..scenarios import Scenario

NAME = "plan"
HELP = (
    "Plan your own problem: a hand (bundled or a hand file), an object (a bundled shape, "
    "sizes, or a mesh file) and a motion (a turn or a CSV of poses); writes the plan, "
    "figures and a viewer page."
)
_SHAPES = ("hexagon", "octagon", "box")


def _vector(text: str) -> tuple[float, float, float]:
    try:
        x, y, z = (float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not x,y,z (three numbers)") from None
    return (x, y, z)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the ``plan`` options to ``parser``."""
    what = parser.add_argument_group("the problem")
    what.add_argument(
        "--hand", type=hand_argument, default="five_finger", metavar=HAND_METAVAR,
        help="a bundled hand or a JSON hand file, see docs/hands.md (default: %(default)s)",
    )  # fmt: skip
    what.add_argument(
        "--fingers", type=lambda v: tuple(f for f in v.split(",") if f),
        help="comma-separated fingers that grasp (default: the hand's canonical ones; all "
        "of a hand file's)",
    )  # fmt: skip
    what.add_argument(
        "--object", dest="obj", default="hexagon", metavar="OBJECT",
        help="hexagon, octagon or box (the hand's own), box:LX,LY,LZ or prism:SIDES,R,H "
        "[m], or a mesh file (.obj, .stl, ...; its convex hull) (default: %(default)s)",
    )  # fmt: skip
    what.add_argument(
        "--scale", type=float, default=1.0,
        help="metres per unit of a mesh file, e.g. 0.001 for millimetres (default: 1)",
    )  # fmt: skip
    motion = parser.add_argument_group(
        "the motion",
        "by default a turn about the axis through the thumb's contact along its normal "
        "(the paper's scenario); --axis/--point turn about an axis of the object instead; "
        "--motion FILE.csv follows timed poses",
    )
    motion.add_argument(
        "--angle", type=float, default=100.0, help="turn [deg], signed (default: %(default)s)"
    )
    motion.add_argument(
        "--rate", type=float, default=20.0, help="turn speed [deg/s] (default: %(default)s)"
    )
    motion.add_argument("--axis", type=_vector, help="turn axis x,y,z in the object frame")
    motion.add_argument(
        "--point", type=_vector,
        help="a point x,y,z [m] of the axis, object frame (default: the centre)",
    )  # fmt: skip
    motion.add_argument(
        "--motion", type=Path, metavar="FILE.csv",
        help="rows t,x,y,z,qx,qy,qz,qw [s, m]: the object's pose relative to its start "
        "(object frame), the first row at the identity",
    )  # fmt: skip
    out = parser.add_argument_group("output")
    out.add_argument("--out", required=True, help="output folder")
    out.add_argument("--json", action="store_true", help="print one JSON object, also on failure")
    out.add_argument("--no-plots", action="store_true", help="no matplotlib figures")
    out.add_argument("--no-viewer", action="store_true", help="no static viewer page (plan.html)")
    add_torsion(what)
    search = parser.add_argument_group("the search")
    search.add_argument("--seed", type=int, default=0, help="seed of the searches (default: 0)")
    add_grasp_backups(search)
    add_time_law(search)


def load_object(spec: str, scale: float, hand: str) -> tuple[ConvexObject, str | None]:
    """The object an ``--object`` value names, and a note about it (or None)."""
    import numpy as np

    from ..exceptions import InputError
    from ..model.mesh_files import convex_object_from_file
    from ..model.objects import Box, Prism
    from ..scenarios import setup_objects

    expected = "hexagon, octagon, box, box:LX,LY,LZ, prism:SIDES,R,H or a mesh file"
    if spec in _SHAPES:
        return setup_objects(hand)[spec](), None
    kind, _, sizes = spec.partition(":")
    if kind in ("box", "prism") and sizes:
        try:
            values = [float(v) for v in sizes.split(",")]
        except ValueError:
            raise InputError(
                "--object", f"{spec!r} has a size that is not a number", expected
            ) from None
        if kind == "box" and len(values) == 3:
            return Box(np.array(values)), None
        if kind == "prism" and len(values) == 3 and values[0].is_integer():
            return Prism(int(values[0]), values[1], values[2]), None
        raise InputError("--object", f"{spec!r} has the wrong number of sizes", expected)
    if "." not in Path(spec).name:
        raise InputError("--object", f"{spec!r} is not known", expected)
    mesh = convex_object_from_file(spec, scale=scale)
    return mesh.obj, mesh.note


def _scenario(args: argparse.Namespace, obj: ConvexObject) -> Scenario:
    from ..grasp.contact import ContactModel
    from ..scenario_motion import relative_motion_from_csv, relative_twist, scenario_for_motion
    from ..scenarios import hand_model, scenario_for_hand, setup_fingers

    hand = hand_model(args.hand)
    contact = ContactModel(torsion_m=args.torsion_mm * 1e-3)
    fingers = args.fingers or (
        hand.finger_names if args.hand.endswith(".json") else setup_fingers(args.hand)
    )
    if args.motion is not None:
        rel = relative_motion_from_csv(args.motion)
        what = f"the poses of {args.motion.name}"
    elif args.axis is not None or args.point is not None:
        rel = relative_twist(
            axis_object=args.axis or (0.0, 0.0, 1.0),
            point_object=args.point or (0.0, 0.0, 0.0),
            angle_deg=args.angle,
            rate_deg_s=args.rate,
        )
        what = f"{args.angle:g} deg at {args.rate:g} deg/s about its axis {args.axis or (0, 0, 1)}"
    else:
        return scenario_for_hand(
            hand,
            obj,
            fingers=fingers,
            angle_deg=args.angle,
            rate_deg_s=args.rate,
            seed=args.seed,
            contact=contact,
        )
    return scenario_for_motion(
        hand, obj, rel, fingers=fingers, seed=args.seed, what=what, contact=contact
    )


def run(args: argparse.Namespace) -> int:
    """Plan the problem; write the plan, figures and viewer page; return the exit status."""
    from ..backups import plan_scenario
    from ..exceptions import ContactError, PlanningError
    from ..planning.params import with_time_law
    from .summary import plan_summary, print_table, report_failure, write_figures

    t0 = time.perf_counter()
    out = output_folder(args.out, "--out")
    obj, note = load_object(args.obj, args.scale, args.hand)
    if note:
        print(f"note: {note}", file=sys.stderr)
    scen = _scenario(args, obj)
    if not args.json:
        print(scen.description)
    try:
        result = plan_scenario(
            scen,
            params=with_time_law(scen.params, chosen_time_law(args)),
            grasp_backups=args.grasp_backups,
        )
    except (PlanningError, ContactError) as exc:
        return report_failure(scen, exc, out, args.json, time.perf_counter() - t0)
    plan_path = result.plan.save(out / "plan.json")
    figures = [] if args.no_plots else write_figures(result, out)
    summary: dict[str, Any] = plan_summary(
        scen, result, plan_path, figures, time.perf_counter() - t0
    )
    summary["object_note"] = note
    summary["viewer"] = None if args.no_viewer else _viewer(result.plan, out / "plan.html")
    if args.json:
        print(json.dumps(summary, indent=2))
        return 0
    print_table(summary["rows"], summary)
    if summary["viewer"]:
        print(f"viewer: {summary['viewer']} (open it in a browser)")
    return 0


def _viewer(plan: Any, path: Path) -> str | None:
    """The static viewer page, or None without meshcat (the viz extra)."""
    try:
        from ..viz import export_html
    except ImportError:
        return None
    return str(export_html(plan, path))
