"""How the command ends: its exit codes, the error it raises for bad input, and what it says
when the fault is ours."""

from __future__ import annotations

from embree_rt.errors import InputError

EXIT_BUG = 1
EXIT_BAD_INPUT = 2
EXIT_INTERRUPTED = 130
BUG_REPORT = (
    "embree-rt: internal error: this is a bug in embree_rt, not a problem with your input; "
    "please report it with the traceback above"
)


class UsageError(InputError):
    """Bad input found by the command itself; printed as one line, exit code 2."""
