"""What ``demo`` and ``plan`` print and write about a plan: the regrasp table, the JSON
summary (on success and on failure) and the figures (Figs. 9, 2 and 8)."""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from ..planning.planner import ManipulationPlan
    from ..scenarios import Scenario

__all__ = [
    "backup_lines",
    "failure_summary",
    "held_path",
    "plan_summary",
    "print_table",
    "report_failure",
    "release_rows",
    "summary_rows",
    "write_figures",
]


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
                "route": r.route,
                "time_law": r.params.time_law,
                "min_clearance_mm": 1e3 * r.min_clearance_m,
                "planning_ms": r.planning_ms,
                "verified": bool(r.report.ok),
                "reason": ph.reason,
            }
        )
    return rows


def release_rows(result: ManipulationPlan) -> list[dict]:
    """One row per release: finger, time [s], smallest clearance [mm]."""
    return [
        {"finger": p.finger, "t_s": p.t_start, "min_clearance_mm": 1e3 * p.min_clearance_m}
        for p in result.plan.releases()
    ]


def plan_summary(
    scen: Scenario, result: ManipulationPlan, plan_path: Path, figures: list[Path], total_s: float
) -> dict:
    """What the demo prints (as a table, or as JSON with ``--json``)."""
    rows = summary_rows(result)
    return {
        "ok": True,
        "scenario": scen.description,
        "hand": scen.hand.name,
        "object": scen.obj.kind,
        "duration_s": scen.motion.duration_s,
        "regrasps": len(rows),
        "fingers_regrasped": sorted({r["finger"] for r in rows}),
        "all_verified": all(r["verified"] for r in rows),
        "rows": rows,
        "releases": release_rows(result),
        "joins": [
            {"finger": p.finger, "t_s": p.t_start, "t_end_s": p.t_end, "reason": p.reason}
            for p in result.plan.joins()
        ],
        "stage_s": result.stage_s,
        "total_s": total_s,
        "plan": str(plan_path),
        "figures": [str(f) for f in figures],
        "grasp_backups": _recorded(result),
    }


def failure_summary(scen: Scenario, exc: Any, partial: Path | None, total_s: float) -> dict:
    """What ``--json`` prints when no plan was found."""
    return {
        "ok": False,
        "scenario": scen.description,
        "hand": scen.hand.name,
        "object": scen.obj.kind,
        "duration_s": scen.motion.duration_s,
        "failure_kind": exc.kind.value,
        "failure": str(exc),
        "finger": exc.finger,
        "time_s": exc.time_s,
        "measured": exc.measured,
        "required": exc.required,
        "attempts": [a.to_dict() for a in exc.attempts],
        "partial_plan": None if partial is None else str(partial),
        "total_s": total_s,
        "grasp_backups": _recorded(exc),
    }


def report_failure(scen: Scenario, exc: Any, out: Path, as_json: bool, total_s: float) -> int:
    """A plan that failed: its partial plan written to ``out`` (if any) and said so on
    stderr, then the failure as JSON on stdout (``as_json``; returns the exit status
    1) or, without it, the backups tried on stderr and ``exc`` raised again (the CLI
    prints it on one line)."""
    partial = getattr(exc, "partial", None)
    path = None if partial is None else partial.save(out / "partial_plan.json")
    if path is not None:
        print(f"partial plan written to {path}", file=sys.stderr)
    if not as_json:
        for line in backup_lines(_recorded(exc)):
            print(line, file=sys.stderr)
        raise exc
    print(json.dumps(failure_summary(scen, exc, path, total_s), indent=2))
    return 1


def _recorded(outcome: Any) -> list[dict]:
    """:func:`~regrasp_pin.backups.recorded_backups` (imported when asked: the commands
    load the planner only to plan)."""
    from ..backups import recorded_backups

    return recorded_backups(outcome)


def backup_lines(backups: list[dict]) -> list[str]:
    """One line per backup to another initial grasp: which finger, after what, how it
    started and what came of it."""
    how = {"elsewhere": "started elsewhere", "held-through": "started where it holds to the end"}
    return [
        f"backed up after {b['after']} at {b['finger']}: {b['finger']} "
        f"{how.get(b['how'], b['how'])} -> {b['outcome']}"
        for b in backups
    ]


