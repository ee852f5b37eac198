"""``embree-rt serve``: bind the port, warm the kernels, run the app until Ctrl-C."""

from __future__ import annotations

import ipaddress
import socket
import sys
from importlib import resources
from pathlib import Path

import numpy as np
import uvicorn

from embree_rt.errors import InputError
from embree_rt.scene.model import Scene
from embree_rt.web.messages import MAX_MESSAGE_BYTES

# The scene shown when none is given: the seed article's showcase, shipped with the package.
DEFAULT_SCENE = "default_scene.toml"


def listen(host: str, port: int) -> tuple[socket.socket, bool]:
    """A listening TCP socket on ``host``:``port`` (0: any free port) and whether the address
    is a loopback one. InputError (one line) when the name does not resolve or the port is
    taken."""
    try:
        family, kind, proto, _, address = socket.getaddrinfo(
            host, port, type=socket.SOCK_STREAM, flags=socket.AI_PASSIVE
        )[0]
    except socket.gaierror as error:
        raise InputError(f"--host: {host}: {error.strerror}") from None
    listener = socket.socket(family, kind, proto)
    listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        listener.bind(address)
        listener.listen(64)
    except OSError as error:
        listener.close()
        raise InputError(f"--port: cannot listen on {host}:{port}: {error.strerror}") from None
    return listener, ipaddress.ip_address(address[0]).is_loopback


def _warm_up(session) -> None:
    """Compile (or load from numba's cache) every kernel a request needs, before the first
    request: the first click would otherwise wait seconds."""
    from embree_rt.film import Film
    from embree_rt.web.trace2d import Layout, trace_layout

    circle = np.array([[480.0, 300.0, 80.0]])
    trace_layout(Layout(circle, np.array([1]), (300.0, 300.0), 8, 360.0, 0.0, 960.0, 600.0))
    session.set_size(16, 9)
    session.render_pass(0, session.generation, Film(16, 9))
    session.close()


def served_scene(path: Path) -> tuple[Scene, dict]:
    """The scene ``serve`` shows of ``path`` and the scene file's content it is edited and
    downloaded as: a scene file as it is; a particle or mesh file as ``render`` makes it
    (framed on its bounds, the default rig, a floor), the document naming the file in a
    ``[[particles]]`` or ``[[meshes]]`` entry beside that camera, lights and floor."""
    from embree_rt.scene import load_scene
    from embree_rt.scene.loader import read_document
    from embree_rt.scene.mesh_formats import MESH_SUFFIXES
    from embree_rt.scene.particles.read import is_particle_file
    from embree_rt.scene.writer import look_document

    if is_particle_file(path):
        scene, key = Scene.from_particles(path), "particles"
    elif path.suffix.lower() in MESH_SUFFIXES:
        scene, key = Scene.from_file(path), "meshes"
    else:
        return load_scene(path), read_document(path)
    size = {"width": scene.render.width, "height": scene.render.height}
    return scene, {"render": size, **look_document(scene), key: [{"file": path.name}]}


def serve(scene_path: str | None, host: str, port: int) -> None:
    """Serve the pages for the scene, particle or mesh file ``scene_path`` (None: the
    showcase) until Ctrl-C."""
    from embree_rt.web.app import create_app
    from embree_rt.web.preview import session_factory

    path = Path(scene_path) if scene_path is not None else _default_scene()
    # a bad file is one line and exit 2, before the port is taken
    scene, document = served_scene(path)
    new_session = session_factory(scene, document, path.parent)
    listener, loopback = listen(host, port)
    with listener:
        _warm_up(new_session())
        bound_host, bound_port = listener.getsockname()[:2]
        if not loopback:
            print(
                f"embree-rt: warning: listening on {bound_host}, not a loopback address: anyone "
                "who can reach this port can drive the server",
                file=sys.stderr,
            )
        shown = f"[{bound_host}]" if ":" in bound_host else bound_host
        announcement = (
            f"embree-rt: serving {path.name} at http://{shown}:{bound_port}/ (the 2D demo at "
            f"http://{shown}:{bound_port}/2d); Ctrl-C stops"
        )
        config = uvicorn.Config(
            create_app(new_session, loopback=loopback),
            log_level="warning",
            lifespan="off",
            ws="websockets-sansio",
            # The protocol's own limit, far above the app's: messages between the two get the
            # app's error reply; beyond it the connection is closed (1009, message too big).
            ws_max_size=16 * MAX_MESSAGE_BYTES,
            timeout_graceful_shutdown=2,
        )
        AnnouncingServer(config, announcement).run(sockets=[listener])


class AnnouncingServer(uvicorn.Server):
    """A uvicorn server that prints its address once it is serving: by then its signal
    handlers are installed, so a Ctrl-C right after the line stops it cleanly (a Ctrl-C before
    the event loop existed left asyncio's half-made loop to fail in its finaliser)."""

    def __init__(self, config: uvicorn.Config, announcement: str) -> None:
        super().__init__(config)
        self.announcement = announcement

    async def startup(self, sockets: list[socket.socket] | None = None) -> None:
        await super().startup(sockets=sockets)
        print(self.announcement, flush=True)


def _default_scene() -> Path:
    return Path(str(resources.files("embree_rt.web") / DEFAULT_SCENE))
