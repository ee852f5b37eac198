"""Particle files (simulation snapshots and trajectories) read into ``ParticleFrame``s, and
the colours and radii each particle is drawn with."""

from embree_rt.scene.particles.errors import ParticleFileError
from embree_rt.scene.particles.frame import ParticleFrame
from embree_rt.scene.particles.look import ParticleLook
from embree_rt.scene.particles.read import PARTICLE_SUFFIXES, is_particle_file, read_particles

__all__ = [
    "PARTICLE_SUFFIXES",
    "ParticleFileError",
    "ParticleFrame",
    "ParticleLook",
    "is_particle_file",
    "read_particles",
]
