"""Tests of the joint-space manifolds (regrasp_pin.grasp.manifold), the paper's Fig. 2.

Scene (palm frame: x toward the fingers, z out of the palm): the five-finger hand and a
box 40 x 60 x 40 mm at (65, 0, 60) mm, axes aligned with the palm, turning about the
palm y axis through its centre at 30 deg/s for 3 s; the surface sampled every 4 mm and
13 grid times (every 0.25 s, 7.5 deg). Every finger has feasible contacts on it.

The manifold is checked against reasons, not against itself: FK round trips of its
joint coordinates, the joint box and the pad cone recomputed from those coordinates,
the same targets solved by ``Finger.ik`` (cold, with restarts, in the real limits),
a dense brute-force sweep of the joint box for the points the prefilters skip, and
random configurations for the workspace cover.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from conftest import assert_close
from scipy.spatial.transform import Rotation

from regrasp_pin.exceptions import InputError, UnknownNameError
from regrasp_pin.grasp import manifold as manifold_module
from regrasp_pin.grasp.choice import exit_times
from regrasp_pin.grasp.contact import ContactModel, tip_targets
from regrasp_pin.grasp.manifold import (
    THREADS_ENV,
    StartTracking,
    build_manifold,
    build_manifolds,
    default_threads,
    forget_first_times,
    pad_directions,
    workspace_voxels,
)
from regrasp_pin.model.hand import Finger, Hand
from regrasp_pin.model.ik import solve_position_ik
from regrasp_pin.model.motion import ObjectMotion
from regrasp_pin.model.objects import Box

EXTEND_RAD = 0.3  # build_manifold's default
CONTACT = ContactModel()


def box_scene() -> tuple[Box, ObjectMotion]:
    box = Box((0.04, 0.06, 0.04))
    T0 = np.eye(4)
    T0[:3, 3] = [0.065, 0.0, 0.06]
    motion = ObjectMotion.constant_twist(
        T0,
        axis_palm=[0.0, 1.0, 0.0],
        point_palm=T0[:3, 3],
        rate_rad_s=np.radians(30.0),
        duration_s=3.0,
        dt_s=0.05,
    )
    return box, motion


@pytest.fixture(scope="module")
def scene():
    hand = Hand.five_finger()
    box, motion = box_scene()
    sample = box.sample_surface(0.004)
    times = np.linspace(0.0, 3.0, 13)
    manifolds = {
        name: build_manifold(hand.finger(name), sample, motion, times) for name in hand.finger_names
    }
    return hand, box, motion, sample, times, manifolds


def _targets(finger: Finger, sample, manifold) -> np.ndarray:
    return tip_targets(sample.points, sample.normals, finger.tip_radius, manifold.T_palm_object)


def _normals_palm(sample, manifold) -> np.ndarray:
    return np.einsum("tij,nj->tni", manifold.T_palm_object[:, :3, :3], sample.normals)


def _pad_cos(finger: Finger, q: np.ndarray, n_palm: np.ndarray) -> np.ndarray:
    """Pad cosines from the tip rotations (not via contact.pad_cosines)."""
    R, _ = finger.tip_poses(q)
    return -np.einsum("nij,j,ni->n", R, finger.pad_axis_tip, n_palm)


def test_every_finger_has_feasible_contacts(scene):
    hand, _, _, sample, times, manifolds = scene
    for name, m in manifolds.items():
        assert m.finger == name
        assert m.q.shape == (times.size, len(sample), hand.finger(name).k)
        assert m.usable(CONTACT.choice_margin_rad)[0].sum() >= 3, name


def test_reachable_entries_reach_their_targets(scene):
    hand, _, _, sample, _, manifolds = scene
    for name, m in manifolds.items():
        f = hand.finger(name)
        targets = _targets(f, sample, m)
        r = m.reachable
        err = np.linalg.norm(f.fk(m.q[r]) - targets[r], axis=1)
        assert err.max() <= CONTACT.ik_tol_m * (1 + 1e-9), name
        # IK ran in the box extended by EXTEND_RAD beyond the limits
        solved = ~np.isnan(m.q[..., 0])
        qs = m.q[solved]
        assert np.all(qs >= f.lower - EXTEND_RAD - 1e-12) and np.all(
            qs <= f.upper + EXTEND_RAD + 1e-12
        ), name
        assert np.all(solved[r]), "a reachable entry has coordinates"


def test_inside_margin_and_pad_follow_from_the_coordinates(scene):
    hand, _, _, sample, _, manifolds = scene
    for name, m in manifolds.items():
        f = hand.finger(name)
        r = m.reachable
        q = m.q[r]
        # margin: distance to the nearest of the 2k boundary planes, written out
        planes = np.concatenate([q - f.lower, f.upper - q], axis=1)
        assert_close(m.margin_rad[r], planes.min(axis=1), atol=1e-15, what=f"{name} margin")
        assert np.all(m.margin_rad[~r] == -np.inf)
        within = np.all((q >= f.lower) & (q <= f.upper), axis=1)
        assert np.array_equal(m.inside[r], within), name
        assert not m.inside[~r].any()
        cos = _pad_cos(f, q, _normals_palm(sample, m)[r])
        assert np.array_equal(m.pad_ok[r], cos >= CONTACT.cos_cone_of(f)), name
        assert not m.pad_ok[~r].any()
        assert np.array_equal(m.feasible, m.inside & m.pad_ok)
        rows, points = np.array([3, 0, 3]), np.arange(0, m.q.shape[1], 7)
        for margin in (0.0, 0.05, 0.2):
            usable = m.feasible & (m.margin_rad >= margin)
            assert np.array_equal(m.usable(margin), usable)
            # a block: index arrays (an outer product), slices, or one of each
            assert np.array_equal(
                m.usable(margin, rows=rows, points=points), usable[np.ix_(rows, points)]
            )
            assert np.array_equal(m.usable(margin, rows=slice(2, None)), usable[2:])
            assert np.array_equal(m.usable(margin, rows=rows), usable[rows])
            assert np.array_equal(m.usable(margin, points=points), usable[:, points])


def test_tip_clear_follows_from_the_tip_orientation(scene):
    """tip_clear: reachable, and the fingertip link's overshoot past the plane the tip
    rests on (from the tip rotations, not via contact.pad_cosines_and_overshoot) within
    the tolerance; holdable = usable and tip_clear. The five-finger distal cylinder
    overshoots when the pad tilts toward the palm, so some feasible entries are not
    clear."""
    hand, _, _, sample, _, manifolds = scene
    tilted = 0
    for name, m in manifolds.items():
        f = hand.finger(name)
        r = m.reachable
        R, _ = f.tip_poses(m.q[r])
        u_tip = -np.einsum("nji,nj->ni", R, _normals_palm(sample, m)[r])
        clear = f.tip_reach.overshoot(u_tip) <= CONTACT.tip_penetration_m
        assert np.array_equal(m.tip_clear[r], clear), name
        assert not m.tip_clear[~r].any()
        rows, points = np.array([1, 0]), np.arange(3, m.q.shape[1], 5)
        for margin in (0.0, 0.05):
            holdable = m.usable(margin) & m.tip_clear
            assert np.array_equal(m.holdable(margin), holdable)
            block = m.holdable(margin, rows=rows, points=points)
            assert np.array_equal(block, holdable[np.ix_(rows, points)])
            assert np.array_equal(m.holdable(margin, rows=slice(1, None)), holdable[1:])
        tilted += int((m.feasible & ~m.tip_clear).sum())
    assert tilted > 0


def test_manifold_crosses_the_boundary_planes(scene):
    # the paper draws the manifold crossing the boundary planes: with the extended box
    # some reachable points lie outside the limits, by at most EXTEND_RAD
    _, _, _, _, _, manifolds = scene
    outside = np.concatenate([m.margin_rad[m.reachable & ~m.inside] for m in manifolds.values()])
    assert outside.size > 100
    assert np.all((outside < 0) & (outside >= -EXTEND_RAD - 1e-12))


def test_feasible_entries_equal_per_point_ik(scene):
    """Each time's targets solved by Finger.ik (cold, restarts, real limits) + the pad test.

    A manifold entry that is feasible is one by its own coordinates (tests above). The
    converse: every target that per-point IK makes feasible is feasible in the manifold,
    except where the manifold followed (warm-started along time) another IK branch of
    the same target: a solution (FK checked above) whose pad does not face the surface
    or that lies beyond a limit (e.g. the thumb's IP hyperextended where per-point IK
    finds it flexed). Those are rare.
    """
    hand, _, _, sample, times, manifolds = scene
    for name, m in manifolds.items():
        f = hand.finger(name)
        targets = _targets(f, sample, m)
        normals = _normals_palm(sample, m)
        n_ref = 0
        other_branch = 0
        for t in range(times.size):
            res = f.ik(targets[t], tol_m=CONTACT.ik_tol_m)
            ref = res.success & (_pad_cos(f, res.q, normals[t]) >= CONTACT.cos_cone_of(f))
            n_ref += int(ref.sum())
            missing = np.flatnonzero(ref & ~m.feasible[t])
            for i in missing:
                assert m.reachable[t, i], (name, t, i)
                # another branch, or the same one just past a limit where per-point IK
                # (clamped to the limits) stops on it within the tolerance
                past = np.maximum(f.lower - m.q[t, i], m.q[t, i] - f.upper).max()
                other = np.abs(m.q[t, i] - res.q[i]).max() > 0.05
                assert other or 0.0 < past < 1e-3, (name, t, i)
            other_branch += missing.size
        assert m.feasible.sum() <= n_ref
        assert other_branch <= 0.02 * n_ref, (name, other_branch, n_ref)


def test_batched_ik_is_per_point_ik(scene):
    # the reference above solves each time's targets in one batch: the same as one
    # Finger.ik call per point (the batch is elementwise)
    hand, _, _, sample, _, manifolds = scene
    rng = np.random.default_rng(7)
    f = hand.finger("middle")
    targets = _targets(f, sample, manifolds["middle"])[4]
    batch = f.ik(targets)
    for i in rng.choice(len(sample), 25, replace=False):
        one = f.ik(targets[i])
        assert one.success[0] == batch.success[i]
        assert_close(one.q[0], batch.q[i], atol=1e-12, what=f"point {i}")


def test_batched_ik_is_bitwise_per_point(scene):
    # what lets a manifold solve a subset of its points: each point's IK result is
    # the same bit for bit in any batch (solved alone, or with other points)
    hand, _, _, sample, _, manifolds = scene
    f = hand.finger("thumb")
    targets = _targets(f, sample, manifolds["thumb"])[6]
    q0 = np.broadcast_to(f.q_mid, targets.shape[:1] + (f.k,))
    batch = solve_position_ik(f.chain, f.lower, f.upper, targets, q0, tol_m=CONTACT.ik_tol_m)
    rng = np.random.default_rng(3)
    some = np.sort(rng.choice(len(sample), 40, replace=False))
    for idx in (some, some[:1], some[7:9]):
        part = solve_position_ik(
            f.chain, f.lower, f.upper, targets[idx], q0[idx], tol_m=CONTACT.ik_tol_m
        )
        assert np.array_equal(part.q, batch.q[idx])
        assert np.array_equal(part.error_m, batch.error_m[idx])


@pytest.mark.parametrize("name", ["thumb", "index", "middle"])
@pytest.mark.parametrize("chunk", [5, 3])
def test_start_tracking_maps_what_the_grasp_reads_as_the_full_manifold(scene, name, chunk):
    # the entries a tracked manifold maps are the full manifold's, bit for bit; it maps
    # every point at the start, the points feasible there through the horizon, then
    # each while it stays usable: the same exit times from the start
    hand, _, motion, sample, _, _ = scene
    times = np.linspace(0.0, 3.0, 31)  # 0.1 s apart: chunks straddle the horizon
    f = hand.finger(name)
    margin = CONTACT.limit_margin_rad
    full = build_manifold(f, sample, motion, times, chunk=chunk)
    track = StartTracking(margin_rad=margin, all_until_s=0.75)
    part = build_manifold(f, sample, motion, times, chunk=chunk, track=track)
    # asked for: every point at the start; those feasible there through the horizon
    # (t <= 0.75 s: 8 times); after it, a point while usable at every earlier time
    start = full.feasible[0]
    assert start.any()
    usable = full.usable(margin)
    before = np.logical_and.accumulate(usable, axis=0)
    asked = np.ones_like(full.reachable)
    asked[1:] = start
    asked[8:] &= before[7:-1]
    assert asked[8:].any() and not asked[8:].all()
    assert np.array_equal(part.q[asked], full.q[asked], equal_nan=True)
    for field in ("reachable", "inside", "pad_ok", "margin_rad"):
        assert np.array_equal(getattr(part, field)[asked], getattr(full, field)[asked])
    assert np.isnan(part.q[~asked]).all() and not part.reachable[~asked].any()
    idx = np.flatnonzero(full.usable(CONTACT.choice_margin_rad)[0])
    assert np.array_equal(
        exit_times(part.usable(margin)[:, idx], times, 0),
        exit_times(usable[:, idx], times, 0),
    )


def _grid(finger: Finger, n: int) -> tuple[np.ndarray, np.ndarray]:
    """A regular grid of about n configurations over the joint box, and its steps."""
    span = finger.upper - finger.lower
    h = float((np.prod(span) / n) ** (1.0 / finger.k))
    counts = np.maximum(np.ceil(span / h).astype(int), 1) + 1
    axes = [
        np.linspace(a, b, c) for a, b, c in zip(finger.lower, finger.upper, counts, strict=True)
    ]
    q = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, finger.k)
    return q, span / (counts - 1)


def _rotation_rates(hand: Hand, finger: Finger) -> np.ndarray:
    """Per independent joint, the largest rate [rad/rad] at which it turns the tip frame:
    1 plus the |multiplier| of every joint that mimics it."""
    rates = np.ones(finger.k)
    m = hand.model
    for a, b in zip(m.mimicking_joints, m.mimicked_joints, strict=True):
        for i, jid in enumerate(finger.chain.joint_ids):
            if int(b) == int(jid):
                rates[i] += abs(m.joints[int(a)].extract().scaling)
    return rates


@pytest.mark.parametrize("name", ["thumb", "index", "little"])
def test_skipped_points_are_infeasible(scene, name):
    """Points the prefilters skip (NaN) cannot be feasible, by a dense sweep of the box.

    Any configuration is within half a grid step per joint of a grid node, so its tip
    is within ``Lp = 1.1 max|J| |h/2|`` of that node's tip and its pad within
    ``La = sum_i rate_i h_i / 2`` [rad] of the node's pad (the 10 % covers the growth
    of |J| between nodes). A feasible configuration would therefore leave a node
    within Lp of the target whose pad cosine is at least ``cos(cone) - La``; there is
    none. The IK in the real limits agrees: it fails, or its solution does not face.
    """
    hand, _, _, sample, _, manifolds = scene
    f = hand.finger(name)
    m = manifolds[name]
    q_grid, h = _grid(f, 150_000)
    p_grid, J = f.chain.positions_jacobians(q_grid)
    pads = f.pad_normals(q_grid)
    Lp = 1.1 * np.linalg.norm(J, ord=2, axis=(1, 2)).max() * np.linalg.norm(h / 2)
    La = float(_rotation_rates(hand, f) @ (h / 2))
    skipped_t, skipped_i = np.nonzero(np.isnan(m.q[..., 0]))
    assert skipped_t.size > 0
    rng = np.random.default_rng(11)
    pick = rng.choice(skipped_t.size, min(60, skipped_t.size), replace=False)
    targets = _targets(f, sample, m)
    normals = _normals_palm(sample, m)
    for j in pick:
        t, i = skipped_t[j], skipped_i[j]
        near = np.linalg.norm(p_grid - targets[t, i], axis=1) <= Lp
        facing = pads[near] @ -normals[t, i] >= CONTACT.cos_cone_of(f) - La
        assert not facing.any(), (name, t, i)
        res = f.ik(targets[t, i])
        assert not res.success[0] or _pad_cos(f, res.q, normals[t, i][None])[
            0
        ] < CONTACT.cos_cone_of(f)


@pytest.mark.parametrize("extend", [0.0, EXTEND_RAD])
def test_workspace_voxels_cover_every_reachable_tip(scene, extend):
    hand = scene[0]
    rng = np.random.default_rng(12)
    for name in hand.finger_names:
        f = hand.finger(name)
        vox = workspace_voxels(f, extend)
        q = rng.uniform(f.lower - extend, f.upper + extend, (20_000, f.k))
        assert vox.contains(f.fk(q)).all(), name
        # corners and faces of the box too (where a sampled grid is sparsest)
        corners = np.stack(
            np.meshgrid(
                *[[a, b] for a, b in zip(f.lower - extend, f.upper + extend, strict=True)],
                indexing="ij",
            ),
            -1,
        ).reshape(-1, f.k)
        assert vox.contains(f.fk(corners)).all(), name
        # and it is a cover, not everything: far points and the palm's back are out
        assert not vox.contains(np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -0.5]])).any()
        assert vox.occupied.mean() < 0.9


@pytest.mark.parametrize("hand_name", ["five_finger", "allegro"])
def test_column_norm_bounds_hold_everywhere_and_are_reached(hand_name):
    """How far a unit turn of a joint moves the tip: never more than the bound, at any
    configuration of the extended box (Jacobian columns), and the bound is nearly
    reached (a straight finger), so the cover's spacing is not wasted."""
    hand = getattr(Hand, hand_name)()
    rng = np.random.default_rng(13)
    for name in hand.finger_names:
        f = hand.finger(name)
        bound = manifold_module._column_norm_bounds(f)
        q = rng.uniform(f.lower - EXTEND_RAD, f.upper + EXTEND_RAD, (20_000, f.k))
        _, J = f.chain.positions_jacobians(q)
        norms = np.linalg.norm(J, axis=1)
        assert (norms <= bound + 1e-12).all(), name
        assert (norms.max(axis=0) >= 0.75 * bound).all(), (name, norms.max(axis=0), bound)


