"""``embree-rt serve`` in a real browser (Debian's Chromium through Playwright), and its
defences against a hostile client: path traversal, cross-site pages and malformed messages.

One server (on a free port, stopped with Ctrl-C at the end) serves every test in this module.
"""

from __future__ import annotations

import http.client
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from embree_rt.scene import load_scene
from embree_rt.web.messages import MAX_MESSAGE_BYTES, layout_2d
from embree_rt.web.trace2d import INTERNAL, trace_layout
from tests.web_harness import (
    browser,
    canvas_image,
    command_render,
    psnr,
    running_server,
    screenshot,
    wait_until,
)

SHOWCASE = Path(__file__).parent.parent / "scenes" / "showcase.toml"
# Small enough that the preview converges and the full-size render finishes in seconds.
RENDER_SIZE = (320, 180)
VIEWPORT = {"width": 900, "height": 620}
VIEWPORT_2D = {"width": 1280, "height": 700}

# Records every segment the page strokes (moveTo then lineTo), frame by frame (clearRect).
RECORD_SEGMENTS = """
window.__frames = [];
const proto = CanvasRenderingContext2D.prototype;
const [clear, move, line] = [proto.clearRect, proto.moveTo, proto.lineTo];
let frame = null, pen = null;
proto.clearRect = function (...args) {
  frame = []; window.__frames.push(frame); window.__frames = window.__frames.slice(-3);
  return clear.apply(this, args);
};
proto.moveTo = function (x, y) { pen = [x, y]; return move.call(this, x, y); };
proto.lineTo = function (x, y) {
  if (frame && pen) frame.push([pen[0], pen[1], x, y]);
  pen = [x, y];
  return line.call(this, x, y);
};
"""


@pytest.fixture(scope="module")
def scene_file(tmp_path_factory) -> Path:
    text = SHOWCASE.read_text().replace("width = 1280", f"width = {RENDER_SIZE[0]}")
    text = text.replace("height = 720", f"height = {RENDER_SIZE[1]}")
    path = tmp_path_factory.mktemp("serve") / "showcase_small.toml"
    path.write_text(text)
    assert load_scene(path).render.width == RENDER_SIZE[0]
    return path


@pytest.fixture(scope="module")
def server(scene_file):
    with running_server(str(scene_file)) as (url, _):
        yield url


@pytest.fixture(scope="module")
def chromium():
    with browser() as instance:
        yield instance


@pytest.fixture
def page(chromium):
    # bypass_csp: Playwright's waits evaluate strings, which the pages' policy forbids.
    context = chromium.new_context(viewport=VIEWPORT, bypass_csp=True, accept_downloads=True)
    try:
        yield context.new_page()
    finally:
        context.close()


# -- /2d ---------------------------------------------------------------------------------------


def _trace_messages(page) -> list[dict]:
    sent: list[dict] = []

    def watch(socket):
        socket.on("framesent", lambda payload: sent.append(json.loads(payload)))

    page.on("websocket", watch)
    return sent


def _answered(page, sent: list[dict]) -> bool:
    answered = page.evaluate("document.getElementById('demo').dataset.answered")
    return bool(sent) and answered == str(sent[-1]["id"])


def _click_canvas(page, x: float, y: float, button: str = "left") -> None:
    box = page.locator("#demo").bounding_box()
    page.mouse.click(
        box["x"] + x * box["width"] / 960, box["y"] + y * box["height"] / 600, button=button
    )


def _set_slider(page, name: str, value: float) -> None:
    page.eval_on_selector(
        f"#{name}", "(el, v) => { el.value = v; el.dispatchEvent(new Event('input')); }", value
    )


