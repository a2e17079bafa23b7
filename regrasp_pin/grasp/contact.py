"""The fingertip contact model and its feasibility test.

A fingertip is a sphere of radius ``r`` centred on the finger's tip frame. It touches
the object's surface point ``s`` (outward unit normal ``n``) when its centre is at
``s + r n``. A contact is *feasible* for a finger at a configuration ``q`` when

1. IK reaches the tip-centre target within tolerance, inside the joint limits;
2. the pad faces the surface: the angle between the pad direction (out of the finger
   pad, :attr:`~regrasp_pin.model.hand.Finger.pad_axis_tip`) and the inward normal ``-n`` is
   at most the pad cone: the finger's own (:attr:`~regrasp_pin.model.hand.Finger.pad_cone_deg`,
   90 deg where the fingertip link carries the tip sphere, the front hemisphere of
   the pad and the fingertip's end; 60 deg where the sphere stands in for a mesh
   pad), or ``cone_deg`` for every finger when given;
3. no other link of that finger intersects the object (Coal distance between the
   finger's non-tip collision geometries and the object >= ``link_clearance_m``).

Frames: contact points and normals in the object frame; the object pose
``T_palm_object`` (4 x 4) maps them to the palm frame.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from .._validate import positive
from ..exceptions import InputError
from ..model import placements_numba, tip_numba
from ..model.hand import Finger
from ..model.ik import ik_backend

__all__ = ["ContactModel", "pad_cosines", "pad_cosines_and_overshoot", "tip_targets"]


@dataclass(frozen=True)
class ContactModel:
    """Parameters of the fingertip contact.

    Attributes:
        cone_deg: Largest angle between the pad direction and the inward normal [deg]
            for every finger; None (default): each finger's own
            :attr:`~regrasp_pin.model.hand.Finger.pad_cone_deg` (:meth:`cos_cone_of`).
            Within it, the fingertip link's shape (``tip_penetration_m``) and the
            other links' clearance decide where the finger can hold.
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
        torsion_m: Soft-finger torsional friction [m]: the largest torque about the
            contact normal per newton of normal force that a fingertip's contact patch
            resists (about ``2/3 mu a`` for a patch of radius ``a`` under even
            pressure). 0 (default): point contacts with friction, which resist no
            such torque, so that at least three fingers must hold; above 0, two
            opposed fingertips (a pinch) can be in force closure. Every force-closure
            test of the grasp search, the planner, its proofs and the plan file's
            re-check uses it (:func:`~regrasp_pin.grasp.quality.contact_wrenches`).
    """

    cone_deg: float | None = None
    ik_tol_m: float = 1e-5
    link_clearance_m: float = 0.001
    limit_margin_rad: float = 0.05
    choice_margin_rad: float = 0.08
    choice_link_clearance_m: float = 0.003
    finger_trigger_m: float = 0.0015
    tip_penetration_m: float = 5e-5
    torsion_m: float = 0.0

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if value is not None:
                positive(value, f"ContactModel.{f.name}", allow_zero=f.name != "cone_deg")
        if self.cone_deg is not None and self.cone_deg > 180.0:
            raise InputError(
                "ContactModel.cone_deg",
                f"{self.cone_deg!r} is not allowed",
                "an angle in (0, 180] deg",
            )

    def cone_deg_of(self, finger: Finger) -> float:
        """The pad cone's half-angle for ``finger`` [deg]: ``cone_deg``, or the finger's
        own."""
        return finger.pad_cone_deg if self.cone_deg is None else float(self.cone_deg)

    def cos_cone_of(self, finger: Finger) -> float:
        """Cosine of the pad cone's half-angle for ``finger`` (:meth:`cone_deg_of`)."""
        return float(np.cos(np.radians(self.cone_deg_of(finger))))


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


def pad_cosines_and_overshoot(
    finger: Finger, q: np.ndarray, normals_palm: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`pad_cosines` (the same numbers) and how far the fingertip link reaches
    past the plane on which the tip sphere rests, ``(N,)`` [m]
    (:class:`~regrasp_pin.model.tip_reach.TipReach`; ``-inf`` without one): above
    ``ContactModel.tip_penetration_m``, the link sinks into a face under it."""
    R, _ = finger.chain.poses(q, compiled=placements_numba.wanted(ik_backend()))
    reach = finger.tip_reach
    if reach is not None and tip_numba.wanted(ik_backend()):  # numpy's bits, in one loop
        n = np.ascontiguousarray(normals_palm, dtype=np.float64).reshape(-1, 3)
        cos, over = np.empty(n.shape[0]), np.empty(n.shape[0])
        tip_numba.pad_overshoot(
            np.ascontiguousarray(R),
            n,
            np.ascontiguousarray(finger.pad_axis_tip, dtype=np.float64),
            reach.centres,
            reach.rotations,
            reach.params,
            reach.radius,
            cos,
            over,
        )
        return cos, over
    cos = _pad_cosines(finger, R, normals_palm)
    if reach is None:
        return cos, np.full(cos.shape, -np.inf)
    n = normals_palm
    # R^T (-n): into the object, in the tip frame (each sum in its written order)
    u_tip = np.stack(
        [-(R[:, 0, i] * n[:, 0] + R[:, 1, i] * n[:, 1] + R[:, 2, i] * n[:, 2]) for i in range(3)],
        axis=1,
    )
    return cos, reach.overshoot(u_tip)


def pad_cosines(finger: Finger, q: np.ndarray, normals_palm: np.ndarray) -> np.ndarray:
    """Cosine of the angle between the pad direction and the inward normal ``-n``.

    Args:
        finger: The finger.
        q: ``(N, k)`` configurations [rad].
        normals_palm: ``(N, 3)`` outward surface normals in the palm frame.

    Returns:
        ``(N,)`` cosines in [-1, 1]; feasible contacts have ``cos >= cos(cone)``.
    """
    R, _ = finger.chain.poses(q, compiled=placements_numba.wanted(ik_backend()))
    return _pad_cosines(finger, R, normals_palm)


def _pad_cosines(finger: Finger, R_tip: np.ndarray, normals_palm: np.ndarray) -> np.ndarray:
    """:func:`pad_cosines` from the tip rotations ``(N, 3, 3)``, each sum in its written
    order (a matrix product or ``einsum`` sums in the order numpy picks for the CPU)."""
    a, n = finger.pad_axis_tip, normals_palm
    pad = [R_tip[:, j, 0] * a[0] + R_tip[:, j, 1] * a[1] + R_tip[:, j, 2] * a[2] for j in range(3)]
    return -(pad[0] * n[:, 0] + pad[1] * n[:, 1] + pad[2] * n[:, 2])
