"""Every snippet and command in README.md and docs/*.md runs as pasted.

The rule, per fenced block:

- ```python blocks are written to a file and run with a fresh interpreter (``python FILE``, so
  ``if __name__ == "__main__":`` holds) and must exit 0; the asserts they hold are part of it.
- ```console, ```bash and ```sh blocks are read line by line (a trailing backslash joins lines,
  ``#`` starts a comment). A line that starts with ``embree-rt`` is run as ``python -m embree_rt``
  with the rest of the line split as a POSIX shell would (``shlex``) and must exit 0, and the
  file it names with ``-o`` must then exist (the first frame, for a ``{frame}`` pattern).
  ``embree-rt serve`` runs until stopped: it must print its address, answer ``GET /`` and
  ``GET /2d`` with 200, and on Ctrl-C (SIGINT) exit with 130, as every command does.
- Other lines are not run, and each must be one of the kinds in ``NOT_RUN``: installing
  (``pip install``, a venv, ``apt-get``, ``git clone``; ``.ci/run`` installs exactly as the
  README's first lines say and then runs the suite), the suite itself, the linter, the
  benchmarks (minutes long; their figures are in docs/performance.md) and the release digests
  (``tests/release_outputs.py``, a few minutes). A line of any other kind fails the test, so
  no command is left untested by accident. Commands written inline in prose (the gallery's,
  those beside measured figures) are not fenced and not run: they render at full size.

Each markdown file runs in a temporary directory of its own holding links to the checkout's
``scenes`` and ``assets`` (the README's commands are written for a checkout), its blocks in the
order they appear, so a command may use what an earlier one wrote. The checkout's ``embree_rt``
comes first on ``PYTHONPATH``, so the snippets test this checkout, not an installed copy.
"""

from __future__ import annotations

import os
import re
import shlex
import signal
import subprocess
import sys
import urllib.request
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
DOCUMENTS = [REPO / "README.md", *sorted((REPO / "docs").glob("*.md"))]
SHELL_LANGUAGES = ("console", "bash", "sh")
# Shell lines that are not run, by how they start (see the module docstring).
NOT_RUN = (
    "python3 -m venv",
    "pip install",
    "apt-get install",
    "git clone",
    "python -m pytest",
    "ruff ",
    "python benchmarks/",
    "python tests/release_outputs.py",
    "PYTHONPATH=/path/to/checkout python tests/release_outputs.py",
)
FENCE = re.compile(r"^```(\w*)\n(.*?)^```", re.MULTILINE | re.DOTALL)
TIMEOUT_S = 300
# What every command exits with on Ctrl-C (the shell's 128 + SIGINT).
EXIT_INTERRUPTED = 130


def fenced_blocks(path: Path) -> list[tuple[str, str]]:
    """(language, text) of each fenced block of the markdown file ``path``, in order."""
    return [(m.group(1), m.group(2)) for m in FENCE.finditer(path.read_text())]


def shell_lines(text: str) -> list[str]:
    """The commands of a shell block: continuation lines joined, comments and blanks dropped."""
    joined = re.sub(r"\\\n\s*", " ", text)
    lines = (shlex.split(line, comments=True) for line in joined.splitlines())
    return [shlex.join(words) for words in lines if words]


def environment() -> dict[str, str]:
    path = os.environ.get("PYTHONPATH")
    return {**os.environ, "PYTHONPATH": str(REPO) + (os.pathsep + path if path else "")}


def run(command: list[str], cwd: Path, what: str) -> None:
    done = subprocess.run(
        command, cwd=cwd, env=environment(), capture_output=True, text=True, timeout=TIMEOUT_S
    )
    assert done.returncode == 0, f"{what}\nexit {done.returncode}\n{done.stdout}\n{done.stderr}"


def run_serve(arguments: list[str], cwd: Path, what: str) -> None:
    """Start ``embree-rt serve``, ask it for both pages, stop it with SIGINT (Ctrl-C)."""
    server = subprocess.Popen(
        [sys.executable, "-m", "embree_rt", *arguments],
        cwd=cwd,
        env=environment(),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        line = server.stdout.readline()
        address = re.search(r"http://\S+/", line)
        assert address, f"{what}: printed no address: {line!r} {server.stderr.read()}"
        for page in ("", "2d"):
            with urllib.request.urlopen(address.group(0) + page, timeout=30) as response:
                assert response.status == 200, f"{what}: GET /{page}: {response.status}"
        server.send_signal(signal.SIGINT)
        assert server.wait(timeout=30) == EXIT_INTERRUPTED, f"{what}: {server.stderr.read()}"
    finally:
        if server.poll() is None:
            server.kill()
            server.wait()


def written_file(arguments: list[str]) -> str | None:
    """The ``-o`` of an embree-rt command line, its first frame for a ``{frame}`` pattern."""
    for flag in ("-o", "--output"):
        if flag in arguments:
            output = arguments[arguments.index(flag) + 1]
            if "{frame" in output:
                frames = (
                    arguments[arguments.index("--frames") + 1] if "--frames" in arguments else "0"
                )
                output = output.format(frame=int(frames.split(":")[0] or 0))
            return output
    return None


def run_shell_line(line: str, cwd: Path, where: str) -> None:
    words = shlex.split(line)
    if words[0] != "embree-rt":
        assert line.startswith(NOT_RUN), f"{where}: neither run nor of a kind not run: {line}"
        return
    arguments = words[1:]
    if arguments[0] == "serve":
        run_serve(arguments, cwd, f"{where}: {line}")
        return
    run([sys.executable, "-m", "embree_rt", *arguments], cwd, f"{where}: {line}")
    output = written_file(arguments)
    if output is not None:
        assert (cwd / output).stat().st_size > 0, f"{where}: {line}: wrote no {output}"


@pytest.mark.parametrize("document", DOCUMENTS, ids=lambda path: path.relative_to(REPO).as_posix())
def test_every_snippet_and_command_runs_as_pasted(document: Path, tmp_path: Path) -> None:
    for name in ("scenes", "assets"):
        (tmp_path / name).symlink_to(REPO / name, target_is_directory=True)
    blocks = fenced_blocks(document)
    for number, (language, text) in enumerate(blocks, 1):
        where = f"{document.name} block {number}"
        if language == "python":
            script = tmp_path / f"snippet_{number}.py"
            script.write_text(text)
            run([sys.executable, str(script)], tmp_path, f"{where}:\n{text}")
        elif language in SHELL_LANGUAGES:
            for line in shell_lines(text):
                run_shell_line(line, tmp_path, where)


def test_the_readme_fits_in_250_lines_and_its_links_exist() -> None:
    readme = (REPO / "README.md").read_text()
    assert len(readme.splitlines()) <= 250
    for path in DOCUMENTS:
        for target in re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", path.read_text()):
            if "://" not in target:
                assert (path.parent / target).exists(), f"{path.name}: broken link {target}"


def test_the_shell_rule_reads_continuations_and_comments() -> None:
    text = "embree-rt render a.toml \\\n    -o 'b c.png'   # a comment\n\n# only a comment\n"
    assert shell_lines(text) == ["embree-rt render a.toml -o 'b c.png'"]
    assert (
        written_file(shlex.split("embree-rt render s.toml -o f_{frame:03d}.png --frames 4:8"))
        == "f_004.png"
    )
