"""Objects from mesh files (OBJ, STL, DAE, ... through Coal's assimp loader).

The planner's objects are convex (:class:`~.objects.ConvexObject`): a mesh file becomes
the convex hull of its vertices, re-centred at the hull's volume centroid. When some
vertices lie inside the hull (the mesh is not convex) the result says so, with how
many, so that a user knows the planner sees the hull, not the mesh.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import coal
import numpy as np

from .._validate import positive
from ..exceptions import ModelFileError
from .objects import ConvexMesh

__all__ = ["MeshObject", "convex_object_from_file"]

_HULL_TOL_M = 1e-6  # a vertex further inside the hull than this is inside


@dataclass(frozen=True)
class MeshObject:
    """A mesh file's convex hull as a planner object.

    Attributes:
        obj: The :class:`~.objects.ConvexMesh` (object frame at its volume centroid).
        path: The file.
        n_vertices: The mesh's vertices.
        n_inside: Of which inside the hull by more than 1 um (0 for a convex mesh).
        note: A sentence for the user when the hull differs from the mesh, else None.
    """

    obj: ConvexMesh
    path: Path
    n_vertices: int
    n_inside: int
    note: str | None


def convex_object_from_file(path: str | Path, *, scale: float = 1.0) -> MeshObject:
    """Load a mesh file and return its convex hull as an object.

    Args:
        path: An OBJ, STL, DAE, PLY, ... file (anything Coal's assimp loader reads).
        scale: Metres per file unit (0.001 for a file in millimetres), > 0.

    Returns:
        The :class:`MeshObject`.

    Raises:
        ModelFileError: the file does not exist or cannot be read as a mesh.
        InputError: a ``scale`` that is not positive.
        GeometryError: the vertices are fewer than 4 or flat.
    """
    file = Path(path)
    s = positive(scale, "scale")
    if not file.is_file():
        raise ModelFileError(file, "no such mesh file")
    try:
        mesh = coal.MeshLoader().load(str(file), np.full(3, s))
    except (ValueError, RuntimeError) as exc:
        first = str(exc).strip().splitlines()
        reason = next((x for x in first if x.startswith("message:")), "cannot be read as a mesh")
        raise ModelFileError(file, reason.removeprefix("message: ")) from None
    vertices = np.asarray(mesh.vertices(), dtype=float).reshape(-1, 3)
    obj = ConvexMesh(vertices)
    inside = _inside_hull(obj, vertices - obj.input_centroid)
    note = None
    if inside:
        note = (
            f"{file.name} is not convex: {inside} of its {len(vertices)} vertices lie inside "
            "its convex hull, which is what the planner uses"
        )
    return MeshObject(obj, file, len(vertices), inside, note)


def _inside_hull(obj: ConvexMesh, points_object: np.ndarray) -> int:
    """How many points lie inside the object by more than :data:`_HULL_TOL_M`."""
    return int((obj.signed_distance(points_object) < -_HULL_TOL_M).sum())
