"""What the browser may send, checked before anything acts on it.

Every message is a JSON object with a ``type``; anything else, or anything out of range, raises
``MessageError`` whose text goes back to that client as ``{"type": "error", "message": ...}``.
No field ever names a file: a client edits its scene in memory only.
"""

from __future__ import annotations

import json
import sys

import numpy as np

from embree_rt.web.trace2d import MATERIALS_2D, Layout

# Larger messages are refused unread (a 2D layout of the most circles is ~5 kB).
MAX_MESSAGE_BYTES = 64 * 1024
# The 2D demo's box, in the page's drawing units.
BOX_2D = (960.0, 600.0)
MAX_CIRCLES = 64
MAX_RAYS = 720
RADIUS_2D = (4.0, 300.0)
# Preview sizes the page may ask for: enough for a big window, small enough to stay live.
MAX_PREVIEW_PIXELS = 1280 * 800
MAX_PREVIEW_SIDE = 2048
# Spheres dropped on the floor: a sane range in the scene's units, and how many one session adds.
DROP_RADIUS = (0.01, 100.0)
MAX_DROPPED = 1000


class MessageError(ValueError):
    """A message this server will not act on; ``str()`` says why, in one line."""


def parse(text: str | bytes | None) -> dict:
    """The JSON object in a text message; MessageError for binary, oversized or malformed ones."""
    if not isinstance(text, str):
        raise MessageError("expected a JSON text message")
    if len(text.encode("utf-8", "surrogatepass")) > MAX_MESSAGE_BYTES:
        raise MessageError(f"message too large: the limit is {MAX_MESSAGE_BYTES} bytes")
    try:
        message = json.loads(text)
    except (json.JSONDecodeError, RecursionError) as error:
        raise MessageError(f"malformed JSON: {error}") from None
    except ValueError:  # an int literal beyond Python's limit on digits
        limit = sys.get_int_max_str_digits()
        raise MessageError(f"malformed JSON: an integer of more than {limit} digits") from None
    if not isinstance(message, dict) or not isinstance(message.get("type"), str):
        raise MessageError('expected a JSON object with a string "type"')
    return message


def number(message: dict, key: str, low: float, high: float) -> float:
    """``message[key]`` as a finite float in [low, high]."""
    value = message.get(key)
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise MessageError(f"{key}: expected a number, got {_short(value)}")
    # Compared before float(): an int of 400 digits is beyond float range (OverflowError).
    if not (low <= value <= high):  # NaN fails it too
        raise MessageError(f"{key}: must lie in [{low:g}, {high:g}], got {_short(value)}")
    return float(value)


def integer(message: dict, key: str, low: int, high: int) -> int:
    """``message[key]`` as an int in [low, high]."""
    value = message.get(key)
    if isinstance(value, bool) or not isinstance(value, int):
        raise MessageError(f"{key}: expected an integer, got {_short(value)}")
    if not low <= value <= high:
        raise MessageError(f"{key}: must lie in [{low}, {high}], got {_short(value)}")
    return value


def vector(message: dict, key: str, size: int, bound: float = 1e6) -> tuple[float, ...]:
    """``message[key]`` as ``size`` finite floats, each within ``bound`` of zero."""
    values = message.get(key)
    if not isinstance(values, list) or len(values) != size:
        raise MessageError(f"{key}: expected {size} numbers, got {_short(values)}")
    return tuple(number({key: v}, key, -bound, bound) for v in values)


def choice(message: dict, key: str, options) -> str:
    """``message[key]``, which must be one of ``options``."""
    value = message.get(key)
    if not isinstance(value, str) or value not in options:
        raise MessageError(f"{key}: expected one of {', '.join(options)}, got {_short(value)}")
    return value


def layout_2d(message: dict) -> Layout:
    """A ``trace`` message of the 2D demo as a ``Layout``: ``circles`` a list of {x, y, r,
    material}, ``light`` [x, y] inside the box, ``rays``, ``spread`` and ``aim`` (degrees)."""
    width, height = BOX_2D
    circles = message.get("circles")
    if not isinstance(circles, list) or len(circles) > MAX_CIRCLES:
        raise MessageError(f"circles: expected a list of at most {MAX_CIRCLES} circles")
    rows, materials = [], []
    for circle in circles:
        if not isinstance(circle, dict):
            raise MessageError("circles: each circle is an object {x, y, r, material}")
        rows.append(
            (
                number(circle, "x", -width, 2 * width),
                number(circle, "y", -height, 2 * height),
                number(circle, "r", *RADIUS_2D),
            )
        )
        materials.append(MATERIALS_2D.index(choice(circle, "material", MATERIALS_2D)))
    light = vector(message, "light", 2)
    if not (0.0 <= light[0] <= width and 0.0 <= light[1] <= height):
        raise MessageError(f"light: must lie in the box [0, {width:g}] x [0, {height:g}]")
    return Layout(
        circles=np.asarray(rows, np.float64).reshape(-1, 3),
        materials=np.asarray(materials, np.int64),
        light=(light[0], light[1]),
        rays=integer(message, "rays", 1, MAX_RAYS),
        spread=number(message, "spread", 0.0, 360.0),
        aim=number(message, "aim", -360.0, 360.0),
        width=width,
        height=height,
    )


def _short(value: object) -> str:
    text = json.dumps(value) if not isinstance(value, str) else repr(value)
    return text if len(text) <= 40 else text[:37] + "..."
