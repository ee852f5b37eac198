"""``embree-rt serve`` refusing what it cannot do: one line, exit code 2, nothing served; and
warning when it listens where others can reach it."""

from __future__ import annotations

import socket
import subprocess
import sys
from pathlib import Path

from tests.web_harness import running_server

ROOT = Path(__file__).resolve().parent.parent


def serve(*args: str, prelude: str = "") -> subprocess.CompletedProcess:
    code = f"{prelude}import sys; from embree_rt.cli import main; sys.exit(main(sys.argv[1:]))"
    return subprocess.run(
        [sys.executable, "-c", code, "serve", *args],
        capture_output=True,
        text=True,
        timeout=60,
        cwd=ROOT,
    )


def assert_one_line(result: subprocess.CompletedProcess, *needles: str) -> None:
    assert result.returncode == 2, result.stderr
    lines = result.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("embree-rt: error: "), result.stderr
    for needle in needles:
        assert needle in lines[0], lines[0]
    assert result.stdout == ""


def test_a_port_in_use_is_one_line_and_exit_2():
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen(1)
        port = taken.getsockname()[1]
        result = serve("--port", str(port))
    assert_one_line(result, f"--port: cannot listen on 127.0.0.1:{port}", "in use")


def test_a_bad_scene_is_one_line_and_exit_2(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("[[spheres]]\ncenter = [0, 1]\nradius = 1\n")
    assert_one_line(serve(str(bad), "--port", "0"), str(bad), "spheres")
    assert_one_line(serve(str(tmp_path / "missing.toml")), "missing.toml", "no such file")


def test_without_the_web_extra_it_says_how_to_install_it():
    result = serve(prelude="import sys; sys.modules['uvicorn'] = None; ")
    # what works for an install from the checkout, as the README installs
    assert_one_line(result, "pip install starlette uvicorn websockets", "pip install '.[web]'")


def test_listening_beyond_loopback_warns(tmp_path):
    with running_server("--host", "0.0.0.0") as (url, process):
        assert url.startswith("http://0.0.0.0:")
    warning = process.stderr_text
    assert "warning: listening on 0.0.0.0" in warning and "anyone" in warning
