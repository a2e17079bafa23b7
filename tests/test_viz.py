"""The meshcat viewer's scene, built without a browser (see test_viz_browser.py for that).

The scene is recorded offline (:class:`regrasp_pin.viz.SceneRecorder`) and checked
against the plan it shows: geometry where the plan says, animation keyframes equal to
the interpolated plan, overlays shown only while they matter.
"""

from __future__ import annotations

import socket
import subprocess
import sys

import numpy as np
import pinocchio as pin
import pytest
from conftest import assert_close
from scipy.spatial.transform import Rotation

pytest.importorskip("meshcat")

from regrasp_pin.exceptions import InputError  # noqa: E402
from regrasp_pin.plan import ContactPhase, Plan  # noqa: E402

viz = pytest.importorskip("regrasp_pin.viz")
from regrasp_pin.viz import shapes  # noqa: E402
from regrasp_pin.viz.example_plan import synthetic_manifold, synthetic_plan  # noqa: E402

FPS = 30.0


# ----------------------------------------------------------------------- fixtures
@pytest.fixture(scope="module")
def plan(tmp_path_factory) -> Plan:
    """The hand-made plan (five-finger hand, a box at (0.06, 0.02, 0.04) in the palm
    frame turning about the palm normal for 1 s, thumb/index/middle held by IK, one
    index regrasp), through a save/load round trip."""
    path = tmp_path_factory.mktemp("plan") / "plan.json"
    synthetic_plan().save(path)
    return Plan.load(path)


@pytest.fixture(scope="module")
def hand(plan):
    return plan.load_hand()


@pytest.fixture(scope="module")
def viewer(plan, hand):
    return viz.PlanViewer(plan, hand=hand)


def _positions(command: dict) -> np.ndarray:
    """Vertex positions (n, 3) of a recorded set_object command."""
    geom = command["object"]["geometries"][0]["data"]["attributes"]["position"]
    return np.frombuffer(geom["array"].data, dtype=np.float32).reshape(-1, 3).astype(float)


def _matrix(command: dict) -> np.ndarray:
    return np.asarray(command["matrix"], float).reshape(4, 4).T


# ------------------------------------------------------------ import boundaries
def _run_python(code: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)


def test_import_regrasp_pin_does_not_import_the_viewer():
    res = _run_python(
        "import sys, regrasp_pin; "
        "print(sorted(m for m in sys.modules if m.split('.')[0] in "
        "('meshcat', 'matplotlib') or m.startswith('regrasp_pin.viz')))"
    )
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip() == "[]"


def test_missing_meshcat_names_the_extra_to_install():
    res = _run_python(
        "import sys; sys.modules['meshcat'] = None\n"
        "from regrasp_pin.exceptions import MissingExtraError\n"
        "try:\n    import regrasp_pin.viz\n"
        "except MissingExtraError as exc:\n"
        "    print(isinstance(exc, ImportError), exc.extra, exc)\n"
    )
    assert res.returncode == 0, res.stderr
    assert res.stdout.startswith("True viz ")
    assert "pip install" in res.stdout and "regrasp-pin[viz]" in res.stdout


def test_every_exported_name_exists():
    for name in viz.__all__:
        assert getattr(viz, name) is not None, name


# ------------------------------------------------------------------- the fixture
def test_fixture_plan_holds_its_contacts(plan, hand):
    """The test data is what it claims: every contact phase's fingertip centre stays at
    T(t) (p + r n) (IK tolerance), and the regrasp lands on Q."""
    T = plan.poses()
    n_contacts = 0
    for finger, phases in plan.phases.items():
        f = hand.fingers[finger]
        for ph in phases:
            if not isinstance(ph, ContactPhase):
                continue
            m = (plan.t >= ph.t_start) & (plan.t <= ph.t_end)
            tip = f.fk(plan.q[m][:, f.q_indices])
            c = ph.p_object + f.tip_radius * ph.n_object
            expected = np.einsum("nij,j->ni", T[m, :3, :3], c) + T[m, :3, 3]
            assert_close(tip, expected, atol=1e-4, what=f"{finger} contact")
            n_contacts += 1
    assert n_contacts == 4
    (r,) = plan.regrasps()
    assert r.finger == "index" and np.linalg.norm(r.Q_object - r.P_object) > 0.01


