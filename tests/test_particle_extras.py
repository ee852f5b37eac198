"""A particle file's box, bonds and legend as a scene file's ``[[particles]]`` keys: each
renders the image its command-line flag renders, bit for bit (both are read from one
description, ``ParticleExtras``, into the same ``Scene.add_particles`` call, and the scene
file is given the camera, lights and floor the command frames the particles with, so the two
renders trace the same scene); bad values are one line naming the file and key, exit 2."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import gsd.hoomd
import numpy as np
import pytest
import tomli_w

from embree_rt.cli import main
from embree_rt.particle_extras import EXTRA_OPTIONS, ParticleExtras, is_switch
from embree_rt.scene.model import Scene
from embree_rt.scene.particles.to_scene import extras_arguments
from embree_rt.scene.views import clear_of_legend
from embree_rt.scene.writer import look_document, plain_values

SIZE = ["--width", "120", "--height", "90", "--spp", "1", "--quiet"]


def write_chain(path: Path) -> None:
    """Four particles of two types in a zig-zag, three bonds and a box, written by gsd."""
    frame = gsd.hoomd.Frame()
    positions = [[0.0, 0.0, 0.0], [1.6, 0.0, 0.0], [2.4, 1.4, 0.0], [4.0, 1.4, 0.5]]
    frame.particles.N = len(positions)
    frame.particles.position = np.array(positions, np.float32)
    frame.particles.types = ["A", "B"]
    frame.particles.typeid = np.array([0, 1, 0, 1], np.uint32)
    frame.configuration.box = [7.0, 5.0, 4.0, 0.0, 0.0, 0.0]
    frame.bonds.N = 3
    frame.bonds.types = ["backbone"]
    frame.bonds.typeid = np.zeros(3, np.uint32)
    frame.bonds.group = np.array([[0, 1], [1, 2], [2, 3]], np.uint32)
    with gsd.hoomd.open(str(path), "w") as trajectory:
        trajectory.append(frame)


def flags_of(keys: dict) -> list[str]:
    """The command-line flags of ``[[particles]]`` ``keys``."""
    flags = []
    for name, value in keys.items():
        flag = "--" + name.replace("_", "-")
        flags += [flag] if value is True else [flag, str(value)]
    return flags


CASES = [
    ({"box": True, "legend": True}, ".toml"),
    ({"bonds": True}, ".json"),
    ({"bonds": True, "bond_radius": 0.12}, ".toml"),
    ({"licorice": True, "bond_radius": 0.3}, ".toml"),
]


@pytest.mark.parametrize(
    ("keys", "suffix"), CASES, ids=["+".join(keys) + suffix for keys, suffix in CASES]
)
def test_scene_file_keys_render_what_the_flags_render(tmp_path, keys, suffix):
    write_chain(tmp_path / "chain.gsd")
    assert main(["render", str(tmp_path / "chain.gsd"), "-o", str(tmp_path / "flags.png"),
                 *flags_of(keys), *SIZE]) == 0  # fmt: skip
    # The camera, lights and floor the command frames these particles with, drawn as asked:
    # with a legend, the framing moved clear of its corner at the image's size.
    extras = ParticleExtras(**keys)
    framed = Scene.from_particles(tmp_path / "chain.gsd", **extras_arguments(extras))
    framed.render.width, framed.render.height = int(SIZE[1]), int(SIZE[3])
    framed.camera = clear_of_legend(framed, framed.legend)
    document = {**look_document(framed), "particles": [{"file": "chain.gsd", **keys}]}
    scene = tmp_path / f"s{suffix}"
    write = json.dumps if suffix == ".json" else tomli_w.dumps
    scene.write_text(write(plain_values(document)))
    assert main(["render", str(scene), "-o", str(tmp_path / "file.png"), *SIZE]) == 0
    flags_image = (tmp_path / "flags.png").read_bytes()
    assert flags_image == (tmp_path / "file.png").read_bytes()
    # ... and the extras show: the image differs from the plain particles'.
    assert main(["render", str(tmp_path / "chain.gsd"), "-o", str(tmp_path / "plain.png"),
                 *SIZE]) == 0  # fmt: skip
    assert flags_image != (tmp_path / "plain.png").read_bytes()


def test_every_option_is_a_key_and_a_flag():
    """The description's every field is read by both (a new field cannot be left out of one)."""
    from embree_rt.cli.parser import build_parser

    render = build_parser()._subparsers._group_actions[0].choices["render"]
    flags = {action.dest: action for action in render._actions}
    for option in EXTRA_OPTIONS:
        assert flags[option.name].default == option.default
        assert (flags[option.name].nargs == 0) == is_switch(option)
    assert {option.name for option in EXTRA_OPTIONS} == {
        field.name for field in dataclasses.fields(ParticleExtras)
    }


@pytest.mark.parametrize(
    ("entry", "problem"),
    [
        ("bond_radius = -0.5\nbonds = true", "particles[0].bond_radius: must be > 0, got -0.5"),
        ("bond_radius = 0.2", "particles[0].bond_radius: sets the sticks' radius, so it needs"),
        ('bonds = "yes"', "particles[0].bonds: expected true or false, got 'yes'"),
        ("legend = 1", "particles[0].legend: expected true or false, got 1"),
        ("bond_radious = 0.2", "bond_radious"),
        ('legend = true\n[[particles]]\nfile = "chain.gsd"\nlegend = true',
         "particles[1].legend: another [[particles]] entry has the legend already"),
    ],
)  # fmt: skip
def test_bad_values_one_line_exit_2_nothing_written(tmp_path, capsys, entry, problem):
    write_chain(tmp_path / "chain.gsd")
    scene = tmp_path / "s.toml"
    scene.write_text(f'[[particles]]\nfile = "chain.gsd"\n{entry}\n')
    assert main(["render", str(scene), "-o", str(tmp_path / "o.png"), *SIZE]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and str(scene) in lines[0] and problem in lines[0], lines
    assert not (tmp_path / "o.png").exists()
