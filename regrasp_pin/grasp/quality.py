"""Grasp quality: force closure and the Ferrari-Canny epsilon of point contacts with friction.

Beyond the paper (which has no grasp-quality test during a regrasp): while one finger
is in the air, the contacts that keep holding must still be in force closure, and the
new contact Q should keep or improve the quality of the grasp.

Model. Contact i at ``p_i`` on a surface with OUTWARD unit normal ``n_i`` (both in the
object frame, origin at the centre of mass) pushes on the object with a force inside
the Coulomb cone ``{f : |f_t| <= mu f_n}`` about the INWARD normal ``-n_i``. The cone
is linearized by ``n_edges`` unit-normal-force edges

    f_ij = -n_i + mu (cos(2 pi j / m) t1_i + sin(2 pi j / m) t2_i),

each giving the primitive wrench ``w_ij = [f_ij, (p_i x f_ij) / L]`` where the torque
scale ``L`` [m] makes forces and torques comparable. The Ferrari-Canny epsilon (L1
version, "the sum of the normal forces is at most 1") is the radius of the largest
ball about the origin inside the convex hull of all ``w_ij``; the grasp is in force
closure iff that radius is > 0.

With point contacts a grasp needs wrenches that span all 6 dimensions: two antipodal
point contacts can never resist a torque about the line through them, so their
epsilon is 0. An optional soft-finger (torsional friction) model, ``torsion_m`` > 0,
lets each contact also resist a torque about its normal: the contact's wrenches
satisfy ``|f_t|^2 / mu^2 + tau_n^2 / torsion_m^2 <= f_n^2`` (an elliptic limit
surface). It is linearized from inside: the cone's edges (no torque about the normal)
and two pure spins ``[-n_i, (p_i x -n_i +- torsion_m n_i) / L]``, whose convex hull lies
within the ellipsoid, so that a grasp in force closure by them is in force closure by
the soft-finger model too. With it a two-finger pinch can be in force closure.

Force closure without the hull (:func:`closure_certificate`). The hull of ``k *
n_edges`` wrenches in 6-D has a thousand facets or more (about 2.5 ms for five
contacts), but where only *whether* ``epsilon > FORCE_CLOSURE_TOL`` matters, twelve
non-negative least-squares problems usually settle it. The directions ``+-e_i`` all
lie in the cone of the wrenches exactly when the wrenches positively span R^6 (the
origin inside their hull). Where NNLS leaves a direction outside the cone, what it
misses, ``y = d - W^T lambda``, bounds epsilon from above: the hull reaches no farther
along ``y`` than its farthest wrench, ``max_i(w_i . y) / |y|`` (<= 0 at the NNLS
optimum), and a bound below the tolerance proves it not in force closure, whatever
NNLS did. Otherwise each solution ``lambda_k >= 0``, ``W^T
lambda_k = d_k + r_k``, puts the point ``(d_k + r_k) / s_k`` (``s_k = sum(lambda_k)``)
in the hull; the hull then holds the cross-polytope through these twelve points and
the ball it contains, of radius at least ``min_k(1 / s_k) / sqrt(6) - max_k |r_k| /
s_k``: a lower bound of epsilon. Where that bound is not clearly above the tolerance,
the hull decides.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import nnls
from scipy.spatial import ConvexHull, QhullError

from .._validate import as_array, positive, positive_int
from ..exceptions import InputError
from ..model._polyhedra import cross

__all__ = [
    "closure_certificate",
    "contact_wrenches",
    "ferrari_canny_epsilon",
    "holding_fingers",
    "is_force_closure",
    "kept_quality",
]

FORCE_CLOSURE_TOL = 1e-9  # epsilon above this counts as force closure
#: epsilons within this relative tolerance are equal: a hull facet set by the same
#: contacts comes out 1-2 ulp apart when its wrenches were rounded differently
EPSILON_RTOL = 1e-9
_NORMAL_TOL = 1e-3  # accepted deviation of |n| from 1
#: an NNLS residual above this is read as a direction outside the wrenches' cone
#: (residuals of directions inside are ~1e-15; wrenches have norms of about 1)
_OUTSIDE_CONE = 1e-6
#: the certificate's bounds of epsilon must clear the tolerance by this factor
_CERTIFY_FACTOR = 1e3
_DIRECTIONS = np.vstack([np.eye(6), -np.eye(6)])  # +-e_i
#: a hull without merged facets is accepted when no wrench is farther than this outside
#: a facet's plane, nor a facet's vertex off it (wrenches have norms of about 1; qhull's
#: own hulls keep them within about 1e-14)
_HULL_CHECK_TOL = 1e-12


def holding_fingers(torsion_m: float) -> int:
    """The fewest contacts that can be in force closure: 3 for point contacts with
    friction (``torsion_m == 0``: two cannot resist a torque about the line through
    them), 2 with torsional friction [m] (a pinch)."""
    return 2 if positive(torsion_m, "torsion_m", allow_zero=True) > 0.0 else 3


def contact_wrenches(
    points_object: np.ndarray,
    normals_object: np.ndarray,
    mu: float,
    *,
    n_edges: int = 8,
    torque_scale_m: float | None = None,
    torsion_m: float = 0.0,
) -> np.ndarray:
    """Primitive wrenches of linearized Coulomb friction cones.

    Args:
        points_object: Contact points in the object frame [m], shape (k, 3).
        normals_object: OUTWARD unit surface normals of the object at the contacts,
            shape (k, 3); the contact forces push along ``-normal`` (into the object).
        mu: Coulomb friction coefficient, >= 0.
        n_edges: Edges per linearized cone, >= 3.
        torque_scale_m: Torques are divided by this [m]; default the largest distance
            of a contact from the origin (the centre of mass). Pass a fixed value
            (e.g. the object radius) to compare different grasps of one object.
        torsion_m: Soft-finger torsional friction [m] (max torque about the normal
            per unit normal force); 0 (default) is a point contact with friction.
            Above 0, each contact adds two pure spins about its normal after its
            cone's edges (the module docstring).

    Returns:
        Wrenches ``[f (3), tau / torque_scale_m (3)]``, shape (k * n_edges, 6)
        (``(k * (n_edges + 2), 6)`` with torsion), in contact-major order, every one
        with unit normal force.

    Raises:
        InputError: for bad shapes, NaN/inf, normals that are not unit length, a
            negative or non-finite ``mu``, or a non-positive ``torque_scale_m``.
    """
    p, n, mu, m, scale, torsion = _check(
        points_object, normals_object, mu, n_edges, torque_scale_m, torsion_m
    )
    t1, t2 = _tangents(n)
    phi = 2.0 * np.pi * np.arange(m) / m
    f = -n[:, None, :] + mu * (
        np.cos(phi)[None, :, None] * t1[:, None, :] + np.sin(phi)[None, :, None] * t2[:, None, :]
    )  # (k, m, 3)
    if torsion > 0.0:  # the two pure spins after each contact's edges
        f = np.concatenate([f, np.repeat(-n[:, None, :], 2, axis=1)], axis=1)  # (k, m + 2, 3)
    tau = cross(p[:, None, :], f)  # about the centre of mass
    if torsion > 0.0:
        tau[:, m:] += torsion * n[:, None, :] * np.array([1.0, -1.0])[None, :, None]
    w = np.concatenate([f, tau / scale], axis=-1)
    return w.reshape(-1, 6)


def ferrari_canny_epsilon(
    points_object: np.ndarray,
    normals_object: np.ndarray,
    mu: float,
    *,
    n_edges: int = 8,
    torque_scale_m: float | None = None,
    torsion_m: float = 0.0,
) -> float:
    """Ferrari-Canny epsilon: the largest origin-centred ball in the wrench hull.

    The facets of ``scipy.spatial.ConvexHull`` of the primitive wrenches are
    ``a . w + b = 0`` with unit ``a`` and ``a . w + b <= 0`` inside, so the distance
    from the origin to facet j is ``-b_j`` and epsilon is ``min_j (-b_j)``.

    Args:
        points_object, normals_object, mu, n_edges, torque_scale_m, torsion_m:
            As in :func:`contact_wrenches`.

    Returns:
        Epsilon (force units per unit total normal force; torques scaled by
        ``torque_scale_m``), >= 0. It is 0.0 when the origin is not strictly inside
        the hull, or when the wrenches span less than 6 dimensions (fewer than 7
        affinely independent wrenches: one contact, two point contacts, frictionless
        contacts, ...); never an exception for such grasps.

    Raises:
        InputError: for invalid arguments (see :func:`contact_wrenches`).
    """
    w = contact_wrenches(
        points_object,
        normals_object,
        mu,
        n_edges=n_edges,
        torque_scale_m=torque_scale_m,
        torsion_m=torsion_m,
    )
    return _hull_epsilon(w)


def _hull_epsilon(w: np.ndarray) -> float:
    """:func:`ferrari_canny_epsilon` of the primitive wrenches ``w`` ``(M, 6)``: from the
    hull without merged facets where it passes its check (:func:`_simplicial_epsilon`),
    else from qhull's default hull."""
    if w.shape[0] < 7:
        return 0.0
    eps = _simplicial_epsilon(w)
    if eps is not None:
        return eps
    try:
        hull = ConvexHull(w)
    except QhullError:
        if np.linalg.matrix_rank(w - w.mean(axis=0), tol=1e-9) < 6:
            return 0.0  # the wrenches span fewer than 6 dimensions
        try:  # full-dimensional but numerically awkward: joggle the input
            hull = ConvexHull(w, qhull_options="QJ")
        except QhullError:
            return 0.0
    eps = float(np.min(-hull.equations[:, -1]))
    return max(eps, 0.0)