# --------------------------------------------------------------------- sampling
def test_plan_states_interpolate_between_samples(plan):
    q, T = viz.plan_states(plan, plan.t)
    assert_close(q, plan.q, atol=1e-12, what="q at samples")
    assert_close(T, plan.poses(), atol=1e-12, what="poses at samples")
    mid = 0.5 * (plan.t[3] + plan.t[4])
    q_mid, T_mid = viz.plan_states(plan, [mid])
    assert_close(q_mid[0], 0.5 * (plan.q[3] + plan.q[4]), atol=1e-12, what="q midpoint")
    R3, R4 = plan.poses()[3:5, :3, :3]
    half = Rotation.from_matrix(R3.T @ R4).as_rotvec() / 2
    assert_close(T_mid[0, :3, :3], R3 @ Rotation.from_rotvec(half).as_matrix(), atol=1e-12,
                 what="slerp midpoint")  # fmt: skip
    q_out, _ = viz.plan_states(plan, [plan.t[0] - 1.0, plan.t[-1] + 1.0])
    assert_close(q_out, plan.q[[0, -1]], atol=0, what="clamped outside the plan")


# ------------------------------------------------------------------------ scene
def test_scene_holds_hand_object_contacts_regrasp_and_trails(viewer, plan, hand):
    rec = viewer.vis.window
    paths = set(rec.paths())
    visuals = [f"/meshcat/{n}" for n in viewer.hand_node_names()]
    assert len(visuals) == len(hand.visual_model.geometryObjects) and set(visuals) <= paths
    # the object is its real mesh, in the object frame, under the moving object node
    mesh = rec.command("/meshcat/plan/object/mesh")
    assert_close(_positions(mesh), np.asarray(plan.object["vertices"]), atol=1e-7, what="mesh")
    contacts = sorted(p for p in paths if p.startswith("/meshcat/plan/object/contacts/"))
    assert contacts == sorted(
        f"/meshcat/plan/object/contacts/{f}_{i}/{part}"
        for f, phases in plan.phases.items()
        for i in range(sum(isinstance(p, ContactPhase) for p in phases))
        for part in ("point", "normal")
    )
    base = "/meshcat/plan/object/regrasps/0_index"
    for part in ("P", "Q", "grid_path", "tip_path", "waypoints", "polygon"):
        assert f"{base}/{part}" in paths, part
    # fingers that move leave a trail; ring and little are still
    trails = {p.rsplit("/", 1)[1] for p in paths if p.startswith("/meshcat/plan/trails/")}
    assert trails == {"thumb", "index", "middle"}


def test_markers_sit_where_the_plan_says(viewer, plan):
    rec = viewer.vis.window
    r = plan.regrasps()[0]
    for name, point in (("P", r.P_object), ("Q", r.Q_object)):
        v = _positions(rec.command(f"/meshcat/plan/object/regrasps/0_index/{name}"))
        assert_close(v.mean(axis=0), point, atol=1e-6, what=f"{name} sphere centre")
    # the normal arrow of the first thumb contact starts at p and points along n
    c = plan.phases["thumb"][0]
    v = _positions(rec.command("/meshcat/plan/object/contacts/thumb_0/normal"))
    tip = v[np.argmax(v @ c.n_object)]
    assert_close(tip, c.p_object + 0.35 * 0.05 * c.n_object, atol=1e-6, what="arrow tip")


def test_tip_path_goes_from_P_to_Q_at_the_fingertip_centre(viewer, plan, hand):
    r = plan.regrasps()[0]
    path = viewer.tip_path_object(r)
    radius = hand.fingers["index"].tip_radius
    n = plan.phases["index"][0].n_object
    assert_close(path[0], r.P_object + radius * n, atol=1e-4, what="tip path start")
    assert_close(path[-1], r.Q_object + radius * n, atol=1e-4, what="tip path end")
    # in between it is lifted off the face (the made-up waypoints arc outwards)
    height = (path - r.P_object) @ n
    assert height.max() > radius + 0.005


def test_display_puts_hand_and_object_at_the_plan_state(plan, hand):
    v = viz.PlanViewer(plan, hand=hand)
    t = 0.55
    v.display(t)
    q, T = viz.plan_states(plan, [t])
    rec = v.vis.window
    assert_close(_matrix(rec.command("/meshcat/plan/object", "transform")), T[0], atol=1e-6,
                 what="object pose")  # fmt: skip
    data = hand.model.createData()
    gdata = pin.GeometryData(hand.visual_model)
    pin.forwardKinematics(hand.model, data, q[0])
    pin.updateGeometryPlacements(hand.model, data, hand.visual_model, gdata)
    for gid, node in enumerate(v.hand_node_names()):
        M = _matrix(rec.command(f"/meshcat/{node}", "transform"))
        assert_close(M, gdata.oMg[gid].homogeneous, atol=1e-6, what=node)
    shown = {
        p["path"]: p["value"]
        for p in rec.command("/meshcat/plan/object/regrasps/0_index", "properties")["properties"]
    }
    assert shown["/meshcat/plan/object/regrasps/0_index"] is True  # 0.55 s is mid-regrasp
    v.display(0.05)
    props = rec.command("/meshcat/plan/object/regrasps/0_index", "properties")["properties"]
    assert props[-1]["value"] is False


