"""How far a fingertip link reaches past the plane on which its tip sphere rests.

At a contact the tip sphere (centre ``c``, radius ``r``) touches the surface, whose
outward normal is ``n``; the convex object lies behind the tangent plane
``{x : u . (x - c) = r}``, ``u = -n``. A geometry of the fingertip link that reaches past
that plane (``max_x u . (x - c) > r``) may be inside the object; one that does not
cannot be. For a contact inside a face, with the face under the geometry, "may" is
"is": the fingertip link sinks in. So the overshoot, a function of ``u`` in the tip
frame only, tells from the finger's orientation alone, without Coal, which contacts the
fingertip link allows (e.g. the Allegro's distal box, 27.5 mm wide under a 24 mm tip
sphere, lets the pad tilt sideways by about 10 deg).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from .support import PRIMITIVES, support_parameters

__all__ = ["TipReach", "tip_reach"]


@dataclass(frozen=True, eq=False)
class TipReach:
    """The fingertip link's primitive geometries in the tip frame.

    Attributes:
        radius: The tip sphere radius [m].
        centres: ``(G, 3)`` the geometries' centres in the tip frame [m].
        rotations: ``(G, 3, 3)`` their orientations in the tip frame.
        params: ``(G, 6)`` their support parameters (:mod:`.support`) [m].
        names: The geometries' names.
        skipped: Names of the tip link's geometries left out (meshes, or on another
            joint than the tip frame): they bound nothing here.
    """

    radius: float
    centres: np.ndarray
    rotations: np.ndarray
    params: np.ndarray
    names: tuple[str, ...] = ()
    skipped: tuple[str, ...] = ()

    def has_tip_sphere(self) -> bool:
        """Whether one of the geometries is the tip sphere itself: a collision sphere of
        the tip radius centred on the tip frame (to 1e-6 m, or 0.1 % of the radius). Then
        the contact model's sphere is the finger's real surface in every direction the
        other geometries leave free; otherwise it stands in for a pad of unknown shape."""
        tol = max(1e-6, 1e-3 * self.radius)
        sphere = np.all(self.params[:, :5] == 0.0, axis=1)
        sphere &= np.abs(self.params[:, 5] - self.radius) <= tol
        sphere &= np.linalg.norm(self.centres, axis=1) <= tol
        return bool(sphere.any())

    def overshoot(self, u_tip: np.ndarray) -> np.ndarray:
        """How far the geometries reach past the tangent plane [m], ``(N,)``.

        Args:
            u_tip: ``(N, 3)`` unit directions from the tip centre into the object (the
                inward surface normal), in the tip frame.

        Returns:
            ``max_g (u . c_g + h_g(R_g^T u)) - radius`` per direction (``-inf`` without
            geometries); above a small tolerance, a geometry may sink into the object.
        """
        u = np.asarray(u_tip, float).reshape(-1, 3)
        if self.params.shape[0] == 0:
            return np.full(u.shape[0], -np.inf)
        u0, u1, u2 = u[:, 0], u[:, 1], u[:, 2]
        best = np.full(u.shape[0], -np.inf)
        # geometry by geometry, each sum in its written order (einsum and matrix products
        # sum in the order numpy picks for the CPU): the compiled loop's bits
        for R, c, par in zip(self.rotations, self.centres, self.params, strict=True):
            local = [u0 * R[0, j] + u1 * R[1, j] + u2 * R[2, j] for j in range(3)]
            uz = np.abs(local[2])
            h = par[0] * np.abs(local[0]) + par[1] * np.abs(local[1]) + par[2] * uz
            h = h + par[3] * uz
            h = h + par[4] * np.sqrt(np.maximum(0.0, 1.0 - uz * uz))
            h = h + par[5]
            best = np.maximum(best, (u0 * c[0] + u1 * c[1] + u2 * c[2]) + h)
        return best - self.radius


def tip_reach(
    model: pin.Model,
    collision: pin.GeometryModel,
    tip_frame: str,
    tip_radius: float,
    geometry_ids: tuple[int, ...],
) -> TipReach:
    """The :class:`TipReach` of the fingertip link geometries ``geometry_ids`` (those on
    the tip frame's joint) of a hand model."""
    frame = model.frames[model.getFrameId(tip_frame)]
    centres, rotations, params, names, skipped = [], [], [], [], []
    for gid in geometry_ids:
        gobj = collision.geometryObjects[gid]
        if int(gobj.parentJoint) != int(frame.parentJoint) or not isinstance(
            gobj.geometry, PRIMITIVES
        ):
            skipped.append(gobj.name)
            continue
        M = frame.placement.inverse() * gobj.placement  # tip frame -> geometry
        centre, par = support_parameters(gobj.geometry)
        centres.append(M.translation + M.rotation @ centre)
        rotations.append(M.rotation.copy())
        params.append(par)
        names.append(gobj.name)
    return TipReach(
        radius=float(tip_radius),
        centres=np.array(centres, float).reshape(-1, 3),
        rotations=np.array(rotations, float).reshape(-1, 3, 3),
        params=np.array(params, float).reshape(-1, 6),
        names=tuple(names),
        skipped=tuple(skipped),
    )
