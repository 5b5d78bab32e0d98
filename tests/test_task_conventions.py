"""The task environments as Gymnasium-Robotics' goal environments: the spec (step limit,
checker on, reward type) and the spaces of every registered id; `step`'s reward, terminated
and truncated against `compute_reward`, `compute_terminated` and `compute_truncated` (one
call and a batch) over rollouts of both rewards of each task, and Gymnasium-Robotics' own
`GoalEnv` checks; then, on one id per task (the sparse one: the dense twin differs in the
reward only), `is_success` and no ground truth in `info` unless asked, gymnasium's env
checker without a warning, a same-seed rollout, pickling, a 2-env AsyncVectorEnv with
autoreset and the common wrappers, failures that end an episode instead of raising, and bad
input in one line.

Settings that keep CI fast: handwriting and the maze without identification (a reset is a
grasp), cup stacking (which places each cup by its identified VLR) with a small filter that
does not update on every step, one letter, one run, one cup. With VLR_TASKS_AT_DEFAULTS=1 every
env runs at its defaults instead (docs/TASKS.md: what the conventions cost there)."""

from __future__ import annotations

import functools
import os
import pickle

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.envs.registration import load_env_creator
from gymnasium.utils.env_checker import check_env
from vlr.tasks.base import _goal_distances

from tests.env_rollout import rollout, same
from vlr import tasks

FAST = {
    tasks.HANDWRITING: {"identify": False, "word": "I"},
    tasks.MARBLE_MAZE: {"identify": False, "n_runs": 1},
    tasks.CUP_STACKING: {"particles": 300, "identify_iterations": 1, "n_cups": 1,
                         "filter_updates": False},
}
if os.environ.get("VLR_TASKS_AT_DEFAULTS") == "1":
    FAST = {env_id: {} for env_id in FAST}
FAST.update({tasks.DENSE[env_id]: kwargs for env_id, kwargs in list(FAST.items())})
IDS = list(tasks.DENSE)                 # one id per task: the sparse one
ALL_IDS = list(tasks.ENVIRONMENTS)      # both rewards of each task
ACTIONS = np.array([[0.5, -0.5, 0.25], [-1.0, 0.5, 0.5], [0.0, 0.0, -0.5]], dtype=np.float32)
# One move per target: the episode ends (terminated) within a few steps.
SHORT = {"vlr/Handwriting": {"steps_per_waypoint": 1},
         "vlr/MarbleMaze": {"steps_per_run": 1, "dwell": 0.0},
         "vlr/CupStacking": {"steps_per_cup": 1}}


def _short(env_id: str) -> dict:
    task = env_id.split("-")[0].removesuffix("Dense")
    return {**FAST[env_id], **SHORT[task]}


def test_every_registered_id_is_covered_here():
    registered = {i for i in gym.registry if i.startswith("vlr/")}
    assert set(FAST) == set(ALL_IDS) == registered
    # Fetch's naming: the plain id sparse, a `Dense` suffix dense, one version for both.
    assert tasks.DENSE == {"vlr/Handwriting-v2": "vlr/HandwritingDense-v2",
                           "vlr/MarbleMaze-v2": "vlr/MarbleMazeDense-v2",
                           "vlr/CupStacking-v2": "vlr/CupStackingDense-v2"}


@pytest.mark.parametrize("env_id", ALL_IDS)
def test_spec_spaces_and_goal_keys(env_id):
    spec = gym.spec(env_id)
    reg = tasks.ENVIRONMENTS[env_id]
    assert spec.max_episode_steps == reg.max_episode_steps
    assert spec.kwargs == {"reward_type": reg.reward_type}
    assert reg.reward_type == ("dense" if env_id in tasks.DENSE.values() else "sparse")
    assert not spec.disable_env_checker
    env = gym.make(env_id, **FAST[env_id])   # nothing is opened before reset
    try:
        assert env.unwrapped.reward_type == reg.reward_type
        assert "PassiveEnvChecker" in str(env) and "TimeLimit" in str(env)
        assert env.action_space == gym.spaces.Box(-1.0, 1.0, (3,), np.float32)
        assert set(env.observation_space.spaces) == {"observation", "achieved_goal",
                                                     "desired_goal"}
        assert env.metadata["render_fps"] == 4
    finally:
        env.close()


