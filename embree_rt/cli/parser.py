"""The command line: the ``embree-rt`` parser, its commands and flags."""

from __future__ import annotations

import argparse
import difflib
import math
import re
import sys

from embree_rt.choices import (
    AOV_NAMES,
    BACKGROUNDS,
    SPHERE_MODES,
    STANDARD_VIEWS,
    TONEMAPS,
    TRANSFERS,
)
from embree_rt.cli.errors import EXIT_BAD_INPUT
from embree_rt.version import __version__

SPHERE_CHOICES = SPHERE_MODES
SCENE_HELP = (
    "scene, mesh or particle file: a .toml or .json scene, a mesh (.obj, .ply, .stl, .off, .glb, "
    ".gltf) or particles (.xyz, .lammpstrj, .pdb, .gro, .gsd, ...) shown on its own, from its "
    "own camera and lights or framed and lit by default"
)
SCENE_DEFAULT = "; default: the scene's"
NO_FLOOR_HELP = "leave out the floor (a mesh file's, or the scene file's)"


class HelpFormatter(argparse.HelpFormatter):
    """Help that ends each flag's text with its default, where it has one worth saying."""

    def _get_help_string(self, action: argparse.Action) -> str | None:
        text = action.help or ""
        quiet = (None, False, argparse.SUPPRESS)
        if "%(default)" in text or any(action.default is value for value in quiet):
            return text
        return f"{text} (default: %(default)s)"


class Parser(argparse.ArgumentParser):
    """argparse, but a usage error is one line on stderr and exit code 2, a mistyped flag or
    command gets a "did you mean", and a flag is never read from its prefix (``--ao`` is not
    ``--aov``: a prefix that names one flag today would name another once a flag is added)."""

    def __init__(self, *args, **kwargs) -> None:
        kwargs.setdefault("formatter_class", HelpFormatter)
        kwargs["allow_abbrev"] = False
        super().__init__(*args, **kwargs)
        self.argv: list[str] = []

    def parse_known_args(self, args=None, namespace=None):
        self.argv = list(sys.argv[1:] if args is None else args)
        return super().parse_known_args(args, namespace)

    def error(self, message: str) -> None:  # type: ignore[override]
        message = message.removeprefix("argument ")
        print(f"embree-rt: error: {message}{self.suggestion(message)}", file=sys.stderr)
        raise SystemExit(EXIT_BAD_INPUT)

    def suggestion(self, message: str) -> str:
        """ " (did you mean ...?)" for the first unrecognized flag close to one the command
        takes, or an invalid command close to one; "" otherwise."""
        commands = next(
            (
                action.choices
                for action in self._actions
                if isinstance(action, argparse._SubParsersAction)
            ),
            {},
        )
        if message.startswith("command: invalid choice:"):
            known = list(commands)
            words = re.findall(r"invalid choice: '([^']*)'", message)
        elif message.startswith("unrecognized arguments:"):
            command = next((commands[word] for word in self.argv if word in commands), self)
            known = [flag for action in command._actions for flag in action.option_strings]
            words = [
                word.split("=")[0]
                for word in message.split(":", 1)[1].split()
                if word.startswith("-")
            ]
        else:
            return ""
        for word in words:
            close = difflib.get_close_matches(word, known, n=1, cutoff=0.6)
            if close:
                return f" (did you mean {close[0]!r}?)"
        return ""


def int_at_least(low: int, high: int | None = None):
    """An argparse type: an integer in [``low``, ``high``] (by default ``INTEGER_LIMIT``, what
    int64 holds; read when a value is parsed, as scene.limits imports NumPy)."""

    # argparse prefixes the message with the flag ("argument --width: ..."), so it is not repeated.
    def parse(text: str) -> int:
        from embree_rt.scene.limits import INTEGER_LIMIT

        most = INTEGER_LIMIT if high is None else high
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
        if value < low:
            raise argparse.ArgumentTypeError(f"must be >= {low}, got {value}")
        if value > most:
            raise argparse.ArgumentTypeError(f"must be <= {most}, got {value}")
        return value

    return parse


def non_empty(text: str) -> str:
    """An argparse type: any text but an empty or blank one (which would read as not given)."""
    if not text.strip():
        raise argparse.ArgumentTypeError(f"expected a value, got {text!r}")
    return text


