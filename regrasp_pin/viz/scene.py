"""Meshcat drawing primitives shared by the plan and manifold scenes.

Each ``draw_*`` function sets one meshcat object at ``vis`` (a node of a
``meshcat.Visualizer``), in the frame of that node. Colours are RGB triples in
``[0, 1]``. :func:`set_camera` and :func:`clean_stage` set up a view for objects of
hand size (meshcat's default camera and grid are made for metre-sized robots).
"""

from __future__ import annotations

from collections.abc import Sequence

import meshcat
import meshcat.geometry as mg
import numpy as np

from .._validate import as_array, positive
from .shapes import arrows_mesh, spheres_mesh, tube_mesh

__all__ = [
    "FINGER_COLORS",
    "OBJECT_COLOR",
    "clean_stage",
    "draw_arrows",
    "draw_mesh",
    "draw_points",
    "draw_segments",
    "draw_spheres",
    "draw_tube",
    "finger_color",
    "hex_color",
    "set_camera",
]

RGB = Sequence[float]

#: The object's colour: a saturated blue that nothing else in the scene uses, so that
#: it can be found in a screenshot.
OBJECT_COLOR: tuple[float, float, float] = (0.12, 0.30, 0.90)

#: One colour per finger (paths, trails, contacts), in the order of the hand's fingers.
FINGER_COLORS: tuple[tuple[float, float, float], ...] = (
    (0.85, 0.15, 0.15),  # red
    (0.10, 0.65, 0.20),  # green
    (0.95, 0.55, 0.05),  # orange
    (0.60, 0.20, 0.75),  # purple
    (0.05, 0.70, 0.75),  # teal
    (0.55, 0.35, 0.15),  # brown
)


def finger_color(index: int) -> tuple[float, float, float]:
    """The colour of the ``index``-th finger (cycles)."""
    return FINGER_COLORS[index % len(FINGER_COLORS)]


def hex_color(rgb: RGB) -> int:
    """``(r, g, b)`` in ``[0, 1]`` -> the ``0xRRGGBB`` integer three.js uses."""
    r, g, b = (int(round(255 * min(max(float(c), 0.0), 1.0))) for c in rgb)
    return (r << 16) | (g << 8) | b


def _material(rgb: RGB, opacity: float = 1.0) -> mg.MeshLambertMaterial:
    return mg.MeshLambertMaterial(color=hex_color(rgb), opacity=float(opacity))


def draw_mesh(
    vis: meshcat.Visualizer,
    vertices: np.ndarray,
    triangles: np.ndarray,
    rgb: RGB,
    opacity: float = 1.0,
) -> None:
    """A triangle mesh ``vertices (V, 3)``, ``triangles (F, 3)`` in one colour."""
    vis.set_object(mg.TriangularMeshGeometry(vertices, triangles), _material(rgb, opacity))


def draw_tube(
    vis: meshcat.Visualizer, points: np.ndarray, rgb: RGB, radius_m: float, opacity: float = 1.0
) -> None:
    """A polyline ``points (K, 3)`` drawn as a tube of radius ``radius_m`` [m]."""
    draw_mesh(vis, *tube_mesh(points, radius_m), rgb, opacity)


def draw_spheres(
    vis: meshcat.Visualizer, centres: np.ndarray, rgb: RGB, radius_m: float, opacity: float = 1.0
) -> None:
    """Spheres of radius ``radius_m`` [m] at ``centres (n, 3)``, as one mesh."""
    draw_mesh(vis, *spheres_mesh(centres, radius_m), rgb, opacity)


def draw_arrows(
    vis: meshcat.Visualizer,
    origins: np.ndarray,
    directions: np.ndarray,
    rgb: RGB,
    length_m: float,
    radius_m: float,
) -> None:
    """Arrows from ``origins (n, 3)`` along ``directions (n, 3)`` (e.g. contact normals)."""
    draw_mesh(vis, *arrows_mesh(origins, directions, length_m, radius_m), rgb)


def draw_points(
    vis: meshcat.Visualizer, points: np.ndarray, colors: np.ndarray, size: float
) -> None:
    """A point cloud ``points (n, 3)`` with per-point ``colors (n, 3)`` in ``[0, 1]``.

    ``size`` is the point size in scene units (points shrink with distance).
    """
    p = as_array(points, "points", (None, 3))
    c = as_array(colors, "colors", (len(p), 3))
    vis.set_object(
        mg.PointsGeometry(p.T.astype(np.float32), c.T.astype(np.float32)),
        mg.PointsMaterial(size=positive(size, "size")),
    )


def draw_segments(
    vis: meshcat.Visualizer, endpoints: np.ndarray, rgb: RGB, opacity: float = 1.0
) -> None:
    """Line segments between consecutive pairs of ``endpoints (2 n, 3)`` (one pixel wide)."""
    e = as_array(endpoints, "endpoints", (None, 3))
    vis.set_object(
        mg.LineSegments(
            mg.PointsGeometry(e.T.astype(np.float32)),
            mg.LineBasicMaterial(color=hex_color(rgb), opacity=float(opacity)),
        )
    )


def set_camera(vis: meshcat.Visualizer, target: RGB, eye: RGB) -> None:
    """Look at ``target (3,)`` from ``eye (3,)`` (frame of ``vis``, z up).

    Meshcat's orbit controls always look at, and turn about, the origin of the
    page's world (this meshcat version has no command to move their target). So the
    node ``vis`` itself is shifted by ``-target`` (everything drawn under it moves
    with it) and the camera, at ``/Cameras/default/rotated/<object>`` under a node
    turned +90 deg about x (three.js is y-up), is put at ``eye - target``.
    """
    target_ = as_array(target, "target", (3,))
    d = as_array(eye, "eye", (3,)) - target_
    T = np.eye(4)
    T[:3, 3] = -target_
    vis.set_transform(T)
    # scene (x, y, z) -> camera parent frame (x, z, -y)
    vis["/Cameras/default/rotated/<object>"].set_property(
        "position", [float(d[0]), float(d[2]), float(-d[1])]
    )


def clean_stage(vis: meshcat.Visualizer, *, grid: bool = False) -> None:
    """Hide meshcat's 20 m grid and 0.5 m axes (far too large for a hand) and its
    background gradient, so the scene is drawn on the page's white background."""
    vis["/Grid"].set_property("visible", bool(grid))
    vis["/Axes"].set_property("visible", False)
    vis["/Background"].set_property("visible", False)
