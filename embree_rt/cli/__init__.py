"""The ``embree-rt`` command: render a scene file, render a random field, describe a scene,
serve the browser demo. ``main`` runs it; each command lives in a module of its own
(``render``, ``animate`` for animations and clusters, ``info``, ``serve``)."""

from __future__ import annotations

import os
import sys
import traceback
import warnings
from contextlib import contextmanager

from embree_rt.cli.errors import (
    BUG_REPORT,
    EXIT_BAD_INPUT,
    EXIT_BUG,
    EXIT_INTERRUPTED,
    EXIT_TERMINATED,
    Terminated,
    sigterm_as_interrupt,
)
from embree_rt.cli.info import command_info
from embree_rt.cli.parser import SPHERE_CHOICES, build_parser
from embree_rt.cli.render import command_random, command_render
from embree_rt.cli.serve import command_serve
from embree_rt.errors import InputError

__all__ = [
    "BUG_REPORT",
    "EXIT_BAD_INPUT",
    "EXIT_BUG",
    "EXIT_INTERRUPTED",
    "EXIT_TERMINATED",
    "SPHERE_CHOICES",
    "build_parser",
    "main",
]

# What a process killed by SIGPIPE exits with (128 + 13), as `yes | head` does.
EXIT_BROKEN_PIPE = 141
COMMANDS = {
    "render": command_render,
    "random": command_random,
    "info": command_info,
    "serve": command_serve,
}


def main(argv: list[str] | None = None) -> int:
    """Run the command ``argv`` (default: the process's arguments); returns the exit code."""
    parser = build_parser()
    if not (sys.argv[1:] if argv is None else argv):  # bare `embree-rt`: what it can do
        print(parser.format_help(), end="", file=sys.stderr)
        return EXIT_BAD_INPUT
    try:
        args = parser.parse_args(argv)
    except SystemExit as exit_:
        return int(exit_.code or 0)
    try:
        with sigterm_as_interrupt(), one_line_warnings():
            COMMANDS[args.command](args)
        sys.stdout.flush()  # here, where a closed pipe is caught, not at the interpreter's exit
    except Terminated:
        print("embree-rt: terminated", file=sys.stderr)
        return EXIT_TERMINATED
    except KeyboardInterrupt:
        print("embree-rt: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except BrokenPipeError:  # `embree-rt info scene.toml | head`: the reader had enough
        # Python would flush stdout again at exit and fail once more: point it at nothing.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return EXIT_BROKEN_PIPE
    except InputError as error:  # scene files, flags, the user's files: one line
        print(f"embree-rt: error: {error}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except Exception:  # anything else is ours to fix: say so, with what a report needs
        traceback.print_exc()
        print(BUG_REPORT, file=sys.stderr)
        return EXIT_BUG
    return 0


@contextmanager
def one_line_warnings():
    """Print each ``InputWarning`` (what a file asks for that is rendered differently or left
    out) as one line, ``embree-rt: warning: MESSAGE``; other warnings as Python prints them."""
    from embree_rt.scene.errors import InputWarning

    with warnings.catch_warnings():
        shown = warnings.showwarning

        def show(message, category, filename, lineno, file=None, line=None):
            if issubclass(category, InputWarning):
                print(f"embree-rt: warning: {message}", file=sys.stderr)
            else:
                shown(message, category, filename, lineno, file, line)

        warnings.showwarning = show
        yield
