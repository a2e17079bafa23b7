"""Tests of the new-contact choice and the initial grasp (regrasp_pin.grasp.choice).

Scenes (palm frame):

* five-finger hand, box 40 x 60 x 40 mm at (65, 0, 60) mm turning about the palm y
  axis through its centre at 30 deg/s for 3 s (thumb on the -x face, the fingers on
  the +x face); surface every 4 mm, manifolds on 13 times (every 0.25 s).
* Allegro hand (fingers along +z of its palm, flexing toward +x), box 40 x 80 x 40 mm
  at (100, 20, 20) mm turning about the palm z axis through its centre at 20 deg/s for
  1 s (thumb on the -z face, the fingers curled onto the +z face); surface every 6 mm,
  manifolds on 5 times.

The choice of Q is checked against a brute force written here from the paper's rules
and the manifold's joint coordinates (not its masks): condition (a) at arrival, the
exit time by a loop over the remaining times, the order (exit time, then margin, then
distance from P), and the grasp tests (force closure with the others, links clear of
the box by Pinocchio's ``computeDistances``, quality kept).
"""

from __future__ import annotations

import dataclasses
import itertools
import re
from types import SimpleNamespace

import coal
import numpy as np
import pinocchio as pin
import pytest
from conftest import assert_close
from hypothesis import given, settings
from hypothesis import strategies as st

from regrasp_pin.exceptions import ContactError, FailureKind, InputError
from regrasp_pin.grasp import screening as screening_module
from regrasp_pin.grasp.choice import (
    DISTANCE_TOL_M,
    TIP_GAP_M,
    Room,
    _apart_from,
    _far_from,
    _link_exit,
    _Ranking,
    _rerank,
    _Screen,
    choose_new_contact,
    exit_times,
)
from regrasp_pin.grasp.contact import ContactModel, tip_targets
from regrasp_pin.grasp.initial import (
    _grasp_score,
    _spread_out,
    _start_candidates,
    _too_close,
    initial_grasp,
)
from regrasp_pin.grasp.manifold import Manifold, build_manifold
from regrasp_pin.grasp.necessity import MustHold
from regrasp_pin.grasp.quality import (
    EPSILON_RTOL,
    FORCE_CLOSURE_TOL,
    ferrari_canny_epsilon,
    is_force_closure,
)
from regrasp_pin.grasp.screening import (
    BOUND_MARGIN_M,
    HELD_FIRST_RUN,
    SCREEN_EDGES,
    ManifoldClearance,
    ScreeningEpsilons,
    closest_object_miss,
    held_clear,
    passes_object_clearance,
)
from regrasp_pin.model.clearance import FingerClearance, LinkClearance
from regrasp_pin.model.hand import Hand
from regrasp_pin.model.motion import ObjectMotion
from regrasp_pin.model.objects import Box

CONTACT = ContactModel()
MU = 0.8
SEP_M = 0.018  # passed explicitly: > 2 tip radii (16 mm) of the five-finger hand


def _twist(position, size, axis, rate_deg_s, duration_s):
    box = Box(size)
    T0 = np.eye(4)
    T0[:3, 3] = position
    motion = ObjectMotion.constant_twist(
        T0,
        axis_palm=axis,
        point_palm=T0[:3, 3],
        rate_rad_s=np.radians(rate_deg_s),
        duration_s=duration_s,
        dt_s=0.05,
    )
    return box, motion


@pytest.fixture(scope="module")
def five():
    hand = Hand.five_finger()
    box, motion = _twist((0.065, 0.0, 0.06), (0.04, 0.06, 0.04), (0, 1, 0), 30.0, 3.0)
    sample = box.sample_surface(0.004)
    times = np.linspace(0.0, 3.0, 13)
    manifolds = {
        n: build_manifold(hand.finger(n), sample, motion, times) for n in hand.finger_names
    }
    # all five fingers on a 60 mm face: they may start 1 mm apart (not the default)
    grasp = initial_grasp(
        hand, box, manifolds, sample, mu=MU, min_separation_m=SEP_M, min_finger_gap_m=0.001
    )
    return hand, box, motion, sample, manifolds, grasp


@pytest.fixture(scope="module")
def allegro():
    hand = Hand.allegro()
    box, motion = _twist((0.1, 0.02, 0.02), (0.04, 0.08, 0.04), (0, 0, 1), 20.0, 1.0)
    sample = box.sample_surface(0.006)
    times = np.linspace(0.0, 1.0, 5)
    manifolds = {
        n: build_manifold(hand.finger(n), sample, motion, times) for n in hand.finger_names
    }
    grasp = initial_grasp(hand, box, manifolds, sample, mu=MU)
    return hand, box, motion, sample, manifolds, grasp


def _link_distance(hand, finger, box, q_finger, T_palm_object, tip=False) -> float:
    """Pinocchio computeDistances: the finger's non-tip geometries (``tip``: its
    fingertip link's geometries) against the box."""
    f = hand.finger(finger)
    gm = pin.GeometryModel()
    for g in hand.collision_model.geometryObjects:
        gm.addGeometryObject(pin.GeometryObject(g))
    placement = pin.SE3(T_palm_object[:3, :3], T_palm_object[:3, 3])
    oid = gm.addGeometryObject(pin.GeometryObject("box", 0, placement, box.coal_geometry()))
    for g in f.geometry_ids:
        if (g in f.tip_geometry_ids) == tip:
            gm.addCollisionPair(pin.CollisionPair(int(g), oid))
    gdata = pin.GeometryData(gm)
    q_full = hand.to_full(finger, q_finger)
    pin.computeDistances(hand.model, hand.model.createData(), gm, gdata, q_full)
    return min(r.min_distance for r in gdata.distanceResults)


def _finger_distance(hand, names, q_fingers) -> float:
    """Pinocchio computeDistances: smallest distance between the named fingers' geometries
    (the other fingers at the neutral configuration play no part)."""
    gm = pin.GeometryModel()
    for g in hand.collision_model.geometryObjects:
        gm.addGeometryObject(pin.GeometryObject(g))
    for a_name, b_name in itertools.combinations(names, 2):
        for a in hand.finger(a_name).geometry_ids:
            for b in hand.finger(b_name).geometry_ids:
                gm.addCollisionPair(pin.CollisionPair(int(a), int(b)))
    gdata = pin.GeometryData(gm)
    q = hand.neutral()
    for n in names:
        q[hand.finger(n).q_indices] = q_fingers[n]
    pin.computeDistances(hand.model, hand.model.createData(), gm, gdata, q)
    return min(r.min_distance for r in gdata.distanceResults)


def _usable_direct(hand, finger, manifold, sample, t, i, margin_rad) -> bool:
    """Feasible with a margin, from the manifold's joint coordinates alone."""
    f = hand.finger(finger)
    q = manifold.q[t, i]
    if np.isnan(q).any():
        return False
    T = manifold.T_palm_object[t]
    target = T[:3, :3] @ (sample.points[i] + f.tip_radius * sample.normals[i]) + T[:3, 3]
    if np.linalg.norm(f.fk(q) - target) > CONTACT.ik_tol_m:
        return False
    if min(np.min(q - f.lower), np.min(f.upper - q)) < margin_rad:
        return False
    R, _ = f.tip_poses(q)
    return float((R @ f.pad_axis_tip) @ -(T[:3, :3] @ sample.normals[i])) >= CONTACT.cos_cone_of(f)


def _tip_clear_direct(hand, finger, manifold, sample, t, i) -> bool:
    """The fingertip link's geometries do not cross the plane on which the tip sphere
    rests (Pinocchio computeDistances against a Coal half-space) by more than the
    tolerance: inside a face, they do not sink into it."""
    f = hand.finger(finger)
    T = manifold.T_palm_object[t]
    n_out = T[:3, :3] @ sample.normals[i]
    contact_palm = T[:3, :3] @ sample.points[i] + T[:3, 3]
    gm = pin.GeometryModel()
    for g in hand.collision_model.geometryObjects:
        gm.addGeometryObject(pin.GeometryObject(g))
    plane = coal.Halfspace(n_out, float(n_out @ contact_palm))  # the object's side
    oid = gm.addGeometryObject(pin.GeometryObject("plane", 0, pin.SE3.Identity(), plane))
    for g in f.tip_geometry_ids:
        gm.addCollisionPair(pin.CollisionPair(int(g), oid))
    gdata = pin.GeometryData(gm)
    q_full = hand.to_full(finger, manifold.q[t, i])
    pin.computeDistances(hand.model, hand.model.createData(), gm, gdata, q_full)
    return min(r.min_distance for r in gdata.distanceResults) >= -CONTACT.tip_penetration_m


# ------------------------------------------------------------------ exit times
@settings(max_examples=60, deadline=None, derandomize=True)
@given(
    st.integers(1, 8),
    st.integers(1, 6),
    st.integers(0, 7),
    st.integers(0, 2**32 - 1),
)
def test_exit_times_against_a_loop(nt, n, start, seed):
    start = min(start, nt - 1)
    rng = np.random.default_rng(seed)
    usable = rng.random((nt, n)) < 0.7
    times = np.cumsum(rng.uniform(0.1, 1.0, nt))
    got = exit_times(usable, times, start)
    for i in range(n):
        expected = times[-1]  # usable to the end
        for t in range(start, nt):
            if not usable[t, i]:
                expected = times[t]
                break
        assert got[i] == expected


# ------------------------------------------------------------------ grasp quality
def test_force_closure_on_the_box():
    box = Box((0.04, 0.06, 0.04))
    scale = box.radius_m
    one = (np.array([[0.02, 0.0, 0.0]]), np.array([[1.0, 0.0, 0.0]]))
    assert ferrari_canny_epsilon(*one, MU, torque_scale_m=scale) == 0.0
    # thumb on -x opposite three fingers spread on +x
    p = np.array([[-0.02, 0.0, 0.0], [0.02, 0.015, 0.01], [0.02, 0.0, -0.01], [0.02, -0.015, 0.01]])
    n = np.array([[-1.0, 0, 0], [1.0, 0, 0], [1.0, 0, 0], [1.0, 0, 0]])
    assert is_force_closure(p, n, MU, torque_scale_m=scale)
    assert ferrari_canny_epsilon(p, n, MU, n_edges=SCREEN_EDGES, torque_scale_m=scale) > 0.01
    # without friction, or all on one face, nothing holds
    assert not is_force_closure(p, n, 0.0, torque_scale_m=scale)
    assert not is_force_closure(p[1:], n[1:], MU, torque_scale_m=scale)
    # an antipodal pinch holds with torsional (soft-finger) friction, not with points
    pinch = (p[[0, 2]] * [1, 0, 0], n[[0, 2]])
    assert not is_force_closure(*pinch, MU, torque_scale_m=scale)
    assert is_force_closure(*pinch, MU, torque_scale_m=scale, torsion_m=0.005)


