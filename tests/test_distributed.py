"""Rendering on a Dask cluster: the same image as local, bit for bit.

Why bitwise equality holds here (and on every ISA, as both sides run on this one machine): the
cluster computes the very batches ``batch_ranges`` cuts, each by ``Renderer.trace_batch`` on the
same scene, in processes on the same CPU, so Embree picks the same kernels and every float
operation is the same; each pixel's sum is formed inside one batch's ``FilmBlock`` (a batch holds
whole pixels), in ray order, and added once onto the film's zero, so the order in which blocks
arrive cannot change a bit. The local render's own image does not depend on its batch size or
thread count (``test_render_images``), so the cluster's batches need not match its split.
Across machines with different instruction sets this is not promised (see README).

One ``LocalCluster`` of 2 worker processes (1 thread each) serves the module and is always shut
down; every wait is bounded.
"""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager, suppress
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from process_groups import stop

distributed = pytest.importorskip("distributed")  # the test extra installs it: CI runs these

import embree_rt as rt  # noqa: E402
from embree_rt import budget  # noqa: E402
from embree_rt import distributed as rd  # noqa: E402
from embree_rt.errors import InputError  # noqa: E402
from embree_rt.scene import RenderSettings  # noqa: E402
from embree_rt.scene.animation import Animation, camera_at  # noqa: E402
from embree_rt.scene.random_field import plan_field  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
SCENES = ROOT / "scenes"
# Small images cut in small batches: dozens of tasks, so both workers take part.
SMALL = {"width": 96, "height": 54, "spp": 2}
SMALL_BATCH = 96 * 2 * 6  # six rows of pixels a task: about a dozen tasks an image
TIMEOUT_S = 120


@pytest.fixture(scope="module")
def cluster():
    with rd.local_cluster(2, silence_logs=50) as local, distributed.Client(local) as client:
        client.wait_for_workers(2, timeout=TIMEOUT_S)
        yield local, client


def test_local_workers_run_without_dasks_stack_sampling_profiler(cluster) -> None:
    # It takes the GIL every 10 ms in every worker; our batches ran 1.35x slower with it.
    _, client = cluster
    sampling = client.run(lambda dask_worker: "profile" in dask_worker.periodic_callbacks)
    assert len(sampling) == 2 and not any(sampling.values()), sampling


def bounded(function, *args, **kwargs):
    """``function(*args, **kwargs)`` in a thread, failing the test past ``TIMEOUT_S``."""
    with ThreadPoolExecutor(max_workers=1) as pool:
        return pool.submit(function, *args, **kwargs).result(timeout=TIMEOUT_S)


def local_image(scene: rt.Scene, camera: rt.Camera | None = None, **settings) -> np.ndarray:
    if camera is not None:
        scene = replace(scene, camera=camera)
    return rt.render(scene, **{**SMALL, **settings}).image


@pytest.mark.parametrize(
    ("name", "as_path"),
    [("showcase", True), ("three_spheres", False), ("mesh_and_spheres", False)],
)
def test_cluster_image_is_bitwise_the_local_image(cluster, name: str, as_path: bool) -> None:
    _, client = cluster
    path = SCENES / f"{name}.toml"
    scene = rt.load_scene(path)
    source = path if as_path else scene  # a file travels as its path, a Scene is scattered
    image = bounded(rd.render, source, client, batch_size=SMALL_BATCH, **SMALL).image
    expected = local_image(scene)
    assert image.dtype == np.float32 and image.shape == expected.shape
    assert np.array_equal(image, expected)
    # render().image freed the workers' renderers of the scene. (A lambda: pickled by value, where a
    # function of this module would be looked up, in vain, by name on the workers.)
    name = rd.plugin_name(rd.scene_key(rd.SceneFile(str(path)) if as_path else scene, "analytic"))
    held = client.run(lambda dask_worker, name=name: name in dask_worker.plugins)
    assert held and not any(held.values())


