"""The Starlette application: two pages, their static files, and one WebSocket each.

``/2d`` sends its layout over ``/ws/2d`` and draws the polylines the server traces; ``/`` opens a
preview session over ``/ws/preview`` (one session per connection, so each tab has its own).
Every reply is JSON text, except the PNG images, which follow the JSON message announcing them.
"""

from __future__ import annotations

import asyncio
import json
import sys
import time
import traceback
from collections.abc import Callable
from urllib.parse import urlsplit

import numpy as np
from starlette.applications import Starlette
from starlette.middleware import Middleware
from starlette.middleware.trustedhost import TrustedHostMiddleware
from starlette.requests import Request
from starlette.responses import Response
from starlette.routing import Route, WebSocketRoute
from starlette.websockets import WebSocket, WebSocketDisconnect, WebSocketState

from embree_rt.film import Film
from embree_rt.web import messages
from embree_rt.web.assets import Asset, load_assets
from embree_rt.web.messages import MessageError
from embree_rt.web.preview import OvertakenError, PreviewSession, png_bytes
from embree_rt.web.trace2d import trace_layout

# Security headers on every HTTP answer: the pages load only their own scripts and styles and
# talk only to this server; nothing may frame them.
HEADERS = {
    "Content-Security-Policy": (
        "default-src 'none'; script-src 'self'; style-src 'self'; img-src 'self' blob: data:; "
        "connect-src 'self'; frame-ancestors 'none'; base-uri 'none'; form-action 'none'"
    ),
    "X-Content-Type-Options": "nosniff",
    "Referrer-Policy": "no-referrer",
    "Cache-Control": "no-cache",
}
LOOPBACK_HOSTS = ["127.0.0.1", "localhost", "::1", "[::1]"]
MAX_SESSIONS = 16
# Close code for a WebSocket from a page of another site (RFC 6455 "policy violation").
POLICY_VIOLATION = 1008


def _answer(asset: Asset | None) -> Response:
    if asset is None:
        return Response("not found\n", 404, HEADERS, "text/plain; charset=utf-8")
    return Response(asset.body, 200, HEADERS, asset.media_type)


def create_app(new_session: Callable[[], PreviewSession], *, loopback: bool = True) -> Starlette:
    """The application. ``new_session()`` makes each preview tab's session; ``loopback``
    (the server listens on a loopback address only) restricts the Host header to loopback
    names, which keeps other sites' pages out through DNS rebinding."""
    static, pages = load_assets()
    # Preview sessions open or being made. Counted (and the slot taken) before the first await
    # that makes one: a check that awaited before counting let 20 sockets opened at once all
    # through the limit.
    open_sessions = 0

    async def page(request: Request) -> Response:
        return _answer(pages.get(request.url.path))

    async def static_file(request: Request) -> Response:
        # A key into the table read at start, never a path: nothing else can be served.
        return _answer(static.get(request.path_params["name"]))

    async def not_found(request: Request) -> Response:
        return _answer(None)

    async def demo2d_socket(socket: WebSocket) -> None:
        if not await _accept(socket):
            return
        while (text := await _receive(socket)) is not _CLOSED:
            reply = await _answer_or_error(_trace_reply, text)
            if not await _send(socket, reply):
                return

    async def preview_socket(socket: WebSocket) -> None:
        nonlocal open_sessions
        if not await _accept(socket):
            return
        if open_sessions >= MAX_SESSIONS:
            await _send(socket, {"type": "error", "message": "too many preview sessions open"})
            await socket.close()
            return
        open_sessions += 1
        try:
            session = await asyncio.to_thread(new_session)
            try:
                await PreviewConnection(socket, session).run()
            finally:
                await asyncio.to_thread(session.close)
        finally:
            open_sessions -= 1

    routes = [
        Route("/", page),
        Route("/2d", page),
        Route("/static/{name}", static_file),
        WebSocketRoute("/ws/2d", demo2d_socket),
        WebSocketRoute("/ws/preview", preview_socket),
        Route("/{rest:path}", not_found),
    ]
    hosts = LOOPBACK_HOSTS if loopback else ["*"]
    return Starlette(
        routes=routes, middleware=[Middleware(TrustedHostMiddleware, allowed_hosts=hosts)]
    )


