"""The object's motion: a time-stamped trajectory of ``T_palm_object(t)``.

``T_palm_object(t)`` (4 x 4 homogeneous) maps points from the object frame (origin at
the centre of mass) to the palm frame: ``p_palm = R(t) p_object + t(t)``. Between the
samples the pose is interpolated: translation linearly, rotation by slerp (constant
angular velocity about a fixed axis). This interpolation *is* the motion: a plan
stores the samples, and any consumer that re-interpolates them gets the same poses.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike
from scipy.spatial.transform import Rotation

from .._validate import as_array, positive
from ..exceptions import InputError

__all__ = ["ObjectMotion"]

_ROTATION_TOL = 1e-6  # max |R^T R - I| and |det R - 1| accepted for a rotation matrix
_TIME_SLACK_S = 1e-9  # times this close outside [t_start, t_end] are clamped to the range
#: ObjectMotion.pose keeps the poses of this many times or time arrays
_POSES_KEPT = 32
#: ... of at most this many times each
_POSES_MAX_TIMES = 4096


def _times_key(t_s: object) -> object:
    """What :meth:`ObjectMotion.pose` keeps the poses of ``t_s`` under: a Python float's
    bits (``-0.0`` apart from ``0.0``), or a 1-D float64 array's bytes (short enough);
    None: not kept."""
    if type(t_s) is float:
        return t_s.hex()
    if (
        isinstance(t_s, np.ndarray)
        and t_s.dtype == np.float64
        and t_s.ndim == 1
        and t_s.size <= _POSES_MAX_TIMES
    ):
        return t_s.tobytes()  # 1-D: its length is in the bytes
    return None


class ObjectMotion:
    """Object poses in the palm frame at strictly increasing times.

    Build one with :meth:`from_poses`, :meth:`from_xyzquat` or :meth:`constant_twist`.
    Instances are immutable.

    Attributes:
        times_s: Sample times [s], shape (T,), strictly increasing, T >= 2.
        T_palm_object: Sampled poses, shape (T, 4, 4).
    """

    def __init__(self, times_s: np.ndarray, rotations: Rotation, positions_m: np.ndarray) -> None:
        """Low-level constructor; prefer :meth:`from_poses` (which validates).

        Args:
            times_s: Strictly increasing sample times [s], shape (T,).
            rotations: ``R_palm_object`` at the samples (T rotations).
            positions_m: Object origin in the palm frame [m], shape (T, 3).
        """
        self._t = np.array(times_s, dtype=float)
        self._t.setflags(write=False)
        self._rot = rotations
        self._pos = np.array(positions_m, dtype=float)
        self._pos.setflags(write=False)
        mats = np.zeros((self._t.size, 4, 4))
        mats[:, :3, :3] = rotations.as_matrix()
        # per step, the rotation vector from one sample's rotation to the next (local)
        self._R = mats[:, :3, :3].copy()
        self._w = (rotations[:-1].inv() * rotations[1:]).as_rotvec()
        mats[:, :3, 3] = self._pos
        mats[:, 3, 3] = 1.0
        mats.setflags(write=False)
        self._mats = mats
        self._poses: dict[object, np.ndarray] = {}  # see pose()

    # ------------------------------------------------------------------ constructors
    @classmethod
    def from_poses(cls, times_s: np.ndarray, T_palm_object: np.ndarray) -> ObjectMotion:
        """A motion from sampled homogeneous poses.

        Args:
            times_s: Sample times [s], shape (T,), strictly increasing, T >= 2.
            T_palm_object: Object poses in the palm frame, shape (T, 4, 4); each
                rotation block must be a proper rotation (to 1e-6) and the last row
                ``[0, 0, 0, 1]``.

        Returns:
            The motion.

        Raises:
            InputError: for NaN/inf, wrong shapes, fewer than 2 samples, times not
                strictly increasing, or a block that is not a rotation.
        """
        t = _check_times(times_s)
        mats = _check_poses(T_palm_object, "T_palm_object", t)
        R = mats[:, :3, :3]
        return cls(t, Rotation.from_matrix(R), mats[:, :3, 3])

    @classmethod
    def from_xyzquat(cls, times_s: np.ndarray, xyzquat: np.ndarray) -> ObjectMotion:
        """A motion from positions and quaternions.

        Args:
            times_s: Sample times [s], shape (T,), strictly increasing, T >= 2.
            xyzquat: Rows ``[x, y, z, qx, qy, qz, qw]`` ([m], scalar-last quaternion),
                shape (T, 7); quaternions are normalized.

        Raises:
            InputError: for NaN/inf, wrong shapes, bad times or a zero quaternion.
        """
        t = _check_times(times_s)
        xq = as_array(xyzquat, "xyzquat", (t.size, 7))
        norm = np.linalg.norm(xq[:, 3:], axis=1)
        if np.any(norm < 1e-9):
            raise InputError("xyzquat", "contains a zero quaternion", "unit quaternions")
        return cls(t, Rotation.from_quat(xq[:, 3:] / norm[:, None]), xq[:, :3])

    @classmethod
    def constant_twist(
        cls,
        T_palm_object_start: np.ndarray,
        *,
        axis_palm: np.ndarray,
        point_palm: np.ndarray,
        rate_rad_s: float,
        velocity_palm_m_s: ArrayLike = (0.0, 0.0, 0.0),
        duration_s: float,
        dt_s: float = 0.01,
        t_start_s: float = 0.0,
    ) -> ObjectMotion:
        """Rotation about a fixed palm axis through a point, plus a constant drift.

        In closed form, with ``tau = t - t_start_s``, ``R_a(phi)`` the rotation by
        ``phi`` about ``axis_palm``, ``c = point_palm`` and ``w = velocity_palm_m_s``:
        ``R(t) = R_a(rate tau) R_0`` and ``p(t) = R_a(rate tau) (p_0 - c) + c + w tau``.
        The samples are exact; the grid has ``ceil(duration_s / dt_s)`` equal steps
        (each <= ``dt_s``), ends included.

        Args:
            T_palm_object_start: Pose at ``t_start_s``, shape (4, 4).
            axis_palm: Rotation axis in the palm frame, shape (3,) (normalized here).
            point_palm: A point of the axis in the palm frame [m], shape (3,).
            rate_rad_s: Angular rate [rad/s] (sign by the right-hand rule about the axis).
            velocity_palm_m_s: Constant translation velocity [m/s], shape (3,).
            duration_s: Duration [s], > 0.
            dt_s: Maximum sample step [s], > 0; one step must turn less than pi.
            t_start_s: Time of the first sample [s].

        Raises:
            InputError: for NaN/inf, a zero axis, non-positive duration or step, a
                step too long for slerp, or a bad start pose.
        """
        T0 = as_array(T_palm_object_start, "T_palm_object_start", (4, 4))
        T0 = _check_poses(T0[None], "T_palm_object_start", np.zeros(1))[0]
        axis = as_array(axis_palm, "axis_palm", (3,))
        if np.linalg.norm(axis) < 1e-12:
            raise InputError("axis_palm", "is zero", "a non-zero axis")
        axis = axis / np.linalg.norm(axis)
        c = as_array(point_palm, "point_palm", (3,))
        w = as_array(velocity_palm_m_s, "velocity_palm_m_s", (3,))
        rate = float(as_array(rate_rad_s, "rate_rad_s", ()))
        duration = positive(duration_s, "duration_s")
        dt = positive(dt_s, "dt_s")
        t0 = float(as_array(t_start_s, "t_start_s", ()))
        n = max(1, math.ceil(duration / dt - 1e-9))
        if abs(rate) * duration / n >= math.pi:
            raise InputError(
                "dt_s",
                f"a step of {duration / n:.4g} s turns >= pi rad",
                f"dt_s < {math.pi / max(abs(rate), 1e-300):.4g} s",
            )
        tau = np.linspace(0.0, duration, n + 1)
        R_a = Rotation.from_rotvec(np.outer(rate * tau, axis))
        pos = R_a.apply(T0[:3, 3] - c) + c + np.outer(tau, w)
        return cls(t0 + tau, R_a * Rotation.from_matrix(T0[:3, :3]), pos)

    # ------------------------------------------------------------------ properties
    @property
    def times_s(self) -> np.ndarray:
        """Sample times [s], shape (T,)."""
        return self._t

    @property
    def T_palm_object(self) -> np.ndarray:
        """Sampled poses, shape (T, 4, 4)."""
        return self._mats

    @property
    def t_start(self) -> float:
        """First sample time [s]."""
        return float(self._t[0])

    @property
    def t_end(self) -> float:
        """Last sample time [s]."""
        return float(self._t[-1])

    @property
    def duration_s(self) -> float:
        """``t_end - t_start`` [s]."""
        return self.t_end - self.t_start

    def __len__(self) -> int:
        return int(self._t.size)

    def __repr__(self) -> str:
        return f"ObjectMotion({len(self)} samples, t=[{self.t_start:.4g}, {self.t_end:.4g}] s)"

    # ------------------------------------------------------------------ evaluation
    def pose(self, t_s: float | np.ndarray) -> np.ndarray:
        """The interpolated pose at a time or at times: linear translation, slerped rotation.

        The planner asks for the poses at the same times again and again (each holding
        finger, each choice and path variant): the poses of the last
        :data:`_POSES_KEPT` float times or arrays of float64 times asked for are kept
        and returned again (a copy: the same bits).

        Args:
            t_s: A time [s] or times, shape (K,), within ``[t_start, t_end]``.

        Returns:
            ``T_palm_object``: shape (4, 4) for a scalar time, (K, 4, 4) for an array.

        Raises:
            InputError: for NaN or times outside ``[t_start, t_end]``.
        """
        key = _times_key(t_s)
        known = None if key is None else self._poses.get(key)
        if known is not None:
            return known.copy()
        t, scalar = self._check_query(t_s)
        R, p = self._interpolate(t)
        out = np.zeros((t.size, 4, 4))
        out[:, :3, :3] = R
        out[:, :3, 3] = p
        out[:, 3, 3] = 1.0
        out = out[0] if scalar else out
        if key is None:
            return out
        if len(self._poses) >= _POSES_KEPT:
            self._poses.clear()  # (threads may share the motion: no ordered eviction)
        self._poses[key] = out
        return out.copy()

    def __getstate__(self) -> dict:
        """Pickled without the kept poses."""
        state = self.__dict__.copy()
        state["_poses"] = {}
        return state

    def transform_points(self, t_s: float | np.ndarray, p_object: np.ndarray) -> np.ndarray:
        """Points of the object frame expressed in the palm frame at time(s) ``t_s``.

        Args:
            t_s: A time [s] or times, shape (K,).
            p_object: Points in the object frame [m], shape (N, 3).

        Returns:
            ``p_palm`` [m]: shape (N, 3) for a scalar time, (K, N, 3) for an array.
        """
        t, scalar = self._check_query(t_s)
        p = as_array(p_object, "p_object", (None, 3))
        R, pos = self._interpolate(t)
        out = np.einsum("kij,nj->kni", R, p) + pos[:, None, :]
        return out[0] if scalar else out

    def transform_directions(self, t_s: float | np.ndarray, d_object: np.ndarray) -> np.ndarray:
        """Directions (e.g. normals) of the object frame rotated into the palm frame.

        Args:
            t_s: A time [s] or times, shape (K,).
            d_object: Directions in the object frame, shape (N, 3).

        Returns:
            ``d_palm``: shape (N, 3) for a scalar time, (K, N, 3) for an array.
        """
        t, scalar = self._check_query(t_s)
        d = as_array(d_object, "d_object", (None, 3))
        R, _ = self._interpolate(t)
        out = np.einsum("kij,nj->kni", R, d)
        return out[0] if scalar else out

    def to_object(self, t_s: float | np.ndarray, p_palm: np.ndarray) -> np.ndarray:
        """Palm-frame points expressed in the object frame (the inverse transform).

        Args:
            t_s: A time [s] or times, shape (K,).
            p_palm: Points in the palm frame [m], shape (N, 3).

        Returns:
            ``p_object`` [m]: shape (N, 3) for a scalar time, (K, N, 3) for an array.
        """
        t, scalar = self._check_query(t_s)
        p = as_array(p_palm, "p_palm", (None, 3))
        R, pos = self._interpolate(t)
        out = np.einsum("kji,knj->kni", R, p[None, :, :] - pos[:, None, :])
        return out[0] if scalar else out

    def as_xyzquat(self, times_s: np.ndarray | None = None) -> np.ndarray:
        """Poses as rows ``[x, y, z, qx, qy, qz, qw]`` ([m], scalar-last quaternion).

        Args:
            times_s: Times [s], shape (K,); default the sample times.

        Returns:
            Shape (K, 7).
        """
        if times_s is None:
            return np.hstack([self._pos, self._rot.as_quat()])
        t, _ = self._check_query(np.atleast_1d(np.asarray(times_s, dtype=float)))
        R, p = self._interpolate(t)
        return np.hstack([p, Rotation.from_matrix(R).as_quat()])

    def resample(self, dt_s: float) -> ObjectMotion:
        """The same motion on a uniform grid of ``ceil(duration / dt_s)`` equal steps.

        Args:
            dt_s: Maximum step [s], > 0.

        Returns:
            A new motion whose samples are interpolated from this one (ends included).
        """
        dt = positive(dt_s, "dt_s")
        n = max(1, math.ceil(self.duration_s / dt - 1e-9))
        t = np.linspace(self.t_start, self.t_end, n + 1)
        R, p = self._interpolate(t)
        return ObjectMotion(t, Rotation.from_matrix(R), p)

    # ------------------------------------------------------------------ internals
    def _check_query(self, t_s: float | np.ndarray) -> tuple[np.ndarray, bool]:
        arr = np.asarray(t_s, dtype=float)
        scalar = arr.ndim == 0
        t = as_array(np.atleast_1d(arr), "t_s", (None,))
        lo, hi = self._t[0], self._t[-1]
        slack = _TIME_SLACK_S * max(1.0, abs(lo), abs(hi))
        if np.any(t < lo - slack) or np.any(t > hi + slack):
            worst = t[np.argmax(np.maximum(lo - t, t - hi))]
            raise InputError(
                "t_s",
                f"time {worst:.6g} s is outside the motion",
                f"times in [{lo:.6g}, {hi:.6g}] s",
            )
        return np.clip(t, lo, hi), scalar

    def _interpolate(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Rotation matrices (K, 3, 3) and positions (K, 3) at clamped times (K,)."""
        i, a = self._segments(t)
        return self._rotations(i, a), (1.0 - a) * self._pos[i] + a * self._pos[i + 1]

    def _segments(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Sample step ``i`` (K,) holding each clamped time and the fraction ``(K, 1)``
        of that step elapsed."""
        i = np.clip(np.searchsorted(self._t, t, side="right") - 1, 0, self._t.size - 2)
        return i, ((t - self._t[i]) / (self._t[i + 1] - self._t[i]))[:, None]

    def _rotations(self, i: np.ndarray, a: np.ndarray) -> np.ndarray:
        """Slerp ``R_i exp(a w_i)`` (K, 3, 3) for steps ``i`` and fractions ``a``: the
        rotation turns at a constant rate about a fixed axis through each step (what
        scipy's ``Slerp`` computes), by Rodrigues' formula, written out per point."""
        w = a * self._w[i]  # (K, 3)
        th2 = np.einsum("ki,ki->k", w, w)
        th = np.sqrt(th2)
        small = th < 1e-4  # the series to th^4 (relative error < 1e-18)
        safe = np.where(small, 1.0, th)
        sinc = np.where(small, 1.0 - th2 / 6.0, np.sin(th) / safe)
        cosc = np.where(small, 0.5 - th2 / 24.0, (1.0 - np.cos(th)) / (safe * safe))
        cos = np.where(small, 1.0 - 0.5 * th2, np.cos(th))
        x, y, z = w[:, 0], w[:, 1], w[:, 2]
        E = np.empty((w.shape[0], 3, 3))  # cos I + sinc [w]x + cosc w w^T
        E[:, 0, 0] = cos + cosc * x * x
        E[:, 1, 1] = cos + cosc * y * y
        E[:, 2, 2] = cos + cosc * z * z
        E[:, 0, 1] = cosc * x * y - sinc * z
        E[:, 1, 0] = cosc * x * y + sinc * z
        E[:, 0, 2] = cosc * x * z + sinc * y
        E[:, 2, 0] = cosc * x * z - sinc * y
        E[:, 1, 2] = cosc * y * z - sinc * x
        E[:, 2, 1] = cosc * y * z + sinc * x
        R0 = self._R[i]
        out = np.empty_like(E)
        for r in range(3):
            for c in range(3):
                out[:, r, c] = R0[:, r, 0] * E[:, 0, c] + R0[:, r, 1] * E[:, 1, c]
                out[:, r, c] += R0[:, r, 2] * E[:, 2, c]
        return out


def _check_times(times_s: np.ndarray) -> np.ndarray:
    t = as_array(times_s, "times_s", (None,))
    if t.size < 2:
        raise InputError("times_s", f"has {t.size} sample(s)", "at least 2 samples")
    steps = np.diff(t)
    if np.any(steps <= 0):
        i = int(np.argmin(steps))
        raise InputError(
            "times_s",
            f"not strictly increasing at index {i + 1} ({t[i]:.6g} s then {t[i + 1]:.6g} s)",
            "strictly increasing times",
        )
    return t


def _check_poses(value: np.ndarray, argument: str, t: np.ndarray) -> np.ndarray:
    """Validate homogeneous poses (K, 4, 4): finite, last row [0 0 0 1], proper rotations."""
    mats = as_array(value, argument, (t.size, 4, 4))
    if np.any(np.abs(mats[:, 3] - [0.0, 0.0, 0.0, 1.0]) > 1e-9):
        raise InputError(argument, "last row is not [0, 0, 0, 1]", "homogeneous poses")
    R = mats[:, :3, :3]
    ortho = np.max(np.abs(np.einsum("kji,kjl->kil", R, R) - np.eye(3)), axis=(1, 2))
    det = np.linalg.det(R)
    bad = np.nonzero((ortho > _ROTATION_TOL) | (np.abs(det - 1.0) > _ROTATION_TOL))[0]
    if bad.size:
        i = int(bad[0])
        raise InputError(
            argument,
            f"pose {i} (t={t[i]:.6g} s) is not a rotation (|R^T R - I| = {ortho[i]:.2e}, "
            f"det = {det[i]:.6g})",
            "orthonormal rotation blocks with det +1",
        )
    return mats
