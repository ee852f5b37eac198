"""Changes to a scene's keys given on the command line (``--set camera.fov=35``, and the flags
that are shortcuts for one: ``--width 32`` is ``--set render.width=32``).

A setting names a key by its path in the scene file's schema, as the loader's messages name it
(``render.max_depth``, ``lights[0].intensity``, ``materials.gold.shininess``), and is applied to
the parsed document before the loader checks it: a value set is checked by the very rules, and
refused with the very messages, that the same value written in the file meets, an unknown key
included ("did you mean"). A scene made without a document (a mesh file on its own, a random
field) is written as a document of its settable tables first (``apply_to_scene``).
"""

from __future__ import annotations

import re
import sys
from dataclasses import replace
from pathlib import Path
from typing import NamedTuple

import numpy as np

from embree_rt.scene.errors import SceneError, unknown_key_message
from embree_rt.scene.loader import SceneReader, read_document
from embree_rt.scene.model import Scene

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

# The tables of a scene that a setting can change when the scene was not read from a file.
SETTABLE_TABLES = ("render", "camera", "background", "lights", "floor", "materials", "animation")
_STEP = re.compile(r"([A-Za-z_][A-Za-z0-9_-]*)((?:\[\d+\])*)")


class Setting(NamedTuple):
    """A scene key to set: ``key`` its path, ``value`` the value (as TOML gives it), ``origin``
    how the user wrote it (``--set camera.fov=35``, ``--width 32``), for messages."""

    key: str
    value: object
    origin: str


def parse_value(text: str) -> object:
    """``text`` read as a TOML value (``35``, ``2.5``, ``true``, ``[0, 1, 5]``, ``"gold"``),
    or, when it is not one, the string itself (``gold``)."""
    try:
        return tomllib.loads(f"value = {text}")["value"]
    except tomllib.TOMLDecodeError:
        return text


def parse_assignment(text: str) -> Setting:
    """A ``--set`` argument ``KEY=VALUE`` as a Setting; ValueError unless it has a key and
    an ``=``."""
    key, equals, value = text.partition("=")
    if not equals or not key.strip():
        raise ValueError(f"expected KEY=VALUE (e.g. camera.fov=35), got {text!r}")
    key_steps(key.strip())
    return Setting(key.strip(), parse_value(value.strip()), f"--set {text}")


def key_steps(key: str) -> list[str | int]:
    """``lights[0].intensity`` → ``["lights", 0, "intensity"]``; ValueError for a path the
    scene schema cannot hold."""
    steps: list[str | int] = []
    for part in key.split("."):
        match = _STEP.fullmatch(part)
        if match is None:
            raise ValueError(f"{key!r} is not a key path (e.g. camera.fov, lights[0].intensity)")
        steps.append(match.group(1))
        steps += [int(index) for index in re.findall(r"\[(\d+)\]", match.group(2))]
    return steps


def apply_setting(document: dict, setting: Setting) -> None:
    """Set ``setting`` in the parsed scene ``document``, making the tables on its path that are
    missing; SceneError naming the setting for a path through a value that is not a table, or
    an index past a list's end."""
    steps = key_steps(setting.key)
    here: object = document
    walked = ""
    for step, following in zip(steps, [*steps[1:], None], strict=True):
        name = (
            f"{walked}[{step}]"
            if isinstance(step, int)
            else (f"{walked}.{step}" if walked else step)
        )
        if isinstance(step, int):
            if not isinstance(here, list):
                raise SceneError(setting.origin, walked, "is not a list: no index to take")
            if step >= len(here):
                count = f"{len(here)} entr{'y' if len(here) == 1 else 'ies'}"
                raise SceneError(setting.origin, name, f"no such entry: {walked} has {count}")
        elif isinstance(here, list):
            raise SceneError(setting.origin, walked, f"is a list: name an entry, {walked}[0]")
        elif not isinstance(here, dict):
            raise SceneError(setting.origin, walked, f"is {here!r}, not a table of keys")
        if following is None:
            here[step] = setting.value
            return
        if isinstance(step, str) and step not in here:
            here[step] = [] if isinstance(following, int) else {}
        here = here[step]
        walked = name


def blamed(error: SceneError, settings: list[Setting]) -> SceneError:
    """``error`` as the loader raised it, said of the last setting that made its key (the key
    itself, a table holding it, or a key inside it), or as it was when no setting did."""
    for setting in reversed(settings):
        key = setting.key
        if (
            key == error.key
            or key.startswith((f"{error.key}.", f"{error.key}["))
            or error.key.startswith((f"{key}.", f"{key}["))
        ):
            return SceneError(setting.origin, error.key, error.problem)
    return error


def load_scene_with(path: str | Path, settings: list[Setting]) -> Scene:
    """``load_scene(path)`` with ``settings`` applied to the file's document before it is
    checked. Raises SceneError: the loader's message, naming the setting that caused it."""
    path = Path(path)
    document = read_document(path)
    for setting in settings:
        apply_setting(document, setting)
    try:
        return SceneReader(path, document).build()
    except SceneError as error:
        raise blamed(error, settings) from None


def apply_to_scene(scene: Scene, settings: list[Setting], made_from: str) -> None:
    """Apply ``settings`` to ``scene``, made without a scene file (``made_from`` says from what,
    for messages): its ``SETTABLE_TABLES`` written as a document as ``save_scene`` writes them,
    set, checked by the loader, and the tables set taken back into ``scene``."""
    if not settings:
        return
    from embree_rt.scene.writer import scene_document

    tables = []
    for setting in settings:
        top = key_steps(setting.key)[0]
        if top not in SETTABLE_TABLES:
            raise SceneError(
                setting.origin,
                str(top),
                f"not settable on {made_from}: " + unknown_key_message(str(top), SETTABLE_TABLES),
            )
        tables.append(top)
    bare = replace(
        scene,
        sphere_centers=np.zeros((0, 3), np.float32),
        sphere_radii=np.zeros(0, np.float32),
        sphere_materials=np.zeros(0, np.int32),
        meshes=[],
        instances=[],
    )
    written = scene_document(bare, Path(made_from))
    # the camera always: an animation is read against it
    document = {name: written[name] for name in {"render", "camera", *tables} if name in written}
    for setting in settings:
        apply_setting(document, setting)
    try:
        made = SceneReader(Path(made_from), document).scene
    except SceneError as error:
        raise blamed(error, settings) from None
    for name in dict.fromkeys(tables):
        setattr(scene, name, getattr(made, name))
