"""Ctrl-C and SIGTERM sent to a real command, in each of its phases: parsing its command line; on
this machine rendering and writing the image; on a ``--cluster local:2`` starting the cluster
(its worker processes importing), the workers building, rendering, writing, as tasks and as
bricks (``--partition``); on an external scheduler (``dask scheduler`` and a worker this test
starts) rendering and writing, and bricks building and rendering (on a local cluster with
queries under way as the signal ends the workers answering them); ``serve`` serving, and
rendering for a client. Each must end the command promptly with exit code 130 (SIGINT) or 143
(SIGTERM) and one line on stderr, close the cluster it started (no worker outlives the command),
and leave the image that was there before as it was, with no temporary file. An external
scheduler is not the command's to close: it and its worker keep running, and render the next
command's image.

The signal is sent, as a terminal's Ctrl-C is, to the command's whole process group, once the
command has reached the phase: a small hook (``PHASED``, test code, run in the command's own
process) prints ``PHASE`` on stdout when the phase begins, and, in the phases that would end
too soon to be caught (a progress update, the image's write), waits there for the signal.
"""

from __future__ import annotations

import json
import os
import re
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from contextlib import ExitStack, contextmanager
from pathlib import Path

import cloudpickle  # distributed's own dependency
import distributed
import numpy as np
import pytest
from process_groups import stop

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

if phase == "parsing":  # the parser being built (the command line's checks import NumPy and more)
    cli.build_parser = wait_for_the_signal
elif phase == "rendering here":  # the render under way on this machine
    import embree_rt.cli.render as here
    render = here.render
    def rendering(*args, **kwargs):
        reached()
        return render(*args, **kwargs)
    here.render = rendering
elif phase == "workers starting":  # a worker process importing, Python's Ctrl-C handler set
    import multiprocessing.context, signal
    spawn = multiprocessing.context.SpawnProcess.start
    def catches_ctrl_c(pid):
        with open(f"/proc/{pid}/status") as status:
            caught = next(line for line in status if line.startswith("SigCgt:"))
        return int(caught.split()[1], 16) & (1 << (signal.SIGINT - 1))
    def spawned(self):
        spawn(self)
        while self.is_alive() and not catches_ctrl_c(self.pid):  # not ended by the signal
            time.sleep(0.005)
        if not spawned.reached:
            spawned.reached = True
            reached()
    spawned.reached = False
    multiprocessing.context.SpawnProcess.start = spawned
elif phase == "building":  # batches sent, the workers building their BVH on the first
    render_frames = distributed.ClusterRenderer.render_frames
    def building(self, *args, **kwargs):
        reached()
        return render_frames(self, *args, **kwargs)
    distributed.ClusterRenderer.render_frames = building
elif phase.startswith("building bricks"):  # the bricks being made on their workers
    from embree_rt.bricks import cluster
    build = cluster.DaskBricks.build
    def building(self):
        reached()
        return build(self)
    cluster.DaskBricks.build = building
elif phase == "serving":  # the server up, no client
    from embree_rt.web import serve
    startup = serve.AnnouncingServer.startup
    async def started(self, *args, **kwargs):
        await startup(self, *args, **kwargs)
        reached()
    serve.AnnouncingServer.startup = started
elif phase == "rendering for a client":  # a tab's full render under way, its next batch due
    from embree_rt.web import preview
    full_render = preview.PreviewSession.full_render
    def rendering(self, generation, progress):
        def reported(done, total):
            if done < total and not getattr(reported, "seen", False):
                reported.seen = True
                reached()
                time.sleep(1.0)
            progress(done, total)
        return full_render(self, generation, reported)
    preview.PreviewSession.full_render = rendering
elif phase.startswith("rendering"):  # some batches back, the rest rendering
    @contextlib.contextmanager
    def progress_bar(total, quiet):
        def show(state):
            assert state.done < state.total, "the render ended before the signal could come"
            if state.done:
                wait_for_the_signal()
        yield show
    distributed.progress_bar = progress_bar
    if phase == "rendering bricks":  # queries under way on the workers the signal ends
        from embree_rt.bricks import cluster
        def answer_slowly():  # run on each worker: its bricks answer after 0.3 s
            import time
            from embree_rt.bricks import cluster
            intersect = cluster.BrickActor.intersect
            def slowly(self, *args):
                time.sleep(0.3)
                return intersect(self, *args)
            cluster.BrickActor.intersect = slowly
        build = cluster.DaskBricks.build
        def building(self):
            self.client.run(answer_slowly)
            return build(self)
        cluster.DaskBricks.build = building
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