@pytest.mark.parametrize("env_id", ALL_IDS)
def test_step_returns_what_the_goal_functions_give(env_id):
    """Gymnasium-Robotics' contract: reward, terminated and truncated are `compute_reward`,
    `compute_terminated` and `compute_truncated` of the returned goals and info, one step at
    a time and over the whole rollout at once (HER relabels in batches). Sparse: -1 or 0,
    Fetch's; dense: minus the distance. The episode runs until the task terminates it."""
    env = gym.make(env_id, **_short(env_id))
    u = env.unwrapped
    try:
        _, info = env.reset(seed=0)
        assert isinstance(info["is_success"], float) and not info["task_done"]
        steps = []
        for k in range(20):
            obs, reward, terminated, truncated, info = env.step(ACTIONS[k % len(ACTIONS)])
            ag, dg = obs["achieved_goal"], obs["desired_goal"]
            assert isinstance(reward, float) and type(terminated) is type(truncated) is bool
            assert reward == u.compute_reward(ag, dg, info)
            assert terminated == u.compute_terminated(ag, dg, info)
            assert truncated == u.compute_truncated(ag, dg, info)
            assert info["is_success"] in (0.0, 1.0) and isinstance(info["is_success"], float)
            steps.append((ag, dg, info, reward, terminated, truncated))
            if terminated or truncated:
                break
        assert terminated and not truncated and info["task_done"]
        ag, dg, infos, rewards, ends, cuts = (np.array(v) for v in zip(*steps, strict=True))
        np.testing.assert_array_equal(u.compute_reward(ag, dg, infos), rewards)
        np.testing.assert_array_equal(u.compute_terminated(ag, dg, infos), ends)
        np.testing.assert_array_equal(u.compute_truncated(ag, dg, infos), cuts)
        # ... and over a vector env's info: a dict of arrays, one value per env.
        stacked = {k: np.array([i[k] for i in infos], dtype=object)
                   for k in ("task_done", "grasp_lost", "identification_failed", "moves")}
        np.testing.assert_array_equal(u.compute_reward(ag, dg, stacked), rewards)
        np.testing.assert_array_equal(u.compute_terminated(ag, dg, stacked), ends)
        np.testing.assert_array_equal(u.compute_truncated(ag, dg, stacked), cuts)
        success = np.array([i["is_success"] for i in infos])
        if u.reward_type == "sparse":
            np.testing.assert_array_equal(rewards, success - 1.0)
        else:
            pos_mm, rot_deg = _goal_distances(u.goal_rows, ag, dg)
            d = {"position": pos_mm, "rotation": rot_deg,
                 "pose": np.hypot(pos_mm, u.controller_config.alpha * rot_deg)}[u.goal_rows]
            np.testing.assert_allclose(rewards, -d)
        # HER's relabelling (empty infos): the achieved goal as the desired one is a success.
        relabelled = u.compute_reward(ag, ag, [{}] * len(ag))
        np.testing.assert_allclose(relabelled, np.zeros(len(ag)), atol=1e-6)
    finally:
        env.close()


