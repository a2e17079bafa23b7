"""Convex objects: faces, sampling, exact distances against Coal, bad input."""

from __future__ import annotations

import json

import coal
import numpy as np
import pytest
from conftest import assert_close
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from regrasp_pin.exceptions import GeometryError, InputError
from regrasp_pin.model.objects import (
    Box,
    ConvexMesh,
    ConvexObject,
    ExtrudedPolygon,
    Prism,
    object_from_params,
)

SPACING_M = 0.003


@pytest.fixture(scope="module")
def objects() -> dict[str, ConvexObject]:
    rng = np.random.default_rng(0)
    return {
        "box": Box((0.06, 0.04, 0.04)),
        "prism": Prism(6, 0.03, 0.05),
        "triangle": ExtrudedPolygon([[0.0, 0.0], [0.05, 0.0], [0.01, 0.04]], 0.02),
        "mesh": ConvexMesh(rng.normal(size=(40, 3)) * 0.03 + [0.1, -0.2, 0.3]),
    }


def _coal_point_distance(obj: ConvexObject, points: np.ndarray) -> np.ndarray:
    """Distance from each point to the object by Coal (a 1e-12 m sphere at the point)."""
    geom, sphere = obj.coal_geometry(), coal.Sphere(1e-12)
    out = np.empty(points.shape[0])
    for i, p in enumerate(points):  # reference only: Coal has no batched distance
        out[i] = (
            coal.distance(
                sphere,
                coal.Transform3s(np.eye(3), p),
                geom,
                coal.Transform3s(),
                coal.DistanceRequest(),
                coal.DistanceResult(),
            )
            + 1e-12
        )
    return out


# ---------------------------------------------------------------------- construction
def test_box_faces_and_mesh():
    box = Box((0.06, 0.04, 0.02))
    assert len(box.faces) == 6 and len(box.face_adjacency) == 12
    assert box.triangles.shape == (12, 3)
    assert_close(box.volume_m3, 0.06 * 0.04 * 0.02, atol=1e-15, what="box volume")
    assert_close(
        np.sort(np.abs(box.offsets)),
        [0.01, 0.01, 0.02, 0.02, 0.03, 0.03],
        atol=1e-15,
        what="face offsets",
    )
    assert isinstance(box.coal_geometry(), coal.Box)
    assert box.coal_geometry() is box.coal_geometry()
    with pytest.raises(ValueError):
        box.vertices[0, 0] = 1.0  # immutable


@pytest.mark.parametrize("name", ["box", "prism", "triangle", "mesh"])
def test_faces_are_consistent(objects, name):
    obj = objects[name]
    verts, tris = obj.mesh()
    for f in obj.faces:
        assert_close(np.linalg.norm(f.normal), 1.0, atol=1e-12, what="unit normal")
        assert_close(
            f.polygon @ f.normal,
            np.full(len(f.polygon), f.offset),
            atol=1e-9,
            what="polygon on its plane",
        )
        assert_close(np.cross(f.u, f.v), f.normal, atol=1e-12, what="u x v = n")
        assert_close(f.from_uv(f.polygon_uv), f.polygon, atol=1e-12, what="polygon uv")
        # CCW seen from outside: positive signed area in (u, v).
        x, y = f.polygon_uv.T
        assert np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y) > 0
    # Every vertex inside every face's half-space: convex, normals outward.
    assert np.all(verts @ obj.normals.T - obj.offsets <= 1e-12)
    # Triangles wind outward: their normals point away from the centre of mass.
    a, b, c = verts[tris[:, 0]], verts[tris[:, 1]], verts[tris[:, 2]]
    assert np.all(np.einsum("ij,ij->i", np.cross(b - a, c - a), a + b + c) > 0)
    # Centre of mass at the origin: tetrahedra (origin, triangle), signed volumes.
    vol = np.einsum("ij,ij->i", np.cross(b - a, c - a), a) / 6.0
    assert_close(vol.sum(), obj.volume_m3, atol=1e-15, rtol=1e-12, what="volume")
    moment = np.sum(vol[:, None] * (a + b + c) / 4.0, axis=0)
    assert_close(moment / obj.volume_m3, np.zeros(3), atol=1e-12, what="centre of mass")


