"""A trajectory's legend (``--legend`` over frames): every frame carries the first frame's
legend, every frame is coloured on its range (so the legend tells the truth on each), and a
video's frames carry it as the PNG frames do, and its record lies beside it as theirs do.

Bitwise where it says so, on every ISA: both sides are rendered by the same code on the same
machine from the same inputs (a still of frame k with the range given, against frame k of the
trajectory)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from PIL import Image, ImageSequence

from embree_rt.cli import main

FRAMES = 3
SIZE = ["--width", "96", "--height", "64", "--spp", "1", "--threads", "2", "--quiet"]


def write_heating_dump(path: Path) -> None:
    """A LAMMPS text dump by hand (no library writes one): 40 particles whose ``c_e`` column
    spans a range that grows frame by frame (0..1, 0..2, 0..3)."""
    rng = np.random.default_rng(8)
    positions = rng.uniform(1.0, 9.0, (40, 3))
    energy = rng.uniform(0.0, 1.0, 40)
    energy[:2] = 0.0, 1.0
    with open(path, "w") as out:
        for step in range(FRAMES):
            out.write(f"ITEM: TIMESTEP\n{step}\nITEM: NUMBER OF ATOMS\n40\n")
            out.write("ITEM: BOX BOUNDS pp pp pp\n" + "0.0 10.0\n" * 3)
            out.write("ITEM: ATOMS id type x y z c_e\n")
            for i, ((x, y, z), e) in enumerate(zip(positions, energy * (step + 1), strict=True)):
                out.write(f"{i + 1} 1 {x} {y} {z} {e}\n")


def test_every_frame_is_coloured_on_the_first_frames_range_and_carries_its_legend(tmp_path):
    dump = str(tmp_path / "d.lammpstrj")
    write_heating_dump(tmp_path / "d.lammpstrj")
    flags = ["--color-by", "c_e", "--legend", *SIZE]
    assert main(["render", dump, "-o", str(tmp_path / "f_{frame}.png"), *flags]) == 0
    for k in range(FRAMES):
        record = json.loads((tmp_path / f"f_{k}.legend.json").read_text())["legend"]
        assert record["title"] == "c_e" and record["range"] == [0.0, 1.0]  # frame 0's
    # frame 2 of the trajectory is the still of frame 2 coloured on frame 0's range ...
    still = ["--frame", "2", "--range", "0", "1", "-o", str(tmp_path / "still.png")]
    assert main(["render", dump, *still, *flags]) == 0
    assert np.array_equal(
        np.asarray(Image.open(tmp_path / "f_2.png")), np.asarray(Image.open(tmp_path / "still.png"))
    )
    # ... not on its own (0..3), which is what it shows without the legend
    assert main(["render", dump, "--frame", "2", "-o", str(tmp_path / "own.png"), *flags]) == 0
    own = json.loads((tmp_path / "own.legend.json").read_text())["legend"]
    assert own["range"] == [0.0, 3.0]
    assert not np.array_equal(
        np.asarray(Image.open(tmp_path / "own.png")), np.asarray(Image.open(tmp_path / "f_2.png"))
    )


def test_a_videos_frames_carry_the_legend_the_png_frames_carry(tmp_path):
    dump = str(tmp_path / "d.lammpstrj")
    write_heating_dump(tmp_path / "d.lammpstrj")
    flags = ["--color-by", "c_e", *SIZE]
    assert main(["render", dump, "-o", str(tmp_path / "f_{frame}.png"), "--legend", *flags]) == 0
    assert main(["render", dump, "-o", str(tmp_path / "v.gif"), "--legend", *flags]) == 0
    assert main(["render", dump, "-o", str(tmp_path / "plain_{frame}.png"), *flags]) == 0
    with Image.open(tmp_path / "v.gif") as gif:
        frames = [np.asarray(f.convert("RGB"), np.float64) for f in ImageSequence.Iterator(gif)]
    assert len(frames) == FRAMES
    for k in range(FRAMES):
        png = np.asarray(Image.open(tmp_path / f"f_{k}.png"), np.float64)
        plain = np.asarray(Image.open(tmp_path / f"plain_{k}.png"), np.float64)
        corner = (slice(png.shape[0] // 2, None), slice(png.shape[1] // 2, None))
        # GIF holds 256 palette colours a frame: near the PNG in the corner, far from the
        # frame without the legend
        near = np.abs(frames[k][corner] - png[corner]).mean()
        far = np.abs(plain[corner] - png[corner]).mean()
        assert near < 4.0 and far > 4 * near + 10.0, (near, far)


def test_a_video_with_a_legend_has_the_png_frames_record_beside_it(tmp_path, capsys):
    """``v.legend.json`` beside ``v.gif``: the record each PNG frame has beside it (written by
    the image's own path, ``RenderResult.save``); none without --legend."""
    dump = str(tmp_path / "d.lammpstrj")
    write_heating_dump(tmp_path / "d.lammpstrj")
    flags = ["--color-by", "c_e", "--legend", *SIZE]
    assert main(["render", dump, "-o", str(tmp_path / "f_{frame}.png"), *flags]) == 0
    assert main(["render", dump, "-o", str(tmp_path / "v.gif"), *flags]) == 0
    record = json.loads((tmp_path / "v.legend.json").read_text())
    assert record == json.loads((tmp_path / "f_0.legend.json").read_text())
    assert record["legend"]["title"] == "c_e" and record["legend"]["range"] == [0.0, 1.0]
    plain = [f for f in flags if f != "--legend"]
    assert main(["render", dump, "-o", str(tmp_path / "plain.gif"), *plain]) == 0
    assert (tmp_path / "plain.gif").exists() and not (tmp_path / "plain.legend.json").exists()
    assert not [p.name for p in tmp_path.iterdir() if p.name.startswith(".")]


def test_a_videos_record_is_not_replaced_without_overwrite(tmp_path, capsys):
    """A record on disk, its video gone: refused before any frame renders (exit 2, one line
    naming it, nothing written); with --overwrite both are written."""
    dump = str(tmp_path / "d.lammpstrj")
    write_heating_dump(tmp_path / "d.lammpstrj")
    record = tmp_path / "v.legend.json"
    record.write_text("kept\n")
    flags = ["--color-by", "c_e", "--legend", *SIZE]
    capsys.readouterr()
    assert main(["render", dump, "-o", str(tmp_path / "v.gif"), *flags]) == 2
    message = capsys.readouterr().err.strip()
    assert message.count("\n") == 0 and str(record) in message and "--overwrite" in message
    assert record.read_text() == "kept\n" and not (tmp_path / "v.gif").exists()
    assert main(["render", dump, "-o", str(tmp_path / "v.gif"), "--overwrite", *flags]) == 0
    assert json.loads(record.read_text())["legend"]["title"] == "c_e"
    assert (tmp_path / "v.gif").exists()
    # a directory where the record goes is not replaced, --overwrite or not
    (tmp_path / "w.legend.json").mkdir()
    capsys.readouterr()
    assert main(["render", dump, "-o", str(tmp_path / "w.gif"), "--overwrite", *flags]) == 2
    assert "w.legend.json: is a directory" in capsys.readouterr().err
    assert not (tmp_path / "w.gif").exists()


def test_an_interrupted_video_leaves_its_record_as_it_was(tmp_path):
    """The files beside a video are renamed with it: an interrupted video writes none of them
    and leaves the one on disk as it was, and no temporary file."""
    from embree_rt.video import VideoWriter

    record = tmp_path / "v.legend.json"
    record.write_text("kept\n")
    beside = [(record, lambda handle: handle.write(b"new\n"))]
    with pytest.raises(KeyboardInterrupt), VideoWriter(tmp_path / "v.gif", 10, None, beside) as v:
        v.add(np.zeros((8, 8, 3), np.uint8))
        raise KeyboardInterrupt
    assert sorted(p.name for p in tmp_path.iterdir()) == ["v.legend.json"]
    assert record.read_text() == "kept\n"
    with VideoWriter(tmp_path / "v.gif", 10, None, beside) as video:
        video.add(np.zeros((8, 8, 3), np.uint8))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["v.gif", "v.legend.json"]
    assert record.read_text() == "new\n"


@pytest.mark.parametrize("follow", [[], ["--follow"]])
def test_a_trajectory_is_framed_clear_of_its_legend_as_a_still_is(tmp_path, follow):
    """In a portrait image the framing moves clear of the legend's corner (the radiance with
    --legend differs from that without, which only the camera can make), and a trajectory's
    first frame, framed once or on its own, is the still of that frame (bitwise: the same code
    renders the same scene on one machine)."""
    dump = str(tmp_path / "d.lammpstrj")
    write_heating_dump(tmp_path / "d.lammpstrj")
    portrait = ["--color-by", "c_e", "--width", "64", "--height", "96", "--spp", "1", "--quiet"]
    assert main(["render", dump, "-o", str(tmp_path / "key.npy"), "--legend", *portrait]) == 0
    assert main(["render", dump, "-o", str(tmp_path / "plain.npy"), *portrait]) == 0
    assert not np.array_equal(np.load(tmp_path / "key.npy"), np.load(tmp_path / "plain.npy"))
    still = ["--frame", "0", "-o", str(tmp_path / "still.png"), "--legend"]
    assert main(["render", dump, *still, *portrait]) == 0
    frames = ["-o", str(tmp_path / "f_{frame}.png"), "--legend", *follow]
    assert main(["render", dump, *frames, *portrait]) == 0
    assert np.array_equal(
        np.asarray(Image.open(tmp_path / "f_0.png")), np.asarray(Image.open(tmp_path / "still.png"))
    )
