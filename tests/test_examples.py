"""examples/compare_policies.py: a user's policy, the baseline and a reference side by side
in one `vlr task` summary (a tiny filter: the plumbing, not the accuracy); examples/
sb3_agent.py: Stable-Baselines3's SAC with HER trained on the sparse handwriting id, then
beside the baseline (with the `learn` extra; CI does not install it, so that test skips)."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "compare_policies.py"


def test_compare_policies_prints_one_table_with_every_policy(tmp_path, capsys):
    spec = importlib.util.spec_from_file_location("compare_policies", EXAMPLE)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    assert module.main(["--particles", "300", "--identify-iterations", "2",
                        "--out", str(tmp_path)]) == 0
    table = capsys.readouterr().out.split("the policies side by side")[1]
    assert "| handwriting | 0 |" in table, table       # the baseline's row
    for policy in ("compare_policies.py:goal_step", "vlr.tasks.examples:hold"):
        assert f"| handwriting, policy {policy} | 0 |" in table, table


SB3_EXAMPLE = EXAMPLE.parent / "sb3_agent.py"


def test_sb3_agent_trains_sac_with_her_and_runs_beside_the_baseline(tmp_path, capsys):
    """A few hundred steps of SAC with HER on the sparse id (CPU-only PyTorch; 20-30 s on a
    2-core machine), then the trained agent beside the baseline through `vlr task`.
    Stable-Baselines3's own goal-env checker passes on the env it trains on first."""
    sb3 = pytest.importorskip(
        "stable_baselines3", reason="the `learn` extra (pip install torch --index-url "
        "https://download.pytorch.org/whl/cpu, then pip install -e '.[learn]')")
    import gymnasium as gym
    from stable_baselines3.common.env_checker import check_env

    from vlr import tasks

    spec = importlib.util.spec_from_file_location("sb3_agent", SB3_EXAMPLE)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    assert module.ENV_ID == tasks.HANDWRITING and gym.spec(module.ENV_ID).kwargs == {
        "reward_type": "sparse"}
    env = gym.make(module.ENV_ID, identify=False, word="I")
    try:
        env.reset(seed=0)
        check_env(env.unwrapped, skip_render_check=True)   # compute_reward over infos too
    finally:
        env.close()
    steps = 256
    assert module.main(["--train-steps", str(steps), "--particles", "300",
                        "--identify-iterations", "2", "--out", str(tmp_path)]) == 0
    table = capsys.readouterr().out.split("the policies side by side")[1]
    assert "| handwriting | 0 |" in table, table
    assert "| handwriting, policy sb3_agent.py:agent | 0 |" in table, table
    env = gym.make(module.ENV_ID, identify=False, word="I")
    try:
        model = sb3.SAC.load(tmp_path / "sac.zip", env=env, device="cpu")
        # Trained: every step taken, gradient steps on HER's relabelled samples after the
        # first episode.
        assert isinstance(model.replay_buffer, sb3.HerReplayBuffer)
        assert model.num_timesteps == steps and model._n_updates > 0
    finally:
        env.close()


def test_sb3_agent_finds_stable_baselines3_without_triton(monkeypatch):
    """CPU-only PyTorch has no triton: Stable-Baselines3, installed, is found all the same
    (the import of triton, which only works around a crash where it exists, is optional)."""
    import sys
    import types

    spec = importlib.util.spec_from_file_location("sb3_agent", SB3_EXAMPLE)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    fake = types.ModuleType("stable_baselines3")
    fake.SAC, fake.HerReplayBuffer = object(), object()
    monkeypatch.setitem(sys.modules, "triton", None)            # `import triton` fails
    monkeypatch.setitem(sys.modules, "stable_baselines3", fake)
    assert module._sb3() == (fake.SAC, fake.HerReplayBuffer)
    monkeypatch.setitem(sys.modules, "stable_baselines3", None)
    with pytest.raises(SystemExit, match=r"needs Stable-Baselines3: pip install -e '\.\[learn\]'"):
        module._sb3()
