"""`python -m vlr.precompile`: compile the particle filter's numba kernels once, at install.

The kernels (`vlr/kernels/`) are compiled with `cache=True` on their first call:
30-50 s on two cores, paid by the first run after a fresh install (the first `vlr demo`
would take about 50 s instead of about 5 s). `make install` runs this module, which calls
every kernel on tiny identifications of the synthetic world (rolling and pinned contacts,
the particle filter and the unscented Kalman filter), so that the cache in `vlr/__pycache__`
(or `NUMBA_CACHE_DIR`) is warm before any user command.
"""

from __future__ import annotations

import logging
import time

TINY = {"world.backend": "synthetic", "filter.particles": 64, "loop.max_iterations": 2,
        "loop.min_iterations": 0}
VARIANTS = ({"filter.motion.rolling": True}, {"filter.motion.rolling": False},
            {"filter.estimator": "ukf"})


def precompile() -> float:
    """Run the tiny identifications (module docstring); the seconds it took."""
    from vlr.run import run_identification
    from vlr.settings import load_settings

    t0 = time.perf_counter()
    for variant in VARIANTS:
        run_identification(load_settings(TINY, variant))
    return time.perf_counter() - t0


def main() -> int:
    logging.getLogger("vlr").setLevel(logging.WARNING)
    print("compiling the particle filter's kernels once (numba, 30-50 s; cached for every "
          "later run) ...", flush=True)
    print(f"compiled in {precompile():.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