_CLOSED = object()


async def _accept(socket: WebSocket) -> bool:
    """Accept a WebSocket unless a browser opened it from a page this server did not serve
    (its Origin names another host): other sites must not drive the server."""
    origin = socket.headers.get("origin")
    if origin is not None and urlsplit(origin).netloc != socket.headers.get("host"):
        await socket.close(code=POLICY_VIOLATION)
        return False
    await socket.accept()
    return True


async def _receive(socket: WebSocket):
    """The next message's text (bytes for a binary one), or ``_CLOSED``."""
    try:
        message = await socket.receive()
    except (WebSocketDisconnect, RuntimeError):
        return _CLOSED
    if message["type"] == "websocket.disconnect":
        return _CLOSED
    text = message.get("text")
    return text if text is not None else message.get("bytes")


async def _send(socket: WebSocket, reply: dict | bytes) -> bool:
    """Send JSON (or bytes); False if the client has gone."""
    if socket.client_state != WebSocketState.CONNECTED:
        return False
    try:
        if isinstance(reply, bytes):
            await socket.send_bytes(reply)
        else:
            await socket.send_text(json.dumps(reply))
    except (WebSocketDisconnect, RuntimeError, OSError):
        return False
    return True


async def _answer_or_error(handle, text) -> dict | None:
    """``await handle(message)`` for the message in ``text``; a message this server will not act
    on is answered with its one-line error, and so is one that meets a bug of ours (said so, the
    traceback on the server's console), so that no message can drop the connection."""
    try:
        return await handle(messages.parse(text))
    except MessageError as error:
        return {"type": "error", "message": str(error)}
    except Exception:
        traceback.print_exc(file=sys.stderr)
        return {"type": "error", "message": "the server failed on this message (see the server)"}


async def _trace_reply(message: dict) -> dict:
    """The answer to a 2D demo message: the traced polylines of its layout."""
    if message["type"] != "trace":
        raise MessageError(f"unknown message type {message['type']!r}; expected 'trace'")
    layout = messages.layout_2d(message)
    started = time.perf_counter()
    paths = await asyncio.to_thread(trace_layout, layout)
    return {
        "type": "rays",
        "id": message.get("id") if isinstance(message.get("id"), int) else None,
        "trace_ms": round(1000 * (time.perf_counter() - started), 2),
        # Packed as ``LightPaths`` is: path k's points from starts[k] to starts[k + 1].
        "points": np.round(paths.points, 3).ravel().tolist(),
        "weights": np.round(paths.weights, 5).tolist(),
        "kinds": paths.kinds.tolist(),
        "starts": paths.starts.tolist(),
    }


