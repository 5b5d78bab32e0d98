"""A learning library's agent beside the VLR baseline: Stable-Baselines3's SAC with hindsight
experience replay (HER) on handwriting.

    pip install torch --index-url https://download.pytorch.org/whl/cpu   # CPU-only PyTorch
    pip install -e '.[learn]'                       # Stable-Baselines3
    python examples/sb3_agent.py                    # train briefly, then compare, one table
    python examples/sb3_agent.py --train-steps 20000 --seeds 0-4

Install CPU-only PyTorch first, as above: the `learn` extra then finds it, where `pip install
-e '.[learn]'` alone pulls PyTorch with its CUDA libraries (about 5 GB), which this example
does not use.

SAC learns on `vlr/Handwriting-v2`, the sparse reward (-1 until the POM is within the
tolerance of its waypoint, then 0), as a goal-conditioned learner sees it: the Dict
observation (`MultiInputPolicy`), actions in [-1, 1], and no identification in its resets
(`identify=False`: a reset is a grasp, so training pays for grasps and moves only).
`HerReplayBuffer` relabels stored moves with goals the POM did reach, rewarded by the env's
`compute_reward`: what makes a sparse reward learnable. The trained agent then runs through
`vlr task handwriting --policy examples/sb3_agent.py:agent` (the same reset, seeds, metrics
and result files as the baseline), beside the baseline in one `vlr task` summary
(examples/compare_policies.py). A few hundred steps show the plumbing, not a good policy.

Run it through this script: PyTorch's compiler (triton), where installed, crashes loading its
native module in a process that loaded the sim first (as `vlr task` does before it loads a
policy); this script loads it before the sim. With a model trained already: `python
examples/sb3_agent.py --model runs/sb3-agent/sac.zip`.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve()
ENV_ID = "vlr/Handwriting-v2"     # the sparse reward, HER's
# Where `agent` finds the trained model (set by `main`, or by you).
MODEL_ENV = "VLR_SB3_MODEL"


def _sb3():
    """Stable-Baselines3's (SAC, HerReplayBuffer), or exit naming the `learn` extra."""
    try:
        # PyTorch's compiler (triton) crashes loading its native module once the sim is
        # loaded; loaded first, it does not (module docstring). CPU-only PyTorch has none.
        import triton  # noqa: F401
    except ImportError:
        pass
    try:
        from stable_baselines3 import SAC, HerReplayBuffer
    except ImportError:
        sys.exit("examples/sb3_agent.py needs Stable-Baselines3: pip install -e '.[learn]' "
                 "(CPU-only PyTorch first: the module docstring)")
    return SAC, HerReplayBuffer


def train(steps: int, path: Path, seed: int = 0, word: str = "I") -> Path:
    """SAC with HER on `ENV_ID` without identification in its resets, saved to `path`."""
    sac, her = _sb3()
    import gymnasium as gym

    from vlr import tasks  # noqa: F401  (registers the environments)

    env = gym.make(ENV_ID, identify=False, word=word)
    # HER samples finished episodes only: learning starts once the first one has surely
    # ended (every waypoint given its whole move budget: 36 moves for "I"). A buffer the
    # size of the run keeps the saved model small to load.
    longest = len(env.unwrapped.waypoints) * env.unwrapped.steps_per_waypoint
    model = sac("MultiInputPolicy", env, replay_buffer_class=her,
                replay_buffer_kwargs={"n_sampled_goal": 4, "goal_selection_strategy": "future"},
                learning_starts=longest, buffer_size=max(steps, 1000), batch_size=64,
                seed=seed, device="cpu", verbose=0)
    model.learn(total_timesteps=steps)
    env.close()
    path.parent.mkdir(parents=True, exist_ok=True)
    model.save(path)
    return path


def agent(env: Any):
    """The `--policy` factory: the trained SAC's deterministic action for an observation.
    Loaded with the env, as a model with a HER buffer must be (its spaces are checked)."""
    sac, _ = _sb3()
    model = sac.load(os.environ[MODEL_ENV], env=env, device="cpu")
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
        _sb3()
        os.environ[MODEL_ENV] = str(Path(args.model).resolve())
    else:
        os.environ[MODEL_ENV] = str(train(args.train_steps, out / "sac.zip", word=args.word))
    sys.path.insert(0, str(HERE.parent))
    from compare_policies import main as compare

    return compare(["--seeds", args.seeds, "--word", args.word, "--particles", args.particles,
                    "--identify-iterations", args.identify_iterations,
                    "--policies", "baseline", f"{HERE}:agent", "--out", str(out / "compare")])


if __name__ == "__main__":
    raise SystemExit(main())
