"""The model check: whether the filter's model explains what the camera sees, from what the
filter sees alone (a posterior-predictive check, docs/METHOD.md 9).

Per update, the observation's surprise under the filter's own predictive distribution. For
the particle filter, the predictive of an observation y is the mixture over the particles
after the motion step (equally weighted: the filter resamples every update) of Eq. 5's
likelihood, so its log-density at the observation is

    L_obs = log (1/K) sum_i p(y_obs | x_i),

on K particles drawn from the valid ones. Replicate observations y_m drawn from the same
predictive (a particle j, then the likelihood's noise about its predicted pose, the turn's
and the tensions' included) give the same log-density's distribution were the model right,
and the update's surprise is the observed log-density's standard score against it,

    z = (mean_m L_m - L_obs) / sd_m L_m.

The errors are taken in the pose's tangent space at the observation (e_i = (p_i - p_obs,
rotvec(R_i R_obs^T))), so a replicate's error against particle i is e_i - e_j - n. For the
unscented Kalman filter the predictive is its Gaussian (innovation y, covariance S), -2 L =
NIS + const with NIS ~ chi2(d) under the model, and the same standard score is
z = (NIS - d) / sqrt(2 d): the classical NIS test.

A trial's statistic is the mean of z over its updates after `burn_in` actions (the grasp's
wide prior first). A model that explains the observations gives a mean about 0 or below (below
when the likelihood's scales are wider than the world's noise, as ours are: they also absorb
the motion model's own error); one that cannot gives a larger mean. The threshold is a
measured one (`ModelCheckConfig.threshold`, docs/RESULTS.md 10), not a theoretical quantile,
because the likelihood's widening makes the statistic's null distribution the filter's
own. The check reads only the particles' predictions and the observation, and draws from a
generator of its own: it never changes the estimate.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from vlr.kernels.likelihood import Observed, mixture_log_density, pose_errors
from vlr.observation import ObservationModel

__all__ = ["ModelCheckConfig", "predictive_surprise", "nis_surprise", "verdict",
           "threshold_by_rule", "calibration_objects", "MIN_CALIBRATION_TRIALS",
           "MIN_OBJECT_TRIALS"]

#: Trials a threshold is measured on, at the least (`threshold_by_rule`).
MIN_CALIBRATION_TRIALS = 5
#: An object's decided trials, at the least, for its median to count (`threshold_by_rule`).
MIN_OBJECT_TRIALS = 3


@dataclass(frozen=True)
class ModelCheckConfig:
    """The model check's settings (module docstring).

    Attributes:
        threshold: the trial statistic (mean surprise after the burn-in) above which the
            model is said not to explain the observations, measured for the likelihood's
            scales it goes with by `threshold_by_rule` over the known hand's trials on the
            paper's four objects (the default: the sim's, median -1.58, the objects' and the
            seeds' spreads 0.07 and 0.09, 40 trials at 60,000 particles, seeds 0-9;
            docs/RESULTS.md 10). A backend with other scales sets its own (`vlr.backends`;
            `vlr model-check-calibrate` measures it).
        threshold_tensions: the same, for trials whose likelihood also weighs the tendons'
            tensions (`filter.observation.sigma_tension_n` > 0): their replicates carry the
            tensions' noise too, which moves the statistic's null (the sim's with 0.25 N
            readings and a 0.56 N scale: median -1.70, spreads 0.04 and 0.14, 30 trials,
            seeds 0-9; the wine glass left out, decided on one trial of ten: it converges
            within seven actions).
        burn_in: the first actions left out of the statistic (the grasp's prior is wider
            than the likelihood and its first updates surprise any model).
        min_actions: actions after the burn-in before a verdict is given.
        particles: K, the particles the predictive is taken over (a uniform draw of the
            valid ones; all of them when fewer).
        replicates: M, the replicate observations per update.
    """

    threshold: float = -1.23
    threshold_tensions: float = -1.26
    burn_in: int = 3
    min_actions: int = 5
    particles: int = 2048
    replicates: int = 64

    def __post_init__(self) -> None:
        for name in ("threshold", "threshold_tensions"):
            if not math.isfinite(getattr(self, name)):
                raise ValueError(f"{name} {getattr(self, name)!r} must be finite")
        if self.burn_in < 0:
            raise ValueError(f"burn_in {self.burn_in} must be >= 0")
        if self.min_actions < 1:
            raise ValueError(f"min_actions {self.min_actions} must be >= 1")
        if self.particles < 16:
            raise ValueError(f"particles {self.particles} must be >= 16")
        if self.replicates < 8:
            raise ValueError(f"replicates {self.replicates} must be >= 8")


def predictive_surprise(pos: np.ndarray, rot: np.ndarray, anchors: np.ndarray,
                        obs_model: ObservationModel, observation,
                        tensions: np.ndarray | None, rng: np.random.Generator,
                        replicates: int) -> float:
    """The standard score z of the observation's log predictive density (module docstring)
    over the given particles' predictions: pos (K, 3) [m], rot (K, 3, 3), anchors (K, N, 3);
    `tensions` (K, N) [N] each particle's predicted tendon tensions, weighed when the
    likelihood weighs them and the observation has them. NaN with fewer than 2 particles."""
    k = len(pos)
    if k < 2:
        return float("nan")
    s2 = obs_model.sigma_turn ** 2
    e, v = np.empty((k, 6)), np.empty((k, 6))
    pose_errors(np.ascontiguousarray(pos, dtype=float), np.ascontiguousarray(rot, dtype=float),
                np.ascontiguousarray(anchors, dtype=float),
                Observed(np.array(observation.position, dtype=float).reshape(3),
                         np.array(observation.rotation, dtype=float).reshape(3, 3)),
                int(obs_model.opposed) if s2 > 0 else -1, e, v)
    d_inv = np.repeat([obs_model.sigma_pos ** -2, obs_model.sigma_rot ** -2], 3)
    observed_t = getattr(observation, "tensions", None)
    weigh_t = obs_model.sigma_tension > 0 and tensions is not None and observed_t is not None
    t_err = (np.asarray(tensions, dtype=float) - np.asarray(observed_t, dtype=float)[None]
             if weigh_t else np.zeros((k, 0)))
    # Replicates: particle j's predicted error plus the likelihood's noise (Eq. 5: D, the
    # turn's s^2 v v^T, the tensions' s_T^2 I); row 0 is the observation itself.
    j = rng.integers(0, k, size=replicates)
    noise = rng.standard_normal((replicates, 6)) / np.sqrt(d_inv)
    noise += math.sqrt(s2) * rng.standard_normal(replicates)[:, None] * v[j]
    w = np.vstack([np.zeros(6), e[j] + noise])
    wt = np.vstack([np.zeros(t_err.shape[1]), t_err[j] + obs_model.sigma_tension
                    * rng.standard_normal((replicates, t_err.shape[1]))])
    # The tensions are further dimensions of the same Gaussian, off the turn's direction.
    n_t = t_err.shape[1]
    log_p = np.empty(replicates + 1)
    mixture_log_density(np.hstack([e, t_err]), np.hstack([v, np.zeros((k, n_t))]),
                        np.hstack([w, wt]),
                        np.concatenate([d_inv, np.full(n_t, obs_model.sigma_tension ** -2.0)
                                        if n_t else d_inv]),
                        float(s2), log_p)
    rep = log_p[1:]
    sd = rep.std()
    z = float((rep.mean() - log_p[0]) / sd) if sd > 0 else float("nan")
    global LAST_PARTS
    LAST_PARTS = (float("nan"), float("nan"))
    if n_t:
        parts = []
        for err, vv, ww, di, ss in ((e, v, w, d_inv, float(s2)),
                                    (t_err, np.zeros((k, n_t)), wt,
                                     np.full(n_t, obs_model.sigma_tension ** -2.0), 0.0)):
            lp = np.empty(replicates + 1)
            mixture_log_density(np.ascontiguousarray(err), np.ascontiguousarray(vv),
                                np.ascontiguousarray(ww), np.ascontiguousarray(di), ss, lp)
            r = lp[1:]
            parts.append(float((r.mean() - lp[0]) / r.std()) if r.std() > 0 else float("nan"))
        LAST_PARTS = tuple(parts)
    return z


LAST_PARTS = (float("nan"), float("nan"))


def nis_surprise(nis: float, dim: int) -> float:
    """The Gaussian predictive's standard score (module docstring): (NIS - d) / sqrt(2 d)."""
    return float((nis - dim) / math.sqrt(2.0 * dim))


