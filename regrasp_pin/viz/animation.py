"""A plan's state at any time, and the plan as a meshcat animation with its timeline.

Between two samples of a plan, ``q`` is interpolated linearly and the object pose by
slerp (rotation) and linearly (position): that is the motion the planner verified
(see :mod:`regrasp_pin.plan`). The animation samples it at a fixed frame rate.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import meshcat
import numpy as np
import pinocchio as pin
from meshcat.animation import Animation
from scipy.spatial.transform import Rotation, Slerp

from .._validate import as_array, positive
from ..plan import Plan

if TYPE_CHECKING:  # pragma: no cover
    from .plan_scene import PlanViewer

__all__ = ["animate_plan", "build_animation", "frame_times", "plan_states"]


def plan_states(plan: Plan, times_s: object) -> tuple[np.ndarray, np.ndarray]:
    """Hand configurations and object poses of a plan at any times.

    Args:
        plan: The plan.
        times_s: Query times ``(N,)`` [s]; clamped to ``[plan.t[0], plan.t[-1]]``.

    Returns:
        ``q (N, nq)`` [rad] (linear interpolation) and ``T_palm_object (N, 4, 4)``
        (slerp of the rotation, linear interpolation of the position).
    """
    t = np.clip(as_array(times_s, "times_s", (None,)), plan.t[0], plan.t[-1])
    i = np.clip(np.searchsorted(plan.t, t, side="right") - 1, 0, plan.t.size - 2)
    w = ((t - plan.t[i]) / (plan.t[i + 1] - plan.t[i]))[:, None]
    q = (1.0 - w) * plan.q[i] + w * plan.q[i + 1]
    xyz = plan.T_palm_object[:, :3]
    T = np.zeros((t.size, 4, 4))
    T[:, :3, :3] = Slerp(plan.t, Rotation.from_quat(plan.T_palm_object[:, 3:]))(t).as_matrix()
    T[:, :3, 3] = (1.0 - w) * xyz[i] + w * xyz[i + 1]
    T[:, 3, 3] = 1.0
    return q, T


def frame_times(plan: Plan, fps: float) -> np.ndarray:
    """Times [s] of the animation frames: ``fps`` per second over the plan, ends included."""
    rate = positive(fps, "fps")
    n = int(np.ceil((plan.t[-1] - plan.t[0]) * rate - 1e-9))
    return np.minimum(plan.t[0] + np.arange(n + 1) / rate, plan.t[-1])


def build_animation(viewer: PlanViewer, fps: float = 30.0) -> Animation:
    """The meshcat animation of a drawn plan (does not send it).

    Per frame: the pose of every visual geometry of the hand and the pose of the
    object node (which carries the object mesh, the contacts and every regrasp path,
    all drawn in the object frame, so they move with it). Contacts and regrasp
    overlays get a visibility track that shows each only while it matters.

    Args:
        viewer: A :class:`~regrasp_pin.viz.plan_scene.PlanViewer` (its scene drawn).
        fps: Frame rate of the animation [1/s].

    Returns:
        A ``meshcat.animation.Animation`` whose clips are keyed by node path; time 0 of
        the timeline is ``plan.t[0]``.
    """
    plan = viewer.plan
    times = frame_times(plan, fps)
    q, T_palm_object = plan_states(plan, times)
    anim = Animation(default_framerate=int(round(fps)))
    model, data = viewer.hand.model, viewer.hand.model.createData()
    gmodel = viewer.hand.visual_model
    gdata = pin.GeometryData(gmodel)
    nodes = viewer.hand_node_names()
    for frame, (q_f, T_f) in enumerate(zip(q, T_palm_object, strict=True)):
        pin.forwardKinematics(model, data, q_f)
        pin.updateGeometryPlacements(model, data, gmodel, gdata)
        with anim.at_frame(viewer.vis, frame) as f:
            for gid, node in enumerate(nodes):
                f[node].set_transform(gdata.oMg[gid].homogeneous)
            f[viewer.object_node].set_transform(T_f)
    last = len(times) - 1
    for node, intervals in viewer.visibility_intervals().items():
        visible = _visible_at(times, intervals)
        changes = np.flatnonzero(np.diff(visible.astype(np.int8))) + 1
        for frame in (0, *changes.tolist(), last):
            anim.at_frame(viewer.vis, frame)[node].set_property(
                "visible", "boolean", bool(visible[frame])
            )
    return anim


def _visible_at(times: np.ndarray, intervals: list[tuple[float, float]]) -> np.ndarray:
    visible = np.zeros(times.shape, dtype=bool)
    for a, b in intervals:
        visible |= (times >= a) & (times <= b)
    return visible


def animate_plan(
    plan: Plan,
    vis: meshcat.Visualizer | None = None,
    *,
    fps: float = 30.0,
    play: bool = True,
    repetitions: int = 1,
    display_time_s: float | None = None,
) -> PlanViewer:
    """Draw a plan and send its animation: hand, object and paths moving together.

    Args:
        plan: The plan.
        vis: A meshcat visualizer (live or recording); default a new recording
            (:func:`~regrasp_pin.viz.recorder.recording_visualizer`).
        fps: Animation frame rate [1/s].
        play: Start playing when the page opens (else it shows ``display_time_s`` and
            waits for "play" in the Animations panel).
        repetitions: How many times the animation plays.
        display_time_s: Time [s] shown before the animation plays (default the start).

    Returns:
        The :class:`~regrasp_pin.viz.plan_scene.PlanViewer` that drew the scene.
    """
    from .plan_scene import PlanViewer

    viewer = PlanViewer(plan, vis)
    if display_time_s is not None:
        viewer.display(display_time_s)
    viewer.vis.set_animation(
        build_animation(viewer, fps), play=bool(play), repetitions=int(repetitions)
    )
    return viewer
