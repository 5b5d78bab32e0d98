"""Compare a policy of your own with the VLR baseline on a task, in the table `vlr task` prints.

    python examples/compare_policies.py                         # handwriting "I", seed 0
    python examples/compare_policies.py --seeds 0-2 --word SCI --particles 5000

Each policy runs through `vlr task NAME --policy FILE.py:FACTORY` (same reset, seeds,
metrics and result files as the baseline), then one summary puts them side by side.

`goal_step` is a policy as a learner sees the task: it reads the observation only (the
camera's goals and the commands), never the filter or the truth. It probes with a few random
moves, fits the goal's response to the tendons by least squares over its own moves, and steps
towards the desired goal. A learning library's agent is a policy too, a factory that returns
its `predict`: examples/sb3_agent.py trains Stable-Baselines3's SAC with HER and runs it here.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

import numpy as np

HERE = Path(__file__).resolve()


def goal_step(env: Any, gain: float = 0.5, probes: int = 3, memory: int = 20):
    """A policy from observations alone (module docstring). `env` is used for nothing but
    its seed-independent constants (the goal's size)."""
    rng = np.random.default_rng(0)
    commands: list[np.ndarray] = []
    goals: list[np.ndarray] = []

    def policy(obs: dict) -> np.ndarray:
        commands.append(np.asarray(obs["observation"], dtype=float)[6:9].copy())
        goals.append(np.asarray(obs["achieved_goal"], dtype=float).copy())
        if len(commands) <= probes:
            return rng.uniform(-0.5, 0.5, 3)
        du = np.diff(np.array(commands[-memory:]), axis=0)
        dg = np.diff(np.array(goals[-memory:]), axis=0)
        moved = np.max(np.abs(du), axis=1) > 1e-7
        if moved.sum() < 3:
            return rng.uniform(-0.5, 0.5, 3)
        jac = np.linalg.lstsq(du[moved], dg[moved], rcond=None)[0].T   # dg = J du
        error = np.asarray(obs["desired_goal"], dtype=float) - goals[-1]
        step = np.linalg.lstsq(jac, error, rcond=None)[0]               # [m]
        return np.clip(gain * step / env.max_step, -1.0, 1.0)

    return policy


def main(argv: list[str] | None = None) -> int:
    from vlr.cli import main as vlr
    from vlr.task_report import summary_markdown

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--task", default="handwriting", choices=("handwriting", "maze"))
    p.add_argument("--seeds", default="0")
    p.add_argument("--word", default="I", help="handwriting: the word to write")
    p.add_argument("--particles", default="2000")
    p.add_argument("--identify-iterations", default="5")
    p.add_argument("--policies", nargs="+",
                   default=["baseline", f"{HERE}:goal_step", "vlr.tasks.examples:hold"],
                   help="baseline, or MODULE:NAME / FILE.py:NAME factories")
    p.add_argument("--out", default="runs/compare-policies")
    args = p.parse_args(argv)
    out = Path(args.out)
    options = ["--option", f"word={args.word}"] if args.task == "handwriting" else []
    results = []
    for k, policy in enumerate(args.policies):
        where = out / f"policy-{k}"
        chosen = [] if policy == "baseline" else ["--policy", policy]
        rc = vlr(["task", args.task, "--seeds", args.seeds, "--particles", args.particles,
                  "--identify-iterations", args.identify_iterations, "--quiet",
                  *options, *chosen, "--out", str(where)])
        if rc != 0:
            return rc
        results += [json.loads(f.read_text()) for f in sorted(where.glob("seed-*/result.json"))]
    print(summary_markdown(results, title=f"{args.task}, seeds {args.seeds}: the policies "
                                          "side by side"), end="")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