def _simplicial_epsilon(w: np.ndarray) -> float | None:
    """Epsilon from qhull's hull of ``w`` ``(M, 6)`` without facet merging (``Q0``), or
    None where that hull fails or does not pass its check.

    qhull merges nearly coplanar facets by default in 5-D and up (``Qx``), which takes
    about three times as long for a grasp's 18-40 wrenches in general position. Without
    merging, qhull may raise on a precision problem (then None) or, in principle, keep
    a facet that is not one. The check: every wrench lies on the inner side of every
    facet's plane and each facet's vertices on it, within ``_HULL_CHECK_TOL``. Then
    every plane supports the wrenches and the facets close around them, so the smallest
    offset is the epsilon, to that tolerance (the default hull's epsilon differs by at
    most 3e-11 relative over 1135 of the planner's grasps in force closure).
    """
    try:
        hull = ConvexHull(w, qhull_options="Q0")
    except QhullError:
        return None
    return _checked_epsilon(w, hull.equations, hull.simplices)


def _checked_epsilon(w: np.ndarray, equations: np.ndarray, simplices: np.ndarray) -> float | None:
    """The epsilon of a hull's facets ``equations`` ``(F, 7)`` (vertices ``simplices``
    ``(F, 6)`` into ``w``), or None if a wrench lies outside a facet's plane or a vertex
    off it by more than ``_HULL_CHECK_TOL``."""
    dist = equations[:, :-1] @ w.T + equations[:, -1:]  # (F, M), <= 0 inside
    if dist.max() > _HULL_CHECK_TOL:
        return None
    if np.abs(np.take_along_axis(dist, simplices, axis=1)).max() > _HULL_CHECK_TOL:
        return None
    return max(float(np.min(-equations[:, -1])), 0.0)