# ------------------------------------------------------------------ initial grasp
def _check_grasp(hand, box, sample, manifolds, grasp, min_sep):
    names = list(manifolds)
    assert list(grasp.points_object) == names
    assert list(grasp.indices) == names and all(type(k) is str for k in grasp.indices)
    pts = np.array([grasp.points_object[n] for n in names])
    nrm = np.array([grasp.normals_object[n] for n in names])
    for name in names:
        i = grasp.indices[name]
        assert_close(grasp.points_object[name], sample.points[i], atol=0.0, what="sample")
        assert_close(grasp.normals_object[name], sample.normals[i], atol=0.0, what="normal")
    # on the surface, with the normal of the face it lies on
    assert_close(box.signed_distance(pts), np.zeros(len(names)), atol=1e-12, what="surface")
    assert_close(nrm, box.normals[box.supporting_face(pts)], atol=1e-12, what="face normal")
    # feasible at t = 0 with the choice margin
    for name in names:
        f = hand.finger(name)
        T = manifolds[name].T_palm_object[0]
        q = grasp.q[name]
        target = tip_targets(
            grasp.points_object[name][None], grasp.normals_object[name][None], f.tip_radius, T
        )[0]
        assert np.linalg.norm(f.fk(q) - target) <= CONTACT.ik_tol_m, name
        assert f.limit_margin(q)[0] >= CONTACT.choice_margin_rad, name
        R, _ = f.tip_poses(q)
        assert (R @ f.pad_axis_tip) @ -(T[:3, :3] @ grasp.normals_object[name]) >= (
            CONTACT.cos_cone_of(f)
        ), name
        d = _link_distance(hand, name, box, q, T)
        assert d >= CONTACT.choice_link_clearance_m, (name, d)
        d_tip = _link_distance(hand, name, box, q, T, tip=True)
        assert d_tip >= -CONTACT.tip_penetration_m, (name, d_tip)
    # pairwise separated: the tip spheres never overlap
    gaps = np.linalg.norm(pts[:, None] - pts[None], axis=2)[np.triu_indices(len(names), 1)]
    assert gaps.min() >= min_sep
    # the grasping fingers' links keep 1 mm from each other (Pinocchio computeDistances)
    assert _finger_distance(hand, names, grasp.q) >= 0.001 - 1e-9
    # force closure, the quality recomputed
    eps = ferrari_canny_epsilon(pts, nrm, MU, torque_scale_m=box.radius_m)
    assert grasp.epsilon > 0.0
    assert_close(grasp.epsilon, eps, atol=1e-12, what="epsilon")


def test_initial_grasp_on_the_five_finger_hand(five):
    hand, box, _, sample, manifolds, grasp = five
    _check_grasp(hand, box, sample, manifolds, grasp, SEP_M)
    # the thumb opposes fingers on the opposite face (others may hold the side faces
    # with their fingertips' ends: the pad cone is the tip sphere's front hemisphere)
    n = grasp.normals_object
    assert min(n["thumb"] @ n[f] for f in n if f != "thumb") < -0.99


def test_initial_grasp_on_the_allegro_hand(allegro):
    hand, box, _, sample, manifolds, grasp = allegro
    r = max(f.tip_radius for f in hand.fingers.values())
    _check_grasp(hand, box, sample, manifolds, grasp, 2 * r)
    assert grasp.normals_object["thumb"] @ grasp.normals_object["middle"] < -0.99


def test_initial_fingers_stay_apart_over_the_first_second(allegro):
    # default gap: the proximity trigger + 0.5 mm, at every manifold time of the first
    # 1 s (all five here) where both fingers still reach their contacts
    hand, _, _, _, manifolds, grasp = allegro
    need = CONTACT.finger_trigger_m + 0.0005
    for a, b in itertools.combinations(grasp.indices, 2):
        for k in range(manifolds[a].times_s.size):
            qa, qb = manifolds[a].q[k, grasp.indices[a]], manifolds[b].q[k, grasp.indices[b]]
            if np.isfinite(qa).all() and np.isfinite(qb).all():
                d = _finger_distance(hand, [a, b], {a: qa, b: qb})
                assert d >= need - 1e-9, (a, b, manifolds[a].times_s[k], d)


def test_initial_grasp_lets_fingers_go(five):
    # the search favours grasps from which a finger can be lifted with the rest still
    # holding: some leave-one-out subsets are in force closure
    _, box, _, _, _, grasp = five
    names = list(grasp.points_object)
    pts = np.array([grasp.points_object[n] for n in names])
    nrm = np.array([grasp.normals_object[n] for n in names])
    held = [
        is_force_closure(
            np.delete(pts, j, 0), np.delete(nrm, j, 0), MU, torque_scale_m=box.radius_m
        )
        for j in range(len(names))
    ]
    assert sum(held) >= 2


def test_initial_grasp_is_seeded(five):
    hand, box, _, sample, manifolds, grasp = five
    again = initial_grasp(
        hand, box, manifolds, sample, mu=MU, min_separation_m=SEP_M, min_finger_gap_m=0.001
    )
    assert again.indices == grasp.indices


def test_initial_grasp_keeps_the_highest_rank_then_the_best_score(five):
    hand, box, _, sample, manifolds, grasp = five
    kw = dict(mu=MU, min_separation_m=SEP_M, min_finger_gap_m=0.001)
    # a constant rank leaves the score alone to decide: the unranked grasp, or one
    # that the one-finger-at-a-time climb improved to a higher score
    flat = initial_grasp(hand, box, manifolds, sample, rank=lambda pick: (0,), **kw)
    frac = {}
    for n, m in manifolds.items():
        idx, fr = _start_candidates(hand, box, m, sample.points, 0, CONTACT, 40)
        frac[n] = dict(zip(idx.tolist(), fr.tolist(), strict=True))

    def score(g):
        ii = [g.indices[n] for n in manifolds]
        fracs = [frac[n][g.indices[n]] for n in manifolds]
        return _grasp_score(sample.points[ii], sample.normals[ii], fracs, MU, box.radius_m)[0]

    assert score(flat) >= score(grasp)
    assert flat.indices == grasp.indices or score(flat) > score(grasp)
    seen = {}

    def rank(pick):
        # the index's contacts far from the unranked grasp's rank higher, then the
        # middle's far from it (two integers, compared in order)
        r = tuple(
            int(np.linalg.norm(sample.points[pick[n]] - grasp.points_object[n]) * 1e3) // 5
            for n in ("index", "middle")
        )
        key = tuple(sorted(pick.items()))
        assert key not in seen, "each combination is ranked once"
        seen[key] = r
        return r

    ranked = initial_grasp(hand, box, manifolds, sample, rank=rank, **kw)
    assert seen[tuple(sorted(grasp.indices.items()))] == (0, 0)
    kept = seen[tuple(sorted(ranked.indices.items()))]
    assert kept == max(seen.values()) and kept > (0, 0)
    assert len(seen) > 1
    _check_grasp(hand, box, sample, manifolds, ranked, SEP_M)


def test_grasps_with_fingers_too_close_are_refused_with_the_closest_distance(five):
    hand, box, _, sample, manifolds, grasp = five
    names = list(manifolds)
    d = _finger_distance(hand, names, grasp.q)
    # ask for more than any grasp of this box offers: refused, with the best found
    with pytest.raises(ContactError) as info:
        initial_grasp(
            hand, box, manifolds, sample, mu=MU, min_separation_m=SEP_M, min_finger_gap_m=0.2
        )
    err = info.value
    assert err.kind == FailureKind.FINGER_COLLISION and err.required == 0.2
    assert d - 1e-9 <= err.measured < 0.2  # at least as far apart as the chosen grasp
    # the two fingers of the closest refusal are named, in the message too
    assert {err.finger, err.other} <= set(names) and err.finger != err.other
    assert f"{err.finger} and {err.other} {err.measured * 1e3:.3f} mm apart" in str(err)


def test_grasps_refused_by_the_callers_finger_clearance_say_so(five):
    hand, box, _, sample, manifolds, _ = five
    calls = []

    def never(q_fingers):  # a caller's clearance that refuses every grasp
        calls.append(q_fingers)
        return -1.0

    with pytest.raises(ContactError) as info:
        initial_grasp(hand, box, manifolds, sample, mu=MU, finger_clearance=never)
    err = info.value
    # every complete grasp it was asked about is counted as refused by it, beside the
    # combination search's own closest refusal (this scene has some)
    assert err.kind == FailureKind.FINGER_COLLISION
    assert f"; finger_clearance refused {len(calls)})" in str(err) and calls
    assert {err.finger, err.other} <= set(manifolds) and err.measured < err.required
    # refused by it alone: no pair, no numbers
    alone = _too_close(SimpleNamespace(closest_pair=lambda: None, refused=4), 4, 0.002)
    assert str(alone).endswith(
        "every grasp tried (4) puts two fingers too close (finger_clearance refused 4)"
    )
    assert (alone.finger, alone.other, alone.measured, alone.required) == (None,) * 4


def test_no_initial_grasp_names_the_finger(five):
    hand, box, _, sample, manifolds, _ = five
    impossible = dataclasses.replace(CONTACT, choice_margin_rad=10.0)
    with pytest.raises(ContactError, match="finger 'thumb'.*t=0.000 s") as info:
        initial_grasp(hand, box, manifolds, sample, contact=impossible)
    assert info.value.finger == "thumb" and info.value.time_s == 0.0


# ------------------------------------------------------------------ the new contact Q
def _exit_index_direct(hand, name, manifold, sample, ka, i, contact):
    """The first manifold time from ``ka`` at which point ``i`` is not usable or its
    fingertip link crosses the plane the tip rests on (the number of times if neither
    happens before the end), tested time by time."""
    nt = manifold.times_s.size
    for t in range(ka, nt):
        if not _usable_direct(hand, name, manifold, sample, t, i, contact.limit_margin_rad):
            return t
        if not _tip_clear_direct(hand, name, manifold, sample, t, i):
            return t
    return nt


def _removable(other_p, other_n, p, n, scale_m):
    """How many of the other contacts could let go with ``(p, n)`` landed, the rest in
    force closure (written out: one screening epsilon per contact left out)."""
    k = len(other_p)
    if k < 3:
        return 0
    return sum(
        ferrari_canny_epsilon(
            np.vstack([np.delete(other_p, w, 0), p]),
            np.vstack([np.delete(other_n, w, 0), n]),
            MU,
            n_edges=SCREEN_EDGES,
            torque_scale_m=scale_m,
        )
        > FORCE_CLOSURE_TOL
        for w in range(k)
    )


