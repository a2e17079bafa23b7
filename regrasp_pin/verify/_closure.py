"""Force closure of the contacts a plan holds, from the plan file alone (for
:func:`~regrasp_pin.verify.plan_check.recheck_plan`).

Written apart from the planner's :mod:`regrasp_pin.grasp.quality` so that a bug there
does not hide here: each contact ``(p, n)`` (object frame, ``n`` the outward normal)
pushes along ``-n`` within a friction cone of coefficient ``mu``, approximated by
``EDGES`` forces on its boundary (an inscribed polygon); each force ``f`` at ``p``
gives the wrench ``(f, p x f / r)`` about the object frame's origin (its centre of
mass), ``r`` the object's largest vertex distance from it. The contacts are in force
closure when the origin lies inside the hull of their wrenches by more than
``CLOSURE_TOL`` (the Ferrari-Canny epsilon: the distance from the origin to the
hull's nearest facet). With soft fingertips (torsional friction ``torsion_m`` [m]) each
contact also pushes along ``-n`` while spinning about ``n`` by ``+-torsion_m`` per unit
normal force: two more wrenches, inside the soft-finger model's elliptic limit
surface.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from scipy.spatial import ConvexHull, QhullError

from ..plan import ContactPhase

if TYPE_CHECKING:
    from ..plan import Plan

EDGES = 8  # forces per friction cone
CLOSURE_TOL = 1e-9  # the epsilon a grasp in force closure exceeds
TIME_TOL_S = 1e-9  # a phase holds within this of its ends (as the holding count)


def epsilon(
    points: np.ndarray, normals: np.ndarray, mu: float, scale_m: float, torsion_m: float = 0.0
) -> float:
    """The Ferrari-Canny epsilon (>= 0) of contacts ``points``, ``normals`` ``(F, 3)``
    (object frame [m]) with friction ``mu`` and torsional friction ``torsion_m`` [m],
    torques divided by ``scale_m`` [m]."""
    n = normals / np.linalg.norm(normals, axis=1, keepdims=True)
    # two tangents per normal: n x a for the axis a least aligned with n, then n x t1
    axis = np.eye(3)[np.argmin(np.abs(n), axis=1)]
    t1 = np.cross(n, axis)
    t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
    t2 = np.cross(n, t1)
    angle = 2.0 * np.pi * np.arange(EDGES) / EDGES
    f = -n[:, None, :] + mu * (
        np.cos(angle)[None, :, None] * t1[:, None, :]
        + np.sin(angle)[None, :, None] * t2[:, None, :]
    )
    tau = np.cross(points[:, None, :], f)
    if torsion_m > 0.0:
        push = np.stack([-n, -n], axis=1)  # (F, 2, 3)
        spin = np.cross(points[:, None, :], push) + np.stack(
            [torsion_m * n, -torsion_m * n], axis=1
        )
        f, tau = np.concatenate([f, push], axis=1), np.concatenate([tau, spin], axis=1)
    w = np.concatenate([f, tau / scale_m], axis=-1).reshape(-1, 6)
    if w.shape[0] < 7 or np.linalg.matrix_rank(w - w.mean(axis=0), tol=1e-9) < 6:
        return 0.0  # the wrenches span fewer than 6 dimensions: no interior
    try:
        hull = ConvexHull(w)
    except QhullError:
        try:
            hull = ConvexHull(w, qhull_options="QJ")
        except QhullError:
            return 0.0
    return max(float(np.min(-hull.equations[:, -1])), 0.0)


def weakest_hold(
    plan: Plan, mu: float, torsion_m: float = 0.0
) -> tuple[float, float, tuple[str, ...]]:
    """Over the plan, the smallest epsilon of the contacts held at once (friction
    ``mu``, torsional friction ``torsion_m`` [m]; between two
    consecutive phase ends, where the held set does not change; a phase holds within
    ``TIME_TOL_S`` of its ends), when it occurs (the middle of that interval [s]) and
    the fingers holding then; ``(inf, t0, ())`` for a plan without contact phases."""
    contacts = [
        (name, c)
        for name, phases in plan.phases.items()
        for c in phases
        if isinstance(c, ContactPhase)
    ]
    verts = np.asarray(plan.object["vertices"], float)
    scale = float(np.max(np.linalg.norm(verts, axis=1)))
    t0, t1 = float(plan.t[0]), float(plan.t[-1])
    ends = np.unique(
        np.clip([t0, t1, *[t for _, c in contacts for t in (c.t_start, c.t_end)]], t0, t1)
    )
    worst: tuple[float, float, tuple[str, ...]] = (np.inf, t0, ())
    known: dict[tuple[int, ...], float] = {}
    for t in 0.5 * (ends[:-1] + ends[1:]):
        held = tuple(
            i
            for i, (_, c) in enumerate(contacts)
            if c.t_start - TIME_TOL_S <= t <= c.t_end + TIME_TOL_S
        )
        if held not in known:
            p = np.array([contacts[i][1].p_object for i in held]).reshape(-1, 3)
            n = np.array([contacts[i][1].n_object for i in held]).reshape(-1, 3)
            known[held] = epsilon(p, n, mu, scale, torsion_m)
        if known[held] < worst[0]:
            worst = (known[held], float(t), tuple(sorted(contacts[i][0] for i in held)))
    return worst
