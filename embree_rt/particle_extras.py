"""What is drawn of a particle file beside its spheres (the simulation box, bonds as sticks, a
colour legend), described once: the command line's flags and a scene file's ``[[particles]]``
keys are both made from ``ParticleExtras``' fields, and both check what they read with
``extras_problem``. A module without NumPy, so that ``embree-rt --help`` lists the flags
without loading the scene."""

from __future__ import annotations

import dataclasses
import math
import numbers
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from embree_rt.errors import range_problem


def _option(default: bool | None, help: str, metavar: str | None = None) -> Any:
    return dataclasses.field(default=default, metadata={"help": help, "metavar": metavar})


@dataclass(frozen=True)
class ParticleExtras:
    """What is drawn beside a particle file's spheres. Each field is a scene file's
    ``[[particles]]`` key and, with ``-`` for ``_``, a command-line flag (``--bond-radius``):
    a field whose default is False is a switch, one whose default is None a number > 0. Its
    ``metadata`` holds the option's ``help`` and the flag's ``metavar``."""

    box: bool = _option(False, "draw the simulation box as thin lines")
    bonds: bool = _option(
        False, "sticks between bonded atoms (the file's bonds, else guessed from distances)"
    )
    bond_radius: float | None = _option(None, "the sticks' radius", "R")
    licorice: bool = _option(False, "bonds, and atoms of the sticks' radius")
    legend: bool = _option(
        False, "draw what the colours mean (a colour bar or a key) in the image's corner"
    )

    @property
    def draws_bonds(self) -> bool:
        """Whether bonds are drawn: licorice is sticks and atoms of one radius, so it draws
        them too."""
        return self.bonds or self.licorice


EXTRA_OPTIONS: tuple[dataclasses.Field, ...] = dataclasses.fields(ParticleExtras)


def is_switch(option: dataclasses.Field) -> bool:
    """Whether ``option`` (one of ``EXTRA_OPTIONS``) is a switch, else a number > 0."""
    return option.default is False


def extras_problem(
    extras: ParticleExtras, name: Callable[[str], str] = str
) -> tuple[str, str] | None:
    """What is wrong with ``extras``, as (field, problem), or None: ``bond_radius`` a finite
    number > 0, and only with bonds (it sets the sticks' radius). The problem names another
    option by ``name`` of its field (the flag's spelling on the command line)."""
    radius = extras.bond_radius
    if radius is None:
        return None
    if isinstance(radius, bool) or not isinstance(radius, numbers.Real):
        return "bond_radius", f"expected a number, got {radius!r}"
    if not math.isfinite(radius):
        return "bond_radius", f"must be finite, got {radius}"
    if (problem := range_problem(radius, 0.0, low_open=True)) is not None:
        return "bond_radius", problem
    if not extras.draws_bonds:
        needs = f"{name('bonds')} (or {name('licorice')})"
        return "bond_radius", f"sets the sticks' radius, so it needs {needs}"
    return None
