"""A small hand-made plan to try the viewer with, without running the planner.

The bundled five-finger hand holds a 35 x 35 x 50 mm box with thumb, index and middle
finger while the box turns about the palm normal; the index finger makes one made-up
regrasp (waypoints lifted off the surface on an arc, a grid path beside them). The
fingers follow their contacts by IK. It only has to *look* plausible: nothing here is
verified, and it is not what the planner would do.
"""

from __future__ import annotations

import numpy as np

from ..model.hand import Hand
from ..model.motion import ObjectMotion
from ..model.objects import Box
from ..plan import ContactPhase, Plan, RegraspPhase, hand_record

__all__ = ["synthetic_manifold", "synthetic_plan"]

BOX_SIZE_M = (0.035, 0.035, 0.05)
BOX_CENTRE_PALM_M = (0.06, 0.02, 0.04)
#: Holding fingers and the outward normal (object frame) of the face each one touches.
HOLDING = {"thumb": (0.0, 0.0, 1.0), "index": (1.0, 0.0, 0.0), "middle": (1.0, 0.0, 0.0)}
MIN_SEPARATION_M = 0.01


def _best_contacts(hand: Hand, box: Box, T0: np.ndarray, finger: str, spacing_m: float):
    """Surface points and normals (object frame) the finger reaches with its pad facing
    the surface, on the face it should touch, best joint-limit margin first."""
    f = hand.fingers[finger]
    s = box.sample_surface(spacing_m)
    targets = (s.points + f.tip_radius * s.normals) @ T0[:3, :3].T + T0[:3, 3]
    res = f.ik(targets, restarts=False)
    facing = np.einsum("ij,ij->i", f.pad_normals(res.q), s.normals @ T0[:3, :3].T)
    margin = f.limit_margin(res.q)
    on_face = s.normals @ np.asarray(HOLDING[finger]) > 0.99
    ok = np.flatnonzero(res.success & (facing < -0.3) & (margin > 0.05) & on_face)
    order = ok[np.argsort(-margin[ok])]
    return s.points[order], s.normals[order]


def _follow(hand: Hand, finger: str, tip_object: np.ndarray, T: np.ndarray, q0: np.ndarray):
    """IK of tip-centre targets given in the object frame ``(N, 3)`` at poses ``(N, 4, 4)``."""
    f = hand.fingers[finger]
    targets = np.einsum("nij,nj->ni", T[:, :3, :3], tip_object) + T[:, :3, 3]
    return f.ik(targets, q_init=q0).q


