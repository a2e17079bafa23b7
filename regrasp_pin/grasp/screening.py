"""Screening a finger's contacts: the tests a new contact and an initial grasp share.

- :class:`ScreeningEpsilons`: the Ferrari-Canny epsilon of contact sets with
  :data:`SCREEN_EDGES` cone edges and a fixed torque scale, each set computed once,
  and whether they are in force closure (mostly without the hull);
  :func:`leave_one_out`: the epsilons with each contact left out in turn, and
  :func:`closes_without`: whether the rest is in force closure.
- :class:`ObjectClearance`: a finger at a candidate contact clears the object (Coal);
  :func:`passes_object_clearance` and :func:`closest_object_miss`: that test on its
  distances, and of the candidates that fail it the one nearest to passing.
- :func:`held_clear`: held at a contact, the finger stays clear of the object over the
  manifold's times, as the tracking measures it (Coal).
- :class:`ManifoldClearance`: those Coal distances at a manifold's (time, point)
  entries, each measured once for the searches of a whole plan (a lower bound spares
  the query where it already meets the requirements).
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

import numpy as np

from .._validate import positive_int
from ..exceptions import InputError
from ..model.clearance import LinkClearance
from ..model.distances import object_gap_bounds
from ..model.hand import Hand
from ..model.objects import ConvexObject
from .contact import ContactModel
from .manifold import Manifold
from .quality import (
    FORCE_CLOSURE_TOL,
    closure_certificate,
    contact_wrenches,
    ferrari_canny_epsilon,
    is_force_closure,
)

__all__ = [
    "PLANNER_EDGES",
    "SCREEN_EDGES",
    "ManifoldClearance",
    "ObjectClearance",
    "ScreeningEpsilons",
    "closes_without",
    "closest_object_miss",
    "held_clear",
    "leave_one_out",
    "passes_object_clearance",
]

SCREEN_EDGES = 6  # friction-cone edges used when screening candidates
PLANNER_EDGES = 8  # the planner's own force-closure test's (ferrari_canny_epsilon's default)


class ScreeningEpsilons:
    """The screening epsilon (:data:`SCREEN_EDGES` edges, a fixed torque scale) of
    contact sets, each set computed once: a pure function of the contacts in their
    order (the same bits in, the same hull out), which the grasp search asks for again
    and again (a combination found by several trials, a leave-one-out set shared by
    combinations that differ in the left-out finger). ``torsion_m``: the contacts'
    torsional friction [m] (:attr:`~.contact.ContactModel.torsion_m`; 0: point
    contacts)."""

    def __init__(self, mu: float, scale_m: float, torsion_m: float = 0.0) -> None:
        self.mu = mu
        self.scale_m = scale_m
        self.torsion_m = torsion_m
        self._known: dict[tuple[bytes, bytes], float] = {}
        self._closes: dict[tuple[bytes, bytes], bool] = {}
        # the planner's test (PLANNER_EDGES): force closure and, where read, epsilons
        self._planner_closes: dict[tuple[bytes, bytes], bool] = {}
        self._planner_known: dict[tuple[bytes, bytes], float] = {}

    def __call__(self, p: np.ndarray, n: np.ndarray) -> float:
        """The screening epsilon of contacts ``p``, ``n`` ``(F, 3)`` (object frame)."""
        key = _key(p, n)
        if key not in self._known:
            self._known[key] = ferrari_canny_epsilon(
                p,
                n,
                self.mu,
                n_edges=SCREEN_EDGES,
                torque_scale_m=self.scale_m,
                torsion_m=self.torsion_m,
            )
        return self._known[key]

    def closes(self, p: np.ndarray, n: np.ndarray) -> bool:
        """Whether contacts ``p``, ``n`` ``(F, 3)`` are in force closure: their screening
        epsilon ``> FORCE_CLOSURE_TOL``, the same answer as ``self(p, n)`` gives, but
        decided without the hull where :func:`~.quality.closure_certificate` can (about
        a seventh of its time)."""
        key = _key(p, n)
        if key not in self._known and key not in self._closes:
            w = contact_wrenches(
                p,
                n,
                self.mu,
                n_edges=SCREEN_EDGES,
                torque_scale_m=self.scale_m,
                torsion_m=self.torsion_m,
            )
            certain = closure_certificate(w, FORCE_CLOSURE_TOL)
            if certain is not None:
                self._closes[key] = certain
        if key in self._closes:
            return self._closes[key]
        return self(p, n) > FORCE_CLOSURE_TOL  # the hull, kept by __call__

    def planner_closes(self, p: np.ndarray, n: np.ndarray) -> bool:
        """:func:`~.quality.is_force_closure` of contacts ``p``, ``n`` ``(F, 3)`` with
        the planner's :data:`PLANNER_EDGES` cone edges (this torque scale), each set
        decided once."""
        return bool(self._planner_once(self._planner_closes, is_force_closure, p, n))

    def planner_epsilon(self, p: np.ndarray, n: np.ndarray) -> float:
        """:func:`~.quality.ferrari_canny_epsilon` of contacts ``p``, ``n`` ``(F, 3)``
        with the planner's :data:`PLANNER_EDGES` cone edges (this torque scale), each
        set's hull computed once."""
        return float(self._planner_once(self._planner_known, ferrari_canny_epsilon, p, n))

    def _planner_once(
        self, table: dict[tuple[bytes, bytes], Any], test: Any, p: np.ndarray, n: np.ndarray
    ) -> Any:
        """``test(p, n)`` with the planner's cone edges and this torque scale, kept in
        ``table`` by the contact set's numbers."""
        key = _key(p, n)
        if key not in table:
            table[key] = test(
                p,
                n,
                self.mu,
                n_edges=PLANNER_EDGES,
                torque_scale_m=self.scale_m,
                torsion_m=self.torsion_m,
            )
        return table[key]


