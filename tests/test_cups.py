"""Cup stacking (`vlr/CupStacking-v0`, tasks/cups.py): the env checker, same-seed
determinism, the hardware backend refused in one line, and `vlr task cups` writing its
result and picture. One cup instead of four and a short identification keep it to about a
minute; the five-seed figures are in docs/TASKS.md."""

from __future__ import annotations

import json

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import tasks
from tests.env_rollout import rollout, same
from vlr.errors import UserError

QUICK = {"particles": 2000, "identify_iterations": 1, "n_cups": 1}


def test_cup_stacking_passes_the_env_checker_and_renders():
    env = gym.make(tasks.CUP_STACKING, render_mode="rgb_array", **QUICK)
    try:
        check_env(env.unwrapped)
        obs, info = env.reset(seed=1)
        frame = env.render()
        assert frame.dtype == np.uint8 and frame.ndim == 3 and frame.shape[2] == 3
        assert set(info["truth"]["cups"]) == {"cup1", "cup2", "cup3", "cup4", "cup5"}
        # the picked cup hangs under the palm, its tag seen by the palm camera
        assert info["tag_seen"] and 0.04 < obs["pose"][2] < 0.1
    finally:
        env.close()


def test_cup_stacking_is_deterministic_for_a_seed():
    actions = np.array([[1e-4, -1e-4, 0.5e-4], [-1e-4, 1e-4, 1e-4]])
    a = rollout(tasks.CUP_STACKING, 3, actions, **QUICK)
    b = rollout(tasks.CUP_STACKING, 3, actions, **QUICK)
    assert same(a, b)
    assert "truth" in a[-1][2] and a[-1][1] <= 0.0


def test_cup_stacking_refuses_the_hardware_backend_in_one_line(tmp_path, capsys):
    with pytest.raises(UserError, match="arm"):
        gym.make(tasks.CUP_STACKING, backend="hardware",
                 hardware_config="hardware/example_sim_config.yaml")
    from vlr.cli import main

    assert main(["task", "cups", "--backend", "hardware", "--config",
                 "hardware/example_sim_config.yaml", "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "arm" in err and "Traceback" not in err


def test_task_cups_writes_result_and_picture(tmp_path):
    """One cup through `vlr task cups`: the keys of result.json and the stack picture."""
    from vlr.cli import main

    out = tmp_path / "cups"
    rc = main(["task", "cups", "--seed", "0", "--particles", "2000",
               "--identify-iterations", "2", "--quiet", "--option", "n_cups=1",
               "--out", str(out)])
    assert rc == 0
    result = json.loads((out / "result.json").read_text())
    assert (out / "task.png").stat().st_size > 1000
    e = result["errors"]
    assert {"position_mm_mean", "rotation_deg_mean"} <= e.keys()
    assert np.isfinite(e["position_mm_mean"]) and np.isfinite(e["rotation_deg_mean"])
    assert result["cups_stacked"] in (0, 1) and len(e["per_cup"]) == 1
