"""The files of an animation's frames: an output pattern formatted with each frame's number,
and the frames ``--frames`` names."""

from __future__ import annotations

import string

from embree_rt.errors import InputError


def output_paths(pattern: str, frames: range | None) -> dict[int | None, str]:
    """The file of each frame: ``pattern.format(frame=f)`` for an animation (``frames``), the
    pattern itself for a still (``frames`` None). Raises InputError naming ``-o``."""
    try:
        fields = {name for _, name, _, _ in string.Formatter().parse(pattern) if name is not None}
    except ValueError as error:
        raise InputError(f"-o: {pattern}: not a valid pattern: {error}") from None
    if frames is None:
        if fields:
            raise InputError(
                f"-o: {pattern}: a pattern with {{frame}} needs a scene with an [animation]"
            )
        return {None: pattern}
    if fields != {"frame"}:
        raise InputError(
            f"-o: {pattern}: the scene is animated: name the file with {{frame}} and nothing "
            "else in braces (e.g. shots/f_{frame:04d}.png), or every frame would overwrite one file"
        )
    try:
        paths = {f: pattern.format(frame=f) for f in frames}
    except (ValueError, TypeError) as error:
        raise InputError(f"-o: {pattern}: cannot format a frame number: {error}") from None
    if len(set(paths.values())) < len(paths):
        raise InputError(f"-o: {pattern}: gives two frames the same file name")
    return paths


def frame_range(text: str | None, count: int) -> range:
    """Frames ``A:B`` (``A`` to ``B - 1``, as a Python slice; either end may be left out) or
    ``A`` (one frame) of an animation of ``count`` frames. Raises InputError naming --frames."""
    if text is None:
        return range(count)
    first, colon, last = text.partition(":")
    try:
        start = int(first) if first.strip() else 0
        stop = (int(last) if last.strip() else count) if colon else start + 1
    except ValueError:
        raise InputError(f"--frames: expected A:B (frame numbers), got {text!r}") from None
    if not 0 <= start < stop <= count:
        raise InputError(
            f"--frames: {text!r} is not a non-empty range within the animation's frames 0:{count}"
        )
    return range(start, stop)
