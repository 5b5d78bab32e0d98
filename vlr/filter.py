"""The particle filter of the self-identification (Algorithm 1; docs/METHOD.md 3, 8.2), and
what it shares with the unscented Kalman filter of `vlr.ukf` (`GraspFilter`).

One iteration: move every particle by the motion model with the common command u_t
(Eq. 4, 9); predict its POM pose (Eq. 5); weight by the likelihood of the observed pose,
tempered so that the effective sample size stays above a fraction of P; resample
(systematic); jitter (Liu-West, scaled to the particle covariance, the springs on their
logarithms) and settle each jittered particle at u_t, its POM anchors re-derived in its new
contact frame.

Sampled dimensions ("dims"), in this order: joint angles theta (N*K) [rad]; the contact on
each pad as two angles (alpha, beta) per finger [rad] (`vlr.kinematics.normals_from_angles`);
then the unknown parameters asked for (`vlr.unknowns`). Both estimators carry these
dimensions, move their hypotheses (particles, or sigma points) by the same motion model and
weigh them by the same observation model (`GraspFilter`); `filter.estimator` chooses one.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace
from typing import Literal

import numpy as np

from vlr.kernels.frames import object_points, palm_points
from vlr.kinematics import HandModel, angles_from_normals, normals_from_angles
from vlr.model_check import ModelCheckConfig, predictive_surprise
from vlr.motion import MotionConfig, MotionModel, ObjectParams, ParticleState
from vlr.observation import ObservationConfig, ObservationModel, PoseObservation
from vlr.surface import surface_contact_normals
from vlr.unknowns import (
    SPRING_KINDS,
    check_unknown_set,
    draw_prior,
    hold_unknowns,
    parse_unknown,
    set_unknown,
    unknown_values,
)

__all__ = [
    "ObjectBelief",
    "UnscentedConfig",
    "FilterConfig",
    "Summary",
    "IterationRecord",
    "GraspFilter",
    "ParticleFilter",
    "systematic_resample",
    "effective_sample_size",
    "temper",
    "interval_width_deg",
]


# --------------------------------------------------------------------------- pure helpers

def systematic_resample(weights: np.ndarray, rng: np.random.Generator | None = None,
                        offset: float | None = None) -> np.ndarray:
    """Systematic resampling: indexes drawn with one uniform offset (filterpy's algorithm).

    Same result as `filterpy.monte_carlo.systematic_resample` for the same offset, but with an
    explicit Generator instead of NumPy's global RNG, and guarded against round-off: the
    cumulative sum's last entry is set to exactly 1, so no index can fall past the end.

    Args:
        weights: (P,) non-negative weights summing to 1 (approximately).
        rng: source of the offset (ignored if `offset` is given).
        offset: the uniform offset in [0, 1), for tests.
    Returns:
        (P,) int indexes.
    """
    w = np.asarray(weights, dtype=float)
    n = w.size
    if offset is None:
        if rng is None:
            raise ValueError("pass an np.random.Generator or an offset")
        offset = float(rng.random())
    positions = (offset + np.arange(n)) / n
    cumulative = np.cumsum(w)
    cumulative[-1] = 1.0
    idx = np.searchsorted(cumulative, positions, side="right")
    return np.minimum(idx, n - 1)


def effective_sample_size(weights: np.ndarray) -> float:
    """ESS = 1 / sum w^2 for normalised weights."""
    w = np.asarray(weights, dtype=float)
    s = w.sum()
    return float(1.0 / np.sum((w / s) ** 2)) if s > 0 else 0.0


def temper(log_lik: np.ndarray, ess_fraction: float, iterations: int = 30,
           max_beta: float = 1.0) -> tuple[np.ndarray, float]:
    """Tempered weights w ~ L^beta with the largest beta in (0, max_beta] whose
    ESS >= ess_fraction P.

    Early in a run the likelihood is sharp against a wide prior and plain weights collapse
    onto a few dozen particles (docs/METHOD.md 8.2); tempering keeps the particle set alive while
    still moving it towards the observation. Bisection on beta.

    Returns:
        normalised weights (P,), beta.
    """
    ll = np.asarray(log_lik, dtype=float)
    finite = np.isfinite(ll)
    if not finite.any():
        raise FloatingPointError("every particle has zero likelihood (all solves failed)")
    ll = ll - ll[finite].max()
    target = ess_fraction * ll.size

    def weights(beta: float) -> np.ndarray:
        w = np.where(finite, np.exp(beta * np.where(finite, ll, 0.0)), 0.0)
        return w / w.sum()

    w = weights(max_beta)
    if effective_sample_size(w) >= target or ess_fraction <= 0:
        return w, max_beta
    lo, hi = 0.0, max_beta
    for _ in range(iterations):
        mid = 0.5 * (lo + hi)
        if effective_sample_size(weights(mid)) >= target:
            lo = mid
        else:
            hi = mid
    beta = max(lo, 1e-12)
    return weights(beta), beta


def interval_width_deg(theta_samples: np.ndarray) -> float:
    """The convergence measure (docs/METHOD.md 3): the mean over joint angles of the 95%
    interval width [deg].

    theta_samples: (P, N*K) or (P, N, K) angles [rad] of equally weighted particles."""
    t = np.asarray(theta_samples).reshape(len(theta_samples), -1)
    q = np.quantile(t, [0.025, 0.975], axis=0)
    return float(np.degrees(np.mean(q[1] - q[0])))


# --------------------------------------------------------------------------- config and records

# A prior of which no particle settles at the grasp command is drawn again this many times in
# all: a small filter's unlucky draw (1000 particles in a task's check) is not a lost grasp.
PRIOR_DRAWS = 3


@dataclass(frozen=True)
class ObjectBelief:
    """The object the filter believes, where it is not its spec's (None: the spec's). The
    world keeps the spec's: a wrong belief is something to measure, and with the object's
    unknowns (`vlr.unknowns`) the belief is the centre of their priors.

    Attributes:
        mass: [kg].
        com: centre of mass in the object frame O [m].
        curvature: the local curvature 1/rho of its surface at the contacts [1/m] (0: flat;
            `vlr.surface.LocalSurface.with_curvature`).
    """

    mass: float | None = None
    com: tuple[float, float, float] | None = None
    curvature: float | None = None

    def __post_init__(self) -> None:
        if self.mass is not None and not (math.isfinite(self.mass) and self.mass > 0):
            raise ValueError(f"mass {self.mass} kg must be finite and > 0")
        if self.com is not None and not all(math.isfinite(c) for c in self.com):
            raise ValueError(f"com {list(self.com)} m must be finite")
        if self.curvature is not None and not (math.isfinite(self.curvature)
                                               and self.curvature >= 0):
            raise ValueError(f"curvature {self.curvature} 1/m must be finite and >= 0")


@dataclass(frozen=True)
class UnscentedConfig:
    """Settings of the unscented Kalman filter (`vlr.ukf`; `filter.estimator: ukf`).

    Attributes:
        alpha: the spread of the scaled sigma points (van der Merwe's alpha, in (0, 1]): they
            lie alpha sqrt(D + kappa) standard deviations from the mean, D the sampled
            dimensions (12 for the Model O without unknowns: 0.5 puts them 1.7 sd out).
        beta: the prior's kurtosis term (2: Gaussian).
        kappa: the secondary scaling (D + kappa > 0).
        process_theta_deg: process noise of each joint angle per action [deg] (the motion
            model's error the particle filter leaves to the likelihood; 0: none).
        process_contact_deg: the same for each pad contact angle [deg].
    """

    alpha: float = 0.5
    beta: float = 2.0
    kappa: float = 0.0
    process_theta_deg: float = 0.0
    process_contact_deg: float = 0.0

    def __post_init__(self) -> None:
        if not 0 < self.alpha <= 1:
            raise ValueError(f"alpha {self.alpha} must be in (0, 1]")
        if not (math.isfinite(self.beta) and self.beta >= 0):
            raise ValueError(f"beta {self.beta} must be >= 0")
        if not math.isfinite(self.kappa):
            raise ValueError(f"kappa {self.kappa} must be finite")
        for name in ("process_theta_deg", "process_contact_deg"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise ValueError(f"{name} {v} must be >= 0 (0: none)")


@dataclass(frozen=True)
class FilterConfig:
    """Filter settings (units in the names or in brackets).

    Attributes:
        estimator: "pf", the particle filter (Algorithm 1, the paper's); "ukf", the unscented
            Kalman filter over the same dimensions, motion and observation models (`vlr.ukf`),
            which ignores `particles`, `ess_fraction` and `jitter_h`.
        ukf: the unscented Kalman filter's settings (`UnscentedConfig`).
        particles: P (the paper: 60,000).
        unknowns: unknown-parameter specs (`vlr.unknowns`).
        priors: {spec: (low, high)} the uniform prior of an unknown in its SI unit; an
            unknown not named keeps its default (`vlr.unknowns.parse_unknown`).
        guess_theta_deg: the user's guess of the grasp's joint angles (what one sees looking
            at the hand): K angles for every finger alike, or N x K finger by finger in the
            hand's order; None: the generic guess (`vlr.synthetic.SyntheticConfig`). The
            prior is the nominal hand's equilibrium from there (`vlr.world.grasp_guess`).
        theta_spread_deg: prior std of the joint angles about the guess.
        contact_prior: what the contact angles are drawn about: "pad", the guess's contacts
            (the pad's inner face); "surface", where each particle's own pads would touch an
            object of the local surface's shape (`vlr.surface.surface_contact_normals`: a
            sphere's or a cylinder's radius, a box's faces, oriented by the observed POM),
            for three fingers; else "pad".
        contact_spread_deg: prior std of each pad contact's two angles (alpha in the
            finger's plane, beta out of it).
        ess_fraction: tempering keeps ESS >= this fraction of P after weighting; 0: none.
        jitter_h: the Liu-West bandwidth h in [0, 1) (docs/DECISIONS.md).
        ci_threshold_deg: convergence when the mean 95% interval width of the joint angles
            falls below this (docs/METHOD.md 3).
        init_jump_theta: the jump limit of the prior's settle at u_0 [rad] (the prior is
            wider than one action).
        object: the object the filter believes (`ObjectBelief`).
        motion: the motion model (`vlr.motion.MotionConfig`).
        observation: the likelihood (`vlr.observation.ObservationConfig`).
        model_check: whether the model explains the observations
            (`vlr.model_check.ModelCheckConfig`).
    """

    estimator: Literal["pf", "ukf"] = "pf"
    ukf: UnscentedConfig = field(default_factory=UnscentedConfig)
    particles: int = 60_000
    unknowns: tuple[str, ...] = ()
    priors: dict[str, tuple[float, float]] = field(default_factory=dict)
    guess_theta_deg: tuple[float, ...] | None = None
    theta_spread_deg: float = 3.0
    contact_prior: Literal["pad", "surface"] = "surface"
    contact_spread_deg: float = math.degrees(0.15)
    ess_fraction: float = 0.1
    jitter_h: float = 0.4
    ci_threshold_deg: float = 2.0
    init_jump_theta: float = 1.0
    object: ObjectBelief = field(default_factory=ObjectBelief)
    motion: MotionConfig = field(default_factory=MotionConfig)
    observation: ObservationConfig = field(default_factory=ObservationConfig)
    model_check: ModelCheckConfig = field(default_factory=ModelCheckConfig)

    def __post_init__(self) -> None:
        if self.estimator not in ("pf", "ukf"):
            raise ValueError(f"estimator {self.estimator!r}: use pf or ukf")
        if self.particles < 10:
            raise ValueError(f"particles {self.particles} must be >= 10")
        if not (math.isfinite(self.theta_spread_deg) and self.theta_spread_deg > 0):
            raise ValueError(f"theta_spread_deg {self.theta_spread_deg} must be > 0")
        if not 0 < self.contact_spread_deg <= 90:
            raise ValueError(f"contact_spread_deg {self.contact_spread_deg} must be in (0, 90]")
        if not 0 <= self.ess_fraction < 1:
            raise ValueError(f"ess_fraction {self.ess_fraction} must be in [0, 1) (0: no "
                             "tempering)")
        if not 0 <= self.jitter_h < 1:
            raise ValueError(f"jitter_h {self.jitter_h} must be in [0, 1)")
        if not self.ci_threshold_deg > 0:
            raise ValueError(f"ci_threshold_deg {self.ci_threshold_deg} must be > 0")
        if self.guess_theta_deg is not None and not all(
                math.isfinite(v) for v in self.guess_theta_deg):
            raise ValueError(f"guess_theta_deg {list(self.guess_theta_deg)} must be finite")
        if self.contact_prior not in ("pad", "surface"):
            raise ValueError(f"contact_prior {self.contact_prior!r}: use pad or surface")
        object.__setattr__(self, "unknowns", tuple(self.unknowns))
        check_unknown_set(self.unknowns)
        for spec, (lo, hi) in self.priors.items():
            if not (math.isfinite(lo) and math.isfinite(hi) and lo <= hi):
                raise ValueError(f"priors {spec!r} ({lo}, {hi}) must be [low, high] with low "
                                 "<= high, both finite")

    @property
    def theta_spread(self) -> float:
        """[rad]"""
        return math.radians(self.theta_spread_deg)

    @property
    def contact_spread(self) -> float:
        """[rad]"""
        return math.radians(self.contact_spread_deg)


@dataclass(frozen=True)
class Summary:
    """Per-dimension mean, median and 95% interval of a particle set.

    The mean minimizes the expected squared error, the median the expected absolute error
    (the paper's measure, docs/METHOD.md 6). They part where the posterior is skewed, as for a
    joint resting on its stop, whose particles can only lie on one side of it.
    """

    mean: np.ndarray
    low: np.ndarray
    high: np.ndarray
    median: np.ndarray

    @classmethod
    def of(cls, x: np.ndarray, weights: np.ndarray | None = None) -> Summary:
        if weights is None:
            q = np.quantile(x, [0.025, 0.5, 0.975], axis=0)
            return cls(mean=x.mean(axis=0), low=q[0], high=q[2], median=q[1])
        w = weights / weights.sum()
        mean = w @ x
        order = np.argsort(x, axis=0)
        cw = np.cumsum(w[order], axis=0)
        cols = np.arange(x.shape[1])
        lo, med, hi = (x[order[np.argmax(cw >= p, axis=0), cols], cols]
                       for p in (0.025, 0.5, 0.975))
        return cls(mean=mean, low=lo, high=hi, median=med)


@dataclass(frozen=True)
class IterationRecord:
    """What one filter iteration did, for history and plots.

    prior: summary after the motion step (before weighting); posterior: after resampling,
    before jitter (None for a prediction-only step). ci_deg: the convergence measure. The
    unscented Kalman filter (`vlr.ukf`) gives its Gaussian's summaries, ess NaN, beta 1 and
    its sigma points that failed to solve as n_invalid. surprise: the observation's
    standard score under the estimator's predictive (`vlr.model_check`), NaN without one.
    """

    iteration: int
    command: np.ndarray
    prior: Summary
    posterior: Summary | None
    ess: float
    beta: float
    n_invalid: int
    ci_deg: float
    surprise: float = float("nan")
    parts: tuple = (float("nan"), float("nan"))


def _liu_west(x: np.ndarray, a: float, h: float, rng: np.random.Generator) -> np.ndarray:
    """x' = a x + (1 - a) mean + h L eps, L L^T the covariance of `x` (P, D) (docs/METHOD.md
    8.2)."""
    mean = x.mean(axis=0)
    cov = np.cov(x, rowvar=False)
    d = cov.shape[0]
    scale = np.sqrt(np.maximum(np.diag(cov), 0.0)) + 1e-12
    corr = cov / np.outer(scale, scale) + 1e-9 * np.eye(d)
    chol = np.linalg.cholesky(corr) * scale[:, None]
    eps = rng.standard_normal(x.shape)
    return a * x + (1.0 - a) * mean + h * eps @ chol.T


# --------------------------------------------------------------------------- the filter

class GraspFilter:
    """What the two estimators share: hypotheses of the grasp as `ParticleState`s over the
    sampled dimensions (module docstring), moved by the motion model Gamma (Eq. 4, 9) and
    weighed by the observation model Lambda (Eq. 5), and the settle that brings a new
    hypothesis to equilibrium at the current command (`_project`). `ParticleFilter` and
    `vlr.ukf.UnscentedFilter` derive from it: `initialize`, `step` and `summarize` are
    theirs.

    Args:
        model: the hand the user believes in.
        obj: the object believed (`vlr.motion.ObjectParams`).
        config: the filter's settings.
        seed: seeds the filter's np.random.Generator (all its randomness).
    """

    def __init__(self, model: HandModel, obj: ObjectParams,
                 config: FilterConfig | None = None, seed: int = 0) -> None:
        self.model = model
        self.config = config or FilterConfig()
        self.motion = MotionModel(model, obj, self.config.motion)
        self.obs_model = ObservationModel(self.config.observation, model)
        check_unknown_set(self.config.unknowns)
        self.unknowns = tuple(parse_unknown(s, model, self.config.priors.get(s), obj)
                              for s in self.config.unknowns)
        self.rng = np.random.default_rng(seed)
        # The model check's draws: a generator of its own, so that the check never moves
        # the estimate (`vlr.model_check`).
        self.check_rng = np.random.default_rng([seed, 0x6D63])
        self.state: ParticleState | None = None
        self.history: list[IterationRecord] = []
        self.iteration = 0
        self.command: np.ndarray | None = None
        # A settle has no history: the pads' spin and sliding, an action's, do not hold it;
        # its contacts are glued (with the pads sliding, from no stretch: `_jitter`).
        self._project_cfg = replace(self.config.motion, jump_theta=self.config.init_jump_theta,
                                    jump_pos=0.05, spin_friction=0.0, friction=None)
        self.project_status = np.zeros(5, dtype=np.int64)
        self.newton_iterations: dict[str, float] = {}
        self.recoveries = 0  # times every hypothesis failed and the prior was drawn again
        self.prior_redraws = 0  # prior draws of which no particle settled (`initialize`)
        self._init_cfg = replace(self.config.motion, jump_theta=self.config.init_jump_theta,
                                 jump_pos=0.05, max_iter=max(self.config.motion.max_iter, 100),
                                 spin_friction=0.0, friction=None)
        # Seconds per phase of the last iteration (motion, observation, weights, resampling,
        # jitter, summary) and what its solves took, for `vlr bench`.
        self.timings: dict[str, float] = {}
        self.profile: dict[str, float] = {}

    # ---- packing of the sampled dimensions

    @property
    def dim_names(self) -> list[str]:
        names = [f"theta:{f}.{k}" for f in self.model.names for k in range(self.model.n_joints)]
        names += [f"contact:{f}.{a}" for f in self.model.names for a in ("alpha", "beta")]
        return names + [u.spec for u in self.unknowns]

    def pack(self, state: ParticleState) -> np.ndarray:
        """(P, D) sampled dimensions of the particles (module docstring)."""
        alpha, beta = angles_from_normals(state.normals)
        cols = [state.theta.reshape(state.n, -1), np.stack([alpha, beta], -1).reshape(
            state.n, -1)]
        cols += [unknown_values(state, u)[:, None] for u in self.unknowns]
        return np.concatenate(cols, axis=1)

    def unpack(self, x: np.ndarray, state: ParticleState) -> None:
        """Write sampled dimensions back into `state` (in place)."""
        nf, nk = self.model.n_fingers, self.model.n_joints
        n_th = nf * nk
        state.theta[...] = x[:, :n_th].reshape(-1, nf, nk)
        ab = x[:, n_th:n_th + 2 * nf].reshape(-1, nf, 2)
        state.normals[...] = normals_from_angles(ab[..., 0], ab[..., 1])
        self._hold_object(state)
        for j, u in enumerate(self.unknowns):
            set_unknown(state, u, x[:, n_th + 2 * nf + j])

    def _hold_object(self, state: ParticleState) -> None:
        hold_unknowns(state, self.unknowns, self.motion.obj)

    def _contact_centre(self, state: ParticleState, nominal_contact: np.ndarray) -> np.ndarray:
        """The pad contact angles (alpha, beta) the prior is drawn about, (P, N, 2) [rad]:
        `config.contact_prior`'s "surface" contacts of each hypothesis's own fingers where the
        local surface fixes them (`vlr.surface.surface_contact_normals`), else the nominal
        contact (N, 2) for all. After the unknowns: a link's length moves its pad, a
        curvature its surface."""
        centre = np.broadcast_to(np.asarray(nominal_contact, dtype=float)[None],
                                 (state.n,) + np.shape(nominal_contact))
        if self.config.contact_prior == "surface":
            normals = surface_contact_normals(self.model, self.motion.obj.surface, state.theta,
                                              state.segments, state.rot,
                                              self.motion.contact_rho(state))
            if normals is not None:
                centre = np.stack(angles_from_normals(normals), axis=-1)
        return centre

    def _spring_columns(self, n_columns: int) -> np.ndarray:
        """The springs' columns among `n_columns` sampled dimensions (the unknowns last)."""
        mask = np.zeros(n_columns, dtype=bool)
        base = n_columns - len(self.unknowns)
        for j, u in enumerate(self.unknowns):
            mask[base + j] = u.kind in SPRING_KINDS
        return mask

    def _project(self, state: ParticleState, moved: np.ndarray | None = None) -> None:
        """Settle new hypotheses (jittered particles, the UKF's sigma points) to equilibrium
        at the current command, then re-anchor.

        A jittered configuration is off its equilibrium (Eq. 9): left as is, the next motion
        solve first travels back to it, several degrees and millimetres (measured: 10-25
        Newton iterations at 0.2-0.4 mm actions), and its predicted POM motion mixes that
        trek with the action's effect, so most jittered particles lose their weight. Settling
        at u_t and re-deriving the anchors against the pre-jitter POM pose (docs/METHOD.md
        8.2) keeps each particle's POM where it was observed, so the next update weighs only
        the action's effect, and the next solve is short.

        `moved` (P,) bool: only these particles were jittered; the others are still at their
        equilibrium and are left alone (with the measured ESS, about half the particles)."""
        if moved is None:
            moved = np.ones(state.n, dtype=bool)
        idx = np.flatnonzero(moved)
        # In place: the rows left alone are held out of the solve as invalid ones are
        # (status "inactive", no evaluation), then given their validity back.
        valid = state.valid.copy()
        state.valid &= moved
        pos, rot = state.pos[idx], state.rot[idx]
        status, iters = self.motion.solve(state, self.command, self._project_cfg)
        state.valid[~moved] = valid[~moved]
        status, iters = status[idx], iters[idx]
        self.project_status = np.bincount(status, minlength=5)
        self.project_status[0] += state.n - len(idx)
        self.newton_iterations["settle"] = float(np.median(iters)) if len(idx) else 0.0
        self.profile.update(settle_mean=float(iters.mean()) if len(idx) else 0.0,
                            settled_share=len(idx) / state.n)
        # The settled particle's contacts, each with its stretch, are where its anchors
        # are now, p + R a (`ParticleState.contact_residuals`); the anchors follow them to
        # the pose before the settle (`anchor_to_pose`).
        held = palm_points(state.anchors[idx], state.pos[idx], state.rot[idx])
        state.pos[idx] = pos
        state.rot[idx] = rot
        state.anchors[idx] = object_points(held, pos, rot)

    def summarize(self, values: np.ndarray) -> Summary:
        """Mean, median and 95% interval of a quantity of the current hypotheses, (H, ...)
        values per hypothesis (`self.state`)."""
        raise NotImplementedError

    def initialize(self, observation: PoseObservation, command: np.ndarray,
                   nominal_theta: np.ndarray, nominal_contact: np.ndarray) -> IterationRecord:
        """The prior about the nominal grasp, settled at u_0 and weighed by the first
        observation."""
        raise NotImplementedError

    def step(self, command: np.ndarray, observation: PoseObservation | None) -> IterationRecord:
        """One iteration for the new absolute command u_t (N,) [m]; `observation` None makes
        it a prediction-only step."""
        raise NotImplementedError

    @property
    def converged(self) -> bool:
        return bool(self.history) and self.history[-1].ci_deg < self.config.ci_threshold_deg


class ParticleFilter(GraspFilter):
    """Algorithm 1 over `ParticleState`s, with the motion model of `vlr.motion`.

    Args:
        model: the hand the user believes in.
        obj: the object believed (`vlr.motion.ObjectParams`).
        config: the filter's settings.
        seed: seeds the filter's np.random.Generator (all its randomness).
    """

    # ---- Algorithm 1

    def initialize(self, observation: PoseObservation, command: np.ndarray,
                   nominal_theta: np.ndarray, nominal_contact: np.ndarray) -> IterationRecord:
        """Sample the prior about the nominal grasp and weight it by the first observation.

        Joint angles ~ N(nominal_theta, theta_spread); pad contact angles ~ N(the nominal
        contact or the surface's, contact_spread); unknowns ~ uniform priors. Each particle
        takes the observed POM pose and derives its anchors from its own contacts, then
        settles to equilibrium at the known command u_0 (docs/METHOD.md 3: a focused prior
        that still covers the truth).

        Args:
            observation: first POM pose (palm frame).
            command: u_0 (N,) [m].
            nominal_theta: (N, K) [rad]; nominal_contact: (N, 2) (alpha, beta) [rad].
        """
        for _ in range(PRIOR_DRAWS):
            self._sample_prior(observation, command, nominal_theta, nominal_contact)
            if self.state.valid.any():
                break
            self.prior_redraws += 1
        else:
            raise FloatingPointError(
                f"none of the {self.config.particles} prior particles settled at the grasp "
                f"command in {PRIOR_DRAWS} draws (solve status counts "
                f"{self.init_status.tolist()}): the nominal guess or its spread misses this "
                "grasp, or the filter is too small")
        return self._update(observation)

    def _sample_prior(self, observation: PoseObservation, command: np.ndarray,
                      nominal_theta: np.ndarray, nominal_contact: np.ndarray) -> None:
        """The prior of `initialize`, settled at `command` (module docstring)."""
        cfg, m, rng = self.config, self.model, self.rng
        p = cfg.particles
        nf = m.n_fingers
        state = ParticleState.nominal(m, p, nominal_theta, np.zeros((nf, 3)) + [0, 1, 0],
                                      np.asarray(observation.position, dtype=float),
                                      np.asarray(observation.rotation, dtype=float))
        state.theta += rng.normal(0.0, cfg.theta_spread, state.theta.shape)
        spread = rng.normal(0.0, cfg.contact_spread, (p, nf, 2))
        self._hold_object(state)
        for u in self.unknowns:
            set_unknown(state, u, draw_prior(rng, u, p))
        ab = self._contact_centre(state, nominal_contact) + spread
        state.normals[...] = normals_from_angles(ab[..., 0], ab[..., 1])
        state.anchor_to_pose(m)
        self.state = state
        self.command = np.asarray(command, dtype=float).copy()
        t0 = time.perf_counter()
        status, _ = self.motion.solve(state, self.command, self._init_cfg)
        self.timings = {"motion": time.perf_counter() - t0}
        self.init_status = np.bincount(status, minlength=5)

    def step(self, command: np.ndarray, observation: PoseObservation | None) -> IterationRecord:
        """One iteration of Algorithm 1 for the new absolute command u_t (N,) [m].

        `observation` None (camera dropped the frame) makes it a prediction-only step."""
        if self.state is None:
            raise RuntimeError("initialize() first")
        previous = self.command
        self.command = np.asarray(command, dtype=float).copy()
        self.iteration += 1
        t0 = time.perf_counter()
        status, iters = self.motion.solve(self.state, self.command, u_from=previous)
        # Newton iterations of the action solve and of the post-jitter settle, failures and
        # follow-ups (`vlr bench`: they are what a filter iteration costs).
        self.newton_iterations = {"action": float(np.median(iters))}
        tried = status != 4   # INACTIVE: invalid before the action
        self.profile = {"action_mean": float(iters[tried].mean()) if tried.any() else 0.0,
                        "action_p99": float(np.quantile(iters, 0.99)),
                        "failed_share": float(np.mean(tried & (status != 0))),
                        "followed_share": float(np.mean(self.motion.followed))
                        if len(self.motion.followed) == len(iters) else 0.0}
        if observation is not None and not self.state.valid.any():
            self._recover(observation)
        self.timings = {"motion": time.perf_counter() - t0}
        return self._update(observation)

    def _recover(self, observation: PoseObservation) -> None:
        """Every particle's solve failed (all hypotheses left the model's reach, e.g. an
        unknown stiffness far from the nominal): resample the prior about the last estimate,
        at the current command and observation, rather than stop with no particle left."""
        last = self.history[-1]
        est = (last.posterior or last.prior).mean
        nf, nk = self.model.n_fingers, self.model.n_joints
        theta = est[:nf * nk].reshape(nf, nk)
        contact = est[nf * nk:nf * nk + 2 * nf].reshape(nf, 2)
        self._sample_prior(observation, self.command, theta, contact)
        self.recoveries += 1

    def _update(self, observation: PoseObservation | None) -> IterationRecord:
        cfg, state, tm = self.config, self.state, self.timings
        t = time.perf_counter()
        x = self.pack(state)
        prior = Summary.of(x[state.valid]) if state.valid.any() else Summary.of(x)
        n_invalid = int((~state.valid).sum())
        tm["summary"] = time.perf_counter() - t
        if observation is None:
            rec = IterationRecord(self.iteration, self.command, prior, None, float("nan"),
                                  float("nan"), n_invalid, self.ci_deg(x[state.valid]))
            self.history.append(rec)
            return rec
        # Eq. 5 likelihood, tempered (docs/METHOD.md 8.2).
        t = time.perf_counter()
        # Each particle's predicted tendon tensions, when the likelihood weighs them: the
        # likelihood's and the model check's.
        tensions = (self.motion.tensions(state, self.command)
                    if self.obs_model.sigma_tension > 0 else None)
        log_lik = self.obs_model.log_likelihood(state, observation, tensions)
        tm["observation"] = time.perf_counter() - t
        t = time.perf_counter()
        surprise = self._surprise(state, observation, tensions)
        import vlr.model_check as _mc
        parts = _mc.LAST_PARTS
        tm["check"] = time.perf_counter() - t
        t = time.perf_counter()
        w, beta = temper(log_lik, cfg.ess_fraction)
        tm["weights"] = time.perf_counter() - t
        ess = effective_sample_size(w)
        # Resample (systematic), then jitter.
        t = time.perf_counter()
        idx = systematic_resample(w, self.rng)
        state.resample(idx)
        x = x[idx]
        tm["resampling"] = time.perf_counter() - t
        t = time.perf_counter()
        posterior = Summary.of(x)
        ci = self.ci_deg(x)
        tm["summary"] += time.perf_counter() - t
        t = time.perf_counter()
        self._jitter(x, idx)
        tm["jitter"] = time.perf_counter() - t
        rec = IterationRecord(self.iteration, self.command, prior, posterior, ess, beta,
                              n_invalid, ci, surprise, parts)
        self.history.append(rec)
        return rec

    def _surprise(self, state: ParticleState, observation: PoseObservation,
                  tensions: np.ndarray | None) -> float:
        """The observation's surprise under the particles' predictive (`vlr.model_check`),
        over a uniform draw of `model_check.particles` of the valid particles; `tensions`
        (P, N) their predicted tendon tensions, or None."""
        cfg = self.config.model_check
        valid = np.flatnonzero(state.valid)
        if len(valid) > cfg.particles:
            valid = np.sort(self.check_rng.choice(valid, size=cfg.particles, replace=False))
        return predictive_surprise(state.pos[valid], state.rot[valid], state.anchors[valid],
                                   self.obs_model, observation,
                                   None if tensions is None else tensions[valid],
                                   self.check_rng, cfg.replicates)

    def _kernel(self, x: np.ndarray,
                parents: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray | None]:
        """Liu-West draw over the sampled dimensions (docs/METHOD.md 8.2).

        x' = a x + (1 - a) mean + h L eps, with L L^T the particle covariance and
        a = sqrt(1 - h^2): the kernel adds h^2 of the variance and the shrink removes it.
        The springs (`vlr.unknowns.SPRING_KINDS`: a joint's, the tendon's) are drawn on
        their logarithms (x -> log x, the draw, exp): positive, their evidence a deflection
        that goes as 1/k, so their likelihood is skewed on k and close to symmetric on log k
        (docs/DECISIONS.md). The first copy of each resampled parent is not jittered.
        Returns x' and the rows that moved (None: all)."""
        h = self.config.jitter_h
        a = np.sqrt(1.0 - h * h)
        on_log = self._spring_columns(x.shape[1])
        y = x.copy()
        y[:, on_log] = np.log(x[:, on_log])
        x_new = _liu_west(y, a, h, self.rng)
        x_new[:, on_log] = np.exp(x_new[:, on_log])
        moved = None
        if parents is not None:
            # Systematic resampling returns sorted indexes, so copies are contiguous.
            first = np.ones(len(parents), dtype=bool)
            first[1:] = parents[1:] != parents[:-1]
            x_new[first] = x[first]
            moved = ~first
        base = x.shape[1] - len(self.unknowns)
        # Keep unknowns inside their priors (reflect at the bounds).
        for j, u in enumerate(self.unknowns):
            lo, hi = u.prior
            col = x_new[:, base + j]
            col = np.where(col < lo, 2 * lo - col, col)
            x_new[:, base + j] = np.clip(np.where(col > hi, 2 * hi - col, col), lo, hi)
        return x_new, moved

    def _jitter(self, x: np.ndarray, parents: np.ndarray | None = None) -> np.ndarray | None:
        """Liu-West kernel (`_kernel`) on `self.state` at `self.command`, then re-anchor and
        settle (`_project`). Returns the rows that moved (None: all)."""
        state = self.state
        # The POM keeps its pose; the anchors follow the jittered contacts, each contact
        # keeping its stretch (the grasp force). With the pads sliding, every particle's
        # anchors are re-derived from no stretch instead: the grasp's internal forces are let
        # go at each update (the stretch a slide leaves sits on the cone's edge, and the next
        # action's slide runs away: docs/DECISIONS.md, the internal forces). The jittered
        # particles' glued settles find them again, as the prior's does; the others, in
        # their next action's solve, or they slide away there (docs/DECISIONS.md, the
        # internal forces let go whole: keeping their squeeze lost on the joints).
        residuals = (state.contact_residuals(self.model)
                     if self.config.motion.friction is None else None)
        x_new, moved = self._kernel(x, parents)
        self.unpack(x_new, state)
        state.anchor_to_pose(self.model, residuals)
        self._project(state, moved)
        return moved

    # ---- summaries

    def summarize(self, values: np.ndarray) -> Summary:
        """Mean, median and 95% interval over the particles (equally weighted)."""
        return Summary.of(np.asarray(values).reshape(len(values), -1))

    def ci_deg(self, x: np.ndarray) -> float:
        """Mean 95% interval width over joint angles [deg] (docs/METHOD.md 3)."""
        n_th = self.model.n_fingers * self.model.n_joints
        return interval_width_deg(x[:, :n_th]) if len(x) else float("inf")
