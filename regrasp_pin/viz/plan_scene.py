"""A whole-hand plan drawn in meshcat: hand, object, contacts, regrasp paths, trails.

The scene frame is the palm frame (x toward the fingers, z out of the palm). Nodes,
under the visualizer's root:

- ``hand/visuals/<geometry>``: the hand's visual model, drawn by Pinocchio's
  ``MeshcatVisualizer`` with the URDF colours.
- ``plan/object``: moves with ``T_palm_object(t)``. Everything below it is drawn in the
  object frame and so moves with the object:

  - ``mesh``: the object's real triangle mesh (from the plan file);
  - ``contacts/<finger>_<i>``: contact point and outward normal of each contact phase;
  - ``regrasps/<k>_<finger>``: for each regrasp, ``P`` and ``Q``, the ``grid_path``,
    the fingertip's ``tip_path``, the Hopfield ``waypoints`` and their ``polygon``,
    and the ``inflated`` region when the plan stores it.

- ``plan/trails/<finger>``: the path of each fingertip centre over the whole plan, in
  the palm frame.

Colours: the object is :data:`~regrasp_pin.viz.scene.OBJECT_COLOR` (blue); each
finger has its colour in :data:`~regrasp_pin.viz.scene.FINGER_COLORS` (contacts, tip
paths, trails); P is magenta, Q green, the Hopfield waypoints and polygon gold, the
grid path dark grey.
"""

from __future__ import annotations

import logging
from contextlib import redirect_stdout
from io import StringIO

import meshcat
import numpy as np
import pinocchio as pin
from meshcat.animation import Animation
from pinocchio.visualize import MeshcatVisualizer

from .._validate import as_array, positive
from ..exceptions import InputError
from ..model.hand import Hand
from ..plan import ContactPhase, Plan, RegraspPhase
from .animation import build_animation, plan_states
from .recorder import recording_visualizer
from .scene import (
    OBJECT_COLOR,
    clean_stage,
    draw_arrows,
    draw_mesh,
    draw_spheres,
    draw_tube,
    finger_color,
    set_camera,
)

__all__ = ["PlanViewer"]

log = logging.getLogger(__name__)

P_COLOR = (0.90, 0.10, 0.55)
Q_COLOR = (0.15, 0.75, 0.25)
WAYPOINT_COLOR = (0.95, 0.75, 0.10)
GRID_COLOR = (0.30, 0.30, 0.30)
INFLATED_COLOR = (0.55, 0.75, 1.00)


