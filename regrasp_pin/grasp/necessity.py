"""What every plan must do: the intervals in which a finger cannot let go.

A finger may be in the air at a time only if the other fingers can hold the object
without it. Over the manifolds' time grid this module computes, per finger, an *upper
bound* of that: whether the contacts that any other finger could use at that time
(inside its joint limits, pad facing: ``Manifold.usable(0.0)``) could, all together,
be in force closure. Where even that set is not, no grasp without the finger exists,
so the finger must hold; a maximal run of such times is a :class:`MustHold`.

Within a run the finger holds *one* contact: changing contact means a flight, and a
flight longer than the grid step leaves the finger in the air at some grid time of
the run. So the finger's contact must stay usable at every time of the run; if none
of its contacts does (or, for a run at the start, not the contact it starts on), no
plan exists from there: :func:`first_infeasibility`. The planner fails early with
``FailureKind.INFEASIBLE`` and :func:`~regrasp_pin.grasp.initial.initial_grasp` keeps
only the contacts that last through a run at the start.

Why it is a proof, and of what (docs/manifold.md):

- the union of every other finger's usable contacts contains every grasp those
  fingers could make (one contact each, any of them joining), and a set whose wrenches
  do not positively span the wrench space has no subset that does;
- friction cones are *circumscribed* polygons (``mu / cos(pi / n_edges)``): they
  contain the exact cone and so every inscribed cone the planner tests with;
- a face's contacts are replaced by the corners of the bounding box of their face
  coordinates: a wrench is linear in the contact point for a fixed normal, so this
  only adds wrenches;
- holding needs only ``margin >= 0`` here (the planner asks for more);
- fewer than three fingers never hold (two point contacts cannot resist a torque
  about the line through them); with torsional friction (soft fingertips) two may,
  and each cone edge then spins about the normal by ``+-torsion_m`` as well (a box
  around the soft-finger model's elliptic limit surface, so again a superset).

It assumes what the planner does: contacts are the surface sample's points, a hold
stays on one object point, and every flight lasts longer than the manifolds' time step.
Which contacts are usable is what the manifolds' IK (with its restarts) finds; the
planner checks a grasp it is given against its own tracking of the contacts instead.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
from scipy.optimize import nnls

from ..model.hand import Hand
from ..model.motion import ObjectMotion
from ..model.objects import ConvexObject, SurfaceSample
from .contact import ContactModel
from .manifold import Manifold, build_manifolds
from .quality import contact_wrenches, holding_fingers

__all__ = [
    "MustHold",
    "closure_possible_with",
    "closure_possible_without",
    "first_infeasibility",
    "must_hold",
    "with_idle_fingers",
]

CONE_EDGES = 8  # edges of the circumscribed friction cones
SPAN_TOL = 1e-8  # relative residual below which wrenches count as positively spanning


@dataclass(frozen=True)
class MustHold:
    """A maximal run of manifold times at which ``finger`` cannot let go.

    Attributes:
        finger: The finger.
        k_from, k_to: First and last manifold time index of the run (inclusive).
        t_from_s, t_to_s: The same as times [s].
        lasting: ``(N,)`` bool per sample point: usable (margin >= 0) by the finger at
            every time of the run; the finger's contact must be one of these.
    """

    finger: str
    k_from: int
    k_to: int
    t_from_s: float
    t_to_s: float
    lasting: np.ndarray

    @property
    def duration_s(self) -> float:
        """Length of the run [s]."""
        return self.t_to_s - self.t_from_s

    @property
    def possible(self) -> bool:
        """Whether any contact of the finger lasts through the run."""
        return bool(self.lasting.any())


def with_idle_fingers(
    hand: Hand,
    manifolds: Mapping[str, Manifold],
    sample: SurfaceSample,
    motion: ObjectMotion,
    contact: ContactModel,
) -> dict[str, Manifold]:
    """``manifolds`` and, on the same times, those of the hand's other fingers: an idle
    finger may join in place of one that lets go, so it counts among those that could
    hold (its manifold is the one a join would build)."""
    times = next(iter(manifolds.values())).times_s
    idle = [n for n in hand.finger_names if n not in manifolds]
    built = build_manifolds(hand, idle, sample, motion, times, contact=contact)
    return {**manifolds, **built}


def _face_corners(
    obj: ConvexObject, sample: SurfaceSample, usable: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per time, the corners of each face's bounding box of usable points.

    Returns ``(points (T, F, 4, 3), normals (F, 3), present (T, F))`` in the object
    frame; ``present`` says which faces have a usable point at that time.
    """
    n_t = usable.shape[0]
    n_f = len(obj.faces)
    pts = np.zeros((n_t, n_f, 4, 3))
    present = np.zeros((n_t, n_f), bool)
    for face in obj.faces:  # few faces; all times at once
        j = np.flatnonzero(sample.face_ids == face.id)
        if j.size == 0:
            continue
        mask = usable[:, j]
        present[:, face.id] = mask.any(axis=1)
        uv = sample.uv[j]
        lo = np.where(mask[..., None], uv[None], np.inf).min(axis=1)  # (T, 2)
        hi = np.where(mask[..., None], uv[None], -np.inf).max(axis=1)
        lo = np.where(np.isfinite(lo), lo, 0.0)
        hi = np.where(np.isfinite(hi), hi, 0.0)
        corners = np.stack(
            [lo, np.c_[lo[:, 0], hi[:, 1]], hi, np.c_[hi[:, 0], lo[:, 1]]], axis=1
        )  # (T, 4, 2)
        pts[:, face.id] = face.from_uv(corners)
    return pts, np.asarray(obj.normals, float), present


