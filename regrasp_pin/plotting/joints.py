"""The paper's Fig. 9: one finger's joint angles over the whole motion."""

from __future__ import annotations

from typing import Any

import numpy as np

from ..plan import Plan, RegraspPhase
from . import require_pyplot


def plot_joint_angles(plan: Plan, finger: str, *, ax: Any = None) -> Any:
    """Joint angles [deg] of ``finger`` against time [s], regrasp intervals shaded.

    Args:
        plan: A plan (e.g. ``Plan.load("out/plan.json")``).
        finger: Finger name (e.g. ``"index"``, the paper's forefinger).
        ax: Matplotlib axes to draw into; a new figure when None.

    Returns:
        The matplotlib figure.
    """
    plt = require_pyplot()
    if ax is None:
        fig, ax = plt.subplots(figsize=(8, 3.6))
    else:
        fig = ax.figure
    info = plan.hand["fingers"][finger]
    hand = plan.load_hand()
    f = hand.finger(finger)
    q = plan.q[:, f.q_indices]
    for j, name in enumerate(info["joints"]):
        line = ax.plot(plan.t, np.degrees(q[:, j]), lw=1.6, label=name)[0]
        for lim in (f.lower[j], f.upper[j]):
            ax.axhline(np.degrees(lim), color=line.get_color(), lw=0.6, ls=":")
    phases = plan.phases.get(finger, [])
    spans = [(ph.t_start, ph.t_end) for ph in phases if isinstance(ph, RegraspPhase)]
    for t0, t1, n in regrasp_runs(spans):
        ax.axvspan(t0, t1, color="0.85", zorder=0)
        ax.text(
            0.5 * (t0 + t1),
            ax.get_ylim()[1],
            "regrasp" if n == 1 else f"{n} regrasps",
            ha="center",
            va="top",
            fontsize=8,
            color="0.3",
        )
    ax.set_xlabel("time [s]")
    ax.set_ylabel("joint angle [deg]")
    ax.set_title(f"{finger}: joint angles (dotted: limits; grey: regrasps)")
    ax.legend(loc="best", fontsize=8)
    fig.tight_layout()
    return fig


def regrasp_runs(spans: list[tuple[float, float]]) -> list[tuple[float, float, int]]:
    """Regrasp intervals ``(t_start, t_end)`` [s], in time order, merged where one lands
    as the next lifts off (within 1 us): ``(t_start, t_end, count)`` per run, one label
    each."""
    runs: list[tuple[float, float, int]] = []
    for t0, t1 in sorted(spans):
        if runs and t0 <= runs[-1][1] + 1e-6:
            runs[-1] = (runs[-1][0], max(runs[-1][1], t1), runs[-1][2] + 1)
        else:
            runs.append((t0, t1, 1))
    return runs