def test_2d_clicks_place_circles_and_draw_the_tracers_segments(server, page):
    sent = _trace_messages(page)
    page.set_viewport_size(VIEWPORT_2D)
    page.add_init_script(RECORD_SEGMENTS)
    page.goto(f"{server}/2d")
    wait_until(lambda: _answered(page, sent), 10, "the first layout's rays")
    page.click("#clear")
    # A glass circle around the light, which sits 75 of 90 from its centre: rays from it meet
    # the glass at up to asin(75/90) = 56 degrees, past the critical angle of 41 degrees.
    clicks = [
        (225.0, 330.0, 90, "glass"),
        (560.0, 200.0, 70, "mirror"),
        (700.0, 460.0, 60, "matte"),
        (480.0, 430.0, 50, "glass"),
    ]
    for x, y, radius, material in clicks:
        page.click(f"#materials button[data-material={material}]")
        _set_slider(page, "radius", radius)
        _click_canvas(page, x, y)
    wait_until(lambda: _answered(page, sent) and len(sent[-1]["circles"]) == 4, 10, "4 circles")
    message = sent[-1]
    placed = [(c["x"], c["y"], c["r"], c["material"]) for c in message["circles"]]
    for (x, y, radius, material), circle in zip(clicks, placed, strict=True):
        assert circle[0] == pytest.approx(x, abs=1) and circle[1] == pytest.approx(y, abs=1)
        assert circle[2:] == (radius, material)
    assert message["light"] == [150, 330]

    paths = trace_layout(layout_2d(message))
    expected = np.round(paths.segments(), 3)
    drawn = np.asarray(page.evaluate("window.__frames[window.__frames.length - 1]"), float)
    assert drawn.shape == expected.shape
    order = np.lexsort(expected.T[::-1])
    assert np.allclose(drawn[np.lexsort(drawn.T[::-1])], expected[order], atol=2e-3)
    assert (paths.kinds == INTERNAL).sum() > 0  # the glass around the light reflects totally


def test_every_2d_click_is_answered_and_the_page_reports_its_round_trip(server, page):
    """Each click sends the new layout and the page draws its answer and says how long the round
    trip took. (How fast is measured by benchmarks/serve_latency.py, not here: a timed test on a
    shared machine would fail for reasons that are not bugs.)"""
    sent = _trace_messages(page)
    page.set_viewport_size(VIEWPORT_2D)
    page.goto(f"{server}/2d")
    wait_until(lambda: _answered(page, sent), 10, "the first layout's rays")
    page.wait_for_timeout(500)  # the page loaded and painted: the browser is idle again
    _set_slider(page, "rays", 180)  # traced again, for the screenshot's status line
    wait_until(lambda: len(sent) > 1 and _answered(page, sent), 10, "the layout traced again")
    screenshot(page, "serve_2d.png")  # the page's own first layout
    page.click("#clear")
    round_trips = []
    for k in range(6):
        _click_canvas(page, 80 + 80 * k, 80 + 60 * k)
        wait_until(
            lambda placed=k + 1: _answered(page, sent) and len(sent[-1]["circles"]) == placed,
            10,
            "the click's rays",
        )
        text = page.inner_text("#status")
        round_trips.append(float(text.split("answered in ")[1].split(" ms")[0]))
    print(f"2D click round trips (ms): {sorted(round_trips)}")
    assert all(0 < trip < 10_000 for trip in round_trips), round_trips


# -- / -----------------------------------------------------------------------------------------


def _pass(page) -> str | None:
    return page.evaluate("document.getElementById('preview').dataset.pass || null")


def _converged_after(
    page, frames: list, seen: int, kind: str, sent: bool = False, converge: bool = True
) -> dict:
    """Wait for the first message of ``kind`` after ``frames[seen]`` (sent by the page, or
    received), then for the passes after it to converge (or, ``converge=False``, for one pass
    after it); returns that message."""

    def find():
        for index in range(seen, len(frames)):
            if frames[index][0] == sent and frames[index][1]["type"] == kind:
                return index + 1
        return None

    index = wait_until(find, 20, f"a {kind} message", page)
    wait_until(
        lambda: any(
            not out and m["type"] == "pass" and (m["pass"] == m["of"] or not converge)
            for out, m in frames[index:]
        ),
        60,
        f"passes after {kind}",
        page,
    )
    return frames[index - 1][1]


