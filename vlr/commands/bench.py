"""`vlr bench`: one particle-filter iteration (Algorithm 1) timed at several particle counts,
against a yardstick measured in the same run.

The filter is built from the settings tree as `vlr identify` builds it on the sim
(`vlr.settings`: rolling contacts, the turn term, the stops at 17 N m/rad), and the world is
the synthetic one holding the apple (the settings' object), so that the iterations are a real
run's. Each phase is timed apart: motion (the Eq. 9 solve of the action), observation
(Eq. 5), check (the model check's predictive, `vlr.model_check`), weights (tempering),
resampling, jitter (the Liu-West draw and the settle of the jittered particles); "total" is
their sum, "summary" (quantiles for the history) is reported apart. The yardstick is one
batched `np.linalg.solve` of P 12x12 systems, the linear algebra of one Newton step for every
particle: the machine's own speed, so that a ratio to it compares across machines; it is
timed after each iteration, and the ratio is the median of the iterations' own ratios.
`--set KEY=VALUE` changes a setting of the tree as `vlr identify --set` does (e.g.
`--set filter.motion.spin_friction=0`), so that a variant is timed as the filter runs it;
a key the bench does not use (the sim's options, the loop's length) is refused.
`--profile` adds what the iterations are made of: Newton-step equivalents per particle (one
energy, gradient and Hessian evaluation with its arrow solve; mean, median, 99th percentile)
of the action and of the settle (per jittered particle), the share of particles that failed
or needed the follow-up of a large move, and the cost of one energy evaluation per term.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

PHASES = ("motion", "observation", "check", "weights", "resampling", "jitter")
CONTACTS = ("rolling", "pinned")


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("bench", help="time one filter iteration at 6k, 60k, 600k "
                              "particles against a yardstick", description=__doc__,
                              formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--particles", type=int, nargs="+", default=[6_000, 60_000, 600_000],
                   help="particle counts (default: 6000 60000 600000)")
    p.add_argument("--repeats", type=int, default=5, help="iterations timed per count")
    p.add_argument("--json", type=Path, default=None,
                   help="write every figure to this file")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--contacts", choices=CONTACTS, default="rolling",
                   help="the motion model timed: rolling contacts (default; the sim's and the "
                        "real hand's) or pinned ones")
    p.add_argument("--profile", action="store_true",
                   help="also Newton iterations, failures and follow-ups, and the cost per "
                        "energy term")
    p.add_argument("--threads", type=int, default=None,
                   help="numba threads of the particle kernels (default: every core)")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="any setting of the filter, as `vlr identify --set` (e.g. "
                        "filter.motion.spin_friction=0); on top of the bench's own")
    p.set_defaults(func=run)


class Yardstick:
    """One batched `np.linalg.solve` of n_particles SPD 12x12 systems, timed by `time()`.
    The bench times it after each filter iteration, so that the two see the machine in the
    same state: on a shared 2-core machine it alone varied from 0.064 to 0.12 s at 60,000
    particles within a minute."""

    def __init__(self, n_particles: int, seed: int = 0) -> None:
        rng = np.random.default_rng(seed)
        a = rng.standard_normal((n_particles, 12, 12))
        self.a = a @ a.transpose(0, 2, 1) + 12 * np.eye(12)
        self.b = rng.standard_normal((n_particles, 12, 1))

    def time(self) -> float:
        """Seconds of one solve."""
        t = time.perf_counter()
        np.linalg.solve(self.a, self.b)
        return time.perf_counter() - t


def yardstick(n_particles: int, repeats: int = 5, seed: int = 0) -> float:
    """Median seconds of `repeats` yardstick solves (`Yardstick`) timed back to back, for a
    cost quoted beside it (`python -m vlr.tasks.cost`)."""
    stick = Yardstick(n_particles, seed)
    return float(np.median([stick.time() for _ in range(repeats)]))


def _filter(n_particles: int, seed: int, contacts: str, sets: Mapping[str, Any] | None = None):
    """The filter as `vlr identify` builds it on the sim (with the `--set` layer `sets` on
    top), initialised on the synthetic world holding the apple, that world, and the trial's
    actions (`vlr.explore.ActionStream`, as `vlr identify --seed` makes them)."""
    from vlr.explore import ActionStream
    from vlr.filter import ParticleFilter
    from vlr.kinematics import HandModel
    from vlr.motion import ObjectParams
    from vlr.settings import load_settings
    from vlr.spec import load_hand, load_object
    from vlr.synthetic import SyntheticConfig, SyntheticWorld
    from vlr.world import grasp_guess

    settings = load_settings({"world.backend": "sim", "filter.particles": n_particles,
                              "seed": seed, "filter.motion.rolling": contacts == "rolling"},
                             sets)
    model = HandModel.from_spec(load_hand(settings.world.hand))
    obj = ObjectParams.from_spec(load_object(settings.world.object))
    # The bench times the filter, not the grasp: a snap-through of the world (a grasp at a
    # fold, `SyntheticConfig.snap_theta`) must not end it.
    world = SyntheticWorld(model, obj, SyntheticConfig(seed=seed, snap_theta=np.pi,
                                                       motion=settings.filter.motion))
    u = world.grasp()
    nominal = grasp_guess(settings, model, obj)
    pf = ParticleFilter(model, obj, settings.filter, seed)
    pf.initialize(world.observe(), u, nominal.theta, nominal.contact)
    return pf, world, ActionStream.of_trial(settings.loop, seed, u)


def bench_one(n_particles: int, repeats: int, seed: int = 0, contacts: str = "rolling",
              profile: bool = False, sets: Mapping[str, Any] | None = None
              ) -> dict[str, float]:
    """Median seconds per phase of `repeats` filter iterations with n_particles, of the
    yardstick timed after each (`Yardstick`), the Newton iterations, and with `profile` the
    iterations' spread and the failures."""
    pf, world, actions = _filter(n_particles, seed, contacts, sets)
    stick = Yardstick(n_particles, seed)
    u = actions.center
    rows = []
    for _ in range(repeats + 1):  # the first iteration also settles the prior: not timed
        u = world.apply(actions.random(u))
        obs = world.observe()
        t0 = time.perf_counter()
        pf.step(u, obs)
        wall = time.perf_counter() - t0
        row = dict(pf.timings)
        row["total"] = sum(row[k] for k in PHASES)
        row["wall"] = wall
        row["yardstick"] = stick.time()
        row["ratio"] = row["total"] / row["yardstick"]
        row.update({f"newton_{k}": v for k, v in pf.newton_iterations.items()})
        if profile:
            row.update(pf.profile)
        rows.append(row)
    rows = rows[1:]
    return {k: float(np.median([r[k] for r in rows])) for k in rows[0]}