def test_ambient_occlusion_on_the_cluster_is_bitwise_the_local_image(cluster) -> None:
    """Each hit's occlusion rays are drawn from its camera sample's index and the seed alone,
    so the workers trace the very rays the local render does."""
    _, client = cluster
    scene = rt.load_scene(SCENES / "benzene.toml")
    scene.render.background = "sky"  # (a background's alpha pass is local-only: refused here)
    scene.render.ao = rt.AmbientOcclusion(samples=6, distance=2.0)
    image = bounded(rd.render, scene, client, batch_size=SMALL_BATCH, **SMALL).image
    assert np.array_equal(image, local_image(scene))
    scene.render.background = "white"
    with pytest.raises(ValueError, match=r"render\.background"):
        rd.render(scene, client, **SMALL)


def test_random_field_of_1e5_spheres_is_bitwise_the_local_image(cluster) -> None:
    _, client = cluster
    plan = plan_field(100_000, seed=3)
    # The workers generate the field from its parameters; the client renders it locally.
    renderer = rd.ClusterRenderer(rd.FieldRecipe(plan), client, batch_size=4096)
    scene = rt.random_field(100_000, seed=3)
    settings = RenderSettings(width=128, height=72, spp=1, max_depth=6, seed=0)
    image = bounded(renderer.render, settings, scene.camera)
    expected = rt.render(scene, width=128, height=72, spp=1, max_depth=6, seed=0).image
    assert np.array_equal(image, expected)
    assert renderer.stats.rays["primary"] == 128 * 72


def test_scene_is_scattered_once_and_built_once_per_worker(cluster) -> None:
    _, client = cluster
    scene = rt.load_scene(SCENES / "three_spheres.toml")
    scene.render.seed = 11  # a scene no other test has used: its own key, its own builds
    renderer = rd.ClusterRenderer(scene, client, batch_size=SMALL_BATCH)
    holders = client.who_has(renderer.source)[renderer.source.key]
    assert len(holders) == 2  # broadcast: on both workers before any task runs
    settings = RenderSettings(max_depth=6, seed=11, **SMALL)
    cameras = [(f, camera_at(scene.camera, Animation(3, orbit=30.0), f)) for f in range(3)]
    images = {}
    bounded(renderer.render_frames, rd.FrameRequest(settings, cameras, images.__setitem__))
    assert sorted(images) == [0, 1, 2]
    # Three frames of a dozen batches each, spread over both workers: one build on each.
    assert renderer.builds() == dict.fromkeys(client.nthreads(), 1)
    assert (
        renderer.key != rd.ClusterRenderer(rt.load_scene(SCENES / "three_spheres.toml"), client).key
    )


def test_animation_frames_equal_frames_rendered_one_by_one_locally(cluster) -> None:
    _, client = cluster
    scene = rt.load_scene(SCENES / "showcase.toml")
    animation = Animation(4, orbit=90.0)
    frames = [0, 3, 1]
    cameras = [(f, camera_at(scene.camera, animation, f)) for f in frames]
    renderer = rd.ClusterRenderer(SCENES / "showcase.toml", client, batch_size=SMALL_BATCH)
    images = {}
    settings = RenderSettings(max_depth=6, seed=0, **SMALL)
    bounded(renderer.render_frames, rd.FrameRequest(settings, cameras, images.__setitem__))
    assert sorted(images) == sorted(frames)
    for f, camera in cameras:
        assert np.array_equal(images[f], local_image(scene, camera)), f"frame {f}"
    assert not np.array_equal(images[0], images[3])  # the camera did move


