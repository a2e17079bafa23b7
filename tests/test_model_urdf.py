"""Loading real URDFs: a palm frame that locks the wrist, couplings, mimic tags in any
order, convex collision meshes; checked against Pinocchio on the unreduced model."""

from __future__ import annotations

import coal
import numpy as np
import pinocchio as pin
import pytest
from conftest import SHADOW_HAND_FILE, assert_close, shadow_urdf
from scipy.spatial import ConvexHull
from scipy.spatial.transform import Rotation

from regrasp_pin.exceptions import InputError, UnknownNameError
from regrasp_pin.model.hand import Hand
from regrasp_pin.model.urdf import read_couplings

SHADOW_TIPS = {
    "thumb": "thtip",
    "index": "fftip",
    "middle": "mftip",
    "ring": "rftip",
    "little": "lftip",
}
COUPLED = {f"{p}J1": f"{p}J2" for p in ("FF", "MF", "RF", "LF")}


@pytest.fixture(scope="module")
def shadow():
    shadow_urdf()
    return Hand.from_file(SHADOW_HAND_FILE)


def _full_configuration(full: pin.Model, hand: Hand, q_hand: np.ndarray) -> np.ndarray:
    """The unreduced model's configuration for a hand configuration (wrist at 0, each
    coupled J1 equal to its J2)."""
    q = pin.neutral(full)
    for f in hand.fingers.values():
        for name, value in zip(f.joint_names, q_hand[f.q_indices], strict=True):
            q[full.joints[full.getJointId(name)].idx_q] = value
            if name in COUPLED.values():
                follower = next(k for k, v in COUPLED.items() if v == name)
                q[full.joints[full.getJointId(follower)].idx_q] = value
    return q


def test_shadow_fingers_have_their_own_joints_only(shadow):
    assert shadow.finger("index").joint_names == ("FFJ4", "FFJ3", "FFJ2")
    assert shadow.finger("little").joint_names == ("LFJ5", "LFJ4", "LFJ3", "LFJ2")
    assert shadow.finger("thumb").joint_names == ("THJ5", "THJ4", "THJ3", "THJ2", "THJ1")
    names = [shadow.model.names[j] for j in range(1, shadow.model.njoints)]
    assert "WRJ1" not in names and "WRJ2" not in names
    # FFJ1 is still in the tree, as a joint that follows FFJ2
    assert shadow.model.joints[shadow.model.getJointId("FFJ1")].shortname() == "JointModelMimic"
    assert shadow.load_options["locked"] == {"WRJ1": 0.0, "WRJ2": 0.0}


def test_shadow_without_palm_frame_names_the_shared_joint():
    with pytest.raises(InputError) as err:
        Hand.from_urdf(shadow_urdf(), SHADOW_TIPS, tip_radius=0.008)
    assert "WRJ2" in str(err.value) and "palm_frame" in str(err.value)


def test_shadow_fk_equals_pinocchio_in_the_palm_frame(shadow):
    """Tip positions of the reduced, coupled, re-rooted model equal Pinocchio's on the
    URDF as it is (wrist at 0, J1 = J2), expressed in the palm frame."""
    full = pin.buildModelFromUrdf(str(shadow_urdf()))
    data = full.createData()
    rng = np.random.default_rng(0)
    for _ in range(100):
        q = shadow.neutral()
        for f in shadow.fingers.values():
            q[f.q_indices] = rng.uniform(f.lower, f.upper)
        pin.framesForwardKinematics(full, data, _full_configuration(full, shadow, q))
        palm_inv = data.oMf[full.getFrameId("palm")].inverse()
        for f in shadow.fingers.values():
            expected = (palm_inv * data.oMf[full.getFrameId(f.tip_frame)]).translation
            assert_close(f.fk(q[f.q_indices]), expected, atol=1e-9, what=f.name)


