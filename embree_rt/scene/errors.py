"""``SceneError``: bad scene input, reported as ``FILE: KEY: problem`` on one line."""

from __future__ import annotations

import difflib
from collections.abc import Iterable

from embree_rt.errors import InputError


class SceneError(InputError, ValueError):
    """A problem with a scene file (bad input, and a ValueError to the Python API). ``key`` is a
    dotted path such as ``spheres[3].radius``."""

    def __init__(self, file: object, key: str, problem: str) -> None:
        self.file = str(file)
        self.key = key
        self.problem = problem
        super().__init__(f"{self.file}: {key}: {problem}")


def unknown_key_message(key: str, known: Iterable[str]) -> str:
    """'unknown key' with a "did you mean" suggestion when a known key is close."""
    close = difflib.get_close_matches(key, list(known), n=1, cutoff=0.6)
    hint = f" (did you mean {close[0]!r}?)" if close else ""
    return f"unknown key{hint}; known keys: {', '.join(sorted(known))}"
