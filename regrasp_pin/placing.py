"""Placing an object in any hand: start poses where the fingers can grasp it.

The ready-made scenarios (:mod:`regrasp_pin.scenarios`) know where the bundled hands
hold their objects. For any other hand, :func:`candidate_placements` finds object poses
``T_palm_object`` in the fingers' common workspace, best first:

1. **Where.** Each finger's tip-centre workspace is sampled (seeded, uniform in its joint
   box). A centre ``c`` can hold the object when every finger has tips in the shell
   where a fingertip touching the object can be, ``r_in + r_tip <= |p - c| <= r_out +
   r_tip`` (``r_in``, ``r_out``: the object's in- and circumradius about its centre).
   Centres on a 1 cm lattice are scored by the smallest such count over the fingers;
   the best few, at least 2 cm apart, are kept.
2. **How turned.** At each centre the object's z axis (a prism's axis) is pointed along
   each of nine fixed palm-frame directions (the axes and the diagonals). With a
   ``pivot`` finger, first along the opposition axis (from the pivot's tips in the
   shell to the other fingers') and along the pivot's mean pad direction there: the
   pivot then presses on an end face, the face a turn about the object's axis leaves
   in place.
3. **Screened.** For each pose, each finger's usable contacts at the start are counted
   (IK inside the limits with the choice margin, pad facing the surface: its joint-space
   manifold at one time, :func:`~regrasp_pin.grasp.manifold.build_manifold`); the
   pivot's count only those on an end face (normal within 10 deg of the object's z
   axis). A pose scores the smallest count over the fingers; poses that put the object within
   ``palm_clearance_m`` of the palm (the geometry that no finger moves) are dropped.

Scores are integer counts and ties keep the fixed order above, so the ranking is the
same on every machine. Whether a force-closure grasp exists, and lasts under the
motion, is decided afterwards by the grasp search
(:func:`~regrasp_pin.scenarios.scenario_for_hand`).

**Regrasp room.** A finger that holds a contact at the edge of its reach must soon
regrasp, and it can only land where its body keeps clear of the fingers that go on
holding. :func:`regrasp_room` counts, for each finger of a grasp, its usable contacts
(away from its own) at which its links stay a given distance from the other grasping
fingers' links at their contacts, at a few times of the motion: each pair of geometries
is bounded from below by capsules (:func:`~regrasp_pin.model.distances.capsule_pair_gaps`, for
all contacts at once) and measured by Coal only where the bound is below the distance.
The scenario search ranks grasps by the smallest count.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import coal
import numpy as np
import pinocchio as pin
from scipy.spatial.transform import Rotation

from ._validate import positive, positive_int
from .exceptions import InputError
from .grasp.contact import ContactModel
from .grasp.manifold import Manifold, build_manifold
from .grasp.screening import ObjectClearance
from .model.clearance import palm_clearance
from .model.distances import capsule_ends, capsule_pair_gaps
from .model.hand import Hand
from .model.motion import ObjectMotion
from .model.objects import ConvexObject, SurfaceSample

__all__ = [
    "END_FACE_COS",
    "Placement",
    "RegraspRoom",
    "candidate_placements",
    "regrasp_room",
    "workspace_centres",
]

#: A pivot's contact normal must be this close to the object's z axis (cos 10 deg).
END_FACE_COS = float(np.cos(np.radians(10.0)))

#: Directions (palm frame) along which the object's z axis is tried, in this order.
AXES = tuple(
    np.array(v, float) / np.linalg.norm(v)
    for v in [
        (1, 0, 0),
        (0, 1, 0),
        (0, 0, 1),
        (1, 1, 0),
        (1, -1, 0),
        (1, 0, 1),
        (1, 0, -1),
        (0, 1, 1),
        (0, 1, -1),
    ]
)


@dataclass(frozen=True)
class Placement:
    """An object pose at the start and how many usable contacts each finger has there.

    Attributes:
        T_palm_object: ``(4, 4)`` object pose in the palm frame.
        usable: Finger -> number of usable contact points (surface sample) at this pose.
    """

    T_palm_object: np.ndarray
    usable: dict[str, int]

    @property
    def score(self) -> int:
        """The smallest number of usable contacts over the fingers."""
        return min(self.usable.values())


@dataclass(frozen=True)
class _Workspace:
    """Tip-centre samples ``(S, 3)`` and pad directions ``(S, 3)`` of one finger."""

    tips: np.ndarray
    pads: np.ndarray
    tip_radius: float


def _workspaces(
    hand: Hand, fingers: Sequence[str], samples: int, seed: int
) -> dict[str, _Workspace]:
    rng = np.random.default_rng(seed)
    out = {}
    for name in fingers:
        f = hand.finger(name)
        q = rng.uniform(f.lower, f.upper, (samples, f.k))
        out[name] = _Workspace(f.fk(q), f.pad_normals(q), f.tip_radius)
    return out


def _shell(obj: ConvexObject) -> tuple[float, float]:
    """In- and circumradius of the object about its centre [m]."""
    r_in = float(-obj.signed_distance(np.zeros((1, 3)))[0])
    return r_in, float(np.linalg.norm(obj.vertices, axis=1).max())


def _pivot_axes(
    spaces: dict[str, _Workspace],
    fingers: Sequence[str],
    pivot: str,
    centre: np.ndarray,
    shell: tuple[float, float],
) -> list[np.ndarray]:
    """Object axes that put the pivot on an end face: the opposition axis (from the
    pivot's reachable tips to the other fingers') and the pivot's mean pad direction,
    both over the workspace samples in the contact shell about ``centre``."""
    near = {}
    for name, w in spaces.items():
        d = np.linalg.norm(w.tips - centre, axis=1)
        near[name] = (d >= shell[0] + w.tip_radius) & (d <= shell[1] + w.tip_radius)
    out = []
    w = spaces[pivot]
    others = [spaces[n].tips[near[n]] for n in fingers if n != pivot and near[n].any()]
    if near[pivot].any() and others:
        v = np.mean([o.mean(axis=0) for o in others], axis=0) - w.tips[near[pivot]].mean(axis=0)
        if np.linalg.norm(v) > 1e-9:
            out.append(v / np.linalg.norm(v))
    pad = w.pads[near[pivot]].sum(axis=0)
    if np.linalg.norm(pad) > 1e-9:
        out.append(pad / np.linalg.norm(pad))
    return out


def workspace_centres(
    hand: Hand,
    obj: ConvexObject,
    fingers: Sequence[str],
    *,
    count: int = 3,
    lattice_m: float = 0.01,
    samples: int = 3000,
    seed: int = 0,
) -> np.ndarray:
    """Up to ``count`` object centres ``(C, 3)`` (palm frame) where every finger can reach
    the object's surface, best first (see the module docstring, step 1).

    Raises:
        InputError: a non-positive count, lattice or sample number.
    """
    count = positive_int(count, "count")
    step = positive(lattice_m, "lattice_m")
    samples = positive_int(samples, "samples")
    r_in, r_out = _shell(obj)
    spaces = _workspaces(hand, fingers, samples, seed)
    tips = [(w.tips, w.tip_radius) for w in spaces.values()]
    allp = np.concatenate([p for p, _ in tips])
    lo, hi = allp.min(axis=0), allp.max(axis=0)
    axes = [np.arange(a, b + step, step) for a, b in zip(lo, hi, strict=True)]
    centres = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
    score = np.full(len(centres), np.iinfo(np.int64).max)
    for p, r_tip in tips:
        n = np.zeros(len(centres), np.int64)
        for s in range(0, len(centres), 512):
            d = np.linalg.norm(centres[s : s + 512, None, :] - p[None], axis=2)
            n[s : s + 512] = ((d >= r_in + r_tip) & (d <= r_out + r_tip)).sum(axis=1)
        score = np.minimum(score, n)
    order = np.lexsort((np.arange(len(centres)), -score))  # best first, ties by index
    chosen: list[np.ndarray] = []
    for i in order:
        if score[i] == 0 or len(chosen) == count:
            break
        if all(np.linalg.norm(centres[i] - c) >= 2 * step - 1e-9 for c in chosen):
            chosen.append(centres[i])
    return np.array(chosen).reshape(-1, 3)


def candidate_placements(
    hand: Hand,
    obj: ConvexObject,
    fingers: Sequence[str],
    *,
    contact: ContactModel | None = None,
    centres: int = 3,
    sample_spacing_m: float = 0.004,
    palm_clearance_m: float = 0.003,
    pivot: str | None = None,
    seed: int = 0,
) -> list[Placement]:
    """Object poses at which every finger has usable contacts, best first.

    Args:
        hand: The hand.
        obj: The object.
        fingers: The fingers that will grasp.
        contact: Contact model (margins, pad cone); default :class:`ContactModel`.
        centres: How many workspace centres to try (:func:`workspace_centres`).
        sample_spacing_m: Surface sample spacing of the screen [m].
        palm_clearance_m: Poses nearer than this to the palm's geometry are dropped [m].
        pivot: A finger whose pad should face an end face (see step 2), or None.
        seed: Seed of the workspace sampling.

    Returns:
        The screened placements with a positive score, highest score first (ties in
        the fixed order of centres and :data:`AXES`).

    Raises:
        InputError: no fingers, or a bad spacing or clearance.
        UnknownNameError: an unknown finger.
    """
    if not fingers:
        raise InputError("fingers", "is empty", "one or more finger names")
    contact = contact or ContactModel()
    spacing = positive(sample_spacing_m, "sample_spacing_m")
    clearance = positive(palm_clearance_m, "palm_clearance_m", allow_zero=True)
    if pivot is not None and pivot not in fingers:
        raise InputError("pivot", f"{pivot!r} is not one of the fingers", f"one of {fingers}")
    sample = obj.sample_surface(spacing)
    shell = _shell(obj)
    spaces = _workspaces(hand, fingers, 3000, seed) if pivot is not None else {}
    out: list[Placement] = []
    for c in workspace_centres(hand, obj, fingers, count=centres, seed=seed):
        axes = list(AXES)
        if pivot is not None:
            axes = _pivot_axes(spaces, fingers, pivot, c, shell) + axes
        for axis in axes:
            T = np.eye(4)
            T[:3, :3] = Rotation.align_vectors([axis], [[0.0, 0.0, 1.0]])[0].as_matrix()
            T[:3, 3] = c
            if palm_clearance(hand, obj, T[None])[0] < clearance:
                continue
            still = ObjectMotion.from_poses(np.array([0.0, 1.0]), np.stack([T, T]))
            usable = {}
            for name in fingers:
                m = build_manifold(
                    hand.finger(name), sample, still, np.array([0.0]), contact=contact
                )
                ok = m.usable(contact.choice_margin_rad)[0]
                if name == pivot:  # only its contacts on an end face count
                    ok = ok & (np.abs(sample.normals[:, 2]) >= END_FACE_COS)
                usable[name] = int(ok.sum())
            placement = Placement(T, usable)
            if placement.score > 0:
                out.append(placement)
    order = sorted(range(len(out)), key=lambda i: (-out[i].score, i))
    return [out[i] for i in order]


class RegraspRoom:
    """How many places each finger of a grasp could regrasp to without touching the others.

    For a grasp (finger -> contact), a finger's room at a manifold time is the number of
    sample points usable there (``margin_rad`` inside the limits, pad facing), at least
    one tip radius from the finger's own contact, at whose configuration the finger's
    links are at least ``clearance_m`` from the links of each other grasping finger
    (every finger of ``manifolds``, at its contact at that time, or where it last reached
    it). Distances are exact (Coal) where the capsule bound of a geometry pair is below
    ``clearance_m``. Fingers not in ``manifolds`` are not measured. A finger's clearances
    to one other finger at one contact and time are computed once and reused by every
    grasp that shares them.

    With ``obj``, a place also passes what
    :func:`~regrasp_pin.grasp.choice.choose_new_contact` asks of a new contact before
    its force closure: it is at least two tip radii + 1 mm from each other finger's
    contact, and at it the finger's other links keep ``contact.choice_link_clearance_m``
    from the object and its fingertip link sinks in by at most
    ``contact.tip_penetration_m`` (Coal, once per finger and time).

    Args:
        hand: The hand.
        manifolds: finger -> its manifold (every grasping finger, the same times).
        sample: The surface sample the manifolds map.
        margin_rad: Joint-limit margin of a usable contact [rad].
        clearance_m: Smallest distance [m] to the other fingers' links.
        obj: The object (None: the places are not screened against it).
        contact: The thresholds of that screening (default ``ContactModel()``).
    """

    def __init__(
        self,
        hand: Hand,
        manifolds: Mapping[str, Manifold],
        sample: SurfaceSample,
        *,
        margin_rad: float,
        clearance_m: float,
        obj: ConvexObject | None = None,
        contact: ContactModel | None = None,
    ) -> None:
        self.hand, self.manifolds, self.sample = hand, manifolds, sample
        self.obj, self.contact = obj, contact or ContactModel()
        self.margin = float(margin_rad)
        self.clearance = float(clearance_m)
        self._usable: dict[tuple[str, int], np.ndarray] = {}
        self._clear: dict[tuple[str, int, str, int], np.ndarray] = {}
        # the capsule ends of a finger at its usable contacts, per (finger, time index)
        self._ends: dict[tuple[str, int], tuple[np.ndarray, np.ndarray]] = {}
        self._data = hand.model.createData()
        self._gdata = pin.GeometryData(hand.collision_model)
        self._req, self._res = coal.DistanceRequest(), coal.DistanceResult()

    def __call__(
        self, indices: Mapping[str, int], fingers: Sequence[str], time_indices: Sequence[int]
    ) -> dict[str, int]:
        """Each finger's room at the grasp ``indices`` (finger -> index into the sample,
        every finger of the manifolds): the smallest count over the manifold times
        ``time_indices`` (0 without times)."""
        return {
            name: min((self.count(indices, name, int(k)) for k in time_indices), default=0)
            for name in fingers
        }

    def count(self, indices: Mapping[str, int], name: str, k: int) -> int:
        """The room of ``name`` at manifold time index ``k`` (an integer count)."""
        key = (name, k)
        if key not in self._usable:
            self._usable[key] = self._places(name, k)
        cand = self._usable[key]
        pts = self.sample.points[cand]
        tip_radius = self.hand.finger(name).tip_radius
        ok = np.linalg.norm(pts - self.sample.points[int(indices[name])], axis=1) >= tip_radius
        for other in self.manifolds:
            if other == name:
                continue
            if self.obj is not None:  # the chooser's separation from the other contacts
                p_other = self.sample.points[int(indices[other])]
                ok &= np.linalg.norm(pts - p_other, axis=1) >= 2 * tip_radius + 0.001
            ok &= self._clear_of(name, k, other, int(indices[other]))
        return int(np.count_nonzero(ok))

    def _places(self, name: str, k: int) -> np.ndarray:
        """The sample indices usable by ``name`` at time index ``k`` and, with an
        object, clear of it there (see the class docstring)."""
        man = self.manifolds[name]
        cand = np.flatnonzero(man.usable(self.margin)[k])
        if self.obj is None or cand.size == 0:
            return cand
        clear = ObjectClearance(self.hand, name, self.obj, self.contact)
        return cand[clear(self.hand.to_full(name, man.q[k, cand]), man.T_palm_object[k])]

    def _clear_of(self, name: str, k: int, other: str, i_other: int) -> np.ndarray:
        """``(C,)`` whether each usable contact of ``name`` at time index ``k`` keeps the
        finger ``clearance`` from ``other`` holding its contact ``i_other`` then (where
        it last reached it, if it no longer does)."""
        key = (name, k, other, i_other)
        if key in self._clear:
            return self._clear[key]
        hand = self.hand
        f, g = hand.finger(name), hand.finger(other)
        cand = self._usable[(name, k)]
        q_held = self.manifolds[other].q[: k + 1, i_other]
        reached = np.flatnonzero(np.isfinite(q_held).all(axis=1))
        ok = np.ones(cand.size, bool)
        if cand.size and reached.size:
            rows = np.repeat(hand.neutral()[None], cand.size, axis=0)
            rows[:, g.q_indices] = q_held[reached[-1]]
            rows[:, f.q_indices] = self.manifolds[name].q[k, cand]
            # geometry pairs whose capsules come within the clearance, and where: the
            # finger's capsules once per time, the other's at its one configuration
            if (name, k) not in self._ends:
                self._ends[(name, k)] = capsule_ends(hand, list(f.geometry_ids), rows)
            close = capsule_pair_gaps(
                hand,
                list(f.geometry_ids),
                list(g.geometry_ids),
                ends_a=self._ends[(name, k)],
                ends_b=capsule_ends(hand, list(g.geometry_ids), rows[:1]),
            )
            close = close < self.clearance
            near = [
                (a, b, close[ia, ib])
                for ia, a in enumerate(f.geometry_ids)
                for ib, b in enumerate(g.geometry_ids)
                if close[ia, ib].any()
            ]
            if near:
                self._measure(rows, near, ok)
        self._clear[key] = ok
        return ok

    def _measure(
        self, rows: np.ndarray, near: list[tuple[int, int, np.ndarray]], ok: np.ndarray
    ) -> None:
        """Clear ``ok[r]`` where a pair of ``near`` (geometry ids, the rows where their
        capsules are close) is closer than the clearance at ``rows[r]`` (Coal)."""
        model, cm = self.hand.model, self.hand.collision_model
        objs = cm.geometryObjects
        for r in np.flatnonzero(np.any([m for _, _, m in near], axis=0)):
            pin.forwardKinematics(model, self._data, rows[r])
            pin.updateGeometryPlacements(model, self._data, cm, self._gdata)
            for a, b, m in near:
                if not m[r]:
                    continue
                self._res.clear()
                d = coal.distance(
                    objs[a].geometry,
                    self._gdata.oMg[a],
                    objs[b].geometry,
                    self._gdata.oMg[b],
                    self._req,
                    self._res,
                )
                if d < self.clearance:
                    ok[r] = False
                    break


def regrasp_room(
    hand: Hand,
    manifolds: Mapping[str, Manifold],
    sample: SurfaceSample,
    indices: Mapping[str, int],
    fingers: Sequence[str],
    time_indices: Sequence[int],
    *,
    margin_rad: float,
    clearance_m: float,
    obj: ConvexObject | None = None,
    contact: ContactModel | None = None,
) -> dict[str, int]:
    """The room to regrasp of each finger of ``fingers`` at the grasp ``indices``
    (finger -> sample index), the smallest over the manifold times ``time_indices``:
    :class:`RegraspRoom`, counted once."""
    room = RegraspRoom(
        hand,
        manifolds,
        sample,
        margin_rad=margin_rad,
        clearance_m=clearance_m,
        obj=obj,
        contact=contact,
    )
    return room(indices, fingers, time_indices)
