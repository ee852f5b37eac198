"""The package's modules import each other without a circle, and only downward through the
layers of docs/architecture.md.

Read from the source with ``ast``: every ``import`` counts, a deferred one inside a function too
(it is the same circle, only hidden until the call), and one under ``if TYPE_CHECKING:`` too:
it never runs, but two modules that each need the other's names to be read are one module
split in two, whatever the interpreter does.
"""

from __future__ import annotations

import ast
import re
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


# The layers of docs/architecture.md ("Layers and their rules"), bottom up: each layer's modules
# (a package's name stands for every module in it; the longest name that fits a module places
# it), and the layers it stands on. A module imports only from its own layer and those its layer
# stands on. A new module or package must be placed here (the test names it until it is), and
# named in the layer's paragraph of docs/architecture.md.
LAYERS: dict[str, tuple[str, ...]] = {
    "leaves": (
        "ambient_occlusion",
        "batches",
        "budget",
        "camera",
        "choices",
        "closing",
        "columns",
        "compiled",
        "errors",
        "film",
        "legend",
        "materials",
        "memory",
        "particle_extras",
        "sampling",
        "shading",
        "sphere_modes",
        "textures",
        "transforms",
        "version",
        "video",
    ),
    "embree": ("embree",),
    "scene": ("scene",),
    "renderer": (
        "aovs",
        "bricks",
        "geometry",
        "integrator",
        "mesh_attributes",
        "tracer",
        "tracing",
    ),
    "trimesh_ray": ("trimesh_ray",),
    "front ends": ("", "__main__", "api", "bricks.cluster", "cli", "distributed", "web"),
}
STANDS_ON: dict[str, tuple[str, ...]] = {
    "leaves": (),
    "embree": ("leaves",),
    # The scene knows nothing of Embree or of rendering.
    "scene": ("leaves",),
    "renderer": ("leaves", "embree", "scene"),
    # trimesh's ray API stands on the Embree layer alone, beside the renderer.
    "trimesh_ray": ("leaves", "embree"),
    "front ends": ("leaves", "embree", "scene", "renderer", "trimesh_ray"),
}


def layer_of(module: str, layers: dict[str, tuple[str, ...]] = LAYERS) -> str | None:
    """The layer whose longest entry holds dotted ``module`` ("embree_rt.x.y"), or None."""
    relative = module.removeprefix("embree_rt").removeprefix(".")
    best, best_length = None, -1
    for layer, entries in layers.items():
        for entry in entries:
            holds = relative == entry or (entry and relative.startswith(entry + "."))
            if holds and len(entry) > best_length:
                best, best_length = layer, len(entry)
    return best


def upward_imports(
    graph: dict[str, set[str]],
    layers: dict[str, tuple[str, ...]] = LAYERS,
    stands_on: dict[str, tuple[str, ...]] = STANDS_ON,
) -> list[str]:
    """Each import of ``graph`` (module -> modules it imports) that leaves its module's layer
    for one it does not stand on, as "a (layer) imports b (layer)"."""
    found = []
    for module, targets in sorted(graph.items()):
        layer = layer_of(module, layers)
        for target in sorted(targets):
            target_layer = layer_of(target, layers)
            if target_layer != layer and target_layer not in stands_on[layer]:
                found.append(f"{module} ({layer}) imports {target} ({target_layer})")
    return found


def test_the_layer_rule_finds_an_upward_import() -> None:
    layers = {"low": ("a",), "high": ("b", "b.c"), "side": ("d",)}
    stands_on = {"low": (), "high": ("low",), "side": ("low",)}
    assert layer_of("embree_rt.b.c.e", layers) == "high"  # the longest entry that fits
    assert layer_of("embree_rt.bc", layers) is None  # a name's prefix is not its package
    graph = {
        "embree_rt.a": {"embree_rt.b"},
        "embree_rt.b": {"embree_rt.a", "embree_rt.b.c"},
        "embree_rt.d": {"embree_rt.b.c"},
        "embree_rt.b.c": {"embree_rt.d"},
    }
    assert upward_imports(graph, layers, stands_on) == [
        "embree_rt.a (low) imports embree_rt.b (high)",
        "embree_rt.b.c (high) imports embree_rt.d (side)",
        "embree_rt.d (side) imports embree_rt.b.c (high)",
    ]


