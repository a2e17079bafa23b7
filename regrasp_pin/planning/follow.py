"""A regrasp's waypoint curve followed in time: sampled, checked, and solved by IK.

Step 3 of :mod:`.regrasp` (section 2.3 of the paper): the curve through the Hopfield
waypoints (object frame) is sampled at the times of the regrasp, each sample keeps the
clearance its place along the surface path requires, and warm-started batched IK turns
the samples, moved to the palm frame with the object's pose at their time, into joint
angles.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.interpolate import PchipInterpolator

from ..exceptions import FailureKind, PlanningError
from ..model.follow_on import follow_on
from ..model.hand import Finger
from ..model.objects import ConvexObject
from ..surface.inflation import TipPath

__all__ = ["CurveSamples", "follow_curve"]

_PENETRATION_TOL_M = 5e-5  # the verifier's tolerance, applied to the planned curve too


@dataclass(frozen=True)
class CurveSamples:
    """The waypoint curve sampled at path parameters: the fingertip centre (object
    frame) and the clearance it must keep there."""

    curve: PchipInterpolator
    chord: np.ndarray  # the waypoints' curve parameters (chord length) [m]
    a_way: np.ndarray  # the waypoints' arc length along the surface path [m]
    tip_path: TipPath
    pts: np.ndarray  # the surface path's fingertip centres, object frame [m]
    clearance_m: float  # in flight, from the object [m]

    def at(
        self, u: np.ndarray, obj: ConvexObject, f: Finger, times: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Tip centres ``(S, 3)`` [m], required clearances ``(S,)`` [m] and the in-flight
        mask ``(S,)`` at curve parameters ``u``; the ends are P's and Q's tip centres.

        Raises:
            PlanningError: ``object-clearance`` if the curve cuts into the clearance.
        """
        tip_obj = self.curve(u)
        tip_obj[0], tip_obj[-1] = self.pts[0], self.pts[-1]
        a_samples = np.interp(u, self.chord, self.a_way)
        taper = self.tip_path.taper_m
        in_flight = (a_samples >= taper) & (a_samples <= self.tip_path.length_m - taper)
        required = np.where(in_flight, self.clearance_m, 0.0)
        planned = obj.signed_distance(tip_obj) - f.tip_radius
        short = planned < required - _PENETRATION_TOL_M
        if short.any():
            i = int(np.argmax(required - planned))
            raise PlanningError(
                f"the waypoint curve keeps only {1e3 * planned[i]:.2f} mm of the required "
                f"{1e3 * required[i]:.2f} mm",
                finger=f.name,
                time_s=float(times[i]),
                kind=FailureKind.OBJECT_CLEARANCE,
                measured=float(planned[i]),
                required=float(required[i]),
            )
        return tip_obj, required, in_flight


_IK_CHUNK = 32  # samples solved per IK batch, each warm-started from the previous batch


def follow_curve(
    f: Finger,
    times: np.ndarray,
    T: np.ndarray,
    tip_obj: np.ndarray,
    q0: np.ndarray,
    tol: np.ndarray,
    ik_tol_m: float,
) -> np.ndarray:
    """Joint trajectory ``(S, k)`` whose tip follows ``tip_obj`` (object frame) within
    ``tol`` ``(S,)`` [m] per sample (each solve to ``ik_tol_m`` [m]), by warm-started
    batched IK in chunks; a sample that a chunk missed or put on another branch of a
    spare joint's solutions is solved again from the sample before
    (:func:`~regrasp_pin.model.follow_on.follow_on`)."""
    targets = np.einsum("nij,nj->ni", T[:, :3, :3], tip_obj) + T[:, :3, 3]
    q = np.empty((times.size, f.k))
    prev = q0
    step = np.diff(times, prepend=times[0])  # q0 is the configuration at times[0]
    for s0 in range(0, times.size, _IK_CHUNK):
        s1 = min(s0 + _IK_CHUNK, times.size)
        # warm start only: a restart may jump to another IK branch (a joint flip)
        res = f.ik(targets[s0:s1], prev, tol_m=ik_tol_m, restarts=False)
        q[s0:s1], err = res.q, res.error_m.copy()
        follow_on(f, q[s0:s1], err, targets[s0:s1], prev, step[s0:s1], ik_tol_m, tol[s0:s1])
        bad = err > tol[s0:s1]
        if bad.any():
            i = int(np.argmax(err - tol[s0:s1]))
            raise PlanningError(
                f"IK cannot follow the path (residual {1e3 * err[i]:.2f} mm, "
                f"tolerance {1e3 * tol[s0 + i]:.3f} mm)",
                finger=f.name,
                time_s=float(times[s0 + i]),
                kind=FailureKind.IK_UNREACHABLE,
                measured=float(err[i]),
                required=float(tol[s0 + i]),
            )
        prev = q[s1 - 1]
    return q
