"""Property-based fuzzing of the scene loader (Hypothesis, derandomized and bounded).

For any document, plausible or hostile, as JSON or TOML: loading gives a scene, or raises
``SceneError`` with a one-line message, never another exception and never a NumPy warning; a
share of the scenes that load are rendered at 16x16 and must hold no NaN or inf. The worst cases
of issue 26 are pinned as examples.
"""

from __future__ import annotations

import json
import math
import warnings
from pathlib import Path

import numpy as np
import pytest
import trimesh
from hypothesis import HealthCheck, event, example, given, settings
from hypothesis import strategies as st

from embree_rt import load_scene, render
from embree_rt.scene import SceneError

NAMES = [
    "box.obj",
    "far.obj",
    "spheres.npz",
    "huge.npz",
    "placements.npz",
    "missing.obj",
    "a\nb.obj",
    "a\x00b.npz",
    "../spheres.npz",
    "",
    "box.fbx",
]
MATERIALS = ["matte", "glass", "mirror", "metal", "red", "nope", ""]
HOSTILE = [
    0,
    -1,
    1,
    0.5,
    180,
    1e-7,
    1e-18,
    1e-320,
    1e6,
    2e6,
    1e10,
    1e39,
    -1e39,
    1e308,
    math.nan,
    math.inf,
    -math.inf,
    2**63,
    2**64,
    10**400,
    -(10**400),
]

numbers = st.one_of(
    st.sampled_from(HOSTILE),
    st.integers(-100, 100),
    st.floats(-20, 20),
    st.floats(allow_nan=True, allow_infinity=True),
)
small = st.floats(-5, 5, allow_nan=False)
scalars = st.one_of(
    numbers, st.booleans(), st.none(), st.text(max_size=6), st.sampled_from(NAMES + MATERIALS)
)
anything = st.recursive(
    scalars,
    lambda inner: (
        st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=4), inner, max_size=3)
    ),
    max_leaves=8,
)
vectors = st.lists(small, min_size=3, max_size=3) | st.lists(numbers, min_size=3, max_size=3)
counts = st.integers(0, 12) | st.sampled_from([-3, 2.5, 2**63, 10**400, 10**13, "many"])


def mostly(plausible: st.SearchStrategy, hostile: st.SearchStrategy) -> st.SearchStrategy:
    """``plausible`` seven times in eight, else ``hostile``: a document has tens of values,
    and enough of them must load to render."""
    return st.integers(0, 7).flatmap(lambda n: hostile if n == 0 else plausible)


PLAUSIBLE = {
    **dict.fromkeys(["position", "look_at", "up", "center", "translate", "rotate"], vectors),
    **dict.fromkeys(
        ["color", "horizon", "zenith", "color_a", "color_b"],
        mostly(st.lists(st.floats(0, 2), min_size=3, max_size=3), vectors),
    ),
    **dict.fromkeys(
        ["radius", "intensity", "size", "height", "extent", "orbit"],
        mostly(st.floats(0.05, 4), numbers),
    ),
    **dict.fromkeys(
        ["ambient", "diffuse", "specular", "reflectivity", "transparency"],
        mostly(st.floats(0, 1), numbers),
    ),
    "fov": mostly(st.floats(10, 120), numbers),
    "shininess": mostly(st.floats(1, 200), numbers),
    "ior": mostly(st.floats(1, 2.5), numbers),
    **dict.fromkeys(
        ["width", "height", "spp", "max_depth", "seed", "frames", "frame"],
        mostly(st.integers(1, 12), counts),
    ),
    "count": mostly(st.integers(1, 40), counts),
    **dict.fromkeys(["file", "mesh", "transforms"], st.sampled_from(NAMES)),
    **dict.fromkeys(["material", "preset"], st.sampled_from(MATERIALS)),
    **dict.fromkeys(["smooth", "metallic", "heroes"], st.booleans()),
    "scale": st.floats(0.1, 3) | vectors | numbers,
    "transform": st.just([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]])
    | st.lists(st.lists(numbers, min_size=4, max_size=4), min_size=4, max_size=4),
    "mix": st.dictionaries(
        st.sampled_from(["matte", "glass", "metal", "mtal"]), numbers, max_size=2
    ),
}