def test_preview_converges_to_the_render_then_edits_restart_it(server, scene_file, page, tmp_path):
    received: list = []  # (sent?, message) in order, images left out

    def watch(socket):
        socket.on("framesent", lambda m: received.append((True, json.loads(m))))
        socket.on(
            "framereceived",
            lambda m: isinstance(m, str) and received.append((False, json.loads(m))),
        )

    page.on("websocket", watch)
    page.goto(server)
    wait_until(lambda: _pass(page) == "8/8", 60, "the preview to converge")
    width, height = page.evaluate("[preview.width, preview.height]")
    shown = canvas_image(page)
    rendered = command_render(scene_file, width, height, tmp_path / "render.png")
    assert shown.shape == rendered.shape == (height, width, 3)
    quality = psnr(shown, rendered)
    print(f"preview {width}x{height} vs embree-rt render: PSNR {quality:.1f} dB")
    assert quality >= 40
    screenshot(page, "serve_preview.png")

    # A click on the floor (the bottom middle of the image) drops a sphere; passes restart.
    page.select_option("#material", "gold")
    box = page.locator("#preview").bounding_box()
    seen = len(received)
    page.mouse.click(box["x"] + box["width"] * 0.5, box["y"] + box["height"] * 0.93)
    dropped = _converged_after(page, received, seen, "dropped")
    assert dropped["placed"] and dropped["spheres"] == 7
    assert psnr(canvas_image(page), rendered) < 40  # the new sphere shows

    # An orbit drag moves the camera.
    page.mouse.move(box["x"] + 100, box["y"] + 60)
    seen = len(received)
    page.mouse.down()
    page.mouse.move(box["x"] + 160, box["y"] + 70, steps=5)
    page.mouse.up()
    _converged_after(page, received, seen, "camera", sent=True, converge=False)

    with page.expect_download(timeout=10_000) as download:
        page.click("#download-scene")
    toml = tmp_path / "edited.toml"
    download.value.save_as(toml)
    edited = load_scene(toml)
    assert len(edited.sphere_radii) == 7
    assert edited.material_names[edited.sphere_materials[-1]] == "gold"
    assert edited.sphere_centers[-1][1] == pytest.approx(edited.sphere_radii[-1], abs=1e-4)
    assert tuple(edited.camera.position) != tuple(load_scene(scene_file).camera.position)

    page.click("#render")
    page.wait_for_selector("#png:not([hidden])", timeout=60_000)
    with page.expect_download(timeout=10_000) as download:
        page.click("#png")
    full = tmp_path / "full.png"
    download.value.save_as(full)
    assert Image.open(full).size == RENDER_SIZE
    # The edited scene file renders to the very image the page rendered.
    again = tmp_path / "again.png"
    subprocess.run(
        [sys.executable, "-m", "embree_rt", "render", str(toml), "-o", str(again), "--quiet"],
        check=True,
        timeout=120,
    )
    assert np.array_equal(np.asarray(Image.open(full)), np.asarray(Image.open(again)))


# -- a hostile client --------------------------------------------------------------------------

TRAVERSALS = [
    "/static/../../etc/passwd",
    "/static/..%2f..%2fetc%2fpasswd",
    "/static/%2e%2e/%2e%2e/etc/passwd",
    "/static/%2e%2e%2f%2e%2e%2fetc%2fpasswd",
    "/static/%252e%252e%252fetc%252fpasswd",
    "/static/..%5c..%5cetc%5cpasswd",
    "/%2e%2e/%2e%2e/etc/passwd",
    "//etc/passwd",
    "/static//etc/passwd",
    "/static/style.css/../../../../etc/passwd",
    "/static/%00../etc/passwd",
    "/2d/../../etc/passwd",
]


def _get(server: str, path: str, host: str | None = None) -> tuple[int, bytes]:
    address = server.removeprefix("http://")
    connection = http.client.HTTPConnection(address, timeout=10)
    try:
        # http.client sends the path exactly as given: nothing normalises it on the way.
        connection.putrequest("GET", path, skip_host=True)
        connection.putheader("Host", host or address)
        connection.endheaders()
        response = connection.getresponse()
        return response.status, response.read()
    finally:
        connection.close()


@pytest.mark.parametrize("path", TRAVERSALS)
def test_no_path_reaches_the_file_system(server, path):
    status, body = _get(server, path)
    assert status == 404, (path, status)
    assert b"root:" not in body


def test_only_the_packages_files_are_served_with_a_strict_policy(server):
    status, body = _get(server, "/static/style.css")
    assert status == 200 and b"--accent" in body
    assert _get(server, "/static/default_scene.toml")[0] == 404  # package data, but not static
    assert _get(server, "/static/app.py")[0] == 404
    # Another host name (DNS rebinding) is refused on a loopback server.
    assert _get(server, "/", host="attacker.example")[0] == 400
    connection = http.client.HTTPConnection(server.removeprefix("http://"), timeout=10)
    connection.request("GET", "/2d")
    response = connection.getresponse()
    assert response.status == 200
    assert "script-src 'self'" in response.headers["Content-Security-Policy"]
    assert response.headers["X-Content-Type-Options"] == "nosniff"
    connection.close()


def _socket(server: str, path: str, **options):
    from websockets.sync.client import connect

    return connect(server.replace("http://", "ws://") + path, open_timeout=10, **options)


