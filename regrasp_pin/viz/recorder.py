"""An offline meshcat "window": records the scene and writes meshcat's static HTML.

:class:`SceneRecorder` stands in for the ZeroMQ connection of a
``meshcat.Visualizer``: every command (``set_object``, ``set_transform``,
``set_property``, ``set_animation``, ``delete``) is kept in the same scene tree the
meshcat server keeps, and :meth:`SceneRecorder.static_html` writes the page the
server's ``get_scene`` would write: the viewer JavaScript of the installed meshcat
package inlined, followed by the recorded commands. No server, no socket, no network.
"""

from __future__ import annotations

import base64
from pathlib import Path
from typing import Any

import meshcat
import umsgpack
from meshcat.servers.tree import SceneTree, find_node, walk

__all__ = ["SceneRecorder", "recording_visualizer", "viewer_js_path"]

_COMMANDS = ("set_object", "set_transform", "set_property", "set_animation", "delete")


def viewer_js_path() -> Path:
    """The minified meshcat viewer shipped with the installed ``meshcat`` package."""
    return Path(meshcat.__file__).resolve().parent / "viewer" / "dist" / "main.min.js"


def _command_js(data: bytes) -> str:
    # the same JavaScript the meshcat server writes for each stored command
    b64 = base64.b64encode(data).decode("ascii")
    return (
        f'\nfetch("data:application/octet-binary;base64,{b64}")\n'
        "    .then(res => res.arrayBuffer())\n"
        "    .then(buffer => viewer.handle_command_bytearray(new Uint8Array(buffer)));\n"
    )


_PAGE = """<!DOCTYPE html>
<html>
<head><meta charset="utf-8"><title>{title}</title></head>
<body>
<div id="meshcat-pane"></div>
<script>
{viewer_js}
</script>
<script>
var viewer = new MeshCat.Viewer(document.getElementById("meshcat-pane"));
{commands}
</script>
<style>
body {{ margin: 0; }}
#meshcat-pane {{ width: 100vw; height: 100vh; overflow: hidden; }}
</style>
<script id="embedded-json"></script>
</body>
</html>
"""


class SceneRecorder:
    """Records meshcat commands into a scene tree, like the meshcat server does.

    Use it as the ``window`` of a ``meshcat.Visualizer`` (see
    :func:`recording_visualizer`); anything that draws on a visualizer (Pinocchio's
    ``MeshcatVisualizer`` included) then draws into the recording.
    """

    web_url: str | None = None

    def __init__(self) -> None:
        self.tree: Any = SceneTree()
        self.n_commands = 0

    def send(self, command: Any) -> None:
        """Store one meshcat command (the ``window.send`` interface of meshcat)."""
        data = command.lower()
        kind = data["type"]
        if kind not in _COMMANDS:
            return
        path = [p for p in data["path"].split("/") if p]
        packed = umsgpack.packb(data)
        self.n_commands += 1
        if kind == "set_object":
            node = find_node(self.tree, path)
            node.object = packed
            node.properties = []
        elif kind == "set_transform":
            find_node(self.tree, path).transform = packed
        elif kind == "set_property":
            find_node(self.tree, path).properties.append(packed)
        elif kind == "set_animation":
            find_node(self.tree, path).animation = packed
        elif kind == "delete":
            if path:
                parent = find_node(self.tree, path[:-1])
                parent.pop(path[-1], None)
            else:
                self.tree = SceneTree()

    def paths(self) -> list[str]:
        """Paths (``/meshcat/...``) of every node that holds an object, in tree order."""
        out = []

        def visit(node: Any, prefix: str) -> None:
            if node.object is not None:
                out.append(prefix or "/")
            for name, child in node.items():
                visit(child, f"{prefix}/{name}")

        visit(self.tree, "")
        return out

    def command(self, path: str, kind: str = "object") -> dict[str, Any] | None:
        """The last recorded command of a node, decoded: ``kind`` is ``"object"``,
        ``"transform"`` or ``"animation"`` (None if there is none); ``"properties"``
        gives ``{"properties": [...]}``, every ``set_property`` in order."""
        node = self.tree
        for name in (p for p in path.split("/") if p):
            if name not in node:
                return None
            node = node[name]
        if kind == "properties":
            return {"properties": [umsgpack.unpackb(p) for p in node.properties]}
        data = getattr(node, kind)
        return None if data is None else umsgpack.unpackb(data)

    def static_html(self, title: str = "regrasp_pin") -> str:
        """The self-contained HTML page of the recorded scene (meshcat's static export)."""
        commands = []
        for node in walk(self.tree):
            if node.object is not None:
                commands.append(_command_js(node.object))
            commands.extend(_command_js(p) for p in node.properties)
            if node.transform is not None:
                commands.append(_command_js(node.transform))
            if node.animation is not None:
                commands.append(_command_js(node.animation))
        return _PAGE.format(
            title=title,
            viewer_js=viewer_js_path().read_text(encoding="utf-8"),
            commands="".join(commands),
        )

    # meshcat.Visualizer calls these on its window; a recording has no browser
    def get_scene(self) -> str:
        """What ``meshcat.Visualizer.static_html()`` asks its window for."""
        return self.static_html()

    def wait(self) -> str:
        """Nothing to wait for: there is no browser."""
        return "ok"

    def open(self) -> SceneRecorder:
        """Nothing to open: there is no browser."""
        return self

    def close(self) -> None:
        """Nothing to close."""
        return None


def recording_visualizer() -> meshcat.Visualizer:
    """A ``meshcat.Visualizer`` whose window is a fresh :class:`SceneRecorder`."""
    return meshcat.Visualizer(window=SceneRecorder())
