"""Data-parallel rendering on Dask: bricks on the workers, shading on the client; the image bitwise
the local render's.

Why bitwise (on every x86-64 ISA, as the workers and the client run on this one machine): each
brick's hits are computed by the code of one BVH from the same numbers (see tests/test_bricks.py,
which checks the brick set in one process); the workers hold bricks made from the same scene
(a file loaded, a Scene unpickled, or a random field generated from its recipe, bit-identical
anywhere: tests/test_random_field.py), and the client shades the merged hits with the local
integrator, batch by batch into float64 blocks added in order. Pixels could differ only at exact
ties between bricks; the brick set counts them, and where there are none no pixel may differ.

The cluster is test_distributed's module fixture (2 worker processes, 1 thread each).
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from concurrent.futures import CancelledError
from pathlib import Path

import numpy as np
import pytest

distributed = pytest.importorskip("distributed")  # the test extra installs it: CI runs these

from test_distributed import TIMEOUT_S, bounded, cluster  # noqa: E402, F401

import embree_rt as rt  # noqa: E402
from embree_rt import distributed as rd  # noqa: E402
from embree_rt.bricks import cluster as bc  # noqa: E402
from embree_rt.bricks.partition import split_points  # noqa: E402
from embree_rt.budget import format_bytes  # noqa: E402
from embree_rt.errors import InputError  # noqa: E402
from embree_rt.scene.random_field import plan_field  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
SCENES = ROOT / "scenes"
SMALL = {"width": 160, "height": 90, "spp": 1}


def assert_same_image(renderer: bc.PartitionedRenderer, image, expected) -> None:
    differing = int(np.any(image != expected, axis=2).sum())
    ties = renderer.brick_set.traffic.ties
    # No exact tie between bricks in these scenes: then no pixel may differ.
    assert ties == 0 and differing == 0, (ties, differing)


@pytest.mark.parametrize(
    ("name", "as_path", "bricks"),
    [
        ("three_spheres", True, 2),
        ("showcase", False, 3),
        ("material_spectrum", True, 2),
        ("random_field", True, 3),
        ("mesh_and_spheres", False, 2),
    ],
)
def test_data_parallel_image_is_bitwise_the_local_image(cluster, name, as_path, bricks) -> None:  # noqa: F811
    _, client = cluster
    path = SCENES / f"{name}.toml"
    scene = rt.load_scene(path)
    settings = scene.render.with_overrides(**SMALL)
    direct = client.direct_to_workers
    renderer = bounded(
        bc.PartitionedRenderer,
        path if as_path else scene,
        client,
        partition=bricks,
        batch_size=4096,
    )
    try:
        image = bounded(renderer.render, settings, scene.camera)
        assert sorted(renderer.bricks_held().values()) == ([1, 1] if bricks == 2 else [1, 2])
        assert client.direct_to_workers is True  # the bricks are called on their workers
    finally:
        renderer.release()
    assert client.direct_to_workers == direct  # and the client is as it was
    assert_same_image(renderer, image, rt.render(scene, **SMALL).image)
    deadline = time.monotonic() + TIMEOUT_S  # released: the workers let the bricks go
    while any(client.run(bc.bricks_held).values()) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not any(client.run(bc.bricks_held).values())


def test_a_field_of_1e6_spheres_made_brick_by_brick_is_bitwise_the_local_image(cluster) -> None:  # noqa: F811
    _, client = cluster
    plan = plan_field(1_000_000, seed=2)
    result = bounded(bc.render, rd.FieldRecipe(plan), client, partition=2, **SMALL)
    expected = rt.render(rt.random_field(1_000_000, seed=2), **SMALL).image
    assert np.array_equal(result.image, expected)
    assert result.stats.rays["primary"] == 160 * 90


def test_a_worker_killed_mid_render_changes_no_pixel(cluster) -> None:  # noqa: F811
    _, client = cluster
    scene = rt.random_field(20_000, seed=4)
    settings = scene.render.with_overrides(**SMALL)
    renderer = bounded(bc.PartitionedRenderer, scene, client, partition=2, batch_size=1024)
    victim = renderer.bricks.assignment[0]
    pid = client.run(os.getpid, workers=[victim])[victim]
    killed = threading.Event()

    def kill_once(state: rd.ClusterProgress) -> None:
        if state.done and not killed.is_set():
            killed.set()
            os.kill(pid, signal.SIGKILL)  # its nanny starts a new worker, under a new address

    try:
        image = bounded(renderer.render, settings, scene.camera, kill_once)
        assert killed.is_set()
        assert renderer.bricks.moves >= 1  # brick 0 was built again elsewhere
        assert victim not in renderer.bricks.assignment.values()
    finally:
        renderer.release()
    assert_same_image(renderer, image, rt.render(scene, **SMALL).image)
    client.wait_for_workers(2, timeout=TIMEOUT_S)


def test_an_abandoned_render_ends_the_bricks_waits_and_the_next_render_is_whole(cluster) -> None:  # noqa: F811
    _, client = cluster
    scene = rt.random_field(20_000, seed=4)
    settings = scene.render.with_overrides(**SMALL)
    renderer = bounded(bc.PartitionedRenderer, scene, client, partition=2, batch_size=1024)

    class AbandonedError(Exception):
        pass

    def abandon(state: rd.ClusterProgress) -> None:
        if state.done:
            raise AbandonedError

    try:
        with pytest.raises(AbandonedError):
            bounded(renderer.render, settings, scene.camera, abandon)
        # the integrator's event, shared with the bricks: a query now raises, waiting for none
        assert renderer.bricks.cancelled is renderer.integrator.cancelled
        assert renderer.bricks.cancelled.is_set()
        with pytest.raises(CancelledError):
            renderer.bricks.build()
        image = bounded(renderer.render, settings, scene.camera)  # cleared as it begins
    finally:
        renderer.release()
    assert_same_image(renderer, image, rt.render(scene, **SMALL).image)


def test_waiting_for_workers_ends_once_cancelled_not_at_its_timeout() -> None:
    cancelled = threading.Event()
    with (
        distributed.LocalCluster(n_workers=0, processes=False, dashboard_address=None) as local,
        distributed.Client(local) as client,
    ):
        threading.Timer(0.5, cancelled.set).start()
        began = time.monotonic()
        with pytest.raises(CancelledError):
            bc.live_workers(client, 60.0, cancelled)
        assert time.monotonic() - began < 30  # not the 60 s timeout
        with pytest.raises(rd.ClusterError, match=r"no workers .* after waiting 0\.5 s"):
            bc.live_workers(client, 0.5)


def test_bricks_too_big_for_the_workers_memory_limits_are_refused_up_front() -> None:
    plan = bc.BrickPlan(split_points(np.zeros((1, 3)), 2), "point", (40_000_000, 40_000_000))
    assignment = {0: "tcp://a:1", 1: "tcp://b:1"}
    limits = {"tcp://a:1": 4 << 30, "tcp://b:1": 4 << 30}
    bc.require_bricks_fit(plan, "field", assignment, limits)  # 2 x ~2.9 GB: fits
    with pytest.raises(InputError) as refused:
        bc.require_bricks_fit(plan, "field", {0: "tcp://a:1", 1: "tcp://a:1"}, limits)
    message = str(refused.value)
    # Both bricks on one worker, each 20 bytes a sphere for the field, 51 for point spheres in
    # Embree and a 20 MB ring a core while it is generated, against 4.29 GB; and what it takes.
    need = 2 * (40_000_000 * (20 + 51) + (os.cpu_count() or 1) * (20 << 20))
    assert message.startswith(
        f"--partition 2: worker tcp://a:1 would hold bricks 0, 1, needing ~{format_bytes(need)}"
    )
    assert "limit of 4.29 GB" in message and "~2 workers of this limit" in message
    bc.require_bricks_fit(plan, "field", assignment, {"tcp://a:1": 0, "tcp://b:1": 0})  # no limit


def test_a_partition_too_big_for_a_workers_limit_is_refused_before_anything_is_built() -> None:
    # An in-process worker limited to 300 MB and a field of 2e7 spheres in 1 brick (~1.4 GB).
    with (
        distributed.LocalCluster(
            n_workers=1, processes=False, memory_limit="300MB", dashboard_address=None
        ) as local,
        distributed.Client(local) as client,
    ):
        with pytest.raises(InputError, match=r"--partition 1: worker .* needing ~1\.\d+ GB"):
            bc.PartitionedRenderer(rd.FieldRecipe(plan_field(20_000_000)), client, partition=1)
        assert not any(client.run(bc.bricks_held).values())


def test_command_renders_data_parallel_and_refuses_partition_without_a_cluster(tmp_path) -> None:
    common = ["random", "--count", "20000", "--width", "64", "--height", "36", "--spp", "1"]
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    run = [sys.executable, "-m", "embree_rt"]
    bricks, local = tmp_path / "bricks.npy", tmp_path / "local.npy"
    done = subprocess.run(
        [*run, *common, "--cluster", "local:2", "--partition", "2", "-o", str(bricks)],
        env=env,
        capture_output=True,
        text=True,
        timeout=TIMEOUT_S,
    )
    assert done.returncode == 0, done.stderr
    subprocess.run([*run, *common, "-o", str(local)], env=env, check=True, timeout=TIMEOUT_S)
    assert np.array_equal(np.load(bricks), np.load(local))
    alone = tmp_path / "alone.npy"
    done = subprocess.run(
        [*run, *common, "--partition", "2", "-o", str(alone)],
        env=env,
        capture_output=True,
        text=True,
        timeout=TIMEOUT_S,
    )
    assert done.returncode == 2 and not alone.exists()
    assert done.stderr.strip().splitlines() == [
        "embree-rt: error: --partition: bricks are held by Dask workers: add --cluster local:N "
        "or --scheduler ADDRESS"
    ]
