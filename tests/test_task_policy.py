"""`vlr task --policy`: a user's policy runs where the baseline would, with the same result
files, and a bad one ends in one line (tiny filters: these check the plumbing, not the
accuracy)."""

from __future__ import annotations

import json

import numpy as np

from vlr.cli import main

TINY = ["--particles", "200", "--identify-iterations", "3", "--quiet", "--option", "word=I"]

POLICY = '''
import json, pathlib
import numpy as np

def make(env):
    """Records what it was given; moves the thumb's tendon a little, then holds."""
    seen = {"has_filter": env.pf is not None, "commands": list(env.commands), "calls": 0}
    log = pathlib.Path(__file__).with_suffix(".json")

    def policy(obs):
        seen["calls"] += 1
        seen["obs_keys"] = sorted(obs)
        log.write_text(json.dumps(seen))
        return np.array([0.25, 0.0, 0.0]) if seen["calls"] == 1 else np.zeros(3)
    return policy

def short(env):
    return lambda obs: [0.0, 0.0]

def not_a_policy(env):
    return 42
'''


def _policy_file(tmp_path):
    path = tmp_path / "my_policy.py"
    path.write_text(POLICY)
    return path


def test_a_users_policy_file_runs_in_place_of_the_baseline(tmp_path):
    path = _policy_file(tmp_path)
    out = tmp_path / "run"
    assert main(["task", "handwriting", *TINY, "--policy", f"{path}:make",
                 "--out", str(out)]) == 0
    result = json.loads((out / "result.json").read_text())
    seen = json.loads(path.with_suffix(".json").read_text())
    assert result["policy"] == f"{path}:make" and "controller" not in result
    assert result["steps"] == seen["calls"] >= 1
    assert seen["has_filter"]
    assert seen["obs_keys"] == ["achieved_goal", "desired_goal", "observation"]
    assert "position_mm_mean" in result["errors"] and (out / "task.png").is_file()


def test_the_example_policies_run_and_name_themselves_in_the_summary(tmp_path):
    """`tasks.examples`: hold runs through `vlr task --seeds` and its summary names it;
    camera_only, given the identification's moves, returns a finite step that is not zero
    (it steps from the camera's fit of those moves)."""
    out = tmp_path / "hold"
    assert main(["task", "handwriting", *TINY, "--seeds", "0", "--policy",
                 "vlr.tasks.examples:hold", "--out", str(out)]) == 0
    assert "policy vlr.tasks.examples:hold" in (out / "summary.md").read_text()

    import gymnasium as gym
    from vlr.tasks.examples import camera_only

    from vlr import tasks

    env = gym.make(tasks.HANDWRITING, particles=200, identify_iterations=3, word="I")
    try:
        obs, _ = env.reset(seed=0)
        policy = camera_only(env.unwrapped)
        action = policy(obs)
        assert action.shape == (3,) and np.all(np.isfinite(action))
        assert np.max(np.abs(action)) > 0
    finally:
        env.close()


def test_a_bad_action_or_factory_is_one_line_naming_the_policy(tmp_path, capsys):
    path = _policy_file(tmp_path)
    for name, message in (("short", "returned [0.0, 0.0] at step 0"),
                          ("not_a_policy", "the factory returned 42")):
        out = tmp_path / name
        assert main(["task", "handwriting", *TINY, "--policy", f"{path}:{name}",
                     "--out", str(out)]) == 2
        err = capsys.readouterr().err
        assert message in err and f"{path}:{name}" in err and "Traceback" not in err, err
        assert not (out / "result.json").exists()
