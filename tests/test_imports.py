"""The package's modules import each other without a circle.

Read from the source with ``ast``: every ``import`` counts, a deferred one inside a function too
(it is the same circle, only hidden until the call), and one under ``if TYPE_CHECKING:`` too:
it never runs, but two modules that each need the other's names to be read are one module
split in two, whatever the interpreter does.
"""

from __future__ import annotations

import ast
from pathlib import Path

import embree_rt

PACKAGE = Path(embree_rt.__file__).parent


def module_files() -> dict[str, Path]:
    """Dotted module name -> source file, for every module of the package."""
    files = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
        files[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return files


def imported_modules(name: str, path: Path, known: set[str]) -> set[str]:
    """The package's modules that module ``name`` (source ``path``) imports."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    package = name.split(".") if path.name == "__init__.py" else name.split(".")[:-1]
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found |= {alias.name for alias in node.names if alias.name in known}
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:  # relative: from the package, up level - 1 steps
                base = ".".join(package[: len(package) - node.level + 1] + ([base] if base else []))
            for alias in node.names:
                submodule = f"{base}.{alias.name}"
                if submodule in known:
                    found.add(submodule)
                elif base in known:
                    found.add(base)
    found.discard(name)
    return found


def import_cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Every cycle a depth-first walk of ``graph`` (module -> modules it imports) closes."""
    state: dict[str, str] = {}
    path: list[str] = []
    cycles = []

    def visit(module: str) -> None:
        state[module] = "open"
        path.append(module)
        for target in sorted(graph[module]):
            if state.get(target) == "open":
                cycles.append([*path[path.index(target) :], target])
            elif target not in state:
                visit(target)
        path.pop()
        state[module] = "done"

    for module in sorted(graph):
        if module not in state:
            visit(module)
    return cycles


def test_the_cycle_finder_finds_a_cycle() -> None:
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}
    assert import_cycles(graph) == [["a", "b", "c", "a"]]
    assert import_cycles({"a": {"b"}, "b": set()}) == []


def test_no_module_imports_itself_through_others() -> None:
    files = module_files()
    assert {"embree_rt.scene.model", "embree_rt.scene.writer", "embree_rt.cli"} <= set(files)
    assert "embree_rt.cli.render" in files  # subpackages' modules too
    graph = {name: imported_modules(name, path, set(files)) for name, path in files.items()}
    # Deferred and type-only imports are seen: the writer reads the model's Scene, the AOV pass
    # names the integrator only for a type, the command imports its renderer on a call.
    assert "embree_rt.scene.model" in graph["embree_rt.scene.writer"]
    assert "embree_rt.integrator" in graph["embree_rt.aovs"]
    assert "embree_rt.api" in graph["embree_rt.cli.render"]
    cycles = import_cycles(graph)
    assert not cycles, "import circles: " + "; ".join(" -> ".join(cycle) for cycle in cycles)


def test_a_scene_without_meshes_renders_without_importing_trimesh(tmp_path: Path) -> None:
    """trimesh (and SciPy's spatial modules behind it) take about a second to import: a scene of
    spheres loads, renders and saves without them, so ``embree-rt random`` starts that much
    sooner. Run in a fresh interpreter, as the command is."""
    import subprocess
    import sys

    script = (
        "import sys\n"
        "import embree_rt.cli\n"
        f"code = embree_rt.cli.main(['random', '--count', '50', '--width', '16', '--height', '9',"
        f" '--spp', '1', '--quiet', '-o', {str(tmp_path / 'out.png')!r}])\n"
        "code = code or embree_rt.cli.main(['render', 'scenes/three_spheres.toml', '--width', '16',"
        f" '--height', '9', '--spp', '1', '--quiet', '-o', {str(tmp_path / 'three.png')!r}])\n"
        "assert code == 0, code\n"
        "print(sorted(m for m in sys.modules if m.split('.')[0] == 'trimesh'))\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", script],
        cwd=PACKAGE.parent,
        capture_output=True,
        text=True,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "[]"
    assert (tmp_path / "out.png").is_file() and (tmp_path / "three.png").is_file()