def test_a_worker_that_joins_late_takes_part(cluster) -> None:
    local, client = cluster
    scene = rt.load_scene(SCENES / "three_spheres.toml")
    scene.render.seed = 5
    # Plugin registered and scene scattered while there are 2 workers.
    renderer = rd.ClusterRenderer(scene, client, batch_size=96 * 2 * 2)
    before = set(client.nthreads())
    local.scale(3)
    try:
        client.wait_for_workers(3, timeout=TIMEOUT_S)
        (late,) = set(client.nthreads()) - before
        image = bounded(renderer.render, RenderSettings(max_depth=6, seed=5, **SMALL), scene.camera)
        assert renderer.builds()[late] == 1  # it got the plugin and the scene, and rendered
        assert np.array_equal(image, local_image(scene, seed=5))
    finally:
        local.scale(2)
        deadline = time.monotonic() + TIMEOUT_S
        while len(client.nthreads()) > 2 and time.monotonic() < deadline:
            time.sleep(0.1)


def test_a_worker_that_cannot_load_the_scene_is_bad_input(cluster, tmp_path: Path) -> None:
    _, client = cluster
    spheres = tmp_path / "many.npz"
    np.savez(spheres, centers=np.zeros((1, 3)), radii=np.ones(1))
    scene_file = tmp_path / "scene.toml"
    scene_file.write_text(f'[[sphere_arrays]]\nfile = "{spheres.name}"\n', encoding="utf-8")
    renderer = rd.ClusterRenderer(scene_file, client)
    spheres.unlink()  # as on a worker whose file system lacks the data file
    settings = RenderSettings(width=8, height=8, spp=1, max_depth=1, seed=0)
    with pytest.raises(rd.WorkerSceneError, match=r"sphere_arrays\[0\]\.file: .*no such file"):
        bounded(renderer.render, settings, rt.Camera())


def test_a_scene_without_spheres_has_a_digest() -> None:
    """A mesh file rendered on its own on a cluster goes to the workers as a ``Scene`` without
    spheres; its digest must neither fail (a memoryview of an empty array cannot be cast to
    bytes) nor match the same scene's with spheres."""
    field = rt.random_field(3, seed=0)
    no_spheres = replace(
        field,
        sphere_centers=field.sphere_centers[:0],
        sphere_radii=field.sphere_radii[:0],
        sphere_materials=field.sphere_materials[:0],
        sphere_colors=None,
    )
    assert rd.scene_digest(no_spheres) == rd.scene_digest(replace(no_spheres))
    assert rd.scene_digest(no_spheres) != rd.scene_digest(field)


def test_a_worker_loads_a_scene_file_without_saying_its_warnings_again(tmp_path: Path) -> None:
    """The client said them as it loaded the file (the command: one line each); a local
    cluster's workers write to the command's stderr, in Python's raw form."""
    import warnings

    from embree_rt.scene import load_scene
    from embree_rt.scene.errors import InputWarning

    (tmp_path / "tri.obj").write_text(
        "mtllib tri.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nusemtl skin\nf 1/1 2/1 3/1\n"
    )
    (tmp_path / "tri.mtl").write_text("newmtl skin\nKd 0.5 0.5 0.5\nmap_Kd missing.png\n")
    scene_file = tmp_path / "scene.toml"
    scene_file.write_text('[[meshes]]\nfile = "tri.obj"\n')
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        on_the_client = load_scene(scene_file)
        assert [w.category for w in said] == [InputWarning]  # the texture it leaves out
        said.clear()
        on_a_worker = rd.SceneFile(str(scene_file)).load()
    assert said == []
    assert rd.scene_digest(on_a_worker) == rd.scene_digest(on_the_client)  # the same scene


