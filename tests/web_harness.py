"""Runs ``embree-rt serve`` on a free port and drives Debian's Chromium with Playwright.

``EMBREE_RT_SCREENSHOTS=DIR`` makes the browser tests save the README's screenshots there
(``serve_2d.png``, ``serve_preview.png``): ``EMBREE_RT_SCREENSHOTS=docs python -m pytest
tests/test_web_browser.py``.
"""

from __future__ import annotations

import base64
import io
import os
import re
import selectors
import signal
import subprocess
import sys
import time
from contextlib import contextmanager
from pathlib import Path

import numpy as np
from PIL import Image

CHROMIUM = "/usr/bin/chromium"
START_TIMEOUT_S = 90  # a cold numba cache compiles every kernel before the server answers


def _read_line(stream, timeout: float) -> str:
    selector = selectors.DefaultSelector()
    selector.register(stream, selectors.EVENT_READ)
    if not selector.select(timeout):
        raise TimeoutError(f"the server printed nothing in {timeout} s")
    return stream.readline()


@contextmanager
def running_server(*args: str):
    """Start ``embree-rt serve --port 0 ARGS``; yields (base URL, process). On exit, Ctrl-C
    (SIGINT) stops it: it must exit as the command does on Ctrl-C, code 130, no traceback.
    Its stderr is then ``process.stderr_text``."""
    process = subprocess.Popen(
        [sys.executable, "-m", "embree_rt", "serve", "--port", "0", *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        line = _read_line(process.stdout, START_TIMEOUT_S)
        match = re.search(r"at (http://[^/ ]+)/ ", line)
        assert match, f"unexpected first line {line!r}; stderr: {process.stderr.read()}"
        yield match.group(1), process
        process.send_signal(signal.SIGINT)
        _, stderr = process.communicate(timeout=20)
        process.stderr_text = stderr
        assert process.returncode == 130, stderr
        assert "Traceback" not in stderr, stderr
    finally:
        if process.poll() is None:
            process.kill()
            process.communicate(timeout=10)


@contextmanager
def browser():
    """A headless Chromium (Debian's package: Playwright cannot download one here)."""
    from playwright.sync_api import sync_playwright

    assert Path(CHROMIUM).exists(), f"{CHROMIUM} is missing: apt-get install chromium"
    with sync_playwright() as playwright:
        instance = playwright.chromium.launch(executable_path=CHROMIUM)
        try:
            yield instance
        finally:
            instance.close()


def screenshot(page, name: str) -> None:
    """Save the page for the README when ``EMBREE_RT_SCREENSHOTS`` names a directory."""
    folder = os.environ.get("EMBREE_RT_SCREENSHOTS")
    if folder:
        # Down to the bottom of the page's content, not the empty viewport below it.
        bottom = page.evaluate("document.querySelector('main').getBoundingClientRect().bottom")
        width = page.viewport_size["width"]
        shot = page.screenshot(clip={"x": 0, "y": 0, "width": width, "height": bottom})
        # 256 colours: the 2D demo's thousand faint lines make a full-colour PNG 3x larger.
        from PIL import Image

        image = Image.open(io.BytesIO(shot)).convert("RGB").quantize(256, dither=Image.Dither.NONE)
        image.save(Path(folder) / name, optimize=True)


def wait_until(condition, timeout: float, what: str, page=None):
    """Poll ``condition()`` until it returns something truthy; fail after ``timeout`` s. With
    ``page``, wait through it: Playwright delivers a page's events only while it is called."""
    deadline = time.monotonic() + timeout
    while True:
        value = condition()
        if value:
            return value
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout} s waiting for {what}")
        if page is not None:
            page.wait_for_timeout(20)
        else:
            time.sleep(0.02)


def canvas_image(page) -> np.ndarray:
    """(height, width, 3) float64 RGB of the page's preview canvas, as the browser drew it."""
    url = page.evaluate("document.getElementById('preview').toDataURL('image/png')")
    data = base64.b64decode(url.split(",", 1)[1])
    return np.asarray(Image.open(io.BytesIO(data)).convert("RGB"), np.float64)


def psnr(a: np.ndarray, b: np.ndarray) -> float:
    """Peak signal-to-noise ratio in dB of two 8-bit-range images (inf where equal)."""
    mse = np.mean((a - b) ** 2)
    return float("inf") if mse == 0 else 10 * np.log10(255.0**2 / mse)


def command_render(path: Path, width: int, height: int, out: Path) -> np.ndarray:
    """(height, width, 3) float64 RGB of ``embree-rt render path`` at ``width`` x ``height``,
    run as a user runs it (a fresh process), written to ``out``."""
    command = [sys.executable, "-m", "embree_rt", "render", str(path), "-o", str(out)]
    command += ["--width", str(width), "--height", str(height), "--quiet"]
    subprocess.run(command, check=True, timeout=120)
    return np.asarray(Image.open(out).convert("RGB"), np.float64)
