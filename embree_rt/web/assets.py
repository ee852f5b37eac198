"""The pages, scripts and styles the server sends: read once from the package, kept in memory.

A request's path is only ever a key into ``load_assets()``'s table, never joined to a
directory, so no request can reach the file system.
"""

from __future__ import annotations

from dataclasses import dataclass
from importlib import resources

# Every file the server may send, by the name it is served under, with its media type.
STATIC_FILES = {
    "style.css": "text/css; charset=utf-8",
    "preview.js": "text/javascript; charset=utf-8",
    "demo2d.js": "text/javascript; charset=utf-8",
    "common.js": "text/javascript; charset=utf-8",
}
PAGES = {"/": "index.html", "/2d": "2d.html"}
HTML = "text/html; charset=utf-8"


@dataclass(frozen=True)
class Asset:
    body: bytes
    media_type: str


def load_assets() -> tuple[dict[str, Asset], dict[str, Asset]]:
    """(static files by name, pages by route path), read from ``embree_rt/web/static``."""
    folder = resources.files("embree_rt.web") / "static"
    static = {
        name: Asset(folder.joinpath(name).read_bytes(), kind) for name, kind in STATIC_FILES.items()
    }
    pages = {
        route: Asset(folder.joinpath(name).read_bytes(), HTML) for route, name in PAGES.items()
    }
    return static, pages