def term_costs(n_particles: int, seed: int = 0, repeats: int = 5,
               sets: Mapping[str, Any] | None = None) -> dict[str, float]:
    """Microseconds per particle of one energy evaluation (energy, gradient and Hessian, the
    contacts' start included) with each term alone, with the contacts pinned, and with all
    of the filter's terms, on n_particles copies of the bench's particles (so that the
    kernel's start-up does not count). The least of `repeats` timed calls, as `timeit`
    takes it: a call of a few milliseconds varies by half on this kind of machine, and the
    noise only adds."""
    from dataclasses import replace

    from vlr.kernels.solve import evaluate_batch
    from vlr.motion import TERMS

    pf, _, _ = _filter(min(n_particles, 6_000), seed, "rolling", sets)
    m = pf.motion
    st = pf.state.take(np.resize(np.arange(pf.state.n), n_particles))  # n_particles of them
    ps = m.particles(st)
    variants = {name: replace(m.config, terms=(name,), rolling=name == "contacts")
                for name in TERMS}
    variants["pinned contacts"] = replace(m.config, terms=("contacts",), rolling=False)
    variants["all"] = m.config
    out = {}
    for name, cfg in variants.items():
        energy = np.empty(st.n)
        record = cfg.record()
        times = []
        # One untimed call first: each term's first calls ran at up to twice its cost (the
        # threads' and the caches' warm-up).
        for _ in range(repeats + 1):
            t = time.perf_counter()
            evaluate_batch(ps, m._hand, m._surface, record, pf.command, energy)
            times.append(time.perf_counter() - t)
        out[name] = float(np.min(times[1:])) / st.n * 1e6
    return out


