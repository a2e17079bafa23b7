"""Fig. 8 of the paper: a curve and the polygon through the waypoints chosen on it."""

from __future__ import annotations

from typing import Any

import numpy as np

from ..exceptions import InputError
from ..polygon.approximate import PolygonResult
from . import require_pyplot

__all__ = ["plot_polygon"]


def plot_polygon(
    points: np.ndarray,
    result: PolygonResult,
    ax: Any = None,
    *,
    title: str | None = None,
) -> Any:
    """Draw the curve, the chosen vertices and the approximating polygon (Fig. 8).

    2-D curves are drawn in the plane with equal axes; 3-D curves on 3-D axes. On an
    open curve the end points are labelled P and Q (the contact points of the paper).

    Args:
        points: The curve that was approximated, shape ``(n, 2)`` or ``(n, 3)``.
        result: The approximation of ``points``
            (:func:`~regrasp_pin.polygon.approximate_polygon`).
        ax: A matplotlib axes (3-D axes for a 3-D curve); default a new figure.
        title: Axes title; default states m, the method, the deviation and the energy.

    Returns:
        The matplotlib figure.

    Raises:
        MissingExtraError: if matplotlib is not installed.
        InputError: if ``points`` does not match ``result``.
    """
    P = np.asarray(points, dtype=float)
    if P.ndim != 2 or P.shape[0] != result.n or P.shape[1] != result.vertices.shape[1]:
        raise InputError(
            "points", f"has shape {P.shape}", f"the approximated curve, shape ({result.n}, d)"
        )
    plt = require_pyplot()
    three_d = P.shape[1] == 3
    if ax is None:
        fig = plt.figure(figsize=(6.5, 5))
        ax = fig.add_subplot(projection="3d" if three_d else None)
    else:
        fig = ax.figure
    poly = result.vertices
    if result.closed:
        poly = np.vstack([poly, poly[:1]])
        curve = np.vstack([P, P[:1]])
    else:
        curve = P
    ax.plot(*curve.T, color="tab:blue", lw=1.2, label=f"curve ({result.n} points)")
    ax.plot(*poly.T, color="tab:red", lw=2, label=f"polygon ({result.m} vertices)")
    ax.scatter(*result.vertices.T, color="tab:red", s=28, zorder=4)
    if not result.closed:
        for label, p in (("P", P[0]), ("Q", P[-1])):
            ax.text(*p, f" {label}", fontsize=11, fontweight="bold")
    if not three_d:
        ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x")
    ax.set_ylabel("y")
    if three_d:
        ax.set_zlabel("z")
    if title is None:
        title = (
            f"{result.m} vertices, {result.method}, deviation {result.deviation}: "
            f"E = {result.energy:.4g} (Fig. 8)"
        )
    if title:
        ax.set_title(title, fontsize=10)
    ax.legend(loc="best", fontsize=8)
    return fig