@pytest.mark.parametrize("hand_name", ["five_finger", "allegro"])
def test_workspace_voxels_are_a_tight_cover(hand_name):
    """Every reachable tip is in the cover, and every voxel of the cover lies near a
    reachable tip: within the dilation the docstring gives (about 10 mm with the five-finger
    hand's three joints, 22-25 mm with the Allegro's four, at the default sampling)
    plus the spacing of a dense random sample of tips (measured: 12-16 mm and 31-37 mm
    from it; the cube-shaped dilation of the cover before reached 24 mm and 62-68 mm)."""
    from scipy.spatial import cKDTree

    hand = getattr(Hand, hand_name)()
    rng = np.random.default_rng(14)
    far_mm = {"five_finger": 19.0, "allegro": 45.0}[hand_name]
    for name in hand.finger_names:
        f = hand.finger(name)
        vox = workspace_voxels(f, EXTEND_RAD)
        q = rng.uniform(f.lower - EXTEND_RAD, f.upper + EXTEND_RAD, (300_000, f.k))
        tips = f.fk(q)
        assert vox.contains(tips).all(), name
        # the centres of the sampling grid's cells, the farthest from the samples
        axes, _ = manifold_module._cover_grid(f, EXTEND_RAD, 120_000)
        mids = [0.5 * (a[:-1] + a[1:]) for a in axes]
        centres = np.stack(np.meshgrid(*mids, indexing="ij"), -1).reshape(-1, f.k)
        assert vox.contains(f.fk(centres)).all(), name
        centres = vox.origin + (np.argwhere(vox.occupied) + 0.5) * vox.voxel_m
        d, _ = cKDTree(tips).query(centres, distance_upper_bound=0.05)
        assert d.max() * 1e3 <= far_mm, (name, d.max())


