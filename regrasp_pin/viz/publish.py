"""Putting a plan in front of people: a static HTML file, or a live viewer on loopback."""

from __future__ import annotations

import logging
import signal
import threading
import time
import webbrowser
from pathlib import Path

import meshcat

from ..plan import Plan
from .animation import animate_plan
from .controls import controls_html
from .server import LiveServer

__all__ = ["export_html", "save_html", "show_plan_live", "wait_until_interrupted"]

log = logging.getLogger(__name__)

#: Live servers started by :func:`show_plan_live`, kept alive until the process exits.
_LIVE: list[LiveServer] = []


def _as_plan(plan: Plan | str | Path) -> Plan:
    return plan if isinstance(plan, Plan) else Plan.load(plan)


def save_html(vis: meshcat.Visualizer, path: str | Path, *, extra_html: str = "") -> Path:
    """Write the scene of ``vis`` (recording or live) as a self-contained HTML file, with
    ``extra_html`` (e.g. :func:`~.controls.controls_html`) at the end of its body."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    page = vis.static_html()
    if extra_html:
        at = page.rfind("</body>")
        page = page[:at] + extra_html + page[at:] if at >= 0 else page + extra_html
    path.write_text(page, encoding="utf-8")
    return path


def export_html(
    plan: Plan | str | Path,
    path: str | Path,
    *,
    fps: float = 30.0,
    play: bool = True,
    display_time_s: float | None = None,
    controls: bool = True,
) -> Path:
    """Write a plan as one self-contained HTML file that opens without a server.

    The page holds meshcat's viewer (inlined from the installed ``meshcat`` package;
    nothing is fetched from the network), the scene and its animation: open it in a
    browser and turn the view with the mouse. With ``controls`` the page also shows a
    play/pause button, a time slider and a legend (:mod:`.controls`); meshcat's own
    "Open Controls > Animations" stays too.

    Args:
        plan: A :class:`~regrasp_pin.plan.Plan` or the path of a plan file.
        path: Output ``.html`` file (folders are created).
        fps: Animation frame rate [1/s].
        play: Start playing when the page opens.
        display_time_s: Time [s] shown before playing (default the start).
        controls: Add the on-page controls and legend.

    Returns:
        The path written.
    """
    viewer = animate_plan(_as_plan(plan), None, fps=fps, play=play, display_time_s=display_time_s)
    out = save_html(viewer.vis, path, extra_html=controls_html(viewer) if controls else "")
    log.info("wrote %s (%.1f MB)", out, out.stat().st_size / 1e6)
    return out


def show_plan_live(
    plan: Plan | str | Path,
    *,
    port: int | None = None,
    open_browser: bool = False,
    fps: float = 30.0,
) -> str:
    """Serve a plan's animated scene on ``127.0.0.1`` and return the page's URL.

    The meshcat server runs in a subprocess until this process exits (or its
    :class:`~regrasp_pin.viz.server.LiveServer` is closed); call
    :func:`wait_until_interrupted` to keep a script alive while people look.

    Args:
        plan: A plan or the path of a plan file.
        port: Web port (default: the first free port from 7000).
        open_browser: Also open the URL in the default browser.
        fps: Animation frame rate [1/s].

    Raises:
        InputError: the port is in use.
    """
    p = _as_plan(plan)
    server = LiveServer(port)
    _LIVE.append(server)
    animate_plan(p, server.vis, fps=fps, play=True)
    if open_browser:
        try:
            webbrowser.open(server.url, new=2)
        except webbrowser.Error as exc:  # no browser on this machine
            log.warning("cannot open a browser: %s", exc)
    return server.url


def wait_until_interrupted() -> None:
    """Block until Ctrl-C (SIGINT) or SIGTERM, then stop the live servers started here."""

    def interrupt(signum: int, frame: object) -> None:
        raise KeyboardInterrupt

    if threading.current_thread() is threading.main_thread():
        # also when started in the background by a shell, which ignores SIGINT there
        signal.signal(signal.SIGINT, interrupt)
        signal.signal(signal.SIGTERM, interrupt)
    try:
        while True:
            time.sleep(3600)
    except KeyboardInterrupt:
        pass
    finally:
        while _LIVE:
            _LIVE.pop().close()