def run(args: argparse.Namespace) -> int:
    from vlr.errors import UserError

    bad = [n for n in args.particles if n < 10]
    if bad:
        raise UserError(f"--particles {bad[0]} must be >= 10")
    if args.repeats < 1:
        raise UserError(f"--repeats {args.repeats} must be >= 1")
    import numba

    cores = numba.config.NUMBA_NUM_THREADS
    if args.threads is not None and not 1 <= args.threads <= cores:
        raise UserError(f"--threads {args.threads} must be 1..{cores} (the cores numba has)")
    numba.set_num_threads(args.threads or cores)
    from vlr import smoke
    from vlr.io import check_output_file, write_json_atomic
    from vlr.kernels.solve import solve_batch  # noqa: F401  (compile/load the cache)
    from vlr.settings import load_settings, parse_assignment

    sets = dict(parse_assignment(t) for t in args.set)
    own = {"filter.particles": "--particles", "seed": "--seed",
           "filter.motion.rolling": "--contacts", "world.backend": "the bench's own world",
           "world.true_hand": "its world holds the filter's own hand"}
    used = ("filter.", "world.hand", "world.object", "loop.action_range_mm",
            "loop.action_band_mm")
    for key in sets:
        if key in own:
            raise UserError(f"--set {key}: vlr bench sets it ({own[key]})")
        if not key.startswith(used):
            raise UserError(f"--set {key}: vlr bench does not use it (it takes filter.*, "
                            "world.hand, world.object and loop.action_range_mm / "
                            "action_band_mm)")
    # A bad key or value ends here, in one line; the object is the settings' (the apple).
    held = load_settings({"world.backend": "sim"}, sets).world.object
    if args.json is not None:
        check_output_file(args.json, "--json")

    results: dict[int, dict[str, float]] = {}
    print(f"{args.contacts} contacts, the synthetic world holding the {held}, the sim's "
          f"filter settings{''.join(f', {t}' for t in args.set)}, "
          f"{numba.get_num_threads()} of {cores} threads; seconds are "
          "medians over the iterations")
    print(f"{'particles':>10} " + " ".join(f"{k:>11}" for k in (*PHASES, "total"))
          + f" {'yardstick':>10} {'ratio':>6}   Newton steps (action, settle)")
    # VLR_SMOKE (vlr/smoke.py): the same run at a smoke test's sizes.
    counts = dict.fromkeys(smoke.cap(n, smoke.BENCH_PARTICLES) for n in args.particles)
    repeats = smoke.cap(args.repeats, 1)
    for n in counts:
        med = bench_one(n, repeats, args.seed, args.contacts, args.profile, sets)
        results[n] = med
        print(f"{n:>10} " + " ".join(f"{med[k]:>10.4f}s" for k in (*PHASES, "total"))
              + f" {med['yardstick']:>9.4f}s {med['ratio']:>6.1f}   "
              f"{med.get('newton_action', float('nan')):.0f}, "
              f"{med.get('newton_settle', float('nan')):.0f}", flush=True)
    if len(results) > 1:
        counts = sorted(results)
        for a, b in zip(counts, counts[1:], strict=False):
            print(f"{b} / {a} particles: {results[b]['total'] / results[a]['total']:.1f}x the "
                  f"time for {b / a:.0f}x the particles")
    costs = None
    if args.profile:
        for n, med in results.items():
            print(f"\n{n} particles, Newton-step equivalents per particle: action "
                  f"{med['action_mean']:.2f} (median {med['newton_action']:.0f}, 99th "
                  f"percentile {med['action_p99']:.0f}), settle {med['settle_mean']:.2f} per "
                  f"jittered particle ({med['settled_share']:.0%} of them); failed "
                  f"{med['failed_share']:.2%}, followed {med['followed_share']:.2%}; "
                  f"{med['motion'] / max(med['action_mean'], 1e-9) / n * 1e6:.2f} us per "
                  "particle-step of the action")
        costs = term_costs(60_000, args.seed, sets=sets)
        print("\none energy evaluation per particle [us]: "
              + ", ".join(f"{k} {v:.2f}" for k, v in costs.items()))
    if args.json is not None:
        write_json_atomic(args.json, {
            "contacts": args.contacts,
            "settings": sets,
            "threads": numba.get_num_threads(),
            "seconds_per_iteration": {str(n): r["total"] for n, r in results.items()},
            "yardstick_seconds": {str(n): r["yardstick"] for n, r in results.items()},
            "ratio_to_yardstick": {str(n): r["ratio"] for n, r in results.items()},
            "medians": {str(n): r for n, r in results.items()},
            **({"energy_term_us": costs} if costs else {})})
    return 0
