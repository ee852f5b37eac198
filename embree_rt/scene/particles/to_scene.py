"""A particle frame as spheres in the renderer's world: selected, wrapped into its box, turned
so the file's up axis is the renderer's +y, coloured and sized (``look``)."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from embree_rt.particle_extras import ParticleExtras
from embree_rt.scene.particles.bonds import BondLook
from embree_rt.scene.particles.box import box_edges, box_radius
from embree_rt.scene.particles.errors import ParticleFileError
from embree_rt.scene.particles.frame import ParticleFrame, gathered, kept_bonds
from embree_rt.scene.particles.look import ParticleLook, particle_look

# Rotations (det +1) taking a file's up axis to the renderer's +y (its floor is y = height).
UP_ROTATIONS = {
    "x": np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]]),
    "y": np.eye(3),
    "z": np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]]),
}


def turned_up(positions: np.ndarray, up: str) -> np.ndarray:
    """(n, 3) ``positions`` (n, 3) turned so the file's ``up`` axis is the renderer's +y, in
    their own dtype: ``positions @ UP_ROTATIONS[up].T`` as NumPy's product gives it in float64,
    bit for bit. Each rotation's row holds one entry of +-1 and zeros, so a coordinate is one
    file coordinate or its negation, exact in float32 as in float64, and the product's sum
    starting from +0 makes a zero +0 (the ``+= 0.0``)."""
    rotation = UP_ROTATIONS[up]
    turned = np.empty(positions.shape, positions.dtype)  # (C order, as Embree reads it)
    for row, column in enumerate(np.argmax(np.abs(rotation), axis=1)):
        sign = positions.dtype.type(rotation[row, column])
        np.multiply(positions[:, column], sign, out=turned[:, row])
    turned += positions.dtype.type(0.0)
    return turned


def as_frame(particles) -> ParticleFrame:
    """A ``ParticleFrame`` of a ``ParticleFrame``, an ``ase.Atoms`` or an MDAnalysis
    ``AtomGroup`` (or ``Universe``). TypeError for anything else."""
    if isinstance(particles, ParticleFrame):
        return particles
    kind = type(particles).__module__.split(".")[0]
    if kind == "ase":
        frame = ParticleFrame(
            path="ase.Atoms",
            positions=np.asarray(particles.get_positions(), np.float64),
        )
        frame.elements = particles.get_chemical_symbols()
        if np.any(particles.cell[:]):
            frame.box = np.asarray(particles.cell[:], np.float64)
        return frame
    if kind == "MDAnalysis":
        atoms = getattr(particles, "atoms", particles)
        frame = ParticleFrame(path="MDAnalysis.AtomGroup", positions=np.asarray(atoms.positions))
        if hasattr(atoms, "types"):
            frame.types = np.asarray(atoms.types, dtype=str)
        if hasattr(atoms, "elements") and np.all(np.asarray(atoms.elements, str) != ""):
            frame.elements = np.char.capitalize(np.asarray(atoms.elements, dtype=str))
        if hasattr(atoms, "radii"):
            frame.radii = np.asarray(atoms.radii, np.float64)
        if hasattr(atoms, "bonds") and len(atoms.bonds):
            frame.bonds = kept_bonds(atoms.bonds.indices, atoms.indices, len(atoms.universe.atoms))
        frame.source = atoms.universe
        return frame
    raise TypeError(
        "particles: expected a ParticleFrame, an ase.Atoms or an MDAnalysis AtomGroup, "
        f"got {type(particles).__name__}"
    )


def selected(frame: ParticleFrame, expression: str) -> ParticleFrame:
    """The particles MDAnalysis's selection ``expression`` picks ("not resname SOL", "type 1
    2", "element O"; a frame not read by MDAnalysis is given a Universe of its types,
    elements and positions). ``ParticleFileError`` for a selection it cannot parse or one
    that keeps nothing."""
    import MDAnalysis

    universe = frame.source
    if not isinstance(universe, MDAnalysis.Universe) or len(universe.atoms) != len(frame):
        universe = MDAnalysis.Universe.empty(len(frame), trajectory=True)
        universe.atoms.positions = frame.positions
        _, labels = frame.labels()
        universe.add_TopologyAttr("types", frame.types if frame.types is not None else labels)
        universe.add_TopologyAttr("names", labels)
        if frame.elements is not None:
            universe.add_TopologyAttr("elements", frame.elements)
    try:
        indices = universe.select_atoms(expression).indices
    except Exception as error:  # MDAnalysis raises SelectionError, ValueError...
        raise ParticleFileError(frame.path, "--select", " ".join(str(error).split())) from None
    if len(indices) == 0:
        raise ParticleFileError(frame.path, "--select", f"{expression!r} keeps no particles")
    return frame.subset(np.sort(indices))


def prepared(particles, select: str | None = None) -> ParticleFrame:
    """The ``ParticleFrame`` of ``particles`` (``as_frame``), ``select`` keeping a subset."""
    frame = as_frame(particles)
    return selected(frame, select) if select else frame


def particle_materials(
    frame: ParticleFrame, materials: Mapping[str, str] | None, default: str
) -> np.ndarray | str:
    """Each particle's material name: ``materials`` maps a type (an element where the file
    names no types) to a material's name, the rest take ``default``. Returns ``default`` itself
    when ``materials`` is empty, else (n,) str. ``ParticleFileError`` for a key no particle
    has (a mistyped type would otherwise change nothing unnoticed)."""
    if not materials:
        return default
    kind, labelled = frame.label_codes()
    if frame.type_labels is not None:
        kind, labelled = "type", frame.type_labels
    present = set(labelled.names.tolist())
    missing = sorted(set(materials) - present)
    if missing:
        raise ParticleFileError(
            frame.path,
            "materials",
            f"no particle of {kind} {missing[0]!r} (the {kind}s: {', '.join(sorted(present))})",
        )
    table = np.array([materials.get(name, default) for name in labelled.names.tolist()], str)
    return gathered(table, labelled.codes)


def box_lines(frame: ParticleFrame, up: str = "z") -> tuple[np.ndarray, float]:
    """(24, 3) float64 end points of the frame's box edges in the renderer's world (pairs:
    ``box.box_edges``) and their radius. ``ParticleFileError`` when the file gives no box."""
    if frame.box is None or abs(np.linalg.det(frame.box)) == 0:
        raise ParticleFileError(frame.path, "--box", "the file gives no simulation box")
    edges = box_edges(frame.box, frame.origin)
    return edges @ UP_ROTATIONS[up].T, box_radius(frame.box)


def wrapped(frame: ParticleFrame) -> np.ndarray:
    """(n, 3) float64 positions put into the frame's periodic box (fractional coordinates
    taken modulo 1). ``ParticleFileError`` when the file gives no box."""
    if frame.box is None or abs(np.linalg.det(frame.box)) == 0:
        raise ParticleFileError(frame.path, "--wrap", "the file gives no periodic box")
    fractions = np.linalg.solve(frame.box.T, (frame.positions - frame.origin).T).T
    return frame.origin + (fractions - np.floor(fractions)) @ frame.box


def particle_spheres(
    particles,
    look: ParticleLook | None = None,
    up: str = "z",
    select: str | None = None,
    wrap: bool = False,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, str]:
    """(n, 3) centres in the renderer's world (the positions' dtype, float64 when ``wrap``),
    (n,) float64 radii, (n, 3) uint8 sRGB colours of ``particles`` (``as_frame``), and a note
    saying what was drawn."""
    if up not in UP_ROTATIONS:
        raise ValueError(f"up: expected one of x, y, z, got {up!r}")
    frame = as_frame(particles)
    if select:
        frame = selected(frame, select)
    positions = wrapped(frame) if wrap else frame.positions
    colors, radii = particle_look(frame, look or ParticleLook())
    bad = ~(np.isfinite(radii) & (radii > 0))
    if bad.any():
        row = int(np.argmax(bad))
        raise ParticleFileError(
            frame.path, "radius", f"particle {row}: {radii[row]:g} is not positive"
        )
    centers = turned_up(positions, up)
    kind, _ = frame.label_codes()
    by = (look.color_by if look else None) or kind
    note = (
        f"particles: {len(frame):,} from {frame.path} (frame {frame.frame} of "
        f"{frame.frame_count}), coloured by {by}, {up} up"
    )
    return centers, radii, colors, note


def extras_arguments(extras: ParticleExtras) -> dict:
    """``Scene.add_particles``' (and ``from_particles``') ``box``, ``bonds`` and ``legend``
    arguments of ``extras`` (``particle_extras.ParticleExtras``, as a flag or a scene file's
    key gives them): one reading for both."""
    bonds = BondLook(extras.bond_radius, extras.licorice) if extras.draws_bonds else None
    return {"box": extras.box, "bonds": bonds, "legend": extras.legend}