def _positively_spanning(wrenches: np.ndarray) -> bool:
    """Whether some strictly positive combination of the rows sums to zero (an upper
    bound of force closure: true for every force-closure set)."""
    if wrenches.shape[0] < 7:
        return False
    # lambda = 1 + x, x >= 0: sum_i lambda_i w_i = 0 has a solution iff this
    # non-negative least-squares residual is 0; a residual within the tolerance counts
    # as a solution, so that rounding can only make the bound looser
    b = -wrenches.sum(axis=0)
    try:
        _, residual = nnls(wrenches.T, b)
    except RuntimeError:  # no convergence: claim nothing
        return True
    return bool(residual <= SPAN_TOL * max(1.0, float(np.linalg.norm(b))))


def _outer_wrenches(
    p: np.ndarray, n: np.ndarray, mu_out: float, torsion_m: float, scale_m: float
) -> np.ndarray:
    """``(k * edges, 6)`` wrenches of contacts ``p``, ``n`` ``(k, 3)`` whose cone hull
    contains every wrench the contact can apply: the circumscribed cone's
    :data:`CONE_EDGES` edges (friction ``mu_out``), each also spinning by
    ``+-torsion_m`` about the normal when ``torsion_m > 0`` (a box around the
    soft-finger model's ellipse)."""
    w = contact_wrenches(p, n, mu_out, n_edges=CONE_EDGES, torque_scale_m=scale_m)
    if torsion_m <= 0.0:
        return w
    w = w.reshape(len(p), CONE_EDGES, 6)
    spin = np.zeros((len(p), 1, 6))
    spin[:, 0, 3:] = torsion_m * np.asarray(n, float) / scale_m
    return np.concatenate([w + spin, w - spin], axis=1).reshape(-1, 6)


def closure_possible_without(
    manifolds: Mapping[str, Manifold],
    sample: SurfaceSample,
    obj: ConvexObject,
    finger: str,
    mu: float,
    min_fingers: int | None = None,
    torsion_m: float = 0.0,
) -> np.ndarray:
    """``(T,)`` bool over the manifolds' times: whether the contacts that the fingers
    other than ``finger`` could use then could be in force closure (an upper bound;
    False proves that no grasp without ``finger`` exists at that time).

    Args:
        manifolds: Every finger that may hold, on one time grid.
        sample: The surface sample the manifolds were built on.
        obj: The object.
        finger: The finger left out.
        mu: Friction coefficient.
        min_fingers: Fewest fingers that can hold; None: 3 for point contacts (two
            cannot resist a torque about the line through them), 2 with torsional
            friction (:func:`~.quality.holding_fingers`).
        torsion_m: Torsional friction of the contacts [m] (0: point contacts).
    """
    if min_fingers is None:
        min_fingers = holding_fingers(torsion_m)
    others = [m.usable(0.0) for name, m in manifolds.items() if name != finger]
    if len(others) < min_fingers:
        return np.zeros(manifolds[finger].times_s.size, bool)
    enough = np.sum([u.any(axis=1) for u in others], axis=0) >= min_fingers
    usable = np.logical_or.reduce(others)
    corners, normals, present = _face_corners(obj, sample, usable)
    mu_out = mu / np.cos(np.pi / CONE_EDGES)
    ks = np.flatnonzero(enough & present.any(axis=1))
    out = np.zeros(usable.shape[0], bool)
    if ks.size == 0:
        return out
    # the cone edges at every (time, face) corner in one call, row for row what one
    # call per time gives; a time's rows are contiguous (faces in ascending order)
    kk, ff = np.nonzero(present[ks])
    wrenches = _outer_wrenches(
        corners[ks[kk], ff].reshape(-1, 3),
        np.repeat(normals[ff], 4, axis=0),
        mu_out,
        torsion_m,
        obj.radius_m,
    ).reshape(kk.size, -1, 6)
    bounds = np.searchsorted(kk, np.arange(ks.size + 1))
    memo: dict[bytes, bool] = {}
    for row, k in enumerate(ks):
        faces = ff[bounds[row] : bounds[row + 1]]
        key = faces.tobytes() + corners[k, faces].tobytes()
        if key not in memo:
            memo[key] = _positively_spanning(wrenches[bounds[row] : bounds[row + 1]].reshape(-1, 6))
        out[k] = memo[key]
    return out


