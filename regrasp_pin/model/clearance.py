"""Exact Coal distances from one finger to the object and to the other fingers.

Used wherever a single configuration (or a few) is judged: the contact model (no other
link of a finger may touch the object), the choice of grasps and new contacts (no two
fingers too close), the holding fingers' proximity. Whole trajectories are checked by
:mod:`regrasp_pin.verify`, on the batched bounds of :mod:`.distances`.

Frames: hand configurations ``q_full`` ``(nq,)`` or ``(N, nq)``; object poses
``T_palm_object`` ``(4, 4)`` in the palm frame; distances in metres, negative when
penetrating.
"""

from __future__ import annotations

import threading
import weakref
from collections import OrderedDict
from collections.abc import Iterable
from typing import Any

import coal
import numpy as np
import pinocchio as pin

from .hand import Hand
from .objects import ConvexObject

__all__ = ["FingerClearance", "LinkClearance", "palm_clearance"]


def palm_clearance(hand: Hand, obj: ConvexObject, T_palm_object: np.ndarray) -> np.ndarray:
    """Coal distances ``(N,)`` [m] from the object at poses ``(N, 4, 4)`` (palm frame) to
    the hand's fixed geometry, the geometry no joint moves (the palm; a locked wrist or
    arm); ``inf`` when there is none."""
    cm = hand.collision_model
    ids = [g for g in range(cm.ngeoms) if int(cm.geometryObjects[g].parentJoint) == 0]
    T = np.asarray(T_palm_object, float).reshape(-1, 4, 4)
    out = np.full(T.shape[0], np.inf)
    if not ids:
        return out
    # on the root joint, a geometry's placement is where it is
    fixed = [(cm.geometryObjects[g].geometry, cm.geometryObjects[g].placement) for g in ids]
    shape, req, res = obj.coal_geometry(), coal.DistanceRequest(), coal.DistanceResult()
    for i, Ti in enumerate(T):
        tf = coal.Transform3s(Ti[:3, :3], Ti[:3, 3])
        for geometry, placement in fixed:
            res.clear()
            out[i] = min(out[i], coal.distance(geometry, placement, shape, tf, req, res))
    return out


class LinkClearance:
    """Coal distances between one finger's collision geometries and the object.

    Args:
        hand: The hand.
        finger: Finger name.
        obj: The object (its Coal geometry, object frame at the centre of mass).
        include_tip: Also measure the fingertip link's geometries.
        tip_only: Measure only the fingertip link's geometries.
    """

    def __init__(
        self,
        hand: Hand,
        finger: str,
        obj: ConvexObject,
        *,
        include_tip: bool = False,
        tip_only: bool = False,
    ):
        self.hand = hand
        self.finger = hand.finger(finger)
        self.obj_geom = obj.coal_geometry()
        ids = self.finger.geometry_ids
        tip = self.finger.tip_geometry_ids
        if tip_only:
            ids = tuple(g for g in ids if g in tip)
        elif not include_tip:
            ids = tuple(g for g in ids if g not in tip)
        self.geometry_ids = ids

    def __call__(self, q_full: np.ndarray, T_palm_object: np.ndarray) -> np.ndarray:
        """Smallest distance [m] per configuration.

        Args:
            q_full: ``(N, nq)`` full hand configurations.
            T_palm_object: ``(N, 4, 4)`` object poses (or one ``(4, 4)`` for all).

        Returns:
            ``(N,)`` minimum over the finger's (non-tip) geometries of the Coal distance
            to the object [m] (negative when penetrating); ``inf`` if there is none.
        """
        q_full = np.atleast_2d(q_full)
        T = np.broadcast_to(T_palm_object, (q_full.shape[0], 4, 4))
        out = np.full(q_full.shape[0], np.inf)
        if not self.geometry_ids:
            return out
        model = self.hand.model
        data, pairs, gdata, obj_id = _object_pairs(self.hand, self.geometry_ids, self.obj_geom)
        results = gdata.distanceResults
        for i, (q, Ti) in enumerate(zip(q_full, T, strict=True)):
            pin.updateGeometryPlacements(model, data, pairs, gdata, q)
            gdata.oMg[obj_id] = pin.SE3(Ti[:3, :3], Ti[:3, 3])
            # Pinocchio returns the pair of the smallest distance (the first of equals;
            # past the last pair when none is finite and below +inf)
            k = pin.computeDistances(pairs, gdata)
            out[i] = results[k].min_distance if k < len(results) else _smallest(results)
        return out


