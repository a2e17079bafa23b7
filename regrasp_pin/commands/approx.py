"""``regrasp-pin approx``: reduce a curve from a CSV file to m waypoints (Fig. 8)."""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from ._args import output_file

NAME = "approx"
HELP = (
    "Approximate a curve (CSV rows x,y or x,y,z; optional header) by m of its points with "
    "the competitive Hopfield network or the exact DP optimum."
)

# Literal copies so that --help does not import numpy; checked against the library in tests.
_DEVIATIONS = ("max", "sum", "ise")
_METHODS = ("hopfield", "exact")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the ``approx`` options to ``parser``."""
    parser.add_argument("curve", type=Path, help="CSV file with x,y or x,y,z rows")
    parser.add_argument("-m", type=int, required=True, help="number of vertices (waypoints), >= 2")
    parser.add_argument("--closed", action="store_true", help="treat the curve as closed")
    parser.add_argument(
        "--deviation",
        choices=_DEVIATIONS,
        default="ise",
        help="arc-to-chord deviation: ise (integral square error), sum, or max (Eq. 7, "
        "the paper's; its optima are degenerate, see docs/hopfield.md) (default: %(default)s)",
    )
    parser.add_argument(
        "--method", choices=_METHODS, default="hopfield", help="solver (default: hopfield)"
    )
    parser.add_argument(
        "--seed", type=int, default=0,
        help="seed of the network's restarts (default: %(default)s)",
    )  # fmt: skip
    parser.add_argument(
        "--restarts",
        type=int,
        default=6,
        help="network perturbation rounds (default: %(default)s)",
    )
    parser.add_argument(
        "--full-matrix",
        action="store_true",
        help="give the network the full deviation matrix (slower; helps --deviation max)",
    )
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.add_argument("--plot", type=Path, metavar="PNG", help="also save a Fig. 8 plot")


def load_curve(path: Path) -> list[list[float]]:
    """Rows of floats from a CSV file; a first line that is not numeric is a header.

    Raises:
        InputError: missing file, no data rows, a non-numeric cell, or ragged rows.
    """
    from ..exceptions import InputError

    expected = "a CSV file of x,y or x,y,z rows"
    try:
        text = path.read_text()
    except OSError as exc:
        raise InputError("curve", f"cannot read {str(path)!r} ({exc.strerror})", expected) from None
    rows: list[list[float]] = []
    header_seen = False
    for lineno, line in enumerate(text.splitlines(), start=1):
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        cells = [c.strip() for c in line.replace(";", ",").split(",")]
        try:
            rows.append([float(c) for c in cells])
        except ValueError:
            if not rows and not header_seen:
                header_seen = True
                continue
            raise InputError(
                "curve", f"{path.name} line {lineno}: {line.strip()!r} is not numeric", expected
            ) from None
        if len(rows[-1]) != len(rows[0]):
            raise InputError(
                "curve",
                f"{path.name} line {lineno}: {len(rows[-1])} columns, earlier rows have "
                f"{len(rows[0])}",
                expected,
            )
    if not rows:
        raise InputError("curve", f"{path.name} has no data rows", expected)
    return rows


def run(args: argparse.Namespace) -> int:
    """Approximate the curve in ``args.curve``; return the exit status."""
    import numpy as np

    from ..polygon.approximate import approximate_polygon

    if args.plot is not None:
        output_file(args.plot, "--plot")  # before the work, not after
    points = np.asarray(load_curve(args.curve), dtype=float)
    t0 = time.perf_counter()
    res = approximate_polygon(
        points,
        args.m,
        closed=args.closed,
        deviation=args.deviation,
        method=args.method,
        seed=args.seed,
        restarts=args.restarts,
        full_matrix=args.full_matrix,
    )
    time_ms = (time.perf_counter() - t0) * 1e3
    if args.plot is not None:
        from ..plotting.polygon import plot_polygon

        fig = plot_polygon(points, res)
        fig.savefig(args.plot, dpi=120, bbox_inches="tight")
    report = {
        "curve": str(args.curve),
        "n": res.n,
        "m": res.m,
        "closed": res.closed,
        "deviation": res.deviation,
        "method": res.method,
        "indices": res.indices.tolist(),
        "vertices": res.vertices.tolist(),
        "energy": res.energy,
        "time_ms": round(time_ms, 3),
        "timings_ms": {k: round(v, 3) for k, v in res.timings_ms.items()},
    }
    network = res.method == "hopfield"
    if network:  # what only the network did
        report["plain_energy"] = res.plain_energy
        report["sweeps"] = res.sweeps
    if args.plot is not None:
        report["plot"] = str(args.plot)
    if args.json:
        print(json.dumps(report))
        return 0
    kind = "closed" if res.closed else "open"
    print(
        f"{args.curve}: {res.n} points ({kind}, {points.shape[1]}-D) -> {res.m} vertices, "
        f"method {res.method}, deviation {res.deviation}"
    )
    if network:
        print(f"energy {res.energy:.6g} (plain network {res.plain_energy:.6g}), {time_ms:.1f} ms")
        print(f"network sweeps {res.sweeps}")
    else:
        print(f"energy {res.energy:.6g} (the exact optimum), {time_ms:.1f} ms")
    print("vertices:")
    for i, v in zip(res.indices.tolist(), res.vertices, strict=True):
        coords = ", ".join(f"{c:.6g}" for c in v)
        print(f"  {i:6d}  ({coords})")
    if args.plot is not None:
        print(f"plot written to {args.plot}")
    return 0
