"""The server's WebSockets against hostile clients, driven in process through the ASGI interface
(no port, no browser): every message gets an answer, and no burst of sockets gets past the cap
on preview sessions.
"""

from __future__ import annotations

import asyncio
import json
import threading
import time
from pathlib import Path

from embree_rt.scene import Scene
from embree_rt.web.app import MAX_SESSIONS, create_app
from embree_rt.web.preview import PreviewSession

DIGITS_400 = "1" + "0" * 400


class Client:
    """One WebSocket to ``app`` at ``path``: what the ASGI server would feed and collect."""

    def __init__(self, app, path: str) -> None:
        self.incoming: asyncio.Queue = asyncio.Queue()
        self.outgoing: asyncio.Queue = asyncio.Queue()
        scope = {
            "type": "websocket",
            "asgi": {"version": "3.0"},
            "scheme": "ws",
            "path": path,
            "raw_path": path.encode(),
            "root_path": "",
            "query_string": b"",
            "headers": [(b"host", b"127.0.0.1:8000")],
            "client": ("127.0.0.1", 50000),
            "server": ("127.0.0.1", 8000),
            "subprotocols": [],
        }
        self.incoming.put_nowait({"type": "websocket.connect"})
        self.task = asyncio.create_task(app(scope, self.incoming.get, self.outgoing.put))

    async def next(self, timeout: float = 60) -> dict:
        """The next event the app sent (accept, send, close); the app's exception if it ended
        in one (what the ASGI server would print as a traceback, dropping the connection)."""
        getter = asyncio.ensure_future(self.outgoing.get())
        done, _ = await asyncio.wait(
            {getter, self.task}, timeout=timeout, return_when=asyncio.FIRST_COMPLETED
        )
        if getter in done:
            return getter.result()
        getter.cancel()
        if self.task.done():
            self.task.result()
            raise AssertionError("the app ended without closing the socket")
        raise TimeoutError(f"no event in {timeout} s")

    async def reply(self) -> dict:
        """The next JSON text message, skipping preview passes and their images."""
        while True:
            event = await self.next()
            if event["type"] == "websocket.close":
                return {"type": "closed"}
            if event["type"] == "websocket.send" and event.get("text") is not None:
                message = json.loads(event["text"])
                if message["type"] != "pass":
                    return message

    def send(self, text: str) -> None:
        self.incoming.put_nowait({"type": "websocket.receive", "text": text})

    async def close(self) -> None:
        self.incoming.put_nowait({"type": "websocket.disconnect", "code": 1000})
        await asyncio.wait_for(self.task, 60)


def _factory(tmp_path: Path, delay: float = 0.0):
    """A session factory of a tiny scene, taking ``delay`` seconds a session, and the list of
    sessions it made."""
    made: list[PreviewSession] = []
    lock = threading.Lock()
    scene = Scene()
    scene.add_sphere((0.0, 1.0, 0.0), 1.0)

    def new_session() -> PreviewSession:
        time.sleep(delay)
        session = PreviewSession(scene, {}, tmp_path)
        with lock:
            made.append(session)
        return session

    return new_session, made


TRACE = {"type": "trace", "circles": [], "light": [10, 10], "rays": 3, "spread": 1, "aim": 0}
HUGE_2D = [
    {**TRACE, "rays": int(DIGITS_400)},
    {**TRACE, "spread": int(DIGITS_400)},
    {**TRACE, "light": [-int(DIGITS_400), 1]},
    {**TRACE, "circles": [{"x": int(DIGITS_400), "y": 1, "r": 5, "material": "glass"}]},
]
HUGE_PREVIEW = [
    {"type": "size", "width": int(DIGITS_400), "height": 10},
    {"type": "camera", "position": [int(DIGITS_400), 0, 0], "look_at": [0, 0, 0]},
    {"type": "drop", "x": int(DIGITS_400), "y": 1, "radius": 0.5, "material": "glass"},
]


def test_huge_numbers_and_literals_get_an_error_reply_and_the_socket_stays(tmp_path) -> None:
    async def scenario() -> None:
        new_session, _ = _factory(tmp_path)
        app = create_app(new_session)
        demo = Client(app, "/ws/2d")
        assert (await demo.next())["type"] == "websocket.accept"
        texts = [json.dumps(message) for message in HUGE_2D]
        texts.append('{"type": "trace", "rays": ' + "9" * 5000 + "}")  # past Python's digits
        for text in texts:
            demo.send(text)
            reply = await demo.reply()
            assert reply["type"] == "error" and "\n" not in reply["message"], text[:60]
        demo.send(json.dumps(TRACE))
        assert (await demo.reply())["type"] == "rays"
        await demo.close()

        preview = Client(app, "/ws/preview")
        assert (await preview.next())["type"] == "websocket.accept"
        assert (await preview.reply())["type"] == "scene"
        preview.send(json.dumps({"type": "size", "width": 16, "height": 9}))
        for message in HUGE_PREVIEW:
            preview.send(json.dumps(message))
            reply = await preview.reply()
            assert reply["type"] == "error" and "must lie in" in reply["message"], message
        preview.send(json.dumps({"type": "scene_toml"}))
        assert (await preview.reply())["type"] == "scene_toml"
        await preview.close()

    asyncio.run(scenario())


def test_sockets_opened_at_once_get_no_more_sessions_than_the_cap(tmp_path) -> None:
    """Twenty preview sockets at once, each session taking 0.2 s to make: sixteen sessions,
    and the other four told so and closed; once those close, a new socket gets one."""

    async def scenario() -> None:
        new_session, made = _factory(tmp_path, delay=0.2)
        app = create_app(new_session)
        clients = [Client(app, "/ws/preview") for _ in range(MAX_SESSIONS + 4)]
        for client in clients:
            assert (await client.next())["type"] == "websocket.accept"
        replies = [await client.reply() for client in clients]
        kinds = [reply["type"] for reply in replies]
        assert kinds.count("scene") == MAX_SESSIONS, kinds
        refused = [r for r in replies if r["type"] == "error"]
        assert len(refused) == 4 and all("too many" in r["message"] for r in refused)
        assert len(made) == MAX_SESSIONS
        for client, reply in zip(clients, replies, strict=True):
            if reply["type"] == "error":
                assert (await client.next())["type"] == "websocket.close"
        for client in clients:
            await client.close()
        latecomer = Client(app, "/ws/preview")
        assert (await latecomer.next())["type"] == "websocket.accept"
        assert (await latecomer.reply())["type"] == "scene"
        await latecomer.close()

    asyncio.run(scenario())
