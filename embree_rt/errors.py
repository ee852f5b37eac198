"""``InputError``: what the user must fix, as opposed to a bug in embree_rt.

The command reports an ``InputError`` as one line, ``embree-rt: error: MESSAGE``, with exit code
2, and any other exception as a bug (a traceback and a request for a report, exit code 1). Raise
it, or a subclass such as ``SceneError``, only for input: a scene file, a flag, a file to read or
write, a request the machine cannot meet.
"""

from __future__ import annotations


class InputError(Exception):
    """Bad input, not a bug. ``str()`` is the whole message: one line that names the file, flag
    or key at fault and the problem."""


def install_hint(extra: str, packages: str) -> str:
    """How to install what an optional feature needs, in words that work for the way embree_rt
    is installed (from a checkout, not from a package index): the packages themselves, or the
    checkout's ``extra``."""
    return f"pip install {packages} (or, from the embree_rt checkout: pip install '.[{extra}]')"


class FieldError(ValueError):
    """A value a dataclass refuses for one of its fields: ``field`` names it, ``problem`` says
    what is wrong (``str()`` is ``"field: problem"``), so that a scene file's reader can report
    it under the file's key."""

    def __init__(self, field: str, problem: str) -> None:
        self.field = field
        self.problem = problem
        super().__init__(f"{field}: {problem}")


def range_problem(
    value: float,
    low: float | None = None,
    high: float | None = None,
    *,
    low_open: bool = False,
    high_open: bool = False,
) -> str | None:
    """What keeps the number ``value`` out of [``low``, ``high``] (either bound None: open;
    ``low_open``/``high_open``: the bound itself excluded), in the one wording every check of a
    range uses ("must be >= 0, got -1"), or None. NaN lies in no range."""
    if low is not None and not (value > low if low_open else value >= low):
        return f"must be {'>' if low_open else '>='} {low:g}, got {value:g}"
    if high is not None and not (value < high if high_open else value <= high):
        return f"must be {'<' if high_open else '<='} {high:g}, got {value:g}"
    return None
