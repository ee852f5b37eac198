"""Ambient occlusion: the share of a surface point's cosine-weighted hemisphere that is open.

Each of a hit's ``samples`` directions is drawn from the counter-based hash
(``sampling.uniform_pair``) at the index ``sample_index * samples + j``, so a hit's directions
depend on its camera sample's global index and the seed alone: the same bits whatever the
threads, batch size or machine. The fraction of those rays that nothing blocks within
``distance`` estimates the cosine-weighted open share (the integral of cos θ / π over the
unblocked directions), which scales the ambient term of the hit.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from embree_rt.sampling import uniform_pair

# The hash dimension of ambient occlusion's directions (the camera's jitter is dimension 0).
AO_DIMENSION = 7
# The hash dimensions between ambient occlusion's directions at one bounce and the next: far
# past every dimension the camera and AO draw at one depth.
BOUNCE_DIMENSIONS = 1000


@dataclass(frozen=True)
class AmbientOcclusion:
    """A render's ambient occlusion: ``samples`` rays a camera-ray hit (0: off), each blocked
    by what lies within ``distance`` world units (inf: anything); with ``bounces`` the hits of
    reflected and refracted rays take it too (else they keep the plain ambient term)."""

    samples: int = 0
    distance: float = math.inf
    bounces: bool = False


def ao_problem(ao: AmbientOcclusion) -> tuple[str, str] | None:
    """What is wrong with ``ao``, as (field, problem), or None: ``samples`` an integer from 0
    to 4096, ``distance`` a number > 0 (inf allowed)."""
    samples = ao.samples
    if isinstance(samples, bool) or not isinstance(samples, int) or not 0 <= samples <= 4096:
        return "samples", f"expected an integer from 0 to 4096, got {samples!r}"
    try:
        distance = float(ao.distance)
    except (TypeError, ValueError):
        return "distance", f"expected a number of world units, got {ao.distance!r}"
    if not distance > 0.0:  # (NaN fails too)
        return "distance", f"must be > 0 (inf: unlimited), got {ao.distance!r}"
    return None


class HemisphereFrames(NamedTuple):
    """k surface points' orthonormal frames, right-handed: ``tangent``, ``bitangent`` and the
    unit ``normal`` (3, k) float32 each (a direction's local x, y and z)."""

    tangent: np.ndarray
    bitangent: np.ndarray
    normal: np.ndarray


class HemisphereQuery(NamedTuple):
    """Ambient occlusion's n = k * samples rays, one occlusion batch: ray r from the point
    ``points[:, r // samples]`` ((3, k) float32) along ``local[:, r]`` ((3, n) float32 unit)
    turned by that point's ``frames`` into ``t x + b y + n z``, normalised in float32; each
    blocked by what lies within ``distance`` (float, inf: any)."""

    points: np.ndarray
    frames: HemisphereFrames
    local: np.ndarray
    distance: float


def orthonormal_frames(normal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two (3, k) float32 unit tangents ``t``, ``b`` with (t, b, n) right-handed and
    orthonormal for the (3, k) float32 unit ``normal`` columns (Duff et al. 2017's branchless
    frame: no division by a small number for any normal)."""
    x, y, z = normal
    sign = np.where(z >= 0, np.float32(1.0), np.float32(-1.0))
    a = np.float32(-1.0) / (sign + z)
    b = x * y * a
    tangent = np.stack([np.float32(1.0) + sign * x * x * a, sign * b, -sign * x])
    bitangent = np.stack([b, sign + y * y * a, -y])
    return tangent.astype(np.float32, copy=False), bitangent.astype(np.float32, copy=False)


def cosine_local_directions(
    sample_index: np.ndarray, samples: int, seed: int, bounce: int = 0
) -> np.ndarray:
    """(3, k * samples) float32 unit directions (x, y, z) in a frame whose z is the normal,
    cosine-weighted over its hemisphere: hit i's ``samples`` directions are columns
    ``i * samples .. i * samples + samples - 1``, drawn at hash indices
    ``sample_index[i] * samples + j`` ((k,) int64 the hits' camera sample indices) of
    dimension ``AO_DIMENSION`` at the camera rays' hits, ``BOUNCE_DIMENSIONS`` more at each
    ``bounce`` after them (a reflected hit's directions independent of its camera hit's)
    (Malley's method: a uniform point on the unit disc lifted to the hemisphere). The world's
    direction of column r is ``t x + b y + n z`` in hit i's frame (``orthonormal_frames``),
    normalised in float32: the tracer forms it as it traces (``Tracer.occluded_hemispheres``)."""
    index = (np.asarray(sample_index, np.int64)[:, None] * samples + np.arange(samples)).ravel()
    u1, u2 = uniform_pair(seed, index, AO_DIMENSION + BOUNCE_DIMENSIONS * bounce)
    radius = np.sqrt(u1)
    phi = np.float32(2.0 * math.pi) * u2
    local = np.empty((3, len(index)), np.float32)
    np.multiply(radius, np.cos(phi), out=local[0])
    np.multiply(radius, np.sin(phi), out=local[1])
    np.sqrt(np.maximum(np.float32(1.0) - u1, np.float32(0.0)), out=local[2])
    return local


def open_share(blocked: np.ndarray, samples: int) -> np.ndarray:
    """(k,) float32 share of each hit's ``samples`` rays not ``blocked`` ((k * samples,)
    bool, a hit's rays together)."""
    unblocked = (~blocked).reshape(-1, samples).sum(axis=1)
    return (unblocked / np.float32(samples)).astype(np.float32)


def open_shares(
    occluded_hemispheres,
    points: np.ndarray,
    normal: np.ndarray,
    sample_index: np.ndarray,
    ao,
    seed: int,
    bounce: int = 0,
) -> np.ndarray:
    """(k,) float32 open share of the hemisphere over each of the k ``points`` (3, k) float32
    (already off their surfaces) about the unit ``normal`` (3, k) float32 (facing the side the
    point is seen from), ``ao`` an ``AmbientOcclusion`` with samples > 0: its rays in one
    occlusion batch through ``occluded_hemispheres(HemisphereQuery)`` (the tracer's,
    ``Tracer.occluded_hemispheres`` -> (k * samples,) bool), the directions of
    ``cosine_local_directions`` at the (k,) int64 camera ``sample_index``, ``seed`` and
    ``bounce`` (0: camera rays' hits) about the ``HemisphereFrames`` of ``orthonormal_frames``."""
    samples = ao.samples
    local = cosine_local_directions(sample_index, samples, seed, bounce)
    frames = HemisphereFrames(*orthonormal_frames(normal), normal)
    rays = HemisphereQuery(points, frames, local, float(ao.distance))
    return open_share(occluded_hemispheres(rays), samples)
