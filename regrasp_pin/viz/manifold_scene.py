"""A finger's joint-space manifold in its own meshcat scene (the paper's Fig. 2, in 3-D).

The scene frame *is* the finger's joint space: x, y, z are its three joint
coordinates [rad] (drawn 1 rad = 1 scene unit). Nodes, under the visualizer's root:

- ``manifold/limits/planes``: the six boundary planes of the joint box
  ``[lower, upper]``, translucent; ``manifold/limits/edges``: its twelve edges;
- ``manifold/axes``: joint 1 (red), joint 2 (green), joint 3 (blue), from the lower
  corner, one quarter of the box long;
- ``manifold/points``: the manifold as a point cloud coloured by margin (the signed
  distance to the nearest boundary plane [rad]): grey-red outside the limits
  (margin < 0), then dark purple at the boundary through teal to yellow at the
  largest margin;
- ``manifold/p_path``: the path of the current contact P through joint space;
  ``manifold/p_now``: its last point; ``manifold/q_new``: the new contact Q.
"""

from __future__ import annotations

import meshcat
import numpy as np

from .._validate import as_array
from ..exceptions import InputError
from .recorder import recording_visualizer
from .scene import clean_stage, draw_mesh, draw_points, draw_segments, draw_spheres, draw_tube
from .scene import set_camera as _set_camera
from .shapes import box_edges, box_planes_mesh

__all__ = ["margin_colors", "show_manifold"]

P_COLOR = (0.90, 0.10, 0.55)
Q_COLOR = (0.15, 0.75, 0.25)
PLANE_COLOR = (0.55, 0.60, 0.70)
OUTSIDE_COLOR = np.array([0.80, 0.45, 0.45])

# viridis at 0, 1/4, 1/2, 3/4, 1
_VIRIDIS = np.array(
    [
        [0.267, 0.005, 0.329],
        [0.230, 0.322, 0.546],
        [0.128, 0.567, 0.551],
        [0.369, 0.789, 0.383],
        [0.993, 0.906, 0.144],
    ]
)


def margin_colors(margin: object, max_margin: float | None = None) -> np.ndarray:
    """Colours ``(N, 3)`` for margins ``(N,)`` [rad]: viridis over ``[0, max_margin]``
    inside the limits, :data:`OUTSIDE_COLOR` outside (negative margin)."""
    m = as_array(margin, "margin", (None,))
    top = float(max_margin) if max_margin is not None else float(max(m.max(initial=0.0), 1e-9))
    s = np.clip(m / top, 0.0, 1.0) * (len(_VIRIDIS) - 1)
    i = np.minimum(s.astype(int), len(_VIRIDIS) - 2)
    f = (s - i)[:, None]
    colors = (1.0 - f) * _VIRIDIS[i] + f * _VIRIDIS[i + 1]
    colors[m < 0] = OUTSIDE_COLOR
    return colors


def show_manifold(
    q_points: object,
    margin: object,
    lower: object,
    upper: object,
    p_path_q: object | None = None,
    q_new: object | None = None,
    vis: meshcat.Visualizer | None = None,
    *,
    point_size_rad: float | None = None,
    set_camera: bool = True,
) -> meshcat.Visualizer:
    """Draw a finger's 3-D joint space: limit box, manifold, P's path and Q.

    Args:
        q_points: Manifold points ``(N, 3)`` in joint space [rad]; rows with NaN (points
            IK did not reach) are skipped.
        margin: Their margin ``(N,)`` [rad], signed distance to the nearest boundary
            plane (negative outside the limits).
        lower: Lower joint limits ``(3,)`` [rad].
        upper: Upper joint limits ``(3,)`` [rad].
        p_path_q: Joint-space path of the current contact P, ``(K, 3)`` [rad].
        q_new: Joint coordinates of the new contact Q, ``(3,)`` [rad].
        vis: Visualizer to draw into (live or recording); default a new recording.
        point_size_rad: Point size in scene units; default 1.5 % of the box diagonal.
        set_camera: Point the camera at the box.

    Returns:
        The visualizer (``vis.static_html()`` gives the page).

    Raises:
        InputError: wrong shapes, a finger that does not have three joints, or
            ``upper <= lower``.
    """
    q = np.asarray(q_points, dtype=float)
    if q.ndim != 2 or q.shape[1] != 3:
        raise InputError(
            "q_points", f"has shape {q.shape}", "(N, 3): a 3-joint finger's joint space"
        )
    m = as_array(margin, "margin", (q.shape[0],), finite=False)
    lo = as_array(lower, "lower", (3,))
    hi = as_array(upper, "upper", (3,))
    if np.any(hi <= lo):
        raise InputError("upper", "is not above lower on every joint", "upper > lower")
    vis = recording_visualizer() if vis is None else vis
    diag = float(np.linalg.norm(hi - lo))
    root = vis["manifold"]
    clean_stage(vis)

    draw_mesh(root["limits/planes"], *box_planes_mesh(lo, hi), PLANE_COLOR, opacity=0.18)
    draw_segments(root["limits/edges"], box_edges(lo, hi), (0.2, 0.2, 0.25))
    axis_len = 0.25 * float(np.min(hi - lo))
    for k, rgb in enumerate(((0.9, 0.1, 0.1), (0.1, 0.7, 0.1), (0.1, 0.2, 0.9))):
        end = lo.copy()
        end[k] += axis_len
        draw_tube(root[f"axes/joint{k + 1}"], np.stack([lo, end]), rgb, 0.004 * diag)

    ok = np.all(np.isfinite(q), axis=1) & np.isfinite(m)
    if np.any(ok):
        size = point_size_rad if point_size_rad is not None else 0.015 * diag
        draw_points(root["points"], q[ok], margin_colors(m[ok]), size)

    if p_path_q is not None:
        path = as_array(p_path_q, "p_path_q", (None, 3))
        if len(path) >= 2:
            draw_tube(root["p_path"], path, P_COLOR, 0.006 * diag)
        if len(path):
            draw_spheres(root["p_now"], path[-1:], P_COLOR, 0.018 * diag)
    if q_new is not None:
        draw_spheres(root["q_new"], as_array(q_new, "q_new", (3,))[None], Q_COLOR, 0.02 * diag)

    if set_camera:
        centre = 0.5 * (lo + hi)
        direction = np.array([1.0, -1.3, 0.9])
        _set_camera(vis, centre, centre + 0.95 * diag * direction / np.linalg.norm(direction))
    return vis