def closure_possible_with(
    points: np.ndarray,
    normals: np.ndarray,
    manifold: Manifold,
    sample: SurfaceSample,
    obj: ConvexObject,
    mu: float,
    rows: np.ndarray,
    torsion_m: float = 0.0,
) -> bool:
    """Whether the contacts ``points``, ``normals`` ``(F, 3)`` (object frame) plus one
    contact that ``manifold``'s finger could use at one of the manifold times ``rows``
    could be in force closure: an upper bound, as :func:`closure_possible_without`'s
    (circumscribed cones; the finger's usable points replaced by the corners of their
    bounding box on their face), one face at a time: the one contact lies on one face,
    so the fixed contacts with that face's corners must positively span, whatever the
    other faces offer. False proves that no contact of that finger landed at those
    times puts them in force closure (e.g. frees a finger whose neighbours do not hold
    without it). ``torsion_m``: the contacts' torsional friction [m]."""
    rows = np.asarray(rows, int)
    if rows.size == 0:
        return False
    corners, face_normals, present = _face_corners(obj, sample, manifold.usable(0.0, rows=rows))
    mu_out = mu / np.cos(np.pi / CONE_EDGES)

    def wrenches(p: np.ndarray, n: np.ndarray) -> np.ndarray:
        return _outer_wrenches(p, n, mu_out, torsion_m, obj.radius_m)

    fixed = wrenches(
        np.asarray(points, float).reshape(-1, 3), np.asarray(normals, float).reshape(-1, 3)
    )
    tested: set[bytes] = set()  # a face's corners at several times: one test
    for k in range(rows.size):
        for face in np.flatnonzero(present[k]):
            key = int(face).to_bytes(4, "little") + corners[k, face].tobytes()
            if key in tested:
                continue
            tested.add(key)
            mine = wrenches(corners[k, face], np.repeat(face_normals[[face]], 4, 0))
            if _positively_spanning(np.vstack([fixed, mine])):
                return True
    return False


def must_hold(
    manifolds: Mapping[str, Manifold],
    sample: SurfaceSample,
    obj: ConvexObject,
    mu: float,
    fingers: tuple[str, ...] | list[str] | None = None,
    min_fingers: int | None = None,
    until_s: float | None = None,
    torsion_m: float = 0.0,
) -> list[MustHold]:
    """Every run of times at which a finger cannot let go, by finger then time.

    Args:
        manifolds: Every finger that may hold, on one time grid.
        sample: The surface sample the manifolds were built on.
        obj: The object.
        mu: Friction coefficient.
        fingers: The fingers to examine (default: all of ``manifolds``).
        min_fingers: Fewest fingers that can hold (:func:`closure_possible_without`;
            None: by ``torsion_m``).
        until_s: Times after this claim nothing [s]; None: every time.
        torsion_m: Torsional friction of the contacts [m] (0: point contacts).
    """
    out = []
    for name in fingers if fingers is not None else list(manifolds):
        man = manifolds[name]
        free = closure_possible_without(
            manifolds, sample, obj, name, mu, min_fingers, torsion_m=torsion_m
        )
        if until_s is not None:
            free |= man.times_s > until_s + 1e-9
        usable = man.usable(0.0)
        edges = np.flatnonzero(np.diff(np.r_[1, free.astype(np.int8), 1]))
        for a, b in zip(edges[::2], edges[1::2] - 1, strict=True):
            out.append(
                MustHold(
                    finger=name,
                    k_from=int(a),
                    k_to=int(b),
                    t_from_s=float(man.times_s[a]),
                    t_to_s=float(man.times_s[b]),
                    lasting=np.asarray(usable[a : b + 1].all(axis=0)),
                )
            )
    return out


def first_infeasibility(
    runs: list[MustHold], start: Mapping[str, int] | None = None, t_index: int = 0
) -> MustHold | None:
    """The earliest run that no contact lasts through (or, for a run at ``t_index``,
    that the finger's starting contact ``start[finger]`` does not), else None."""
    bad = [
        r
        for r in runs
        if r.k_to >= t_index
        and (
            not r.lasting[start[r.finger]]
            if start is not None and r.finger in start and r.k_from <= t_index
            else not r.possible
        )
    ]
    return min(bad, key=lambda r: (r.k_from, r.finger), default=None)
