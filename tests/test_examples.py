"""examples/compare_policies.py: a user's policy, the baseline and a reference side by side
in one `vlr task` summary (a tiny filter: the plumbing, not the accuracy)."""

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


def test_sb3_agent_trains_and_runs_beside_the_baseline(tmp_path, capsys):
    pytest.importorskip("stable_baselines3", reason="the `learn` extra (pip install -e '.[learn]')")
    spec = importlib.util.spec_from_file_location("sb3_agent", SB3_EXAMPLE)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    assert module.main(["--train-steps", "16", "--particles", "300",
                        "--identify-iterations", "2", "--out", str(tmp_path)]) == 0
    assert (tmp_path / "ppo.zip").is_file()
    table = capsys.readouterr().out.split("the policies side by side")[1]
    assert "| handwriting | 0 |" in table, table
    assert "| handwriting, policy sb3_agent.py:agent | 0 |" in table, table


def test_sb3_agent_finds_stable_baselines3_without_triton(monkeypatch):
    """CPU-only PyTorch has no triton: Stable-Baselines3, installed, is found all the same
    (the import of triton, which only works around a crash where it exists, is optional)."""
    import sys
    import types

    spec = importlib.util.spec_from_file_location("sb3_agent", SB3_EXAMPLE)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    fake = types.ModuleType("stable_baselines3")
    fake.PPO = object()
    monkeypatch.setitem(sys.modules, "triton", None)            # `import triton` fails
    monkeypatch.setitem(sys.modules, "stable_baselines3", fake)
    assert module._ppo() is fake.PPO
    monkeypatch.setitem(sys.modules, "stable_baselines3", None)
    with pytest.raises(SystemExit, match="needs Stable-Baselines3"):
        module._ppo()