@pytest.mark.parametrize("hand_name", ["five_finger", "allegro"])
def test_cover_grid_puts_every_tip_within_its_bound_of_the_nearest_sample(hand_name):
    """``_cover_grid``'s ``L``: the tip of any configuration, random or at the centre of
    a grid cell (the farthest from the samples), lies within ``L`` of the tip of the
    sample nearest to it joint by joint; and ``L`` is not loose by more than 4x."""
    hand = getattr(Hand, hand_name)()
    rng = np.random.default_rng(16)
    for name in hand.finger_names:
        f = hand.finger(name)
        axes, reach = manifold_module._cover_grid(f, EXTEND_RAD, 120_000)
        q = rng.uniform(f.lower - EXTEND_RAD, f.upper + EXTEND_RAD, (20_000, f.k))
        picks = [rng.integers(0, max(len(a) - 1, 1), 2_000) for a in axes]
        centres = np.stack(
            [
                0.5 * (a[i] + a[np.minimum(i + 1, len(a) - 1)])
                for a, i in zip(axes, picks, strict=True)
            ],
            axis=1,
        )
        q = np.vstack([q, centres])
        nearest = np.stack(
            [a[np.abs(q[:, j, None] - a[None]).argmin(axis=1)] for j, a in enumerate(axes)],
            axis=1,
        )
        gap = np.linalg.norm(f.fk(q) - f.fk(nearest), axis=1)
        assert gap.max() <= reach, (name, gap.max(), reach)
        assert gap.max() >= reach / 4, (name, gap.max(), reach)


