"""Typed reading of scene-file values: each reader names the key it rejects.

A key that is absent takes its default (unchecked: defaults are trusted); a key that is present is
always checked, so a JSON ``null`` is an error, not a silent default.
"""

from __future__ import annotations

import difflib
from collections.abc import Mapping
from typing import Any

from embree_rt.scene.errors import SceneError, unknown_key_message
from embree_rt.scene.limits import (
    INTEGER_LIMIT,
    color_problem,
    number_problem,
    shown,
    vector_problem,
)

_ABSENT = object()


class Table:
    """One table of a scene file, read key by key; ``finish()`` rejects keys nobody read."""

    def __init__(self, file: object, path: str, data: object) -> None:
        if not isinstance(data, Mapping):
            raise SceneError(file, path or "(top level)", f"expected a table, got {_kind(data)}")
        self.file = file
        self.path = path
        self.data = data
        self.known: set[str] = set()

    def key(self, name: str) -> str:
        return f"{self.path}.{name}" if self.path else name

    def error(self, name: str, problem: str) -> SceneError:
        return SceneError(self.file, self.key(name), problem)

    def has(self, name: str) -> bool:
        self.known.add(name)
        return name in self.data

    def raw(self, name: str, default: Any = None) -> Any:
        self.known.add(name)
        return self.data.get(name, default)

    def _value(self, name: str, required: bool) -> Any:
        """The value at ``name``, or ``_ABSENT``; a missing required key is an error that points
        at a misspelling of it when there is one (``radious`` for ``radius``)."""
        self.known.add(name)
        if name in self.data:
            return self.data[name]
        if required:
            strangers = [key for key in self.data if key not in self.known]
            close = difflib.get_close_matches(name, strangers, n=1, cutoff=0.6)
            if close:
                raise self.error(close[0], f"unknown key (did you mean {name!r}?)")
            raise self.error(name, "is required")
        return _ABSENT

    def require(self, name: str) -> Any:
        return self._value(name, required=True)

    def number(
        self,
        name: str,
        default: float | None = None,
        *,
        low: float | None = None,
        high: float | None = None,
        low_open: bool = False,
        high_open: bool = False,
        required: bool = False,
    ) -> float | None:
        value = self._value(name, required)
        if value is _ABSENT:
            return default
        return check_number(self, name, value, low, high, low_open, high_open)

    def integer(
        self,
        name: str,
        default: int | None = None,
        *,
        low: int | None = None,
        high: int = INTEGER_LIMIT,
    ) -> int:
        """An integer in [low, high] (``high`` by default what int64 holds)."""
        value = self._value(name, required=False)
        if value is _ABSENT:
            return default
        if isinstance(value, bool) or not isinstance(value, int):
            raise self.error(name, f"expected an integer, got {shown(value)}")
        if low is not None and value < low:
            raise self.error(name, f"must be >= {low}, got {shown(value)}")
        if value > high:
            raise self.error(name, f"must be <= {high}, got {shown(value)}")
        return value

    def boolean(self, name: str, default: bool) -> bool:
        value = self._value(name, required=False)
        if value is _ABSENT:
            return default
        if not isinstance(value, bool):
            raise self.error(name, f"expected true or false, got {shown(value)}")
        return value

    def string(self, name: str, default: str | None = None, *, required: bool = False) -> str:
        value = self._value(name, required)
        if value is _ABSENT:
            return default
        if not isinstance(value, str) or not value:
            raise self.error(name, f"expected a non-empty string, got {shown(value)}")
        return value

    def file_name(self, name: str) -> str:
        """A required file name: a non-empty string the operating system can take (no NUL)."""
        value = self.string(name, required=True)
        if "\0" in value:
            raise self.error(name, f"a file name cannot hold a NUL character, got {shown(value)}")
        return value

    def vector(
        self,
        name: str,
        default=None,
        *,
        required: bool = False,
        non_negative=False,
        high: float | None = None,
    ):
        """Three finite numbers as a tuple of floats, each at most ``high`` if given."""
        value = self._value(name, required)
        if value is _ABSENT:
            return default
        if (problem := vector_problem(value, non_negative=non_negative, high=high)) is not None:
            raise self.error(name, problem)
        return tuple(float(item) for item in value)

    def pair(
        self, name: str, *, low: float | None = None, low_open: bool = False
    ) -> tuple[float, float]:
        """A required ``[min, max]`` with ``min <= max``, both checked against ``low``."""
        value = self.require(name)
        if not isinstance(value, list | tuple) or len(value) != 2:
            raise self.error(name, f"expected [min, max], got {shown(value)}")
        low_value, high_value = (
            check_number(self, name, item, low, None, low_open, False) for item in value
        )
        if low_value > high_value:
            raise self.error(name, f"expected min <= max, got {shown(value)}")
        return low_value, high_value

    def color(self, name: str, default=None):
        """A colour: three numbers from 0 to ``RADIANCE_LIMIT`` (``limits.color_problem``)."""
        value = self._value(name, required=False)
        if value is _ABSENT:
            return default
        if (problem := color_problem(value)) is not None:
            raise self.error(name, problem)
        return tuple(float(item) for item in value)

    def table(self, name: str) -> Table | None:
        """The sub-table at ``name``, or None when absent."""
        value = self._value(name, required=False)
        return None if value is _ABSENT else Table(self.file, self.key(name), value)

    def tables(self, name: str) -> list[Table]:
        """The array of tables at ``name`` (``[[name]]`` in TOML), empty when absent."""
        value = self._value(name, required=False)
        if value is _ABSENT:
            return []
        if not isinstance(value, list):
            raise self.error(name, f"expected a list of tables, got {_kind(value)}")
        return [Table(self.file, f"{self.key(name)}[{i}]", item) for i, item in enumerate(value)]

    def finish(self) -> None:
        for name in self.data:
            if name not in self.known:
                raise SceneError(self.file, self.key(name), unknown_key_message(name, self.known))


def check_number(table, name, value, low, high, low_open, high_open) -> float:
    """``value`` at ``table``'s key ``name`` as a float, or its ``limits.number_problem`` as a
    ``SceneError``."""
    problem = number_problem(value, low, high, low_open=low_open, high_open=high_open)
    if problem is not None:
        raise table.error(name, problem)
    return float(value)


def _kind(value: object) -> str:
    return {list: "a list", dict: "a table", str: "a string"}.get(type(value), shown(value))
