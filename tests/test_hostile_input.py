"""Hostile and extreme scene input: whatever a file holds, loading ends in a ``SceneError`` of one
line naming the file and the key, or in a scene that renders without NaN; never another exception.

The cases are the ones a hostile user tried: parser limits (nesting, the digits of an integer),
numbers float64 holds and float32 does not, names with NUL or newline characters, a zip bomb.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from embree_rt import Scene, load_scene, render
from embree_rt.integrator import Integrator
from embree_rt.materials import Checker, Material
from embree_rt.scene import SceneError

SPHERE = "[[spheres]]\ncenter = [0, 1, 0]\nradius = 1\n"
DIGITS_400 = "1" + "0" * 400
ROOT = Path(__file__).resolve().parent.parent


def _load_error(path: Path, text: str) -> SceneError:
    path.write_text(text)
    with pytest.raises(SceneError) as caught:
        load_scene(path)
    message = str(caught.value)
    assert "\n" not in message and "\r" not in message and message.isprintable()
    return caught.value


# case: (file name, text, key, words the problem must contain)
PARSER_LIMITS = {
    "600 nested toml arrays": ("s.toml", "a = " + "[" * 600 + "]" * 600, "(syntax)", "nested"),
    "600 nested toml tables": (
        "s.toml",
        "a = " + "{b = " * 600 + "1" + "}" * 600,
        "(syntax)",
        "nested",
    ),
    "100000 nested json lists": (
        "s.json",
        '{"a": ' + "[" * 100_000 + "]" * 100_000 + "}",
        "(syntax)",
        "nested",
    ),
    "20 nested json tables": (
        "s.json",
        '{"render": ' + '{"a": ' * 20 + "1" + "}" * 21,
        "render" + ".a" * 16,
        "levels deep",
    ),
    "4400-digit toml integer": (
        "s.toml",
        "[render]\nwidth = " + "1" * 4400,
        "(syntax)",
        "more than 4300 digits",
    ),
    "4400-digit json integer": (
        "s.json",
        '{"render": {"width": ' + "1" * 4400 + "}}",
        "(syntax)",
        "4300 digits",
    ),
    "400-digit radius": (
        "s.toml",
        SPHERE.replace("radius = 1", f"radius = {DIGITS_400}"),
        "spheres[0].radius",
        "within ±1e+10",
    ),
    "400-digit centre": (
        "s.toml",
        SPHERE.replace("[0, 1, 0]", f"[{DIGITS_400}, 1, 0]"),
        "spheres[0].center",
        "within ±1e+10",
    ),
    "400-digit negative fov": (
        "s.json",
        json.dumps({"camera": {"fov": -(10**400)}}),
        "camera.fov",
        "within",
    ),
    "NUL in a mesh file name": (
        "s.toml",
        '[[meshes]]\nfile = "a\\u0000b.obj"',
        "meshes[0].file",
        "NUL",
    ),
    "NUL in a sphere array name": (
        "s.toml",
        '[[sphere_arrays]]\nfile = "a\\u0000.npz"',
        "sphere_arrays[0].file",
        "NUL",
    ),
    "NUL in a placements name": (
        "s.toml",
        '[[instances]]\nmesh = "m.obj"\ntransforms = "\\u0000"',
        "instances[0].transforms",
        "NUL",
    ),
}


@pytest.mark.parametrize("case", sorted(PARSER_LIMITS))
def test_parser_limits_are_one_line_scene_errors(tmp_path: Path, case: str) -> None:
    name, text, key, words = PARSER_LIMITS[case]
    error = _load_error(tmp_path / name, text)
    assert (error.file, error.key) == (str(tmp_path / name), key)
    assert words in error.problem


def test_a_newline_in_a_key_or_a_file_name_stays_on_one_line(tmp_path: Path) -> None:
    error = _load_error(tmp_path / "s.toml", '[render]\n"wid\\nth" = 3\n')
    assert error.key == "render.wid\nth"
    assert "'render.wid\\nth'" in str(error)  # quoted by repr: where the key ends is plain
    error = _load_error(tmp_path / "s.toml", '[[meshes]]\nfile = "a\\nb.obj"\n')
    assert "a\\nb.obj" in str(error) and "no such file" in str(error)
    folder = tmp_path / "new\nline"
    folder.mkdir()
    error = _load_error(folder / "s.toml", "[render]\nwidth = 0\n")
    assert str(error).startswith(repr(str(folder / "s.toml")) + ": render.width: ")


def _run(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "embree_rt", *args],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=cwd,
    )


def test_the_command_says_one_line_and_exits_2_for_a_parser_limit(tmp_path: Path) -> None:
    (tmp_path / "deep.toml").write_text("a = " + "[" * 600 + "]" * 600)
    result = _run("render", "deep.toml", "-o", "out.png", cwd=tmp_path)
    assert result.returncode == 2, result.stderr
    assert result.stderr.count("\n") == 1 and "deep.toml: (syntax):" in result.stderr
    assert not (tmp_path / "out.png").exists()


# -- numbers float64 holds and float32 does not ----------------------------------------------------

LIGHT = "[[lights]]\nposition = [0, 5, 0]\n"
# case: (scene text, support file to write (name, kind, value), key, words)
BEYOND_FLOAT32 = {
    "centre 1e39": (
        SPHERE.replace("[0, 1, 0]", "[1e39, 1, 0]"),
        None,
        "spheres[0].center",
        "within ±1e+10",
    ),
    "light at 1e39": (
        "[[lights]]\nposition = [0, 1e39, 0]\n",
        None,
        "lights[0].position",
        "within",
    ),
    "light intensity 1e39": (LIGHT + "intensity = 1e39\n", None, "lights[0].intensity", "within"),
    "light intensity 2e6": (LIGHT + "intensity = 2e6\n", None, "lights[0].intensity", "<= 1e+06"),
    "light colour 1e39": (LIGHT + "color = [1, 1e39, 1]\n", None, "lights[0].color", "within"),
    "light colour 1e7": (LIGHT + "color = [1, 1e7, 1]\n", None, "lights[0].color", "<= 1e+06"),
    "material colour 1e39": (
        "[materials.hot]\ncolor = [1e39, 0, 0]\n",
        None,
        "materials.hot.color",
        "within",
    ),
    "material colour 2e6": (
        "[materials.hot]\ncolor = [0, 2e6, 0]\n",
        None,
        "materials.hot.color",
        "<= 1e+06",
    ),
    "sky 1e39": ("[background]\nzenith = [1e39, 0, 0]\n", None, "background.zenith", "within"),
    "ior 1e39": ("[materials.hot]\nior = 1e39\n", None, "materials.hot.ior", "within"),
    "radius 1e-320": (
        SPHERE.replace("radius = 1", "radius = 1e-320"),
        None,
        "spheres[0].radius",
        ">= 1e-18",
    ),
    "floor square 1e-300": ("[floor]\nsize = 1e-300\n", None, "floor.size", ">= 1e-18"),
    "npz centre 1e308": (
        '[[sphere_arrays]]\nfile = "a.npz"\n',
        ("a.npz", "centers", 1e308),
        "sphere_arrays[0].file",
        "centers row 1 must be finite and within",
    ),
    "npz radius 1e-320": (
        '[[sphere_arrays]]\nfile = "a.npz"\n',
        ("a.npz", "radii", 1e-320),
        "sphere_arrays[0].file",
        "radii row 1",
    ),
    "obj vertex 1e39": (
        '[[meshes]]\nfile = "far.obj"\n',
        ("far.obj", "vertex", 1e39),
        "meshes[0].file",
        "beyond the ±1e+10",
    ),
    "mesh scaled past the limit": (
        '[[meshes]]\nfile = "far.obj"\nscale = 1e9\n',
        ("far.obj", "vertex", 100.0),
        "meshes[0].file",
        "beyond",
    ),
    "instances placed at 1e12": (
        '[[instances]]\nmesh = "far.obj"\ntransforms = "p.npz"\n',
        ("p.npz", "positions", 1e12),
        "instances[0].transforms",
        "row 1 places the mesh",
    ),
}


def _write_support(folder: Path, name: str, kind: str, value: float) -> None:
    if kind in ("centers", "radii"):
        arrays = {"centers": np.zeros((3, 3)), "radii": np.ones(3)}
        arrays[kind][1] = value
        np.savez(folder / name, **arrays)
    elif kind == "vertex":
        (folder / name).write_text(f"v 0 0 0\nv {value!r} 0 0\nv 0 1 0\nf 1 2 3\n")
    else:
        (folder / "far.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
        np.savez(folder / name, positions=np.array([[0.0, 0, 0], [value, 0, 0]]))


@pytest.mark.parametrize("case", sorted(BEYOND_FLOAT32))
def test_numbers_beyond_float32_are_refused_where_they_enter(tmp_path: Path, case: str) -> None:
    text, support, key, words = BEYOND_FLOAT32[case]
    if support is not None:
        _write_support(tmp_path, *support)
    error = _load_error(tmp_path / "s.toml", text)
    assert error.key == key
    assert words in error.problem


def test_the_python_api_holds_spheres_and_meshes_to_the_same_limits() -> None:
    import trimesh

    scene = Scene()
    with pytest.raises(ValueError, match=r"centers row 0 must be finite and within"):
        scene.add_sphere((1e39, 0.0, 0.0), 1.0)
    with pytest.raises(ValueError, match=r"radii row 1"):
        scene.add_spheres(np.zeros((2, 3)), np.array([1.0, 1e-320]), "matte")
    assert len(scene.sphere_radii) == 0
    triangle = trimesh.Trimesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]])
    with pytest.raises(ValueError, match=r"transform: places the mesh 2e\+11"):
        scene.add_mesh(triangle, transform=np.diag([2e11, 2e11, 2e11, 1.0]))
    placements = np.stack([np.eye(4)] * 3)
    placements[2, 0, 3] = -3e10
    with pytest.raises(ValueError, match=r"transforms: row 2: places the mesh 3e\+10"):
        scene.add_instances(triangle, placements)
    assert scene.meshes == [] and scene.instances == []


def _lit_sphere() -> Scene:
    from embree_rt.scene.model import PointLight

    scene = Scene(lights=[PointLight((0.0, 5.0, 3.0))])
    scene.add_sphere((0.0, 1.0, 0.0), 1.0)
    return scene


def _set_light(field: str, value):
    def change(scene: Scene) -> None:
        setattr(scene.lights[0], field, value)

    return change


def _set_floor(change):
    def apply(scene: Scene) -> None:
        change(scene.floor)

    return apply


# A scene built in Python with one value a file could not hold: (change, its key in a file).
PYTHON_VALUES = {
    "light intensity 1e39": (_set_light("intensity", 1e39), "lights[0].intensity"),
    "light intensity 2e6": (_set_light("intensity", 2e6), "lights[0].intensity"),
    "light colour 1e39": (_set_light("color", (1e39, 1.0, 1.0)), "lights[0].color"),
    "light at 1e39": (_set_light("position", (1e39, 5.0, 0.0)), "lights[0].position"),
    "light intensity NaN": (_set_light("intensity", float("nan")), "lights[0].intensity"),
    "material colour 1e39": (
        lambda scene: scene.add_material("hot", Material(color=(1e39, 0.5, 0.5))),
        "materials.hot.color",
    ),
    "sky 1e39": (
        lambda scene: setattr(scene.background, "horizon", (1e39, 1.0, 1.0)),
        "background.horizon",
    ),
    "floor at 1e39": (_set_floor(lambda floor: setattr(floor, "height", 1e39)), "floor.height"),
    "floor square 1e-320": (
        _set_floor(lambda floor: setattr(floor, "checker", Checker(size=1e-320))),
        "floor.size",
    ),
    "floor colour 1e39": (
        _set_floor(lambda floor: setattr(floor, "checker", Checker(color_a=(1e39, 0.0, 0.0)))),
        "floor.color_a",
    ),
    "camera at 1e39": (
        lambda scene: setattr(scene.camera, "position", (0.0, 1e39, 5.0)),
        "camera.position",
    ),
    "sphere centres set to 1e39": (
        lambda scene: setattr(scene, "sphere_centers", np.array([[1e39, 1.0, 0.0]])),
        "spheres",
    ),
}


@pytest.mark.parametrize("case", sorted(PYTHON_VALUES))
def test_python_built_values_are_held_to_a_files_limits_before_rendering(case: str) -> None:
    """``PointLight(intensity=1e39)`` made an image with NaN at exit 0: the renderer now holds
    a scene built in Python to a file's limits (``Scene.check``, the rules the file's reader
    applies too), so it is refused as the same value in a file is, naming the key a file would
    use."""
    change, key = PYTHON_VALUES[case]
    scene = _lit_sphere()
    change(scene)
    with pytest.raises(SceneError) as caught:
        render(scene, width=8, height=8, spp=1)
    assert caught.value.file == "scene" and caught.value.key == key, str(caught.value)
    # So is it by the bare Integrator that Dask workers and the browser preview build.
    with pytest.raises(SceneError) as caught:
        Integrator(scene, threads=1)
    assert caught.value.key == key, str(caught.value)


@pytest.mark.parametrize("case", sorted(set(PYTHON_VALUES) - {"sphere centres set to 1e39"}))
def test_a_python_built_value_and_the_same_value_in_a_file_are_refused_alike(
    tmp_path: Path, case: str
) -> None:
    """The same key and the same words whether the value was set in Python (``Scene.check``)
    or written to a file and read (the writer does not check; the reader does). The sphere
    case is left out: the writer stores centres as float32, where 1e39 is already inf."""
    from embree_rt.scene.writer import save_scene

    change, key = PYTHON_VALUES[case]
    scene = _lit_sphere()
    change(scene)
    with pytest.raises(SceneError) as in_python:
        scene.check()
    save_scene(scene, tmp_path / "s.toml")
    with pytest.raises(SceneError) as in_file:
        load_scene(tmp_path / "s.toml")
    assert in_python.value.key == in_file.value.key == key
    assert in_python.value.problem == in_file.value.problem


@pytest.mark.parametrize(
    ("field", "value", "problem"),
    [
        ("reflectivity", 1.5, "must be <= 1, got 1.5"),
        ("ambient", -0.25, "must be >= 0, got -0.25"),
        ("shininess", 0.0, "must be > 0, got 0"),
        ("ior", 0.5, "must be >= 1, got 0.5"),
        ("attenuation_distance", 0.0, "must be > 0, got 0"),
    ],
)
def test_a_materials_ranges_are_checked_by_the_material_and_named_by_a_file(
    tmp_path: Path, field: str, value: float, problem: str
) -> None:
    """``Material`` is the one place its ranges are checked: in Python a ``FieldError`` (a
    ValueError) naming the field, in a file the same words under the file's key, for a
    material and for the floor's (whose keys the floor's table holds)."""
    from embree_rt.errors import FieldError

    with pytest.raises(FieldError) as caught:
        Material(**{field: value})
    assert isinstance(caught.value, ValueError)
    assert (caught.value.field, caught.value.problem) == (field, problem)
    assert str(caught.value) == f"{field}: {problem}"
    for table, key in (("materials.odd", f"materials.odd.{field}"), ("floor", f"floor.{field}")):
        error = _load_error(tmp_path / "s.toml", f"[{table}]\n{field} = {value}\n")
        assert (error.key, error.problem) == (key, problem)


def test_python_built_values_at_the_limits_render_without_nan() -> None:
    from embree_rt.scene.limits import RADIANCE_LIMIT

    scene = _lit_sphere()
    scene.lights[0].intensity = RADIANCE_LIMIT
    scene.lights[0].color = (RADIANCE_LIMIT,) * 3
    scene.add_material("hot", Material(color=(RADIANCE_LIMIT,) * 3))
    scene.add_sphere((2.5, 1.0, 0.0), 1.0, "hot")
    image = render(scene, width=16, height=16, spp=1).image
    assert np.isfinite(image).all() and image.max() > 1e12


def test_a_scene_at_every_limit_renders_without_nan_or_inf(tmp_path: Path) -> None:
    """Colours and intensities at 1e6, lights and spheres at 1e10, a 1e-18 radius and floor
    square, an ior and shininess of 1e10, eight bounces: finite pixels, and bright ones."""
    (tmp_path / "limits.toml").write_text(LIMITS_SCENE)
    image = render(load_scene(tmp_path / "limits.toml")).image
    assert np.isfinite(image).all()
    assert image.max() > 1e12  # the 1e6 colours did reach the image


LIMITS_SCENE = """
[render]
width = 24
height = 16
spp = 2
max_depth = 8
[camera]
position = [0, 2, 8]
look_at = [0, 1, 0]
[background]
horizon = [1e6, 1e6, 1e6]
zenith = [1e6, 0, 1e6]
[materials.hot]
color = [1e6, 1e6, 1e6]
shininess = 1e10
ior = 1e10
transparency = 0.5
reflectivity = 0.5
specular = 1
diffuse = 1
[floor]
color_a = [1e6, 1e6, 1e6]
size = 1e-18
[[lights]]
position = [0, 1e10, 0]
intensity = 1e6
color = [1e6, 1e6, 1e6]
[[lights]]
position = [1e10, -1e10, 1e10]
intensity = 1e6
color = [1e6, 1e6, 1e6]
[[spheres]]
center = [0, 1, 0]
radius = 1
material = "hot"
[[spheres]]
center = [1e10, 1e10, -1e10]
radius = 1e10
material = "hot"
[[spheres]]
center = [1, 1, 1]
radius = 1e-18
material = "mirror"
"""


# -- a zip bomb --------------------------------------------------------------------------------


def test_a_sphere_array_too_large_for_memory_is_refused_from_its_headers(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The issue's bomb (3.7 MB of zip declaring 610 M spheres) scaled to a machine with 40 MB
    available: 400,000 spheres of zeros, 190 kB of zip, 12.8 MB of arrays, and 28.4 MB more for
    the scene and the BVH (71 bytes a sphere at least): 41.2 MB. The headers alone refuse it:
    nothing near the arrays' size is allocated. 50,000 spheres then load under that budget."""
    import tracemalloc

    from embree_rt import budget

    count = 400_000
    np.savez_compressed(tmp_path / "bomb.npz", centers=np.zeros((count, 3)), radii=np.ones(count))
    assert (tmp_path / "bomb.npz").stat().st_size < 300_000
    monkeypatch.setattr(budget, "available_memory", lambda: 40_000_000)
    path = tmp_path / "s.toml"
    path.write_text('[[sphere_arrays]]\nfile = "bomb.npz"\n')
    tracemalloc.start()
    try:
        with pytest.raises(SceneError) as caught:
            load_scene(path)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert caught.value.key == "sphere_arrays[0].file"
    assert "400,000 spheres would need ~0.0412 GB of memory" in caught.value.problem
    assert peak < 2_000_000  # the arrays alone are 12.8 MB
    count = 50_000
    np.savez_compressed(tmp_path / "bomb.npz", centers=np.zeros((count, 3)), radii=np.ones(count))
    assert len(load_scene(path).sphere_radii) == count


