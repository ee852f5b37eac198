"""A colour legend: what the colours of an image mean, drawn into the bottom-right corner of
its display pixels (a colour bar with its property's name, range and ticks, or a key of
labelled colours) with Pillow's drawing and its scalable default font, and the same as a JSON
record for formats that hold radiance, not pictures."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass

import numpy as np

# The legend's height as a share of the image's, and the least it is drawn at (text smaller
# than this cannot be read).
HEIGHT_SHARE = 0.25
MIN_HEIGHT = 48
PANEL = (255, 255, 255)
INK = (0, 0, 0)
TICKS = 5


@dataclass(frozen=True)
class Legend:
    """What an image's colours mean: ``title`` (a property's name, or "element" / "type");
    for a colour bar ``value_range`` (low, high) and ``colors`` (256, 3) uint8 sRGB, the
    colormap sampled evenly from low to high; for a key ``labels`` (k,) str and ``colors``
    (k, 3) uint8 sRGB, one a label (``value_range`` None)."""

    title: str
    colors: np.ndarray
    value_range: tuple[float, float] | None = None
    labels: tuple[str, ...] = ()
    colormap: str | None = None

    @property
    def is_bar(self) -> bool:
        return self.value_range is not None

    def record(self) -> dict:
        """The legend as plain JSON values: title, and range, colormap and colours (a bar) or
        each label's colour (a key), colours as 8-bit sRGB triples."""
        colors = np.asarray(self.colors).tolist()
        if self.is_bar:
            return {
                "title": self.title,
                "range": list(self.value_range),
                "colormap": self.colormap,
                "colors": colors,
            }
        return {"title": self.title, "colors": dict(zip(self.labels, colors, strict=True))}

    def json_bytes(self) -> bytes:
        return (json.dumps({"legend": self.record()}, indent=2) + "\n").encode()


def tick_values(low: float, high: float, count: int = TICKS) -> np.ndarray:
    """(t,) float64 round tick values within [low, high]: multiples of the least step of 1, 2
    or 5 times a power of ten cutting the range into at most ``count`` parts (low alone when
    low == high)."""
    span = high - low
    if not span > 0:
        return np.array([low])
    base = 10.0 ** math.floor(math.log10(span / count))
    step = next(base * m for m in (1.0, 2.0, 5.0, 10.0) if span / (base * m) <= count)
    first = math.ceil(low / step - 1e-9)
    values = np.arange(first, math.floor(high / step + 1e-9) + 1) * step
    return values[(values >= low - 1e-9 * span) & (values <= high + 1e-9 * span)]


def tick_label(value: float) -> str:
    return f"{value:.4g}" if value != 0 else "0"


def legend_size(legend: Legend, image_height: int) -> int:
    """The legend's height in pixels on an image ``image_height`` tall."""
    return max(MIN_HEIGHT, round(HEIGHT_SHARE * image_height))


