"""The paper's Fig. 2: one finger's joint space, its boundary planes and the moving manifold."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from .._validate import as_array
from ..exceptions import InputError
from ..grasp.manifold import Manifold
from ..grasp.tracking import ContactTrack
from . import require_pyplot

__all__ = ["plot_manifold"]


def plot_manifold(
    manifold: Manifold,
    *,
    times_idx: np.ndarray | list[int] | None = None,
    track: ContactTrack | None = None,
    q_new: Any = None,
    trigger_index: int | None = None,
    held: tuple[Any, Any] | None = None,
    joint_names: Sequence[str] | None = None,
    ax: Any = None,
) -> Any:
    """Draw a finger's 3-D joint space as in the paper's Fig. 2.

    The joint-limit box is drawn as its six boundary planes (translucent faces), the
    manifold (the reachable surface points' joint coordinates) at several instants
    coloured by time, the path of the held contact P through joint space, the trigger
    point where P meets a boundary plane (or stops being feasible) and the new contact
    Q. Angles are drawn in degrees. A finger with more than three joints is drawn in
    its first three (the title says so).

    Args:
        manifold: The finger's manifold (:func:`regrasp_pin.grasp.manifold.build_manifold`).
        times_idx: Grid indices of the instants to draw; default four evenly spaced
            ones, first and last included.
        track: The held contact followed over time
            (:func:`regrasp_pin.grasp.tracking.track_contact`); its ``q`` is P's path.
        q_new: Q's joint coordinates ``(k,)`` [rad], or a
            :class:`~regrasp_pin.grasp.choice.NewContact` (its ``q_arrive``).
        trigger_index: Index into ``track`` of the trigger; default
            ``track.trigger_index()``.
        held: Instead of ``track``: ``(times_s (S,), q (S, k))``, the finger's joint path
            [rad] while it held P, up to its lift-off, e.g. from a plan; its last point
            is marked as the trigger.
        joint_names: The axes' joint names (the first three); default "joint 1..3".
        ax: A matplotlib 3-D axes; default a new figure.

    Returns:
        The matplotlib figure.

    Raises:
        MissingExtraError: if matplotlib is not installed.
        InputError: for indices out of range or arrays of the wrong shape.
    """
    plt = require_pyplot()
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    nt, _, k = manifold.q.shape
    if k < 3:
        raise InputError("manifold", f"has {k} joints", "a finger with at least 3 joints")
    if times_idx is None:
        times_idx = np.unique(np.linspace(0, nt - 1, min(4, nt)).round().astype(int))
    idx = np.asarray(times_idx)
    if (
        idx.ndim != 1
        or idx.size == 0
        or not np.issubdtype(idx.dtype, np.integer)
        or np.any((idx < 0) | (idx >= nt))
    ):
        raise InputError("times_idx", f"{times_idx!r} is not allowed", f"indices in [0, {nt})")
    if ax is None:
        fig = plt.figure(figsize=(8, 7))
        ax = fig.add_subplot(projection="3d")
    else:
        fig = ax.figure
    ax.computed_zorder = False  # draw in the order below: planes, manifold, P, Q
    deg = np.degrees
    lo, hi = deg(manifold.lower[:3]), deg(manifold.upper[:3])

    # the boundary planes: the six faces of the joint-limit box
    corners = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)])
    box = lo + corners * (hi - lo)
    faces = [[0, 1, 3, 2], [4, 5, 7, 6], [0, 1, 5, 4], [2, 3, 7, 6], [0, 2, 6, 4], [1, 3, 7, 5]]
    ax.add_collection3d(
        Poly3DCollection(
            [box[f] for f in faces],
            facecolors=(0.85, 0.3, 0.25, 0.07),
            edgecolors=(0.6, 0.15, 0.1, 0.6),
            linewidths=0.8,
        )
    )

    # the manifold at the chosen instants, coloured by time
    drawn = [box]
    cmap = plt.get_cmap("viridis")
    t = manifold.times_s
    span = max(float(t[-1] - t[0]), 1e-12)
    for i in idx:
        r = manifold.reachable[i]
        q = deg(manifold.q[i, r, :3])
        drawn.append(q)
        colour = cmap((t[i] - t[0]) / span)
        ax.scatter(
            q[:, 0],
            q[:, 1],
            q[:, 2],
            s=3,
            color=colour,
            alpha=0.5,
            depthshade=False,
            label=f"manifold t = {t[i]:.2f} s ({int(manifold.feasible[i].sum())} feasible)",
        )

    p_path, mark = _held_path(track, trigger_index, held, k)
    if p_path is not None:
        path = np.degrees(p_path[:, :3])
        drawn.append(path)
        ax.plot(*path.T, color="tab:blue", lw=2.5, zorder=5, label="P's path (held)")
        ax.scatter(*path[0], s=50, color="tab:blue", marker="o", depthshade=False)
        if mark is not None:
            ax.scatter(
                *path[-1], s=120, color="tab:orange", marker="X", depthshade=False, label=mark
            )
    if q_new is not None:
        q_arr = getattr(q_new, "q_arrive", q_new)
        qn = deg(as_array(q_arr, "q_new", (k,))[:3])
        ax.scatter(*qn, s=160, color="tab:red", marker="*", depthshade=False, label="Q")

    # 3-D axes do not clip: the limits hold everything drawn
    pts = np.vstack(drawn)
    a, b = pts.min(axis=0), pts.max(axis=0)
    pad = 0.05 * (b - a)
    ax.set_xlim(a[0] - pad[0], b[0] + pad[0])
    ax.set_ylim(a[1] - pad[1], b[1] + pad[1])
    ax.set_zlim(a[2] - pad[2], b[2] + pad[2])
    names = list(joint_names or [f"joint {j + 1}" for j in range(3)])
    if len(names) < 3:
        raise InputError("joint_names", f"has {len(names)} names", "at least 3 (the axes')")
    ax.set_xlabel(f"{names[0]} [deg]")
    ax.set_ylabel(f"{names[1]} [deg]")
    ax.set_zlabel(f"{names[2]} [deg]")
    title = f"{manifold.finger}: manifold in joint space (Fig. 2)"
    if k > 3:
        title += f"\nfirst 3 of its {k} joints"
    ax.set_title(title)
    # the legend below the axes, clear of the tick labels
    fig.subplots_adjust(bottom=0.2)
    handles, labels = ax.get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=2, fontsize="x-small", frameon=False)
    sm = plt.cm.ScalarMappable(cmap=cmap, norm=plt.Normalize(t[0], t[-1]))
    fig.colorbar(sm, ax=ax, shrink=0.55, pad=0.12, label="time [s]")
    return fig


def _held_path(
    track: ContactTrack | None,
    trigger_index: int | None,
    held: tuple[Any, Any] | None,
    k: int,
) -> tuple[np.ndarray | None, str | None]:
    """P's joint path [rad] up to its trigger (from ``track``) or lift-off (``held``),
    and the label of the point that ends it (None: not marked)."""
    if held is not None:
        times = as_array(held[0], "held[0]", (None,))
        return as_array(held[1], "held[1]", (times.size, k)), f"lift-off t = {times[-1]:.2f} s"
    if track is None:
        return None, None
    if trigger_index is None:
        trigger_index = track.trigger_index()
    if trigger_index is None:
        return track.q, None
    if not 0 <= trigger_index < track.q.shape[0]:
        raise InputError("trigger_index", f"{trigger_index} is out of range", "an index into track")
    # P is held up to the trigger; after it the finger lets go
    return track.q[: trigger_index + 1], f"trigger t = {track.times_s[trigger_index]:.2f} s"
