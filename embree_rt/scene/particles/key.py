"""What a particle image's colours mean (``legend.Legend``): the colour bar of the property
particles are coloured by, or the key of their element or type colours."""

from __future__ import annotations

import warnings

import numpy as np

from embree_rt.legend import Legend
from embree_rt.scene.particles.frame import ParticleFrame
from embree_rt.scene.particles.look import (
    ParticleLook,
    colormap_colors,
    colormap_range,
    label_look,
    natural_order,
    to_srgb8,
)

# Samples of the colormap a bar holds: one a code of an 8-bit colormap.
BAR_SAMPLES = 256


def particle_legend(frame: ParticleFrame, look: ParticleLook) -> Legend:
    """The ``Legend`` of ``frame``'s particles drawn by ``look``: a bar of ``BAR_SAMPLES``
    colours of its colormap over the property's range, or each element's or type's colour in
    natural order (one colour for all when ``look.color`` is given, titled "all")."""
    kind, labels = frame.labels()
    by = look.color_by or kind
    if look.color is not None:
        return Legend("all", to_srgb8(np.asarray(look.color)[None]), labels=("all",))
    if by in ("element", "type"):
        values = labels if by == kind else (frame.elements if by == "element" else frame.types)
        names = natural_order(values)
        with warnings.catch_warnings():  # (an unknown element was said when it was drawn)
            warnings.simplefilter("ignore")
            colors = to_srgb8(label_look(frame.path, by, names)[0])
        return Legend(by, colors, labels=tuple(str(n) for n in names))
    low, high = colormap_range(frame.properties[by], look.value_range)
    samples = np.linspace(low, high, BAR_SAMPLES)
    colors = colormap_colors(samples, look.colormap, (low, high))
    return Legend(by, colors, value_range=(low, high), colormap=look.colormap)