def test_a_data_file_replaced_under_a_live_renderer_is_loaded_again(cluster, tmp_path) -> None:
    # Renderers of one scene share the workers' BVH while any of them lives: a scene file whose
    # sphere array was rewritten is another scene, and must not be rendered from the old BVH.
    _, client = cluster
    spheres = tmp_path / "spheres.npz"
    scene_file = tmp_path / "scene.toml"
    scene_file.write_text(
        f'[[sphere_arrays]]\nfile = "{spheres.name}"\n[camera]\nposition = [0, 1, -6]\n',
        encoding="utf-8",
    )
    settings = RenderSettings(width=32, height=24, spp=1, max_depth=1, seed=0)
    np.savez(spheres, centers=[[-1.0, 1.0, 0.0]], radii=[1.0])
    first = rd.ClusterRenderer(scene_file, client, batch_size=32)  # a task a row
    try:
        camera = rt.load_scene(scene_file).camera
        for _ in range(3):  # until both workers have taken a task and hold the old scene
            old = bounded(first.render, settings, camera)
            if sorted(first.builds().values()) == [1, 1]:
                break
        assert sorted(first.builds().values()) == [1, 1]
        np.savez(spheres, centers=[[1.0, 1.0, 0.0], [-1.5, 0.5, 1.0]], radii=[1.0, 0.5])
        second = rd.ClusterRenderer(scene_file, client, batch_size=32)
        try:
            new = bounded(second.render, settings, rt.load_scene(scene_file).camera)
        finally:
            second.release()
    finally:
        first.release()
    expected = local_image(rt.load_scene(scene_file), width=32, height=24, spp=1, max_depth=1)
    assert not np.array_equal(old, expected)  # the two scenes do look different
    assert np.array_equal(new, expected)


@pytest.mark.parametrize("as_recipe", [True, False])
def test_a_scene_too_big_for_a_worker_is_refused_before_it_is_built(monkeypatch, as_recipe) -> None:
    # The worker's own check (its plugin, in this process): with 1 MB available, a field of
    # 1e4 spheres is refused before it is generated, and a scattered scene before its BVH.
    plan = plan_field(10_000, seed=0)
    monkeypatch.setattr(budget, "available_memory", lambda: 1 << 20)
    plugin = rd.SceneRendererPlugin("key", "analytic")
    plugin.setup(None)
    made = []
    monkeypatch.setattr(rd.FieldRecipe, "load", lambda self: made.append(self))
    source = rd.FieldRecipe(plan) if as_recipe else rt.load_scene(SCENES / "three_spheres.toml")
    if not as_recipe:
        monkeypatch.setattr(budget, "GEOMETRY_BYTES_PER_SPHERE", {"user": 1 << 20, "point": 0})
    with pytest.raises(rd.WorkerSceneError, match=r"spheres would need ~.* GB of memory"):
        plugin.integrator_for(source)
    assert plugin.integrator is None and made == []


def test_a_worker_killed_mid_render_leaves_the_image_unchanged(cluster) -> None:
    # Last of the cluster's tests: the worker's nanny restarts it while the module closes.
    _, client = cluster
    scene = rt.load_scene(SCENES / "three_spheres.toml")
    renderer = rd.ClusterRenderer(scene, client, batch_size=96 * 2 * 2)  # 27 tasks of 2 rows
    victim = sorted(client.nthreads())[0]
    pid = client.run(os.getpid, workers=[victim])[victim]
    killed = threading.Event()

    def kill_once(state: rd.ClusterProgress) -> None:
        if state.done and not killed.is_set():
            killed.set()
            # The worker process dies at once; its nanny starts a new one, which has to load
            # the scene again. The batches it held run elsewhere.
            os.kill(pid, signal.SIGKILL)

    settings = RenderSettings(max_depth=6, seed=0, **SMALL)
    image = bounded(renderer.render, settings, scene.camera, kill_once)
    assert killed.is_set()
    assert np.array_equal(image, local_image(scene))


def test_a_cluster_without_workers_is_an_error_not_a_hang() -> None:
    class NoWorkers:  # a client whose cluster has lost every worker
        scheduler = type("Scheduler", (), {"address": "tcp://10.0.0.1:8786"})()

        def nthreads(self):
            return {}

    renderer = rd.ClusterRenderer.__new__(rd.ClusterRenderer)
    renderer.client, renderer.no_workers_timeout_s = NoWorkers(), 0.3
    started = time.monotonic()
    with pytest.raises(rd.ClusterError, match=r"no workers \(all lost mid-render\)"):
        renderer._wait_for_workers(rd.ClusterProgress(done=5))
    assert time.monotonic() - started < 5