def _brute_force_q(hand, box, manifold, sample, ka, P, n_P, others, contact=CONTACT, kb=None):
    """The paper's rules plus the grasp tests, written out candidate by candidate; the
    landing lies between manifold times ``kb`` and ``ka`` (default: at ``ka``)."""
    name = manifold.finger
    other_p = np.array([p for p, _ in others.values()])
    other_n = np.array([n for _, n in others.values()])
    rows = []
    for i in range(len(sample)):
        if not all(
            _usable_direct(hand, name, manifold, sample, k, i, contact.choice_margin_rad)
            for k in {ka, ka if kb is None else kb}
        ):
            continue
        if np.min(np.linalg.norm(other_p - sample.points[i], axis=1)) < SEP_M:
            continue
        exit_index = _exit_index_direct(hand, name, manifold, sample, ka, i, contact)
        q = manifold.q[ka, i]
        f = hand.finger(name)
        margin = min(np.min(q - f.lower), np.min(f.upper - q))
        rows.append((-exit_index, -margin, float(np.linalg.norm(sample.points[i] - P)), i))
    rows.sort()

    def eps(p, n):
        return ferrari_canny_epsilon(
            np.vstack([other_p, p]),
            np.vstack([other_n, n]),
            MU,
            n_edges=SCREEN_EDGES,
            torque_scale_m=box.radius_m,
        )

    def removable(p, n):  # other contacts that could let go with (p, n) landed
        return _removable(other_p, other_n, p, n, box.radius_m)

    eps_P = eps(P, n_P)
    passing = []
    for rank, (neg_exit, _, _, i) in enumerate(rows):
        e = eps(sample.points[i], sample.normals[i])
        if e <= FORCE_CLOSURE_TOL:
            continue
        q_i, T_i = manifold.q[ka, i], manifold.T_palm_object[ka]
        if _link_distance(hand, name, box, q_i, T_i) < contact.choice_link_clearance_m:
            continue
        if _link_distance(hand, name, box, q_i, T_i, tip=True) < -contact.tip_penetration_m:
            continue
        passing.append((rank, i, -neg_exit, e))
    counts = [removable(sample.points[c[1]], sample.normals[c[1]]) for c in passing]
    most = len(other_p) if len(other_p) >= 3 else 0
    return _window_choice(passing, counts, eps_P, most), rows, passing, eps_P


def _window_choice(passing, counts, eps_P, most):
    """Among the first 4 candidates that pass (fewer if one lets every other finger go
    and keeps the quality): most fingers that could let go, then quality kept, then rank."""
    window = []
    for c, r in zip(passing, counts, strict=True):
        kept = c[3] >= eps_P - EPSILON_RTOL * max(abs(eps_P), 1e-12)  # equal counts as kept
        window.append((r, kept, -c[0], c))
        if (r == most and kept) or len(window) == 4:
            break
    return max(window, key=lambda w: w[:3])[3] if window else None


def _choose_from_grasp(five, finger, t_arrive, **kwargs):
    """choose_new_contact for ``finger`` of the fixture's grasp, the others holding."""
    hand, box, _, sample, manifolds, grasp = five
    others = {
        n: (grasp.points_object[n], grasp.normals_object[n])
        for n in grasp.points_object
        if n != finger
    }
    return choose_new_contact(
        hand,
        box,
        manifolds[finger],
        sample,
        t_arrive,
        P_object=grasp.points_object[finger],
        n_P_object=grasp.normals_object[finger],
        others=others,
        mu=MU,
        min_separation_m=SEP_M,
        **kwargs,
    )


@pytest.mark.parametrize(
    "finger, t_arrive",
    [("middle", 1.25), ("little", 1.0), ("thumb", 0.75), ("thumb", 1.15), ("little", 1.15)],
)
def test_q_stays_inside_longest_by_brute_force(five, finger, t_arrive):
    # 1.15 s falls between manifold times (every 0.25 s): Q must be usable at
    # both neighbours (there, the first choice usable at the later one only is not)
    hand, box, _, sample, manifolds, grasp = five
    m = manifolds[finger]
    P, n_P = grasp.points_object[finger], grasp.normals_object[finger]
    others = {
        n: (grasp.points_object[n], grasp.normals_object[n])
        for n in grasp.points_object
        if n != finger
    }
    # the paper's order exactly (the re-rank by the finger's links is tested below)
    q = _choose_from_grasp(five, finger, t_arrive, max_checks=10_000, rerank=0)
    ka = m.time_index(t_arrive)
    kb = int(np.flatnonzero(m.times_s <= t_arrive + 1e-9)[-1])
    expected, rows, passing, eps_P = _brute_force_q(hand, box, m, sample, ka, P, n_P, others, kb=kb)
    rank, i, exit_index, e = expected
    assert q.index == i and q.rank == rank
    assert q.n_candidates == len(rows)
    exit_time = m.times_s[min(exit_index, m.times_s.size - 1)]
    assert q.exit_time_s == pytest.approx(exit_time)
    assert q.t_arrive_s == pytest.approx(m.times_s[ka])
    # Q is one of the first four candidates that pass, in the order of condition (b)
    assert q.rank in [p[0] for p in passing[:4]]
    # the reported numbers
    assert_close(q.p_object, sample.points[i], atol=0.0, what="Q")
    assert_close(q.q_arrive, m.q[ka, i], atol=0.0, what="q at arrival")
    assert q.distance_from_P_m == pytest.approx(np.linalg.norm(sample.points[i] - P))
    assert q.epsilon == pytest.approx(e) and q.epsilon > 0
    assert q.epsilon_with_P == pytest.approx(eps_P)
    assert q.quality_kept == (q.epsilon >= eps_P - EPSILON_RTOL * max(abs(eps_P), 1e-12))
    assert q.margin_rad >= CONTACT.choice_margin_rad
    # Q is far enough from every other contact
    for p_other, _ in others.values():
        assert np.linalg.norm(q.p_object - p_other) >= SEP_M


def test_q_lets_more_fingers_go_among_the_first_that_pass():
    """Among the first candidates that pass, the one after which most of the other
    fingers could let go is taken, whatever its rank (leave-one-out epsilons)."""
    hand = Hand.five_finger()
    finger = hand.finger("little")
    box = Box((0.04, 0.06, 0.04))
    sample = box.sample_surface(0.01)
    pts, nrm = sample.points, sample.normals
    top = int(np.flatnonzero(nrm[:, 2] > 0.99)[0])
    bottom = int(np.flatnonzero(nrm[:, 2] < -0.99)[0])
    side = int(np.flatnonzero(nrm[:, 0] > 0.99)[0])
    others = {
        n: (pts[i], nrm[i]) for n, i in zip(("a", "b", "c"), (top, bottom, side), strict=True)
    }
    op, on = (
        np.array([pts[top], pts[bottom], pts[side]]),
        np.array([nrm[top], nrm[bottom], nrm[side]]),
    )

    def eps(p, n):
        return ferrari_canny_epsilon(
            np.vstack([op, p]),
            np.vstack([on, n]),
            MU,
            n_edges=SCREEN_EDGES,
            torque_scale_m=box.radius_m,
        )

    def removable(i):
        return _removable(op, on, pts[i], nrm[i], box.radius_m)

    closing = [
        i for i in range(len(sample)) if i not in (top, bottom, side) and eps(pts[i], nrm[i]) > 0
    ]
    counts = {i: removable(i) for i in closing}
    low = min(closing, key=lambda i: (counts[i], i))
    high = max(closing, key=lambda i: (counts[i], -i))
    assert counts[low] < counts[high]  # the scene offers a choice
    n_t, n = 2, len(sample)
    manifold = Manifold(
        finger="little",
        times_s=np.array([0.0, 1.0]),
        q=np.zeros((n_t, n, finger.k)),
        reachable=np.ones((n_t, n), bool),
        inside=np.ones((n_t, n), bool),
        margin_rad=np.full((n_t, n), 0.2),
        pad_ok=np.ones((n_t, n), bool),
        lower=finger.lower,
        upper=finger.upper,
        T_palm_object=np.tile(np.eye(4), (n_t, 1, 1)),
    )
    screen = _Screen(hand, finger, box, manifold, sample, 0, others, MU, None, CONTACT, None, 0.0)
    idx = np.array([low, high])
    ranked = _Ranking(np.ones(2), np.full(2, 0.2), np.zeros(2), idx, 0.0)
    P = np.array([0.0, 0.0, 0.02])  # the contact let go, on the top face
    chosen = screen.first(np.array([0, 1]), ranked, P, np.array([0.0, 0.0, 1.0]), 60)
    assert chosen.index == high and chosen.rank == 1  # taken from second place
    # outside the window of passing candidates the rank decides
    screen.window = 1
    assert screen.first(np.array([0, 1]), ranked, P, np.array([0.0, 0.0, 1.0]), 60).index == low


def test_q_skips_candidates_whose_links_touch(five):
    # demand more link clearance than the paper's first choice has: Q moves down the
    # order of condition (b) to the first candidate that passes every test
    hand, box, _, sample, manifolds, grasp = five
    finger, t_arrive = "ring", 1.25
    m = manifolds[finger]
    ka = m.time_index(t_arrive)
    P, n_P = grasp.points_object[finger], grasp.normals_object[finger]
    others = {
        n: (grasp.points_object[n], grasp.normals_object[n])
        for n in grasp.points_object
        if n != finger
    }
    _, rows, _, _ = _brute_force_q(hand, box, m, sample, ka, P, n_P, others)
    first = rows[0][3]
    d_first = _link_distance(hand, finger, box, m.q[ka, first], m.T_palm_object[ka])
    strict = dataclasses.replace(CONTACT, choice_link_clearance_m=d_first + 1e-4)
    q = choose_new_contact(
        hand,
        box,
        m,
        sample,
        t_arrive,
        P_object=P,
        n_P_object=n_P,
        others=others,
        contact=strict,
        mu=MU,
        min_separation_m=SEP_M,
        max_checks=10_000,
    )
    (rank, i, _, _), _, _, _ = _brute_force_q(hand, box, m, sample, ka, P, n_P, others, strict)
    assert q.rank == rank >= 1 and q.index == i
    assert _link_distance(hand, finger, box, q.q_arrive, m.T_palm_object[ka]) > d_first
    # candidates whose links touch do not use up the checks: one check is enough when
    # the first candidate whose links clear the object passes the other tests
    lean = dataclasses.replace(CONTACT, choice_link_clearance_m=d_first + 1e-4)
    kwargs = dict(P_object=P, n_P_object=n_P, others=others, contact=lean, mu=MU)
    first_clear = choose_new_contact(
        hand, box, m, sample, t_arrive, min_separation_m=SEP_M, max_checks=1, **kwargs
    )
    assert first_clear.index == q.index


