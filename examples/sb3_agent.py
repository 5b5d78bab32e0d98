"""A learning library's agent beside the VLR baseline: Stable-Baselines3's PPO on handwriting.

    pip install -e '.[learn]'                       # Stable-Baselines3 and PyTorch (large)
    python examples/sb3_agent.py                    # train briefly, then compare, one table
    python examples/sb3_agent.py --train-steps 20000 --seeds 0-4

PPO learns on `vlr/Handwriting-v2` as a learner sees it: the goal-conditioned Dict
observation (`MultiInputPolicy`), actions in [-1, 1], rewards from `compute_reward`, and no
identification in its resets (`identify=False`: a reset is a grasp, so training pays for
grasps and moves only). The trained agent then runs through `vlr task handwriting --policy
examples/sb3_agent.py:agent` (the same reset, seeds, metrics and result files as the
baseline), beside the baseline in one `vlr task` summary (examples/compare_policies.py). A
few hundred steps show the plumbing, not a good policy.

Run it through this script: PyTorch's compiler (triton), which building PPO's optimizer
loads, crashes loading its native module in a process that loaded the sim first (as `vlr
task` does before it loads a policy); this script loads it before the sim. With a model
trained already: `python examples/sb3_agent.py --model runs/sb3-agent/ppo.zip`.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve()
# Where `agent` finds the trained model (set by `main`, or by you).
MODEL_ENV = "VLR_SB3_MODEL"


def _ppo():
    try:
        # PyTorch's compiler (triton) crashes loading its native module once the sim is
        # loaded; loaded first, it does not (module docstring). CPU-only PyTorch has none.
        import triton  # noqa: F401
    except ImportError:
        pass
    try:
        from stable_baselines3 import PPO
    except ImportError:
        sys.exit("examples/sb3_agent.py needs Stable-Baselines3: pip install -e '.[learn]'")
    return PPO


def train(steps: int, path: Path, seed: int = 0, word: str = "I") -> Path:
    """PPO on `vlr/Handwriting-v2` without identification in its resets, saved to `path`."""
    ppo = _ppo()
    import gymnasium as gym

    from vlr import tasks  # noqa: F401  (registers the environments)

    env = gym.make("vlr/Handwriting-v2", identify=False, word=word)
    n_steps = min(64, max(8, steps))
    model = ppo("MultiInputPolicy", env, n_steps=n_steps, batch_size=n_steps, n_epochs=4,
                   seed=seed, verbose=0)
    model.learn(total_timesteps=steps)
    env.close()
    path.parent.mkdir(parents=True, exist_ok=True)
    model.save(path)
    return path


def agent(env: Any):
    """The `--policy` factory: the trained PPO's deterministic action for an observation."""
    model = _ppo().load(os.environ[MODEL_ENV])
    return lambda obs: model.predict(obs, deterministic=True)[0]


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--train-steps", type=int, default=256)
    p.add_argument("--model", help="a trained model's zip: compare it, without training")
    p.add_argument("--seeds", default="0")
    p.add_argument("--word", default="I")
    p.add_argument("--particles", default="2000", help="the comparison's identification")
    p.add_argument("--identify-iterations", default="5")
    p.add_argument("--out", default="runs/sb3-agent")
    args = p.parse_args(argv)
    if args.train_steps < 1:
        p.error(f"--train-steps {args.train_steps}: must be at least 1")
    out = Path(args.out)
    if args.model:
        if not Path(args.model).is_file():
            p.error(f"--model {args.model}: no such file")
        _ppo()
        os.environ[MODEL_ENV] = str(Path(args.model).resolve())
    else:
        os.environ[MODEL_ENV] = str(train(args.train_steps, out / "ppo.zip", word=args.word))
    sys.path.insert(0, str(HERE.parent))
    from compare_policies import main as compare

    return compare(["--seeds", args.seeds, "--word", args.word, "--particles", args.particles,
                    "--identify-iterations", args.identify_iterations,
                    "--policies", "baseline", f"{HERE}:agent", "--out", str(out / "compare")])


if __name__ == "__main__":
    raise SystemExit(main())
