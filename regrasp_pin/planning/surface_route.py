"""A regrasp's route over the inflated surface: the grid path and the fingertip-centre curve.

Step 1 of :mod:`.regrasp` (section 2.1 of the paper). The surface region holding P and
Q is unfolded into a grid (:mod:`regrasp_pin.surface.grid`); each node costs more where
the finger's IK, at the time the tip would pass over it, comes near a boundary plane,
and where its links (conservative capsules) come near another finger; nodes under
another fingertip, or where the finger's links would come within the variant's gap of
another finger in flight, are forbidden. The cheapest grid path (Dijkstra,
:mod:`regrasp_pin.surface.path`) is lifted onto the virtually inflated surface
(:mod:`regrasp_pin.surface.inflation`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from ..model.distances import capsule_gap
from ..model.hand import Finger, Hand
from ..model.scene import Scene
from ..surface.grid import SurfaceGrid
from ..surface.inflation import TipPath, grid_inflation, inflate_path
from ..surface.path import GridPath, shortest_grid_path
from .timing import inverse_progress

if TYPE_CHECKING:
    from .regrasp import RegraspParams

__all__ = ["RegraspTask", "surface_path"]

_UNREACHABLE_COST = 20.0  # node cost where IK cannot reach the inflated point
#: DLS iterations per pass for the grid nodes' IK (from the contact's configuration).
#: Reachable nodes converge within 4 (every node of the demo neighbourhood and the
#: regrasp bench); the cap ends the slow creep of unreachable ones along their limits.
_NODE_IK_ITERATIONS = 8
_FINGER_GAP_M = 0.004  # grid nodes whose finger comes closer than this to another cost more
_FINGER_COST = 10.0  # cost per unit of (gap deficit / _FINGER_GAP_M)
_FINGER_GAP_SLACK_M = 0.001  # forbidden-gap threshold below the gap that P and Q have


@dataclass(frozen=True)
class RegraspTask:
    """One regrasp to plan: what stays the same over its path variants.

    ``q0`` is the finger at lift-off; ``q_hand`` maps times to the hand with the other
    fingers holding, ``q_others`` ``(T, nq)`` is that hand at times ``t_others``, and
    ``others_tips`` ``(F, 3)`` are their tip centres in the object frame [m].
    """

    scene: Scene
    finger: Finger
    t_start: float
    q0: np.ndarray
    grid: SurfaceGrid
    q_hand: Callable[[np.ndarray], np.ndarray]
    others_tips: np.ndarray
    t_others: np.ndarray
    q_others: np.ndarray


def surface_path(task: RegraspTask, p: RegraspParams) -> tuple[GridPath, TipPath]:
    """Grid path weighing distance, joint limits and the other fingers, lifted onto the
    inflated surface.

    Each node is judged at the time the tip passes over it: its IK margin
    costs, and where the finger's links (conservative capsules) come within
    ``p.finger_gap_m`` of another finger the node is forbidden (outside the lift-off
    and landing zones); nearer than ``_FINGER_GAP_M`` it costs more.
    """
    f, grid, t_start = task.finger, task.grid, task.t_start
    height = p.inflation_factor * p.clearance_m
    taper = p.taper_m if p.taper_m is not None else height
    h_nodes = grid_inflation(grid, height, taper)
    tips = grid.points_object + (f.tip_radius + h_nodes)[:, None] * grid.normals_object
    # time at which the tip passes over each node: progress along P -> Q (unfolded)
    uvP, uvQ = grid.uv[grid.p_index], grid.uv[grid.q_index]
    d = uvQ - uvP
    s = np.clip((grid.uv - uvP) @ d / max(float(d @ d), 1e-18), 0.0, 1.0)
    t_nodes = t_start + p.duration_s * inverse_progress(s, p.time_law)
    from_p = np.linalg.norm(grid.uv - uvP, axis=1)
    from_q = np.linalg.norm(grid.uv - uvQ, axis=1)
    T = task.scene.motion.pose(t_nodes)
    targets = np.einsum("nij,nj->ni", T[:, :3, :3], tips) + T[:, :3, 3]
    res = f.ik(targets, task.q0, tol_m=1e-4, max_iter=_NODE_IK_ITERATIONS, restarts=False)
    margin = f.limit_margin(res.q)
    cost = np.clip((p.limit_margin_rad - margin) / p.limit_margin_rad, 0.0, 1.0) ** 2
    cost[~res.success] = _UNREACHABLE_COST
    t_others, q_others = task.t_others, task.q_others
    q_nodes = np.stack(
        [np.interp(t_nodes, t_others, q_others[:, j]) for j in range(q_others.shape[1])],
        axis=1,
    )
    # gaps from this cap on cost nothing and are never forbidden (nor set `allowed`)
    cap = max(_FINGER_GAP_M, p.finger_gap_m + _FINGER_GAP_SLACK_M)
    gap = _finger_gap(task.scene.hand, f.name, res.q, q_nodes, cap)
    cost += _FINGER_COST * np.clip((_FINGER_GAP_M - gap) / _FINGER_GAP_M, 0.0, None)
    # forbidden: nearer than the gap, but never more than P and Q themselves allow (the
    # capsules are conservative: a finger that holds P may already be "within" them)
    ends = [grid.p_index, grid.q_index]
    allowed = min(p.finger_gap_m, float(gap[ends].min()) - _FINGER_GAP_SLACK_M)
    in_flight = (from_p > taper) & (from_q > taper)
    cost[in_flight & (gap < allowed)] = np.inf
    others_tips = task.others_tips
    if others_tips.size:
        # under another fingertip: forbidden, but never more than P and Q themselves are
        # (a P right beside another finger would otherwise be walled in)
        dist = np.linalg.norm(tips[:, None, :] - others_tips[None], axis=2).min(axis=1)
        at_ends = float(dist[[grid.p_index, grid.q_index]].min())
        keep = min(2 * f.tip_radius + p.contact_keepout_m, at_ends - _FINGER_GAP_SLACK_M)
        cost[dist < keep] = np.inf
    cost[[grid.p_index, grid.q_index]] = np.minimum(cost[[grid.p_index, grid.q_index]], 0.0)
    # decisions must not follow last-bit noise: costs on a 1e-9 lattice
    finite = np.isfinite(cost)
    cost[finite] = np.round(cost[finite], 9)
    gpath = shortest_grid_path(grid, cost, cost_weight=p.limit_weight)
    tip_path = inflate_path(
        task.scene.obj, gpath, tip_radius_m=f.tip_radius, clearance_m=height, taper_m=taper
    )
    return gpath, tip_path


def _finger_gap(
    hand: Hand, finger: str, q_finger: np.ndarray, q_others: np.ndarray, cap_m: float
) -> np.ndarray:
    """Lower bound ``(M,)`` on the distance between the finger (at each ``q_finger`` row)
    and the other fingers (at the matching ``q_others`` row, ``(M, nq)``), capped at
    ``cap_m`` (:func:`~regrasp_pin.model.distances.capsule_gap`)."""
    f = hand.finger(finger)
    other_ids = [g for n, o in hand.fingers.items() if n != finger for g in o.geometry_ids]
    q_full = np.array(q_others, float)
    # the other fingers are placed once per distinct configuration (bit for bit): over
    # the grid nodes they repeat (the nodes beyond P or Q share the regrasp's ends)
    rows = q_full.view(np.dtype((np.void, 8 * q_full.shape[1])))[:, 0]
    _, first, inverse = np.unique(rows, return_index=True, return_inverse=True)
    q_distinct = q_full[first]
    q_full[:, f.q_indices] = q_finger
    return capsule_gap(
        hand,
        list(f.geometry_ids),
        other_ids,
        q_full,
        cap_m=cap_m,
        q_b=q_distinct,
        rows_b=inverse.reshape(-1),
    )