def print_table(rows: list[dict], summary: dict) -> None:
    """The regrasp table (the README's), releases, joins, stages and the files written."""
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
        wp = f"{r['waypoints']}" + ("*" if r["route"] == "joint-space" else "")
        print(
            f"{r['finger']:7} {r['trigger_s']:8.2f} {r['t_start_s']:8.2f} {P:>20} {Q:>20} "
            f"{r['path_length_mm']:7.1f} {wp:>3} {r['min_clearance_mm']:6.2f} "
            f"{r['planning_ms']:7.0f}"
        )
    print("-" * len(head))
    if any(r["route"] == "joint-space" for r in rows):
        print(
            "* the joint-space fallback (no surface path passed): lift off P, move in "
            "joint space, come down onto Q; wp counts its keyframes"
        )
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
        laws = sorted({r.get("time_law", "minimum-jerk") for r in rows} - {"minimum-jerk"})
        if laws:
            print(f"by the {', '.join(laws)} time law (RegraspParams.time_law)")
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
    for line in backup_lines(summary.get("grasp_backups", [])):
        print(line)
    stages = ", ".join(f"{k} {v:.2f} s" for k, v in summary["stage_s"].items())
    print(f"stages: {stages}; total {summary['total_s']:.2f} s")
    print(f"plan: {summary['plan']}")
    for f in summary["figures"]:
        print(f"figure: {f}")


def write_figures(result: ManipulationPlan, out: Path) -> list[Path]:
    """Fig. 9 (forefinger joint angles), Fig. 2 (one regrasp's manifold), Fig. 8 (the
    first surface-path regrasp; none if every regrasp flew the joint-space fallback)."""
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
        # Fig. 8 shows a surface path: the forefinger's first, else any finger's first
        on_surface = [g for g in result.regrasps if g.route == "surface"]
        r8 = next((g for g in on_surface if g.finger == forefinger), None) or next(
            iter(on_surface), None
        )
        try:
            from ..plotting.manifold import plot_manifold

            man = result.manifolds[r.finger]
            fig = plot_manifold(
                man,
                q_new=r.q[-1],
                held=held_path(result.plan, r.finger, r.t_start),
                joint_names=result.plan.hand["fingers"][r.finger]["joints"],
            )
            fig.gca().set_title(
                f"{r.finger}: joint-space manifold (Fig. 2), regrasp at {r.t_start:.2f} s"
            )
            files.append(out / "fig2_manifold.png")
            fig.savefig(files[-1], dpi=110)
            plt.close(fig)
        except ImportError:  # the Fig. 2 module is optional
            pass
        if r8 is not None:
            files.append(_fig8(r8, out / "fig8_hopfield_path.png"))
    return files


def _fig8(r: Any, path: Path) -> Path:
    """Fig. 8 of a surface-path regrasp ``r``, written to ``path``."""
    from ..plotting import require_pyplot
    from ..plotting.surface import plot_unfolded_grid
    from ..surface.inflation import grid_inflation

    plt = require_pyplot()
    p = r.params
    height = p.inflation_factor * p.clearance_m
    heights = grid_inflation(r.grid, height, r.tip_path.taper_m)
    fig = plot_unfolded_grid(
        r.grid,
        path=r.grid_path,
        heights=heights,
        polygon_indices=r.polygon.indices,
        tip_path=r.tip_path,
        zoom=True,
        title=f"Fig. 8: {r.finger}, P -> Q in {len(r.polygon.indices)} waypoints",
    )
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def held_path(plan: Any, finger: str, t_lift_s: float) -> tuple[Any, Any]:
    """``(times_s, q)`` of ``finger`` [rad] over its contact phase that ends at the
    lift-off ``t_lift_s`` [s] (the path of P in joint space, for Fig. 2)."""
    import numpy as np

    phase = next(
        p for p in plan.phases[finger] if p.kind == "contact" and abs(p.t_end - t_lift_s) < 1e-6
    )
    hand = plan.load_hand()
    rows = (plan.t >= phase.t_start - 1e-9) & (plan.t <= phase.t_end + 1e-9)
    return plan.t[rows], plan.q[np.ix_(rows, hand.finger(finger).q_indices)]
