"""``embree-rt info``: what a scene holds, its bounds, the BVH's build time and memory, and the
ids its AOVs give objects and materials."""

from __future__ import annotations

import argparse
import time

import numpy as np

from embree_rt.cli.checks import check_library


def command_info(args: argparse.Namespace) -> None:
    from embree_rt import budget
    from embree_rt.aovs import id_listing
    from embree_rt.cli.scene_input import read_scene
    from embree_rt.geometry import SceneGeometry, sphere_kind
    from embree_rt.scene.views import scene_bounds

    scene, _ = read_scene(args)
    check_library()
    resident_before = resident_bytes()
    started = time.perf_counter()
    with SceneGeometry(scene, spheres=args.spheres) as geometry:
        build_s = time.perf_counter() - started
        resident_growth = resident_bytes() - resident_before
        floor_material = geometry.floor_material
        triangles = geometry.triangle_count
        instances = geometry.instance_count
        in_arrays = geometry.bvh.instance_count
        arrays = geometry.bvh.array_count
    objects = [*scene.meshes, *scene.instances]
    distinct = {id(o.mesh): o.mesh for o in objects}.values()
    unique_triangles = sum(len(mesh.faces) for mesh in distinct)
    placements = len(scene.meshes) + sum(len(entry) for entry in scene.instances)
    spheres = len(scene.sphere_radii)
    bounds = scene_bounds(scene)
    # Embree's own footprint is not exposed: estimated by the budget's figures, the spheres'
    # own instances (--spheres mesh) counted among the spheres.
    kind = sphere_kind(spheres, args.spheres)
    sphere_instances = spheres if kind == "mesh" else 0
    estimate = budget.bvh_bytes(
        spheres,
        kind,
        unique_triangles,
        instances=instances - in_arrays,
        arrayed=in_arrays - sphere_instances,
        curve_segments=sum(len(curves) for curves in scene.curves),
    )
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
    print(f"materials:  {len(scene.materials)}")
    floor = f"y = {scene.floor.height:g}" if scene.floor else "none"
    print(f"floor:      {floor}")
    if bounds is None:
        print("bounds:     empty")
    else:
        low, high = bounds
        print(f"bounds:     {point(low)} .. {point(high)}")
    print(f"BVH build:  {build_s:.3f} s")
    print(
        f"memory:     ~{estimate / 2**20:.1f} MiB (estimate), "
        # (the resident set can shrink meanwhile, as freed pages go back: growth is >= 0)
        f"{max(resident_growth, 0) / 2**20:.1f} MiB measured (resident set growth while "
        "building)"
    )
    for line in id_listing(scene, floor_material):
        print(line)


def count(number: int, noun: str) -> str:
    """``number`` with ``noun``, plural unless one: "1 distinct mesh", "2 instance arrays"."""
    plural = noun + ("es" if noun.endswith(("sh", "ch", "s", "x")) else "s")
    return f"{number:,} {noun if number == 1 else plural}"


def point(values: np.ndarray) -> str:
    """Coordinates to 6 significant digits: float32 scene data without its binary noise
    (3.1, not 3.0999999046325684)."""
    return "[" + ", ".join(f"{float(v):.6g}" for v in values) + "]"


def resident_bytes() -> int:
    """This process's resident set in bytes (Linux), or 0 where /proc is missing."""
    import resource

    try:
        with open("/proc/self/statm") as statm:
            return int(statm.read().split()[1]) * resource.getpagesize()
    except OSError:
        return 0
