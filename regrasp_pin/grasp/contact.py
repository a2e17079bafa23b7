"""The fingertip contact model and its feasibility test.

A fingertip is a sphere of radius ``r`` centred on the finger's tip frame. It touches
the object's surface point ``s`` (outward unit normal ``n``) when its centre is at
``s + r n``. A contact is *feasible* for a finger at a configuration ``q`` when

1. IK reaches the tip-centre target within tolerance, inside the joint limits;
2. the pad faces the surface: the angle between the pad direction (out of the finger
   pad, :attr:`~regrasp_pin.model.hand.Finger.pad_axis_tip`) and the inward normal ``-n`` is
   at most ``cone_deg`` (default 60 deg);
3. no other link of that finger intersects the object (Coal distance between the
   finger's non-tip collision geometries and the object >= ``link_clearance_m``).

Frames: contact points and normals in the object frame; the object pose
``T_palm_object`` (4 x 4) maps them to the palm frame.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

import coal
import numpy as np
import pinocchio as pin

from ..model.hand import Finger, Hand
from ..model.objects import ConvexObject

__all__ = ["ContactModel", "FingerClearance", "LinkClearance", "pad_cosines", "tip_targets"]


@dataclass(frozen=True)
class ContactModel:
    """Parameters of the fingertip contact.

    Attributes:
        cone_deg: Largest angle between the pad direction and the inward normal [deg].
        ik_tol_m: IK tolerance for a contact to count as reached [m].
        link_clearance_m: A held contact triggers a regrasp when the finger's non-tip
            links come closer than this to the object [m].
        limit_margin_rad: A contact closer than this to a joint limit (boundary plane)
            triggers a regrasp [rad].
        choice_margin_rad: New and initial contacts must be at least this far inside
            the joint limits [rad] (more than the trigger margin, so that a new contact
            is not let go at once).
        choice_link_clearance_m: New and initial contacts must keep the finger's other
            links at least this far from the object [m].
        finger_trigger_m: A holding finger that comes closer than this to another
            holding finger triggers a regrasp of one of them [m].
        tip_penetration_m: The fingertip link's geometries may press at most this far
            into the object at a contact [m] (the pad touches; a distal link shaped
            other than the pad, such as the Allegro's box, must not sink in when the
            pad tilts).
    """

    cone_deg: float = 60.0
    ik_tol_m: float = 1e-5
    link_clearance_m: float = 0.001
    limit_margin_rad: float = 0.05
    choice_margin_rad: float = 0.08
    choice_link_clearance_m: float = 0.003
    finger_trigger_m: float = 0.0015
    tip_penetration_m: float = 5e-5

    @property
    def cos_cone(self) -> float:
        """Cosine of the pad cone's half-angle."""
        return float(np.cos(np.radians(self.cone_deg)))


def tip_targets(
    points_object: np.ndarray,
    normals_object: np.ndarray,
    tip_radius: float,
    T_palm_object: np.ndarray,
) -> np.ndarray:
    """Tip-centre targets ``s + r n`` in the palm frame.

    Args:
        points_object: ``(N, 3)`` surface points, object frame [m].
        normals_object: ``(N, 3)`` outward unit normals, object frame.
        tip_radius: Fingertip radius [m].
        T_palm_object: ``(4, 4)`` object pose, or ``(T, 4, 4)`` for several poses.

    Returns:
        ``(N, 3)`` or ``(T, N, 3)`` targets in the palm frame [m].
    """
    c_object = points_object + tip_radius * normals_object
    R = T_palm_object[..., :3, :3]
    t = T_palm_object[..., :3, 3]
    return c_object @ np.swapaxes(R, -1, -2) + t[..., None, :]


def pad_cosines(finger: Finger, q: np.ndarray, normals_palm: np.ndarray) -> np.ndarray:
    """Cosine of the angle between the pad direction and the inward normal ``-n``.

    Args:
        finger: The finger.
        q: ``(N, k)`` configurations [rad].
        normals_palm: ``(N, 3)`` outward surface normals in the palm frame.

    Returns:
        ``(N,)`` cosines in [-1, 1]; feasible contacts have ``cos >= cos(cone)``.
    """
    R, _ = finger.chain.poses(q)
    pad = R @ finger.pad_axis_tip
    return -np.einsum("ij,ij->i", pad, normals_palm)


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
        self._data = hand.model.createData()
        self._gdata = pin.GeometryData(hand.collision_model)
        self._req = coal.DistanceRequest()
        self._res = coal.DistanceResult()

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
        model, cm = self.hand.model, self.hand.collision_model
        objs = cm.geometryObjects
        for i, (q, Ti) in enumerate(zip(q_full, T, strict=True)):
            pin.forwardKinematics(model, self._data, q)
            pin.updateGeometryPlacements(model, self._data, cm, self._gdata)
            tf_obj = coal.Transform3s(Ti[:3, :3], Ti[:3, 3])
            best = np.inf
            for g in self.geometry_ids:
                self._res.clear()
                d = coal.distance(
                    objs[g].geometry,
                    self._gdata.oMg[g],
                    self.obj_geom,
                    tf_obj,
                    self._req,
                    self._res,
                )
                best = min(best, d)
            out[i] = best
        return out


class FingerClearance:
    """Coal distances between one finger's collision geometries and the other fingers'.

    Args:
        hand: The hand.
        finger: Finger name.
        others: The fingers to measure against (default: every other finger).
    """

    def __init__(self, hand: Hand, finger: str, others: Iterable[str] | None = None):
        self.hand = hand
        self.finger = hand.finger(finger)
        mine = set(self.finger.geometry_ids)
        keep = set(hand.finger_names if others is None else others) - {finger}
        self.pairs = [
            (a, b)
            for name, other in hand.fingers.items()
            if name in keep
            for a in self.finger.geometry_ids
            for b in other.geometry_ids
            if b not in mine
        ]
        self._data = hand.model.createData()
        self._gdata = pin.GeometryData(hand.collision_model)
        self._req = coal.DistanceRequest()
        self._res = coal.DistanceResult()

    def __call__(self, q_full: np.ndarray) -> float:
        """Smallest distance [m] between this finger and any other finger at ``q_full``."""
        model, cm = self.hand.model, self.hand.collision_model
        pin.forwardKinematics(model, self._data, np.asarray(q_full, float))
        pin.updateGeometryPlacements(model, self._data, cm, self._gdata)
        objs = cm.geometryObjects
        best = np.inf
        for a, b in self.pairs:
            self._res.clear()
            d = coal.distance(
                objs[a].geometry,
                self._gdata.oMg[a],
                objs[b].geometry,
                self._gdata.oMg[b],
                self._req,
                self._res,
            )
            best = min(best, d)
        return float(best)