def _key(p: np.ndarray, n: np.ndarray) -> tuple[bytes, bytes]:
    """A contact set's cache key: its numbers, in order."""
    return (np.ascontiguousarray(p).tobytes(), np.ascontiguousarray(n).tobytes())


def leave_one_out(
    p: np.ndarray,
    n: np.ndarray,
    mu: float,
    scale_m: float,
    rows: Iterable[int],
    epsilons: ScreeningEpsilons | None = None,
) -> list[float]:
    """The screening epsilon of contacts ``p``, ``n`` ``(F, 3)`` with each of ``rows``
    left out in turn (> 0: the others hold without it); from ``epsilons`` if given
    (they carry the contacts' torsion; else point contacts)."""
    eps = epsilons or ScreeningEpsilons(mu, scale_m)
    return [eps(np.delete(p, j, 0), np.delete(n, j, 0)) for j in rows]


def closes_without(
    p: np.ndarray,
    n: np.ndarray,
    rows: Iterable[int],
    epsilons: ScreeningEpsilons,
) -> list[bool]:
    """Whether contacts ``p``, ``n`` ``(F, 3)`` with each of ``rows`` left out in turn
    are in force closure: :func:`leave_one_out`'s epsilons ``> FORCE_CLOSURE_TOL``, from
    :meth:`ScreeningEpsilons.closes` (mostly without hulls)."""
    return [epsilons.closes(np.delete(p, j, 0), np.delete(n, j, 0)) for j in rows]


#: A lower bound spares the Coal query of a :class:`ManifoldClearance` entry when it
#: meets the requirement by this much [m] (Coal's GJK tolerance is 1e-9 m).
BOUND_MARGIN_M = 1e-6

#: The times :func:`held_clear` measures first for each point; the runs then double.
HELD_FIRST_RUN = 4


