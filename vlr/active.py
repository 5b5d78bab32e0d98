"""Active exploration (METHOD.md 8.2; issue 5 item 4): among candidate tendon changes, take
the one whose predicted POM poses disagree most across the particles.

The paper explored with random actions. An action is informative when the hypotheses predict
different outcomes for it: the particles' predicted POM poses, in units of the likelihood's
scales (Eq. 5), spread the most. That spread is a cheap proxy for the expected information
gain. Each candidate is predicted by the motion model (Eq. 9) on a random subset of the
particles, so a choice costs `candidates` solves of `subset` particles.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from vlr.explore import ExplorationRange, random_action

__all__ = ["ActiveExploration", "prediction_spread", "choose_action"]


@dataclass(frozen=True)
class ActiveExploration:
    """Settings of the active choice.

    Attributes:
        candidates: random candidate actions drawn per step (`vlr.explore.random_action`).
        subset: particles predicted per candidate.
        model_error: kappa, the model's expected error as a fraction of the motion a
            candidate causes; the spread is then measured against sigma^2 + (kappa x the
            subset's mean predicted POM motion)^2, so that a large action, whose outcome the
            model predicts worst, is not chosen for its size alone. 0 = the likelihood's
            fixed scales (the choice measured on the synthetic world).
    """

    candidates: int = 8
    subset: int = 256
    model_error: float = 0.0

    def __post_init__(self) -> None:
        for name in ("candidates", "subset"):
            v = getattr(self, name)
            if not isinstance(v, int) or isinstance(v, bool) or v < 1:
                raise ValueError(f"active exploration {name} {v!r} must be an integer >= 1")
        if (isinstance(self.model_error, bool) or not isinstance(self.model_error, int | float)
                or not 0 <= self.model_error < 10):
            raise ValueError(f"active exploration model_error {self.model_error!r} must be a "
                             "number in [0, 10)")


def prediction_spread(pos: np.ndarray, rot: np.ndarray, sigma_pos: float,
                      sigma_rot: float) -> float:
    """Spread of predicted POM poses in likelihood units: the summed variance of the
    positions over sigma_pos^2 plus that of the rotation vectors about their first pose over
    sigma_rot^2 (Eq. 5's scales)."""
    if len(pos) < 2:
        return 0.0
    rel = Rotation.from_matrix(np.einsum("ba,pbc->pac", rot[0], rot)).as_rotvec()
    return float(pos.var(axis=0).sum() / sigma_pos**2 + rel.var(axis=0).sum() / sigma_rot**2)


def choose_action(pf, rng: np.random.Generator, commands: np.ndarray, center: np.ndarray,
                  explore: ExplorationRange, settings: ActiveExploration) -> np.ndarray:
    """The candidate tendon change whose predicted POM poses spread the most across a random
    subset of the filter's valid particles (`pf`: a `vlr.filter.ParticleFilter`). Falls back
    to the first candidate when no particle is valid or every prediction fails."""
    cands = [random_action(rng, commands, center, explore) for _ in range(settings.candidates)]
    valid = np.flatnonzero(pf.state.valid)
    if len(valid) == 0:
        return cands[0]
    idx = rng.choice(valid, size=min(settings.subset, len(valid)), replace=False)
    base = pf.state.take(idx)
    obs = pf.config.observation
    best, best_score = cands[0], -np.inf
    k = settings.model_error
    for delta in cands:
        st = base.copy()
        pf.motion.solve(st, commands + delta, u_from=commands)
        ok = st.valid
        sp, sr = obs.sigma_pos, obs.sigma_rot
        if k > 0 and ok.any():
            moved = np.linalg.norm(st.pos[ok] - base.pos[ok], axis=-1).mean()
            turned = Rotation.from_matrix(np.einsum("pba,pbc->pac", base.rot[ok],
                                                    st.rot[ok])).magnitude().mean()
            sp, sr = np.hypot(sp, k * moved), np.hypot(sr, k * turned)
        score = prediction_spread(st.pos[ok], st.rot[ok], sp, sr)
        if score > best_score:
            best, best_score = delta, score
    return best