@pytest.mark.parametrize("width", [0.0, 1e-5])
def test_workspace_voxels_of_a_locked_or_nearly_locked_joint(scene, width):
    """A joint whose range is narrower than its step takes one value, the middle, and
    leaves the samples to the others (a nearly locked joint once asked for 6e7 samples):
    the grid stays near its budget and the cover holds every reachable tip."""
    hand = scene[0]
    f = hand.finger("index")
    upper = f.upper.copy()
    upper[1] = f.lower[1] + width
    locked = dataclasses.replace(f, upper=upper)
    axes, _ = manifold_module._cover_grid(locked, 0.0, 120_000)
    assert len(axes[1]) == 1
    assert np.prod([len(a) for a in axes]) <= 2 * 120_000
    vox = manifold_module.workspace_voxels.__wrapped__(locked, 0.0)
    q = np.random.default_rng(15).uniform(locked.lower, locked.upper, (5_000, locked.k))
    assert vox.contains(locked.fk(q)).all()
    assert vox.occupied.sum() < workspace_voxels(f, 0.0).occupied.sum()


def test_pad_direction_samples_bound_every_configuration(scene):
    """``max(P @ -n) + slack >= cos(cone)`` whenever some configuration faces n.

    For random configurations q and normals n exactly at the cone's edge from q's pad
    (the hardest case for a sampled maximum), the sampled best plus the slack reaches
    cos(cone).
    """
    hand = scene[0]
    rng = np.random.default_rng(13)
    for name in hand.finger_names:
        f = hand.finger(name)
        pads, slack = pad_directions(f)
        assert 0.0 < slack <= 1.0
        q = rng.uniform(f.lower, f.upper, (500, f.k))
        d = f.pad_normals(q)
        # a unit vector at the cone's angle from d, in a random direction around it
        perp = np.cross(d, rng.normal(size=(500, 3)))
        perp /= np.linalg.norm(perp, axis=1, keepdims=True)
        a = np.radians(CONTACT.cone_deg_of(f))
        inward = np.cos(a) * d + np.sin(a) * perp  # = -n
        best = (inward @ pads.T).max(axis=1)
        assert np.all(best + slack >= CONTACT.cos_cone_of(f)), name


