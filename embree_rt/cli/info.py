"""``embree-rt info``: what a scene holds, its bounds, the BVH's build time and memory, and the
ids its AOVs give objects and materials."""

from __future__ import annotations

import argparse
import time

import numpy as np

from embree_rt import budget
from embree_rt.aovs import id_listing
from embree_rt.cli.clock import CompileClock, resident_bytes
from embree_rt.cli.job import info_job
from embree_rt.cli.sources import prepare_scene
from embree_rt.cli.summary import Timeline
from embree_rt.geometry import SceneGeometry, sphere_kind
from embree_rt.scene.views import scene_bounds


def command_info(args: argparse.Namespace, clock: CompileClock, timeline: Timeline) -> None:
    """Print what ``args.scene`` holds, its bounds, the BVH's build and compile times and
    memory, and the AOVs' ids; a particle file's own summary (``cli.particles``)."""
    from embree_rt.scene.particles.read import is_particle_file

    if is_particle_file(args.scene):
        from embree_rt.cli.particles import command_particle_info

        command_particle_info(args)
        return
    job = info_job(args)
    scene = prepare_scene(job, timeline).scene
    resident_before = resident_bytes()
    compile_growth_before = clock.resident_growth
    started = time.perf_counter()
    with SceneGeometry(scene, spheres=job.spheres) as geometry:
        ended = time.perf_counter()
        # numba's compiling on a fresh install (LLVM's memory) is no part of the BVH's
        compile_growth = clock.resident_growth - compile_growth_before
        build_growth = resident_bytes() - resident_before - compile_growth
        floor_material = geometry.floor_material
        triangles = geometry.triangle_count
        instances = geometry.instance_count
        in_arrays = geometry.bvh.instance_count
        arrays = geometry.bvh.array_count
    compile_s = clock.seconds(started, ended)
    objects = [*scene.meshes, *scene.instances]
    distinct = {id(o.mesh): o.mesh for o in objects}.values()
    unique_triangles = sum(len(mesh.faces) for mesh in distinct)
    placements = len(scene.meshes) + sum(len(entry) for entry in scene.instances)
    spheres = len(scene.sphere_radii)
    bounds = scene_bounds(scene)
    # Embree's own footprint is not exposed: estimated by the budget's figures, the spheres'
    # own instances (--spheres mesh) counted among the spheres.
    kind = sphere_kind(spheres, job.spheres)
    sphere_instances = spheres if kind == "mesh" else 0
    estimate = budget.bvh_bytes(
        spheres,
        kind,
        unique_triangles,
        instances=instances - in_arrays,
        arrayed=in_arrays - sphere_instances,
        curve_segments=sum(len(curves) for curves in scene.curves),
    )
    listing = id_listing(scene, floor_material)
    print(f"scene:      {args.scene}")
    for note in scene.notes:  # what was chosen for a mesh file rendered on its own
        print(f"note:       {note}")
    print(f"spheres:    {spheres:,}")
    meshes = count(len(distinct), "distinct mesh")
    print(f"meshes:     {count(placements, 'placement')} of {meshes}")
    print(f"triangles:  {unique_triangles:,} stored, {triangles:,} placed")
    print(f"instances:  {instances:,}")
    print(f"arrays:     {count(arrays, 'instance array')} holding {count(in_arrays, 'instance')}")
    segments = sum(len(curves) for curves in scene.curves)
    print(f"curves:     {count(segments, 'segment')} in {count(len(scene.curves), 'set')}")
    print(f"lights:     {len(scene.lights)}")
    # as many as the material ids listed below: the scene's and, with a floor, the floor's
    print(f"materials:  {sum(line.startswith('  material ') for line in listing)}")
    floor = f"y = {scene.floor.height:g}" if scene.floor else "none"
    print(f"floor:      {floor}")
    if bounds is None:
        print("bounds:     empty")
    else:
        low, high = bounds
        print(f"bounds:     {point(low)} .. {point(high)}")
    print(f"BVH build:  {ended - started - compile_s:.3f} s")
    if compile_s > 0:
        print(f"compile:    {compile_s:.3f} s (numba, once after installing; not in the build)")
    print(
        f"memory:     BVH ~{estimate / 2**20:.1f} MiB (estimate), "
        # (the resident set can shrink meanwhile, as freed pages go back: growth is >= 0)
        f"{max(build_growth, 0) / 2**20:.1f} MiB measured (resident set growth while "
        f"building, compiling left out); scene {scene_bytes(scene) / 2**20:.1f} MiB (its arrays)"
    )
    for line in listing:
        print(line)


def count(number: int, noun: str) -> str:
    """``number`` with ``noun``, plural unless one: "1 distinct mesh", "2 instance arrays"."""
    plural = noun + ("es" if noun.endswith(("sh", "ch", "s", "x")) else "s")
    return f"{number:,} {noun if number == 1 else plural}"


def point(values: np.ndarray) -> str:
    """Coordinates to 6 significant digits: float32 scene data without its binary noise
    (3.1, not 3.0999999046325684)."""
    return "[" + ", ".join(f"{float(v):.6g}" for v in values) + "]"


def scene_bytes(scene) -> int:
    """Bytes of the scene's arrays: its spheres, each distinct mesh's vertices and faces, and
    the instances' transforms and materials."""
    total = sum(
        a.nbytes for a in (scene.sphere_centers, scene.sphere_radii, scene.sphere_materials)
    )
    distinct = {id(o.mesh): o.mesh for o in [*scene.meshes, *scene.instances]}.values()
    for mesh in distinct:
        total += mesh.vertices.nbytes + mesh.faces.nbytes
    total += sum(entry.transforms.nbytes + entry.materials.nbytes for entry in scene.instances)
    return total