class PreviewConnection:
    """One tab's preview: reads its messages, runs passes and full renders, sends results."""

    def __init__(self, socket: WebSocket, session: PreviewSession) -> None:
        self.socket = socket
        self.session = session
        self.dirty = asyncio.Event()
        self.sending = asyncio.Lock()  # an image's JSON header and bytes go out together
        self.full_render: asyncio.Task | None = None
        self.sized = False

    async def send(self, *parts: dict | bytes) -> bool:
        async with self.sending:
            for part in parts:
                if not await _send(self.socket, part):
                    return False
        return True

    async def run(self) -> None:
        passes = asyncio.create_task(self._pass_loop())
        try:
            await self.send(self._scene_message())
            while (text := await _receive(self.socket)) is not _CLOSED:
                reply = await _answer_or_error(self._handle, text)
                if reply is not None and not await self.send(reply):
                    break
        finally:
            self.session.generation += 1
            self.session.render_generation += 1
            passes.cancel()
            tasks = [passes] + ([self.full_render] if self.full_render else [])
            await asyncio.gather(*tasks, return_exceptions=True)

    def _scene_message(self) -> dict:
        scene = self.session.scene
        camera = scene.camera
        return {
            "type": "scene",
            "camera": {
                "position": list(map(float, camera.position)),
                "look_at": list(map(float, camera.look_at)),
                "up": list(map(float, camera.up)),
                "fov": float(camera.fov),
            },
            "materials": scene.material_names,
            "render": {
                "width": scene.render.width,
                "height": scene.render.height,
                "spp": scene.render.spp,
            },
            "spheres": len(scene.sphere_radii),
            "floor": scene.floor is not None,
        }

    async def _handle(self, message: dict) -> dict | None:
        session = self.session
        kind = message["type"]
        if kind == "size":
            width = messages.integer(message, "width", 8, messages.MAX_PREVIEW_SIDE)
            height = messages.integer(message, "height", 8, messages.MAX_PREVIEW_SIDE)
            if width * height > messages.MAX_PREVIEW_PIXELS:
                raise MessageError(f"size: at most {messages.MAX_PREVIEW_PIXELS} pixels")
            session.set_size(width, height)
            self.sized = True
        elif kind == "camera":
            position = messages.vector(message, "position", 3)
            look_at = messages.vector(message, "look_at", 3)
            problem = session.set_camera(position, look_at)
            if problem is not None:
                raise MessageError(problem)
        elif kind == "drop":
            if not self.sized:
                raise MessageError("drop: send the preview size first")
            if session.scene.floor is None:
                raise MessageError("drop: this scene has no floor")
            if len(session.dropped) >= messages.MAX_DROPPED:
                raise MessageError(f"drop: at most {messages.MAX_DROPPED} spheres a session")
            x = messages.number(message, "x", 0, session.width)
            y = messages.number(message, "y", 0, session.height)
            radius = messages.number(message, "radius", *messages.DROP_RADIUS)
            material = messages.choice(message, "material", session.scene.material_names)
            placed = await asyncio.to_thread(session.drop_sphere, x, y, radius, material)
            self.dirty.set()
            return {"type": "dropped", "placed": placed, "spheres": len(session.scene.sphere_radii)}
        elif kind == "render":
            if self.full_render is not None and not self.full_render.done():
                raise MessageError("render: a full-size render is already running")
            self.full_render = asyncio.create_task(self._full_render())
            return None
        elif kind == "cancel_render":
            session.render_generation += 1
            return None
        elif kind == "scene_toml":
            return {"type": "scene_toml", "text": await asyncio.to_thread(session.scene_toml)}
        else:
            raise MessageError(f"unknown message type {kind!r}")
        self.dirty.set()
        return None

    async def _pass_loop(self) -> None:
        """Whenever the scene, camera or size changes: passes 1..spp, each sent as it ends."""
        session = self.session
        while True:
            await self.dirty.wait()
            self.dirty.clear()
            if not self.sized:
                continue
            generation = session.generation
            width, height = session.width, session.height
            spp = session.scene.render.spp
            film = Film(width, height)
            for sample in range(spp):
                started = time.perf_counter()
                try:
                    await asyncio.to_thread(session.render_pass, sample, generation, film)
                except OvertakenError:
                    break
                image = film.image(sample + 1)
                png = await asyncio.to_thread(png_bytes, image)
                if generation != session.generation:
                    break
                header = {
                    "type": "pass",
                    "pass": sample + 1,
                    "of": spp,
                    "width": width,
                    "height": height,
                    "ms": round(1000 * (time.perf_counter() - started)),
                }
                if not await self.send(header, png):
                    return

    async def _full_render(self) -> None:
        session = self.session
        loop = asyncio.get_running_loop()
        generation = session.render_generation
        last = [0.0]

        def progress(done: int, total: int) -> None:
            now = time.perf_counter()
            if now - last[0] >= 0.1 or done == total:
                last[0] = now
                asyncio.run_coroutine_threadsafe(
                    self.send({"type": "progress", "done": done, "total": total}), loop
                )

        started = time.perf_counter()
        try:
            image = await asyncio.to_thread(session.full_render, generation, progress)
            png = await asyncio.to_thread(png_bytes, image)
        except OvertakenError:
            await self.send({"type": "render_cancelled"})
            return
        except Exception:  # a bug of ours: say so on the console, tell the tab
            traceback.print_exc(file=sys.stderr)
            await self.send({"type": "error", "message": "the render failed (see the server)"})
            return
        settings = session.scene.render
        await self.send(
            {
                "type": "rendered",
                "width": settings.width,
                "height": settings.height,
                "spp": settings.spp,
                "seconds": round(time.perf_counter() - started, 2),
            },
            png,
        )
