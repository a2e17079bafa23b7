"""Batched forward kinematics and Jacobians of one finger, derived from a Pinocchio model.

A finger is the chain of joints from the model's root (the palm frame) to a tip frame.
:class:`FingerChain` reads the chain once from the Pinocchio model (joint placements,
joint axes, mimic scalings and offsets) and then evaluates tip positions, tip
rotations and 3 x k position Jacobians for ``N`` configurations at once with a
handful of numpy operations per joint. Nothing is hard-coded per hand, so it serves
any URDF whose finger chains are made of revolute joints (mimic joints included).
Pinocchio stays the reference: the tests compare every output with
``pin.forwardKinematics`` / ``pin.computeFrameJacobian`` point by point.

Kernel. With ``P_j = (R_j, t_j)`` the placement of joint j in its parent joint frame,
``a_j`` its axis and ``A_j`` a constant rotation with ``A_j e_z = a_j``,

    W_j = W_{j-1} R_j A_j Rz(theta_j) A_j^T,   o_j = o_{j-1} + W_{j-1} t_j.

Carrying ``W'_j = W_j A_j`` instead of ``W_j`` folds every constant into one 3 x 3
matrix per joint, ``W'_j = W'_{j-1} C_j Rz(theta_j)`` with ``C_j = A_{j-1}^T R_j A_j``,
so a joint costs one product with a 3 x 3 matrix and four column updates; the joint's
world axis is the third column of ``W'_j``.

Every product with a constant is written out as elementwise sums in a fixed order
(:func:`_combine`, :func:`_linear`) rather than handed to BLAS: a BLAS kernel rounds a
point's result differently depending on where the point falls in the batch (vector
lanes, fused multiply-adds, the tail) and on the machine, whereas here each point's
result depends on that point alone, bit for bit. That is what lets a caller solve any subset of
points and get exactly the entries of the whole batch.
"""

from __future__ import annotations

import threading
from collections import OrderedDict
from collections.abc import Iterator
from dataclasses import dataclass
from typing import cast

import numpy as np
import pinocchio as pin

from ..exceptions import InputError
from . import placements_numba
from .trig import cos_sin

__all__ = ["FingerChain", "attached_placements", "attached_points", "attached_points_soa"]

_FEW_POINTS = 256  # up to this many points, the Jacobian in one batch over the joints


def _rotation_z_to(axis: np.ndarray) -> np.ndarray:
    """A rotation matrix A with ``A @ e_z = axis`` (axis unit)."""
    z = np.array([0.0, 0.0, 1.0])
    v = np.cross(z, axis)
    c = float(z @ axis)
    if np.linalg.norm(v) < 1e-12:
        return np.eye(3) if c > 0 else np.diag([1.0, -1.0, -1.0])
    return pin.exp3(v / np.linalg.norm(v) * np.arctan2(np.linalg.norm(v), c))


def _combine(coef: np.ndarray, cols: list[np.ndarray], out: np.ndarray) -> np.ndarray:
    """``out = sum_b coef[b] * cols[b]`` in the order of ``b``, elementwise (each point's
    result from its own entries only); exact terms skipped (a zero coefficient adds
    nothing, a unit one multiplies by nothing). Returns ``out``."""
    first = True
    for c, col in zip(coef.tolist(), cols, strict=True):
        if c == 0.0:
            continue
        if first:
            if c == 1.0:
                out[...] = col
            else:
                np.multiply(col, c, out=out)
            first = False
        else:
            np.add(out, col if c == 1.0 else col * c, out=out)
    if first:
        out[...] = 0.0
    return out


def _terms(coef: np.ndarray) -> tuple[tuple[int, float], ...]:
    """The nonzero terms ``(b, coef[b])`` of a constant vector, in the order of ``b``."""
    return tuple((b, c) for b, c in enumerate(coef.tolist()) if c != 0.0)


def _linear(terms: tuple[tuple[int, float], ...], cols: list[np.ndarray]) -> np.ndarray | None:
    """``sum_b coef[b] * cols[b]`` over ``terms`` in their order, the same operations as
    :func:`_combine` (a unit coefficient multiplies by nothing) but without copies: a
    single unit term is ``cols[b]`` itself (read-only use). None when there is no term
    (the sum is zero)."""
    acc = None
    owned = False
    for b, c in terms:
        term = cols[b] if c == 1.0 else cols[b] * c
        if acc is None:
            acc, owned = term, c != 1.0
        elif owned:
            acc += term
        else:
            acc, owned = acc + term, True
    return acc


