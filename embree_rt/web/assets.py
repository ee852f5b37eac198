"""The pages, scripts and styles the server sends: read once from the package, kept in memory.

A request's path is only ever a key into ``load_assets()``'s table, never joined to a
directory, so no request can reach the file system.

Every page is one frame (``static/frame.html``: head, header with the pages' links, scripts)
around its own ``<main>`` (``static/NAME.html``), filled in once at start.
"""

from __future__ import annotations

from dataclasses import dataclass
from html import escape
from importlib import resources
from string import Template

# Every file the server may send, by the name it is served under, with its media type.
STATIC_FILES = {
    "style.css": "text/css; charset=utf-8",
    "preview.js": "text/javascript; charset=utf-8",
    "demo2d.js": "text/javascript; charset=utf-8",
    "common.js": "text/javascript; charset=utf-8",
}
HTML = "text/html; charset=utf-8"


@dataclass(frozen=True)
class Page:
    """One page of the site. ``static/NAME.html`` holds its ``<main>`` and ``NAME.js`` is its
    script; ``link`` is its entry in every page's header, ``title`` follows "embree_rt · " in
    the tab, ``hint`` is the header's right-hand line (the preview's script fills its own)."""

    route: str
    name: str
    link: str
    title: str
    hint: str = ""


PAGES = (
    Page("/", "preview", "Live preview", "live preview"),
    Page(
        "/2d",
        "demo2d",
        "2D ray demo",
        "2D rays",
        "traced by embree_rt's BVH and shading on the server; the page only draws",
    ),
)


@dataclass(frozen=True)
class Asset:
    body: bytes
    media_type: str


def _nav(current: Page) -> str:
    """The header's links, the current page's marked."""
    links = []
    for page in PAGES:
        mark = ' class="current"' if page is current else ""
        links.append(f'<a href="{page.route}"{mark}>{escape(page.link)}</a>')
    return "".join(links)


def load_assets() -> tuple[dict[str, Asset], dict[str, Asset]]:
    """(static files by name, pages by route path), read from ``embree_rt/web/static``."""
    folder = resources.files("embree_rt.web") / "static"
    static = {
        name: Asset(folder.joinpath(name).read_bytes(), kind) for name, kind in STATIC_FILES.items()
    }
    frame = Template(folder.joinpath("frame.html").read_text(encoding="utf-8"))
    pages = {
        page.route: Asset(
            frame.substitute(
                title=escape(page.title),
                nav=_nav(page),
                hint=escape(page.hint, quote=False),
                main=folder.joinpath(f"{page.name}.html").read_text(encoding="utf-8").rstrip(),
                script=f"{page.name}.js",
            ).encode(),
            HTML,
        )
        for page in PAGES
    }
    return static, pages
