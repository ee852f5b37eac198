"""``embree-rt serve``: the 2D ray demo and the live preview in a browser."""

from __future__ import annotations

import argparse
import importlib.util

from embree_rt.cli.checks import check_library
from embree_rt.cli.errors import UsageError
from embree_rt.errors import install_hint


def command_serve(args: argparse.Namespace) -> None:
    needed = ("starlette", "uvicorn", "websockets")
    if any(importlib.util.find_spec(name) is None for name in needed):
        raise UsageError(f"serve needs the web extra: {install_hint('web', ' '.join(needed))}")
    check_library()
    from embree_rt.web.serve import serve

    serve(args.scene, args.host, args.port)