@dataclass(frozen=True)
class _ChainJoint:
    """One revolute joint on the path root -> tip (internal)."""

    joint_id: int
    column: int  # index of the driving independent joint in the finger's q
    scaling: float  # theta = scaling * q[column] + offset
    offset: float
    C: np.ndarray  # (3, 3) constant, see module docstring
    t: np.ndarray  # (3,) translation in the previous W' frame


class FingerChain:
    """Batched kinematics of the chain palm -> tip frame of one finger.

    Args:
        model: Pinocchio model (built with ``mimic=True`` when the URDF has mimic joints).
        tip_frame: Name of the tip frame (must exist in ``model``).

    Attributes:
        joint_ids: Pinocchio ids of the finger's independent joints, ordered by their
            index in the configuration vector, shape ``(k,)``.
        q_indices: Indices of those joints in the full configuration ``q``, ``(k,)``.
        k: Number of independent joints (the dimension of the finger's joint space).

    Raises:
        InputError: if a joint on the chain is not a one-dof revolute joint.
    """

    def __init__(self, model: pin.Model, tip_frame: str) -> None:
        frame_id = model.getFrameId(tip_frame)
        frame = model.frames[frame_id]
        path = []
        j = int(frame.parentJoint)
        while j > 0:
            path.append(j)
            j = int(model.parents[j])
        path.reverse()

        mimic_of = {
            int(a): int(b)
            for a, b in zip(model.mimicking_joints, model.mimicked_joints, strict=True)
        }
        drivers = sorted(
            {mimic_of.get(j, j) for j in path}, key=lambda jid: model.joints[jid].idx_q
        )
        self.joint_ids = np.array(drivers, dtype=int)
        self.q_indices = np.array([model.joints[j].idx_q for j in drivers], dtype=int)
        self.k = len(drivers)
        self.tip_frame = tip_frame

        q0 = pin.neutral(model)
        #: (joint id, unit axis in the joint frame) for every joint on the chain
        self.path_axes: list[tuple[int, np.ndarray]] = []
        joints: list[_ChainJoint] = []
        A_prev = np.eye(3)
        for jid in path:
            jm = model.joints[jid]
            driver = mimic_of.get(jid, jid)
            scaling = 1.0
            if jid in mimic_of:
                scaling = float(jm.extract().scaling)
            axis, offset = self._revolute_axis(model, jid, driver, q0, scaling)
            self.path_axes.append((jid, axis))
            A = _rotation_z_to(axis)
            placement = model.jointPlacements[jid]
            joints.append(
                _ChainJoint(
                    joint_id=jid,
                    column=drivers.index(driver),
                    scaling=scaling,
                    offset=offset,
                    C=A_prev.T @ placement.rotation @ A,
                    t=A_prev.T @ placement.translation,
                )
            )
            A_prev = A
        self._joints = tuple(joints)
        #: Pinocchio ids of the joints on the chain, root to tip.
        self.path: tuple[int, ...] = tuple(path)
        self._tip_t = A_prev.T @ frame.placement.translation
        self._tip_R = A_prev.T @ frame.placement.rotation
        # the kernel's plan: nonzero terms of every constant product, the joints' angle
        # columns, scalings and offsets as arrays (all joints' angles in one batch)
        self._t_terms = tuple(_terms(jt.t) for jt in joints)
        # W <- W @ C: None where C is the identity (exactly: W is unchanged)
        self._C_terms = tuple(
            None if np.array_equal(jt.C, np.eye(3)) else tuple(_terms(jt.C[:, a]) for a in range(3))
            for jt in joints
        )
        self._tip_terms = _terms(self._tip_t)
        self._theta_column = np.array([jt.column for jt in joints], dtype=np.int64)
        self._scaled = tuple(i for i, jt in enumerate(joints) if jt.scaling != 1.0)
        self._offset = tuple(i for i, jt in enumerate(joints) if jt.offset)
        # the same constants for the compiled placements (placements_numba); a chain
        # without joints has no kernel
        self._plan = (
            placements_numba.chain_plan(joints, self._t_terms, self._C_terms) if joints else ()
        )
        for a in self._plan:
            a.flags.writeable = False
        self._packed = (
            np.array([jt.C for jt in joints]).reshape(-1, 3, 3),
            np.array([jt.t for jt in joints]).reshape(-1, 3),
            np.array([jt.column for jt in joints], dtype=np.int64),
            np.array([jt.scaling for jt in joints]),
            np.array([jt.offset for jt in joints]),
            self._tip_t.copy(),
        )
        for a in self._packed:
            a.flags.writeable = False

    def packed(self) -> tuple[np.ndarray, ...]:
        """The kernel's constants as arrays (read-only), for compiled kernels.

        Returns:
            ``(C, t, column, scaling, offset, tip_t)``: per joint on the path root ->
            tip, ``C`` ``(m, 3, 3)`` and ``t`` ``(m, 3)`` [m] as in the module docstring,
            the index of its driving joint in the finger's q ``(m,)``, its mimic scaling
            and offset [rad] ``(m,)``; and the tip frame's origin in the last ``W'``
            frame ``(3,)`` [m].
        """
        return self._packed

    @staticmethod
    def _revolute_axis(
        model: pin.Model, jid: int, driver: int, q0: np.ndarray, scaling: float
    ) -> tuple[np.ndarray, float]:
        """Axis (in the joint frame) and angle offset of a revolute (or mimic) joint."""
        jm = model.joints[jid]
        idx = model.joints[driver].idx_q
        if model.joints[driver].nq != 1:
            raise InputError(
                "tip_frame",
                f"joint {model.names[jid]!r} on the finger chain has nq={model.joints[driver].nq}",
                "revolute joints with one configuration variable",
            )
        data = jm.createData()
        logs = []
        for value in (0.0, 0.5):
            q = q0.copy()
            q[idx] = value
            jm.calc(data, q)
            if np.linalg.norm(data.M.translation) > 1e-12:
                raise InputError(
                    "tip_frame",
                    f"joint {model.names[jid]!r} on the finger chain is not revolute",
                    "revolute joints",
                )
            logs.append(pin.log3(data.M.rotation))
        diff = logs[1] - logs[0]
        axis = diff / (0.5 * scaling)
        norm = np.linalg.norm(axis)
        if not np.isclose(norm, 1.0, atol=1e-6):
            raise InputError(
                "tip_frame",
                f"joint {model.names[jid]!r} on the finger chain is not revolute",
                "revolute joints",
            )
        axis = axis / norm
        return axis, float(logs[0] @ axis)

    # ------------------------------------------------------------------ kernel
    def forward_soa(self, qT: np.ndarray, want_jacobian: bool):
        """Kernel on component-major arrays (internal; used by the batched IK).

        Args:
            qT: ``(k, N)`` configurations, one row per joint [rad].
            want_jacobian: Also return the Jacobian.

        Returns:
            ``p`` ``(3, N)`` tip positions [m], ``W`` ``(3, 3, N)`` (the last ``W'``), and
            ``J`` ``(3, k, N)`` [m/rad] or None.
        """
        n = qT.shape[1]
        p, cols, J = self._kernel(qT, want_jacobian)
        W = np.empty((3, 3, n))
        for a in range(3):
            W[:, a] = cols[a]
        return p, W, J

    def tip_soa(self, qT: np.ndarray, want_jacobian: bool) -> tuple[np.ndarray, np.ndarray | None]:
        """:meth:`forward_soa` without ``W``: ``p`` ``(3, N)`` and ``J`` ``(3, k, N)`` or
        None, the same bits (internal; the batched IK's kernel)."""
        p, _, J = self._kernel(qT, want_jacobian)
        return p, J

    def _kernel(
        self,
        qT: np.ndarray,
        want_jacobian: bool,
        keep: dict[int, tuple[np.ndarray, list[np.ndarray]]] | None = None,
    ) -> tuple[np.ndarray, list[np.ndarray], np.ndarray | None]:
        """``p`` ``(3, N)``, the columns of the last ``W'`` (``(3, N)`` or ``(3, 1)``
        each, read-only) and ``J`` or None.

        The operations on each point's numbers are those of the kernel in the module
        docstring, term by term in a fixed order; products with constants skip exact
        terms (zero coefficients, unit factors) and a column that a constant product
        only moves is not copied. The first joint's constants broadcast over the
        points, and all joints' angles, cosines and sines are computed in one batch
        (:func:`~.trig.cos_sin`: the same bits as the compiled IK's, on any CPU).
        ``keep`` (joint index -> filled with the origin and the ``W'`` columns after that
        joint) serves :func:`attached_placements`.
        """
        n = qT.shape[1]
        cos, sin = cos_sin(self._angles(qT))
        axes = []
        origins = []
        first = self._joints[0]
        o = first.t[:, None]  # W = I: o = t, W = C (exactly what the products give)
        cols = [first.C[:, 0, None], first.C[:, 1, None], first.C[:, 2, None]]
        for i in range(len(self._joints)):
            if i:
                d = _linear(self._t_terms[i], cols)  # o += W @ t, per point
                o = o + (0.0 if d is None else d)
                C_terms = self._C_terms[i]
                if C_terms is not None:  # W <- W @ C (a rotation has no zero column)
                    cols = [cast(np.ndarray, _linear(terms, cols)) for terms in C_terms]
            c, s = cos[i], sin[i]
            w0 = c * cols[0]  # column 0 of W Rz(theta): c m0 + s m1
            w0 += s * cols[1]
            w1 = c * cols[1]  # column 1: c m1 - s m0
            w1 -= s * cols[0]
            cols = [w0, w1, cols[2]]
            if keep is not None and i in keep:
                keep[i] = (o, cols)
            if want_jacobian:
                axes.append(cols[2])
                origins.append(o)
        d = _linear(self._tip_terms, cols)
        p = o + (0.0 if d is None else d)
        if p.shape[1] != n:  # a single joint and a tip on its axis
            p = np.repeat(p, n, axis=1)
        if not want_jacobian:
            return p, cols, None
        if n <= _FEW_POINTS:
            return p, cols, self._jacobian_few(p, axes, origins)
        return p, cols, self._jacobian_loop(p, axes, origins)

    def _angles(self, qT: np.ndarray) -> np.ndarray:
        """The joints' angles ``(m, N)`` [rad] on the path root -> tip, from the
        finger's configurations ``qT`` ``(k, N)`` (mimic scalings and offsets applied)."""
        theta = qT[self._theta_column]  # (m, N)
        for i in self._scaled:
            jt = self._joints[i]
            theta[i] = qT[jt.column] * jt.scaling
        for i in self._offset:
            theta[i] += self._joints[i].offset
        return theta

    def _frame_terms(
        self, R_off: np.ndarray | None, p_off: np.ndarray
    ) -> tuple[tuple[tuple[int, float], ...], tuple[tuple[tuple[int, float], ...], ...] | None]:
        """The terms of :meth:`_attached`'s sums for the frame ``(R_off, p_off)`` (its
        origin; its rotation's columns, None without ``R_off``)."""
        p_terms = _terms(self._tip_t + self._tip_R @ p_off)
        if R_off is None:
            return p_terms, None
        R_c = self._tip_R @ R_off
        return p_terms, tuple(_terms(R_c[:, a]) for a in range(3))

    def _jacobian_loop(
        self, p: np.ndarray, axes: list[np.ndarray], origins: list[np.ndarray]
    ) -> np.ndarray:
        """The Jacobian ``(3, k, N)`` of :meth:`_kernel`: joint by joint, component by
        component, ``z x (p - o)`` (times the mimic scaling) added to its column."""
        J = np.zeros((3, self.k, p.shape[1]))
        for jt, z, oj in zip(self._joints, axes, origins, strict=True):
            r = p - oj
            col = J[:, jt.column]
            f = jt.scaling
            if f == 1.0:  # (1.0 * x is x)
                col[0] += z[1] * r[2] - z[2] * r[1]
                col[1] += z[2] * r[0] - z[0] * r[2]
                col[2] += z[0] * r[1] - z[1] * r[0]
            else:
                col[0] += f * (z[1] * r[2] - z[2] * r[1])
                col[1] += f * (z[2] * r[0] - z[0] * r[2])
                col[2] += f * (z[0] * r[1] - z[1] * r[0])
        return J

    def _jacobian_few(
        self, p: np.ndarray, axes: list[np.ndarray], origins: list[np.ndarray]
    ) -> np.ndarray:
        """The Jacobian ``(3, k, N)`` of :meth:`_kernel` for few points: every joint's
        ``z x (p - o)`` in one batch, on rows extended cyclically (row 3 = row 0, row 4
        = row 1) so that the rotated rows are slices. The same products and
        differences per point as the loop over joints, in fewer numpy calls."""
        m, n = len(axes), p.shape[1]
        Z = np.empty((m, 5, n))
        R = np.empty((m, 5, n))
        for j, (z, o) in enumerate(zip(axes, origins, strict=True)):
            Z[j, :3] = z
            R[j, :3] = o
        Z[:, 3:] = Z[:, :2]
        R[:, 3:] = R[:, :2]
        np.subtract(np.concatenate([p, p[:2]]), R, out=R)  # r = p - o
        X = Z[:, 1:4] * R[:, 2:5]  # (z1 r2, z2 r0, z0 r1) - (z2 r1, z0 r2, z1 r0)
        X -= Z[:, 2:5] * R[:, 1:4]
        J = np.zeros((3, self.k, n))
        for j, jt in enumerate(self._joints):
            J[:, jt.column] += X[j] if jt.scaling == 1.0 else jt.scaling * X[j]
        return J

    def _forward(self, q: np.ndarray, want_jacobian: bool):
        p, W, J = self.forward_soa(np.ascontiguousarray(q.T), want_jacobian)
        return (
            p.T,
            np.moveaxis(W, 2, 0),
            None if J is None else np.moveaxis(J, 2, 0),
        )

    def positions(self, q: np.ndarray) -> np.ndarray:
        """Tip positions in the palm (model root) frame.

        Args:
            q: Finger configurations, shape ``(N, k)`` [rad]; not validated here
                (:class:`regrasp_pin.model.hand.Finger` validates).

        Returns:
            ``(N, 3)`` tip positions [m].
        """
        return self._forward(q, False)[0]

    def positions_jacobians(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Tip positions ``(N, 3)`` [m] and position Jacobians ``(N, 3, k)`` [m/rad].

        The Jacobian is d p_tip / d q of the independent joints, in the palm frame
        (Pinocchio's LOCAL_WORLD_ALIGNED linear part, mimic scalings included).
        """
        p, _, J = self._forward(q, True)
        return p, J

    def poses(self, q: np.ndarray, compiled: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """Tip frame rotations ``(N, 3, 3)`` and positions ``(N, 3)`` [m] in the palm
        frame, at configurations ``q`` ``(N, k)`` [rad]; ``compiled``: by the compiled
        loop (:mod:`.placements_numba`, numba installed), the same bits (the tip frame as
        a frame attached to it)."""
        if compiled:
            n = q.shape[0]
            R_out, p_out = np.empty((n, 1, 3, 3)), np.empty((n, 1, 3))
            ((_, frames),) = _frame_plans([self], _TIP_FRAME[0], _TIP_FRAME[1])
            _place_compiled(self, frames, np.ascontiguousarray(q.T), R_out, p_out)
            return R_out[:, 0], p_out[:, 0]
        p, W, _ = self.forward_soa(np.ascontiguousarray(q.T), False)
        cols = [W[:, 0], W[:, 1], W[:, 2]]  # R = W @ tip_R, per point
        R = np.empty_like(W)
        for a in range(3):
            _combine(self._tip_R[:, a], cols, R[:, a])
        return np.moveaxis(R, 2, 0), p.T

    def _attached(
        self,
        o: np.ndarray,
        cols: list[np.ndarray],
        R_off: np.ndarray | None,
        p_off: np.ndarray,
        R_out: np.ndarray | None,
        p_out: np.ndarray,
    ) -> None:
        """Palm-frame placement of the frame ``(R_off, p_off)`` in this chain's tip frame,
        from the kernel's state after the chain's last joint, into ``R_out`` ``(N, 3,
        3)`` (skipped when None) and ``p_out`` ``(N, 3)``: the constants folded into one
        rotation and one offset in the last ``W'`` frame, then written-out sums per
        point."""
        p_terms, R_terms = self._frame_terms(None if R_out is None else R_off, p_off)
        d = _linear(p_terms, cols)
        p_out[...] = (o + (0.0 if d is None else d)).T
        if R_terms is None or R_out is None:
            return
        for a in range(3):
            R_out[:, :, a] = cast(np.ndarray, _linear(R_terms[a], cols)).T


def _hosts(chains: list[FingerChain]) -> list[tuple[FingerChain, list[int]]]:
    """The chains whose paths do not start a longer one's (the hosts), each with the
    indices of the chains on its path (a finger's link frames lie on prefixes of the
    path to its tip): one kernel run per host serves them all."""
    distinct = list({id(c): c for c in chains}.values())
    distinct.sort(key=lambda c: -len(c.path))  # stable: ties keep the given order
    hosts: list[FingerChain] = []
    host_of: dict[int, FingerChain] = {}
    for c in distinct:
        host = next((h for h in hosts if h.path[: len(c.path)] == c.path), None)
        if host is None:
            hosts.append(c)
            host = c
        host_of[id(c)] = host
    return [(h, [j for j, c in enumerate(chains) if host_of[id(c)] is h]) for h in hosts]


def _kernel_states(
    chains: list[FingerChain], q: np.ndarray
) -> Iterator[tuple[int, np.ndarray, list[np.ndarray]]]:
    """``(j, o, cols)`` for every chain ``j``: the kernel's origin and ``W'`` columns after
    the chain's last joint, at full model configurations ``q`` ``(N, nq)``, with one
    kernel run per host (:func:`_hosts`)."""
    for host, members in _hosts(chains):
        keep: dict[int, tuple[np.ndarray, list[np.ndarray]]] = {
            len(chains[j].path) - 1: (np.empty(0), []) for j in members
        }
        host._kernel(np.ascontiguousarray(q[:, host.q_indices].T), False, keep)
        for j in members:
            yield (j, *keep[len(chains[j].path) - 1])


def attached_placements(
    chains: list[FingerChain],
    R_off: np.ndarray,
    p_off: np.ndarray,
    q: np.ndarray,
    compiled: bool = False,
) -> tuple[np.ndarray, np.ndarray]:
    """Palm-frame placements of frames fixed to chains' tip frames (a finger's links and
    their collision geometries), with one kernel run per finger (see
    :func:`_kernel_states`). Each point's result depends on that point's numbers alone
    (no BLAS).

    Args:
        chains: ``G`` chains of one model (repeats allowed).
        R_off: Rotations of the attached frames in their chain's tip frame ``(G, 3, 3)``.
        p_off: Their origins in the tip frame ``(G, 3)`` [m].
        q: Full model configurations ``(N, nq)`` [rad].
        compiled: Run the compiled loop (:mod:`.placements_numba`, numba installed):
            the same numbers, bit for bit.

    Returns:
        ``R`` ``(N, G, 3, 3)`` and ``p`` ``(N, G, 3)`` [m], palm frame.
    """
    n, g = q.shape[0], len(chains)
    R, p = np.empty((n, g, 3, 3)), np.empty((n, g, 3))
    if compiled:
        _compiled_placements(chains, R_off, p_off, q, R, p)
        return R, p
    for j, o, cols in _kernel_states(chains, q):
        chains[j]._attached(o, cols, R_off[j], p_off[j], R[:, j], p[:, j])
    return R, p


#: the attached frames' packed terms, by chains and frames, the most recently used last
#: (the entries hold their chains: an id in a key stays its chain's)
_FRAME_PLANS: OrderedDict[tuple, tuple] = OrderedDict()
_FRAME_PLANS_KEPT = 256
_FRAME_PLANS_LOCK = threading.Lock()


def _frame_plans(
    chains: list[FingerChain], R_off: np.ndarray | None, p_off: np.ndarray
) -> list[tuple[FingerChain, tuple[np.ndarray, ...]]]:
    """Per host (:func:`_hosts`), the packed terms of its frames
    (:func:`~.placements_numba.frame_terms` and the joint and output column of each),
    kept for the same chains and frames (the checks of a plan place the same geometries
    thousands of times)."""
    key = (
        tuple(id(c) for c in chains),
        None if R_off is None else R_off.tobytes(),
        np.ascontiguousarray(p_off).tobytes(),
    )
    with _FRAME_PLANS_LOCK:
        kept = _FRAME_PLANS.get(key)
        if kept is not None and all(a is b for a, b in zip(kept[0], chains, strict=True)):
            _FRAME_PLANS.move_to_end(key)
            return kept[1]
    plans = []
    for host, members in _hosts(chains):
        terms = [
            chains[j]._frame_terms(None if R_off is None else R_off[j], p_off[j]) for j in members
        ]
        packed = placements_numba.frame_terms(
            [t[0] for t in terms], None if R_off is None else [t[1] for t in terms]
        )
        joint_of = np.array([len(chains[j].path) - 1 for j in members], np.int64)
        frames = (joint_of, np.array(members, np.int64), *packed)
        for a in frames:
            a.flags.writeable = False
        plans.append((host, frames))
    with _FRAME_PLANS_LOCK:
        if len(_FRAME_PLANS) >= _FRAME_PLANS_KEPT:
            _FRAME_PLANS.popitem(last=False)
        _FRAME_PLANS[key] = (tuple(chains), plans)
    return plans


def _compiled_placements(
    chains: list[FingerChain],
    R_off: np.ndarray | None,
    p_off: np.ndarray,
    q: np.ndarray,
    R_out: np.ndarray | None,
    p_out: np.ndarray,
) -> None:
    """:func:`attached_placements` (``R_out`` ``(N, G, 3, 3)``, or None for the
    positions alone) into ``p_out`` ``(N, G, 3)`` (any strides), by the compiled loop."""
    want_R = R_out is not None and R_off is not None
    for host, frames in _frame_plans(chains, R_off if want_R else None, p_off):
        qT = np.ascontiguousarray(q[:, host.q_indices].T)
        _place_compiled(host, frames, qT, R_out if want_R else None, p_out)


#: the tip frame itself, attached to its chain's tip: ``(R_off (1, 3, 3), p_off (1, 3))``
_TIP_FRAME = (np.eye(3)[None], np.zeros((1, 3)))
_TIP_FRAME[0].flags.writeable = _TIP_FRAME[1].flags.writeable = False


def _place_compiled(
    host: FingerChain,
    frames: tuple[np.ndarray, ...],
    qT: np.ndarray,
    R_out: np.ndarray | None,
    p_out: np.ndarray,
) -> None:
    """One host's frames (:func:`_frame_plans`) placed by the compiled loop at its
    finger's configurations ``qT`` ``(k, N)``, into ``p_out`` (and ``R_out`` unless
    None)."""
    theta = host._angles(qT)
    want_R = R_out is not None
    R_fill = R_out if R_out is not None else np.empty((1, 1, 3, 3))
    placements_numba.placements(theta, *host._plan, *frames, want_R, R_fill, p_out)


def attached_points(chains: list[FingerChain], p_off: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Palm-frame positions ``(N, G, 3)`` [m] of points fixed to chains' tip frames,
    ``p_off`` ``(G, 3)`` [m] in the tip frames, at full model configurations ``q`` ``(N,
    nq)``: :func:`attached_placements` without the rotations."""
    return np.moveaxis(attached_points_soa(chains, p_off, q), 0, -1).swapaxes(0, 1)


def attached_points_soa(
    chains: list[FingerChain], p_off: np.ndarray, q: np.ndarray, compiled: bool = False
) -> np.ndarray:
    """:func:`attached_points` laid out coordinate first, ``(3, G, N)`` [m] (the same
    bits): each coordinate of each point a contiguous row, for batched arithmetic;
    ``compiled`` as :func:`attached_placements`'s."""
    n, g = q.shape[0], len(chains)
    if compiled:  # (N, G, 3), as attached_placements writes it: one compiled layout
        rows = np.empty((n, g, 3))
        _compiled_placements(chains, None, p_off, q, None, rows)
        return np.ascontiguousarray(rows.transpose(2, 1, 0))
    p = np.empty((3, g, n))
    for j, o, cols in _kernel_states(chains, q):
        chains[j]._attached(o, cols, None, p_off[j], None, p[:, j].T)
    return p
