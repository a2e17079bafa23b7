"""Screenshots of a viewer page in headless Chromium (for tests and documentation images).

Chromium is driven through its DevTools protocol (a WebSocket, via tornado, which
meshcat already depends on): open the page, wait until meshcat has built the scene,
optionally run some JavaScript (pause the animation and seek to a time), then
capture the page as PNG. The same flags work with Chromium's ``--screenshot``
command-line mode (:func:`chromium_command`).

WebGL without a GPU: ``--disable-gpu`` keeps Chromium off the GPU and WebGL then
runs on SwiftShader, Chromium's software renderer; ``--use-angle=swiftshader`` and
``--enable-unsafe-swiftshader`` ask for it explicitly (recent Chromium versions
refuse the SwiftShader fallback for WebGL without the latter). The host resolver
rule makes every name except ``127.0.0.1`` unresolvable, so a page that needed the
network would visibly fail.
"""

from __future__ import annotations

import asyncio
import base64
import itertools
import json
import os
import shutil
import subprocess
import tempfile
import time
import urllib.request
from pathlib import Path
from typing import Any

from ..exceptions import RegraspError

__all__ = [
    "CHROMIUM_FLAGS",
    "ChromiumNotFound",
    "chromium_command",
    "find_chromium",
    "screenshot",
]

#: Flags for headless Chromium on a machine without GPU, display or internet.
CHROMIUM_FLAGS: tuple[str, ...] = (
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--disable-dev-shm-usage",
    "--use-angle=swiftshader",
    "--enable-unsafe-swiftshader",
    "--hide-scrollbars",
    "--host-resolver-rules=MAP * ~NOTFOUND, EXCLUDE 127.0.0.1",
)


class ChromiumNotFound(RegraspError):
    """No Chromium executable was found."""


def find_chromium() -> str:
    """Path of a Chromium executable (``$CHROMIUM``, then ``chromium``,
    ``chromium-browser``, ``google-chrome`` on the PATH).

    Raises:
        ChromiumNotFound: none was found.
    """
    env = os.environ.get("CHROMIUM")
    if env and shutil.which(env):
        return str(shutil.which(env))
    for name in ("chromium", "chromium-browser", "google-chrome"):
        path = shutil.which(name)
        if path:
            return path
    raise ChromiumNotFound(
        "no Chromium found (install Debian's `chromium` package or set $CHROMIUM)"
    )


def chromium_command(
    url: str, png: str | Path, user_data_dir: str | Path, *, width: int = 800, height: int = 600,
    virtual_time_budget_ms: int = 3000,
) -> list[str]:  # fmt: skip
    """The command line of Chromium's one-shot ``--screenshot`` mode for ``url``."""
    return [
        find_chromium(),
        *CHROMIUM_FLAGS,
        f"--user-data-dir={user_data_dir}",
        f"--window-size={width},{height}",
        f"--screenshot={png}",
        f"--virtual-time-budget={virtual_time_budget_ms}",
        url,
    ]


class _DevTools:
    """A minimal DevTools protocol client over one page's WebSocket."""

    def __init__(self, ws: Any) -> None:
        self.ws = ws
        self.ids = itertools.count(1)

    async def call(self, method: str, **params: object) -> dict:
        msg_id = next(self.ids)
        await self.ws.write_message(json.dumps({"id": msg_id, "method": method, "params": params}))
        while True:
            raw = await self.ws.read_message()
            if raw is None:
                raise RegraspError(f"Chromium closed the DevTools connection during {method}")
            msg = json.loads(raw)
            if msg.get("id") == msg_id:
                if "error" in msg:
                    raise RegraspError(f"DevTools {method}: {msg['error']}")
                return msg.get("result", {})

    async def evaluate(self, expression: str) -> object:
        res = await self.call(
            "Runtime.evaluate", expression=expression, awaitPromise=True, returnByValue=True
        )
        if "exceptionDetails" in res:
            raise RegraspError(f"JavaScript failed: {res['exceptionDetails']}")
        return res.get("result", {}).get("value")


_NEXT_FRAMES = "new Promise(r => requestAnimationFrame(() => requestAnimationFrame(() => r(1))))"


