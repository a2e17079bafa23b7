"""On-page controls of an exported plan: play/pause, a time slider and a legend.

meshcat's own animation controls sit three clicks deep ("Open Controls > Animations >
default"). :func:`controls_html` is a small overlay added to the static page
(:func:`~regrasp_pin.viz.export_html`): a play/pause button and a time slider at the
bottom left, always visible, that drive meshcat's animator (``viewer.animator``), and a
legend of what the scene draws at the top right.
"""

from __future__ import annotations

import html

from .plan_scene import GRID_COLOR, P_COLOR, Q_COLOR, WAYPOINT_COLOR, PlanViewer
from .scene import OBJECT_COLOR, finger_color

__all__ = ["controls_html"]

_STYLE = (
    "position:fixed;z-index:10;background:rgba(255,255,255,0.88);font:13px sans-serif;"
    "padding:6px 10px;border-radius:4px;box-shadow:0 1px 4px rgba(0,0,0,0.25)"
)

_SCRIPT = """
<script>
(function () {
  var btn = document.getElementById("rp-play"), slider = document.getElementById("rp-time"),
      label = document.getElementById("rp-label");
  function show(t) { label.textContent = t.toFixed(2) + " / " + slider.max + " s"; }
  function start() {
    if (typeof viewer === "undefined" || !viewer.animator || !(viewer.animator.duration > 0)) {
      return setTimeout(start, 100);
    }
    var a = viewer.animator;
    slider.max = a.duration.toFixed(2);
    btn.disabled = false;
    btn.onclick = function () {
      if (a.playing) { a.pause(); } else { a.play(); }
    };
    slider.oninput = function () {
      var t = parseFloat(slider.value);
      a.pause(); a.seek(t); a.display_progress(t); show(t);
    };
    (function tick() {
      btn.textContent = a.playing ? "Pause" : "Play";
      if (a.playing) { slider.value = a.time; show(a.time); }
      requestAnimationFrame(tick);
    })();
  }
  start();
})();
</script>
"""


def _swatch(rgb: tuple[float, float, float]) -> str:
    r, g, b = (int(round(255 * c)) for c in rgb)
    return (
        f"<span style='display:inline-block;width:12px;height:12px;margin-right:6px;"
        f"vertical-align:middle;background:rgb({r},{g},{b})'></span>"
    )


def controls_html(viewer: PlanViewer) -> str:
    """The overlay's HTML (controls, legend and their script) for ``viewer``'s plan."""
    entries = [
        (OBJECT_COLOR, "object"),
        (P_COLOR, "P: where a finger lifts off"),
        (Q_COLOR, "Q: where it lands"),
        (GRID_COLOR, "grid path on the surface"),
        (WAYPOINT_COLOR, "Hopfield waypoints"),
    ]
    fingers = [
        (finger_color(i), f"{name}: fingertip path")
        for i, name in enumerate(viewer.hand.fingers)
        if any(p.kind == "regrasp" for p in viewer.plan.phases.get(name, []))
    ]
    legend = "".join(
        f"<div>{_swatch(rgb)}{html.escape(text)}</div>" for rgb, text in entries + fingers
    )
    duration = float(viewer.plan.t[-1] - viewer.plan.t[0])
    return (
        f"<div id='rp-controls' style='{_STYLE};left:12px;bottom:12px'>"
        "<button id='rp-play' disabled style='width:60px'>Play</button> "
        f"<input id='rp-time' type='range' min='0' max='{duration:.2f}' step='0.01' "
        "value='0' style='width:340px;vertical-align:middle'> "
        f"<span id='rp-label'>0.00 / {duration:.2f} s</span></div>"
        f"<div id='rp-legend' style='{_STYLE};right:12px;top:40px;line-height:1.6'>"
        f"{legend}</div>" + _SCRIPT
    )
