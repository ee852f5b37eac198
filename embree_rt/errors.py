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
