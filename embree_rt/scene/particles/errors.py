"""Problems in a particle file: ``ParticleFileError`` (a ``SceneError`` naming file, where in
it, and the problem) and the refusal of a count that would not fit in memory."""

from __future__ import annotations

from embree_rt.memory import available_memory, format_bytes
from embree_rt.scene.errors import SceneError

# Reading a particle: its float64 position and the text or arrays it is parsed from (a dump row
# of ~5 numbers is parsed into float64 columns, then copied once).
READ_BYTES_PER_PARTICLE = 160


class ParticleFileError(SceneError):
    """Bad input in a particle file: ``FILE: WHERE: problem`` on one line."""


def check_count(path: str, where: str, count: int) -> None:
    """Refuse a header's particle ``count`` that is negative or would not fit in memory,
    before anything of that size is allocated."""
    if count < 0:
        raise ParticleFileError(path, where, f"a negative particle count ({count})")
    available = available_memory()
    needed = count * READ_BYTES_PER_PARTICLE
    if available is not None and needed > available:
        raise ParticleFileError(
            path,
            where,
            f"the header claims {count:,} particles, which would need ~{format_bytes(needed)} "
            f"of memory to read; this machine has {format_bytes(available)} available",
        )
