"""Shared by the task tests: a seeded rollout of a gymnasium env, and exact comparison of two."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np


def rollout(env_id: str, seed: int, actions: np.ndarray, **make_kwargs: Any) -> list:
    """(observation, reward, info) after reset and after each action, until the episode ends."""
    env = gym.make(env_id, **make_kwargs)
    try:
        obs, info = env.reset(seed=seed)
        out = [(obs, 0.0, info)]
        for a in actions:
            obs, reward, terminated, truncated, info = env.step(a)
            out.append((obs, reward, info))
            if terminated or truncated:
                break
        return out
    finally:
        env.close()


def same(a: Any, b: Any) -> bool:
    """Exact equality of nested dicts, lists and arrays (same seed, same numbers)."""
    if isinstance(a, dict):
        return a.keys() == b.keys() and all(same(a[k], b[k]) for k in a)
    if isinstance(a, (list, tuple)):
        return len(a) == len(b) and all(same(x, y) for x, y in zip(a, b, strict=True))
    return bool(np.array_equal(np.asarray(a), np.asarray(b)))
