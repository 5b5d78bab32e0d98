"""Active exploration (docs/METHOD.md 8.2): among candidate tendon changes, take the one
whose outcome the particles disagree on most.

The paper explored with random actions. Here each candidate is predicted by the motion model
(Eq. 9) on a random subset of the particles, so that a choice costs `candidates` solves of
`subset` particles, and scored by how much the particles' predicted POM poses spread, in
units of the likelihood's covariance R (Eq. 5): trace(R^-1 C_yy), a cheap proxy for the
expected information gain about every sampled dimension alike.

With the likelihood's turn term (`vlr.observation`, s > 0) R = D + s^2 v v^T, v the subset's
mean turn direction (`vlr.observation.grasp_turn`): an action whose outcomes differ only
along the object's turn in its grip, where the model's own error lies, is worth little; one
that moves the pose off the turn is worth a lot. Measured against random actions in
docs/DECISIONS.md: not a win on the identification's accuracy, kept for users who explore.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vlr.explore import ExplorationRange, random_action
from vlr.observation import grasp_turn, rotation_error

__all__ = ["ActiveExploration", "noise_covariance", "prediction_spread", "choose_action"]


@dataclass(frozen=True)
class ActiveExploration:
    """Settings of the active choice.

    Attributes:
        candidates: random candidate actions drawn per step (`vlr.explore.random_action`).
        subset: particles predicted per candidate.
    """

    candidates: int = 8
    subset: int = 256

    def __post_init__(self) -> None:
        for name in ("candidates", "subset"):
            v = getattr(self, name)
            if not isinstance(v, int) or isinstance(v, bool) or v < 1:
                raise ValueError(f"active exploration {name} {v!r} must be an integer >= 1")


def noise_covariance(sigma_pos: float, sigma_rot: float, turn: np.ndarray | None = None,
                     sigma_turn: float = 0.0) -> np.ndarray:
    """(6, 6) the likelihood's covariance of a POM pose error (position [m], rotation vector
    [rad]): D = diag(sigma_pos^2 I, sigma_rot^2 I) (Eq. 5), plus sigma_turn^2 v v^T with v
    (6,) the turn direction when the turn term is on (`vlr.observation`)."""
    r = np.diag([sigma_pos**2] * 3 + [sigma_rot**2] * 3)
    if sigma_turn > 0 and turn is not None:
        v = np.asarray(turn, dtype=float)
        r = r + sigma_turn**2 * np.outer(v, v)
    return r


def prediction_spread(pos: np.ndarray, rot: np.ndarray, sigma_pos: float,
                      sigma_rot: float, turn: np.ndarray | None = None,
                      sigma_turn: float = 0.0) -> float:
    """Spread of predicted POM poses in likelihood units, trace(R^-1 C_yy): with the fixed
    scales, the summed variance of the positions over sigma_pos^2 plus that of the rotation
    vectors about the first pose over sigma_rot^2 (Eq. 5's scales); R takes the turn term
    when `sigma_turn` > 0 (`noise_covariance`)."""
    if len(pos) < 2:
        return 0.0
    y = np.concatenate([pos, rotation_error(rot, rot[:1])], axis=1)
    c_yy = np.cov(y, rowvar=False, bias=True)
    r = noise_covariance(sigma_pos, sigma_rot, turn, sigma_turn)
    return float(np.trace(np.linalg.solve(r, c_yy)))


def choose_action(pf, rng: np.random.Generator, commands: np.ndarray, center: np.ndarray,
                  explore: ExplorationRange, settings: ActiveExploration) -> np.ndarray:
    """The candidate tendon change whose predicted poses spread most over a random subset of
    the filter's valid particles (`pf`: a `vlr.filter.ParticleFilter`). Falls back to the
    first candidate when no particle is valid or every prediction fails."""
    cands = [random_action(rng, commands, center, explore) for _ in range(settings.candidates)]
    valid = np.flatnonzero(pf.state.valid)
    if len(valid) == 0:
        return cands[0]
    idx = rng.choice(valid, size=min(settings.subset, len(valid)), replace=False)
    base = pf.state.take(idx)
    obs = pf.obs_model
    best, best_score = cands[0], -np.inf
    for delta in cands:
        st = base.copy()
        pf.motion.solve(st, commands + delta, u_from=commands)
        ok = st.valid
        turn = None
        if obs.sigma_turn > 0 and ok.any():
            turn = grasp_turn(st.pos[ok], st.rot[ok], st.anchors[ok], obs.opposed).mean(axis=0)
        score = prediction_spread(st.pos[ok], st.rot[ok], obs.sigma_pos, obs.sigma_rot, turn,
                                  obs.sigma_turn)
        if score > best_score:
            best, best_score = delta, score
    return best
