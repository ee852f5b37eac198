"""``SceneError``: bad scene input, reported as ``FILE: KEY: problem`` on one line."""

from __future__ import annotations

import difflib
from collections.abc import Iterable

from embree_rt.errors import InputError


class SceneError(InputError, ValueError):
    """A problem with a scene file (bad input, and a ValueError to the Python API). ``key`` is a
    dotted path such as ``spheres[3].radius``. The message stays on one line whatever the file
    holds: a file name or key with a newline (or any other character that does not print) is
    shown quoted, by ``repr``, and such a character in the problem is shown escaped."""

    def __init__(self, file: object, key: str, problem: str) -> None:
        self.file = str(file)
        self.key = key
        self.problem = problem
        super().__init__(f"{quoted(self.file)}: {quoted(key)}: {escaped(problem)}")


def quoted(name: str) -> str:
    """``name`` as it is when every character prints, else its ``repr`` (quoted, one line)."""
    return name if name.isprintable() else repr(name)


def escaped(text: str) -> str:
    """``text`` with each character that does not print (a newline, a NUL) written as its
    escape, so a message that quotes a file's words stays one line."""
    if text.isprintable():
        return text
    return "".join(c if c.isprintable() else repr(c)[1:-1] for c in text)


def unknown_key_message(key: str, known: Iterable[str]) -> str:
    """'unknown key' with a "did you mean" suggestion when a known key is close."""
    close = difflib.get_close_matches(key, list(known), n=1, cutoff=0.6)
    hint = f" (did you mean {close[0]!r}?)" if close else ""
    return f"unknown key{hint}; known keys: {', '.join(sorted(known))}"


class InputWarning(UserWarning):
    """Something a file asks for that embree_rt renders differently or leaves out, said in one
    line (``str()``) naming the file and the key: the picture is still made."""


def warn_input(message: str) -> None:
    """Issue ``message`` as an ``InputWarning`` (the command prints it as one line)."""
    import warnings

    warnings.warn(InputWarning(message), stacklevel=3)


class MeshFileError(ValueError):
    """A problem inside a mesh file, before it is known which scene file and key named it:
    ``key`` is the place in the mesh file (``buffers[0].uri``, ``element 'tristrips'``, or
    "(file)"), ``problem`` what is wrong there. The loader reports it as a ``SceneError``."""

    def __init__(self, key: str, problem: str) -> None:
        self.key = key
        self.problem = problem
        super().__init__(f"{key}: {problem}")
