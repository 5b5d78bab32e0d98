"""What the task environments cost: median seconds of a `reset` and of a `step` per registered
id (by default each task's sparse id: its dense twin differs in the reward only), at its
defaults and with `identify=False`, beside `vlr bench`'s yardstick measured in the same run
(docs/TASKS.md, "Cost").

    python -m vlr.tasks.cost                       # every task, seeds 0-2, 3 steps per reset
    python -m vlr.tasks.cost --ids vlr/Handwriting-v2 --seeds 5
    python -m vlr.tasks.cost --particles 5000 --identify-iterations 15   # another identification
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np


def env_cost(env_id: str, seeds: int, steps: int, **make_kwargs) -> tuple[float, float]:
    """Median seconds of a reset and of a step (zero actions) over `seeds` resets."""
    import gymnasium as gym

    env = gym.make(env_id, **make_kwargs)
    resets, moves = [], []
    try:
        for seed in range(seeds):
            t = time.perf_counter()
            env.reset(seed=seed)
            resets.append(time.perf_counter() - t)
            for _ in range(steps):
                t = time.perf_counter()
                env.step(np.zeros(env.action_space.shape, dtype=env.action_space.dtype))
                moves.append(time.perf_counter() - t)
    finally:
        env.close()
    return float(np.median(resets)), float(np.median(moves)) if moves else float("nan")


def main(argv: list[str] | None = None) -> int:
    from vlr import tasks
    from vlr.commands.bench import yardstick

    p = argparse.ArgumentParser(prog="python -m vlr.tasks.cost",
                                description=__doc__.split("\n\n")[0])
    p.add_argument("--ids", nargs="+", default=list(tasks.DENSE),
                   help="registered ids (default: each task's sparse id)")
    p.add_argument("--seeds", type=int, default=3, help="resets per id (seeds 0..N-1)")
    p.add_argument("--steps", type=int, default=3, help="steps timed after each reset")
    p.add_argument("--particles", type=int, help="the identification's (default: the task's)")
    p.add_argument("--identify-iterations", type=int,
                   help="its exploratory moves (default: the task's)")
    args = p.parse_args(argv)
    unknown = [i for i in args.ids if i not in tasks.ENVIRONMENTS]
    if unknown:
        print(f"tasks.cost: unknown id {unknown[0]!r} (ids: {', '.join(tasks.ENVIRONMENTS)})",
              file=sys.stderr)
        return 2
    if args.seeds < 1 or args.steps < 0:
        print(f"tasks.cost: --seeds {args.seeds} must be >= 1 and --steps {args.steps} >= 0",
              file=sys.stderr)
        return 2
    if (args.particles is not None and args.particles < 10) or (
            args.identify_iterations is not None and args.identify_iterations < 0):
        print(f"tasks.cost: --particles {args.particles} must be >= 10 and "
              f"--identify-iterations {args.identify_iterations} >= 0", file=sys.stderr)
        return 2
    given = {"particles": args.particles, "identify_iterations": args.identify_iterations}
    make = {k: v for k, v in given.items() if v is not None}
    print(f"yardstick (vlr bench, 60,000 particles): {yardstick(60000):.3f} s")
    print(f"{'id':24s} {'identify':>8s} {'reset s':>8s} {'step s':>8s}")
    for env_id in args.ids:
        for identify in (True, False):
            if not identify and env_id in (tasks.CUP_STACKING, tasks.CUP_STACKING_DENSE):
                continue   # cup stacking needs the identification (tasks/cups.py)
            reset, step = env_cost(env_id, args.seeds, args.steps, identify=identify, **make)
            print(f"{env_id:24s} {str(identify):>8s} {reset:8.2f} {step:8.3f}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
