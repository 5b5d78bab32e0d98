"""The main job as one function: an identification from the settings tree to a typed result.

    from vlr import load_settings, run_identification

    settings = load_settings({"world.object": "apple", "filter.particles": 6000,
                              "loop.max_iterations": 10})
    run = run_identification(settings)
    print(run.theta_deg, run.errors)

`run_identification` opens the world (`vlr.world.open_world`), runs Algorithm 1
(`vlr.identify.identify`) and scores the result against the world's truth where it has one
(scoring only: the filter never sees it). `vlr identify`, `vlr sweep` and the tasks call it.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from vlr.settings import Settings
from vlr.world import World, open_world

__all__ = ["Identification", "run_identification"]

_LOG = logging.getLogger(__name__)


@dataclass
class Identification:
    """What one identification produced.

    Attributes:
        settings: the settings tree it ran (`vlr.settings.Settings`).
        result: the loop's outcome (`vlr.identify.IdentifyResult`): estimates with their 95%
            intervals (`theta`, `unknowns`, `contacts`), convergence, the per-iteration
            history and, where the world has a truth, the per-iteration scores.
        model: the filter's hand model.
        truths: the world's truth at each update (scoring only; empty on the real hand).
        summary: the `result.json` content (`vlr.results.summarize`).
        filter: the particle filter at the end (`vlr.filter.ParticleFilter`), its particles
            the last posterior after the jitter.
    """

    settings: Settings
    result: Any
    model: Any
    truths: list
    summary: dict[str, Any]
    filter: Any = None

    @property
    def theta_deg(self) -> dict[str, float]:
        """Each joint's posterior median [deg], "finger.k"."""
        return {k: float(np.degrees(e.median)) for k, e in self.result.theta.items()}

    @property
    def unknowns(self) -> dict[str, Any]:
        """{spec: `vlr.identify.Estimate`} of the unknowns (SI units)."""
        return self.result.unknowns

    @property
    def errors(self) -> dict[str, Any] | None:
        """Errors against the truth at the end (posterior median; None without a truth)."""
        return self.summary.get("errors_median")

    @property
    def converged(self) -> bool:
        return bool(self.result.converged)

    def write(self, out: str | Path) -> None:
        """result.json, history.npz and convergence.png into `out` (`vlr.results`)."""
        from vlr.results import write_result_files

        write_result_files(Path(out), self)


def run_identification(settings: Settings, *, progress: Callable | None = None,
                       watch: Callable | None = None,
                       observe_through: Callable[[World], Callable] | None = None,
                       world: World | None = None) -> Identification:
    """Open the world of `settings`, run the identification loop, close the world, score.

    Args:
        settings: the settings tree (`vlr.settings.load_settings`).
        progress: called with each `vlr.filter.IterationRecord` (a progress bar).
        watch: called with the filter and each record after the update (a live view).
        observe_through: (world) -> another observer to use (the live view wraps the
            camera's with one that also draws it).
        world: an already open world (`vlr.world.hand_world` around a task's hand); it is
            not closed here.
    """
    from vlr.identify import identify
    from vlr.memory import keep_freed_memory
    from vlr.results import summarize

    # A script calling this gets the CLI's allocator setting too: the filter's particle-set
    # temporaries reused, not paged in afresh each iteration (`vlr.memory`).
    keep_freed_memory()
    t0 = time.perf_counter()
    own = world is None
    w = open_world(settings) if own else world
    _LOG.debug("%s world open: %s holding %s; %d particles, at most %d actions",
               settings.world.backend, w.hand_spec.name, w.object_spec.name,
               settings.filter.particles, settings.loop.max_iterations)
    box: dict[str, Any] = {}

    def watching(pf, rec) -> None:
        # A line per update for `vlr -v`: the progress of a run without a bar (--quiet, a
        # sweep's worker, a log file).
        _LOG.debug("iteration %d: mean 95%% interval %.2f deg, ESS %.0f", rec.iteration,
                   rec.ci_deg, rec.ess)
        box["pf"] = pf
        if watch is not None:
            watch(pf, rec)

    truths: list = []
    try:
        scorer = None
        if w.truth is not None:
            def scorer():  # scoring only; the filter never sees this
                truths.append(w.truth())
                return truths[-1]
        observer = w.observer if observe_through is None else observe_through(w)
        result = identify(w.world, observer, w.model, w.obj, w.nominal, settings.filter,
                          settings.loop, settings.seed, truth=scorer, progress=progress,
                          watch=watching)
    finally:
        if own:
            w.close()
    wall = time.perf_counter() - t0
    _LOG.debug("identification done in %.1f s: %d actions, converged %s", wall,
               result.iterations, result.converged)
    summary = summarize(result, w.model, settings, wall, truths[-1] if truths else None)
    summary["settings"] = settings.flat()
    # What ran: a backend may hold another hand or object than the settings name (the real
    # hand's config names its own).
    summary["hand"], summary["object"] = w.hand_spec.name, w.object_spec.name
    if hasattr(w.world, "regrasps"):  # synthetic: truths drawn again for sitting at a fold
        summary["world_regrasps"] = int(w.world.regrasps)
    return Identification(settings, result, w.model, truths, summary, box.get("pf"))