def legend_patch(legend: Legend, height: int) -> tuple[np.ndarray, BarPlace | None]:
    """The legend drawn on its panel, ``height`` pixels tall: (height, w, 3) uint8 sRGB, and
    where its colour bar lies in it (None for a key)."""
    from PIL import Image, ImageDraw, ImageFont

    font_size = max(8, height // 7)
    font = ImageFont.load_default(size=font_size)
    pad = max(2, height // 12)
    if legend.is_bar:
        width = round(1.7 * height)
    else:
        widest = max(font.getlength(label) for label in (*legend.labels, legend.title))
        width = round(2 * pad + font_size * 1.4 + widest)
    image = Image.new("RGB", (width, height), PANEL)
    draw = ImageDraw.Draw(image)
    draw.rectangle((0, 0, width - 1, height - 1), outline=INK)
    draw.text((pad, pad), legend.title, fill=INK, font=font)
    top = pad + round(font_size * 1.3)
    if legend.is_bar:
        place = BarPlace(pad, top, width - 2 * pad, max(4, height // 4))
        pixels = np.asarray(image).copy()
        pixels[place.top : place.top + place.height, place.left : place.left + place.width] = (
            bar_colors(legend.colors, place.width)[None]
        )
        image = Image.fromarray(pixels)
        draw = ImageDraw.Draw(image)
        low, high = legend.value_range
        below = place.top + place.height
        for value in tick_values(low, high):
            share = 0.0 if high == low else (value - low) / (high - low)
            x = place.left + round(share * (place.width - 1))
            draw.line((x, below, x, below + pad), fill=INK)
            label = tick_label(float(value))
            half = font.getlength(label) / 2
            left = min(max(x - half, 1), width - 2 * half - 1)
            draw.text((left, below + pad), label, fill=INK, font=font)
        return np.asarray(image), place
    row = round(font_size * 1.2)
    fit = max(1, (height - top - pad) // row)
    shown = legend.labels if len(legend.labels) <= fit else legend.labels[: fit - 1]
    for i, (label, color) in enumerate(zip(shown, legend.colors, strict=False)):
        y = top + i * row
        draw.rectangle((pad, y, pad + font_size, y + font_size), fill=tuple(int(c) for c in color))
        draw.text((pad + round(font_size * 1.4), y), label, fill=INK, font=font)
    if len(shown) < len(legend.labels):
        more = f"+{len(legend.labels) - len(shown)} more"
        draw.text((pad, top + len(shown) * row), more, fill=INK, font=font)
    return np.asarray(image), None


@dataclass(frozen=True)
class BarPlace:
    """Where a colour bar lies in its legend: left, top, width and height in pixels."""

    left: int
    top: int
    width: int
    height: int


def bar_colors(colors: np.ndarray, width: int) -> np.ndarray:
    """(width, 3) uint8: the bar's ``colors`` (m, 3) uint8, sampled low to high, at each of
    ``width`` columns (column c shows sample ``round(c (m - 1) / (width - 1))``)."""
    samples = np.rint(np.linspace(0.0, len(colors) - 1.0, width)).astype(np.intp)
    return np.asarray(colors, np.uint8)[samples]


def legend_margin(image_height: int) -> int:
    """The legend's distance in pixels from the image's edges: 1/40 of its height."""
    return max(2, image_height // 40)


def legend_room(legend: Legend, image_height: int) -> float:
    """The share of an image ``image_height`` tall that the legend and its margins take from
    its bottom (at most 0.9): what a framing keeps clear for it."""
    return min(0.9, kept_rows(legend, image_height) / image_height)


def kept_rows(legend: Legend, image_height: int) -> int:
    """The rows the legend takes from the bottom of an image ``image_height`` tall with its
    margins: one from the image's edge, one of clearance above it."""
    return legend_size(legend, image_height) + 2 * legend_margin(image_height)


def legend_box(legend: Legend, width: int, height: int) -> tuple[int, int]:
    """(columns, rows): the box the legend and its margins take from the bottom-right corner
    of an image ``width`` × ``height`` (the patch ``draw_legend`` draws there, one margin from
    the image's edges and one of clearance from its top and left), at most the image."""
    patch, _ = legend_patch(legend, legend_size(legend, height))
    columns = patch.shape[1] + 2 * legend_margin(height)
    return min(width, columns), min(height, kept_rows(legend, height))


def legend_corner(shape: tuple[int, ...], patch_shape: tuple[int, ...]) -> tuple[int, int]:
    """(top, left) of a legend patch of ``patch_shape`` in an image of ``shape``: the
    bottom-right corner, ``legend_margin`` from its edges."""
    margin = legend_margin(shape[0])
    return max(0, shape[0] - patch_shape[0] - margin), max(0, shape[1] - patch_shape[1] - margin)


def draw_legend(pixels: np.ndarray, legend: Legend) -> np.ndarray:
    """Display ``pixels`` (h, w, 3 or 4) uint8 or uint16 with ``legend`` drawn over their
    bottom-right corner (opaque where an alpha channel is), as a new array; a legend larger
    than the image is cut at its top and left."""
    result = np.array(pixels)
    height = legend_size(legend, result.shape[0])
    patch, _ = legend_patch(legend, height)
    top, left = legend_corner(result.shape, patch.shape)
    patch = patch[-(result.shape[0] - top) :, -(result.shape[1] - left) :]
    scale = 257 if result.dtype == np.uint16 else 1  # 8-bit codes to 16-bit ones
    region = result[top : top + patch.shape[0], left : left + patch.shape[1]]
    region[..., :3] = patch.astype(result.dtype) * result.dtype.type(scale)
    if result.shape[2] == 4:
        region[..., 3] = np.iinfo(result.dtype).max
    return result
