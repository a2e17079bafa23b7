"""Figs. 4 and 8 of the paper: the unfolded grid, its inflation, the grid path and the polygon."""

from __future__ import annotations

from typing import Any

import numpy as np

from ..exceptions import InputError
from ..surface.grid import SurfaceGrid
from ..surface.inflation import TipPath
from ..surface.path import GridPath
from . import require_pyplot

__all__ = ["plot_unfolded_grid"]


def _draw_faces(ax: Any, grid: SurfaceGrid) -> None:
    """Outline the unfolded faces [mm] and dash the edges between them."""
    mm = 1e3
    for unf in grid.unfoldings:
        poly = np.vstack([unf.polygon_uv, unf.polygon_uv[:1]]) * mm
        ax.plot(poly[:, 0], poly[:, 1], color="0.25", lw=1.2, zorder=3)
        centre = unf.polygon_uv.mean(axis=0) * mm
        ax.annotate(f"face {unf.face_id}", centre, color="0.45", fontsize=8, ha="center")
    for hinge in grid.hinges_uv:
        ax.plot(hinge[:, 0] * mm, hinge[:, 1] * mm, color="tab:orange", lw=1.5, ls="--", zorder=3)


def _polygon_indices(value: Any, n: int) -> np.ndarray:
    """``value`` as >= 2 integer indices into a path of ``n`` points (else InputError)."""
    idx = np.asarray(value)
    if (
        idx.ndim != 1
        or idx.size < 2
        or not np.issubdtype(idx.dtype, np.integer)
        or (np.any(idx < 0) or np.any(idx >= n))
    ):
        raise InputError(
            "polygon_indices", "must be >= 2 indices into the path", f"integers in [0, {n})"
        )
    return idx


def plot_unfolded_grid(
    grid: SurfaceGrid,
    path: GridPath | None = None,
    heights: np.ndarray | None = None,
    polygon_indices: np.ndarray | None = None,
    tip_path: TipPath | None = None,
    ax: Any = None,
    *,
    title: str | None = "Unfolded surface grid from P to Q (Fig. 4)",
    zoom: bool = False,
) -> Any:
    """Draw the unfolded region, the grid, the grid path and a polygon through waypoints.

    Face polygons are outlined, the edges between unfolded faces dashed; grid nodes are
    coloured by inflation height when ``heights`` is given; P and Q are marked. All
    lengths are drawn in millimetres in the unfolded plane.

    Args:
        grid: The surface grid.
        path: A grid path to draw.
        heights: Inflation height of each node [m], shape (M,) (e.g.
            :func:`regrasp_pin.surface.inflation.grid_inflation`).
        polygon_indices: Indices of waypoints, shape (m,) int, into ``tip_path`` if
            given, else into ``path``; the polygon through them is drawn (Fig. 8).
        tip_path: The inflated tip path (its surface points are drawn in the plane).
        ax: A matplotlib axes; default a new figure.
        title: Axes title (None for none).
        zoom: Frame P, Q, the paths and the polygon (with a margin of 30 % of their
            extent, at least 5 mm) and show the whole unfolded region in an inset with
            the framed part outlined, as the paper's Fig. 8 does.

    Returns:
        The matplotlib figure.

    Raises:
        MissingExtraError: if matplotlib is not installed.
        InputError: if ``heights`` or ``polygon_indices`` do not fit.
    """
    plt = require_pyplot()
    if ax is None:
        fig, ax = plt.subplots(figsize=(6.5, 5))
    else:
        fig = ax.figure
    mm = 1e3
    _draw_faces(ax, grid)
    uv = grid.uv * mm
    if heights is not None:
        h = np.asarray(heights, dtype=float)
        if h.shape != (len(grid),):
            raise InputError("heights", f"has shape {h.shape}", f"({len(grid)},)")
        sc = ax.scatter(uv[:, 0], uv[:, 1], c=h * mm, s=4, cmap="viridis", zorder=2)
        fig.colorbar(sc, ax=ax, label="inflation height [mm]")
    else:
        ax.scatter(uv[:, 0], uv[:, 1], s=2, c="0.6", zorder=2, label="grid nodes")
    if path is not None:
        ax.plot(
            path.uv[:, 0] * mm,
            path.uv[:, 1] * mm,
            color="tab:blue",
            lw=2,
            zorder=3,
            label=f"grid path ({path.length_m * mm:.1f} mm)",
        )
    if tip_path is not None:
        ax.plot(
            tip_path.uv[:, 0] * mm,
            tip_path.uv[:, 1] * mm,
            color="tab:cyan",
            lw=1,
            ls=":",
            zorder=3,
            label="tip path (surface trace)",
        )
    if polygon_indices is not None:
        source = tip_path.uv if tip_path is not None else (path.uv if path is not None else None)
        if source is None:
            raise InputError("polygon_indices", "needs a path or a tip_path to index")
        idx = _polygon_indices(polygon_indices, source.shape[0])
        poly = source[idx] * mm
        ax.plot(
            poly[:, 0],
            poly[:, 1],
            color="tab:red",
            lw=1.5,
            marker="o",
            ms=5,
            zorder=4,
            label=f"polygon ({idx.size} waypoints)",
        )
    for name, i, colour in (("P", grid.p_index, "tab:green"), ("Q", grid.q_index, "tab:red")):
        ax.scatter(*uv[i], s=90, c=colour, marker="*", zorder=5)
        ax.annotate(
            name,
            uv[i],
            textcoords="offset points",
            xytext=(6, 6),
            fontsize=11,
            weight="bold",
            color=colour,
        )
    ax.set_aspect("equal")
    if zoom:
        drawn = [uv[[grid.p_index, grid.q_index]]]
        drawn += [x.uv * mm for x in (path, tip_path) if x is not None]
        _zoom(ax, grid, np.vstack(drawn), path)
    ax.set_xlabel("unfolded u [mm]")
    ax.set_ylabel("unfolded v [mm]")
    ax.legend(loc="best", fontsize=8)
    if title:
        ax.set_title(title)
    return fig


