"""The summary line of a render: the command's whole wall time, from the process's start, split
into start-up, compile, reading or generating the scene, the BVH (or the cluster's set-up),
rendering and output, and the rays it traced."""

from __future__ import annotations

import sys
import time
from typing import NamedTuple

from embree_rt.cli.clock import CompileClock, process_age_s


class Phases(NamedTuple):
    """Seconds of each phase; they add up to ``total``."""

    startup: float
    compile: float
    made: float
    setup: float
    render: float
    output: float

    @property
    def total(self) -> float:
        return sum(self)


class Timeline:
    """The moments a command passes (``time.perf_counter``): its start (``begun``, with the
    process's age then), the scene made (``scene_started`` .. ``scene_made``) and the render
    done (``rendered``); with the ``CompileClock`` that heard numba compile meanwhile."""

    def __init__(self, clock: CompileClock) -> None:
        self.clock = clock
        self.age_at_begin = process_age_s()
        self.begun = time.perf_counter()
        self.scene_started = self.scene_made = self.rendered = self.begun

    def mark_scene_started(self) -> None:
        self.scene_started = time.perf_counter()

    def mark_scene_made(self) -> None:
        self.scene_made = time.perf_counter()

    def mark_rendered(self) -> None:
        self.rendered = time.perf_counter()

    def phases(self, render_s: float) -> Phases:
        """The phases up to now, ``render_s`` the seconds spent rendering, which end at
        ``rendered``; the set-up is the rest between the scene and the render (the BVH's
        build, or starting the cluster and its workers' builds)."""
        now = time.perf_counter()
        compiled = self.clock.seconds
        render_start = self.rendered - render_s
        return Phases(
            startup=self.age_at_begin
            + self.scene_started
            - self.begun
            - compiled(self.begun, self.scene_started),
            compile=compiled(),
            made=self.scene_made
            - self.scene_started
            - compiled(self.scene_started, self.scene_made),
            setup=render_start - self.scene_made - compiled(self.scene_made, render_start),
            render=render_s - compiled(render_start, self.rendered),
            output=now - self.rendered - compiled(self.rendered, now),
        )


def print_summary(
    timeline: Timeline,
    *,
    what: str,
    made_verb: str,
    setup_name: str,
    render_s: float,
    rays: int,
    output: str,
) -> None:
    """Print the summary line: ``what`` was rendered ("16x9 at 1 spp", with frames and where),
    the phases' seconds (the scene ``made_verb``: "load" or "generate"; the set-up called
    ``setup_name``: "BVH" or "cluster"), ``rays`` traced in ``render_s``, and the ``output``."""
    phases = timeline.phases(render_s)
    rate = rays / max(render_s, 1e-9) / 1e6
    print(
        f"embree-rt: {what} in {phases.total:.2f} s (start-up {phases.startup:.2f} s, compile "
        f"{phases.compile:.2f} s, {made_verb} {phases.made:.2f} s, {setup_name} "
        f"{phases.setup:.2f} s, render {phases.render:.2f} s, output {phases.output:.2f} s): "
        f"{rays:,} rays, {rate:.1f} Mrays/s -> {output}",
        file=sys.stderr,
    )