def _reply(socket) -> dict:
    return json.loads(socket.recv(timeout=20))


MALFORMED = [
    "not json",
    "[1, 2]",
    '{"type": 5}',
    '{"no": "type"}',
    '{"type": "teleport"}',
    "[" * 100_000 + "]" * 100_000,
    "x" * (MAX_MESSAGE_BYTES + 1),
    '{"type": "trace", "circles": "many", "light": [1, 1], "rays": 3, "spread": 1, "aim": 0}',
    '{"type": "trace", "circles": [], "light": [NaN, 1], "rays": 3, "spread": 1, "aim": 0}',
    '{"type": "trace", "circles": [], "light": [10, 10], "rays": 1e9, "spread": 1, "aim": 0}',
    '{"type": "trace", "circles": [{"x": 1, "y": 1, "r": 1e30, "material": "gold"}], '
    '"light": [10, 10], "rays": 3, "spread": 1, "aim": 0}',
    '{"type": "trace", "circles": [], "light": [-5, 10], "rays": 3, "spread": 1, "aim": 0}',
]


def test_malformed_2d_messages_get_an_error_and_the_server_keeps_serving(server):
    good = {
        "type": "trace",
        "id": 1,
        "circles": [{"x": 400, "y": 300, "r": 50, "material": "glass"}],
        "light": [100, 300],
        "rays": 16,
        "spread": 360,
        "aim": 0,
    }
    with _socket(server, "/ws/2d", max_size=None) as socket:
        for text in [*MALFORMED, b"\x00\x01binary"]:
            socket.send(text)
            reply = _reply(socket)
            assert reply["type"] == "error" and reply["message"], text[:40]
        socket.send(json.dumps(good))
        assert _reply(socket)["type"] == "rays"
    # Past the protocol's own limit the connection is closed (1009) and the server goes on.
    from websockets.exceptions import ConnectionClosed

    with _socket(server, "/ws/2d", max_size=None) as socket:
        socket.send("x" * (32 * MAX_MESSAGE_BYTES))
        with pytest.raises(ConnectionClosed):
            socket.recv(timeout=20)
    with _socket(server, "/ws/2d") as socket:
        socket.send(json.dumps(good))
        assert _reply(socket)["type"] == "rays"


def test_malformed_preview_messages_and_separate_sessions(server):
    bad = [
        {"type": "size", "width": 100000, "height": 100000},
        {"type": "size", "width": "wide", "height": 10},
        {"type": "camera", "position": [0, 0], "look_at": [0, 0, 0]},
        {"type": "camera", "position": [0, 1, 2], "look_at": [0, 1, 2]},
        {"type": "drop", "x": 1, "y": 1, "radius": 0.5, "material": "glass"},  # before a size
        {"type": "load", "path": "/etc/passwd"},
    ]
    with _socket(server, "/ws/preview") as first, _socket(server, "/ws/preview") as second:
        for socket in (first, second):
            assert _reply(socket)["type"] == "scene"
        for message in bad:
            first.send(json.dumps(message))
            assert _reply(first)["type"] == "error", message
        first.send(json.dumps({"type": "size", "width": 64, "height": 36}))
        for message in (
            {"type": "drop", "x": 32, "y": 35, "radius": 0.3, "material": "nope"},
            {"type": "drop", "x": 320, "y": 35, "radius": 0.3, "material": "gold"},
        ):
            first.send(json.dumps(message))
            assert _next(first, "error")["type"] == "error"
        first.send(
            json.dumps({"type": "drop", "x": 32, "y": 35, "radius": 0.3, "material": "gold"})
        )
        assert _next(first, "dropped") == {"type": "dropped", "placed": True, "spheres": 7}
        for socket, spheres in ((first, 7), (second, 6)):
            socket.send(json.dumps({"type": "scene_toml"}))
            text = _next(socket, "scene_toml")["text"]
            assert text.count("[[spheres]]") == spheres
    # A page of another site may not open a session.
    from websockets.exceptions import InvalidStatus

    with pytest.raises(InvalidStatus):
        _socket(server, "/ws/preview", origin="http://attacker.example")


def _next(socket, kind: str) -> dict:
    """The next JSON message of ``kind``, skipping passes (and their images)."""
    while True:
        message = socket.recv(timeout=30)
        if isinstance(message, str) and json.loads(message)["type"] == kind:
            return json.loads(message)
        if isinstance(message, str) and json.loads(message)["type"] == "error":
            return json.loads(message)