def test_face_adjacency_edges(objects):
    prism = objects["prism"]
    assert len(prism.face_adjacency) == 18  # 6 sides x 3 edges per vertical face
    for adj in prism.face_adjacency:
        fa, fb = prism.faces[adj.face_a], prism.faces[adj.face_b]
        for f in (fa, fb):
            assert_close(
                adj.edge @ f.normal, np.full(2, f.offset), atol=1e-12, what="edge on both faces"
            )
        # edge[0] -> edge[1] runs counter-clockwise around face_a (seen from outside).
        d = adj.edge[1] - adj.edge[0]
        assert np.cross(fa.normal, d) @ (fa.origin - adj.edge[0]) > 0


def test_extruded_polygon_centre_and_cw_input():
    poly = np.array([[0.0, 0.0], [0.05, 0.0], [0.01, 0.04]])
    ccw = ExtrudedPolygon(poly, 0.02)
    cw = ExtrudedPolygon(poly[::-1], 0.02)
    assert_close(ccw.vertices, cw.vertices, atol=1e-15, what="orientation independent")
    assert_close(ccw.vertices.mean(axis=0)[2], 0.0, atol=1e-15, what="mid-height")
    assert_close(
        ccw.polygon_xy.mean(axis=0), np.zeros(2), atol=1e-15, what="triangle centroid at the origin"
    )


def test_convex_mesh_of_cube_equals_box():
    box = Box((0.06, 0.04, 0.04))
    rng = np.random.default_rng(1)
    pts = rng.permutation(box.vertices) + [0.5, 0.2, -0.1]
    # Interior and edge-midpoint points are dropped by the hull.
    pts = np.vstack([pts, [0.5, 0.2, -0.1], [0.5, 0.22, -0.1]])
    mesh = ConvexMesh(pts)
    assert_close(mesh.input_centroid, [0.5, 0.2, -0.1], atol=1e-12, what="centroid")
    assert_close(mesh.vertices, box.vertices, atol=1e-12, what="vertices")
    assert np.array_equal(mesh.triangles, box.triangles)
    sb, sm = box.sample_surface(SPACING_M), mesh.sample_surface(SPACING_M)
    assert np.array_equal(sb.face_ids, sm.face_ids)
    assert_close(sm.points, sb.points, atol=1e-12, what="samples")
    assert_close(sm.normals, sb.normals, atol=1e-12, what="normals")


def test_convex_mesh_rebuilt_from_its_plan_params_is_the_same_to_the_bit():
    """A mesh's params hold its centred vertices; rebuilding it (as a plan file is
    opened) keeps them as they are instead of re-centring them by rounding."""
    rng = np.random.default_rng(4)
    for _ in range(10):
        mesh = ConvexMesh(rng.normal(size=(40, 3)) * 0.02 + rng.uniform(-0.1, 0.1, 3))
        again = object_from_params(mesh.kind, mesh.params)
        assert np.array_equal(again.vertices, mesh.vertices)
        assert np.array_equal(again.input_centroid, np.zeros(3))
        assert np.max(np.abs(mesh.input_centroid)) > 1e-3  # the first build did re-centre


def test_volume_centroid_of_a_square_pyramid_is_a_quarter_up():
    """A square pyramid's centroid lies a quarter of its height above the base, not at
    the mean of its vertices (a fifth): the volumes weigh the tetrahedra. Turned and
    far from the origin."""
    h = 0.05
    pyramid = np.array(
        [
            [-0.02, -0.02, 0.0],
            [0.02, -0.02, 0.0],
            [0.02, 0.02, 0.0],
            [-0.02, 0.02, 0.0],
            [0.0, 0.0, h],
        ]
    )
    R = Rotation.from_rotvec([0.3, -0.5, 0.2]).as_matrix()
    shift = np.array([0.31, 0.12, -0.2])
    mesh = ConvexMesh(pyramid @ R.T + shift)
    assert_close(mesh.input_centroid, R @ [0.0, 0.0, h / 4] + shift, atol=1e-15, what="centroid")


def test_coplanar_triangles_merge_into_polygons():
    # A cube whose faces carry extra vertices in their plane: still 6 faces.
    rng = np.random.default_rng(2)
    extra = rng.uniform(-0.01, 0.01, size=(30, 3))
    extra[np.arange(30), rng.integers(0, 3, 30)] = 0.01 * rng.choice([-1, 1], 30)
    mesh = ConvexMesh(np.vstack([Box((0.02, 0.02, 0.02)).vertices, extra]))
    assert len(mesh.faces) == 6
    assert all(len(f.polygon) == 4 for f in mesh.faces)