def table(*keys: str, required: tuple[str, ...] = ()) -> st.SearchStrategy[dict]:
    """A table of some of ``keys`` (always the ``required`` ones) with plausible or hostile
    values, now and then a stranger."""
    values = {key: mostly(PLAUSIBLE.get(key, numbers), anything) for key in keys}
    known = st.fixed_dictionaries({key: values.pop(key) for key in required}, optional=values)
    return mostly(
        known,
        st.builds(
            lambda d, extra: {**d, **extra},
            known,
            st.dictionaries(st.text(max_size=5), anything, max_size=1),
        ),
    )


MATERIAL_KEYS = [
    "preset",
    "color",
    "ambient",
    "diffuse",
    "specular",
    "reflectivity",
    "transparency",
    "shininess",
    "ior",
    "metallic",
]
documents = st.fixed_dictionaries(
    {},
    optional={
        "render": table("width", "height", "spp", "max_depth", "seed"),
        "camera": table("position", "look_at", "up", "fov"),
        "background": table("horizon", "zenith"),
        "lights": st.lists(
            table("position", "color", "intensity", required=("position",)), max_size=3
        ),
        "materials": st.dictionaries(
            st.sampled_from(["red", "hot"]), table(*MATERIAL_KEYS), max_size=2
        ),
        "floor": st.booleans()
        | table("height", "color_a", "color_b", "size", "preset", "diffuse", "reflectivity"),
        "spheres": st.lists(
            table("center", "radius", "material", required=("center", "radius")), max_size=4
        ),
        "sphere_arrays": st.lists(table("file", "material", required=("file",)), max_size=2),
        "meshes": st.lists(
            table(
                "file",
                "material",
                "smooth",
                "scale",
                "translate",
                "rotate",
                "transform",
                required=("file",),
            ),
            max_size=2,
        ),
        "instances": st.lists(
            table("mesh", "transforms", "material", "smooth", required=("mesh", "transforms")),
            max_size=1,
        ),
        "random_field": st.fixed_dictionaries(
            {"count": PLAUSIBLE["count"]},
            optional={key: PLAUSIBLE[key] for key in ("seed", "extent", "radius", "mix", "heroes")},
        ),
        "animation": st.fixed_dictionaries(
            {"frames": PLAUSIBLE["frames"]},
            optional={
                "orbit": numbers,
                "keyframes": st.lists(
                    table("frame", "position", "look_at", "fov", required=("frame",)), max_size=3
                ),
            },
        ),
    },
)


def toml_text(document: dict) -> str:
    """``document`` as TOML: one ``key = value`` line a top-level key, inline tables and arrays
    below (TOML has no null: None values are left out)."""

    def value(item) -> str:
        if isinstance(item, bool):
            return "true" if item else "false"
        if isinstance(item, int):
            return str(item)
        if isinstance(item, float):
            return (
                "nan"
                if math.isnan(item)
                else {math.inf: "inf", -math.inf: "-inf"}.get(item, repr(item))
            )
        if isinstance(item, str):
            return json.dumps(item)
        if isinstance(item, list):
            return "[" + ", ".join(value(x) for x in item if x is not None) + "]"
        pairs = (f"{json.dumps(k)} = {value(v)}" for k, v in item.items() if v is not None)
        return "{" + ", ".join(pairs) + "}"

    return "".join(f"{json.dumps(k)} = {value(v)}\n" for k, v in document.items() if v is not None)


def _documents_as_text(document: dict, as_toml: bool) -> tuple[str, str]:
    if as_toml:
        return "scene.toml", toml_text(document)
    return "scene.json", json.dumps(document)


scene_texts = st.builds(_documents_as_text, documents, st.booleans())