def synthetic_plan(duration_s: float = 1.0, dt_s: float = 0.02) -> Plan:
    """The hand-made plan described in the module docstring.

    Args:
        duration_s: Length of the motion [s].
        dt_s: Sample step [s].

    Returns:
        A :class:`~regrasp_pin.plan.Plan` with a contact phase per holding finger and
        one regrasp of the index finger from 35 % to 75 % of the motion.
    """
    hand = Hand.five_finger()
    box = Box(BOX_SIZE_M)
    T0 = np.eye(4)
    T0[:3, 3] = BOX_CENTRE_PALM_M
    motion = ObjectMotion.constant_twist(
        T0,
        axis_palm=np.array([0.0, 0.0, 1.0]),
        point_palm=np.array(BOX_CENTRE_PALM_M),
        rate_rad_s=0.3,
        duration_s=duration_s,
        dt_s=dt_s,
    )
    t = motion.times_s
    T = motion.T_palm_object
    q = np.broadcast_to(hand.neutral(), (t.size, hand.model.nq)).copy()
    for name in ("ring", "little"):  # curled, out of the way
        f = hand.fingers[name]
        q[:, f.q_indices] = f.lower + np.array([0.5, 0.7, 0.7]) * (f.upper - f.lower)

    # lift-off and landing on samples, so that the plan's samples hold the contacts exactly
    t_lift = float(t[np.searchsorted(t, t[0] + 0.35 * duration_s)])
    t_land = float(t[np.searchsorted(t, t[0] + 0.75 * duration_s)])
    phases: dict[str, list] = {}
    taken: list[np.ndarray] = []
    for name in HOLDING:
        f = hand.fingers[name]
        points, normals = _best_contacts(hand, box, T0, name, 0.004)
        free = [
            i for i in range(len(points))
            if all(np.linalg.norm(points[i] - c) >= MIN_SEPARATION_M for c in taken)
        ]  # fmt: skip
        p, n = points[free[0]], normals[free[0]]
        taken.append(p)
        tip = np.broadcast_to(p + f.tip_radius * n, (t.size, 3))
        q0 = f.ik((T0[:3, :3] @ tip[0]) + T0[:3, 3]).q[0]
        q[:, f.q_indices] = _follow(hand, name, tip, T, q0)
        phases[name] = [ContactPhase(name, float(t[0]), float(t[-1]), p, n)]
        if name != "index":
            continue
        # a made-up regrasp: to the reachable point farthest from P, away from the others
        k = max(free, key=lambda i: float(np.linalg.norm(points[i] - p)))
        Q = points[k]
        taken.append(Q)
        s = np.linspace(0.0, 1.0, 7)[:, None]
        lift = 0.012 * np.sin(np.pi * s)
        P_c, Q_c = p + f.tip_radius * n, Q + f.tip_radius * n
        waypoints = (1 - s) * P_c + s * Q_c + lift * n
        side = np.cross(n, Q - p)
        side = 0.004 * side / max(float(np.linalg.norm(side)), 1e-12)
        sg = np.linspace(0.0, 1.0, 25)[:, None]
        grid = (1 - sg) * P_c + sg * Q_c + 0.012 * np.minimum(1.0, 3 * np.sin(np.pi * sg)) * n
        grid = grid + np.sin(np.pi * sg) * side
        during = (t >= t_lift) & (t <= t_land)
        u = (t[during] - t_lift) / (t_land - t_lift)
        tip_during = np.stack([np.interp(u, s[:, 0], waypoints[:, j]) for j in range(3)], 1)
        q_regrasp = _follow(hand, name, tip_during, T[during], q[during][0, f.q_indices])
        after = t > t_land
        q_hold = _follow(hand, name, np.broadcast_to(Q_c, (after.sum(), 3)), T[after],
                         q_regrasp[-1])  # fmt: skip
        q[np.ix_(during, f.q_indices)] = q_regrasp
        q[np.ix_(after, f.q_indices)] = q_hold
        phases[name] = [
            ContactPhase(name, float(t[0]), float(t_lift), p, n),
            RegraspPhase(
                finger=name,
                t_start=float(t_lift),
                t_end=float(t_land),
                P_object=p,
                Q_object=Q,
                waypoints_object=waypoints,
                min_clearance_m=0.0,
                planning_ms=0.0,
                reason="made up for the viewer example",
                extra={"grid_path_object": grid.tolist()},
            ),
            ContactPhase(name, float(t_land), float(t[-1]), Q, n),
        ]
    return Plan(
        hand=hand_record(hand),
        object=box.to_dict(),
        t=t,
        q=q,
        T_palm_object=motion.as_xyzquat(),
        phases=phases,
        summary={"example": "regrasp_pin.viz.example_plan.synthetic_plan"},
    )


def synthetic_manifold(finger: str = "index", spacing_m: float = 0.0015) -> dict[str, np.ndarray]:
    """A finger's joint-space view of the box of :func:`synthetic_plan`, for
    :func:`~regrasp_pin.viz.manifold_scene.show_manifold`.

    Every surface sample (step ``spacing_m`` [m]) is mapped into joint space by IK of
    its tip-centre target at the start pose; points IK does not reach are NaN.

    Returns:
        ``{"q_points" (N, 3), "margin" (N,), "lower" (3,), "upper" (3,),
        "p_path_q" (K, 3), "q_new" (3,)}`` with the finger's path at contact P over
        the motion and its configuration at the new contact Q of the regrasp.
    """
    plan = synthetic_plan()
    hand = Hand.five_finger()
    f = hand.fingers[finger]
    box = Box(BOX_SIZE_M)
    T = plan.poses()
    s = box.sample_surface(spacing_m)
    targets = (s.points + f.tip_radius * s.normals) @ T[0, :3, :3].T + T[0, :3, 3]
    res = f.ik(targets, restarts=False)
    q_points = np.where(res.success[:, None], res.q, np.nan)
    margin = np.where(res.success, f.limit_margin(res.q), np.nan)
    q_finger = plan.q[:, f.q_indices]
    regrasp = next((r for r in plan.regrasps() if r.finger == finger), None)
    before = plan.t <= (regrasp.t_start if regrasp else plan.t[-1])
    q_new = q_finger[-1] if regrasp is None else q_finger[np.searchsorted(plan.t, regrasp.t_end)]
    return {
        "q_points": q_points,
        "margin": margin,
        "lower": f.lower.copy(),
        "upper": f.upper.copy(),
        "p_path_q": q_finger[before],
        "q_new": q_new,
    }