def test_time_index_is_the_first_grid_time_at_or_after(scene):
    m = scene[5]["index"]
    assert m.time_index(0.0) == 0
    assert m.time_index(0.25) == 1
    assert m.time_index(0.26) == 2
    assert m.time_index(2.99) == 12
    assert m.time_index(5.0) == 12


def test_a_static_object_gives_the_same_manifold_at_every_time(scene):
    hand, box, motion, sample, _, _ = scene
    T = motion.pose(0.0)
    static = ObjectMotion.from_poses([0.0, 1.0], [T, T])
    m = build_manifold(hand.finger("ring"), sample, static, np.linspace(0.0, 1.0, 4))
    for t in range(1, 4):
        assert np.array_equal(m.reachable[t], m.reachable[0])
        assert np.array_equal(m.feasible[t], m.feasible[0])
        r = m.reachable[0]
        assert_close(m.q[t][r], m.q[0][r], atol=1e-3, what="same solutions")


def test_manifold_of_a_turned_object_is_the_turned_manifold(scene):
    # turning the object about the tip target's own frame does nothing to a sphere
    # contact except turning the normals: the same points stay reachable
    hand, box, motion, sample, _, _ = scene
    f = hand.finger("middle")
    T = motion.pose(0.0)
    flip = np.eye(4)
    flip[:3, :3] = Rotation.from_euler("z", 180, degrees=True).as_matrix()
    m1 = build_manifold(f, sample, ObjectMotion.from_poses([0, 1], [T, T]), np.array([0.0]))
    T2 = T @ flip  # the box is symmetric under this half turn: the same surface
    m2 = build_manifold(f, sample, ObjectMotion.from_poses([0, 1], [T2, T2]), np.array([0.0]))
    # point i under the flip lands where its mirror j was
    p_flipped = sample.points @ flip[:3, :3].T
    j = np.array([np.argmin(np.linalg.norm(sample.points - p, axis=1)) for p in p_flipped])
    assert_close(sample.points[j], p_flipped, atol=1e-12, what="the sample is symmetric")
    assert np.array_equal(m2.feasible[0], m1.feasible[0][j])