# (the signal, how many times it is sent, the exit code, stderr)
INTERRUPTED = (signal.SIGINT, 1, 130, "embree-rt: interrupted\n")
TERMINATED = (signal.SIGTERM, 1, 143, "embree-rt: terminated\n")
# an impatient user's Ctrl-C Ctrl-C: the second lands in the clean-up the first began
INTERRUPTED_TWICE = (signal.SIGINT, 2, 130, "embree-rt: interrupted\n")
HERE = ["random", "--count", "200000", "--width", "1920", "--height", "1080", "--spp", "16"]
SMALL = [*HERE[:3], "--width", "64", "--height", "32", "--spp", "1"]
FIELD = ["random", "--count", "2000", "--width", "320", "--height", "180", "--spp", "2"]
BATCHES = ["--spp", "16"]  # a few batches of 2^18 samples: some back while the rest render
CLUSTER = [*FIELD, "--cluster", "local:2"]
BRICKS = [*CLUSTER, "--partition", "2"]
SCHEDULER = "tcp://the external scheduler"  # replaced by the address of ``external_scheduler``
ON_SCHEDULER = [*FIELD, "--scheduler", SCHEDULER]
BRICKS_ON_SCHEDULER = [*ON_SCHEDULER, "--partition", "2"]
SERVE = ["serve", "--port", "0"]
# (phase, command line without its output and --quiet, the signal and what it must end in):
# every phase, the two signals taking turns where one path out serves both (an external
# scheduler's workers are outside the command's process group: one path), both where they take
# different paths (a local cluster's start and teardown, uvicorn's handlers); Ctrl-C twice
# stands for Ctrl-C once where both are sent (the second lands in the first's clean-up, which
# must end as a single Ctrl-C's does); a few seconds a case (a cluster takes 5 s and more to
# start on two busy cores, and holds a signal until it has)
CASES = [
    ("parsing", SMALL, INTERRUPTED),
    ("rendering here", HERE, TERMINATED),
    ("rendering here", HERE, INTERRUPTED_TWICE),
    ("writing here", SMALL, INTERRUPTED),
    ("writing here", SMALL, TERMINATED),
    ("workers starting", CLUSTER, INTERRUPTED),
    ("workers starting", CLUSTER, TERMINATED),
    ("building", CLUSTER, INTERRUPTED),
    ("rendering", [*CLUSTER, *BATCHES], TERMINATED),
    ("rendering", [*CLUSTER, *BATCHES], INTERRUPTED_TWICE),
    ("writing", CLUSTER, TERMINATED),
    ("building bricks", BRICKS, INTERRUPTED),
    ("rendering bricks", [*BRICKS, *BATCHES], TERMINATED),
    ("writing bricks", BRICKS, INTERRUPTED),
    ("rendering on a scheduler", [*ON_SCHEDULER, *BATCHES], TERMINATED),
    ("writing on a scheduler", ON_SCHEDULER, INTERRUPTED),
    ("building bricks on a scheduler", BRICKS_ON_SCHEDULER, TERMINATED),
    ("rendering bricks on a scheduler", [*BRICKS_ON_SCHEDULER, *BATCHES], INTERRUPTED),
    ("serving", SERVE, INTERRUPTED),
    ("serving", SERVE, TERMINATED),
    ("serving", SERVE, INTERRUPTED_TWICE),
    ("rendering for a client", SERVE, INTERRUPTED),
    ("rendering for a client", SERVE, TERMINATED),
]


# How soon after the signal the command must have ended: at once, but for a cluster's start (it
# holds the signal until it has started: 5 s and more on two busy cores) and close, so 30 s, not
# after the whole render. Bricks give up their queries at once, none waiting for the workers
# the signal ended (up to ``NO_WORKERS_TIMEOUT_S``, 30 s, each): a cluster's close and room for
# a loaded machine, 15 s.
ENDED_WITHIN_S = 30
BRICKS_ENDED_WITHIN_S = 15


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


@pytest.fixture(scope="module")
def external_scheduler() -> Iterator[tuple[str, list[subprocess.Popen]]]:
    """``dask scheduler`` and one ``dask worker`` (importing this checkout), each in a session
    of its own, as a cluster someone else runs: a signal to the command's group never reaches
    them. Yields the scheduler's address and the two processes."""
    address = f"tcp://127.0.0.1:{free_port()}"
    dask = Path(sys.executable).parent / "dask"
    environment = {
        **os.environ,
        "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]),
        "DASK_DISTRIBUTED__WORKER__PROFILE__ENABLED": "False",
    }
    commands = [
        [dask, "scheduler", "--host", "127.0.0.1", "--port", address.rsplit(":", 1)[1]],
        [dask, "worker", address, "--nthreads", "1", "--memory-limit", "0", "--host", "127.0.0.1"],
    ]
    started = [
        subprocess.Popen(
            [*command, "--no-dashboard"],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
            start_new_session=True,
            env=environment,
        )
        for command in commands
    ]
    try:
        with distributed.Client(address, timeout=TIMEOUT_S) as client:
            client.wait_for_workers(1, timeout=TIMEOUT_S)
        yield address, started
    finally:
        for process in reversed(started):
            stop(process)