class PlanViewer:
    """Draws a plan into a meshcat visualizer and moves it to any time.

    Construction draws the whole scene and shows the plan's first sample;
    :meth:`display` moves it to another time; :meth:`animate` sends the animation.

    Args:
        plan: The plan to show.
        vis: A ``meshcat.Visualizer`` (live, or a recording from
            :func:`~regrasp_pin.viz.recorder.recording_visualizer`); default a new
            recording.
        hand: The plan's hand if already loaded (default ``plan.load_hand()``).
        object_opacity: Opacity of the object mesh in ``(0, 1]``.
        regrasp_margin_s: A regrasp's overlay is shown from this long before lift-off
            to this long after landing [s].
        show_all: Show every contact and regrasp overlay at all times instead.

    Attributes:
        plan: The plan.
        vis: The visualizer drawn into.
        hand: The hand (a :class:`~regrasp_pin.model.hand.Hand`).
        object_node: Path of the object node, relative to ``vis``.
        camera_target: Point the camera looks at, palm frame ``(3,)`` [m].
        camera_eye: Camera position, palm frame ``(3,)`` [m].
    """

    object_node = "plan/object"

    def __init__(
        self,
        plan: Plan,
        vis: meshcat.Visualizer | None = None,
        *,
        hand: Hand | None = None,
        object_opacity: float = 1.0,
        regrasp_margin_s: float = 0.2,
        show_all: bool = False,
    ) -> None:
        if not 0.0 < float(object_opacity) <= 1.0:
            raise InputError("object_opacity", f"{object_opacity!r} is not allowed", "(0, 1]")
        self.plan = plan
        self.vis = recording_visualizer() if vis is None else vis
        self.hand: Hand = plan.load_hand() if hand is None else hand
        self.object_opacity = float(object_opacity)
        self.regrasp_margin_s = float(regrasp_margin_s)
        self.show_all = bool(show_all)
        self._finger_index = {name: i for i, name in enumerate(self.hand.fingers)}
        self._visibility: dict[str, list[tuple[float, float]]] = {}
        self._draw()
        self.display(float(plan.t[0]))

    # ------------------------------------------------------------------ drawing
    def _draw(self) -> None:
        vis = self.vis
        clean_stage(vis)
        with redirect_stdout(StringIO()):  # pinocchio/meshcat chatter
            self._pin_viz = MeshcatVisualizer(self.hand.model, None, self.hand.visual_model)
            self._pin_viz.initViewer(viewer=vis)
            self._pin_viz.loadViewerModel(rootNodeName="hand")
        obj = vis[self.object_node]
        vertices = np.asarray(self.plan.object["vertices"], float)
        faces = np.asarray(self.plan.object["faces"], int)
        draw_mesh(obj["mesh"], vertices, faces, OBJECT_COLOR, self.object_opacity)
        size = float(np.ptp(vertices, axis=0).max())
        self._draw_contacts(obj["contacts"], size)
        for k, phase in enumerate(self.plan.regrasps()):
            self._draw_regrasp(f"{self.object_node}/regrasps/{k}_{phase.finger}", phase, size)
        self._draw_trails(vis["plan/trails"])
        self._frame_camera()

    def _draw_contacts(self, node: meshcat.Visualizer, size_m: float) -> None:
        for finger, phases in self.plan.phases.items():
            rgb = finger_color(self._finger_index.get(finger, 0))
            contacts = [p for p in phases if isinstance(p, ContactPhase)]
            for i, c in enumerate(contacts):
                name = f"{finger}_{i}"
                draw_spheres(node[f"{name}/point"], c.p_object[None], rgb, 0.045 * size_m)
                draw_arrows(
                    node[f"{name}/normal"], c.p_object[None], c.n_object[None], rgb,
                    0.35 * size_m, 0.012 * size_m,
                )  # fmt: skip
                self._visibility[f"{self.object_node}/contacts/{name}"] = [(c.t_start, c.t_end)]

    def _draw_regrasp(self, name: str, r: RegraspPhase, size_m: float) -> None:
        node = self.vis[name]
        rgb = finger_color(self._finger_index.get(r.finger, 0))
        draw_spheres(node["P"], r.P_object[None], P_COLOR, 0.05 * size_m)
        draw_spheres(node["Q"], r.Q_object[None], Q_COLOR, 0.05 * size_m)
        grid = np.asarray(r.extra.get("grid_path_object", []), float).reshape(-1, 3)
        if len(grid) >= 2:
            draw_tube(node["grid_path"], grid, GRID_COLOR, 0.008 * size_m)
        inflated = np.asarray(r.extra.get("inflated_region_object", []), float).reshape(-1, 3)
        if len(inflated):
            draw_spheres(node["inflated"], inflated, INFLATED_COLOR, 0.01 * size_m, 0.35)
        tip = np.asarray(r.extra.get("tip_path_object", []), float).reshape(-1, 3)
        if len(tip) < 2:
            tip = self.tip_path_object(r)
        if len(tip) >= 2:
            draw_tube(node["tip_path"], tip, rgb, 0.012 * size_m)
        w = np.asarray(r.waypoints_object, float).reshape(-1, 3)
        if len(w):
            draw_spheres(node["waypoints"], w, WAYPOINT_COLOR, 0.03 * size_m)
        if len(w) >= 2:
            draw_tube(node["polygon"], w, WAYPOINT_COLOR, 0.01 * size_m)
        m = self.regrasp_margin_s
        self._visibility[name] = [(r.t_start - m, r.t_end + m)]

    def tip_path_object(self, r: RegraspPhase) -> np.ndarray:
        """The fingertip centre during a regrasp ``(K, 3)``, object frame [m], from the
        plan's samples (FK of the interpolated q, moved into the object frame)."""
        finger = self.hand.fingers.get(r.finger)
        if finger is None:
            return np.zeros((0, 3))
        inside = (self.plan.t > r.t_start) & (self.plan.t < r.t_end)
        times = np.concatenate([[r.t_start], self.plan.t[inside], [r.t_end]])
        q, T = plan_states(self.plan, times)
        p_palm = finger.fk(q[:, finger.q_indices])
        return np.einsum("nji,nj->ni", T[:, :3, :3], p_palm - T[:, :3, 3])

    def _draw_trails(self, node: meshcat.Visualizer) -> None:
        for name, finger in self.hand.fingers.items():
            p_palm = finger.fk(self.plan.q[:, finger.q_indices])
            if np.ptp(p_palm, axis=0).max() > 1e-6:
                rgb = finger_color(self._finger_index[name])
                draw_tube(node[name], p_palm, rgb, 0.0009, opacity=0.6)

    def _frame_camera(self) -> None:
        """Frame the hand and the object; look from the side of the first regrasp."""
        direction = np.array([0.55, -0.75, 0.65])
        direction /= np.linalg.norm(direction)
        regrasps = self.plan.regrasps()
        if regrasps:
            T0 = self.plan.poses()[0]
            side = T0[:3, :3] @ (regrasps[0].P_object + regrasps[0].Q_object)
            if np.linalg.norm(side) > 1e-9:
                direction = direction + 0.6 * side / np.linalg.norm(side)
        self.look_from(direction)

    def look_from(self, direction_palm: object, distance: float = 1.5) -> None:
        """Point the camera at the object and the fingertips of the fingers that take
        part (at the plan's start; idle fingers and the palm may fall outside) from
        ``direction_palm (3,)`` (palm frame), at ``distance`` times the radius of the
        sphere around them."""
        d = as_array(direction_palm, "direction_palm", (3,))
        if np.linalg.norm(d) < 1e-12:
            raise InputError("direction_palm", "is zero", "a non-zero direction")
        working = [
            f
            for name, f in self.hand.fingers.items()
            if any(p.kind != "idle" for p in self.plan.phases.get(name, []))
        ] or list(self.hand.fingers.values())
        tips = np.concatenate([f.fk(self.plan.q[:1, f.q_indices]) for f in working])
        verts = np.asarray(self.plan.object["vertices"], float)
        T0 = self.plan.poses()[0]
        pts = np.concatenate([tips, verts @ T0[:3, :3].T + T0[:3, 3]])
        lo, hi = pts.min(axis=0), pts.max(axis=0)
        radius = 0.5 * float(np.linalg.norm(hi - lo))
        self.camera_target = 0.5 * (lo + hi)
        self.camera_eye = self.camera_target + positive(distance, "distance") * radius * (
            d / np.linalg.norm(d)
        )
        set_camera(self.vis, self.camera_target, self.camera_eye)

    # ------------------------------------------------------------------ queries
    def hand_node_names(self) -> list[str]:
        """Node path (relative to ``vis``) of each visual geometry, in the visual model's
        order."""
        return [
            self._pin_viz.getViewerNodeName(g, pin.GeometryType.VISUAL)
            for g in self.hand.visual_model.geometryObjects
        ]

    def visibility_intervals(self) -> dict[str, list[tuple[float, float]]]:
        """Node path -> time intervals [s] in which it is shown (empty with ``show_all``)."""
        return {} if self.show_all else dict(self._visibility)

    # ------------------------------------------------------------------ updates
    def display(self, t_s: float) -> None:
        """Show the plan at time ``t_s`` [s]: hand configuration, object pose, and which
        contacts and regrasp overlays are visible."""
        q, T = plan_states(self.plan, [float(t_s)])
        self._pin_viz.display(q[0])
        self.vis[self.object_node].set_transform(T[0])
        for node, intervals in self.visibility_intervals().items():
            on = any(a <= t_s <= b for a, b in intervals)
            self.vis[node].set_property("visible", on)

    def animation(self, fps: float = 30.0) -> Animation:
        """The meshcat animation of the plan (see :func:`.animation.build_animation`)."""
        return build_animation(self, fps)

    def animate(self, fps: float = 30.0, *, play: bool = True, repetitions: int = 1) -> Animation:
        """Send the animation to the visualizer; returns it."""
        anim = self.animation(fps)
        self.vis.set_animation(anim, play=bool(play), repetitions=int(repetitions))
        return anim

    def static_html(self) -> str:
        """The self-contained page of the scene as drawn so far (meshcat's static export)."""
        return self.vis.static_html()