@pytest.mark.parametrize("env_id", IDS)
def test_gymnasium_robotics_goal_env_checks(env_id):
    """Gymnasium-Robotics' `GoalEnv` as a base of the task's class (tasks/base.py does not
    import it: docs/DECISIONS.md): its `reset` checks the observation space, and the
    three goal functions it leaves abstract are the task's, with its signatures."""
    import inspect

    core = pytest.importorskip(
        "gymnasium_robotics.core",
        reason="Gymnasium-Robotics is in the dev extra (pip install -e '.[dev]')")
    cls = load_env_creator(gym.spec(env_id).entry_point)
    checked = type(f"Goal{cls.__name__}", (cls, core.GoalEnv), {})
    for name in ("compute_reward", "compute_terminated", "compute_truncated"):
        assert getattr(checked, name) is getattr(cls, name)
        assert (list(inspect.signature(getattr(cls, name)).parameters)
                == list(inspect.signature(getattr(core.GoalEnv, name)).parameters))
    env = checked(reward_type=tasks.ENVIRONMENTS[env_id].reward_type, **FAST[env_id])
    try:
        obs, info = env.reset(seed=0)   # GoalEnv.reset's checks run first
        assert env.observation_space.contains(obs)
        obs, reward, terminated, truncated, info = env.step(ACTIONS[0])
        assert reward == env.compute_reward(obs["achieved_goal"], obs["desired_goal"], info)
        env.observation_space = gym.spaces.Dict({"observation": env.observation_space[
            "observation"]})
        with pytest.raises(gym.error.Error, match="achieved_goal"):
            env.reset(seed=0)            # the check can fail
    finally:
        env.close()


@pytest.mark.parametrize("env_id", IDS)
def test_env_checker_rewards_success_and_no_truth(env_id):
    import warnings

    env = gym.make(env_id, render_mode="rgb_array", **FAST[env_id])
    try:
        env.reset(seed=0)   # seeded: check_env also resets without a seed, which would draw
        # one from the OS and make the test vary run to run. No warning, as
        # Gymnasium-Robotics' own test of its environments asks.
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            check_env(env.unwrapped)
        assert not [str(w.message) for w in caught]
        obs, info = env.reset(seed=1)
        assert "truth" not in info and info["is_success"] in (0.0, 1.0)
        frame = env.render()
        assert frame.dtype == np.uint8 and frame.ndim == 3 and frame.shape[2] == 3
        u = env.unwrapped
        for a in ACTIONS:
            obs, reward, terminated, truncated, info = env.step(a)
            assert "truth" not in info and isinstance(info["is_success"], float)
            # The change applied is the action times max_step, unless the band clipped it.
            assert np.all(np.abs(info["action_m"]) <= np.abs(a.astype(float)) * u.max_step + 1e-12)
    finally:
        env.close()


def test_truth_only_when_asked():
    env = gym.make(tasks.HANDWRITING, expose_truth=True, **FAST[tasks.HANDWRITING])
    try:
        _, info = env.reset(seed=0)
        assert {"pom_position", "pom_rotation"} <= set(info["truth"])
    finally:
        env.close()


@pytest.mark.parametrize("env_id", IDS)
def test_same_seed_same_episode(env_id):
    a = rollout(env_id, 3, ACTIONS[:2], **FAST[env_id])
    b = rollout(env_id, 3, ACTIONS[:2], **FAST[env_id])
    assert same(a, b)


@pytest.mark.parametrize("env_id", IDS)
def test_a_pickled_env_runs_the_same_episode(env_id):
    env = gym.make(env_id, **FAST[env_id])
    copy = pickle.loads(pickle.dumps(env))
    try:
        for e in (env, copy):
            e.reset(seed=2)
        assert same([env.step(ACTIONS[0])[:2]], [copy.step(ACTIONS[0])[:2]])
    finally:
        env.close()
        copy.close()


def _wrapped(env_id: str) -> gym.Env:
    """The env as a learner wraps it: a short step limit, episode statistics, flat
    observations."""
    env = gym.make(env_id, max_episode_steps=2, **FAST[env_id])
    env = gym.wrappers.RecordEpisodeStatistics(env)
    return gym.wrappers.FlattenObservation(env)