def test_params_round_trip_through_json(objects):
    for obj in objects.values():
        data = json.loads(json.dumps(obj.to_dict()))
        again = object_from_params(data["kind"], data["params"])
        assert again.kind == obj.kind
        assert_close(again.vertices, obj.vertices, atol=1e-12, what=obj.kind)
        assert_close(np.array(data["vertices"]), obj.vertices, atol=0, what="mesh")
        assert np.array_equal(np.array(data["faces"]), obj.triangles)


# ---------------------------------------------------------------------- sampling
def test_box_sample_counts_are_exact():
    box = Box((0.06, 0.04, 0.02))
    s = box.sample_surface(0.002)
    counts = np.bincount(s.face_ids, minlength=6)
    expected = [round(f.area / 0.002**2) for f in box.faces]  # 30x20, 30x10, 20x10 grids
    assert counts.tolist() == expected
    assert s.spacing_m == 0.002 and len(s) == sum(expected)


@pytest.mark.parametrize("name", ["box", "prism", "triangle", "mesh"])
def test_sampling_points_normals_and_uv(objects, name):
    obj = objects[name]
    s = obj.sample_surface(SPACING_M)
    assert s.points.shape == s.normals.shape == (len(s), 3)
    counts = np.bincount(s.face_ids, minlength=len(obj.faces))
    assert np.all(counts >= 1), "every face gets a point"
    areas = np.array([f.area for f in obj.faces])
    big = areas > 25 * SPACING_M**2  # counts ~ area / spacing^2, minus the inset rim
    perim = np.array(
        [
            np.sum(np.linalg.norm(np.diff(f.polygon_uv, axis=0, append=f.polygon_uv[:1]), axis=1))
            for f in obj.faces
        ]
    )
    approx = areas / SPACING_M**2
    rim = perim / SPACING_M + 4
    assert np.all(np.abs(counts - approx)[big] <= rim[big]), (counts, approx)
    # Normals unit and outward.
    assert_close(np.linalg.norm(s.normals, axis=1), np.ones(len(s)), atol=1e-12, what="unit")
    assert np.all(np.einsum("ij,ij->i", s.normals, s.points) > 0)
    # On the surface: own signed distance and Coal distance are ~0.
    assert_close(obj.signed_distance(s.points), np.zeros(len(s)), atol=1e-12, what="sdf")
    subset = s.points[:: max(1, len(s) // 150)]
    assert_close(
        _coal_point_distance(obj, subset),
        np.zeros(len(subset)),
        atol=1e-7,
        what="Coal distance of samples",
    )
    # Not on an edge: at least half a spacing inside the face polygon.
    for f in obj.faces:
        uv = s.uv[s.face_ids == f.id]
        if len(uv) > 1:
            assert np.all(f.contains_uv(uv, 0.5 * SPACING_M * (1 - 1e-6)))
    # uv round-trip.
    assert_close(obj.surface_points(s.face_ids, s.uv), s.points, atol=1e-15, what="uv")
    uv_back = np.concatenate(
        [obj.faces[i].to_uv(s.points[s.face_ids == i]) for i in range(len(obj.faces))]
    )
    order = np.argsort(s.face_ids, kind="stable")
    assert_close(uv_back, s.uv[order], atol=1e-15, what="to_uv")
    assert np.array_equal(obj.supporting_face(s.points), s.face_ids)


def test_tiny_face_still_gets_a_point():
    prism = Prism(3, 0.02, 0.001)  # 1 mm thick: the side faces are thinner than the spacing
    s = prism.sample_surface(0.005)
    assert np.all(np.bincount(s.face_ids, minlength=len(prism.faces)) >= 1)
    assert_close(prism.signed_distance(s.points), np.zeros(len(s)), atol=1e-12, what="sdf")


def test_sample_is_cached_and_immutable(objects):
    box = objects["box"]
    s = box.sample_surface(SPACING_M)
    assert box.sample_surface(SPACING_M) is s
    with pytest.raises(ValueError):
        s.points[0, 0] = 0.0


# ---------------------------------------------------------------------- distances
@pytest.mark.parametrize("name", ["box", "prism", "triangle", "mesh"])
def test_signed_distance_matches_coal(objects, name):
    obj = objects[name]
    rng = np.random.default_rng(3)
    pts = rng.normal(size=(200, 3)) * 0.7 * obj.radius_m
    sd = obj.signed_distance(pts)
    ref = _coal_point_distance(obj, pts)
    outside = sd > 0
    assert 40 < outside.sum() < 200
    assert_close(sd[outside], ref[outside], atol=1e-9, what="outside distance vs Coal")
    # Inside: minus the distance to the nearest face plane, checked through projection.
    proj = obj.project_to_surface(pts)
    assert_close(np.linalg.norm(proj - pts, axis=1), np.abs(sd), atol=1e-12, what="|p - proj|")
    assert_close(obj.signed_distance(proj), np.zeros(len(pts)), atol=1e-12, what="proj on surface")
    assert np.array_equal(obj.contains(pts), sd <= 0)


@settings(max_examples=15, deadline=None, derandomize=True)
@given(st.integers(min_value=0, max_value=10_000))
def test_signed_distance_is_exact_on_random_hulls(seed):
    rng = np.random.default_rng(seed)
    obj = ConvexMesh(rng.uniform(-0.02, 0.02, size=(rng.integers(5, 25), 3)))
    pts = rng.normal(size=(20, 3)) * 0.03
    sd = obj.signed_distance(pts)
    # Exactness: the nearest point is on the surface and no sampled surface point is nearer.
    s = obj.sample_surface(0.002)
    brute = np.min(np.linalg.norm(pts[:, None] - s.points[None], axis=2), axis=1)
    assert np.all(np.abs(sd) <= brute + 1e-12)
    out = sd > 0
    ref = _coal_point_distance(obj, pts[out])
    assert_close(sd[out], ref, atol=1e-9, what="vs Coal")


# ---------------------------------------------------------------------- bad input
@pytest.mark.parametrize(
    ("make", "exc", "argument"),
    [
        (lambda: Box((0.0, 0.02, 0.02)), InputError, "size"),
        (lambda: Box((-0.01, 0.02, 0.02)), InputError, "size"),
        (lambda: Box((np.nan, 0.02, 0.02)), InputError, "size"),
        (lambda: Box((0.02, 0.02)), InputError, "size"),
        (lambda: Prism(2, 0.02, 0.02), InputError, "n_sides"),
        (lambda: Prism(5, 0.0, 0.02), InputError, "circumradius_m"),
        (lambda: Prism(5, 0.02, -1.0), InputError, "height_m"),
        (lambda: ExtrudedPolygon([[0, 0], [1, 0], [1, 1]], 0.0), InputError, "height_m"),
        (lambda: ConvexMesh([[0, 0, np.nan]] * 5), InputError, "vertices"),
    ],
)
def test_bad_parameters_name_the_argument(make, exc, argument):
    with pytest.raises(exc) as info:
        make()
    assert info.value.argument == argument
    assert argument in str(info.value)


@pytest.mark.parametrize(
    ("make", "words"),
    [
        (
            lambda: ExtrudedPolygon([[0, 0], [0.02, 0], [0.005, 0.005], [0, 0.02]], 0.01),
            "not convex",
        ),
        (lambda: ExtrudedPolygon([[0, 0], [0.01, 0], [0.02, 0]], 0.01), "zero area"),
        (lambda: ExtrudedPolygon([[0, 0], [0.01, 0]], 0.01), "at least 3"),
        (lambda: ExtrudedPolygon([[0, 0], [0.01, 0], [0.01, 0], [0, 0.01]], 0.01), "repeated"),
        (
            lambda: ConvexMesh(np.c_[np.random.default_rng(0).normal(size=(10, 2)), np.zeros(10)]),
            "flat",
        ),
        (lambda: ConvexMesh(np.zeros((3, 3))), "at least 4"),
    ],
)
def test_degenerate_shapes_raise_geometry_error(make, words):
    with pytest.raises(GeometryError, match=words):
        make()


@pytest.mark.parametrize("spacing", [0.0, -0.001, float("nan"), float("inf")])
def test_bad_spacing(objects, spacing):
    with pytest.raises(InputError) as info:
        objects["box"].sample_surface(spacing)
    assert info.value.argument == "spacing_m"


def test_unknown_kind():
    with pytest.raises(InputError, match="kind"):
        object_from_params("sphere", {"radius": 1.0})


def test_plot_object_draws_faces_points_and_contacts(objects, tmp_path):
    pytest.importorskip("matplotlib")
    from regrasp_pin.plotting.objects import plot_object

    prism = objects["prism"]
    s = prism.sample_surface(0.005)
    ax = plot_object(prism, s, contacts_object=s.points[[0, len(s) // 2]])
    assert len(ax.collections) >= 4  # faces, samples, contacts, normals
    ax.figure.savefig(tmp_path / "fig1.png")
    assert (tmp_path / "fig1.png").stat().st_size > 1000
    with pytest.raises(InputError):
        plot_object(prism, contacts_object=np.zeros((2, 2)))