@pytest.fixture(scope="module")
def rendered_here(tmp_path_factory: pytest.TempPathFactory) -> Callable[[list[str]], np.ndarray]:
    """The image a command renders on this machine (without its ``--scheduler`` and
    ``--partition``: bricks render the local image bit for bit), each command's once."""
    images: dict[tuple[str, ...], np.ndarray] = {}

    def render(command: list[str]) -> np.ndarray:
        here = list(command)
        for flag in ("--scheduler", "--partition"):
            if flag in here:
                at = here.index(flag)
                del here[at : at + 2]
        here = tuple(here)
        if here not in images:
            output = tmp_path_factory.mktemp("here") / "here.npy"
            result = subprocess.run(
                [sys.executable, "-m", "embree_rt", *here, "-o", str(output), "--quiet"],
                capture_output=True,
                text=True,
                timeout=TIMEOUT_S,
                cwd=ROOT,
            )
            assert result.returncode == 0, result.stderr
            images[here] = np.load(output)
        return images[here]

    return render


@contextmanager
def client_rendering(announcement: str) -> Iterator[None]:
    """A preview tab of the server that printed ``announcement``: connected, its full render
    asked for, the connection held open while inside."""
    from websockets.sync.client import connect

    url = re.search(r"at http://([^/ ]+)/ ", announcement).group(1)
    with connect(f"ws://{url}/ws/preview", open_timeout=TIMEOUT_S) as tab:
        assert json.loads(tab.recv(timeout=TIMEOUT_S))["type"] == "scene"
        tab.send(json.dumps({"type": "render"}))
        yield


def case_id(phase: str, command: list[str], ending: tuple) -> str:
    signum, times = ending[:2]
    return f"{phase}-{signum.name}" + ("-twice" if times == 2 else "")


@pytest.mark.parametrize(("phase", "command", "ending"), CASES, ids=[case_id(*c) for c in CASES])
def test_a_signal_in_any_phase_ends_the_command_in_one_line_and_leaves_the_old_image(
    request: pytest.FixtureRequest,
    rendered_here: Callable[[list[str]], np.ndarray],
    tmp_path: Path,
    phase: str,
    command: list[str],
    ending: tuple,
) -> None:
    signum, times, code, line = ending
    output = tmp_path / "out.npy"
    output.write_bytes(b"the image of an earlier render")
    scheduler = None
    if SCHEDULER in command:
        scheduler, dask_processes = request.getfixturevalue("external_scheduler")
        command = [scheduler if word == SCHEDULER else word for word in command]
    written = [] if command[0] == "serve" else ["-o", str(output), "--quiet"]
    process = subprocess.Popen(
        [sys.executable, "-c", PHASED, phase, *command, *written],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=ROOT,
        start_new_session=True,
    )
    with ExitStack() as stack:
        try:
            while (said := process.stdout.readline()) != "PHASE\n":
                served = said.startswith("embree-rt: serving ")
                assert served, process.communicate(timeout=TIMEOUT_S)
                if phase == "rendering for a client":
                    stack.enter_context(client_rendering(said))
            if phase == "rendering here":  # well into the render, its threads busy
                time.sleep(1.0)
            sent = time.monotonic()
            for _ in range(times):
                os.killpg(process.pid, signum)  # as a terminal's Ctrl-C: the whole group
                time.sleep(0.3)
            _, stderr = process.communicate(timeout=TIMEOUT_S)
        finally:
            if process.poll() is None:
                os.killpg(process.pid, signal.SIGKILL)
                process.wait()
    assert process.returncode == code, stderr
    assert stderr == line
    ended_s = time.monotonic() - sent
    assert ended_s < (BRICKS_ENDED_WITHIN_S if "--partition" in command else ENDED_WITHIN_S)
    assert [p.name for p in tmp_path.iterdir()] == ["out.npy"]  # no temporary file
    assert output.read_bytes() == b"the image of an earlier render"
    # the cluster the command started was closed: no worker outlives the command
    deadline = time.monotonic() + 15
    while session_members(process.pid) and time.monotonic() < deadline:
        time.sleep(0.2)
    assert session_members(process.pid) == []
    if scheduler is not None:  # not the command's to close, and left as it was
        assert all(p.poll() is None for p in dask_processes)
        again = subprocess.run(
            [sys.executable, "-m", "embree_rt", *command, *written],
            capture_output=True,
            text=True,
            timeout=TIMEOUT_S,
            cwd=ROOT,
        )
        assert (again.returncode, again.stderr) == (0, "")
        assert np.array_equal(np.load(output), rendered_here(command))
        # the worker cannot import this test module: the function goes by value
        cloudpickle.register_pickle_by_value(sys.modules[__name__])
        with distributed.Client(scheduler, timeout=TIMEOUT_S) as client:
            # nothing of the two renders left on the worker: no task, no scene's renderer, no
            # brick held
            assert client.run(held_on_worker) == {w: (0, [], 0) for w in client.nthreads()}


def held_on_worker(dask_worker: distributed.Worker) -> tuple[int, list[str], int]:
    """The tasks a worker holds, the scene renderers (plugins) it keeps, and its actors (the
    bricks of ``--partition``)."""
    scenes = [name for name in dask_worker.plugins if name.startswith("embree-rt-scene-")]
    return len(dask_worker.state.tasks), scenes, len(dask_worker.state.actors)