def test_shadow_collision_geometry_follows_the_full_model(shadow):
    """Every collision geometry sits where Pinocchio puts it on the unreduced model."""
    urdf = shadow_urdf()
    full = pin.buildModelFromUrdf(str(urdf))
    geom = pin.buildGeomFromUrdf(full, str(urdf), pin.COLLISION, package_dirs=[str(urdf.parent)])
    rng = np.random.default_rng(1)
    q = shadow.neutral()
    for f in shadow.fingers.values():
        q[f.q_indices] = rng.uniform(f.lower, f.upper)
    d_full, g_full = full.createData(), pin.GeometryData(geom)
    q_full = _full_configuration(full, shadow, q)
    pin.framesForwardKinematics(full, d_full, q_full)
    pin.updateGeometryPlacements(full, d_full, geom, g_full, q_full)
    d, g = shadow.model.createData(), pin.GeometryData(shadow.collision_model)
    pin.updateGeometryPlacements(shadow.model, d, shadow.collision_model, g, q)
    palm_inv = d_full.oMf[full.getFrameId("palm")].inverse()
    assert shadow.collision_model.ngeoms == geom.ngeoms
    for i, gobj in enumerate(shadow.collision_model.geometryObjects):
        j = geom.getGeometryId(gobj.name)
        assert_close(
            (palm_inv * g_full.oMg[j]).homogeneous, g.oMg[i].homogeneous, atol=1e-12, what=gobj.name
        )


def test_shadow_ik_round_trips(shadow):
    rng = np.random.default_rng(2)
    rates = []
    for f in shadow.fingers.values():
        q = rng.uniform(f.lower, f.upper, size=(400, f.k))
        res = f.ik(f.fk(q), tol_m=1e-5)
        assert np.all(res.error_m[res.success] <= 1e-5)
        assert f.within_limits(res.q, tol=1e-12).all()
        rates.append(res.success.mean())
    assert min(rates) >= 0.995, rates


def test_collision_meshes_are_convex_with_signed_distances(shadow):
    """A mesh becomes its convex hull: Coal then measures penetration depth, not 0."""
    meshes = [
        o for o in shadow.collision_model.geometryObjects if isinstance(o.geometry, coal.ConvexBase)
    ]
    assert meshes and not any(
        isinstance(o.geometry, coal.BVHModelBase) for o in shadow.collision_model.geometryObjects
    )
    tip = next(o for o in meshes if o.name.startswith("ffdistal"))
    tip.geometry.computeLocalAABB()
    centre = np.asarray(tip.geometry.aabb_center)
    ball = coal.Sphere(0.001)
    res = coal.DistanceResult()
    d = coal.distance(
        tip.geometry,
        coal.Transform3s(),
        ball,
        coal.Transform3s(np.eye(3), centre),
        coal.DistanceRequest(),
        res,
    )
    # the hull holds the point, a millimetre ball there is several millimetres deep
    assert d < -0.004


def test_a_box_over_any_mesh_vertex_is_found_to_penetrate(shadow):
    """The collision meshes are true convex hulls (not the mesh's own triangles, on
    which GJK can stop at a local maximum): a box placed over any vertex of the
    original mesh, up to 1 mm deep, is reported penetrating; and the hull has no more
    vertices than qhull's hull of the mesh (scipy)."""
    urdf = shadow_urdf()
    model = pin.buildModelFromUrdf(str(urdf))
    raw = pin.buildGeomFromUrdf(
        model, str(urdf), pin.COLLISION, package_dirs=[str(urdf.parent), str(urdf.parent.parent)]
    )
    mesh = next(o for o in raw.geometryObjects if o.name.startswith("ffdistal")).geometry
    vertices = np.asarray(mesh.vertices())
    tip = next(o for o in shadow.collision_model.geometryObjects if o.name.startswith("ffdistal"))
    assert tip.geometry.num_points == ConvexHull(vertices).vertices.size < len(vertices)
    rng = np.random.default_rng(0)
    box, req, res = coal.Box(0.02, 0.02, 0.02), coal.DistanceRequest(), coal.DistanceResult()
    for _ in range(1000):
        R = Rotation.random(random_state=int(rng.integers(1 << 30))).as_matrix()
        v = vertices[rng.integers(len(vertices))]
        centre = v + (0.01 - rng.uniform(0.0, 0.001)) * R[:, 0]  # v inside, near a face
        res.clear()
        d = coal.distance(
            tip.geometry, coal.Transform3s(), box, coal.Transform3s(R, centre), req, res
        )
        assert d < 0.0


