"""Objects from mesh files: the convex hull of an OBJ/STL, in metres, with a note when
the mesh is not convex."""

from __future__ import annotations

import struct

import numpy as np
import pytest

from regrasp_pin.exceptions import InputError, ModelFileError
from regrasp_pin.model.mesh_files import convex_object_from_file
from regrasp_pin.model.objects import Box


def _cube_corners(side: float) -> np.ndarray:
    return side / 2 * np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)])


_CUBE_TRIANGLES = [  # 12 outward triangles over _cube_corners' indices
    (0, 2, 3), (0, 3, 1), (4, 5, 7), (4, 7, 6), (0, 1, 5), (0, 5, 4),
    (2, 6, 7), (2, 7, 3), (0, 4, 6), (0, 6, 2), (1, 3, 7), (1, 7, 5),
]  # fmt: skip


def _write_obj(path, vertices, triangles):
    lines = [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in vertices]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in triangles]
    path.write_text("\n".join(lines) + "\n")


def _write_binary_stl(path, vertices, triangles):
    records = b"".join(
        struct.pack("<12fH", 0, 0, 0, *vertices[a], *vertices[b], *vertices[c], 0)
        for a, b, c in triangles
    )
    path.write_bytes(b"\0" * 80 + struct.pack("<I", len(triangles)) + records)


@pytest.mark.parametrize("writer", [_write_obj, _write_binary_stl], ids=["obj", "stl"])
def test_a_cube_in_millimetres_is_the_box_in_metres(tmp_path, writer):
    path = tmp_path / ("cube.obj" if writer is _write_obj else "cube.stl")
    writer(path, _cube_corners(40.0), _CUBE_TRIANGLES)
    mesh = convex_object_from_file(path, scale=0.001)
    ref = Box((0.04, 0.04, 0.04))
    assert (mesh.n_vertices >= 8, mesh.n_inside, mesh.note) == (True, 0, None)
    assert len(mesh.obj.faces) == 6  # coplanar triangles merged
    assert mesh.obj.volume_m3 == pytest.approx(ref.volume_m3, rel=1e-9)
    probe = np.random.default_rng(0).uniform(-0.03, 0.03, (200, 3))
    np.testing.assert_allclose(
        mesh.obj.signed_distance(probe), ref.signed_distance(probe), atol=1e-9
    )


def test_a_dented_mesh_is_its_hull_with_a_note(tmp_path):
    corners = _cube_corners(40.0)
    dent = np.array([[0.0, 0.0, 10.0]])  # the top face pushed 10 mm in, at its centre
    top = [(a, b, c) for a, b, c in _CUBE_TRIANGLES if all(corners[i][2] > 0 for i in (a, b, c))]
    rest = [t for t in _CUBE_TRIANGLES if t not in top]
    fan = [(1, 3, 8), (3, 7, 8), (7, 5, 8), (5, 1, 8)]  # the top corners around the dent
    path = tmp_path / "dented.obj"
    _write_obj(path, np.vstack([corners, dent]), rest + fan)
    mesh = convex_object_from_file(path, scale=0.001)
    assert mesh.n_inside == 1 and "not convex: 1 of its 9 vertices" in (mesh.note or "")
    assert mesh.obj.volume_m3 == pytest.approx(0.04**3, rel=1e-9)  # the hull, not the mesh


def test_missing_or_unreadable_files_and_bad_scale(tmp_path):
    with pytest.raises(ModelFileError, match="no such mesh file"):
        convex_object_from_file(tmp_path / "missing.obj")
    junk = tmp_path / "junk.stl"
    junk.write_text("this is not a mesh")
    with pytest.raises(ModelFileError, match=str(junk)):
        convex_object_from_file(junk)
    _write_obj(tmp_path / "c.obj", _cube_corners(1.0), _CUBE_TRIANGLES)
    with pytest.raises(InputError, match="scale"):
        convex_object_from_file(tmp_path / "c.obj", scale=0.0)
