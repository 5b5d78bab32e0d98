"""The task environments as Gymnasium-Robotics' goal environments, over every registered id:
the spec (step limit, checker on), the spaces, `compute_reward` against the step rewards,
`is_success` and no ground truth in `info` unless asked, gymnasium's env checker, a same-seed
rollout, pickling, a 2-env AsyncVectorEnv with autoreset and the common wrappers, failures
that end an episode instead of raising, and bad input in one line.

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
from gymnasium.utils.env_checker import check_env

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
IDS = list(tasks.ENVIRONMENTS)
ACTIONS = np.array([[0.5, -0.5, 0.25], [-1.0, 0.5, 0.5], [0.0, 0.0, -0.5]], dtype=np.float32)


def test_every_registered_id_is_covered_here():
    assert set(FAST) == set(gym.registry) & {i for i in gym.registry if i.startswith("vlr/")}


@pytest.mark.parametrize("env_id", IDS)
def test_spec_spaces_and_goal_keys(env_id):
    spec = gym.spec(env_id)
    assert spec.max_episode_steps == tasks.ENVIRONMENTS[env_id][1]
    assert not spec.disable_env_checker
    env = gym.make(env_id, **FAST[env_id])   # nothing is opened before reset
    try:
        assert "PassiveEnvChecker" in str(env) and "TimeLimit" in str(env)
        assert env.action_space == gym.spaces.Box(-1.0, 1.0, (3,), np.float32)
        assert set(env.observation_space.spaces) == {"observation", "achieved_goal",
                                                     "desired_goal"}
        assert env.metadata["render_fps"] == 4
    finally:
        env.close()


@pytest.mark.parametrize("env_id", IDS)
def test_env_checker_rewards_success_and_no_truth(env_id):
    env = gym.make(env_id, render_mode="rgb_array", **FAST[env_id])
    try:
        env.reset(seed=0)   # seeded: check_env also resets without a seed, which would draw
        check_env(env.unwrapped)  # one from the OS and make the test vary run to run
        obs, info = env.reset(seed=1)
        assert "truth" not in info and info["is_success"] in (True, False)
        frame = env.render()
        assert frame.dtype == np.uint8 and frame.ndim == 3 and frame.shape[2] == 3
        u = env.unwrapped
        achieved, desired, rewards = [], [], []
        for a in ACTIONS:
            obs, reward, terminated, truncated, info = env.step(a)
            assert "truth" not in info and isinstance(info["is_success"], bool)
            # The change applied is the action times max_step, unless the band clipped it.
            assert np.all(np.abs(info["action_m"]) <= np.abs(a.astype(float)) * u.max_step + 1e-12)
            achieved.append(obs["achieved_goal"])
            desired.append(obs["desired_goal"])
            rewards.append(reward)
            assert reward == u.compute_reward(obs["achieved_goal"], obs["desired_goal"], info)
        # Vectorised, as HER relabels: one call over the batch gives each step's reward.
        np.testing.assert_allclose(u.compute_reward(np.array(achieved), np.array(desired),
                                                    None), rewards)
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


@pytest.mark.parametrize("env_id", IDS)
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
        assert not info["is_success"] and env.observation_space.contains(obs)
        _, _, terminated, truncated, info = env.step(ACTIONS[0])
        assert truncated and not terminated
    finally:
        env.close()


def test_bad_input_is_one_line():
    with pytest.raises(TypeError, match="speed"):
        gym.make(tasks.HANDWRITING, speed=2)
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
