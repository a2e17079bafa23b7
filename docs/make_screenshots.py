"""Render the viewer's documentation images with headless Chromium.

Writes ``docs/viewer.png`` (a plan, paused in the middle of its first regrasp) and
``docs/manifold.png`` (a finger's joint-space manifold), the way
``tests/test_viz_browser.py`` renders them. The plan is ``--plan FILE`` if given, else
``out/plan.json`` when ``make demo`` has written it, else the small hand-made plan of
``regrasp_pin.viz.example_plan``. Usage::

    python docs/make_screenshots.py [--plan out/plan.json] [--out docs]
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

from PIL import Image

from regrasp_pin.plan import Plan
from regrasp_pin.viz import animate_plan, save_html, show_manifold
from regrasp_pin.viz.browser import screenshot
from regrasp_pin.viz.example_plan import synthetic_manifold, synthetic_plan

ROOT = Path(__file__).resolve().parent.parent
HIDE_CONTROLS = "viewer.gui.domElement.style.display = 'none'"


def _save_small(png: Path, out: Path, colors: int = 256) -> None:
    """Quantize to a palette: the images stay a few tens of kB."""
    img = Image.open(png).convert("RGB").quantize(colors, method=Image.Quantize.MEDIANCUT)
    img.save(out, optimize=True)
    print(f"wrote {out} ({out.stat().st_size / 1e3:.0f} kB)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--plan", type=Path, default=None, help="plan file to show")
    parser.add_argument("--out", type=Path, default=ROOT / "docs", help="output folder")
    parser.add_argument("--size", default="800x600", help="image size WxH [px]")
    args = parser.parse_args()
    width, height = (int(v) for v in args.size.split("x"))
    demo = ROOT / "out" / "plan.json"
    view_from = None
    if args.plan is not None:
        plan = Plan.load(args.plan)
    elif demo.is_file():
        plan = Plan.load(demo)
    else:
        plan = synthetic_plan()
        view_from = (0.9, -0.1, 0.8)  # its one regrasp is on the +x face
    regrasps = plan.regrasps()
    t_show = 0.5 * (regrasps[0].t_start + regrasps[0].t_end) if regrasps else float(plan.t[0])
    args.out.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        tmp_dir = Path(tmp)
        viewer = animate_plan(plan, play=False, display_time_s=t_show)
        if view_from is not None:
            viewer.look_from(view_from, 2.0)
        html = save_html(viewer.vis, tmp_dir / "plan.html")
        screenshot(
            html.as_uri(), tmp_dir / "viewer.png", width=width, height=height,
            before_js=HIDE_CONTROLS,
        )  # fmt: skip
        _save_small(tmp_dir / "viewer.png", args.out / "viewer.png")
        html = save_html(show_manifold(**synthetic_manifold()), tmp_dir / "manifold.html")
        screenshot(
            html.as_uri(), tmp_dir / "manifold.png", width=width, height=height,
            before_js=HIDE_CONTROLS,
        )  # fmt: skip
        _save_small(tmp_dir / "manifold.png", args.out / "manifold.png")


if __name__ == "__main__":
    main()
