"""The version of embree_rt: the installed distribution's, or, for a checkout run without
installing it (on ``PYTHONPATH``), the one its pyproject.toml declares."""

from __future__ import annotations

import sys
from importlib import metadata
from pathlib import Path

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

DISTRIBUTION = "embree-rt"


def find_version() -> str:
    """The checkout's pyproject.toml version when this package sits in a checkout (it is then
    what runs, even beside an installed copy of another version), else the installed
    distribution's; "0+unknown" when neither says."""
    pyproject = Path(__file__).resolve().parent.parent / "pyproject.toml"
    try:
        project = tomllib.loads(pyproject.read_text(encoding="utf-8")).get("project", {})
        if project.get("name") == DISTRIBUTION and isinstance(project.get("version"), str):
            return project["version"]
    except (OSError, tomllib.TOMLDecodeError):
        pass
    try:
        return metadata.version(DISTRIBUTION)
    except metadata.PackageNotFoundError:
        return "0+unknown"


__version__ = find_version()