def calibration_objects(objects: list[str]) -> tuple[list[str], list[str]]:
    """The objects whose decided trials (one entry each in `objects`) are enough for their
    median to count in `threshold_by_rule` (`MIN_OBJECT_TRIALS`), and those left out: an
    object that converges within a few actions gets a verdict on a trial or two, and one
    short trial is no median (the wine glass with the tensions read)."""
    from collections import Counter

    from vlr import smoke

    counts = Counter(objects)
    need = smoke.cap(MIN_OBJECT_TRIALS, 1)
    return (sorted(o for o, n in counts.items() if n >= need),
            sorted(o for o, n in counts.items() if n < need))


def threshold_by_rule(objects: list[str], statistics: list[float]) -> float:
    """The threshold measured on trials the model explains, each trial's object and
    statistic: the median plus three times the statistic's spread for a new object,
    sqrt(s_b^2 + s_w^2), with s_b the SD of the objects' medians and s_w the robust SD
    (1.4826 median absolute deviation) of the trials about their object's median, over the
    objects with `MIN_OBJECT_TRIALS` decided trials or more (`calibration_objects`). The
    trials come in clusters, an object's seeds close together and the objects apart: a robust
    SD of them all discounts the objects' spread, a plain SD follows a trial that lost track
    (docs/DECISIONS.md)."""
    from vlr import smoke

    pairs = [(o, float(x)) for o, x in zip(objects, statistics, strict=True) if x is not None]
    kept = set(calibration_objects([o for o, _ in pairs])[0])
    pairs = [(o, x) for o, x in pairs if o in kept]
    need = smoke.cap(MIN_CALIBRATION_TRIALS, smoke.TRIALS)
    if len(pairs) < need or not all(math.isfinite(x) for _, x in pairs):
        raise ValueError(f"{len(pairs)} finite statistics: the rule needs at least {need}")
    names = sorted({o for o, _ in pairs})
    if len(names) < 2:
        raise ValueError(f"trials on {names} alone: the rule needs two objects or more, "
                         f"each with {smoke.cap(MIN_OBJECT_TRIALS, 1)} decided trials")
    medians = {o: float(np.median([x for p, x in pairs if p == o])) for o in names}
    residuals = np.array([x - medians[o] for o, x in pairs])
    s_w = 1.4826 * float(np.median(np.abs(residuals)))
    s_b = float(np.std(list(medians.values()), ddof=1))
    return float(np.median([x for _, x in pairs]) + 3.0 * math.hypot(s_b, s_w))


