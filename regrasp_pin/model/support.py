"""Support functions of Coal's primitive shapes, batched.

The support function of a convex shape in a unit direction ``u`` is how far the shape
reaches along ``u``: ``h(u) = max_{x in shape} u . x``. About a shape's centre of
symmetry, in its own frame, it is ``sum_i half_i |u_i| + axial |u_z| + radial
sqrt(1 - u_z^2) + round`` with six parameters per shape: a box (``half``), a cylinder
(``axial`` = half length, ``radial`` = radius), a capsule (``axial``, ``round``), a
sphere (``round``). Any other shape gets the sphere of its local AABB, which contains
it (a bound, not its support function).
"""

from __future__ import annotations

from typing import Any

import coal
import numpy as np

__all__ = ["PRIMITIVES", "support", "support_parameters"]

#: The shapes whose support function the parameters give exactly.
PRIMITIVES = (coal.Box, coal.Cylinder, coal.Capsule, coal.Sphere)


def support_parameters(shape: Any) -> tuple[np.ndarray, np.ndarray]:
    """Centre ``(3,)`` (shape frame [m]) and support parameters ``(6,)`` (half_x, half_y,
    half_z, axial, radial, round [m]) of a Coal shape; exact for :data:`PRIMITIVES`, the
    local AABB's bounding sphere for any other shape."""
    out = np.zeros(6)
    centre = np.zeros(3)
    if isinstance(shape, coal.Box):
        out[:3] = np.asarray(shape.halfSide, dtype=float)
    elif isinstance(shape, coal.Cylinder):
        out[3], out[4] = float(shape.halfLength), float(shape.radius)
    elif isinstance(shape, coal.Capsule):
        out[3], out[5] = float(shape.halfLength), float(shape.radius)
    elif isinstance(shape, coal.Sphere):
        out[5] = float(shape.radius)
    else:
        shape.computeLocalAABB()
        centre = np.asarray(shape.aabb_center, dtype=float).copy()
        out[5] = float(shape.aabb_radius)
    return centre, out


def support(u_local: np.ndarray, params: np.ndarray) -> np.ndarray:
    """Support function values ``(...)`` about the shapes' centres for unit directions
    ``(..., 3)`` in the shapes' frames and support parameters ``(..., 6)`` (broadcast)."""
    uz = np.abs(u_local[..., 2])
    return (
        np.sum(params[..., :3] * np.abs(u_local), axis=-1)
        + params[..., 3] * uz
        + params[..., 4] * np.sqrt(np.maximum(0.0, 1.0 - uz * uz))
        + params[..., 5]
    )