async def _drive(
    port: int, url: str, png: Path, ready_js: str, before_js: str | None, timeout_s: float,
    width: int, height: int,
) -> object:  # fmt: skip
    from tornado.websocket import websocket_connect

    deadline = time.monotonic() + timeout_s
    ws_url = None
    while ws_url is None:
        with urllib.request.urlopen(f"http://127.0.0.1:{port}/json/list", timeout=5) as r:
            pages = [t for t in json.load(r) if t.get("type") == "page"]
        if pages:
            ws_url = pages[0]["webSocketDebuggerUrl"]
        elif time.monotonic() > deadline:
            raise RegraspError("Chromium opened no page")
        else:
            await asyncio.sleep(0.1)
    ws = await websocket_connect(ws_url, max_message_size=256 * 1024 * 1024)
    try:
        dt = _DevTools(ws)
        await dt.call(
            "Emulation.setDeviceMetricsOverride",
            width=width, height=height, deviceScaleFactor=1, mobile=False,
        )  # fmt: skip
        await dt.call("Page.navigate", url=url)
        while not await dt.evaluate(f"(() => {{ try {{ return !!({ready_js}); }} "
                                    "catch (e) { return false; } })()"):  # fmt: skip
            if time.monotonic() > deadline:
                raise RegraspError(f"the page was not ready within {timeout_s} s: {ready_js}")
            await asyncio.sleep(0.1)
        await dt.evaluate(_NEXT_FRAMES)
        result = None
        if before_js:
            result = await dt.evaluate(before_js)
            await dt.evaluate(_NEXT_FRAMES)
        shot = await dt.call("Page.captureScreenshot", format="png")
        png.write_bytes(base64.b64decode(shot["data"]))
        return result
    finally:
        ws.close()


def screenshot(
    url: str,
    png: str | Path,
    *,
    width: int = 800,
    height: int = 600,
    ready_js: str = "typeof viewer !== 'undefined' && viewer.scene.children.length > 0",
    before_js: str | None = None,
    timeout_s: float = 40.0,
) -> object:
    """Open ``url`` in headless Chromium and save a PNG of the page.

    Args:
        url: Page to open (``file://`` or ``http://127.0.0.1:...``).
        png: Output file.
        width: Viewport width [px].
        height: Viewport height [px].
        ready_js: JavaScript expression polled until true before the capture.
        before_js: JavaScript run (awaited) before the capture, e.g. to pause the
            animation and seek; its JSON-able value is returned.
        timeout_s: Give up after this long [s].

    Returns:
        The value of ``before_js`` (or None).

    Raises:
        ChromiumNotFound: no Chromium on this machine.
        RegraspError: the page did not get ready, or Chromium failed.
    """
    exe = find_chromium()
    png = Path(png)
    png.parent.mkdir(parents=True, exist_ok=True)
    # Chromium's helper processes may still write to the profile while it is removed
    with tempfile.TemporaryDirectory(
        prefix="regrasp-chromium-", ignore_cleanup_errors=True
    ) as profile:
        proc = subprocess.Popen(
            [
                exe, *CHROMIUM_FLAGS, f"--user-data-dir={profile}",
                f"--window-size={width},{height}", "--remote-debugging-port=0", "about:blank",
            ],
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True,
        )  # fmt: skip
        try:
            port_file = Path(profile) / "DevToolsActivePort"
            deadline = time.monotonic() + timeout_s
            while not (port_file.is_file() and port_file.read_text().strip()):
                if proc.poll() is not None:
                    raise RegraspError(f"Chromium exited with code {proc.returncode}")
                if time.monotonic() > deadline:
                    raise RegraspError("Chromium did not open its DevTools port")
                time.sleep(0.05)
            port = int(port_file.read_text().splitlines()[0])
            return asyncio.run(
                _drive(port, url, png, ready_js, before_js, timeout_s, width, height)
            )
        finally:
            _stop_group(proc)


def _stop_group(proc: subprocess.Popen) -> None:
    """Stop Chromium and its helper processes (its own process group)."""
    import os
    import signal

    for sig, wait_s in ((signal.SIGTERM, 10.0), (signal.SIGKILL, 5.0)):
        try:
            os.killpg(proc.pid, sig)
        except (ProcessLookupError, PermissionError):
            pass
        try:
            proc.wait(timeout=wait_s)
            break
        except subprocess.TimeoutExpired:
            continue
    time.sleep(0.2)  # let the helpers of the group exit before the profile is removed