def test_scale_factors_are_honoured(shadow):
    """The forearm mesh is in millimetres with scale 0.001: about 15 cm across, not 150 m."""
    forearm = next(o for o in shadow.collision_model.geometryObjects if o.name == "forearm_0")
    forearm.geometry.computeLocalAABB()
    assert 0.05 < 2 * forearm.geometry.aabb_radius < 0.5


# ------------------------------------------------------------------ synthetic URDFs
def _chain_urdf(mimic: str = "") -> str:
    """A base with one 3-joint finger: j1 (abduction, z), j2 and j3 (flexion, y)."""
    link = (
        '<link name="{0}"><collision><geometry><sphere radius="0.005"/></geometry>'
        "</collision></link>"
    )
    joints = []
    for i, (parent, axis, lo, hi) in enumerate(
        [("base", "0 0 1", -0.5, 0.5), ("l1", "0 1 0", 0.0, 1.5), ("l2", "0 1 0", 0.0, 1.2)],
        start=1,
    ):
        extra = mimic if i == 2 else ""
        joints.append(
            f'<joint name="j{i}" type="revolute"><parent link="{parent}"/><child link="l{i}"/>'
            f'<origin xyz="0.03 0 0"/><axis xyz="{axis}"/>'
            f'<limit lower="{lo}" upper="{hi}" effort="1" velocity="{2 * i}"/>{extra}</joint>'
        )
    links = "".join(link.format(n) for n in ("base", "l1", "l2", "l3"))
    tip = (
        '<link name="tip"/><joint name="t" type="fixed"><parent link="l3"/>'
        '<child link="tip"/><origin xyz="0.02 0 0"/></joint>'
    )
    return f'<robot name="chain">{links}{"".join(joints)}{tip}</robot>'


def test_mimic_of_a_later_joint_is_applied(tmp_path):
    """j2 mimics j3 (later in the tree; Pinocchio's parser refuses that): j2 drives,
    j3 = (j2 - 0.1) / 0.5, and j2's limits shrink to keep j3 inside its own."""
    urdf = tmp_path / "chain.urdf"
    urdf.write_text(_chain_urdf('<mimic joint="j3" multiplier="0.5" offset="0.1"/>'))
    hand = Hand.from_urdf(urdf, {"f": "tip"}, tip_radius=0.005)
    f = hand.finger("f")
    assert f.joint_names == ("j1", "j2")
    # j2 in [0, 1.5] and j3 = 2 (j2 - 0.1) in [0, 1.2]  ->  j2 in [0.1, 0.7]
    assert_close(f.lower, [-0.5, 0.1], atol=1e-12)
    assert_close(f.upper, [0.5, 0.7], atol=1e-12)
    # velocity: j3 moves twice as fast as j2 and is limited to 6 rad/s
    assert_close(f.velocity_limit, [2.0, 3.0], atol=1e-12)
    free = pin.buildModelFromXML(read_couplings(urdf.read_text())[0])
    data = free.createData()
    for q2 in np.linspace(0.1, 0.7, 5):
        q = np.array([0.2, q2, 2.0 * (q2 - 0.1)])
        pin.framesForwardKinematics(free, data, q)
        assert_close(f.fk([0.2, q2]), data.oMf[free.getFrameId("tip")].translation, atol=1e-12)