def _smallest(results: Any) -> float:
    """The smallest ``min_distance`` of Coal distance results, NaN left out (inf if
    there is none)."""
    best = np.inf
    for r in results:
        best = min(best, r.min_distance)
    return best


#: per hand: (thread, geometries, object geometry) -> the object pairs' models, the
#: most recently used last
_OBJECT_PAIRS: weakref.WeakKeyDictionary[Hand, OrderedDict[tuple, tuple]] = (
    weakref.WeakKeyDictionary()
)
_OBJECT_PAIRS_KEPT = 64  # per hand (the objects of one process's scenarios)
_OBJECT_PAIRS_LOCK = threading.Lock()


def _object_pairs(
    hand: Hand, geometry_ids: tuple[int, ...], obj_geom: Any
) -> tuple[Any, pin.GeometryModel, pin.GeometryData, int]:
    """Pinocchio data, a copy of the hand's collision model with the object added (on
    the root, placed by the caller in the geometry data) and a collision pair for each of
    ``geometry_ids`` with it (Coal's default distance request each), its geometry data
    and the object's id; built at the first call and kept while ``hand`` lives, one per
    thread (the data are written by every call; a finished thread's entries stay until
    they are the least recently used of the hand's last ``_OBJECT_PAIRS_KEPT``).

    One C++ call then measures every pair (``pin.computeDistances``), the same Coal
    distances as one ``coal.distance`` call per pair, bit for bit. Pinocchio leaves out
    a pair of a geometry whose collisions are disabled; the copy measures them all."""
    key = (threading.get_ident(), geometry_ids, id(obj_geom))
    with _OBJECT_PAIRS_LOCK:
        per_hand = _OBJECT_PAIRS.setdefault(hand, OrderedDict())
        kept = per_hand.get(key)
        if kept is not None and kept[0] is obj_geom:
            per_hand.move_to_end(key)
            return kept[1]
    pairs = hand.collision_model.copy()
    pairs.removeAllCollisionPairs()
    obj_id = pairs.addGeometryObject(pin.GeometryObject("object", 0, pin.SE3.Identity(), obj_geom))
    for g in geometry_ids:
        pairs.geometryObjects[g].disableCollision = False  # measured as coal.distance would
        pairs.addCollisionPair(pin.CollisionPair(g, obj_id))
    gdata = pin.GeometryData(pairs)
    for k in range(len(geometry_ids)):
        gdata.distanceRequests[k] = coal.DistanceRequest()
    built = (hand.model.createData(), pairs, gdata, obj_id)
    with _OBJECT_PAIRS_LOCK:
        if len(per_hand) >= _OBJECT_PAIRS_KEPT:
            per_hand.popitem(last=False)
        per_hand[key] = (obj_geom, built)  # the geometry kept: its id stays its own
    return built


#: configurations whose distance a :class:`FingerClearance` keeps (about 1 MB)
_MEMO_KEPT = 4096


