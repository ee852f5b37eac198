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
