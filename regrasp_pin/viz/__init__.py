"""Meshcat viewer for plans and joint-space manifolds (optional extra ``viz``).

Never imported by ``import regrasp_pin``; ``import regrasp_pin.viz`` raises
:class:`~regrasp_pin.exceptions.MissingExtraError` (an ImportError that says
``pip install 'regrasp-pin[viz]'``) when meshcat is not installed.

- :class:`PlanViewer` draws a plan (hand, object mesh, contacts and normals, grid
  path, tip path, Hopfield waypoints and polygon of each regrasp, fingertip trails);
  :func:`animate_plan` adds the animation with its timeline.
- :func:`export_html` writes a self-contained static HTML page;
  :func:`show_plan_live` serves the viewer on ``127.0.0.1`` and returns its URL.
- :func:`show_manifold` draws a finger's 3-D joint space: limit box, manifold
  coloured by margin, P's path and Q.

See ``docs/viewer.md``.
"""

from __future__ import annotations

from ..exceptions import MissingExtraError

try:
    import meshcat  # noqa: F401
    import meshcat.animation  # noqa: F401
except ImportError:
    raise MissingExtraError("meshcat", "viz") from None

from .animation import animate_plan, build_animation, frame_times, plan_states
from .manifold_scene import margin_colors, show_manifold
from .plan_scene import PlanViewer
from .publish import export_html, save_html, show_plan_live, wait_until_interrupted
from .recorder import SceneRecorder, recording_visualizer
from .server import LiveServer

__all__ = [
    "LiveServer",
    "PlanViewer",
    "SceneRecorder",
    "animate_plan",
    "build_animation",
    "export_html",
    "frame_times",
    "margin_colors",
    "plan_states",
    "recording_visualizer",
    "save_html",
    "show_manifold",
    "show_plan_live",
    "wait_until_interrupted",
]