def test_ties_within_an_exit_tolerance_prefer_the_shorter_move(five):
    hand, box, _, sample, manifolds, grasp = five
    m = manifolds["middle"]
    P, n_P = grasp.points_object["middle"], grasp.normals_object["middle"]
    others = {
        n: (grasp.points_object[n], grasp.normals_object[n])
        for n in grasp.points_object
        if n != "middle"
    }
    kw = dict(
        P_object=P, n_P_object=n_P, others=others, mu=MU, min_separation_m=SEP_M, max_checks=10_000
    )
    exact = choose_new_contact(hand, box, m, sample, 1.25, **kw)
    loose = choose_new_contact(hand, box, m, sample, 1.25, exit_tolerance_s=10.0, **kw)
    # with every exit time tied, the nearest candidate that passes the tests wins
    assert loose.distance_from_P_m <= exact.distance_from_P_m
    assert loose.exit_time_s <= exact.exit_time_s


@pytest.mark.parametrize("finger, t_arrive", [("middle", 1.25), ("thumb", 0.75)])
def test_reserved_room_is_left_free_and_nothing_else_changes(five, finger, t_arrive):
    """Q keeps out of reserved room; it is the choice among the candidates outside it
    (the same as excluding those points by hand)."""
    hand, box, _, sample, manifolds, grasp = five
    first = _choose_from_grasp(five, finger, t_arrive, max_checks=10_000)
    radius = 0.006
    again = _choose_from_grasp(
        five, finger, t_arrive, max_checks=10_000, reserved=((first.p_object, radius),)
    )
    assert np.linalg.norm(again.p_object - first.p_object) >= radius
    # the same as a manifold on which the reserved points are not inside the limits
    m = manifolds[finger]
    away = np.linalg.norm(sample.points - first.p_object, axis=1) >= radius
    masked = {**manifolds, finger: dataclasses.replace(m, inside=m.inside & away[None, :])}
    by_hand = _choose_from_grasp(
        (hand, box, None, sample, masked, grasp), finger, t_arrive, max_checks=10_000
    )
    assert by_hand.index == again.index


def test_no_feasible_q_names_the_finger_and_time(five):
    hand, box, _, sample, manifolds, grasp = five
    P, n_P = grasp.points_object["middle"], grasp.normals_object["middle"]
    others = {
        n: (grasp.points_object[n], grasp.normals_object[n])
        for n in grasp.points_object
        if n != "middle"
    }
    impossible = dataclasses.replace(CONTACT, choice_margin_rad=10.0)
    with pytest.raises(ContactError, match=r"finger 'middle', t=1\.500 s: no surface point") as e:
        choose_new_contact(
            hand,
            box,
            manifolds["middle"],
            sample,
            1.5,
            P_object=P,
            n_P_object=n_P,
            others=others,
            contact=impossible,
        )
    assert e.value.finger == "middle" and e.value.time_s == pytest.approx(1.5)
    assert e.value.measured == 0.0  # none inside the limits with that margin
    assert "0 with the margin at both arrival times" in e.value.reason
    # alone on the object, no candidate is in force closure (links not tested: they
    # are tested first and would reject some candidates before their force closure)
    with pytest.raises(ContactError, match="finger 'middle'.*force closure") as e:
        choose_new_contact(
            hand,
            box,
            manifolds["middle"],
            sample,
            1.5,
            P_object=P,
            n_P_object=n_P,
            others={},
            link_check=False,
        )
    assert e.value.kind == FailureKind.FORCE_CLOSURE


def test_no_candidate_counts_what_each_test_kept(five):
    """Every contact inside the limits kept 1 m from the other contacts: the failure
    counts the contacts inside the limits with the choice margin at both arrival times
    (the manifold's usable mask, read directly) and says that the separation from the
    others left none."""
    hand, box, _, sample, manifolds, grasp = five
    P, n_P = grasp.points_object["middle"], grasp.normals_object["middle"]
    others = {n: (grasp.points_object[n], grasp.normals_object[n]) for n in ("thumb", "index")}
    man = manifolds["middle"]
    ka = int(np.searchsorted(man.times_s, 1.5))
    inside = int(man.usable(CONTACT.choice_margin_rad, rows=np.array([ka, ka])).all(0).sum())
    assert inside > 0
    with pytest.raises(ContactError) as e:
        choose_new_contact(
            hand,
            box,
            man,
            sample,
            1.5,
            P_object=P,
            n_P_object=n_P,
            others=others,
            contact=CONTACT,
            min_separation_m=1.0,
        )
    assert e.value.kind == FailureKind.NO_CANDIDATE and e.value.measured == inside
    assert f"{inside} with the margin at both arrival times, 0 of them apart" in e.value.reason


def test_a_point_exactly_a_radius_away_is_kept_on_every_machine():
    """Sample points lie on grids, so a distance between two is often exactly an
    exclusion radius; its last bits follow how the sample was placed. Such a point is
    kept whichever way its last bits fall, one more than the tolerance nearer is not."""
    r = 0.008
    centre = np.array([0.01, 0.02, 0.03])
    on = centre + np.array([r, 0.0, 0.0])
    pts = np.array(
        [on, np.nextafter(on, np.inf), np.nextafter(on, -np.inf), on - [3 * DISTANCE_TOL_M, 0, 0]]
    )
    assert _far_from(pts, [centre], r).tolist() == [True, True, True, False]
    assert not _far_from(centre[None], [centre], 1e-12)[0]  # a tiny radius: the centre


def test_fingertip_spheres_exactly_the_gap_apart_are_kept_on_every_machine(five):
    """Two fingertip spheres resting on one face exactly ``TIP_GAP_M`` apart (their
    points ``2 r + TIP_GAP_M`` apart along the face): the point is kept whichever way
    its last bits fall; one more than the tolerance nearer is not."""
    hand, box, _, sample, manifolds, grasp = five
    finger = hand.finger("middle")
    r = finger.tip_radius + hand.finger("index").tip_radius + TIP_GAP_M
    p, n = np.zeros(3), np.array([0.0, 0.0, 1.0])
    pts = np.array([[r, 0, 0], [np.nextafter(r, 0.0), 0, 0], [r - 3 * DISTANCE_TOL_M, 0, 0]])
    fake = dataclasses.replace(sample, points=pts, normals=np.tile(n, (3, 1)))
    ok = _apart_from(hand, finger, fake, {"index": (p, n)}, None)
    assert ok.tolist() == [True, True, False]


def _regrasp_of(grasp, finger):
    """``(P, n_P, others)`` of ``finger`` regrasping from ``grasp``: its contact, and
    the other fingers' contacts (point, normal), object frame."""
    others = {n: (grasp.points_object[n], grasp.normals_object[n]) for n in grasp.points_object}
    P, n_P = others.pop(finger)
    return P, n_P, others


def _grasp_configuration(hand, grasp):
    """The whole hand's configuration ``(nq,)`` with every finger of ``grasp`` at its
    grasp (the others at zero)."""
    q_hand = np.zeros(hand.model.nq)
    for n, q in grasp.q.items():
        q_hand[hand.finger(n).q_indices] = q
    return q_hand


def test_finger_clearance_is_tested_before_force_closure(five, monkeypatch):
    """A candidate too close to another finger is refused without any 6-D hull, and
    counts as a finger-clearance rejection; with the clearance met, the same Q as
    without the test."""
    hand, box, _, sample, manifolds, grasp = five
    P, n_P, others = _regrasp_of(grasp, "middle")
    q_hand = _grasp_configuration(hand, grasp)
    kw = dict(P_object=P, n_P_object=n_P, others=others, contact=CONTACT, mu=MU, link_check=False)
    calls = []
    real = screening_module.ferrari_canny_epsilon
    monkeypatch.setattr(
        screening_module, "ferrari_canny_epsilon", lambda *a, **k: calls.append(1) or real(*a, **k)
    )
    seen, at = [], []
    real_gap = FingerClearance.__call__
    monkeypatch.setattr(
        FingerClearance,
        "__call__",
        lambda self, q: at.append(np.array(q)) or seen.append(real_gap(self, q)) or seen[-1],
    )
    # 1 m from every other finger: nothing passes, and no epsilon is computed (not even
    # P's: it is read only to compare a passing candidate's with it)
    with pytest.raises(ContactError) as e:
        choose_new_contact(
            hand, box, manifolds["middle"], sample, 1.5, q_hand_arrive=q_hand,
            finger_clearance_m=1.0, **kw,
        )  # fmt: skip
    # the numbers are those of the candidate nearest to passing: the largest distance
    assert e.value.kind == FailureKind.FINGER_COLLISION and e.value.required == 1.0
    assert e.value.measured == max(seen) and 0.0 < e.value.measured < 1.0
    assert len(calls) == 0
    # and the finger it came nearest to: measured against each other finger alone
    q_best = at[int(np.argmax(seen))]
    alone_to = {
        o: real_gap(FingerClearance(hand, "middle", others=[o]), q_best)
        for o in hand.finger_names
        if o != "middle"
    }
    assert e.value.other == min(alone_to, key=alone_to.get)
    assert min(alone_to.values()) == e.value.measured
    free = choose_new_contact(
        hand, box, manifolds["middle"], sample, 1.5, q_hand_arrive=q_hand,
        finger_clearance_m=-1.0, **kw,
    )  # fmt: skip
    alone = choose_new_contact(hand, box, manifolds["middle"], sample, 1.5, **kw)
    assert (free.index, free.rank, free.epsilon) == (alone.index, alone.rank, alone.epsilon)


def test_candidates_too_near_another_finger_do_not_use_up_the_checks(five, monkeypatch):
    """A candidate refused for its finger clearance (one Coal pass) does not count
    against ``max_checks``: with one check allowed and the first candidate too near
    another finger, the choice goes on to a candidate that clears the fingers."""
    hand, box, _, sample, manifolds, grasp = five
    P, n_P, others = _regrasp_of(grasp, "middle")
    q_hand = _grasp_configuration(hand, grasp)
    kw = dict(
        P_object=P, n_P_object=n_P, others=others, contact=CONTACT, mu=MU, link_check=False,
        q_hand_arrive=q_hand,
    )  # fmt: skip
    seen, at = [], []
    real_gap = FingerClearance.__call__
    monkeypatch.setattr(
        FingerClearance,
        "__call__",
        lambda self, q: at.append(np.array(q)) or seen.append(real_gap(self, q)) or seen[-1],
    )
    first = choose_new_contact(hand, box, manifolds["middle"], sample, 1.5, max_checks=1,
                               finger_clearance_m=-1.0, **kw)  # fmt: skip
    # ask a little more than the first candidate in the ranking keeps
    need = seen[0] + 1e-6
    seen.clear()
    q = choose_new_contact(
        hand, box, manifolds["middle"], sample, 1.5, max_checks=1, finger_clearance_m=need, **kw
    )
    assert seen[0] < need and len(seen) > 1
    assert q.rank > first.rank
    q_all = hand.to_full("middle", q.q_arrive, q_hand)
    assert real_gap(FingerClearance(hand, "middle"), q_all) >= need