def test_any_archive_unpacking_beyond_memory_is_refused_from_its_headers(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Instance placements too: 200,000 (4, 4) float64 matrices are 25.6 MB unpacked."""
    from embree_rt import budget

    (tmp_path / "m.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    np.savez_compressed(tmp_path / "p.npz", transforms=np.zeros((200_000, 4, 4)))
    monkeypatch.setattr(budget, "available_memory", lambda: 20_000_000)
    path = tmp_path / "s.toml"
    path.write_text('[[instances]]\nmesh = "m.obj"\ntransforms = "p.npz"\n')
    error = _load_error(path, path.read_text())
    assert error.key == "instances[0].transforms"
    assert "its arrays would need ~0.0256 GB of memory" in error.problem


# -- integers beyond int64 ---------------------------------------------------------------------

BIG_INTEGERS = {
    "spp 1e29 (a float)": ("[render]\nspp = 1e29\n", "render.spp", "expected an integer"),
    "spp 10**29": (f"[render]\nspp = {10**29}\n", "render.spp", f"<= {2**63 - 1}"),
    "width 2**63": (f"[render]\nwidth = {2**63}\n", "render.width", "<= 9223372036854775807"),
    "2**64 samples": (
        f"[render]\nwidth = {2**32}\nheight = {2**16}\nspp = {2**16}\n",
        "render.spp",
        "1.84e+19 samples, more than",
    ),
    "seed 2**64": (f"[render]\nseed = {2**64}\n", "render.seed", f"<= {2**64 - 1}"),
    "field seed 2**64": (
        f"[random_field]\ncount = 5\nseed = {2**64}\n",
        "random_field.seed",
        "<= 18446744073709551615",
    ),
    "field count 10**30": (f"[random_field]\ncount = {10**30}\n", "random_field.count", "<="),
    "frames 10**30": (f"[animation]\nframes = {10**30}\norbit = 360\n", "animation.frames", "<="),
}


@pytest.mark.parametrize("case", sorted(BIG_INTEGERS))
def test_integers_beyond_int64_are_refused(tmp_path: Path, case: str) -> None:
    text, key, words = BIG_INTEGERS[case]
    error = _load_error(tmp_path / "s.toml", text)
    assert error.key == key
    assert words in error.problem


def test_the_command_refuses_spp_beyond_int64_in_a_file_in_one_line(tmp_path: Path) -> None:
    (tmp_path / "s.toml").write_text(f"[render]\nwidth = 16\nheight = 16\nspp = {10**29}\n")
    result = _run("render", "s.toml", "-o", "out.png", cwd=tmp_path)
    assert result.returncode == 2, result.stderr
    assert result.stderr.count("\n") == 1 and "s.toml: render.spp: must be <=" in result.stderr
    assert not (tmp_path / "out.png").exists()


def test_a_long_camera_path_is_checked_whole_and_bounded(tmp_path: Path) -> None:
    """Every frame's camera is checked (as arrays: a million frames in about a second, where a
    camera object a frame took minutes, and 10**12 frames never ended); past a million frames
    the path is refused."""
    keys = "keyframes = [{frame = 0, position = [0, 1, 5]}, {frame = 999999, position = [5, 1, 0]}]"
    path = tmp_path / "s.toml"
    path.write_text(f"[animation]\nframes = 1000000\n{keys}\n")
    assert load_scene(path).animation.frames == 1_000_000
    # Through look_at = [0, 0, 0] half way: the one frame where position meets it is found.
    keys = (
        "keyframes = [{frame = 0, position = [0, 0, -5]}, {frame = 999998, position = [0, 0, 5]}]"
    )
    error = _load_error(path, f"[animation]\nframes = 1000000\n{keys}\n")
    assert error.key == "animation.keyframes"
    assert error.problem.startswith("frame 499999's interpolated camera: look_at must differ")
    error = _load_error(path, "[animation]\nframes = 1000001\norbit = 360\n")
    assert error.key == "animation.frames" and "<= 1000000" in error.problem


def test_no_warning_is_printed_before_the_one_line_error(tmp_path: Path) -> None:
    """A keyframe at 1e308 once printed NumPy's RuntimeWarnings (overflow in the spline) before
    its error; an OBJ vertex at 1e39 those of the float32 cast. Now: the one line alone."""
    (tmp_path / "far.obj").write_text("v 0 0 0\nv 1e39 0 0\nv 0 1 0\nf 1 2 3\n")
    (tmp_path / "mesh.toml").write_text('[[meshes]]\nfile = "far.obj"\n')
    (tmp_path / "keys.toml").write_text(
        "[animation]\nframes = 10\nkeyframes = [{frame = 0, position = [0, 1, 5]}, "
        "{frame = 9, position = [1e308, 1, 0]}]\n"
    )
    for name, key in (("mesh.toml", "meshes[0].file"), ("keys.toml", "keyframes[1].position")):
        result = _run("render", name, "-o", "out.png", cwd=tmp_path)
        assert result.returncode == 2
        assert result.stderr.startswith("embree-rt: error: ") and result.stderr.count("\n") == 1
        assert key in result.stderr


# -- paths the operating system refuses ---------------------------------------------------------


def _mesh_scene(folder: Path, name: str) -> Path:
    """A scene whose seventh mesh names ``name`` (the six before it fine)."""
    (folder / "tri.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    lines = ["[[lights]]\nposition = [0, 5, 0]\n"]
    lines += ['[[meshes]]\nfile = "tri.obj"\n'] * 6
    lines.append(f"[[meshes]]\nfile = {json.dumps(name)}\n")
    scene = folder / "scene.toml"
    scene.write_text("".join(lines))
    return scene


def _main(folder: Path, *args: str) -> tuple[int, str]:
    """The command run in this process from ``folder`` (as a subprocess would, quicker): its
    exit code and stderr."""
    import contextlib
    import io

    from embree_rt.cli import main

    stderr = io.StringIO()
    previous = Path.cwd()
    os.chdir(folder)
    try:
        with contextlib.redirect_stderr(stderr):
            code = main(list(args))
    finally:
        os.chdir(previous)
    return code, stderr.getvalue()


def _make_fifo(folder: Path, name: str) -> str:
    os.mkfifo(folder / name)
    return name


def _make_directory(folder: Path, name: str) -> str:
    (folder / name).mkdir()
    return name


def _make_symlink_loop(folder: Path, name: str) -> str:
    (folder / name).symlink_to(name)
    return name


# case: (what makes the path in a folder and returns the name the scene gives, the problem)
UNREADABLE_PATHS = {
    "over-long name": (lambda folder, name: "m" * 300 + ".obj", "the name is too long"),
    "directory": (_make_directory, "is a directory, not a file"),
    "FIFO": (_make_fifo, "is a FIFO (named pipe), not a file"),
    "symlink loop": (_make_symlink_loop, "a loop of symbolic links"),
    "a file in the path": (lambda folder, name: "tri.obj/x.obj", "not a directory"),
}


@pytest.mark.parametrize("case", sorted(UNREADABLE_PATHS))
def test_an_unreadable_mesh_path_is_one_line_naming_its_key(tmp_path: Path, case: str) -> None:
    make, problem = UNREADABLE_PATHS[case]
    name = make(tmp_path, "bad.obj")
    scene = _mesh_scene(tmp_path, name)
    result = _run(
        "render", scene.name, "-o", "out.png", "--width", "8", "--height", "8", cwd=tmp_path
    )
    assert result.returncode == 2, result.stderr
    assert result.stderr.count("\n") == 1 and "Traceback" not in result.stderr, result.stderr
    assert result.stderr.startswith("embree-rt: error: scene.toml: meshes[6].file: ")
    assert problem in result.stderr
    assert not (tmp_path / "out.png").exists()


@pytest.mark.parametrize("case", ["directory", "FIFO", "symlink loop", "over-long name"])
def test_a_scene_or_mesh_file_argument_that_is_no_file_is_one_line(
    tmp_path: Path, case: str
) -> None:
    make, problem = UNREADABLE_PATHS[case]
    for suffix in (".toml", ".obj"):
        name = make(tmp_path, "given" + suffix)
        code, stderr = _main(tmp_path, "render", name, "-o", "out.png")
        assert code == 2, stderr
        # the problem's words, then (an over-long name) its lengths, on the one line
        assert stderr.startswith(f"embree-rt: error: {name}: (file): {problem}"), stderr
        assert stderr.count("\n") == 1 and stderr.endswith("\n"), stderr


def test_a_file_without_read_permission_is_said_so(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The tests may run as root, whom no mode bit stops: the permission is taken from
    ``os.access``, as the check asks it."""
    from embree_rt.scene import paths

    scene = _mesh_scene(tmp_path, "locked.obj")
    (tmp_path / "locked.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    real_access = os.access
    monkeypatch.setattr(
        paths.os, "access", lambda path, mode: "locked" not in str(path) and real_access(path, mode)
    )
    error = _load_error(scene, scene.read_text())
    assert error.key == "meshes[6].file"
    assert error.problem == f"{tmp_path / 'locked.obj'}: no permission to read it"


@pytest.mark.parametrize("case", ["FIFO", "symlink loop"])
def test_an_output_that_is_no_file_is_refused_and_left_alone(tmp_path: Path, case: str) -> None:
    make, problem = UNREADABLE_PATHS[case]
    name = make(tmp_path, "out.png")
    scene = ROOT / "scenes" / "three_spheres.toml"
    code, stderr = _main(tmp_path, "render", str(scene), "-o", name, "--width", "8")
    assert code == 2, stderr
    assert stderr == f"embree-rt: error: {name}: {problem}\n"
    assert not (tmp_path / name).is_file()  # the FIFO or the link is still there, not replaced
    assert (tmp_path / name).is_symlink() or (tmp_path / name).is_fifo()


# case: (what makes the output path in a folder and returns it, the problem)
OUTPUT_PATHS = {
    "a directory": (lambda folder: _make_directory(folder, "out.png"), "out.png: is a directory"),
    "over-long name": (lambda folder: "o" * 300 + ".png", "name too long"),
    "over-long folder": (lambda folder: "o" * 300 + "/out.png", "name too long"),
    "a FIFO as its folder": (
        lambda folder: _make_fifo(folder, "pipe") + "/out.png",
        "out.png: pipe is not a directory",
    ),
    "a loop in the path": (
        lambda folder: _make_symlink_loop(folder, "loop") + "/out.png",
        "out.png: Too many levels of symbolic links",
    ),
}


@pytest.mark.parametrize("case", sorted(OUTPUT_PATHS))
def test_an_output_path_the_os_refuses_is_one_line_before_any_work(
    tmp_path: Path, case: str
) -> None:
    make, problem = OUTPUT_PATHS[case]
    name = make(tmp_path)
    before = sorted(tmp_path.iterdir())
    scene = ROOT / "scenes" / "three_spheres.toml"
    code, stderr = _main(tmp_path, "render", str(scene), "-o", name, "--width", "8")
    assert code == 2, stderr
    assert stderr.startswith(f"embree-rt: error: {name}: ") and stderr.count("\n") == 1, stderr
    assert problem.lower() in stderr.lower(), stderr
    assert sorted(tmp_path.iterdir()) == before


def _file_as_folder(folder: Path) -> str:
    (folder / "f").write_text("")
    return "f/s.toml"


# case: (what makes the path in a folder and returns --save-scene's value, the path the line
# names, its problem)
SAVED_SCENE_PATHS = {
    "a directory": (lambda f: _make_directory(f, "s.toml"), "s.toml", "is a directory, not a file"),
    "a FIFO": (lambda f: _make_fifo(f, "s.toml"), "s.toml", "is a FIFO (named pipe), not a file"),
    "a FIFO where its spheres go": (
        lambda f: _make_fifo(f, "s.spheres.npz").replace(".spheres.npz", ".toml"),
        "s.spheres.npz",
        "is a FIFO (named pipe), not a file",
    ),
    "a loop of links": (
        lambda f: _make_symlink_loop(f, "s.toml"),
        "s.toml",
        "a loop of symbolic links",
    ),
    "a file as its folder": (_file_as_folder, "f/s.toml", "f is not a directory"),
    "over-long name": (lambda f: "s" * 300 + ".toml", "s" * 300 + ".toml", "the name is too long"),
}


@pytest.mark.parametrize("case", sorted(SAVED_SCENE_PATHS))
def test_a_save_scene_path_the_os_refuses_is_one_line_before_any_work(
    tmp_path: Path, case: str
) -> None:
    """Refused before the field is made: nothing written, not even the spheres beside it, and
    no write left waiting on a FIFO for a reader."""
    make, named, problem = SAVED_SCENE_PATHS[case]
    given = make(tmp_path)
    before = sorted(tmp_path.iterdir())
    # a reader on each FIFO: a write that got past the check fails the test, not hangs it
    readers = [os.open(p, os.O_RDONLY | os.O_NONBLOCK) for p in before if p.is_fifo()]
    try:
        code, stderr = _main(
            tmp_path,
            "random",
            "--count",
            "10",
            "--save-scene",
            given,
            "-o",
            "out.png",
            "--width",
            "8",
        )
    finally:
        for reader in readers:
            os.close(reader)
    assert code == 2, stderr
    assert stderr.startswith(f"embree-rt: error: --save-scene: {named}: {problem}"), stderr
    assert stderr.count("\n") == 1, stderr
    assert sorted(tmp_path.iterdir()) == before


def _without_permission_overrides() -> list[str]:
    """What runs a command under the file modes: as root, whom no mode bit stops, the command
    runs without the capabilities that let root past them (util-linux's setpriv drops them from
    the bounding set, so the process root's ``exec`` makes never has them); otherwise as is."""
    if os.geteuid() != 0:
        return []
    return [shutil.which("setpriv"), "--bounding-set=-dac_override,-dac_read_search"]


def test_paths_without_permission_are_one_line_naming_them(tmp_path: Path) -> None:
    """A scene, a mesh it names and an output's folder the modes forbid, each refused in one
    line before any work. Real modes (not a stand-in for the check): root runs the command
    without its capabilities to pass them."""
    scene = _mesh_scene(tmp_path, "locked.obj")
    locked = tmp_path / "locked.obj"
    locked.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    shut = tmp_path / "shut"
    shut.mkdir()
    unreadable_scene = tmp_path / "unreadable.toml"
    unreadable_scene.write_text("[[lights]]\nposition = [0, 5, 0]\n")
    cases = [
        (scene, "out.png", f"scene.toml: meshes[6].file: {locked}: no permission to read it"),
        (unreadable_scene, "out.png", "unreadable.toml: (file): no permission to read it"),
        (scene, "shut/out.png", "shut/out.png: directory shut is not writable"),
    ]
    for path, mode in ((locked, 0o000), (unreadable_scene, 0o000), (shut, 0o500)):
        path.chmod(mode)
    try:
        command = [*_without_permission_overrides(), sys.executable, "-m", "embree_rt", "render"]
        for given, output, problem in cases:
            result = subprocess.run(
                [*command, given.name, "-o", output, "--width", "8", "--height", "8"],
                capture_output=True,
                text=True,
                timeout=300,
                cwd=tmp_path,
            )
            assert result.returncode == 2, result.stderr
            assert result.stderr == f"embree-rt: error: {problem}\n"
            assert not (tmp_path / output).exists() and list(shut.iterdir()) == []
    finally:
        for path in (locked, unreadable_scene, shut):
            path.chmod(0o700)


def test_a_ply_whose_vertices_overflow_its_float_type_is_one_line(tmp_path: Path) -> None:
    """trimesh casts a PLY's 1e308 to the float32 the file declares: NumPy's overflow warning
    is caught where it happens, and the one error line says what it meant."""
    (tmp_path / "far.ply").write_text(
        "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
        "property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n"
        "0 0 0\n1e308 0 0\n0 1 0\n3 0 1 2\n"
    )
    (tmp_path / "scene.toml").write_text('[[meshes]]\nfile = "far.ply"\n')
    for name, key in (("scene.toml", "scene.toml: meshes[0].file: "), ("far.ply", "far.ply: ")):
        result = _run("render", name, "-o", "out.png", cwd=tmp_path)
        assert result.returncode == 2, result.stderr
        assert result.stderr.count("\n") == 1, result.stderr  # no RuntimeWarning before it
        assert result.stderr.startswith(f"embree-rt: error: {key}")
        assert "values beyond the range of the file's number type" in result.stderr
        assert not (tmp_path / "out.png").exists()


def test_a_mesh_file_placed_beyond_float32_geometry_is_bad_input_not_a_bug(tmp_path: Path) -> None:
    """A mesh file rendered on its own is held to the limits a scene file's mesh is."""
    (tmp_path / "far.ply").write_text(
        "ply\nformat ascii 1.0\nelement vertex 3\nproperty double x\nproperty double y\n"
        "property double z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n"
        "0 0 0\n1e308 0 0\n0 1 0\n3 0 1 2\n"
    )
    result = _run("render", "far.ply", "-o", "out.png", cwd=tmp_path)
    assert result.returncode == 2, result.stderr
    assert result.stderr.startswith("embree-rt: error: far.ply: (file): ")
    assert "beyond the" in result.stderr and result.stderr.count("\n") == 1
