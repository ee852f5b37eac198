"""What is wrong, if anything, with a path a scene names for reading: a name too long for the
file system, a loop of symbolic links, a directory, a FIFO or device (which would block or
never end), no permission. Asked before a file is opened, so that each is one line naming the
key, never an OSError's traceback and never a read that waits forever."""

from __future__ import annotations

import errno
import os
import stat
from pathlib import Path

KINDS = {
    stat.S_IFDIR: "a directory",
    stat.S_IFIFO: "a FIFO (named pipe)",
    stat.S_IFSOCK: "a socket",
    stat.S_IFCHR: "a character device",
    stat.S_IFBLK: "a block device",
}


def unreadable_problem(path: Path) -> str | None:
    """Why the file at ``path`` cannot be read as a file, or None when it can, or when it does
    not exist (which its reader reports in its own words)."""
    if (problem := not_a_file_problem(path)) is not None:
        return problem
    if os.path.exists(path) and not os.access(path, os.R_OK):
        return "no permission to read it"
    return None


def not_a_file_problem(path: Path) -> str | None:
    """Why ``path``, where it exists, is not a regular file (following symbolic links), or
    cannot be looked at; None for a file or for nothing there."""
    try:
        status = os.stat(path)
    except FileNotFoundError:
        return None
    except OSError as error:
        return os_error_problem(error, path)
    kind = stat.S_IFMT(status.st_mode)
    if kind != stat.S_IFREG:
        return f"is {KINDS.get(kind, 'not a regular file')}, not a file"
    return None


def os_error_problem(error: OSError, path: Path) -> str:
    """``error``, raised for ``path``, said in a few words (no errno, no repeated path)."""
    if error.errno == errno.ENAMETOOLONG:
        longest = max((len(part.encode()) for part in Path(path).parts), default=0)
        return (
            f"the name is too long for the file system ({len(str(path).encode()):,} bytes, "
            f"its longest part {longest:,})"
        )
    if error.errno == errno.ELOOP:
        return "a loop of symbolic links"
    if error.errno == errno.ENOTDIR:
        return "a part of the path is not a directory"
    if error.errno in (errno.EACCES, errno.EPERM):
        return "no permission to reach it"
    return (error.strerror or str(error)).lower()