# -------------------------------------------------------------------- animation
def test_animation_keyframes_are_the_plan(viewer, plan, hand):
    anim = viewer.animation(FPS)
    clips = {path.lower(): clip for path, clip in anim.clips.items()}
    times = viz.frame_times(plan, FPS)
    assert times.size == int(np.ceil((plan.t[-1] - plan.t[0]) * FPS)) + 1
    q, T = viz.plan_states(plan, times)
    obj = clips["/meshcat/plan/object"]
    quat_xyzw = np.asarray(obj.tracks["quaternion"].values)
    assert obj.tracks["quaternion"].frames == list(range(times.size))
    expected = Rotation.from_matrix(T[:, :3, :3]).as_quat()
    same_sign = np.sign(np.sum(quat_xyzw * expected, axis=1))[:, None]
    assert_close(quat_xyzw * same_sign, expected, atol=1e-9, what="object quaternions")
    # a fingertip geometry of the index finger follows FK at every frame
    names = viewer.hand_node_names()
    gid = next(i for i, n in enumerate(names) if n.endswith("index_distal_1"))
    track = np.asarray(clips[f"/meshcat/{names[gid]}"].tracks["position"].values)
    data = hand.model.createData()
    gdata = pin.GeometryData(hand.visual_model)
    expected_p = []
    for q_f in q:
        pin.forwardKinematics(hand.model, data, q_f)
        pin.updateGeometryPlacements(hand.model, data, hand.visual_model, gdata)
        expected_p.append(gdata.oMg[gid].translation.copy())
    assert_close(track, np.array(expected_p), atol=1e-9, what="index tip sphere")


def test_overlays_are_shown_only_while_they_matter(viewer, plan):
    anim = viewer.animation(FPS)
    clips = {path.lower(): clip for path, clip in anim.clips.items()}
    r = plan.regrasps()[0]
    track = clips["/meshcat/plan/object/regrasps/0_index"].tracks["visible"]
    on = [f / FPS for f, v in zip(track.frames, track.values, strict=True) if v]
    off = [f / FPS for f, v in zip(track.frames, track.values, strict=True) if not v]
    m = viewer.regrasp_margin_s
    assert on and abs(min(on) - (r.t_start - m)) <= 1 / FPS
    assert max(off) >= r.t_end + m - 1 / FPS
    # the index finger's first contact is hidden once it lifts off
    c_track = clips["/meshcat/plan/object/contacts/index_0"].tracks["visible"]
    hidden_from = min(f for f, v in zip(c_track.frames, c_track.values, strict=True) if not v)
    assert abs(hidden_from / FPS - r.t_start) <= 1 / FPS


# --------------------------------------------------------------------- exports
def test_static_html_is_self_contained(tmp_path, plan):
    path = viz.export_html(plan, tmp_path / "plan.html")
    html = path.read_text()
    assert "MeshCat.Viewer" in html and "set_animation" not in html[:100]
    assert "<script src" not in html.replace(" ", "").lower()
    import re

    urls = set(re.findall(r"https?://[^\s\"'<>)]+", html))
    assert urls <= {"http://www.w3.org/1999/xhtml"}, urls
    assert path.stat().st_size < 5e6


def test_view_command_writes_html(tmp_path, plan):
    from regrasp_pin.commands import view

    plan_path = plan.save(tmp_path / "p.json")
    out = tmp_path / "out" / "v.html"
    assert view.main([str(plan_path), "--html", str(out)]) == 0
    assert "new MeshCat.Viewer" in out.read_text()
    assert view.main([str(tmp_path / "missing.json"), "--html", str(out)]) == 2


def test_live_server_refuses_a_busy_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        port = s.getsockname()[1]
        with pytest.raises(InputError, match=f"{port} is in use"):
            viz.LiveServer(port)