# -- the command against `dask scheduler` / `dask worker` ------------------------------------


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def run_cli(*args: str, env: dict[str, str] | None = None) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "embree_rt", *args],
        capture_output=True,
        text=True,
        timeout=TIMEOUT_S,
        cwd=ROOT,
        env={**os.environ, **(env or {})},
    )


ORBIT = "\n[animation]\nframes = 6\norbit = 60.0\n"


def test_command_on_dask_scheduler_and_worker_processes(tmp_path: Path) -> None:
    address = f"tcp://127.0.0.1:{free_port()}"
    bin_dir = Path(sys.executable).parent
    started = []
    try:
        started.append(
            subprocess.Popen(
                [
                    bin_dir / "dask",
                    "scheduler",
                    "--host",
                    "127.0.0.1",
                    "--port",
                    address.rsplit(":", 1)[1],
                    "--no-dashboard",
                ],
                stdout=subprocess.DEVNULL,
                stderr=subprocess.DEVNULL,
                start_new_session=True,
            )
        )
        started.append(
            subprocess.Popen(
                [
                    bin_dir / "dask",
                    "worker",
                    address,
                    "--nthreads",
                    "1",
                    "--nworkers",
                    "1",
                    "--memory-limit",
                    "0",
                    "--no-dashboard",
                    "--host",
                    "127.0.0.1",
                ],
                stdout=subprocess.DEVNULL,
                stderr=subprocess.DEVNULL,
                start_new_session=True,
            )
        )
        with distributed.Client(address, timeout=TIMEOUT_S) as client:
            client.wait_for_workers(1, timeout=TIMEOUT_S)
        # An animated scene: the command's frame files, rendered on the cluster.
        scene_file = tmp_path / "orbit.toml"
        scene_file.write_text((SCENES / "three_spheres.toml").read_text() + ORBIT)
        pattern = str(tmp_path / "f{frame}.npy")
        flags = ["--width", "64", "--height", "36", "--spp", "2", "--frames", "2:4"]
        result = run_cli("render", str(scene_file), "-o", pattern, *flags, "--scheduler", address)
        assert result.returncode == 0, result.stderr
        assert "on 1 Dask worker " in result.stderr
        assert sorted(p.name for p in tmp_path.glob("*.npy")) == ["f2.npy", "f3.npy"]
        scene = rt.load_scene(scene_file)
        for f in (2, 3):
            camera = camera_at(scene.camera, scene.animation, f)
            expected = rt.render(replace(scene, camera=camera), width=64, height=36, spp=2).image
            assert np.array_equal(np.load(tmp_path / f"f{f}.npy"), expected), f"frame {f}"
    finally:
        for process in reversed(started):
            stop(process)


def test_command_with_an_unreachable_scheduler_fails_in_one_line(tmp_path: Path) -> None:
    output = tmp_path / "out.png"
    address = f"tcp://127.0.0.1:{free_port()}"  # nothing listens there
    started = time.monotonic()
    # --scheduler-timeout bounds the attempt (default 10 s).
    result = run_cli(
        "render",
        "scenes/three_spheres.toml",
        "-o",
        str(output),
        "--width",
        "8",
        "--height",
        "8",
        "--scheduler",
        address,
        "--scheduler-timeout",
        "2",
    )
    assert result.returncode == 2, result.stderr
    lines = result.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("embree-rt: error: --scheduler: "), lines
    assert address in lines[0] and "Traceback" not in result.stderr
    assert not output.exists()
    assert time.monotonic() - started < 60