def _record_links_at(monkeypatch, ka):
    """A list that collects the links' distances (Coal, or a bound above the
    requirements) that ManifoldClearance gives at the manifold time ``ka``: at arrival,
    those of the candidates measured."""
    seen = []
    real = ManifoldClearance.__call__

    def record(self, rows, points):
        d, d_tip = real(self, rows, points)
        seen.append(d[np.asarray(rows) == ka])
        return d, d_tip

    monkeypatch.setattr(ManifoldClearance, "__call__", record)
    return seen


def test_an_object_clearance_failure_gives_the_nearest_candidate_in_metres(five, monkeypatch):
    """Every candidate refused for its links (1 m asked of them): the error's numbers
    are the largest links' distance measured (Coal) and the 1 m asked, not a count."""
    hand, box, _, sample, manifolds, grasp = five
    seen = _record_links_at(monkeypatch, manifolds["index"].time_index(0.5))
    far = dataclasses.replace(CONTACT, choice_link_clearance_m=1.0)
    others = {n: (grasp.points_object[n], grasp.normals_object[n]) for n in ("thumb", "ring")}
    with pytest.raises(ContactError, match="link clearance") as e:
        choose_new_contact(
            hand, box, manifolds["index"], sample, 0.5, contact=far, mu=MU, others=others,
            P_object=grasp.points_object["index"], n_P_object=grasp.normals_object["index"],
        )  # fmt: skip
    links = np.concatenate(seen)
    assert e.value.kind == FailureKind.OBJECT_CLEARANCE and e.value.required == 1.0
    assert e.value.measured == links.max() < 1.0


def test_closest_object_miss_is_the_requirement_missed_by_the_least():
    c = ContactModel(choice_link_clearance_m=0.003, tip_penetration_m=5e-5)
    links = np.array([0.004, 0.001, 0.0025, 0.010])
    tip = np.array([0.0, 0.0, 0.0, -0.0009])
    # misses: 2 mm (links), 0.5 mm (links), 0.85 mm (tip): the second link one
    assert closest_object_miss(links, tip, c) == (0.0025, 0.003)
    assert closest_object_miss(links[[1, 3]], tip[[1, 3]], c) == (-0.0009, -5e-5)
    assert closest_object_miss(links[:1], tip[:1], c) is None
    assert passes_object_clearance(links, tip, c).tolist() == [True, False, False, False]


@pytest.mark.parametrize("t_arrive", [np.nan, -0.5, 3.5])
def test_arrival_outside_the_manifold_is_rejected(five, t_arrive):
    hand, box, _, sample, manifolds, grasp = five
    with pytest.raises(InputError, match="t_arrive_s"):
        choose_new_contact(
            hand,
            box,
            manifolds["index"],
            sample,
            t_arrive,
            P_object=grasp.points_object["index"],
            n_P_object=grasp.normals_object["index"],
            others={},
        )


@pytest.mark.parametrize("finger, t_arrive", [("middle", 1.25), ("thumb", 0.75), ("index", 0.5)])
def test_q_exit_time_counts_the_other_links_of_the_finger(five, finger, t_arrive):
    """The manifold does not model the finger's other links: the chosen Q's exit time
    must, so that a new contact is not lost to a link touching the object at once.
    Until its exit time, every link stays clear and the fingertip link does not sink in
    (Pinocchio computeDistances)."""
    hand, box, _, _, manifolds, _ = five
    m = manifolds[finger]
    q = _choose_from_grasp(five, finger, t_arrive)
    ka = m.time_index(t_arrive)
    for k in range(ka, m.times_s.size):
        if m.times_s[k] >= q.exit_time_s - 1e-9:
            break
        d = _link_distance(hand, finger, box, m.q[k, q.index], m.T_palm_object[k])
        assert d >= CONTACT.link_clearance_m, (finger, m.times_s[k], d)
        d = _link_distance(hand, finger, box, m.q[k, q.index], m.T_palm_object[k], tip=True)
        assert d >= -CONTACT.tip_penetration_m, (finger, m.times_s[k], d)


@pytest.mark.parametrize("finger, t_arrive", [("middle", 0.5), ("thumb", 0.75), ("ring", 0.0)])
def test_link_exit_measures_only_until_each_point_leaves(five, finger, t_arrive):
    """The exit times cut by the finger's links equal those of measuring every point at
    every time (a loop over Pinocchio computeDistances), though only the times before a
    point leaves its usable set are measured."""
    hand, box, _, sample, manifolds, _ = five
    m = manifolds[finger]
    ka = m.time_index(t_arrive)
    rng = np.random.default_rng(7)
    usable = m.usable(CONTACT.limit_margin_rad)
    pool = np.flatnonzero(usable[ka])
    points = rng.choice(pool, size=min(12, pool.size), replace=False)
    assert points.size >= 4
    t_exit, lasts = _link_exit(hand, finger, box, m, points, ka, CONTACT)
    for c, i in enumerate(points):
        ok = []
        for k in range(ka, m.times_s.size):
            good = bool(usable[k, i])
            if good:
                d = _link_distance(hand, finger, box, m.q[k, i], m.T_palm_object[k])
                d_tip = _link_distance(hand, finger, box, m.q[k, i], m.T_palm_object[k], tip=True)
                good = d >= CONTACT.link_clearance_m and d_tip >= -CONTACT.tip_penetration_m
            ok.append(good)
        first_bad = ok.index(False) if False in ok else None
        expected = m.times_s[-1] if first_bad is None else m.times_s[ka + first_bad]
        assert t_exit[c] == pytest.approx(expected), (i, ok)
        assert lasts[c] == (first_bad is None)


class _Asked(ManifoldClearance):
    """A ManifoldClearance that records the (rows, points) it is asked for."""

    def __init__(self, *args):
        super().__init__(*args)
        self.asked = []

    def __call__(self, rows, points):
        self.asked.append((np.asarray(rows), np.asarray(points)))
        return super().__call__(rows, points)


@pytest.mark.parametrize("finger, t_arrive", [("middle", 0.5), ("thumb", 0.75), ("index", 0.0)])
def test_held_clear_measures_each_point_only_in_runs_up_to_its_first_failure(
    five, finger, t_arrive
):
    """held_clear asks for a point's usable times in runs of HELD_FIRST_RUN, then twice
    as many, and so on, and stops after the run that holds its first failure (or at its
    last usable time); its answer is that of measuring every usable time."""
    hand, box, _, _, manifolds, _ = five
    m = manifolds[finger]
    ka = m.time_index(t_arrive)
    usable = m.usable(CONTACT.limit_margin_rad)[ka:]
    pool = np.flatnonzero(usable[0])
    points = np.random.default_rng(3).choice(pool, size=min(40, pool.size), replace=False)
    asked = _Asked(hand, finger, box, m, CONTACT)
    got = held_clear(hand, finger, box, m, points, ka, CONTACT, asked)
    # the full measurement: every time before each point leaves its usable set
    still = np.logical_and.accumulate(usable[:, points], axis=0)
    full = ManifoldClearance(hand, finger, box, m, CONTACT)
    rows, cols = np.nonzero(still)
    d, d_tip = full(ka + rows, points[cols])
    ok = np.zeros_like(still)
    ok[rows, cols] = (d >= CONTACT.link_clearance_m) & (d_tip >= -CONTACT.tip_penetration_m)
    np.testing.assert_array_equal(got, np.logical_and.accumulate(ok, axis=0))
    ends = np.cumsum(HELD_FIRST_RUN * 2 ** np.arange(10))  # where the runs end
    every = np.concatenate([p for _, p in asked.asked])
    measured = np.array([(every == p).sum() for p in points])
    n_still = still.sum(axis=0)
    for c in range(points.size):
        fails = np.flatnonzero(still[:, c] & ~ok[:, c])
        need = fails[0] + 1 if fails.size else n_still[c]
        expected = min(int(ends[np.searchsorted(ends, need)]), int(n_still[c]))
        assert measured[c] == expected, (c, need, n_still[c])
    assert measured.sum() < still.sum()  # some point failed early: its tail was spared


@pytest.mark.parametrize("finger, horizon", [("middle", 2), ("thumb", 5)])
def test_held_clear_horizon_is_the_first_rows_and_measures_no_further(five, finger, horizon):
    """held_clear(horizon=h) answers the first h rows of the full call (a prefix of the
    same running AND) and measures no time beyond them."""
    hand, box, _, _, manifolds, _ = five
    m = manifolds[finger]
    ka = m.time_index(0.25)
    pool = np.flatnonzero(m.usable(CONTACT.limit_margin_rad)[ka])
    points = np.random.default_rng(5).choice(pool, size=min(30, pool.size), replace=False)
    full = held_clear(hand, finger, box, m, points, ka, CONTACT)
    asked = _Asked(hand, finger, box, m, CONTACT)
    got = held_clear(hand, finger, box, m, points, ka, CONTACT, asked, horizon=horizon)
    assert got.shape == (horizon, points.size)
    np.testing.assert_array_equal(got, full[:horizon])
    assert np.concatenate([r for r, _ in asked.asked]).max() < ka + horizon
    with pytest.raises(InputError, match="horizon"):
        held_clear(hand, finger, box, m, points, ka, CONTACT, horizon=0)