# --------------------------------------------------------------------- manifold
def test_manifold_scene_draws_box_points_path_and_q():
    m = synthetic_manifold()
    vis = viz.show_manifold(**m)
    rec = vis.window
    finite = np.all(np.isfinite(m["q_points"]), axis=1)
    pts = rec.command("/meshcat/manifold/points")
    assert_close(_positions(pts), m["q_points"][finite], atol=1e-6, what="manifold points")
    planes = _positions(rec.command("/meshcat/manifold/limits/planes"))
    assert_close(planes.min(axis=0), m["lower"], atol=1e-6, what="box lower")
    assert_close(planes.max(axis=0), m["upper"], atol=1e-6, what="box upper")
    q_new = _positions(rec.command("/meshcat/manifold/q_new")).mean(axis=0)
    assert_close(q_new, m["q_new"], atol=1e-6, what="Q")
    assert rec.command("/meshcat/manifold/p_path") is not None


def test_margin_colors_mark_points_outside_the_limits():
    c = viz.margin_colors([-0.1, 0.0, 0.5, 1.0])
    assert_close(c[0], [0.80, 0.45, 0.45], atol=1e-12, what="outside")
    assert c[1, 2] > c[1, 1] and c[3, 0] > 0.9 and c[3, 1] > 0.8  # purple ... yellow


def test_manifold_bad_input_is_refused():
    with pytest.raises(InputError, match="q_points"):
        viz.show_manifold(np.zeros((4, 4)), np.zeros(4), np.zeros(3), np.ones(3))
    with pytest.raises(InputError, match="upper"):
        viz.show_manifold(np.zeros((4, 3)), np.zeros(4), np.ones(3), np.ones(3))
    with pytest.raises(InputError, match="margin"):
        viz.show_manifold(np.zeros((4, 3)), np.zeros(5), np.zeros(3), np.ones(3))


# ----------------------------------------------------------------------- shapes
def _segment_distance(points: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    ab = b - a
    s = np.clip((points - a) @ ab / (ab @ ab), 0.0, 1.0)
    return np.linalg.norm(points - (a + s[:, None] * ab), axis=1)


def test_tube_vertices_lie_at_the_radius_around_the_polyline():
    s = np.linspace(0.0, 4.0 * np.pi, 40)
    poly = np.stack([np.cos(s), np.sin(s), 0.2 * s], axis=1)  # a helix
    seg = np.diff(poly, axis=0)
    seg /= np.linalg.norm(seg, axis=1, keepdims=True)
    bend = np.arccos(np.clip(np.sum(seg[:-1] * seg[1:], axis=1), -1, 1)).max()
    v, f = shapes.tube_mesh(poly, 0.1, sides=8)
    d = np.min([_segment_distance(v, a, b) for a, b in zip(poly[:-1], poly[1:], strict=True)], 0)
    assert np.all(d <= 0.1 + 1e-9)
    assert np.all(d >= 0.1 * np.cos(bend / 2) - 1e-9)  # a ring tilts by half the bend
    assert f.max() < len(v) and len(f) == 2 * 8 * (len(poly) - 1)
    with pytest.raises(InputError, match="distinct"):
        shapes.tube_mesh([[0, 0, 0], [0, 0, 0]], 0.1)


def test_spheres_are_closed_outward_and_at_the_radius():
    v, f = shapes.icosphere(2)
    assert len(v) - 3 * len(f) // 2 + len(f) == 2  # Euler characteristic of a sphere
    centroids = v[f].mean(axis=1)
    normals = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    assert np.all(np.einsum("ij,ij->i", normals, centroids) > 0)
    c = np.array([[1.0, 2.0, 3.0], [0.0, 0.0, 0.0]])
    sv, _ = shapes.spheres_mesh(c, 0.5)
    d = np.linalg.norm(sv.reshape(2, -1, 3) - c[:, None], axis=2)
    assert_close(d, np.full(d.shape, 0.5), atol=1e-12, what="sphere radius")


def test_arrows_and_box_have_the_right_extent():
    v, _ = shapes.arrows_mesh([[1.0, 0, 0]], [[0, 0, 2.0]], 0.3, 0.01)
    assert_close(v[np.argmax(v[:, 2])], [1.0, 0.0, 0.3], atol=1e-12, what="apex")
    lo, hi = np.array([0.0, -1.0, 2.0]), np.array([1.0, 1.0, 5.0])
    corners, tris = shapes.box_planes_mesh(lo, hi)
    assert len(tris) == 12 and set(map(tuple, corners)) == {
        (x, y, z) for x in (0.0, 1.0) for y in (-1.0, 1.0) for z in (2.0, 5.0)
    }
    e = shapes.box_edges(lo, hi).reshape(12, 2, 3)
    lengths = np.sort(np.linalg.norm(e[:, 1] - e[:, 0], axis=1))
    assert_close(lengths, np.repeat([1.0, 2.0, 3.0], 4), atol=1e-12, what="edge lengths")