def test_every_module_has_a_layer_and_imports_only_downward() -> None:
    files = module_files()
    assert LAYERS.keys() == STANDS_ON.keys()
    unplaced = sorted(name for name in files if layer_of(name) is None)
    assert not unplaced, f"modules in no layer of LAYERS (place them): {unplaced}"
    stale = [
        entry
        for entries in LAYERS.values()
        for entry in entries
        if not any(name == f"embree_rt.{entry}".rstrip(".") for name in files)
    ]
    assert not stale, f"LAYERS names modules that do not exist: {stale}"
    graph = {name: imported_modules(name, path, set(files)) for name, path in files.items()}
    upward = upward_imports(graph)
    assert not upward, "imports against the layers:\n" + "\n".join(upward)


def test_the_architecture_document_names_each_module_in_its_layer() -> None:
    """docs/architecture.md's paragraph of each layer (numbered, in ``LAYERS``' order) names
    every entry of it, as `name`, `name.py`, `name/` or `embree_rt/name/`."""
    text = (PACKAGE.parent / "docs" / "architecture.md").read_text(encoding="utf-8")
    section = text.split("## Layers and their rules", 1)[1].split("\n## ", 1)[0]
    paragraphs = re.split(r"\n(?=\d+\. )", section)[1:]
    assert len(paragraphs) == len(LAYERS), "one numbered paragraph a layer"
    for (layer, entries), paragraph in zip(LAYERS.items(), paragraphs, strict=True):
        named = set()
        for quoted in re.findall(r"`([^`]+)`", paragraph):
            name = quoted.removeprefix("embree_rt").strip("./").removesuffix(".py")
            named.add(name.replace("/", "."))
        missing = [entry for entry in entries if entry and entry not in named]
        assert not missing, f"docs/architecture.md's {layer} paragraph does not name {missing}"


def test_a_scene_without_meshes_renders_without_importing_trimesh(tmp_path: Path) -> None:
    """trimesh (and SciPy's spatial modules behind it) take about a second to import: a scene of
    spheres loads, renders and saves without them, so ``embree-rt random`` starts that much
    sooner. Nor does it import Pillow (~12 ms), which decodes textures and draws legends (its
    PNG is pypng's), or the glTF reader (~12 ms). Run in a fresh interpreter, as the command
    is."""

    script = (
        "import sys\n"
        "import embree_rt.cli\n"
        f"code = embree_rt.cli.main(['random', '--count', '50', '--width', '16', '--height', '9',"
        f" '--spp', '1', '--quiet', '-o', {str(tmp_path / 'out.png')!r}])\n"
        "code = code or embree_rt.cli.main(['render', 'scenes/three_spheres.toml', '--width', '16',"
        f" '--height', '9', '--spp', '1', '--quiet', '-o', {str(tmp_path / 'three.png')!r}])\n"
        "assert code == 0, code\n"
        "print(sorted(m for m in sys.modules if m.split('.')[0] in ('trimesh', 'PIL')\n"
        "             or m.startswith('embree_rt.scene.gltf')))\n"
    )
    assert printed_by(script) == "[]"
    assert (tmp_path / "out.png").is_file() and (tmp_path / "three.png").is_file()