def one_line_refusal(result: subprocess.CompletedProcess, start: str) -> str:
    """The command's single stderr line, asserted to be exit 2 starting with ``start``."""
    assert result.returncode == 2, result.stderr
    lines = result.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"embree-rt: error: {start}"), lines
    return lines[0]


@contextmanager
def listening(answer: bytes | None):
    """A socket on 127.0.0.1 that accepts every connection and, when ``answer`` is given,
    replies it to whatever arrives (else says nothing, ever): its tcp:// address."""
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen()
    server.settimeout(0.2)
    stopping = threading.Event()
    held = []

    def serve() -> None:
        while not stopping.is_set():
            try:
                connection, _ = server.accept()
            except TimeoutError:
                continue
            held.append(connection)
            if answer is not None:
                connection.settimeout(5)
                with suppress(OSError):
                    connection.recv(4096)
                    connection.sendall(answer)

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    try:
        yield f"tcp://127.0.0.1:{server.getsockname()[1]}"
    finally:
        stopping.set()
        thread.join(timeout=5)
        for connection in held:
            connection.close()
        server.close()


SMALL_FLAGS = ("--width", "8", "--height", "8", "--spp", "1")


def test_a_scheduler_that_accepts_and_never_answers_is_refused_within_the_timeout(tmp_path):
    output = tmp_path / "out.npy"
    with listening(None) as address:
        started = time.monotonic()
        result = run_cli(
            "render",
            "scenes/three_spheres.toml",
            "-o",
            str(output),
            *SMALL_FLAGS,
            "--scheduler",
            address,
            "--scheduler-timeout",
            "2",
        )
        elapsed = time.monotonic() - started
    line = one_line_refusal(result, f"--scheduler: {address}: no answer within 2 s")
    assert "--scheduler-timeout" in line
    assert 2 <= elapsed < 30  # waited the 2 s, not forever (Python and Embree start in the rest)
    assert list(tmp_path.iterdir()) == []


def test_a_port_speaking_http_is_not_a_scheduler(tmp_path):
    # Dask would read "HTTP/1.1" as a frame length of 3.5e18 bytes and try to allocate it.
    output = tmp_path / "out.npy"
    with listening(b"HTTP/1.1 400 Bad Request\r\nContent-Length: 0\r\n\r\n") as address:
        result = run_cli(
            "render",
            "scenes/three_spheres.toml",
            "-o",
            str(output),
            *SMALL_FLAGS,
            "--scheduler",
            address,
        )
    one_line_refusal(result, f"--scheduler: {address}: does not speak Dask's protocol")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    ("flags", "start"),
    [
        (("--scheduler", ""), "--scheduler: expected a value, got ''"),
        (("--scheduler", " "), "--scheduler: expected a value"),
        (("--cluster", ""), "--cluster: expected a value"),
        (("--scheduler", "tcp://127.0.0.1:1", "--scheduler-timeout", "0"), "--scheduler-timeout"),
        (("--scheduler", "tcp://127.0.0.1:1", "--scheduler-timeout", "nan"), "--scheduler-timeout"),
        (("--cluster", f"local:{4 * (os.cpu_count() or 1) + 1}"), "--cluster: local:"),
        (("--cluster", "local:10000"), "--cluster: local:10000 would start 10,000 worker"),
    ],
)
def test_empty_addresses_bad_timeouts_and_more_workers_than_the_machine_are_refused(
    tmp_path, flags, start
):
    output = tmp_path / "out.npy"
    result = run_cli("render", "scenes/three_spheres.toml", "-o", str(output), *SMALL_FLAGS, *flags)
    one_line_refusal(result, start)
    assert list(tmp_path.iterdir()) == []


def test_local_worker_count_takes_up_to_four_workers_a_core() -> None:
    most = 4 * (os.cpu_count() or 1)
    assert rd.local_worker_count(f"local:{most}") == most
    with pytest.raises(InputError, match=f"at most {most}"):
        rd.local_worker_count(f"local:{most + 1}")
