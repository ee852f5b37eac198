"""Ctrl-C and SIGTERM sent to a real render, in each of its phases: on this machine rendering
and writing the image; on a ``--cluster local:2`` starting the cluster, the workers building,
rendering (as tasks, and as bricks), writing. Each must end the command promptly with exit code
130 (SIGINT) or 143 (SIGTERM) and one line on stderr, close the cluster (no worker outlives the
command), and leave the image that was there before as it was, with no temporary file.

The signal is sent, as a terminal's Ctrl-C is, to the command's whole process group, once the
command has reached the phase: a small hook (``PHASED``, test code, run in the command's own
process) prints ``PHASE`` on stdout when the phase begins, and, in the phases that would end
too soon to be caught (a progress update, the image's write), waits there for the signal.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
TIMEOUT_S = 180

PHASED = """
import contextlib, sys, time
from embree_rt import cli, distributed, film

phase = sys.argv[1]

def reached():
    print("PHASE", flush=True)

def wait_for_the_signal():
    reached()
    for _ in range(1200):
        time.sleep(0.05)
    raise AssertionError("the signal did not come")

if phase == "rendering here":  # the render under way on this machine
    import embree_rt.cli.render as here
    render = here.render
    def rendering(*args, **kwargs):
        reached()
        return render(*args, **kwargs)
    here.render = rendering
elif phase == "starting":  # the signal comes while Dask starts the scheduler and workers
    start = distributed.local_cluster
    def starting(*args, **kwargs):
        reached()
        return start(*args, **kwargs)
    distributed.local_cluster = starting
elif phase == "building":  # batches sent, the workers building their BVH on the first
    render_frames = distributed.ClusterRenderer.render_frames
    def building(self, *args, **kwargs):
        reached()
        return render_frames(self, *args, **kwargs)
    distributed.ClusterRenderer.render_frames = building
elif phase in ("rendering", "rendering bricks"):  # the first batch back, the rest rendering
    @contextlib.contextmanager
    def progress_bar(total, quiet):
        yield lambda state: wait_for_the_signal()
    distributed.progress_bar = progress_bar
elif phase.startswith("writing"):  # the image half written
    def write_half(image, handle, encoding=None):
        handle.write(b"half an image")
        handle.flush()
        wait_for_the_signal()
    film.WRITERS[".npy"] = write_half
sys.exit(cli.main(sys.argv[2:]))
"""


def session_members(session: int) -> list[int]:
    """Processes still running in the session ``session`` (started with a session of its own)."""
    import psutil  # distributed's own dependency

    members = []
    for candidate in psutil.process_iter():
        try:
            if os.getsid(candidate.pid) == session and candidate.status() != "zombie":
                members.append(candidate.pid)
        except (OSError, psutil.Error):
            continue
    return members


INTERRUPTED = (signal.SIGINT, 130, "embree-rt: interrupted\n")
TERMINATED = (signal.SIGTERM, 143, "embree-rt: terminated\n")
HERE = ["random", "--count", "200000", "--width", "1920", "--height", "1080", "--spp", "16"]
CLUSTER = [
    *("random", "--count", "2000", "--width", "320", "--height", "180", "--spp", "2"),
    *("--cluster", "local:2"),
]
# (phase, command line without its output and --quiet, the signal and what it must end in):
# every phase once, the two signals taking turns, a few cases all told (a cluster takes 10 s
# and more to start on two busy cores); SIGINT and SIGTERM share the command's one path out
CASES = [
    ("rendering here", HERE, INTERRUPTED),
    ("rendering here", HERE, TERMINATED),
    ("writing here", [*HERE[:3], "--width", "64", "--height", "32", "--spp", "1"], INTERRUPTED),
    ("writing here", [*HERE[:3], "--width", "64", "--height", "32", "--spp", "1"], TERMINATED),
    ("starting", CLUSTER, TERMINATED),
    ("building", CLUSTER, INTERRUPTED),
    ("rendering bricks", [*CLUSTER, "--partition", "2"], TERMINATED),
    ("writing", CLUSTER, INTERRUPTED),
]


@pytest.mark.parametrize(
    ("phase", "command", "ending"), CASES, ids=[f"{c[0]}-{c[2][0].name}" for c in CASES]
)
def test_a_signal_in_any_phase_ends_the_render_in_one_line_and_leaves_the_old_image(
    tmp_path: Path, phase: str, command: list[str], ending: tuple
) -> None:
    signum, code, line = ending
    output = tmp_path / "out.npy"
    output.write_bytes(b"the image of an earlier render")
    process = subprocess.Popen(
        [sys.executable, "-c", PHASED, phase, *command, "-o", str(output), "--quiet"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=ROOT,
        start_new_session=True,
    )
    try:
        assert process.stdout.readline() == "PHASE\n", process.communicate(timeout=TIMEOUT_S)
        if phase == "rendering here":  # well into the render, its threads busy
            time.sleep(1.0)
        sent = time.monotonic()
        os.killpg(process.pid, signum)  # as a terminal's Ctrl-C: the whole group
        _, stderr = process.communicate(timeout=TIMEOUT_S)
    finally:
        if process.poll() is None:
            os.killpg(process.pid, signal.SIGKILL)
            process.wait()
    assert process.returncode == code, stderr
    assert stderr == line
    assert time.monotonic() - sent < 30  # promptly, not after the whole render
    assert [p.name for p in tmp_path.iterdir()] == ["out.npy"]  # no temporary file
    assert output.read_bytes() == b"the image of an earlier render"
    # the cluster was closed: no worker outlives the command
    deadline = time.monotonic() + 15
    while session_members(process.pid) and time.monotonic() < deadline:
        time.sleep(0.2)
    assert session_members(process.pid) == []