def printed_by(script: str, cwd: Path | None = None) -> str:
    """What the Python ``script`` prints, run in a fresh interpreter from the checkout (as the
    command runs; from ``cwd`` with the checkout first on its path, when given), after checking
    it exits 0."""
    import subprocess
    import sys

    if cwd is not None:
        script = f"import sys\nsys.path.insert(0, {str(PACKAGE.parent)!r})\n{script}"
    done = subprocess.run(
        [sys.executable, "-c", script],
        cwd=PACKAGE.parent if cwd is None else cwd,
        capture_output=True,
        text=True,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    return done.stdout.strip()


def test_a_particle_file_renders_without_trimesh_or_matplotlib(tmp_path: Path) -> None:
    """A particle file coloured by type (a GSD frame of two types) loads, renders and saves
    without trimesh, the SciPy modules trimesh brings (spatial, optimize, ndimage) or
    matplotlib: meshes and colormaps are for the paths that read meshes or colour by a
    property. (``scipy.linalg`` is numba's own: its first kernel checks for BLAS through it.)
    Run in a fresh interpreter, as the command is."""

    path = two_types_gsd(tmp_path / "two_types.gsd")
    script = (
        "import sys\n"
        "import embree_rt.cli\n"
        f"code = embree_rt.cli.main(['render', {str(path)!r}, '--width', '16', '--height', '9',"
        f" '--spp', '1', '--quiet', '-o', {str(tmp_path / 'out.png')!r}])\n"
        "assert code == 0, code\n"
        "heavy = ('trimesh', 'matplotlib', 'scipy.spatial', 'scipy.optimize', 'scipy.ndimage')\n"
        "print(sorted(m for m in sys.modules if m.startswith(heavy)))\n"
    )
    assert printed_by(script) == "[]"
    assert (tmp_path / "out.png").is_file()


def two_types_gsd(path: Path, count: int = 20) -> Path:
    """A GSD file of one frame of ``count`` particles of two types at ``path``."""
    import gsd.hoomd
    import numpy as np

    frame = gsd.hoomd.Frame()
    frame.particles.N = count
    frame.particles.position = (
        np.random.default_rng(1).uniform(-3, 3, (count, 3)).astype(np.float32)
    )
    frame.particles.types = ["A", "B"]
    frame.particles.typeid = (np.arange(count) % 2).astype(np.uint32)
    frame.configuration.box = [10.0, 10.0, 10.0, 0.0, 0.0, 0.0]
    with gsd.hoomd.open(str(path), "w") as trajectory:
        trajectory.append(frame)
    return path


def test_the_commands_own_process_sets_numba_up_without_scipy(tmp_path: Path) -> None:
    """The command's own process (``main()`` reading ``sys.argv``, as ``embree-rt`` runs)
    renders a particle file without importing any of SciPy: numba is imported and its
    implementations loaded while SciPy looks absent (``cli/numba_setup.py``), so its check for
    a BLAS does not import ``scipy.linalg``. The image is byte for byte the one rendered by
    ``main(argv)`` in a process whose numba did find SciPy's BLAS (the library's way, where it
    must still import it). After the command SciPy imports again, and a kernel typing ``np.dot``
    compiles and agrees with NumPy. Each in a fresh interpreter."""
    path = two_types_gsd(tmp_path / "two_types.gsd")
    flags = f"{str(path)!r}, '--width', '16', '--height', '9', '--spp', '2', '--quiet', '-o'"
    own = (
        "import sys\n"
        "import embree_rt.cli\n"
        f"sys.argv = ['embree-rt', 'render', {flags}, {str(tmp_path / 'own.png')!r}]\n"
        "assert embree_rt.cli.main() == 0\n"
        "print(sorted(m for m in sys.modules if m.split('.')[0] == 'scipy'))\n"
        "import numba\n"
        "import numpy as np\n"
        "x = np.arange(5.0)\n"
        "dot = numba.njit(lambda a, b: np.dot(a, b))\n"
        "print(dot(x, x) == 30.0, 'scipy.linalg' in sys.modules)\n"
    )
    assert printed_by(own).splitlines() == ["[]", "True True"]
    library = (
        "import sys\n"
        "import embree_rt.cli\n"
        f"assert embree_rt.cli.main(['render', {flags}, {str(tmp_path / 'library.png')!r}]) == 0\n"
        "print('scipy.linalg' in sys.modules)\n"
    )
    assert printed_by(library) == "True"
    assert (tmp_path / "own.png").read_bytes() == (tmp_path / "library.png").read_bytes()


def test_the_commands_usage_errors_and_help_leave_scipy_importable() -> None:
    """A parse that ends the command (``--version``, a usage error) imports no numba, and SciPy
    imports afterwards in that process: it is hidden only while the parse runs."""
    script = (
        "import sys\n"
        "import embree_rt.cli\n"
        "codes = []\n"
        "for argv in (['embree-rt', '--version'], ['embree-rt', 'render', '--no-such-flag']):\n"
        "    sys.argv = argv\n"
        "    codes.append(embree_rt.cli.main())\n"
        "import scipy.linalg\n"
        "print(codes, 'numba' in sys.modules)\n"
    )
    assert printed_by(script).splitlines()[-1] == "[0, 2] False"


def test_the_commands_own_process_imports_pyyaml_only_for_a_numba_config_file(
    tmp_path: Path,
) -> None:
    """numba imports PyYAML only to read ``.numba_config.yaml`` from the working directory: the
    command's own process, run where there is none, never imports it (``cli/numba_setup.py``),
    and run where there is one, numba still reads it (its colour scheme, a setting that changes
    no kernel, is the file's); PyYAML imports afterwards either way. Each in a fresh
    interpreter."""
    script = (
        "import sys\n"
        "import embree_rt.cli\n"
        "sys.argv = ['embree-rt', 'random', '--count', '20', '--width', '8', '--height', '4',\n"
        "            '--spp', '1', '--quiet', '-o', 'field.png']\n"
        "assert embree_rt.cli.main() == 0\n"
        "from numba.core import config\n"
        "print('yaml' in sys.modules, config.COLOR_SCHEME)\n"
        "import yaml\n"
        "print(yaml.safe_load('a: 1'))\n"
    )
    plain = tmp_path / "plain"
    plain.mkdir()
    assert printed_by(script, cwd=plain).splitlines() == ["False no_color", "{'a': 1}"]
    configured = tmp_path / "configured"
    configured.mkdir()
    (configured / ".numba_config.yaml").write_text("color_scheme: dark_bg\n", encoding="utf-8")
    assert printed_by(script, cwd=configured).splitlines() == ["True dark_bg", "{'a': 1}"]
    assert (plain / "field.png").read_bytes() == (configured / "field.png").read_bytes()


def test_the_commands_own_process_asks_openblas_for_no_threads() -> None:
    """The command's own process asks NumPy's OpenBLAS for no threads of its own before NumPy
    is imported (``cli.blas_without_threads``): the process then has one thread after
    ``import numpy``, as Linux lists them (OpenBLAS starts one for each further core). A thread
    count the user set (``OMP_NUM_THREADS=2``) stands: two threads on a machine of two cores or
    more, ``OPENBLAS_NUM_THREADS`` left unset. Each in a fresh interpreter."""
    import os

    def threads_after_numpy(chosen: str | None) -> str:
        script = (
            "import glob, os, sys\n"
            "for name in ('OPENBLAS_NUM_THREADS', 'GOTO_NUM_THREADS', 'OMP_NUM_THREADS'):\n"
            "    os.environ.pop(name, None)\n"
            + (f"os.environ['OMP_NUM_THREADS'] = {chosen!r}\n" if chosen else "")
            + "import embree_rt.cli\n"
            "sys.argv = ['embree-rt', '--version']\n"
            "assert embree_rt.cli.main() == 0\n"
            "import numpy\n"
            "print(os.environ.get('OPENBLAS_NUM_THREADS'), len(glob.glob('/proc/self/task/*')))\n"
        )
        return printed_by(script).splitlines()[-1]

    assert threads_after_numpy(None) == "1 1"
    assert threads_after_numpy("2") == f"None {min(2, os.cpu_count() or 1)}"


# What numba's check for a BLAS decides (numba.np.arraymath): how these two are compiled.
DECIDED_BY_BLAS_CHECK = {"correlate", "convolve"}


def test_no_kernel_calls_what_numbas_blas_check_decides() -> None:
    """numba's check for a BLAS, which the command's own process skips (``cli/numba_setup.py``),
    decides only whether ``np.correlate`` and ``np.convolve`` call ``np.dot``: no module of the
    package that imports numba names either (read with ``ast``), so no kernel is compiled
    differently in the command and in a library user's process."""
    assert "embree_rt.compiled.film_sums" in module_files()
    named = []
    for name, path in module_files().items():
        tree = ast.parse(path.read_text(encoding="utf-8"))
        imports_numba = any(
            (
                isinstance(node, ast.Import)
                and any(a.name.split(".")[0] == "numba" for a in node.names)
            )
            or (isinstance(node, ast.ImportFrom) and (node.module or "").split(".")[0] == "numba")
            for node in ast.walk(tree)
        )
        if not imports_numba:
            continue
        for node in ast.walk(tree):
            words = (
                {node.attr}
                if isinstance(node, ast.Attribute)
                else {node.id}
                if isinstance(node, ast.Name)
                else {alias.name for alias in node.names}
                if isinstance(node, ast.ImportFrom)
                else set()
            )
            named += [f"{name}: {word}" for word in words & DECIDED_BY_BLAS_CHECK]
    assert not named, named