class ManifoldClearance:
    """The Coal distances [m] of one finger, held at its manifold's points, to the
    object: from its other links and from its fingertip link (negative when sunk in),
    each ``(time index, point)`` entry measured once.

    An entry is a pure function of the manifold's configuration and object pose there,
    so the answers are the same bits as measuring afresh; the searches of one plan ask
    for the same entries again and again (the same candidates at the next lift-off
    time, after a failed attempt, when backing up). Their readers compare them with the
    contact model's requirements only, so an entry whose lower bound
    (:func:`~regrasp_pin.model.distances.object_gap_bounds`) already meets the largest of
    them by :data:`BOUND_MARGIN_M` keeps that bound instead of a Coal query: a distance
    below ``max(link_clearance_m, choice_link_clearance_m)`` (links) or
    ``-tip_penetration_m`` (fingertip link) is exact, one above may be a lower bound.

    Args:
        hand: The hand.
        finger: Finger name.
        obj: The object.
        manifold: The finger's manifold (the entries' configurations and poses).
        contact: The requirements the readers compare with (default ``ContactModel()``).

    Attributes:
        n_queries: Configurations measured by Coal so far (the links' and the fingertip
            link's counted apart).
    """

    def __init__(
        self,
        hand: Hand,
        finger: str,
        obj: ConvexObject,
        manifold: Manifold,
        contact: ContactModel | None = None,
    ):
        self.hand, self.finger, self.manifold = hand, finger, manifold
        self.contact = contact or ContactModel()
        self.obj = obj
        self._links = LinkClearance(hand, finger, obj)
        self._tip = LinkClearance(hand, finger, obj, tip_only=True)
        c = self.contact
        self._exact_below = (
            max(c.link_clearance_m, c.choice_link_clearance_m) + BOUND_MARGIN_M,
            -c.tip_penetration_m + BOUND_MARGIN_M,
        )
        shape = (int(manifold.q.shape[0]), int(manifold.q.shape[1]))  # (times, points)
        self._known = np.zeros(shape, bool)  # entries measured
        self._values = np.empty((*shape, 2))  # their (links, tip) distances [m]
        self.n_queries = 0  # configurations measured by Coal (links and tip apart)

    def __call__(self, rows: np.ndarray, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(links, tip)`` distances ``(M,)`` [m] at the manifold entries
        ``(rows[j], points[j])`` (time indices and sample indices, ``(M,)`` each); exact
        below the requirements (see the class)."""
        r = np.asarray(rows, np.int64).reshape(-1)
        c = np.asarray(points, np.int64).reshape(-1)
        unknown = ~self._known[r, c]
        if unknown.any():
            n = int(self._known.shape[1])
            new_r, new_c = np.divmod(np.unique(r[unknown] * n + c[unknown]), n)
            full = self.hand.to_full(self.finger, self.manifold.q[new_r, new_c])
            T = self.manifold.T_palm_object[new_r]
            clearances = (self._links, self._tip)
            bounds = object_gap_bounds(
                self.hand, [m.geometry_ids for m in clearances], self.obj, full, T
            )
            for j, (m, below) in enumerate(zip(clearances, self._exact_below, strict=True)):
                self._values[new_r, new_c, j] = self._exact_where_low(m, bounds[j], full, T, below)
            self._known[new_r, new_c] = True
        out = self._values[r, c]
        return out[:, 0], out[:, 1]

    def _exact_where_low(
        self,
        clearance: LinkClearance,
        bound: np.ndarray,
        full: np.ndarray,
        T: np.ndarray,
        exact_below: float,
    ) -> np.ndarray:
        """The lower bounds ``bound`` of the configurations ``full``, replaced by Coal's
        distance where a bound is below ``exact_below`` [m]."""
        out = bound.copy()
        low = np.flatnonzero(out < exact_below)
        if low.size:
            out[low] = clearance(full[low], T[low])
            self.n_queries += int(low.size)
        return out


class ObjectClearance:
    """Whether a finger at a candidate contact clears the object: its other links by
    ``contact.choice_link_clearance_m``, its fingertip link not sunk in by more than
    ``contact.tip_penetration_m`` (Coal)."""

    def __init__(self, hand: Hand, finger: str, obj: ConvexObject, contact: ContactModel):
        self.links = LinkClearance(hand, finger, obj)
        self.tip = LinkClearance(hand, finger, obj, tip_only=True)
        self.contact = contact

    def __call__(self, q_full: np.ndarray, T_palm_object: np.ndarray) -> np.ndarray:
        """``(N,)`` bool for the ``(N, nq)`` configurations at the object pose(s)."""
        return passes_object_clearance(*self.distances(q_full, T_palm_object), self.contact)

    def distances(
        self, q_full: np.ndarray, T_palm_object: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """``(links, tip)`` Coal distances ``(N,)`` [m] to the object (negative when
        inside) of the ``(N, nq)`` configurations at the object pose(s)."""
        return self.links(q_full, T_palm_object), self.tip(q_full, T_palm_object)


def passes_object_clearance(
    links: np.ndarray, tip: np.ndarray, contact: ContactModel
) -> np.ndarray:
    """``(N,)`` bool: a finger at a candidate contact whose other links are ``links`` and
    whose fingertip link is ``tip`` [m] from the object (:meth:`ObjectClearance.distances`)
    clears it: ``contact.choice_link_clearance_m`` and ``contact.tip_penetration_m``."""
    return (links >= contact.choice_link_clearance_m) & (tip >= -contact.tip_penetration_m)


def closest_object_miss(
    links: np.ndarray, tip: np.ndarray, contact: ContactModel
) -> tuple[float, float] | None:
    """Of the candidates that do not pass :func:`passes_object_clearance`, the one
    nearest to passing: ``(measured, required)`` [m] of the requirement it misses by the
    least (its links' distance and ``choice_link_clearance_m``, or its fingertip link's
    and ``-tip_penetration_m``; negative: inside the object); None if all pass."""
    links, tip = np.atleast_1d(np.asarray(links, float)), np.atleast_1d(np.asarray(tip, float))
    short_links = contact.choice_link_clearance_m - links  # > 0: missed by that much
    short_tip = -contact.tip_penetration_m - tip
    worse = np.maximum(short_links, short_tip)
    miss = np.flatnonzero(worse > 0.0)
    if miss.size == 0:
        return None
    j = int(miss[np.argmin(worse[miss])])  # the first of equals
    if short_links[j] >= short_tip[j]:
        return float(links[j]), float(contact.choice_link_clearance_m)
    return float(tip[j]), float(-contact.tip_penetration_m)


def check_kept_clearance(
    distances: ManifoldClearance, finger: str, manifold: Manifold, contact: ContactModel
) -> None:
    """InputError unless ``distances`` are ``finger``'s on ``manifold``, kept for the
    requirements of ``contact`` (above them its entries may be lower bounds)."""
    if distances.manifold is not manifold or distances.finger != finger:
        raise InputError(
            "distances",
            f"are {distances.finger!r}'s, on another manifold or finger",
            f"a ManifoldClearance of {finger!r} on this manifold",
        )
    if distances.contact != contact:
        raise InputError(
            "distances",
            "were kept for another contact model",
            "a ManifoldClearance made with the same ContactModel",
        )


def held_clear(
    hand: Hand,
    finger: str,
    obj: ConvexObject,
    manifold: Manifold,
    points: np.ndarray,
    ka: int,
    contact: ContactModel,
    distances: ManifoldClearance | None = None,
    horizon: int | None = None,
) -> np.ndarray:
    """``(K, C)`` bool over the manifold's times from index ``ka``: the points are usable
    (``contact.limit_margin_rad``) and, held there, the finger's other links keep
    ``contact.link_clearance_m`` from the object and its fingertip link sinks in by at
    most ``contact.tip_penetration_m`` (Coal), at that time and every one before it.

    Only the times up to a column's first failure are measured (what comes after cannot
    change it): the times before the point leaves the usable set, in runs that double
    in length (:data:`HELD_FIRST_RUN` times first) until the column fails or ends.
    ``distances``: where the distances are kept between calls (the finger's, on this
    manifold); None: measured afresh. ``horizon``: only the first ``horizon`` times from
    ``ka`` are asked about (``K = min(horizon, times - ka)``), and only they are
    measured."""
    if distances is None:
        distances = ManifoldClearance(hand, finger, obj, manifold, contact)
    else:
        check_kept_clearance(distances, finger, manifold, contact)
    points = np.asarray(points, np.int64).reshape(-1)
    end = None if horizon is None else ka + positive_int(horizon, "horizon", minimum=1)
    usable = manifold.usable(contact.limit_margin_rad, rows=slice(ka, end), points=points)
    # the times before each column first leaves the usable set: rows 0 .. n_rows - 1
    n_rows = np.logical_and.accumulate(usable, axis=0).sum(axis=0)
    ok = np.zeros(usable.shape, bool)
    done = np.zeros(points.size, np.int64)  # rows measured so far, per column
    open_cols = np.flatnonzero(n_rows > 0)
    run = HELD_FIRST_RUN
    while open_cols.size:
        start = done[open_cols]
        length = np.minimum(start + run, n_rows[open_cols]) - start
        cols = np.repeat(open_cols, length)
        rows = np.repeat(start - np.cumsum(length) + length, length) + np.arange(length.sum())
        d, d_tip = distances(ka + rows, points[cols])
        passed = (d >= contact.link_clearance_m) & (d_tip >= -contact.tip_penetration_m)
        ok[rows, cols] = passed
        failed = np.zeros(points.size, bool)
        failed[cols[~passed]] = True
        done[open_cols] = start + length
        open_cols = open_cols[~failed[open_cols] & (done[open_cols] < n_rows[open_cols])]
        run *= 2
    return np.logical_and.accumulate(ok, axis=0)