def test_bad_times_are_rejected(scene):
    hand, _, motion, sample, _, _ = scene
    f = hand.finger("index")
    for times, word in (
        ([0.0, np.nan, 1.0], "NaN"),
        ([0.0, 1.0, 1.0], "increasing"),
        ([1.0, 0.5], "increasing"),
        ([], "empty"),
    ):
        with pytest.raises(InputError, match=word):
            build_manifold(f, sample, motion, np.array(times))
    with pytest.raises(InputError, match="outside the motion"):
        build_manifold(f, sample, motion, np.array([0.0, 4.0]))
    with pytest.raises(InputError, match="extend_rad"):
        build_manifold(f, sample, motion, np.array([0.0]), extend_rad=-0.1)


def test_a_nan_pose_cannot_make_a_motion():
    T = np.tile(np.eye(4), (2, 1, 1))
    T[1, 0, 3] = np.nan
    with pytest.raises(InputError, match="NaN"):
        ObjectMotion.from_poses([0.0, 1.0], T)


def test_fig2_draws_the_box_the_instants_p_and_q(scene):
    pytest.importorskip("matplotlib")
    from regrasp_pin.grasp.tracking import track_contact
    from regrasp_pin.plotting.manifold import plot_manifold

    hand, box, motion, sample, times, manifolds = scene
    m = manifolds["index"]
    f = hand.finger("index")
    i = int(np.flatnonzero(m.usable(0.1)[0])[0])
    track = track_contact(
        hand, "index", box, motion, times, sample.points[i], sample.normals[i], m.q[0, i]
    )
    fig = plot_manifold(m, times_idx=[0, 6, 12], track=track, q_new=f.q_mid, trigger_index=3)
    ax = fig.axes[0]
    assert "index" in ax.get_title() and "first 3" not in ax.get_title()
    labels = [t.get_text() for t in fig.legends[0].get_texts()]  # below the axes
    assert sum(lbl.startswith("manifold t =") for lbl in labels) == 3
    assert {"Q", "P's path (held)", f"trigger t = {times[3]:.2f} s"} <= set(labels)
    # P's path is drawn up to the trigger: 4 held times
    (path,) = [ln for ln in ax.get_lines() if ln.get_label() == "P's path (held)"]
    assert_close(np.radians(path.get_data_3d()[2]), track.q[:4, 2], atol=1e-12, what="path")
    # the six boundary planes, all inside the drawn limits [deg]
    fig.canvas.draw()  # 3-D collections project their paths when drawn
    assert any(len(c.get_paths()) == 6 for c in ax.collections)
    for get, j in ((ax.get_xlim, 0), (ax.get_ylim, 1), (ax.get_zlim, 2)):
        a, b = get()
        assert a < np.degrees(f.lower[j]) and np.degrees(f.upper[j]) < b
    with pytest.raises(InputError, match="times_idx"):
        plot_manifold(m, times_idx=[13])
    # from a plan: the joint path held up to the lift-off, and the joints by name
    fig = plot_manifold(m, held=(times[:5], track.q[:5]), joint_names=f.joint_names)
    ax = fig.axes[0]
    assert ax.get_xlabel() == f"{f.joint_names[0]} [deg]"
    assert ax.get_zlabel() == f"{f.joint_names[2]} [deg]"
    labels = [t.get_text() for t in fig.legends[0].get_texts()]
    assert f"lift-off t = {times[4]:.2f} s" in labels
    (path,) = [ln for ln in ax.get_lines() if ln.get_label() == "P's path (held)"]
    assert_close(np.radians(path.get_data_3d()[0]), track.q[:5, 0], atol=1e-12, what="held")
    with pytest.raises(InputError, match="joint_names"):
        plot_manifold(m, joint_names=["a", "b"])
    # a finger with more joints is drawn in its first three, and says so
    k4 = dataclasses.replace(
        m,
        q=np.concatenate([m.q, m.q[..., :1]], axis=2),
        lower=np.append(m.lower, 0.0),
        upper=np.append(m.upper, 1.0),
    )
    assert "first 3 of its 4 joints" in plot_manifold(k4).axes[0].get_title()
    import matplotlib.pyplot as plt

    plt.close("all")