@pytest.fixture(scope="module")
def folder(tmp_path_factory) -> Path:
    """The files fuzzed documents may name: a box, a mesh at 1e39, sphere arrays (one beyond
    float32), instance placements."""
    folder = tmp_path_factory.mktemp("fuzz")
    trimesh.creation.box().export(folder / "box.obj")
    (folder / "far.obj").write_text("v 0 0 0\nv 1e39 0 0\nv 0 1 0\nf 1 2 3\n")
    np.savez(
        folder / "spheres.npz",
        centers=[[0, 1, 0], [2, 1, 0]],
        radii=[1.0, 0.5],
        materials=np.array(["glass", "mirror"]),
    )
    np.savez(folder / "huge.npz", centers=[[0, 1, 0], [1e308, 1, 0]], radii=[1.0, 1e-320])
    np.savez(folder / "placements.npz", positions=[[0, 0, 0], [3, 0, 0]])
    return folder


def _check(folder: Path, name: str, text: str, render_it: bool) -> str:
    """Load (and render) the document; the outcome: "refused", "loaded" or "rendered"."""
    path = folder / name
    path.write_text(text, encoding="utf-8", errors="surrogatepass")
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)  # noise before an error is a failure too
        try:
            scene = load_scene(path)
        except SceneError as error:
            message = str(error)
            assert "\n" not in message and "\r" not in message and "\x00" not in message
            assert message.startswith(str(path) + ": ")
            return "refused"
        if not render_it:
            return "loaded"
        image = render(scene, width=16, height=16, spp=1, max_depth=3, threads=1).image
        assert image.shape == (16, 16, 3)
        assert np.isfinite(image).all()
        return "rendered"


WORST = [
    ("scene.toml", "a = " + "[" * 600 + "]" * 600),
    ("scene.json", '{"a": ' + "[" * 100_000 + "]" * 100_000 + "}"),
    ("scene.toml", "[render]\nspp = " + "1" * 4400),
    ("scene.toml", "[[spheres]]\ncenter = [0, 1, 0]\nradius = 1" + "0" * 400),
    ("scene.toml", '[[meshes]]\nfile = "a\\u0000b.obj"'),
    ("scene.toml", '[render]\n"wid\\nth" = 3'),
    ("scene.toml", "[[spheres]]\ncenter = [1e39, 1, 0]\nradius = 1"),
    ("scene.toml", "[[lights]]\nposition = [0, 5, 0]\nintensity = 1e39"),
    ("scene.toml", '[[sphere_arrays]]\nfile = "huge.npz"'),
    ("scene.toml", '[[meshes]]\nfile = "far.obj"'),
    ("scene.toml", "[render]\nspp = 100000000000000000000000000000"),
    (
        "scene.toml",
        "[animation]\nframes = 10\nkeyframes = [{frame = 0}, "
        "{frame = 9, position = [1e308, 1, 0]}]",
    ),
    ("scene.toml", "[animation]\nframes = 1000000000000\norbit = 360"),
]


def _pin(cases):
    def decorate(test):
        for name, text in reversed(cases):
            test = example(case=(name, text), render_it=True)(test)
        return test

    return decorate


@settings(
    max_examples=150,
    deadline=None,
    derandomize=True,
    database=None,
    suppress_health_check=[
        HealthCheck.too_slow,
        HealthCheck.data_too_large,
        HealthCheck.function_scoped_fixture,
    ],
)
@_pin(WORST)
@given(case=scene_texts, render_it=st.integers(0, 9).map(lambda n: n == 0))
def test_any_document_loads_or_is_one_scene_error(folder: Path, case, render_it: bool) -> None:
    name, text = case
    event(_check(folder, name, text, render_it))  # --hypothesis-show-statistics counts them


def test_a_lit_scene_at_the_limits_renders_from_both_formats(folder: Path) -> None:
    """The generator's plausible side reaches renders: one by hand, through both writers."""
    document = {
        "spheres": [{"center": [0, 1, 0], "radius": 1, "material": "glass"}],
        "lights": [{"position": [0, 1e10, 0], "intensity": 1e6, "color": [1e6, 1e6, 1e6]}],
        "sphere_arrays": [{"file": "spheres.npz"}],
        "instances": [{"mesh": "box.obj", "transforms": "placements.npz"}],
    }
    for as_toml in (False, True):
        name, text = _documents_as_text(document, as_toml)
        assert _check(folder, name, text, render_it=True) == "rendered"
        assert len(load_scene(folder / name).sphere_radii) == 3
