"""`vlr bench`: time one particle-filter iteration (Algorithm 1) at several particle counts.

Each phase is timed separately: motion (Eq. 9 solve), observation (Eq. 5 likelihood), weights
(tempering), resampling, jitter; "total" is their sum, "summary" (per-iteration quantiles for
history) is reported apart. The world is the synthetic one (vlr.synthetic) holding the apple,
and the filter is built from the settings tree as `vlr identify` builds it (`vlr.settings`), so
the numbers are those of a real identification run's iterations. `--contacts rolling` (the
default: what `vlr identify` runs on the sim and the real hand) times the rolling motion model,
`pinned` the pinned one (the synthetic world's default).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

PHASES = ("motion", "observation", "weights", "resampling", "jitter")
CONTACTS = ("rolling", "pinned")


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("bench", help="time one filter iteration at 6k, 60k, 600k "
                              "particles", description=__doc__)
    p.add_argument("--particles", type=int, nargs="+", default=[6_000, 60_000, 600_000],
                   help="particle counts (default: 6000 60000 600000)")
    p.add_argument("--repeats", type=int, default=5, help="iterations timed per count")
    p.add_argument("--json", type=Path, default=None,
                   help="write the contacts timed, {particles: median seconds per iteration} "
                        "and each count's per-phase medians to this file")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--contacts", choices=CONTACTS, default="rolling",
                   help="the motion model timed: rolling contacts (default; the sim's and the "
                        "real hand's) or pinned ones")
    p.set_defaults(func=run)


def bench_one(n_particles: int, repeats: int, seed: int = 0,
              contacts: str = "rolling") -> dict[str, float]:
    """Median seconds per phase of `repeats` filter iterations with n_particles."""
    from vlr.filter import ParticleFilter
    from vlr.kinematics import HandModel
    from vlr.motion import ObjectParams
    from vlr.settings import load_settings
    from vlr.spec import load_hand, load_object
    from vlr.synthetic import SyntheticConfig, SyntheticWorld, random_action

    settings = load_settings({"world.backend": "synthetic", "world.object": "apple",
                              "filter.particles": n_particles, "seed": seed,
                              "filter.motion.rolling": contacts == "rolling"})
    model = HandModel.from_spec(load_hand(settings.world.hand))
    obj = ObjectParams.from_spec(load_object(settings.world.object))
    # The bench times the filter, not the grasp: a snap-through of the world (a grasp at a
    # fold, `SyntheticConfig.snap_theta`) must not end it.
    world = SyntheticWorld(model, obj, SyntheticConfig(seed=seed, snap_theta=np.pi,
                                                       motion=settings.filter.motion))
    u = world.grasp()
    pf = ParticleFilter(model, obj, settings.filter, seed)
    pf.initialize(world.observe(), u, world.nominal.theta, world.nominal.contact)
    rng = np.random.default_rng(seed + 1)
    rows = []
    for _ in range(repeats + 1):  # the first iteration also settles the prior: not timed
        u = world.apply(random_action(rng, model.n_fingers))
        obs = world.observe()
        t0 = time.perf_counter()
        pf.step(u, obs)
        wall = time.perf_counter() - t0
        row = dict(pf.timings)
        row["total"] = sum(row[k] for k in PHASES)
        row["wall"] = wall
        row.update({f"newton_{k}": v for k, v in pf.newton_iterations.items()})
        rows.append(row)
    rows = rows[1:]
    return {k: float(np.median([r[k] for r in rows])) for k in rows[0]}


def run(args: argparse.Namespace) -> int:
    from vlr.errors import UserError

    bad = [n for n in args.particles if n < 10]
    if bad:
        raise UserError(f"--particles {bad[0]} must be >= 10")
    if args.repeats < 1:
        raise UserError(f"--repeats {args.repeats} must be >= 1")
    from vlr._energy_kernels import solve_batch  # noqa: F401  (compile/load the cache first)
    from vlr.io import write_json_atomic

    results: dict[int, dict[str, float]] = {}
    header = (f"{'particles':>10} " + " ".join(f"{k:>11}" for k in (*PHASES, "total",
                                                                      "summary"))
              + "   Newton iterations (action, settle)")
    print(f"{args.contacts} contacts, the synthetic world holding the apple")
    print(header)
    for n in args.particles:
        med = bench_one(n, args.repeats, args.seed, args.contacts)
        results[n] = med
        print(f"{n:>10} " + " ".join(f"{med[k]:>10.4f}s" for k in (*PHASES, "total",
                                                                    "summary"))
              + f"   {med.get('newton_action', float('nan')):.0f}, "
              f"{med.get('newton_settle', float('nan')):.0f}", flush=True)
    if args.json is not None:
        write_json_atomic(args.json, {
            "contacts": args.contacts,
            "seconds_per_iteration": {str(n): r["total"] for n, r in results.items()},
            "medians": {str(n): r for n, r in results.items()}})
    return 0