def positive_seconds(text: str) -> float:
    """An argparse type: a finite number of seconds > 0."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number of seconds, got {text!r}") from None
    if not 0 < value < math.inf:
        raise argparse.ArgumentTypeError(f"must be a finite number > 0, got {text!r}")
    return value


def aov_list(text: str) -> tuple[str, ...]:
    """An argparse type: comma-separated AOV names (``aovs.parse_aov_list``)."""
    from embree_rt.aovs import parse_aov_list

    try:
        return parse_aov_list(text)
    except ValueError as error:
        raise argparse.ArgumentTypeError(str(error)) from None


class SetKey(argparse.Action):
    """Appends a ``settings.Setting`` to ``args.settings``, in the order the flags come:
    ``--set KEY=VALUE``, or a flag that stands for one key (``key``): ``--width 32`` is
    ``--set render.width=32``. Values are checked when the scene is read, by the loader."""

    def __init__(self, option_strings, dest, key: str | None = None, **kwargs) -> None:
        self.key = key
        super().__init__(option_strings, "settings", default=argparse.SUPPRESS, **kwargs)

    def __call__(self, parser, namespace, values, option_string=None) -> None:
        from embree_rt.scene.settings import Setting, parse_assignment, parse_value

        if self.key is None:
            try:
                setting = parse_assignment(values)
            except ValueError as error:
                raise argparse.ArgumentError(self, str(error)) from None
        else:
            words = values if isinstance(values, list) else [values]
            if self.nargs == 0:  # a flag standing for one value of its key: --ortho
                value = self.const
            elif self.nargs:
                value = [parse_value(word) for word in words]
            else:
                value = parse_value(values)
            setting = Setting(self.key, value, " ".join([option_string, *words]))
        namespace.settings = (*namespace.settings, setting)


def add_setting_flags(parser: argparse.ArgumentParser) -> None:
    """``--set`` and the flags that stand for one scene key each."""
    parser.set_defaults(settings=())  # (before the flags: theirs is SUPPRESS, not shown)
    parser.add_argument(
        "-D",
        "--set",
        action=SetKey,
        metavar="KEY=VALUE",
        help="set any scene key, named as in the scene file: camera.fov=35, "
        "lights[0].intensity=2, materials.gold.shininess=200, render.max_depth=3 (the value is "
        "read as TOML, else as a string; repeatable, the last wins)",
    )
    shortcuts = {
        "--width": ("render.width", "image width in pixels (render.width)"),
        "--height": ("render.height", "image height in pixels (render.height)"),
        "--spp": ("render.spp", "samples per pixel (render.spp)"),
        "--max-depth": (
            "render.max_depth",
            "bounces of reflection and refraction (render.max_depth)",
        ),
        "--seed": ("render.seed", "the sampler's seed (render.seed); random: the field's too"),
        "--fov": ("camera.fov", "vertical field of view in degrees (camera.fov)"),
        "--ao": (
            "render.ao.samples",
            "ambient occlusion: rays a camera-ray hit, 0 off (render.ao.samples)",
        ),
        "--ao-distance": (
            "render.ao.distance",
            "how far ambient occlusion looks for occluders, world units (render.ao.distance)",
        ),
        "--exposure": (
            "render.exposure",
            "stops of exposure before the tone map, e.g. 1 doubles the light (render.exposure)",
        ),
    }
    for flag, (key, text) in shortcuts.items():
        metavar = {"--exposure": "EV", "--ao-distance": "D"}.get(flag, "N")
        parser.add_argument(
            flag, action=SetKey, key=key, metavar=metavar, help=text + SCENE_DEFAULT
        )
    parser.add_argument(
        "--tonemap",
        action=SetKey,
        key="render.tonemap",
        choices=TONEMAPS,
        help="the tone map (render.tonemap)" + SCENE_DEFAULT + ", else reinhard",
    )
    parser.add_argument(
        "--transfer",
        action=SetKey,
        key="render.transfer",
        choices=TRANSFERS,
        help="the display curve: a 2.2 power, or sRGB's piecewise curve "
        "(render.transfer)" + SCENE_DEFAULT + ", else gamma2.2",
    )
    parser.add_argument(
        "--ao-bounces",
        action=SetKey,
        key="render.ao.bounces",
        nargs=0,
        const=True,
        help="ambient occlusion at reflected and refracted hits too (render.ao.bounces = true)",
    )
    for flag, projection in (("--ortho", "orthographic"), ("--perspective", "perspective")):
        parser.add_argument(
            flag,
            action=SetKey,
            key="camera.projection",
            nargs=0,
            const=projection,
            help=f'a {projection} camera (camera.projection = "{projection}")'
            + (
                ", its view_height from camera.view_height or else what fov sees at look_at"
                if projection == "orthographic"
                else ", also with --view"
            ),
        )
    parser.add_argument(
        "--background",
        action=SetKey,
        key="render.background",
        choices=BACKGROUNDS,
        help="what camera rays that meet nothing show: the sky, white, black, or transparent "
        "(an alpha channel: .png, .tif, .webp) (render.background)" + SCENE_DEFAULT,
    )
    for flag, key in (("--camera-position", "camera.position"), ("--look-at", "camera.look_at")):
        parser.add_argument(
            flag,
            action=SetKey,
            key=key,
            nargs=3,
            metavar=("X", "Y", "Z"),
            help=f"the camera's {key.split('.')[1]} ({key})" + SCENE_DEFAULT,
        )


def add_render_flags(parser: argparse.ArgumentParser) -> None:
    """The flags of every command that renders and writes images (``render``, ``random``): one
    set, so that what one takes the other takes too."""
    parser.add_argument("--no-floor", action="store_true", help=NO_FLOOR_HELP)
    positive = int_at_least(1)
    parser.add_argument(
        "-o",
        "--output",
        required=True,
        metavar="IMAGE",
        help="image to write: .png, .jpg, .tif, .webp (tone-mapped), .npy, .npz or .exr "
        "(linear float32)",
    )
    parser.add_argument(
        "--bit-depth",
        type=int,
        choices=(8, 16),
        default=8,
        help="bits per channel of a .png or .tif",
    )
    parser.add_argument(
        "--quality",
        type=int_at_least(1),
        metavar="Q",
        help="1 to 100, of a .jpg or .webp (default: 90)",
    )
    parser.add_argument(
        "--aov",
        type=aov_list,
        metavar="NAMES",
        help=f"also write AOVs, any of {','.join(AOV_NAMES)}: in the .npz or .exr, or one "
        "file each beside a .png or .npy",
    )
    add_setting_flags(parser)
    parser.add_argument(
        "--view",
        choices=STANDARD_VIEWS,
        help="a standard view framing the scene's bounds along an axis of its up convention, "
        "orthographic unless --perspective",
    )
    parser.add_argument(
        "--headlight",
        action="store_true",
        help="add a white light at the camera (a still's: not with an animation)",
    )
    parser.add_argument(
        "-t",
        "--threads",
        "--nthreads",
        type=positive,
        metavar="N",
        help="worker threads (default: all cores)",
    )
    parser.add_argument(
        "--spheres",
        choices=SPHERE_CHOICES,
        default="analytic",
        help="analytic spheres (compiled user geometry), Embree's own point spheres, or "
        "tessellated icospheres",
    )
    parser.add_argument("--quiet", action="store_true", help="no progress bar or summary")
    cluster = parser.add_mutually_exclusive_group()  # embree_rt/distributed.py
    cluster.add_argument(
        "--cluster", type=non_empty, metavar="local:N", help="render on N local Dask workers"
    )
    cluster.add_argument(
        "--scheduler", type=non_empty, metavar="tcp://HOST:PORT", help="render on a Dask cluster"
    )
    parser.add_argument(
        "--scheduler-timeout",
        type=positive_seconds,
        default=10.0,
        metavar="SECONDS",
        help="how long --scheduler may take to answer",
    )
    parser.add_argument(
        "--partition",
        type=positive,
        metavar="K",
        help="with --cluster or --scheduler: cut the scene into K spatial bricks, each held by "
        "one worker (scenes bigger than one machine's memory; shading on this machine)",
    )
    parser.add_argument("--frames", metavar="A:B", help="an animation's frames A to B-1 only")
    parser.add_argument("--overwrite", action="store_true", help="render frames already on disk")
    parser.add_argument(
        "--cameras",
        metavar="FILE",
        help="a JSON/TOML file of cameras: render each view to -o's {view} pattern",
    )


def build_parser() -> argparse.ArgumentParser:
    """The ``embree-rt`` parser: its commands and their flags. Builds without NumPy or numba
    (``--help`` and ``--version`` stay light); flag values are checked as they are parsed."""
    from embree_rt.cli.particles import add_particle_flags

    parser = Parser(
        prog="embree-rt",
        description="Whitted-style ray tracing of scenes with very many objects, on Embree.",
    )
    parser.add_argument("--version", action="version", version=f"embree-rt {__version__}")
    commands = parser.add_subparsers(dest="command", required=True)
    render = commands.add_parser("render", help="render a scene file or a mesh file")
    render.add_argument("scene", help=SCENE_HELP)
    add_render_flags(render)
    add_particle_flags(render)
    random = commands.add_parser("random", help="render a random sphere field of N spheres")
    random.add_argument(
        "--count", type=int_at_least(1), required=True, metavar="N", help="spheres in the field"
    )
    random.add_argument("--save-scene", help="also write the generated scene to this file")
    random.add_argument(
        "--instance",
        metavar="MESHFILE",
        help="replace every small sphere by this mesh (fitted into the sphere, resting on the "
        "floor, turned at random about y), all through one Embree instance array",
    )
    add_render_flags(random)
    info = commands.add_parser("info", help="describe a scene: objects, bounds, build time")
    info.add_argument("scene", help=SCENE_HELP)
    info.add_argument("--no-floor", action="store_true", help=NO_FLOOR_HELP)
    info.add_argument(
        "--spheres",
        choices=SPHERE_CHOICES,
        default="analytic",
        help="how spheres enter the BVH, as render's --spheres",
    )
    add_setting_flags(info)
    add_particle_flags(info)
    info.add_argument("--json", action="store_true", help="a particle file's summary as JSON")
    serve = commands.add_parser("serve", help="the 2D ray demo and a live preview in a browser")
    serve.add_argument(
        "scene", nargs="?", help="scene, particle or mesh file (default: the showcase)"
    )
    serve.add_argument("--host", default="127.0.0.1", help="address to listen on")
    serve.add_argument("--port", type=int_at_least(0), default=8000, help="0: any free port")
    return parser
