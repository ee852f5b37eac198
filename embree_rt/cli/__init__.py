"""The ``embree-rt`` command: render a scene file, render a random field, describe a scene,
serve the browser demo.

``main`` parses the command line (``parser``), turns a render's flags into a ``Job`` (``job``:
the one place that decides what the command asks for and refuses bad combinations), and runs
it with the runner it needs: ``render`` on this machine, ``cluster`` on Dask; ``info`` and
``serve`` are commands of their own. Only the parser is imported up front, so that ``--help``
and ``--version`` load neither NumPy nor numba.
"""

from __future__ import annotations

import gc
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
    interrupting_signals,
)
from embree_rt.cli.numba_setup import numba_loaded_without_scipy
from embree_rt.cli.parser import SPHERE_CHOICES, build_parser
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

# New objects before a collection of the youngest generation, for the command's process
# (``main``; Python's default is 700).
YOUNG_COLLECTION_OBJECTS = 10_000
# What a process killed by SIGPIPE exits with (128 + 13), as `yes | head` does.
EXIT_BROKEN_PIPE = 141
# The variables OpenBLAS (NumPy's BLAS) reads its thread count from; one set by the user stands.
BLAS_THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "GOTO_NUM_THREADS", "OMP_NUM_THREADS")


def main(argv: list[str] | None = None) -> int:
    """Run the command ``argv`` (default: the process's arguments); returns the exit code.

    Run for the process's own arguments (the ``embree-rt`` command, ``python -m embree_rt``),
    the process ends with the command: what it made is left to the exit (``gc.freeze``), not
    collected first. The interpreter's last collections walk every object numba and the
    renderer made, and freeing them took 0.7-1.0 s after the summary line on this project's
    loaded machine (0.13-0.16 s frozen, as against 0.11-0.13 s for no finalisation at all);
    exit handlers still run, streams are still flushed, and the files are closed before.
    Meanwhile the collector's youngest generation waits for ``YOUNG_COLLECTION_OBJECTS`` new
    objects, not Python's 700: importing numba and setting it up make some 10^5 objects that
    all live on, and each young collection that promoted them led to a full walk of them (the
    1e6 GSD's render: 274 collections, 0.42-0.47 s of one core, loaded; 18, 0.16-0.19 s)."""
    if argv is None:
        _, middle, oldest = gc.get_threshold()
        gc.set_threshold(YOUNG_COLLECTION_OBJECTS, middle, oldest)
        blas_without_threads()
    code = exit_code(argv)
    if argv is None:
        gc.freeze()
    return code


def blas_without_threads() -> None:
    """Have OpenBLAS, NumPy's BLAS, start no threads of its own in this process (and the
    processes it starts), unless NumPy is imported already or the user set its thread count
    (``BLAS_THREAD_VARIABLES``). The renderer calls no BLAS routine: its parallel work is its
    own worker threads and Embree's. But OpenBLAS starts a thread for each further core when
    NumPy is imported, which spins for about 0.1 s before it sleeps: on this project's 2-core
    machine 0.12 s of CPU a command (``embree-rt random`` at 1e6, eight runs each in turns),
    taken from the imports on a loaded machine."""
    if "numpy" in sys.modules or any(name in os.environ for name in BLAS_THREAD_VARIABLES):
        return
    os.environ["OPENBLAS_NUM_THREADS"] = "1"


def exit_code(argv: list[str] | None) -> int:
    """Run the command ``argv`` (None: the process's arguments); returns its exit code."""
    try:
        # from the start: parsing imports NumPy and the scene model (seconds on a busy machine)
        with interrupting_signals():
            parser = build_parser()
            if not (sys.argv[1:] if argv is None else argv):  # bare `embree-rt`: what it can do
                print(parser.format_help(), end="", file=sys.stderr)
                return EXIT_BAD_INPUT
            try:
                # the command's own process: numba set up without SciPy (numba_setup)
                with numba_loaded_without_scipy(enabled=argv is None):
                    args = parser.parse_args(argv)
            except SystemExit as exit_:
                return int(exit_.code or 0)
            with one_line_warnings():
                run_command(args, ends_process=argv is None)
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


def run_command(args, ends_process: bool = False) -> None:
    """Run the parsed command, importing only the runner it needs. ``ends_process``: the
    process ends with it (``main``), so what is alive once the job is known lives as long."""
    if args.command == "serve":
        from embree_rt.cli.serve import command_serve

        command_serve(args)
        return
    from embree_rt.cli.clock import FIRST_COMPILE_NOTICE, CompileClock
    from embree_rt.cli.summary import Timeline

    # Like the progress bar, the notice is for someone watching a terminal, not for scripts.
    watched = sys.stderr.isatty() and not getattr(args, "quiet", False)
    clock = CompileClock(notice=FIRST_COMPILE_NOTICE if watched else None)
    with clock.listening():
        timeline = Timeline(clock)
        if args.command == "info":
            from embree_rt.cli.info import command_info

            command_info(args, clock, timeline)
            return
        from embree_rt.cli.job import job_from_args

        job = job_from_args(args)
        if getattr(args, "cameras", None) is not None:
            from embree_rt.cli.views import run_views

            run_views(job, args, timeline)
            return
        if job.reads_trajectory:
            from embree_rt.cli.trajectory import render_trajectory

            render_trajectory(args)
            return
        if job.on_dask:
            from embree_rt.cli import cluster as runner
        else:
            from embree_rt.cli import render as runner
        if ends_process:
            # The modules and settings made so far live as long as the process: out of the
            # collector's walks (one full collection of them and numba's first-kernel set-up
            # took 0.15-0.3 s, loaded).
            gc.freeze()
        runner.run(job, timeline)


@contextmanager
def one_line_warnings():
    """Print each ``InputWarning`` (what a file asks for that is rendered differently or left
    out) as one line, ``embree-rt: warning: MESSAGE``; a warning of a library we call (trimesh,
    NumPy, Pillow, Dask) that its caller did not silence as one line too, naming the library,
    never Python's two-line form with the source line. Each line once: a scene file loaded
    twice (once to plan a cluster's bricks) says its warnings once."""
    from embree_rt.scene.errors import InputWarning

    with warnings.catch_warnings():
        said: set[str] = set()

        def show(message, category, filename, lineno, file=None, line=None):
            if issubclass(category, InputWarning):
                text = f"embree-rt: warning: {message}"
            else:
                where = library_of(filename)
                words = " ".join(str(message).split())
                text = f"embree-rt: warning: {where}: {category.__name__}: {words}"
            if text not in said:
                said.add(text)
                print(text, file=sys.stderr)

        warnings.showwarning = show
        yield


def library_of(filename: str) -> str:
    """The top-level package a warning's ``filename`` belongs to ("trimesh", "numpy"), or the
    file's name outside site-packages."""
    parts = os.path.normpath(filename).split(os.sep)
    for marker in ("site-packages", "dist-packages"):
        if marker in parts[:-1]:
            return parts[parts.index(marker) + 1].removesuffix(".py")
    return os.path.basename(filename)