def closure_certificate(wrenches: np.ndarray, tol: float = FORCE_CLOSURE_TOL) -> bool | None:
    """Whether the Ferrari-Canny epsilon of ``wrenches`` exceeds ``tol``, decided
    without their hull where twelve NNLS problems can (module docstring).

    Args:
        wrenches: Primitive wrenches ``(M, 6)``, as :func:`contact_wrenches` gives them.
        tol: The threshold on epsilon, >= 0.

    Returns:
        True: a lower bound of epsilon exceeds ``1000 max(tol, FORCE_CLOSURE_TOL)``
        (above the hull's own rank tolerance); False: a direction outside the
        wrenches' cone bounds epsilon from above by at most ``tol / 1000`` (no wrench
        reaches farther towards it), or fewer than 7 wrenches; None: undecided,
        :func:`ferrari_canny_epsilon` decides. Where it decides, the answer is the
        hull's ``epsilon > tol``.

    Raises:
        InputError: wrenches not ``(M, 6)`` or not finite, a negative ``tol``.
    """
    w = as_array(wrenches, "wrenches", (None, 6))
    tol = positive(tol, "tol", allow_zero=True)
    if w.shape[0] < 7:
        return False  # fewer than 7 points span no 6-D hull (ferrari_canny_epsilon: 0)
    A = np.ascontiguousarray(w.T)
    largest_sum, slack = 0.0, 0.0
    for d in _DIRECTIONS:
        try:
            lam, _ = nnls(A, d)
        except RuntimeError:  # no convergence within its iterations
            return None
        y = d - A @ lam  # what the cone misses of d
        miss = float(np.linalg.norm(y))
        if miss > _OUTSIDE_CONE:
            # no wrench reaches farther than max(w . y) / |y| along y, so neither does
            # the hull's ball: an upper bound of epsilon, whatever NNLS did
            upper = float(np.max(w @ y)) / miss
            return False if upper <= tol / _CERTIFY_FACTOR else None
        total = float(lam.sum())
        largest_sum = max(largest_sum, total)
        slack = max(slack, miss / total)
    bound = 1.0 / (largest_sum * np.sqrt(6.0)) - slack
    return True if bound > _CERTIFY_FACTOR * max(tol, FORCE_CLOSURE_TOL) else None