def test_couplings_argument_equals_a_mimic_tag(tmp_path):
    tagged = tmp_path / "tagged.urdf"
    tagged.write_text(_chain_urdf('<mimic joint="j3" multiplier="0.5" offset="0.1"/>'))
    plain = tmp_path / "plain.urdf"
    plain.write_text(_chain_urdf())
    a = Hand.from_urdf(tagged, {"f": "tip"}, tip_radius=0.005).finger("f")
    b = Hand.from_urdf(
        plain, {"f": "tip"}, tip_radius=0.005, couplings={"j2": ("j3", 0.5, 0.1)}
    ).finger("f")
    q = np.column_stack([np.linspace(-0.5, 0.5, 7), np.linspace(0.1, 0.7, 7)])
    assert_close(a.fk(q), b.fk(q), atol=1e-15)
    assert_close(a.lower, b.lower, atol=0.0)


@pytest.mark.parametrize(
    ("kwargs", "error", "argument"),
    [
        ({"couplings": {"j9": ("j2", 1.0, 0.0)}}, UnknownNameError, "couplings['j9']"),
        ({"couplings": {"j3": ("j2", 0.0, 0.0)}}, InputError, "couplings['j3']"),
        ({"couplings": {"j3": ("j2", 1.0)}}, InputError, "couplings['j3']"),
        ({"couplings": {"j3": ("j2", 1.0, 0.0), "j2": ("j3", 1.0, 0.0)}}, InputError, None),
        ({"palm_frame": "nowhere"}, UnknownNameError, "palm_frame"),
        ({"locked": {"j1": 2.0}}, InputError, "locked['j1']"),
        ({"locked": {"j1": 0.0}, "couplings": {"j1": ("j2", 1.0, 0.0)}}, InputError, None),
    ],
)
def test_bad_load_options_name_the_argument(tmp_path, kwargs, error, argument):
    urdf = tmp_path / "chain.urdf"
    urdf.write_text(_chain_urdf())
    with pytest.raises(error) as err:
        Hand.from_urdf(urdf, {"f": "tip"}, tip_radius=0.005, **kwargs)
    if argument is not None:
        assert err.value.argument == argument


def test_palm_frame_locks_what_is_above_it(tmp_path):
    """With the palm at l1, j1 is locked at its given value and l1 is the origin."""
    urdf = tmp_path / "chain.urdf"
    urdf.write_text(_chain_urdf())
    hand = Hand.from_urdf(urdf, {"f": "tip"}, tip_radius=0.005, palm_frame="l1", locked={"j1": 0.3})
    f = hand.finger("f")
    assert f.joint_names == ("j2", "j3")
    full = pin.buildModelFromXML(urdf.read_text())
    data = full.createData()
    pin.framesForwardKinematics(full, data, np.array([0.3, 0.4, 0.5]))
    palm_inv = data.oMf[full.getFrameId("l1")].inverse()
    expected = (palm_inv * data.oMf[full.getFrameId("tip")]).translation
    assert_close(f.fk([0.4, 0.5]), expected, atol=1e-12)


def test_a_mimic_tag_across_the_palm_frame_is_named(tmp_path):
    """j2 mimics j1, but the palm at l1 locks j1 and leaves j2 free: refused, naming
    the tag; with the palm at l2 both are locked and the tag goes with them."""
    urdf = tmp_path / "chain.urdf"
    urdf.write_text(_chain_urdf('<mimic joint="j1" multiplier="1.0" offset="0.0"/>'))
    with pytest.raises(InputError) as err:
        Hand.from_urdf(urdf, {"f": "tip"}, tip_radius=0.005, palm_frame="l1")
    assert err.value.argument == "URDF <mimic> of 'j2'"
    hand = Hand.from_urdf(urdf, {"f": "tip"}, tip_radius=0.005, palm_frame="l2")
    assert hand.finger("f").joint_names == ("j3",)