def test_margins_and_outside_test_equal_the_vector_formulas():
    # joint by joint with scalar limits: the same values as the vector formulas
    from regrasp_pin.grasp.manifold import _margins, _outside

    rng = np.random.default_rng(25)
    lower, upper = np.array([-0.3, -0.2, 0.0]), np.array([0.3, 1.5, 1.6])
    q = rng.uniform(-0.6, 1.9, (7, 50, 3))
    q[:, ::4] = np.nan
    ref = np.minimum(q - lower, upper - q).min(axis=-1)
    assert np.array_equal(_margins(q, lower, upper), ref, equal_nan=True)
    flat = q.reshape(-1, 3)
    assert np.array_equal(
        _outside(flat, lower, upper), np.any((flat < lower) | (flat > upper), axis=1)
    )


def test_first_time_solves_are_remembered_and_copied(scene, monkeypatch):
    """A second manifold of the same surface at the same first pose reuses the first
    time's cold IK (no solve with restarts) and equals the first, bit for bit; the
    remembered result is not changed by the builds that use it; another IK backend or
    forget_first_times solves it again."""
    hand, _, motion, sample = scene[:4]
    f = hand.finger("index")
    times = np.linspace(0.0, 1.0, 6)
    forget_first_times()
    first = build_manifold(f, sample, motion, times)
    restarts = []
    real = manifold_module.solve_position_ik
    monkeypatch.setattr(
        manifold_module,
        "solve_position_ik",
        lambda *a, **k: restarts.append(k["restarts"]) or real(*a, **k),
    )
    for _ in range(2):
        again = build_manifold(f, sample, motion, times)
        assert not any(restarts)
        for field in ("q", "reachable", "inside", "pad_ok", "margin_rad"):
            assert np.array_equal(getattr(again, field), getattr(first, field), equal_nan=True)
    # another IK backend (its iterates differ in the last bits): solved again
    monkeypatch.setattr(manifold_module, "ik_backend", lambda: "another")
    build_manifold(f, sample, motion, times)
    assert any(restarts)
    restarts.clear()
    forget_first_times()
    monkeypatch.undo()
    monkeypatch.setattr(
        manifold_module,
        "solve_position_ik",
        lambda *a, **k: restarts.append(k["restarts"]) or real(*a, **k),
    )
    build_manifold(f, sample, motion, times)
    assert any(restarts)


