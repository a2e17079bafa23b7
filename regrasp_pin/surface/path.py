"""The grid path from P to Q over the unfolded surface region (section 2.2, Fig. 4).

"The decision for the best path to connect them takes into account the distance to
be traveled and the finger joint angle limitations" (section 2.2). Each grid edge
``(a, b)`` of length ``L`` weighs

    w = L * (1 + cost_weight * (c_a + c_b) / 2),

where ``c`` is the caller's non-negative node cost (e.g. how close the finger's IK at
the time of passage comes to a boundary plane; ``inf`` forbids a node). The shortest
path under these weights comes from :func:`scipy.sparse.csgraph.dijkstra`. Build the
weights with :func:`edge_weights`, or solve directly with :func:`shortest_grid_path`.

The search runs on the weights rounded to whole multiples of :data:`WEIGHT_QUANTUM_M`
(exact integers in double precision): every path's sum is then exact, so two routes of
equal weight tie exactly, and the winner of a tie is the same on every machine,
instead of following the rounding of sums (a near-tie of 4e-11 m once picked a route
4 mm away on another IK backend).

Costs are sampled at the nodes: an edge between two allowed nodes (a knight move is
sqrt(5) steps long) may cut the corner of a forbidden area by up to half a lattice
step, so a caller that needs a hard margin should widen its forbidden area by that.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra

from .._validate import as_array, frozen, positive
from ..exceptions import FailureKind, InputError, PlanningError
from .grid import SurfaceGrid

__all__ = ["WEIGHT_QUANTUM_M", "GridPath", "edge_weights", "shortest_grid_path"]

#: The lattice of the search's edge weights [m]: a weight is rounded to a whole number of
#: these (path sums then exact; a grid of 10^4 edges of 10 cm would stay below 2^53).
WEIGHT_QUANTUM_M = 1e-9


@dataclass(frozen=True, eq=False)
class GridPath:
    """A path of grid nodes from P to Q.

    Consecutive nodes are joined by a grid edge: a straight segment of the unfolded
    plane, i.e. a straight line on each face it crosses.

    Attributes:
        nodes: Grid node indices from P to Q, shape (L,) int.
        uv: Node coordinates in the unfolded plane [m], shape (L, 2).
        points_object: Node positions on the surface, object frame [m], shape (L, 3).
        normals_object: Outward unit normals at the nodes, shape (L, 3).
        face_ids: Face of each node, shape (L,) int.
        arc_length_m: Length along the path from P to each node [m], shape (L,).
        length_m: Length of the path on the surface [m].
        cost: Sum of the edge weights (see module docstring) [m].
        grid: The grid the path lies on.
    """

    nodes: np.ndarray
    uv: np.ndarray
    points_object: np.ndarray
    normals_object: np.ndarray
    face_ids: np.ndarray
    arc_length_m: np.ndarray
    length_m: float
    cost: float
    grid: SurfaceGrid

    def __len__(self) -> int:
        return int(self.nodes.shape[0])


def edge_weights(
    grid: SurfaceGrid, node_cost: np.ndarray | None = None, *, cost_weight: float = 1.0
) -> np.ndarray:
    """Weights of the grid edges: ``L * (1 + cost_weight * (c_a + c_b) / 2)``.

    Args:
        grid: The grid.
        node_cost: Non-negative cost of each node, shape (M,); ``inf`` forbids the
            node. Default all zero (shortest path by length).
        cost_weight: Weight of the node costs relative to length, >= 0.

    Returns:
        Edge weights [m], shape (E,) (``inf`` for edges touching a forbidden node).

    Raises:
        InputError: if ``node_cost`` has the wrong shape or holds NaN or negative
            values, or ``cost_weight`` is negative or not finite.
    """
    w = positive(cost_weight, "cost_weight", allow_zero=True)
    length = grid.edge_lengths_m
    if node_cost is None:
        return length.copy()
    c = as_array(node_cost, "node_cost", (len(grid),), finite=False)
    if np.any(np.isnan(c)):
        raise InputError(
            "node_cost",
            f"holds NaN at node {int(np.argmax(np.isnan(c)))}",
            "costs >= 0 (inf forbids a node)",
        )
    if np.any(c < 0):
        bad = int(np.argmin(c))
        raise InputError(
            "node_cost",
            f"is negative at node {bad} ({c[bad]:.3g})",
            "costs >= 0 (inf forbids a node)",
        )
    mean = 0.5 * (c[grid.edges[:, 0]] + c[grid.edges[:, 1]])
    with np.errstate(invalid="ignore"):  # 0 * inf when cost_weight == 0
        factor = np.where(np.isinf(mean), np.inf, 1.0 + w * np.nan_to_num(mean, posinf=0.0))
    return length * factor


def shortest_grid_path(
    grid: SurfaceGrid, node_cost: np.ndarray | None = None, *, cost_weight: float = 1.0
) -> GridPath:
    """Shortest grid path from P to Q under the weights of :func:`edge_weights`.

    Args:
        grid: The grid (from :func:`regrasp_pin.surface.grid.build_surface_grid`).
        node_cost: Non-negative cost of each node, shape (M,); ``inf`` forbids the node.
        cost_weight: Weight of the node costs relative to length, >= 0.

    Returns:
        The path (see :class:`GridPath`).

    Raises:
        InputError: for a malformed ``node_cost`` or ``cost_weight``.
        PlanningError: if P or Q is forbidden or Q cannot be reached from P.
    """
    weights = edge_weights(grid, node_cost, cost_weight=cost_weight)
    p, q = grid.p_index, grid.q_index
    if node_cost is not None:
        c = np.asarray(node_cost, dtype=float)
        for name, i in (("P", p), ("Q", q)):
            if np.isinf(c[i]):
                raise PlanningError(
                    f"{name} has an infinite node cost: no grid path exists",
                    kind=FailureKind.GRID_UNREACHABLE,
                )
    ok = np.isfinite(weights)
    e = grid.edges[ok]
    # whole quanta (>= 1: a zero would not be an edge): exact sums, exact ties
    units = np.maximum(np.round(weights[ok] / WEIGHT_QUANTUM_M), 1.0)
    graph = csr_matrix((units, (e[:, 0], e[:, 1])), shape=(len(grid), len(grid)))
    dist, pred = dijkstra(graph, directed=False, indices=p, return_predecessors=True)
    if not np.isfinite(dist[q]):
        reached = int(np.isfinite(dist).sum())
        raise PlanningError(
            f"Q is unreachable from P on the surface grid ({reached} of {len(grid)} nodes "
            f"reachable; node costs forbid every route)",
            kind=FailureKind.GRID_UNREACHABLE,
            measured=float(reached),
            required=float(len(grid)),
        )
    nodes = [q]
    while nodes[-1] != p:  # walk back along the path (its length, not the grid size)
        nodes.append(int(pred[nodes[-1]]))
    idx = np.array(nodes[::-1], dtype=np.int64)
    uv = grid.uv[idx]
    step = np.linalg.norm(np.diff(uv, axis=0), axis=1)
    arc = np.concatenate([[0.0], np.cumsum(step)])
    return GridPath(
        nodes=frozen(idx),
        uv=frozen(uv),
        points_object=frozen(grid.points_object[idx]),
        normals_object=frozen(grid.normals_object[idx]),
        face_ids=frozen(grid.face_ids[idx]),
        arc_length_m=frozen(arc),
        length_m=float(arc[-1]),
        cost=float(dist[q] * WEIGHT_QUANTUM_M),
        grid=grid,
    )
