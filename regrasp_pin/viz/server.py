"""A meshcat server bound to loopback, on a port of your choice.

meshcat's own ``meshcat-server`` picks the first free web port from 7000 and listens
on every interface; it has no ``--port`` option. This module runs the same server
(meshcat's ``ZMQWebSocketBridge``) but binds the web server to ``127.0.0.1`` and
honours ``--port``. :class:`LiveServer` starts it as a subprocess and connects a
``meshcat.Visualizer`` to it.

Run directly: ``python -m regrasp_pin.viz.server [--port N]``; it prints
``zmq_url=...`` and ``web_url=...`` lines, like meshcat's server.
"""

from __future__ import annotations

import argparse
import atexit
import os
import subprocess
import sys
import tempfile
from collections.abc import Sequence
from contextlib import redirect_stdout
from io import StringIO

import meshcat

from ..exceptions import InputError, RegraspError

__all__ = ["LiveServer", "main"]

LOOPBACK = "127.0.0.1"


class LiveServer:
    """A meshcat server subprocess on ``127.0.0.1`` and a visualizer connected to it.

    Args:
        port: Web port; default the first free port from 7000.
        startup_timeout_s: How long to wait for the server to report its URLs [s].

    Attributes:
        url: The viewer page, ``http://127.0.0.1:<port>/static/``.
        zmq_url: Where the visualizer sends its commands.
        vis: A ``meshcat.Visualizer`` connected to the server.

    Raises:
        InputError: the port is in use or not allowed.
        RegraspError: the server did not start (its error output is in the message).
    """

    def __init__(self, port: int | None = None, startup_timeout_s: float = 20.0) -> None:
        if port is not None and not (isinstance(port, int) and 0 < port < 65536):
            raise InputError("port", f"{port!r} is not allowed", "an integer in 1..65535")
        args = [sys.executable, "-u", "-m", "regrasp_pin.viz.server", "--parent", str(os.getpid())]
        if port is not None:
            args += ["--port", str(port)]
        env = dict(os.environ)
        package_parent = os.path.dirname(os.path.dirname(os.path.dirname(__file__)))
        env["PYTHONPATH"] = os.pathsep.join(
            p for p in (package_parent, env.get("PYTHONPATH", "")) if p
        )
        self._stderr = tempfile.TemporaryFile()
        self._proc = subprocess.Popen(
            args, stdout=subprocess.PIPE, stderr=self._stderr, env=env, start_new_session=True
        )
        atexit.register(self.close)
        lines: dict[str, str] = {}
        while len(lines) < 2:
            raw = self._proc.stdout.readline() if self._proc.stdout else b""
            if not raw:  # the process ended
                self._proc.wait(timeout=startup_timeout_s)
                self._stderr.seek(0)
                err = self._stderr.read().decode(errors="replace").strip()
                self.close()
                if "Address already in use" in err or "Errno 98" in err:
                    raise InputError("port", f"{port} is in use on {LOOPBACK}", "a free port")
                raise RegraspError(f"the meshcat server did not start: {err[-2000:]}")
            key, _, value = raw.decode().strip().partition("=")
            if key in ("zmq_url", "web_url"):
                lines[key] = value
        self.zmq_url = lines["zmq_url"]
        self.url = lines["web_url"]
        with redirect_stdout(StringIO()):  # meshcat prints the URL; the caller decides
            self.vis = meshcat.Visualizer(zmq_url=self.zmq_url)

    @property
    def running(self) -> bool:
        """Whether the server process is alive."""
        return self._proc.poll() is None

    def close(self) -> None:
        """Stop the server (idempotent)."""
        if self._proc.poll() is None:
            self._proc.terminate()
            try:
                self._proc.wait(timeout=5)
            except subprocess.TimeoutExpired:
                self._proc.kill()
                self._proc.wait()
        if self._proc.stdout is not None:
            self._proc.stdout.close()
        self._stderr.close()

    def __enter__(self) -> LiveServer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _bridge_class() -> type:
    from meshcat.servers.zmqserver import ZMQWebSocketBridge

    class LoopbackBridge(ZMQWebSocketBridge):
        """meshcat's bridge with its web server bound to ``self.host`` only."""

        def make_app(self):  # noqa: ANN202 - tornado application
            app = super().make_app()
            listen = app.listen

            def listen_on_host(port: int, **kwargs: object) -> object:
                return listen(port, address=self.host, **kwargs)

            app.listen = listen_on_host
            return app

    return LoopbackBridge


def main(argv: Sequence[str] | None = None) -> int:
    """Run the server until interrupted; print its ``zmq_url`` and ``web_url``."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--port", type=int, default=None, help="web port (default: from 7000)")
    parser.add_argument(
        "--parent", type=int, default=None, help="exit when the process with this id ends"
    )
    args = parser.parse_args(argv)
    bridge = _bridge_class()(host=LOOPBACK, port=args.port)
    print(f"zmq_url={bridge.zmq_url}", flush=True)
    print(f"web_url={bridge.web_url}", flush=True)
    if args.parent is not None:
        from tornado.ioloop import PeriodicCallback

        def stop_if_orphaned() -> None:  # the parent died without closing us
            if os.getppid() != args.parent:
                bridge.ioloop.stop()

        PeriodicCallback(stop_if_orphaned, 500).start()
    try:
        bridge.run()
    except KeyboardInterrupt:
        pass
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