def verdict(surprise: list[float], config: ModelCheckConfig, tensions: bool = False) -> dict:
    """The trial's model check from its per-update surprises (the grasp's update first):
    the statistic (mean surprise after the burn-in), the threshold (`threshold_tensions`
    where the likelihood weighed the tendons' tensions, `tensions`), the verdict
    ("consistent", "inconsistent", or "undecided" with fewer than `min_actions` actions
    after the burn-in) and the first action from which the running statistic stays above
    the threshold to the end (None when consistent)."""
    z = np.asarray(surprise, dtype=float)
    threshold = config.threshold_tensions if tensions else config.threshold
    first = 1 + config.burn_in  # update i follows action i (update 0 is the grasp's)
    tail = z[first:]
    idx = np.flatnonzero(np.isfinite(tail))
    out = {"statistic": None, "threshold": threshold, "tensions": bool(tensions),
           "verdict": "undecided",
           "first_action_flagged": None, "actions": int(len(idx)), "burn_in": config.burn_in,
           "surprise_by_iteration": [None if not math.isfinite(x) else round(float(x), 3)
                                     for x in z]}
    if len(idx) < config.min_actions:
        return out
    running = np.cumsum(tail[idx]) / np.arange(1, len(idx) + 1)
    stat = float(running[-1])
    out["statistic"] = round(stat, 4)
    if stat <= threshold:
        out["verdict"] = "consistent"
        return out
    out["verdict"] = "inconsistent"
    below = np.flatnonzero(running[config.min_actions - 1:] <= threshold)
    start = (below[-1] + 1 if len(below) else 0) + config.min_actions - 1
    out["first_action_flagged"] = int(first + idx[start])
    return out