@pytest.mark.parametrize("finger, t_arrive", [("middle", 0.5), ("thumb", 0.75)])
def test_link_exit_reads_lasting_only_until_the_links_end_a_hold(five, finger, t_arrive):
    """``lasting`` gets each point's horizon: the times before its links or its limits
    end it (what comes after cannot move the first False). Two ``lasting`` that differ
    only from the horizon on give the same exit times; one that is False from a
    point's middle time on cuts that point there."""
    hand, box, _, _, manifolds, _ = five
    m = manifolds[finger]
    ka = m.time_index(t_arrive)
    pool = np.flatnonzero(m.usable(CONTACT.limit_margin_rad)[ka])
    points = np.random.default_rng(11).choice(pool, size=min(12, pool.size), replace=False)
    K = m.times_s.size - ka
    base, _ = _link_exit(hand, finger, box, m, points, ka, CONTACT)
    seen = []

    def after(value, cut_at=None):
        def lasting(pts, k, horizon):
            assert k == ka and np.array_equal(pts, points)
            seen.append(np.asarray(horizon).copy())
            out = np.ones((K, pts.size), bool)
            for c, h in enumerate(horizon):
                out[h:, c] = value
                if cut_at is not None and h > 1:
                    out[h // 2 :, c] = False
            return out

        return lasting

    t_true, last_true = _link_exit(hand, finger, box, m, points, ka, CONTACT, after(True))
    t_false, last_false = _link_exit(hand, finger, box, m, points, ka, CONTACT, after(False))
    np.testing.assert_array_equal(t_true, base)
    np.testing.assert_array_equal(t_false, base)
    np.testing.assert_array_equal(last_true, last_false)
    # the horizon is where the unconstrained exit falls (the whole tail if none)
    exits = np.searchsorted(m.times_s[ka:], base - 1e-9)
    h = seen[0]
    np.testing.assert_array_equal(h, np.where(last_true, K, exits))
    assert (h > 1).any()
    t_cut, _ = _link_exit(hand, finger, box, m, points, ka, CONTACT, after(True, cut_at=True))
    np.testing.assert_array_equal(t_cut, np.where(h > 1, m.times_s[ka + h // 2], base))


def test_kept_distances_equal_pinocchio_and_are_measured_once(five, monkeypatch):
    """ManifoldClearance gives each entry's link and fingertip distances as Pinocchio
    computeDistances does below the contact model's requirements, and above them a
    lower bound that meets them (so every comparison with a requirement is the same)
    without a Coal query; a second question about known entries measures nothing: the
    same bits as the first answer."""
    hand, box, _, sample, manifolds, _ = five
    m = manifolds["index"]
    rng = np.random.default_rng(11)
    rows, cols = np.nonzero(np.isfinite(m.q[..., 0]))
    pick = rng.choice(rows.size, size=40, replace=False)
    rows, cols = rows[pick], cols[pick]
    kept = ManifoldClearance(hand, "index", box, m, CONTACT)
    d, d_tip = kept(rows, cols)
    need = (
        max(CONTACT.link_clearance_m, CONTACT.choice_link_clearance_m),
        -CONTACT.tip_penetration_m,
    )
    bounded = 0
    for j in range(rows.size):
        q_j, T_j = m.q[rows[j], cols[j]], m.T_palm_object[rows[j]]
        for got, tip, req in ((d[j], False, need[0]), (d_tip[j], True, need[1])):
            exact = _link_distance(hand, "index", box, q_j, T_j, tip=tip)
            if got == pytest.approx(exact, abs=1e-9):
                continue
            bounded += 1  # a lower bound, above the requirement
            assert req + BOUND_MARGIN_M <= got <= exact + 1e-9, (j, tip, got, exact)
    # spared: the bounds that differ, and bounds that are exact (a sphere's face bound)
    assert 0 < bounded and kept.n_queries <= 2 * rows.size - bounded
    measured = []
    real = LinkClearance.__call__
    monkeypatch.setattr(
        LinkClearance, "__call__", lambda self, *a: measured.append(1) or real(self, *a)
    )
    again, again_tip = kept(rows[::-1], cols[::-1])
    assert not measured
    assert again.tolist() == d[::-1].tolist() and again_tip.tolist() == d_tip[::-1].tolist()
    with pytest.raises(InputError, match="distances"):
        held_clear(hand, "middle", box, manifolds["middle"], cols[:2], 0, CONTACT, kept)
    looser = dataclasses.replace(CONTACT, choice_link_clearance_m=0.01)
    with pytest.raises(InputError, match="another contact model"):
        held_clear(hand, "index", box, m, cols[:2], 0, looser, kept)


@pytest.mark.parametrize("finger, t_arrive", [("middle", 1.25), ("thumb", 0.75)])
def test_choices_with_kept_distances_and_epsilons_are_the_same(five, finger, t_arrive):
    """Choosing Q again and again with the distances and epsilons kept between the
    calls (as the planner's search does) gives, call by call, the same choice as
    measuring afresh, while later calls find what they need already known."""
    hand, box, _, sample, manifolds, grasp = five
    kept = ManifoldClearance(hand, finger, box, manifolds[finger])
    epsilons = ScreeningEpsilons(MU, box.radius_m)
    excluded: list[np.ndarray] = []
    for _ in range(3):
        kw = {"exclude_points_object": np.array(excluded)} if excluded else {}
        fresh = _choose_from_grasp(five, finger, t_arrive, **kw)
        reused = _choose_from_grasp(five, finger, t_arrive, distances=kept, epsilons=epsilons, **kw)
        assert (reused.index, reused.rank, reused.epsilon, reused.exit_time_s) == (
            fresh.index,
            fresh.rank,
            fresh.epsilon,
            fresh.exit_time_s,
        )
        excluded.append(fresh.p_object)
    assert kept._known.any() and len(epsilons._known) > 0
    with pytest.raises(InputError, match="epsilons"):
        _choose_from_grasp(five, finger, t_arrive, epsilons=ScreeningEpsilons(MU + 0.1, 1.0))


@pytest.mark.parametrize("finger, k_to", [("index", 4), ("middle", 3)])
def test_a_finger_that_must_hold_starts_where_its_links_last(allegro, finger, k_to):
    """A finger that cannot let go over a run from the start gets only candidates at
    which, followed by the manifold, its other links keep clear of the object and its
    fingertip link does not sink in through the run (as the tracking will measure;
    Pinocchio computeDistances), not only contacts inside its joint limits; and some
    contacts that last through the run inside the limits do not keep clear."""
    hand, box, _, sample, manifolds, _ = allegro
    m = manifolds[finger]
    lasting = m.usable(0.0)[: k_to + 1].all(axis=0)
    run = MustHold(finger, 0, k_to, 0.0, float(m.times_s[k_to]), lasting)

    def clear_through(i: int) -> bool:
        for k in range(k_to + 1):
            q_k, T_k = m.q[k, i], m.T_palm_object[k]
            if _link_distance(hand, finger, box, q_k, T_k) < CONTACT.link_clearance_m:
                return False
            if _link_distance(hand, finger, box, q_k, T_k, tip=True) < -CONTACT.tip_penetration_m:
                return False
        return True

    idx, _ = _start_candidates(hand, box, m, sample.points, 0, CONTACT, 40, run)
    assert idx.size > 0
    assert all(lasting[i] and clear_through(int(i)) for i in idx)
    start = np.flatnonzero(lasting & m.usable(CONTACT.choice_margin_rad)[0])
    assert not all(clear_through(int(i)) for i in start)


def _held_until_next(hand, finger, box, m, i) -> bool:
    """The tracking holds sample point ``i`` from the manifold's first time to its
    next: inside the limits, the other links clear of the object and the fingertip link
    not sinking in at both (Pinocchio computeDistances at the manifold's joints)."""
    for k in (0, 1):
        q_k, T_k = m.q[k, i], m.T_palm_object[k]
        if not m.usable(CONTACT.limit_margin_rad)[k, i]:
            return False
        if _link_distance(hand, finger, box, q_k, T_k) < CONTACT.link_clearance_m:
            return False
        if _link_distance(hand, finger, box, q_k, T_k, tip=True) < -CONTACT.tip_penetration_m:
            return False
    return True


@pytest.mark.parametrize("finger", ["index", "middle", "ring"])
def test_every_start_candidate_is_held_until_the_next_manifold_time(allegro, finger):
    """Without a run it must hold, a finger still gets only candidates that the
    tracking holds until the next manifold time: inside the limits there, its other
    links clear of the object and its fingertip link not sinking in at both times
    (Pinocchio computeDistances); a contact lost at once is no start. Some contacts
    usable and clear at the start are not (the Allegro's fingertip link sinks as the
    box turns)."""
    hand, box, _, sample, manifolds, _ = allegro
    m = manifolds[finger]
    idx, _ = _start_candidates(hand, box, m, sample.points, 0, CONTACT, 40)
    assert idx.size > 0
    assert all(_held_until_next(hand, finger, box, m, int(i)) for i in idx)


def test_some_start_contacts_clear_at_the_start_are_lost_at_once(allegro):
    """What the test above guards against occurs: on the Allegro fixture, some
    contacts usable and clear of the object at the start are not held until the next
    manifold time."""
    hand, box, _, sample, manifolds, _ = allegro
    lost = 0
    for finger in ("index", "middle", "ring"):
        m = manifolds[finger]
        start = np.flatnonzero(m.usable(CONTACT.choice_margin_rad)[0])
        for i in start[:: max(start.size // 60, 1)]:
            q0, q1 = m.q[0, i], m.q[1, i]
            clear0 = (
                _link_distance(hand, finger, box, q0, m.T_palm_object[0], tip=True)
                >= -CONTACT.tip_penetration_m
            )
            sinks1 = (
                _link_distance(hand, finger, box, q1, m.T_palm_object[1], tip=True)
                < -CONTACT.tip_penetration_m
            )
            lost += clear0 and sinks1
    assert lost > 0


@pytest.mark.parametrize("finger", ["index", "thumb"])
def test_a_finger_with_few_usable_contacts_gets_every_clear_one(five, finger):
    """A finger whose usable contacts at the start lie in one small patch (here: the
    manifold cut down to the points within 1.5 tip radii of one of them) gets every
    one of them whose links clear the object (Pinocchio computeDistances) and that is
    held until the next manifold time, up to the limit: the spacing passes only
    order the candidates, they do not thin out a finger that has few (with spacings
    alone it got two or three)."""
    hand, box, _, sample, manifolds, _ = five
    m = manifolds[finger]
    T0 = m.T_palm_object[0]

    def clears(i: int) -> bool:
        return bool(
            _link_distance(hand, finger, box, m.q[0, i], T0) >= CONTACT.choice_link_clearance_m
            and _link_distance(hand, finger, box, m.q[0, i], T0, tip=True)
            >= -CONTACT.tip_penetration_m
        )

    usable0 = np.flatnonzero(m.usable(CONTACT.choice_margin_rad)[0])
    # the patch around the held contact (links clear, held until the next time) with the
    # most held contacts near it (most of the thumb's usable contacts sink its
    # fingertip link)
    r = 1.5 * hand.finger(finger).tip_radius
    held = np.array(
        [
            int(i)
            for i in usable0
            if clears(int(i)) and _held_until_next(hand, finger, box, m, int(i))
        ]
    )
    pts_held = sample.points[held]
    near_counts = (np.linalg.norm(pts_held[:, None] - pts_held[None], axis=2) <= r).sum(axis=1)
    centre_i = int(held[np.argmax(near_counts)])
    centre = sample.points[centre_i]
    near = np.linalg.norm(sample.points - centre, axis=1) <= r
    patch = dataclasses.replace(m, inside=m.inside & near[None, :])
    start = np.flatnonzero(patch.usable(CONTACT.choice_margin_rad)[0])
    assert 5 <= start.size < 40
    clear = [
        int(i)
        for i in start
        if clears(int(i)) and _held_until_next(hand, finger, box, patch, int(i))
    ]
    idx, _ = _start_candidates(hand, box, patch, sample.points, 0, CONTACT, 40)
    assert sorted(idx.tolist()) == clear and len(clear) > 3
    few, _ = _start_candidates(hand, box, patch, sample.points, 0, CONTACT, 3)
    assert few.size == 3 and set(few.tolist()) <= set(clear)


# ------------------------------------------------------------------ grasp search parts
def test_spread_out_covers_the_surface_first_then_fills_in():
    rng = np.random.default_rng(3)
    pts = rng.uniform(-0.05, 0.05, (400, 3))
    order = rng.permutation(400)
    refused = set(order[::7].tolist())
    chosen = _spread_out(pts, order, (0.03, 0.01), 60, lambda j: j not in refused)
    assert len(chosen) == len(set(chosen)) == 60 and not refused & set(chosen)
    d = np.linalg.norm(pts[chosen][:, None] - pts[chosen][None], axis=-1)
    first = next(k for k in range(1, 60) if d[k, :k].min() < 0.03)  # start of pass 2
    assert first > 1
    # pass 1 is every admissible point of `order` at least 30 mm from those before it
    greedy = []
    for j in order:
        if j not in refused and all(np.linalg.norm(pts[j] - pts[g]) >= 0.03 for g in greedy):
            greedy.append(int(j))
    assert chosen[:first] == greedy
    # pass 2: every later point at least 10 mm from all chosen before it
    assert all(d[k, :k].min() >= 0.01 for k in range(first, 60))


def test_spread_out_points_exactly_a_spacing_apart_are_near_wherever_they_lie():
    # a grid of 4 mm steps, the spacing 8 mm: many points are exactly the spacing from
    # one chosen before, which the placement's last bits must not decide: they are near
    steps = np.array([[i, j, 0] for j in range(3) for i in range(9)])
    greedy: list[int] = []  # the same pass in exact integer arithmetic (grid steps)
    for j, p in enumerate(steps):
        if all(((p - steps[g]) ** 2).sum() > 4 for g in greedy):
            greedy.append(j)
    rng = np.random.default_rng(8)
    for _ in range(30):
        R = np.linalg.qr(rng.standard_normal((3, 3)))[0]
        pts = (0.004 * steps) @ R.T + rng.uniform(-0.3, 0.3, 3)
        chosen = _spread_out(pts, np.arange(len(steps)), (0.008,), 100, lambda j: True)
        assert chosen == greedy


def test_screening_epsilons_are_the_hulls_each_computed_once(monkeypatch):
    # the grasp search's memo: the value of ferrari_canny_epsilon for the contacts in
    # their order, one hull per distinct set (a reordered set is another key)
    import regrasp_pin.grasp.screening as screening

    rng = np.random.default_rng(26)
    p = rng.normal(0.0, 0.02, (4, 3))
    n = rng.normal(size=(4, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    calls = []
    real = screening.ferrari_canny_epsilon
    monkeypatch.setattr(
        screening, "ferrari_canny_epsilon", lambda *a, **k: calls.append(1) or real(*a, **k)
    )
    eps = screening.ScreeningEpsilons(MU, 0.03)
    ref = real(p, n, MU, n_edges=SCREEN_EDGES, torque_scale_m=0.03)
    assert eps(p, n) == ref and eps(p.copy(), n.copy()) == ref
    loo = screening.leave_one_out(p, n, MU, 0.03, range(4), eps)
    assert loo == [
        real(np.delete(p, j, 0), np.delete(n, j, 0), MU, n_edges=SCREEN_EDGES, torque_scale_m=0.03)
        for j in range(4)
    ]
    assert screening.leave_one_out(p, n, MU, 0.03, range(4), eps) == loo
    assert len(calls) == 5
    eps(p[::-1], n[::-1])
    assert len(calls) == 6


def test_screening_closes_without_gives_the_hulls_answers_mostly_without_hulls(monkeypatch):
    # which fingers could let go (choice.removable): leave_one_out's epsilons > tol, from
    # the NNLS certificate where it decides; every answer is the hull's
    import regrasp_pin.grasp.screening as screening
    from regrasp_pin.grasp.quality import FORCE_CLOSURE_TOL

    real = screening.ferrari_canny_epsilon
    calls = []
    monkeypatch.setattr(
        screening, "ferrari_canny_epsilon", lambda *a, **k: calls.append(1) or real(*a, **k)
    )
    rng = np.random.default_rng(27)
    n_sets = closing = 0
    for _ in range(40):
        k = int(rng.integers(4, 7))
        p = rng.normal(0.0, 0.02, (k, 3))
        n = p / np.linalg.norm(p, axis=1, keepdims=True)  # outward, as on a round object
        n += rng.normal(0.0, 0.3, (k, 3))
        n /= np.linalg.norm(n, axis=1, keepdims=True)
        eps = screening.ScreeningEpsilons(MU, 0.03)
        got = screening.closes_without(p, n, range(k), eps)
        want = [
            real(
                np.delete(p, j, 0),
                np.delete(n, j, 0),
                MU,
                n_edges=SCREEN_EDGES,
                torque_scale_m=0.03,
            )
            > FORCE_CLOSURE_TOL
            for j in range(k)
        ]
        assert got == want
        before = eps.closes(p, n)  # the certificate's answer (or the hull's)
        hull = eps(p, n) > FORCE_CLOSURE_TOL
        assert before == hull and eps.closes(p, n) == hull  # then read from the hull
        n_sets += k
        closing += sum(want)
    assert closing >= 20 and n_sets - closing >= 20, (closing, n_sets)
    assert len(calls) - 40 <= n_sets // 10  # the 40 full sets' hulls, few of the rest


def _cut_ranking(seed: int, n: int, tolerance: float) -> tuple[_Ranking, np.ndarray, np.ndarray]:
    """Random candidates (exit times on a 0.01 s grid up to 3 s) and their cut exit
    times: each cut to a random earlier grid time or kept, as links and other fingers
    do (a cut never lengthens a hold)."""
    rng = np.random.default_rng(seed)
    t_exit = np.round(rng.uniform(0.1, 3.0, n), 2)
    cut = np.where(rng.random(n) < 0.6, np.round(t_exit * rng.random(n), 2), t_exit)
    ranked = _Ranking(
        t_exit=t_exit,
        margin=rng.uniform(0.05, 0.3, n),
        dist=rng.uniform(0.0, 0.05, n),
        idx=np.arange(n) * 3,
        exit_tolerance_s=tolerance,
    )
    return ranked, cut, np.zeros(n, bool)


@pytest.mark.parametrize("seed", range(20))
def test_rerank_gives_the_first_candidates_of_the_fully_cut_ranking(seed):
    """An uncut exit time bounds the cut one from above, so once the first `rerank`
    candidates are all cut, no other can come before them: the head of the order is the
    one that cutting every candidate gives (the paper's order), with fewer cut."""
    ranked, cut, lasts = _cut_ranking(seed, 80, 0.0)
    asked: list[int] = []

    def cutter(top):
        asked.extend(top.tolist())
        return cut[top], np.zeros(top.size, bool)

    got, order = _rerank(ranked, lasts, 12, 80, cutter)
    full = dataclasses.replace(ranked, t_exit=cut).order(lasts)
    assert order[:12].tolist() == full[:12].tolist()
    assert len(set(asked)) == len(asked)  # no candidate cut twice
    assert set(order[:12].tolist()) <= set(asked)
    np.testing.assert_array_equal(got.t_exit[asked], cut[asked])


def test_rerank_looks_past_the_first_candidates_when_their_holds_are_cut_short():
    """The first twelve by the manifold are all cut to 0.5 s; the thirteenth holds 2.5 s
    uncut: it comes first (a fixed re-rank of twelve would have put it after them)."""
    n = 20
    t_exit = np.r_[np.full(12, 3.0), 2.5, np.full(7, 1.0)]
    cut = np.r_[np.full(12, 0.5), 2.5, np.full(7, 1.0)]
    ranked = _Ranking(t_exit, np.full(n, 0.1), np.zeros(n), np.arange(n), 0.25)
    asked: list[np.ndarray] = []

    def cutter(top):
        asked.append(top)
        return cut[top], top < 0

    got, order = _rerank(ranked, np.zeros(n, bool), 12, 60, cutter)
    assert order[0] == 12 and got.t_exit[12] == 2.5
    assert sorted(np.concatenate(asked).tolist()) == list(range(20))  # 12, then the rest
    # at most twelve cut: the order is by what is known (the others' bounds)
    asked.clear()
    got, capped = _rerank(ranked, np.zeros(n, bool), 12, 12, cutter)
    assert len(asked) == 1 and sorted(asked[0].tolist()) == list(range(12))
    assert capped[0] == 12 and set(capped[8:].tolist()) == set(range(12))


def test_q_that_would_land_too_late_is_not_chosen(five):
    """With ``landing_s`` (here: the largest joint move from P's configuration, a stand-in
    for a flight's duration), a Q whose landing comes after ``land_by_s`` is passed
    over for the next one that lands in time; when none does, the error is
    ``too-late`` with the earliest landing as its measure."""
    _, _, _, _, manifolds, _ = five
    m = manifolds["middle"]
    q_from = np.nanmean(m.q[0], axis=0)

    def landing(q_to: np.ndarray) -> np.ndarray:
        return np.abs(q_to - q_from).max(axis=1)

    free = _choose_from_grasp(five, "middle", 1.25, max_checks=10_000)
    same = _choose_from_grasp(
        five, "middle", 1.25, max_checks=10_000, landing_s=landing, land_by_s=np.inf
    )
    assert same.index == free.index
    late = float(landing(free.q_arrive[None])[0])
    sooner = _choose_from_grasp(
        five, "middle", 1.25, max_checks=10_000, landing_s=landing, land_by_s=late - 1e-6
    )
    assert sooner.index != free.index
    assert landing(sooner.q_arrive[None])[0] <= late - 1e-6
    with pytest.raises(ContactError) as info:
        _choose_from_grasp(
            five, "middle", 1.25, max_checks=10_000, landing_s=landing, land_by_s=-1.0
        )
    assert info.value.kind == FailureKind.TOO_LATE
    assert info.value.required == -1.0 and info.value.measured >= 0.0
    # one finite landing time per candidate, or an error that names the argument
    for bad in (lambda q: 0.5, lambda q: np.full(len(q), np.nan)):
        with pytest.raises(InputError, match="landing_s"):
            _choose_from_grasp(five, "middle", 1.25, landing_s=bad, land_by_s=1.0)


def test_a_failure_names_what_refused_the_candidates_that_cleared_the_object(five, monkeypatch):
    """Most candidates refused for their links (the 80th percentile of their distances
    asked), the rest, which clear the object, refused for another finger 1 m away: the
    error's kind and numbers are the finger clearance's, what bound the candidates that
    got furthest, though the object clearance refused more; the message counts both."""
    hand, box, _, sample, manifolds, grasp = five
    others = {n: (grasp.points_object[n], grasp.normals_object[n]) for n in ("thumb", "ring")}
    kw = dict(
        mu=MU,
        others=others,
        P_object=grasp.points_object["index"],
        n_P_object=grasp.normals_object["index"],
    )
    seen = _record_links_at(monkeypatch, manifolds["index"].time_index(0.5))
    everything = dataclasses.replace(CONTACT, choice_link_clearance_m=1.0)
    with pytest.raises(ContactError):
        choose_new_contact(hand, box, manifolds["index"], sample, 0.5, contact=everything, **kw)
    links = np.concatenate(seen)
    monkeypatch.undo()
    some = dataclasses.replace(CONTACT, choice_link_clearance_m=float(np.quantile(links, 0.8)))
    q_hand = _grasp_configuration(hand, grasp)
    with pytest.raises(ContactError) as e:
        choose_new_contact(
            hand, box, manifolds["index"], sample, 0.5, contact=some, q_hand_arrive=q_hand,
            finger_clearance_m=1.0, max_checks=1000, **kw,
        )  # fmt: skip
    counts = {
        k: int(n) for n, k in re.findall(r"(\d+) (link clearance|finger clearance)", str(e.value))
    }
    assert counts["link clearance"] > counts["finger clearance"] > 0
    assert e.value.kind == FailureKind.FINGER_COLLISION and e.value.required == 1.0
    assert 0.0 < e.value.measured < 1.0


def test_a_new_contact_is_apart_when_the_fingertip_spheres_resting_there_are():
    """Around a box's edge the fingertip spheres resting on the two faces stand further
    apart than their contact points (the normals diverge): a candidate within
    ``2 r + 1 mm`` of another contact, on the next face, is apart when the spheres'
    centres are ``2 r + TIP_GAP_M`` apart; on the same face the points' distance is the
    centres' one."""
    from regrasp_pin.grasp import choice as choice_module
    from regrasp_pin.model.objects import Box

    hand = Hand.five_finger()
    f = hand.finger("index")
    r = f.tip_radius
    box = Box((0.04, 0.04, 0.04))
    sample = box.sample_surface(0.001)
    p_other, n_other = np.array([0.02, 0.015, 0.0]), np.array([1.0, 0.0, 0.0])  # face +x
    others = {"middle": (p_other, n_other)}
    ok = choice_module._apart_from(hand, f, sample, others, None)
    centres = sample.points + r * sample.normals
    c_other = p_other + hand.finger("middle").tip_radius * n_other
    gap = np.linalg.norm(centres - c_other, axis=1) - r - hand.finger("middle").tip_radius
    np.testing.assert_array_equal(ok, gap >= choice_module.TIP_GAP_M)
    near = np.linalg.norm(sample.points - p_other, axis=1) < 2 * r + 0.001
    same_face = np.abs(sample.normals @ n_other - 1.0) < 1e-9
    assert not (ok & near & same_face).any()  # on one face: as the points' distance
    assert (ok & near & ~same_face).any()  # across the edge: some the points' test refused
    # the pair test the recovery's room reads is the same test
    for i in np.random.default_rng(1).choice(len(ok), 50, replace=False):
        g = choice_module.tip_gap(
            hand, "index", (sample.points[i], sample.normals[i]), "middle", others["middle"]
        )
        assert g == pytest.approx(gap[i], abs=1e-15) and (g >= choice_module.TIP_GAP_M) == ok[i]
    # an explicit separation is the points' distance, as before
    by_points = choice_module._apart_from(hand, f, sample, others, 2 * r + 0.001)
    np.testing.assert_array_equal(by_points, ~near)


def test_q_that_frees_a_finger_lets_the_others_hold_without_it(five):
    """With ``frees``, Q is one with which the other contacts without that finger are in
    force closure (the planner's test before a finger lifts off, is_force_closure), also
    for a finger that the plain choice does not free; where no candidate does, the
    failure is a force-closure one that says so. A name not among the others, or a
    string, is refused."""
    hand, box, _, sample, manifolds, grasp = five
    P, n_P, others = _regrasp_of(grasp, "thumb")
    kw = dict(P_object=P, n_P_object=n_P, others=others, contact=CONTACT, mu=MU, link_check=False)
    m = manifolds["thumb"]
    plain = choose_new_contact(hand, box, m, sample, 0.5, **kw)
    freed = 0
    for name in others:
        rest = [n for n in others if n != name]

        def frees(q, rest=rest):
            return is_force_closure(
                np.vstack([[others[n][0] for n in rest], q.p_object]),
                np.vstack([[others[n][1] for n in rest], q.n_object]),
                MU,
                torque_scale_m=box.radius_m,
            )

        try:
            q = choose_new_contact(hand, box, m, sample, 0.5, frees=(name,), **kw)
        except ContactError as e:
            assert e.kind == FailureKind.FORCE_CLOSURE and "not freeing" in str(e), name
            assert not frees(plain)
            continue
        assert frees(q), name
        freed += not frees(plain)  # the constraint chose another Q
    assert freed >= 1
    for bad in (("thumb",), "index"):
        with pytest.raises(InputError, match="frees"):
            choose_new_contact(hand, box, m, sample, 0.5, frees=bad, **kw)


def test_no_q_frees_a_finger_that_would_leave_two_contacts(five):
    """Two point contacts cannot resist a torque about the line through them: with only
    two others, no Q frees either, and the failure is a force-closure one whose numbers
    are the largest epsilon (8 cone edges, the planner's) among the sets refused, below
    the tolerance."""
    hand, box, _, sample, manifolds, grasp = five
    P, n_P, others = _regrasp_of(grasp, "middle")
    two = {n: others[n] for n in ("thumb", "index")}
    with pytest.raises(ContactError) as e:
        choose_new_contact(
            hand, box, manifolds["middle"], sample, 1.5, P_object=P, n_P_object=n_P,
            others=two, contact=CONTACT, mu=MU, link_check=False, frees=("index",),
        )  # fmt: skip
    err = e.value
    counts = {k: int(n) for n, k in re.findall(r"(\d+) (force closure|not freeing)", str(err))}
    assert err.kind == FailureKind.FORCE_CLOSURE and counts["not freeing"] > 0
    assert err.required == FORCE_CLOSURE_TOL and 0.0 <= err.measured <= FORCE_CLOSURE_TOL


def test_an_absent_finger_is_left_out_of_the_finger_clearance(five, monkeypatch):
    """With ``absent``, the clearance of each candidate at arrival is its Coal distance
    to the other fingers but the absent one (which stands in ``q_hand_arrive`` where it
    does not hold): the distances measured equal a FingerClearance without it, and the
    choice is the one whose clearance is met without it. A string, a holding finger,
    the finger itself or an unknown name is refused."""
    hand, box, _, sample, manifolds, grasp = five
    P, n_P, others = _regrasp_of(grasp, "middle")
    away = {n: v for n, v in others.items() if n != "ring"}  # the ring makes room
    q_hand = _grasp_configuration(hand, grasp)  # ... but stands at its contact
    kw = dict(
        P_object=P, n_P_object=n_P, others=away, contact=CONTACT, mu=MU, link_check=False,
        q_hand_arrive=q_hand,
    )  # fmt: skip
    seen = []
    real_gap = FingerClearance.__call__

    def record(self, q):
        seen.append((q.copy(), real_gap(self, q)))
        return seen[-1][1]

    monkeypatch.setattr(FingerClearance, "__call__", record)
    m = manifolds["middle"]
    q = choose_new_contact(
        hand, box, m, sample, 1.5, finger_clearance_m=0.001, absent=("ring",), **kw
    )
    present = FingerClearance(hand, "middle", [n for n in away if n != "middle"])
    everyone = FingerClearance(hand, "middle")
    assert seen
    for q_all, d in seen:
        assert d == pytest.approx(real_gap(present, q_all), abs=1e-12)
    q_all = hand.to_full("middle", q.q_arrive, q_hand)
    assert real_gap(present, q_all) >= 0.001
    # the ring, where it stands, is the nearest finger of some candidates measured:
    # without ``absent`` their clearance would have been smaller
    assert any(real_gap(everyone, q_all) < d - 1e-6 for q_all, d in seen)
    for bad in ("ring", ("index",), ("middle",), ("sixth",)):
        with pytest.raises(InputError, match="absent"):
            choose_new_contact(hand, box, m, sample, 1.5, absent=bad, **kw)


def test_a_room_with_a_posture_keeps_the_finger_clear_of_that_finger(five):
    """A room with a finger posture (the middle standing where the index would have
    landed, at the index's arrival) refuses the candidates whose finger, at its own
    configuration then, comes nearer that finger than the clearance (Coal): the plain
    choice is refused and the one made instead clears it. A posture of the choosing
    finger itself, of the wrong size or at no time is refused."""
    hand, box, _, sample, manifolds, grasp = five
    P, n_P, others = _regrasp_of(grasp, "index")
    others.pop("middle")  # the middle is to land in the room
    kw = dict(P_object=P, n_P_object=n_P, others=others, contact=CONTACT, mu=MU, link_check=False)
    m, t = manifolds["index"], 1.5
    plain = choose_new_contact(hand, box, m, sample, t, **kw)
    q_middle = manifolds["middle"].q[manifolds["middle"].time_index(t), plain.index]
    room = Room(plain.p_object, 0.0, "middle", q_middle, t)
    q = choose_new_contact(hand, box, m, sample, t, reserved=[room], finger_clearance_m=0.001, **kw)
    clear = FingerClearance(hand, "index", ["middle"])

    def gap(i: int) -> float:
        at = hand.to_full("index", m.q[m.time_index(t), i], hand.to_full("middle", q_middle))
        return clear(at)

    assert gap(plain.index) < 0.001 <= gap(q.index)
    assert q.rank > plain.rank
    # a (point, radius) pair is a room without a posture: the plain choice stands
    again = choose_new_contact(hand, box, m, sample, t, reserved=[(plain.p_object, 0.0)], **kw)
    assert again.index == plain.index
    for bad in (
        [Room(plain.p_object, 0.0, "index", plain.q_arrive, t)],
        [Room(plain.p_object, 0.0, "middle", q_middle[:2], t)],
        [Room(plain.p_object, 0.0, "middle", q_middle, float("nan"))],
        [Room(plain.p_object, 0.0, "middle", q_middle, 99.0)],  # after the manifold
        [Room(plain.p_object, 0.0, "sixth", q_middle, t)],
        [Room(plain.p_object[:2], 0.0)],
        [(plain.p_object, float("nan"))],
        (plain.p_object, 0.01),  # one pair, not a sequence of them
        Room(plain.p_object, 0.0),  # one room, not a sequence of them
    ):
        with pytest.raises(InputError, match="reserved"):
            choose_new_contact(hand, box, m, sample, t, reserved=bad, **kw)
    with pytest.raises(InputError, match="absent"):
        choose_new_contact(hand, box, m, sample, t, absent=None, **kw)