@pytest.mark.parametrize("env_id", IDS)
def test_async_vector_env_with_autoreset(env_id):
    envs = gym.vector.AsyncVectorEnv([functools.partial(_wrapped, env_id)] * 2,
                                     context="spawn")
    try:
        obs, _ = envs.reset(seed=[0, 1])
        assert obs.shape[0] == 2 and np.all(np.isfinite(obs))
        ended = np.zeros(2, dtype=bool)
        for a in ACTIONS:
            obs, reward, terminated, truncated, info = envs.step(np.stack([a, -a]))
            assert np.all(np.isfinite(reward))
            if np.any(terminated | truncated):
                assert "episode" in info     # RecordEpisodeStatistics
            ended |= terminated | truncated
        assert ended.all()   # the step limit of 2 ended both; the next step autoreset them
    finally:
        envs.close()


def _at_defaults(env_id: str) -> gym.Env:
    return gym.wrappers.FlattenObservation(gym.make(env_id, max_episode_steps=2))


@pytest.mark.parametrize("env_id", ALL_IDS)
def test_forked_workers_run_after_the_parent_used_an_env(env_id):
    """Fork is gymnasium's (and Stable-Baselines3's) default start method on Linux: workers
    forked from a process that has already identified a grasp and rendered its camera (a
    user reading the spaces, the checker first) run too, at the defaults. numba's GNU
    OpenMP layer aborted them and Mesa's llvmpipe threads hung them; `vlr` picks numba's
    fork-safe layer and `sim` renders on the caller's thread."""
    parent = gym.make(env_id)
    try:
        parent.reset(seed=0)
    finally:
        parent.close()
    envs = gym.vector.AsyncVectorEnv([functools.partial(_at_defaults, env_id)] * 2)
    try:
        # With a timeout: a hung or aborted worker leaves the parent waiting for ever.
        envs.reset_async(seed=[0, 1])
        obs, _ = envs.reset_wait(timeout=300)
        assert obs.shape[0] == 2 and np.all(np.isfinite(obs))
        envs.step_async(np.stack([ACTIONS[0], -ACTIONS[0]]))
        _, reward, *_ = envs.step_wait(timeout=300)
        assert np.all(np.isfinite(reward))
    finally:
        envs.close(terminate=True)


def test_a_failed_identification_truncates_the_episode(monkeypatch):
    import vlr.run

    def fails(*args, **kwargs):
        raise FloatingPointError("no particle settled at the grasp command")

    monkeypatch.setattr(vlr.run, "run_identification", fails)
    env = gym.make(tasks.HANDWRITING, word="I", particles=100)
    try:
        obs, info = env.reset(seed=0)
        assert "no particle settled" in info["identification_failed"]
        assert info["is_success"] == 0.0 and env.observation_space.contains(obs)
        obs, reward, terminated, truncated, info = env.step(ACTIONS[0])
        assert truncated and not terminated and info["is_success"] == 0.0
        # Sparse: no pose was seen, so no success, though both goals are zeros.
        u, ag, dg = env.unwrapped, obs["achieved_goal"], obs["desired_goal"]
        assert np.array_equal(ag, dg) and reward == u.compute_reward(ag, dg, info) == -1.0
        assert u.compute_truncated(ag, dg, info) and not u.compute_terminated(ag, dg, info)
    finally:
        env.close()


def test_bad_input_is_one_line():
    with pytest.raises(TypeError, match="speed"):
        gym.make(tasks.HANDWRITING, speed=2)
    with pytest.raises(ValueError, match="reward_type 'shaped'"):
        gym.make(tasks.HANDWRITING, reward_type="shaped")
    with pytest.raises(ValueError, match="identify=False"):
        gym.make(tasks.CUP_STACKING, identify=False)
    env = gym.make(tasks.HANDWRITING, **FAST[tasks.HANDWRITING])
    try:
        with pytest.raises(Exception, match="[Ss]eed"):
            env.reset(seed="zero")
        env.reset(seed=0)
        with pytest.raises(ValueError, match=r"shape \(2,\), expected \(3,\)"):
            env.unwrapped.step(np.zeros(2))
        with pytest.raises(ValueError, match="not finite"):
            env.unwrapped.step(np.array([np.nan, 0.0, 0.0]))
    finally:
        env.close()