FIELDS = ("q", "reachable", "inside", "pad_ok", "margin_rad", "tip_clear")


@pytest.mark.parametrize("threads", [1, 2, 5])
def test_fingers_mapped_on_threads_are_the_fingers_mapped_one_by_one(scene, threads):
    """build_manifolds on any number of threads returns, in the order asked, each
    finger's build_manifold bit for bit (each finger's manifold is its own)."""
    hand, _, motion, sample, times, manifolds = scene
    names = ["ring", "thumb", "index", "little", "middle"]
    got = build_manifolds(hand, names, sample, motion, times, threads=threads)
    assert list(got) == names
    for n in names:
        for field in FIELDS:
            a, b = getattr(got[n], field), getattr(manifolds[n], field)
            assert np.array_equal(a, b, equal_nan=True), (n, field)


def test_thread_counts_come_from_the_argument_or_the_environment(scene, monkeypatch):
    hand, _, motion, sample, times, _ = scene
    for bad in (0, -1, 1.5, True):
        with pytest.raises(InputError, match="threads"):
            build_manifolds(hand, ["index"], sample, motion, times, threads=bad)
    with pytest.raises(UnknownNameError, match="little_finger"):
        build_manifolds(hand, ["index", "little_finger"], sample, motion, times)
    monkeypatch.setenv(THREADS_ENV, "3")
    assert default_threads() == 3
    for bad in ("0", "two", "-2"):
        monkeypatch.setenv(THREADS_ENV, bad)
        with pytest.raises(InputError, match=THREADS_ENV):
            default_threads()
    monkeypatch.delenv(THREADS_ENV)
    monkeypatch.setattr(manifold_module, "ik_backend", lambda: "numpy")
    assert default_threads() == 1  # threads only contend for the GIL with numpy
    monkeypatch.setattr(manifold_module, "ik_backend", lambda: "numba")
    monkeypatch.setattr(manifold_module.os, "cpu_count", lambda: 4)
    assert default_threads() == 4
