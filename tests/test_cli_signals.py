"""Ctrl-C and SIGTERM sent to a real ``--cluster local:2`` render, in each of its phases:
starting the cluster, the workers building, rendering, writing the image. Each must end the
command with exit code 130 (SIGINT) or 143 (SIGTERM) and one line on stderr, close the
cluster (no worker outlives the command), and leave no file.

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

if phase == "starting":  # the signal comes while Dask starts the scheduler and workers
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
elif phase == "rendering":  # at the first batch back, the others still rendering
    @contextlib.contextmanager
    def progress_bar(total, quiet):
        yield lambda state: wait_for_the_signal()
    distributed.progress_bar = progress_bar
elif phase == "writing":  # the image half written
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


@pytest.mark.parametrize(
    ("phase", "signum", "code", "line"),
    [
        ("starting", signal.SIGINT, 130, "embree-rt: interrupted"),
        ("starting", signal.SIGTERM, 143, "embree-rt: terminated"),
        ("building", signal.SIGINT, 130, "embree-rt: interrupted"),
        ("building", signal.SIGTERM, 143, "embree-rt: terminated"),
        ("rendering", signal.SIGINT, 130, "embree-rt: interrupted"),
        ("rendering", signal.SIGTERM, 143, "embree-rt: terminated"),
        ("writing", signal.SIGINT, 130, "embree-rt: interrupted"),
        ("writing", signal.SIGTERM, 143, "embree-rt: terminated"),
    ],
)
def test_a_signal_in_any_phase_of_a_cluster_render_ends_it_in_one_line_with_nothing_left(
    tmp_path: Path, phase: str, signum: int, code: int, line: str
) -> None:
    output = tmp_path / "out.npy"
    command = [
        *("random", "--count", "20000", "-o", str(output)),
        *("--width", "320", "--height", "180", "--spp", "2", "--quiet", "--cluster", "local:2"),
    ]
    process = subprocess.Popen(
        [sys.executable, "-c", PHASED, phase, *command],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=ROOT,
        start_new_session=True,
    )
    try:
        assert process.stdout.readline() == "PHASE\n", process.communicate(timeout=TIMEOUT_S)
        os.killpg(process.pid, signum)  # as a terminal's Ctrl-C: the whole group
        _, stderr = process.communicate(timeout=TIMEOUT_S)
    finally:
        if process.poll() is None:
            os.killpg(process.pid, signal.SIGKILL)
            process.wait()
    assert process.returncode == code, stderr
    assert stderr == line + "\n"
    assert list(tmp_path.iterdir()) == []  # no image, no temporary file
    # the cluster was closed: no worker outlives the command
    deadline = time.monotonic() + 15
    while session_members(process.pid) and time.monotonic() < deadline:
        time.sleep(0.2)
    assert session_members(process.pid) == []