def _zoom(ax: Any, grid: SurfaceGrid, drawn_mm: np.ndarray, path: GridPath | None) -> None:
    """Frame ``drawn_mm`` (points [mm]) and put the whole region in an inset."""
    from matplotlib.patches import Rectangle

    lo, hi = drawn_mm.min(axis=0), drawn_mm.max(axis=0)
    side = float((hi - lo).max()) + 2 * max(0.3 * float((hi - lo).max()), 5.0)
    centre = (lo + hi) / 2
    lo, hi = centre - side / 2, centre + side / 2  # a square frame
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    # the inset in the corner that hides the fewest drawn points (first of equals)
    frac = (drawn_mm - lo) / side
    corners = ((0.0, 0.0), (0.7, 0.0), (0.0, 0.7), (0.7, 0.7))
    hidden = [int(np.all((frac >= c) & (frac <= np.add(c, 0.3)), axis=1).sum()) for c in corners]
    x0, y0 = corners[int(np.argmin(hidden))]
    inset = ax.inset_axes((x0, y0, 0.3, 0.3))
    mm = 1e3
    for unf in grid.unfoldings:
        poly = np.vstack([unf.polygon_uv, unf.polygon_uv[:1]]) * mm
        inset.plot(poly[:, 0], poly[:, 1], color="0.35", lw=0.6)
    if path is not None:
        inset.plot(path.uv[:, 0] * mm, path.uv[:, 1] * mm, color="tab:blue", lw=1)
    inset.add_patch(Rectangle(tuple(lo), *(hi - lo), fill=False, ec="tab:red", lw=1))
    inset.set_aspect("equal")
    inset.set_xticks([])
    inset.set_yticks([])
    inset.set_title("whole region", fontsize=7)