class FingerClearance:
    """Coal distances between one finger's collision geometries and the other fingers'.

    Args:
        hand: The hand.
        finger: Finger name.
        others: The fingers to measure against (default: every other finger).
    """

    def __init__(self, hand: Hand, finger: str, others: Iterable[str] | None = None):
        self._hand = weakref.ref(hand)  # a shared one must not keep the hand alive
        self._pin_model = hand.model
        self.finger = hand.finger(finger)
        mine = set(self.finger.geometry_ids)
        keep = set(hand.finger_names if others is None else others) - {finger}
        named = [
            ((a, b), name)
            for name, other in hand.fingers.items()
            if name in keep
            for a in self.finger.geometry_ids
            for b in other.geometry_ids
            if b not in mine
        ]
        self.pairs = [pair for pair, _ in named]
        self._other_of = [name for _, name in named]  # the finger of each pair's second
        # the pairs as the collision pairs of a copy of the hand's geometry model, with
        # Coal's default distance request each: Pinocchio computes them all in C++ (it
        # leaves out a geometry whose collisions are disabled: the copy enables them)
        self._model = hand.collision_model.copy()
        self._model.removeAllCollisionPairs()
        for a, b in self.pairs:
            self._model.geometryObjects[a].disableCollision = False
            self._model.geometryObjects[b].disableCollision = False
            self._model.addCollisionPair(pin.CollisionPair(a, b))
        self._data = hand.model.createData()
        self._gdata = pin.GeometryData(self._model)
        for k in range(len(self.pairs)):
            self._gdata.distanceRequests[k] = coal.DistanceRequest()
        # the distances measured and the index of the pair nearest, by the
        # configuration's bytes, the oldest dropped first
        self._memo: dict[bytes, tuple[float, int]] = {}

    @classmethod
    def shared(
        cls, hand: Hand, finger: str, others: Iterable[str] | None = None
    ) -> FingerClearance:
        """The :class:`FingerClearance` of ``(hand, finger, others)`` built at the first
        call and kept while ``hand`` lives (building one copies the hand's collision
        model; the searches of a plan ask for the same pairs thousands of times), one
        per thread (its Pinocchio data is written by every call: do not hand it to
        another thread; the entries of finished threads stay while the hand lives)."""
        names = None if others is None else tuple(others)  # read an iterator once
        per_hand = _SHARED.setdefault(hand, {})
        key = (threading.get_ident(), finger, None if names is None else tuple(sorted(names)))
        fc = per_hand.get(key)
        if fc is None:
            fc = per_hand[key] = cls(hand, finger, names)
        return fc

    @property
    def hand(self) -> Hand:
        """The hand (raises ReferenceError once it is gone)."""
        hand = self._hand()
        if hand is None:
            raise ReferenceError("the hand of this FingerClearance no longer exists")
        return hand

    def __call__(self, q_full: np.ndarray) -> float:
        """Smallest distance [m] between this finger and any other finger at ``q_full``.

        A configuration measured before (the same bits; one of the last
        :data:`_MEMO_KEPT`) is not measured again: the searches ask for the same
        candidates under the same postures again and again."""
        return self._measured(q_full)[0]

    def nearest(self, q_full: np.ndarray) -> tuple[float, str | None]:
        """:meth:`__call__`'s distance [m] and the other finger it is measured to (of
        equal distances the first pair's; None without pairs, or when no distance is
        finite)."""
        d, k = self._measured(q_full)
        return d, (self._other_of[k] if 0 <= k < len(self.pairs) and np.isfinite(d) else None)

    def _measured(self, q_full: np.ndarray) -> tuple[float, int]:
        """The smallest distance [m] at ``q_full`` and the index of its pair."""
        if not self.pairs:
            return float(np.inf), -1
        q = np.asarray(q_full, float)
        key = q.tobytes()
        known = self._memo.get(key)
        if known is not None:
            return known
        # Pinocchio returns the pair of the smallest distance (the first of equals; past
        # the last pair when none is finite and below +inf)
        k = pin.computeDistances(self._pin_model, self._data, self._model, self._gdata, q)
        results = self._gdata.distanceResults
        d = float(results[k].min_distance if k < len(results) else _smallest(results))
        if len(self._memo) >= _MEMO_KEPT:
            del self._memo[next(iter(self._memo))]
        self._memo[key] = (d, int(k))
        return d, int(k)


_SHARED: weakref.WeakKeyDictionary[Hand, dict[tuple, FingerClearance]] = weakref.WeakKeyDictionary()