def is_force_closure(
    points_object: np.ndarray,
    normals_object: np.ndarray,
    mu: float,
    *,
    n_edges: int = 8,
    torque_scale_m: float | None = None,
    torsion_m: float = 0.0,
    tol: float = FORCE_CLOSURE_TOL,
) -> bool:
    """Whether the contacts can resist any wrench: epsilon > ``tol``.

    Args:
        points_object, normals_object, mu, n_edges, torque_scale_m, torsion_m:
            As in :func:`contact_wrenches`.
        tol: Threshold on :func:`ferrari_canny_epsilon`, >= 0.

    Returns:
        True when the grasp is in force closure (with margin ``tol``).

    Raises:
        InputError: for invalid arguments.
    """
    tol = positive(tol, "tol", allow_zero=True)
    w = contact_wrenches(
        points_object,
        normals_object,
        mu,
        n_edges=n_edges,
        torque_scale_m=torque_scale_m,
        torsion_m=torsion_m,
    )
    certain = closure_certificate(w, tol)
    return _hull_epsilon(w) > tol if certain is None else certain


def _check(
    points: object,
    normals: object,
    mu: float,
    n_edges: int,
    torque_scale_m: float | None,
    torsion_m: float,
) -> tuple[np.ndarray, np.ndarray, float, int, float, float]:
    p = as_array(points, "points_object", (None, 3))
    n = as_array(normals, "normals_object", (p.shape[0], 3))
    if p.shape[0] == 0:
        raise InputError("points_object", "is empty", "at least one contact")
    norm = np.linalg.norm(n, axis=1)
    if np.any(np.abs(norm - 1.0) > _NORMAL_TOL):
        i = int(np.argmax(np.abs(norm - 1.0)))
        raise InputError(
            "normals_object", f"normal {i} has length {norm[i]:.6g}", "unit outward normals"
        )
    mu = positive(mu, "mu", allow_zero=True)
    m = positive_int(n_edges, "n_edges", minimum=3)
    if torque_scale_m is None:
        scale = float(np.max(np.linalg.norm(p, axis=1)))
        scale = scale if scale > 0.0 else 1.0
    else:
        scale = positive(torque_scale_m, "torque_scale_m")
    torsion = positive(torsion_m, "torsion_m", allow_zero=True)
    return p, n / norm[:, None], mu, m, scale, torsion


def _tangents(n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit tangents per normal, ``t1 x t2 = n``, shape (k, 3) each."""
    axis = np.eye(3)[np.argmin(np.abs(n), axis=1)]
    t1 = cross(n, axis)
    t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
    return t1, cross(n, t1)


def kept_quality(epsilon: float, epsilon_before: float) -> bool:
    """Whether a grasp of quality ``epsilon`` keeps the quality ``epsilon_before``
    (Ferrari-Canny epsilons): at least as large, within ``EPSILON_RTOL`` (equal in exact
    arithmetic counts as kept, whatever the last bits)."""
    return bool(epsilon >= epsilon_before - EPSILON_RTOL * max(abs(epsilon_before), 1e-12))
