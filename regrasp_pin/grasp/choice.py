"""Choosing the new contact Q (the paper's conditions (a) and (b)); the initial grasp is
chosen in :mod:`.initial`, with the screening shared from here.

Condition (a): Q lies inside the boundary planes (and is feasible) at the time the
finger can arrive, ``t_arrive`` = trigger time + regrasp duration (between two
manifold times, at both: the pad may turn away between them). Condition (b): among
those, Q stays inside longest over the rest of the motion (read from
``Manifold.holdable``: inside the limits, pad facing, and the fingertip link not
reaching past the plane the tip rests on). Ties are broken by the
larger joint margin at arrival, then by the shorter distance from P.

Beyond the paper, the grasp must keep holding: Q's fingertip sphere must stand clear of
the other fingers' (``TIP_GAP_M`` apart, each resting on its contact's normal), the
other contacts plus Q must be in force closure, and Q should keep or improve the grasp
quality (Ferrari-Canny epsilon) that P gave with the others. Candidates are taken in the
order of (b) and tested (and a Coal check that no other link of the finger touches the
object at arrival); among the first four that pass, Q is the one after which most other
fingers could let go with the rest in force closure (so that a finger that must regrasp
later can), then one that keeps the quality, then the first; the result says whether the
quality was kept.

What the manifold does not model (the finger's other links reaching the object, a
holding neighbour coming near) only shortens a hold, so the manifold's exit times bound
the real ones from above: the first candidates' exit times are cut by it and all are
ranked again, and again while uncut candidates come first (:func:`_rerank`), so that
the head of the order is the one the real exit times give.

"Distance from P" is the straight-line distance in the object frame (a lower bound of
the surface distance; it is only a tie-breaker).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace

import numpy as np

from ..exceptions import ContactError, FailureKind, InputError
from ..model.clearance import FingerClearance
from ..model.hand import Finger, Hand
from ..model.objects import ConvexObject, SurfaceSample
from .contact import ContactModel
from .manifold import Manifold
from .quality import FORCE_CLOSURE_TOL, holding_fingers, kept_quality
from .screening import (
    ManifoldClearance,
    ScreeningEpsilons,
    check_kept_clearance,
    closes_without,
    closest_object_miss,
    held_clear,
    passes_object_clearance,
)

__all__ = [
    "DISTANCE_TOL_M",
    "apart_threshold",
    "TIP_GAP_M",
    "NewContact",
    "Room",
    "choose_new_contact",
    "exit_times",
    "tip_gap",
]

#: The gap kept between a new contact's fingertip sphere and another finger's [m].
TIP_GAP_M = 0.001
#: Distances within this of a separation or exclusion radius meet it [m]: the surface
#: sample's points lie on grids, so a distance between two of them is often exactly
#: such a radius, and its last bits (the sample's placement by matrix products) follow
#: the machine's BLAS kernels; such a point is kept on every machine
DISTANCE_TOL_M = 1e-9
_REMOVABLE_WINDOW = 4  # passing candidates compared by how many fingers could let go
_LINK_BATCH = 64  # candidates whose link clearance is measured at once (Coal)
_NEAREST_SETS = 8  # refused contact sets whose epsilons a force-closure failure reads


@dataclass(frozen=True, eq=False)
class Room:
    """Room a new contact leaves for another finger's landing.

    Attributes:
        point: The other finger's contact to be, object frame ``(3,)`` [m].
        radius_m: Candidates closer than this to ``point`` (by more than
            :data:`DISTANCE_TOL_M`) are not chosen [m].
        finger: Optionally, that finger, standing at ``q_finger`` [rad] at ``t_s`` [s]
            (e.g. its arrival configuration there): the choosing finger, held at a
            candidate (its manifold's configuration at ``t_s``), must then stand at
            least the choice's finger clearance from it (Coal), so that neither
            finger's links take the other's place.
        q_finger: See ``finger``, ``(k,)`` [rad].
        t_s: See ``finger`` [s].
    """

    point: np.ndarray
    radius_m: float
    finger: str | None = None
    q_finger: np.ndarray | None = None
    t_s: float | None = None

    @classmethod
    def of(cls, room: Room | tuple[np.ndarray, float]) -> Room:
        """``room``, or a ``(point, radius)`` pair as a Room."""
        if isinstance(room, Room):
            return room
        point, radius = room
        return cls(np.asarray(point, float), float(radius))


@dataclass(frozen=True)
class NewContact:
    """The chosen new contact Q.

    Attributes:
        finger: Finger name.
        index: Index of Q in the surface sample.
        p_object: Q, object frame ``(3,)`` [m].
        n_object: Outward normal at Q, object frame ``(3,)``.
        q_arrive: ``(k,)`` finger configuration at arrival [rad].
        t_arrive_s: Arrival time [s].
        exit_time_s: First grid time after arrival at which Q stops being usable (the
            motion's end if never) [s].
        margin_rad: Joint margin at arrival [rad].
        distance_from_P_m: Straight distance from P [m].
        epsilon: Ferrari-Canny epsilon of the other contacts plus Q.
        epsilon_with_P: Epsilon of the other contacts plus P (the quality to keep).
        quality_kept: Whether ``epsilon >= epsilon_with_P``.
        n_candidates: Number of candidates that satisfied condition (a).
        rank: Position of Q in the order of condition (b) (0 = the paper's choice).
    """

    finger: str
    index: int
    p_object: np.ndarray
    n_object: np.ndarray
    q_arrive: np.ndarray
    t_arrive_s: float
    exit_time_s: float
    margin_rad: float
    distance_from_P_m: float
    epsilon: float
    epsilon_with_P: float
    quality_kept: bool
    n_candidates: int
    rank: int


def exit_times(usable: np.ndarray, times_s: np.ndarray, start: int) -> np.ndarray:
    """First time at or after grid index ``start`` at which each point is not usable.

    Args:
        usable: ``(T, N)`` boolean.
        times_s: ``(T,)`` grid times [s].
        start: Grid index to start from.

    Returns:
        ``(N,)`` exit times [s]; ``times_s[-1]`` for points usable to the end, and
        ``times_s[start]`` for points not usable at ``start``.
    """
    tail = usable[start:]
    never_leaves = tail.all(axis=0)
    first_bad = np.argmin(tail, axis=0)  # index of the first False
    out = times_s[start + first_bad]
    out[never_leaves] = times_s[-1]
    return out


def choose_new_contact(
    hand: Hand,
    obj: ConvexObject,
    manifold: Manifold,
    sample: SurfaceSample,
    t_arrive_s: float,
    *,
    P_object: np.ndarray,
    n_P_object: np.ndarray,
    others: Mapping[str, tuple[np.ndarray, np.ndarray]],
    contact: ContactModel | None = None,
    mu: float = 0.8,
    min_separation_m: float | None = None,
    link_check: bool = True,
    max_checks: int = 60,
    exclude_radius_m: float = 0.0,
    exclude_points_object: np.ndarray | None = None,
    exclude_points_radius_m: float | None = None,
    q_hand_arrive: np.ndarray | None = None,
    finger_clearance_m: float = 0.002,
    exit_tolerance_s: float = 0.0,
    rerank: int = 12,
    lasting: Callable[[np.ndarray, int, np.ndarray], np.ndarray] | None = None,
    reserved: Sequence[Room | tuple[np.ndarray, float]] = (),
    distances: ManifoldClearance | None = None,
    epsilons: ScreeningEpsilons | None = None,
    landing_s: Callable[[np.ndarray], np.ndarray] | None = None,
    land_by_s: float = math.inf,
    frees: Sequence[str] = (),
    absent: Sequence[str] = (),
) -> NewContact:
    """Choose Q for ``manifold.finger`` (see the module docstring).

    Args:
        hand: The hand.
        obj: The object.
        manifold: The finger's manifold over times that reach the end of the motion.
        sample: The surface sample the manifold was built on.
        t_arrive_s: When the finger can land [s].
        P_object: The contact being released, object frame ``(3,)`` [m].
        n_P_object: Its outward normal.
        others: The contacts that keep holding: finger -> (point, outward normal),
            object frame.
        contact: Contact model (margin for condition (a), link clearance).
        mu: Friction coefficient for the grasp-quality test.
        min_separation_m: Smallest distance from the other contacts [m]; default:
            the fingertip spheres resting on Q and on each other contact (along
            their normals) ``TIP_GAP_M`` apart (``2 * tip_radius + 1 mm`` between the
            points on one face).
        link_check: Check with Coal that no other link of the finger touches the
            object at arrival.
        max_checks: Most candidates given the (slower) force-closure test, in the
            order of the ranking. Candidates refused before it, for their links
            (Coal, in batches) or for their finger clearance (one Coal pass each,
            about 70 us), do not count: the choice may read every candidate.
        exclude_radius_m: Candidates closer than this to P (and to each of
            ``exclude_points_object``; by more than :data:`DISTANCE_TOL_M`) are ignored
            [m].
        exclude_points_object: ``(E, 3)`` points to stay away from (e.g. contacts
            for which no verified path was found).
        exclude_points_radius_m: Radius around each of ``exclude_points_object``
            [m]; default ``exclude_radius_m``.
        q_hand_arrive: ``(nq,)`` hand configuration at arrival (the other fingers
            holding), at the manifold time whose joint coordinates judge the finger
            there (:func:`judging_time`, the first at or after ``t_arrive_s``); when
            given, Q must put the finger at least ``finger_clearance_m`` from the other
            fingers (Coal).
        finger_clearance_m: See ``q_hand_arrive`` [m].
        exit_tolerance_s: With a positive value, exit times that differ by less than
            this are ties, broken by the shorter distance from P and then the margin
            (instead of the margin first). 0 keeps the paper's order exactly.
        rerank: How many of the first candidates get their exit times cut by what the
            manifold does not model (the finger's other links, ``lasting``) and are
            ranked again.
        lasting: Optional ``(points (C,), ka, horizon (C,)) -> (K, C)`` bool over the
            manifold's times from index ``ka`` on: False where something else ends the
            contact (e.g. another holding finger comes too near); applied in the
            re-rank, where only each point's first ``horizon`` times are read (the
            times before its links or its limits end it; the rest may be anything).
        reserved: :class:`Room` s (or ``(point, radius)`` pairs, object frame [m])
            kept free for another finger's landing: candidates closer than the radius
            to the point are ignored, and with a room's finger posture, those whose
            finger would stand nearer it than ``finger_clearance_m`` too.
        distances: The finger's link-object distances on ``manifold``, kept between
            calls (the searches of one plan ask for the same entries again); None:
            measured afresh. The same choice either way.
        epsilons: The screening epsilons of contact sets, kept between calls (with
            ``mu`` and the object's radius as torque scale); None: computed afresh.
        landing_s: Optional ``(C, k) -> (C,)``: the earliest time [s] the finger can
            land at each arrival configuration (e.g. from the joint velocity limits);
            candidates that would land after ``land_by_s`` [s] are not chosen.
        land_by_s: See ``landing_s`` [s].
        frees: Fingers of ``others`` that Q must free: with Q landed, the other
            contacts without any one of them are still in force closure
            (:func:`~.quality.is_force_closure`, the planner's test before a finger
            lifts off), for a finger whose neighbours do not hold without it now.
        absent: Fingers left out of the finger-clearance test (``q_hand_arrive``):
            fingers supposed elsewhere at arrival, e.g. a neighbour asked to make room
            (in ``q_hand_arrive`` such a finger stands where it does not hold).

    Returns:
        The :class:`NewContact`.

    Raises:
        ContactError: no candidate satisfies condition (a), or none keeps the other
            fingers' grasp in force closure or frees the ``frees`` fingers
            (``force-closure``, "not freeing"), or every one would land too late
            (``too-late``); the message says which finger, when, why.
        InputError: ``t_arrive_s`` is NaN or outside the manifold's times; ``frees``
            is a string or names a finger not in ``others``; ``absent`` is a string,
            names a finger of ``others``, the finger itself or no finger of the hand;
            ``reserved`` is not a sequence of rooms (a point not ``(3,)``, a radius not
            finite and >= 0, a posture not of another finger's joints at a time of the
            manifold).
    """
    contact = contact or ContactModel()
    finger = hand.finger(manifold.finger)
    if isinstance(frees, str) or not set(frees) <= set(others):
        raise InputError(
            "frees", f"is {frees!r}", f"a sequence of names of others: {sorted(others)}"
        )
    away = sorted(set(hand.finger_names) - set(others) - {finger.name})
    if not isinstance(absent, Sequence) or isinstance(absent, str) or not set(absent) <= set(away):
        raise InputError(
            "absent", f"is {absent!r}", f"a sequence of names of fingers not holding: {away}"
        )
    ka, kb = _arrival_indices(manifold, t_arrive_s)
    rooms = _rooms(reserved)
    postures = [_posture(hand, finger, manifold, r, ka) for r in rooms if r.finger is not None]
    # the landing falls between two manifold times: Q must be usable at both
    cand = manifold.usable(contact.choice_margin_rad, rows=np.array([ka, min(kb, ka)])).all(0)
    pts = sample.points
    kept = [int(cand.sum())]  # how many each test keeps, for a failure's message
    cand &= _apart_from(hand, finger, sample, others, min_separation_m)
    kept.append(int(cand.sum()))
    if exclude_radius_m > 0:
        cand &= _far_from(pts, [P_object], exclude_radius_m)
    kept.append(int(cand.sum()))
    if exclude_points_object is not None:
        r_ex = exclude_radius_m if exclude_points_radius_m is None else exclude_points_radius_m
        ex = np.asarray(exclude_points_object, float).reshape(-1, 3)
        cand &= _far_from(pts, list(ex), max(r_ex, 1e-12))
    for room in rooms:
        cand &= _far_from(pts, [np.asarray(room.point, float)], float(room.radius_m))
    idx = np.flatnonzero(cand)
    if idx.size == 0:
        usable = manifold.usable(contact.limit_margin_rad, rows=np.array([ka]))[0]
        raise ContactError(
            f"no surface point is inside the joint limits (margin >= "
            f"{contact.choice_margin_rad:.2f} rad), faces the pad and is clear of the other "
            f"contacts at arrival ({int(usable.sum())} usable before the separation test; "
            + _emptied_words(kept, exclude_radius_m)
            + ")",
            finger=finger.name,
            time_s=float(manifold.times_s[ka]),
            kind=FailureKind.NO_CANDIDATE,
            measured=float(kept[0]),  # inside the limits with the choice margin
            required=1.0,
        )
    if landing_s is not None:
        idx = _landing_in_time(idx, manifold, ka, landing_s, land_by_s, finger.name)
    # condition (b) read from the contacts the finger can hold: inside the limits and,
    # as far as the fingertip link's shape tells, without it sinking into the face
    holdable = manifold.holdable(contact.limit_margin_rad, rows=slice(ka, None), points=idx)
    ranked = _Ranking(
        t_exit=exit_times(holdable, manifold.times_s[ka:], 0),
        margin=manifold.margin_rad[ka, idx],
        dist=np.linalg.norm(pts[idx] - P_object, axis=1),
        idx=idx,
        exit_tolerance_s=exit_tolerance_s,
    )
    lasts = holdable[-1].copy()
    order = ranked.order(lasts)
    if link_check:
        # one store for the call's link measurements (the re-rank's first times are the
        # arrival's), or the one kept between calls
        if distances is None:
            distances = ManifoldClearance(hand, finger.name, obj, manifold, contact)
        else:
            check_kept_clearance(distances, finger.name, manifold, contact)
    if link_check and rerank > 0:
        ranked, order = _rerank(
            ranked,
            lasts,
            rerank,
            max_checks,
            lambda top: _link_exit(
                hand, finger.name, obj, manifold, idx[top], ka, contact, lasting, distances
            ),
        )
    screen = _Screen(
        hand,
        finger,
        obj,
        manifold,
        sample,
        ka,
        others,
        mu,
        _arrival_clearance(manifold, ka, distances)
        if link_check and distances is not None
        else None,
        contact,
        q_hand_arrive,
        finger_clearance_m,
        epsilons,
        frees=[list(others).index(n) for n in frees],
        absent=absent,
        postures=postures,
    )
    return screen.first(order, ranked, P_object, n_P_object, max_checks)


def _landing_in_time(
    idx: np.ndarray,
    manifold: Manifold,
    ka: int,
    landing_s: Callable[[np.ndarray], np.ndarray],
    land_by_s: float,
    finger: str,
) -> np.ndarray:
    """The candidates of ``idx`` whose earliest landing (``landing_s`` of their arrival
    configurations) is by ``land_by_s`` [s]; ContactError (``too-late``) if none is."""
    landing = np.asarray(landing_s(manifold.q[ka, idx]), float)
    if landing.shape != idx.shape or not np.isfinite(landing).all():
        raise InputError(
            "landing_s",
            f"returned {landing.shape} values, finite: {bool(np.isfinite(landing).all())}",
            f"a finite landing time [s] for each of the {idx.size} candidates",
        )
    keep = landing <= land_by_s
    if not keep.any():
        earliest = float(landing.min())
        raise ContactError(
            f"every candidate would land after t={land_by_s:.3f} s within the joint "
            f"velocity limits (the earliest at t={earliest:.3f} s)",
            finger=finger,
            time_s=float(manifold.times_s[ka]),
            kind=FailureKind.TOO_LATE,
            measured=earliest,
            required=float(land_by_s),
        )
    return idx[keep]


def _arrival_clearance(
    manifold: Manifold, ka: int, distances: ManifoldClearance
) -> Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]:
    """``points (C,) -> (links, tip)``: held at the sample ``points`` at the manifold
    time ``ka``, the distances ``(C,)`` [m] of the finger's other links and of its
    fingertip link to the object, from ``distances`` (exact below the requirements)."""
    return lambda points: distances(np.full(points.size, ka), points)


def judging_time(manifold: Manifold, t_arrive_s: float) -> float:
    """The manifold time [s] at which :func:`choose_new_contact` judges a landing at
    ``t_arrive_s`` [s]: the first at or after it (raises InputError outside the
    manifold's times); ``q_hand_arrive`` belongs to it."""
    return float(manifold.times_s[_arrival_indices(manifold, t_arrive_s)[0]])


def _arrival_indices(manifold: Manifold, t_arrive_s: float) -> tuple[int, int]:
    """The manifold's time indices around a landing at ``t_arrive_s`` [s]: the first
    time at or after it and the last time at or before it (raises InputError outside)."""
    t_arrive = float(t_arrive_s)
    t0, t1 = float(manifold.times_s[0]), float(manifold.times_s[-1])
    if not t0 - 1e-9 <= t_arrive <= t1 + 1e-9:  # also rejects NaN
        raise InputError(
            "t_arrive_s",
            f"{t_arrive_s!r} is outside the manifold's times",
            f"a time in [{t0:.6g}, {t1:.6g}] s",
        )
    ka = manifold.time_index(t_arrive)
    kb = max(int(np.searchsorted(manifold.times_s, t_arrive + 1e-9)) - 1, 0)
    return ka, kb


def tip_gap(
    hand: Hand,
    a: str,
    contact_a: tuple[np.ndarray, np.ndarray],
    b: str,
    contact_b: tuple[np.ndarray, np.ndarray],
) -> float:
    """The gap [m] between the fingertip spheres of fingers ``a`` and ``b`` resting on
    their contacts ``(point, outward unit normal)`` (object frame [m]): the distance of
    the centres ``p + r n`` less the two radii (negative where they overlap)."""
    ra, rb = hand.finger(a).tip_radius, hand.finger(b).tip_radius
    ca = np.asarray(contact_a[0], float) + ra * np.asarray(contact_a[1], float)
    cb = np.asarray(contact_b[0], float) + rb * np.asarray(contact_b[1], float)
    return float(np.linalg.norm(ca - cb)) - ra - rb


def _emptied_words(kept: list[int], exclude_radius_m: float) -> str:
    """How the tests of :func:`choose_new_contact` left no candidate, in words, from
    ``kept``: how many points the choice margin at both arrival indices kept, then
    apart from the other contacts, then away from P (the rest: failed points, rooms)."""
    words = (
        f"{kept[0]} with the margin at both arrival times, {kept[1]} of them apart from "
        "the other contacts"
    )
    if exclude_radius_m > 0:
        words += f", {kept[2]} of those at least {exclude_radius_m * 1e3:.1f} mm from P"
    if kept[2]:
        words += ", none of those away from the points that failed before and the rooms"
    return words


def _apart_from(
    hand: Hand,
    finger: Finger,
    sample: SurfaceSample,
    others: Mapping[str, tuple[np.ndarray, np.ndarray]],
    min_separation_m: float | None,
) -> np.ndarray:
    """``(N,)`` whether each sample point is far enough from the other contacts: at
    least ``min_separation_m`` from each when given, else with the two fingertip
    spheres resting there (each on its own normal) ``TIP_GAP_M`` apart (within
    :data:`DISTANCE_TOL_M`: :func:`apart_threshold`). On one face
    that is ``2 r + 1 mm`` between the points; across an edge the spheres stand
    further apart than their points (the normals diverge), so it admits more."""
    if min_separation_m is not None:
        return _far_from(sample.points, [p for p, _ in others.values()], min_separation_m)
    ok = np.ones(len(sample.points), bool)
    centres = sample.points + finger.tip_radius * sample.normals
    for name, (p, n) in others.items():
        r = hand.finger(name).tip_radius
        c = np.asarray(p, float) + r * np.asarray(n, float)
        gap = np.linalg.norm(centres - c, axis=1)
        ok &= gap >= apart_threshold(finger.tip_radius + r + TIP_GAP_M)
    return ok


def _rooms(reserved: object) -> list[Room]:
    """``reserved`` as Rooms; InputError unless it is a sequence of Rooms or ``(point,
    radius)`` pairs with a finite point ``(3,)`` [m] and a finite radius >= 0 [m]."""
    wanted = "a sequence of Rooms or (point (3,), radius >= 0) pairs [m]"
    if isinstance(reserved, (Room, str)) or not isinstance(reserved, Sequence):
        raise InputError("reserved", f"is {reserved!r}", wanted)
    rooms = []
    for r in reserved:
        try:
            room = Room.of(r)
            point, radius = np.asarray(room.point, float), float(room.radius_m)
        except (TypeError, ValueError) as exc:
            raise InputError("reserved", f"holds {r!r}", wanted) from exc
        if point.shape != (3,) or not np.isfinite(point).all() or not radius >= 0.0:
            raise InputError("reserved", f"holds {r!r}", wanted)
        rooms.append(room)
    return rooms


def _posture(
    hand: Hand, finger: Finger, manifold: Manifold, room: Room, ka: int
) -> tuple[FingerClearance, np.ndarray, int]:
    """``(finger's clearance to room.finger, the hand at room.q_finger, time index)``
    of a room with a finger posture: the index of ``room.t_s``, not before the
    arrival's ``ka`` (a candidate is read where the finger holds it); InputError for
    a posture that is not one of another finger of the hand at a time of the
    manifold."""
    times = manifold.times_s
    names = [n for n in hand.finger_names if n != finger.name]
    q = np.asarray(room.q_finger, float) if room.q_finger is not None else None
    t = float(room.t_s) if room.t_s is not None else math.nan
    k = hand.finger(room.finger).k if room.finger in names else -1
    if (
        q is None
        or q.shape != (k,)
        or not np.isfinite(q).all()
        or not times[0] - 1e-9 <= t <= times[-1] + 1e-9  # also rejects NaN
    ):
        raise InputError(
            "reserved",
            f"holds a room of finger {room.finger!r} with q_finger {room.q_finger!r} "
            f"at t_s {room.t_s!r}",
            f"one of the fingers {names}, its finite joint values [rad] and a time in "
            f"[{times[0]:.6g}, {times[-1]:.6g}] s",
        )
    clear = FingerClearance.shared(hand, finger.name, [str(room.finger)])
    row = max(manifold.time_index(t), ka)
    return clear, hand.to_full(str(room.finger), q), row


def apart_threshold(radius_m: float) -> float:
    """The distance [m] from which two points count as ``radius_m`` apart: the radius
    within :data:`DISTANCE_TOL_M` (``radius_m - DISTANCE_TOL_M``; a radius below twice
    that: ``min(radius_m, DISTANCE_TOL_M)``, so that a point is still near itself), so
    that points of the sample's grids exactly a radius apart are apart on every
    machine."""
    if radius_m >= 2 * DISTANCE_TOL_M:
        return radius_m - DISTANCE_TOL_M
    return min(radius_m, DISTANCE_TOL_M)  # about the tolerance: what is nearer (itself)


def _far_from(pts: np.ndarray, centres: list[np.ndarray], radius_m: float) -> np.ndarray:
    """``(N,)`` True where a point is at least ``radius_m`` from every centre, within
    :data:`DISTANCE_TOL_M` (:func:`apart_threshold`)."""
    ok = np.ones(pts.shape[0], bool)
    least = apart_threshold(radius_m)
    for c in centres:
        ok &= np.linalg.norm(pts - c, axis=1) >= least
    return ok


@dataclass(frozen=True)
class _Ranking:
    """The candidates' keys (exit time, margin, distance from P; ``idx``: their sample
    indices) and the order they give."""

    t_exit: np.ndarray
    margin: np.ndarray
    dist: np.ndarray
    idx: np.ndarray
    exit_tolerance_s: float

    def order(self, lasts: np.ndarray) -> np.ndarray:
        """Candidate positions, best first (``lasts``: usable to the end)."""
        # the order must not follow last-bit noise of the IK: keys on a 1e-9 lattice
        t_exit = self.t_exit
        margin_key, dist_key = np.round(self.margin, 9), np.round(self.dist, 9)
        if self.exit_tolerance_s > 0:
            # exit times within the tolerance of each other count as ties; among them the
            # shorter move first (a short move is less likely to cross another finger)
            # (on the 1e-9 lattice too: grid times carry float noise, e.g. 4.800000000000001,
            # and a ratio of exactly 2.0 must not fall into bin 1 or 2 by one ulp)
            bins = np.floor(np.round((t_exit.max() - t_exit) / self.exit_tolerance_s, 9))
            return np.lexsort((self.idx, -margin_key, dist_key, bins))
        # (b), then margin, then distance; a point usable to the end outlasts one that
        # leaves at the last grid time (both have exit time times_s[-1])
        return np.lexsort((self.idx, dist_key, -margin_key, ~lasts, -t_exit))


class _Screen:
    """The slower tests of a ranked candidate, cheapest first: the finger's links clear
    of the object and of the other fingers at arrival, force closure with the other
    contacts."""

    def __init__(
        self,
        hand: Hand,
        finger: Finger,
        obj: ConvexObject,
        manifold: Manifold,
        sample: SurfaceSample,
        ka: int,
        others: Mapping[str, tuple[np.ndarray, np.ndarray]],
        mu: float,
        link_clear: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]] | None,
        contact: ContactModel,
        q_hand_arrive: np.ndarray | None,
        finger_clearance_m: float,
        epsilons: ScreeningEpsilons | None = None,
        frees: Sequence[int] = (),
        absent: Sequence[str] = (),
        postures: Sequence[tuple[FingerClearance, np.ndarray, int]] = (),
    ) -> None:
        self.hand, self.finger, self.manifold, self.sample = hand, finger, manifold, sample
        self.ka = ka
        self.other_p = np.array([p for p, _ in others.values()]).reshape(-1, 3)
        self.other_n = np.array([n for _, n in others.values()]).reshape(-1, 3)
        if epsilons is None:
            epsilons = ScreeningEpsilons(mu, obj.radius_m, contact.torsion_m)
        elif (epsilons.mu, epsilons.scale_m, epsilons.torsion_m) != (
            mu,
            obj.radius_m,
            contact.torsion_m,
        ):
            raise InputError(
                "epsilons",
                f"use mu={epsilons.mu}, scale {epsilons.scale_m} m, torsion {epsilons.torsion_m} m",
                f"mu={mu}, the object's radius {obj.radius_m} m and the contact "
                f"model's torsion {contact.torsion_m} m",
            )
        self.epsilons = epsilons
        self.link_clear, self.contact = link_clear, contact
        self.q_hand_arrive = q_hand_arrive
        self.finger_clearance_m = finger_clearance_m
        # the finger-clearance tests, (clearance, hand configuration, time index): the
        # other fingers (but the absent) at arrival, then the rooms' finger postures
        # (:func:`_posture`)
        self.clearances = list(postures)
        if q_hand_arrive is not None:
            present = [n for n in hand.finger_names if n not in absent] if absent else None
            arrival = FingerClearance.shared(hand, finger.name, present)
            self.clearances.insert(0, (arrival, q_hand_arrive, ka))
        self.frees = tuple(frees)  # rows of the other contacts that Q must free
        # the contact sets refused for force closure and for not freeing a finger: their
        # epsilons (6-D hulls) are computed only if the choice fails for that reason
        self.refused: dict[str, list[tuple[np.ndarray, np.ndarray]]] = {
            "force closure": [],
            "not freeing": [],
        }
        self.rejected = {
            "force closure": 0,
            "link clearance": 0,
            "finger clearance": 0,
            "not freeing": 0,
        }
        # per reason, the rejected candidate nearest to passing: (measured, required),
        # and for the finger clearance the finger it came nearest to
        self.closest: dict[str, tuple[float, float]] = {}
        self.closest_other: str | None = None
        self.window = _REMOVABLE_WINDOW

    def with_others(self, p: np.ndarray, n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The other contacts and ``(p, n)``: points and normals ``(F, 3)``."""
        return np.vstack([self.other_p, p[None]]), np.vstack([self.other_n, n[None]])

    def eps(self, p: np.ndarray, n: np.ndarray) -> float:
        """Ferrari-Canny epsilon of the other contacts and ``(p, n)`` (each set's hull
        computed once)."""
        return self.epsilons(*self.with_others(p, n))

    def links_clear(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(C,)`` bool: the finger at the sample ``points`` keeps its links clear of the
        object at arrival (all True without the test); and the Coal distances ``(links,
        tip)`` [m] behind it (NaN without the test)."""
        if self.link_clear is None:
            nan = np.full(points.size, np.nan)
            return np.ones(points.size, bool), nan, nan
        links, tip = self.link_clear(points)
        return passes_object_clearance(links, tip, self.contact), links, tip

    def _reject(self, why: str, measured: float, required: float, other: str | None = None) -> None:
        """Count a rejection and keep the one nearest to passing (the largest
        ``measured - required``; the first of equals), with ``other``, the finger a
        finger-clearance rejection came nearest to."""
        self.rejected[why] += 1
        best = self.closest.get(why)
        if best is None or measured - required > best[0] - best[1]:
            self.closest[why] = (measured, required)
            if why == "finger clearance":
                self.closest_other = other

    def _reject_links(self, links: np.ndarray, tip: np.ndarray) -> None:
        """Count the candidates refused for their links, whose distances are ``links``
        and ``tip`` [m], and keep the one nearest to passing
        (:func:`closest_object_miss`, the first of equals)."""
        self.rejected["link clearance"] += int(links.size)
        miss = closest_object_miss(links, tip, self.contact)
        if miss is not None:
            self.closest["link clearance"] = miss

    def rejection(self, i: int, p: np.ndarray, n: np.ndarray) -> str | None:
        """Why sample point ``i`` at ``(p, n)`` (its links already clear of the object)
        is refused, or None; a refusal is counted (:attr:`rejected`, :attr:`closest`).
        The finger clearance is tested first: one Coal pass, where the epsilon is a 6-D
        hull; a candidate that fails both counts as a finger-clearance rejection. Force
        closure is decided by :meth:`ScreeningEpsilons.closes` (mostly without the hull),
        with the other contacts, then without each of :attr:`frees` in turn ("not
        freeing", :func:`~.quality.is_force_closure`); a refused contact set is kept
        (:attr:`refused`) for the failure's numbers."""
        for clear_of, q_hand, k in self.clearances:
            q_all = np.array(q_hand, float)
            q_all[self.finger.q_indices] = self.manifold.q[k, i]
            d = clear_of(q_all)
            if d < self.finger_clearance_m:
                _, other = clear_of.nearest(q_all)  # measured: from the memo
                self._reject("finger clearance", d, self.finger_clearance_m, other)
                return "finger clearance"
        p_all, n_all = self.with_others(p, n)
        if not self.epsilons.closes(p_all, n_all):
            self.rejected["force closure"] += 1
            self.refused["force closure"].append((p_all, n_all))
            return "force closure"
        for row in self.frees:
            p_rest, n_rest = np.delete(p_all, row, 0), np.delete(n_all, row, 0)
            if not self.epsilons.planner_closes(p_rest, n_rest):
                self.rejected["not freeing"] += 1
                self.refused["not freeing"].append((p_rest, n_rest))
                return "not freeing"
        return None

    def _closest_refused(self, why: str) -> None:
        """Of the first :data:`_NEAREST_SETS` contact sets refused for ``why`` (force
        closure or not freeing), in the order of the ranking, the one nearest to
        passing, by its epsilon (the test's own: the screening epsilon, or the
        planner's with 8 cone edges), kept in :attr:`closest` (the first of equals);
        computed only for a failure that this refusal binds (each is a 6-D hull, and
        every refused set's epsilon is at most the tolerance)."""
        sets = self.refused.get(why, [])[:_NEAREST_SETS]
        if not sets:
            return
        if why == "force closure":
            eps = [self.epsilons(p, n) for p, n in sets]
        else:
            eps = [self.epsilons.planner_epsilon(p, n) for p, n in sets]
        self.closest[why] = (max(eps), FORCE_CLOSURE_TOL)  # max: the first of equals

    def removable(self, p: np.ndarray, n: np.ndarray) -> int:
        """How many of the other contacts could let go, with ``(p, n)`` landed, the rest
        staying in force closure."""
        k = self.other_p.shape[0]
        if k < holding_fingers(self.epsilons.torsion_m):
            return 0
        closes = closes_without(
            np.vstack([self.other_p, p[None]]),
            np.vstack([self.other_n, n[None]]),
            range(k),
            self.epsilons,
        )
        return sum(closes)

    def first(
        self,
        order: np.ndarray,
        ranked: _Ranking,
        P_object: np.ndarray,
        n_P_object: np.ndarray,
        max_checks: int,
    ) -> NewContact:
        """Among the first ``self.window`` candidates in ``order`` that pass, the one
        after which most other fingers could let go, then the first that keeps the grasp
        quality of P, then the first; ContactError (the most frequent rejection) if none
        passes.

        The link clearance is tested first, in batches of ``_LINK_BATCH`` candidates in
        order (Coal); at most ``max_checks`` candidates whose links clear the object and
        the other fingers get the slower quality test (a finger-clearance refusal costs
        one Coal pass and does not count). The epsilons (6-D hulls) of P and of a
        passing candidate are computed only where the choice reads them."""
        pts, normals, idx = self.sample.points, self.sample.normals, ranked.idx
        P, n_P = np.asarray(P_object, float), np.asarray(n_P_object, float)

        def kept(i: int) -> bool:
            return kept_quality(self.eps(pts[i], normals[i]), self.eps(P, n_P))

        passing: list[tuple[int, int, int]] = []  # (removable, position, candidate)
        k = self.other_p.shape[0]
        best_removable = k if k >= holding_fingers(self.epsilons.torsion_m) else 0
        clear = np.zeros(order.size, bool)
        links, tip = np.zeros(order.size), np.zeros(order.size)  # [m]
        screened = tested = 0
        refused: list[int] = []  # positions refused for their links (counted at the end)
        for position, j in enumerate(order):
            if tested >= max_checks:
                break
            if position % _LINK_BATCH == 0:
                batch = slice(position, position + _LINK_BATCH)
                clear[batch], links[batch], tip[batch] = self.links_clear(idx[order[batch]])
            if not clear[position]:
                refused.append(position)
                continue
            screened += 1
            i = int(idx[j])
            why = self.rejection(i, pts[i], normals[i])
            if why != "finger clearance":
                tested += 1
            if why is not None:
                continue
            r = self.removable(pts[i], normals[i]) if self.window > 1 else 0
            passing.append((r, position, int(j)))
            if len(passing) >= self.window or (r == best_removable and kept(i)):
                break
        if not passing:
            self._reject_links(links[refused], tip[refused])
            raise self.failure(screened + self.rejected["link clearance"], idx.size, screened)
        most = max(r for r, _, _ in passing)
        # among those after which most fingers could let go (in order): the first that
        # keeps the quality, else the first; each later one's hull only if needed
        best = [(position, j) for r, position, j in passing if r == most]
        position, j = next(((pos, j) for pos, j in best if kept(int(idx[j]))), best[0])
        return self.new_contact(int(idx[j]), position, j, ranked, P, n_P)

    def new_contact(
        self, i: int, position: int, j: int, ranked: _Ranking, P: np.ndarray, n_P: np.ndarray
    ) -> NewContact:
        """The :class:`NewContact` of sample point ``i``, candidate ``j`` of ``ranked``,
        at ``position`` in the order."""
        pts, normals = self.sample.points, self.sample.normals
        e, eps_P = self.eps(pts[i], normals[i]), self.eps(P, n_P)
        return NewContact(
            finger=self.finger.name,
            index=i,
            p_object=pts[i].copy(),
            n_object=normals[i].copy(),
            q_arrive=self.manifold.q[self.ka, i].copy(),
            t_arrive_s=float(self.manifold.times_s[self.ka]),
            exit_time_s=float(ranked.t_exit[j]),
            margin_rad=float(ranked.margin[j]),
            distance_from_P_m=float(ranked.dist[j]),
            epsilon=float(e),
            epsilon_with_P=float(eps_P),
            quality_kept=kept_quality(e, eps_P),
            n_candidates=int(ranked.idx.size),
            rank=position,
        )

    def failure(self, checked: int, n_candidates: int, screened: int) -> ContactError:
        """The error when none of ``checked`` candidates passes: the binding rejection,
        with the numbers of the candidate that came nearest to passing it (a distance
        [m] and its requirement, or an epsilon and the force-closure tolerance). When
        ``screened`` candidates cleared the object, what refused those binds (the most
        frequent of the later tests); else the object clearance."""
        rejected = self.rejected
        why = ", ".join(f"{n} {k}" for k, n in rejected.items() if n)
        later = {k: n for k, n in rejected.items() if k != "link clearance" and n}
        if screened and later:
            main = max(later, key=lambda k: later[k])  # dict order breaks ties
        else:
            main = max(rejected, key=lambda k: rejected[k])
        self._closest_refused(main)
        measured, required = self.closest.get(main, (None, None))
        nearest = ""
        if measured is not None and required is not None:
            epsilon = main in ("force closure", "not freeing")
            scale, unit = (1.0, "") if epsilon else (1e3, " mm")
            among = (
                f" (of the first {_NEAREST_SETS})"
                if len(self.refused.get(main, [])) > _NEAREST_SETS
                else ""
            )
            nearest = (
                f"; the nearest to passing the {main}{among}: {measured * scale:.3g}{unit}, "
                f"need {required * scale:.3g}{unit}"
            )
        return ContactError(
            f"none of the {checked} best candidates (of {n_candidates}) passes "
            f"(rejected for: {why}{nearest})",
            finger=self.finger.name,
            time_s=float(self.manifold.times_s[self.ka]),
            kind={
                "force closure": FailureKind.FORCE_CLOSURE,
                "link clearance": FailureKind.OBJECT_CLEARANCE,
                "finger clearance": FailureKind.FINGER_COLLISION,
                "not freeing": FailureKind.FORCE_CLOSURE,
            }[main],
            measured=measured,
            required=required,
            other=self.closest_other if main == "finger clearance" else None,
        )


def _rerank(
    ranked: _Ranking,
    lasts: np.ndarray,
    rerank: int,
    most: int,
    cut: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]],
) -> tuple[_Ranking, np.ndarray]:
    """The ranking with the first candidates' exit times cut by what the manifold does
    not model (``cut``: candidate positions -> exit times, usable to the end), and the
    order it gives.

    The manifold knows nothing of the finger's other links or of the other fingers:
    their cuts only shorten a candidate's exit time, so an uncut exit time is an upper
    bound. The first ``rerank`` candidates are cut and all are ranked again; while the
    new first ``rerank`` hold candidates not yet cut (which may outlast the ones cut),
    those are cut too, until the first ``rerank`` are all cut or ``most`` candidates
    have been.
    """
    t_exit, lasts = ranked.t_exit.copy(), lasts.copy()
    done = np.zeros(t_exit.size, bool)
    order = ranked.order(lasts)
    while True:
        top = order[:rerank][~done[order[:rerank]]]
        if top.size == 0 or int(done.sum()) >= most:
            return ranked, order
        t_exit[top], last = cut(top)
        lasts[top] &= last
        done[top] = True
        ranked = replace(ranked, t_exit=t_exit.copy())
        order = ranked.order(lasts)


def _link_exit(
    hand: Hand,
    finger: str,
    obj: ConvexObject,
    manifold: Manifold,
    points: np.ndarray,
    ka: int,
    contact: ContactModel,
    lasting: Callable[[np.ndarray, int, np.ndarray], np.ndarray] | None = None,
    distances: ManifoldClearance | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Exit times ``(C,)`` [s] of the manifold points ``points`` from grid index ``ka``,
    cut where another link of the finger comes within ``contact.link_clearance_m`` of the
    object or the fingertip link sinks in by more than ``contact.tip_penetration_m``
    (Coal, at the manifold's times) or ``lasting`` says so, and whether each stays
    usable to the end."""
    ok = held_clear(hand, finger, obj, manifold, points, ka, contact, distances)
    if lasting is not None:
        # ok is False from a column's first failure on: only the times before it count
        ok &= lasting(points, ka, ok.sum(axis=0))
    return exit_times(ok, manifold.times_s[ka:], 0), np.asarray(ok.all(axis=0))
