"""The particle filter of the self-identification (Algorithm 1; METHOD.md 3, 8.2).

One iteration: move every particle by the motion model with the common command u_t
(Eq. 4, 9); predict its POM pose (Eq. 5); weight by the likelihood of the observed pose,
tempered so that the effective sample size stays above a fraction of P; resample
(systematic); jitter (Liu-West, scaled to the particle covariance) and re-derive each
particle's POM anchor in its new contact frame.

Sampled dimensions ("dims"), in this order: joint angles theta (N*K) [rad]; the contact on
each pad as two angles (alpha, beta) per finger [rad] (`vlr.kinematics.normals_from_angles`);
then the unknown parameters asked for, e.g. "stiffness:thumb.distal" [N m/rad],
"length:left.proximal" [m], "tendon" or "tendon:thumb" [N/m], the object's "mass" [kg] or
a coordinate of its centre of mass in O, "com:z" [m], and the local curvature of its surface
at the contacts, "curvature" or at one finger's, "curvature:thumb" [1/m] (issue #5, term
(b)). Known parameters are not sampled (METHOD.md 3).
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from vlr.copula import NormalScores
from vlr.kinematics import HandModel, angles_from_normals, normals_from_angles
from vlr.motion import MotionConfig, MotionModel, ObjectParams, ParticleState
from vlr.observation import ObservationModel, PoseObservation, rotation_angle
from vlr.surface import surface_contact_normals

__all__ = [
    "Unknown",
    "parse_unknown",
    "unknown_values",
    "set_unknown",
    "hold_unknowns",
    "draw_prior",
    "FilterConfig",
    "Summary",
    "IterationRecord",
    "ParticleFilter",
    "systematic_resample",
    "effective_sample_size",
    "temper",
    "interval_width_deg",
]


# --------------------------------------------------------------------------- unknowns

# The "noise" unknown's default prior: uniform factors on the configured pose scales. The
# top is the configured scale (set for the objects the model gets worst); the bottom a
# quarter of it, about the camera's own error at the sim's default scales (0.05 mm of 0.2).
NOISE_PRIOR = (0.25, 1.0)

# The object's unknowns' default priors (ours): its mass 0.25-4x the spec's, as a spring's;
# a coordinate of its centre of mass within 15 mm of the spec's, a third of the apple's
# radius: a user's guess of where an object's weight sits, not a measurement.
MASS_PRIOR_FACTORS = (0.25, 4.0)
COM_PRIOR_HALF_WIDTH = 0.015
COM_AXES = ("x", "y", "z")
# The curvature's (ours): uniform on [0, 2 kappa] about the believed surface's kappa = 1/rho,
# and up to at least 50 /m (a 20 mm radius, the tightest of the test objects' bar the
# screwdriver's handle): a believed plane may be a ball, a believed ball may be flat.
CURVATURE_PRIOR_TOP = 50.0


@dataclass(frozen=True)
class Unknown:
    """One unknown physical parameter sampled as a particle dimension (METHOD.md 3).

    Attributes:
        spec: the spec string, e.g. "stiffness:thumb.distal".
        kind: "stiffness" | "length" | "tendon" | "noise" | "mass" | "com" | "curvature".
        finger: finger index, or -1 for all fingers ("tendon", "noise", "curvature": one
            curvature at every contact) and the object's "mass" and "com".
        joint: joint index (stiffness, length), the axis of O ("com": 0, 1, 2), else -1.
        prior: (low, high) of the uniform prior [SI units].
    """

    spec: str
    kind: str
    finger: int
    joint: int
    prior: tuple[float, float]


def parse_unknown(spec: str, model: HandModel,
                  prior: tuple[float, float] | None = None,
                  obj: ObjectParams | None = None) -> Unknown:
    """Parse "stiffness:FINGER.JOINT", "length:FINGER.JOINT", "tendon", "tendon:FINGER",
    "noise", or the object's "mass", "com:x|y|z", "curvature" and "curvature:FINGER" (which
    need `obj`, the object believed).

    Default priors (ours): stiffness 0.25-4x nominal; length 0.5-1.3x nominal (a replaced
    finger may be much shorter: NF1 is 40 mm against 62 mm); tendon stiffness 0.5-2x nominal;
    noise, the factor on the likelihood's pose scales (`vlr.observation`, "The model error's
    size"), `NOISE_PRIOR`: the configured scales are its top, set for the worst object;
    the object's mass `MASS_PRIOR_FACTORS` times the believed, a coordinate of its centre of
    mass the believed +- `COM_PRIOR_HALF_WIDTH` (the weight's potential, Eq. 9); the local
    curvature at the contacts (the rolling term's rho, METHOD.md 8.2) 0 to the larger of
    twice the believed and `CURVATURE_PRIOR_TOP`. A curvature keeps the believed surface's
    kind: a cylinder's is across its axis, and a believed plane with a curvature is a sphere.
    A "distal" length is the pad centre's offset along the distal link (kinematics.py).
    """
    kind, _, rest = spec.partition(":")
    if kind in ("mass", "com"):
        return _parse_object_unknown(spec, kind, rest, prior, obj)
    if kind == "curvature":
        return _parse_curvature(spec, rest, model, prior, obj)
    if kind == "noise":
        if rest:
            raise ValueError(f"unknown parameter spec {spec!r}: 'noise' takes no finger")
        lo, hi = prior or NOISE_PRIOR
        if not 0 < lo <= hi < math.inf:
            raise ValueError(f"noise prior ({lo}, {hi}) must satisfy 0 < low <= high, "
                             "both finite")
        return Unknown(spec, kind, -1, -1, (float(lo), float(hi)))
    if kind == "tendon":
        finger = model.finger_index(rest) if rest else -1
        nominal = model.tendon_stiffness
        lo, hi = prior or (0.5 * nominal, 2.0 * nominal)
        return Unknown(spec, kind, finger, -1, _positive_prior(spec, lo, hi))
    if kind not in ("stiffness", "length") or "." not in rest:
        raise ValueError(f"unknown parameter spec {spec!r}; use stiffness:FINGER.JOINT, "
                         "length:FINGER.JOINT, tendon, tendon:FINGER, noise, mass, com:x|y|z, "
                         "curvature or curvature:FINGER")
    fname, jname = rest.split(".", 1)
    i, k = model.finger_index(fname), model.joint_index(jname)
    if kind == "stiffness":
        nominal = model.stiffness[i, k]
        lo, hi = prior or (0.25 * nominal, 4.0 * nominal)
    else:
        nominal = model.segments[i, k]
        lo, hi = prior or (0.5 * nominal, 1.3 * nominal)
    return Unknown(spec, kind, i, k, _positive_prior(spec, lo, hi))


def _positive_prior(spec: str, lo: float, hi: float) -> tuple[float, float]:
    """A spring rate's or a length's prior: 0 < low <= high, both finite."""
    if not 0 < lo <= hi < math.inf:
        raise ValueError(f"{spec} prior ({lo}, {hi}) must satisfy 0 < low <= high, both "
                         "finite")
    return float(lo), float(hi)


def _parse_object_unknown(spec: str, kind: str, rest: str, prior: tuple[float, float] | None,
                          obj: ObjectParams | None) -> Unknown:
    """The object's "mass" or "com:AXIS" (`parse_unknown`)."""
    if obj is None:
        raise ValueError(f"unknown parameter spec {spec!r}: the object's unknowns need the "
                         "object believed (its spec's mass and centre of mass)")
    if kind == "mass":
        if rest:
            raise ValueError(f"unknown parameter spec {spec!r}: 'mass' is the object's, "
                             "it takes no finger")
        lo, hi = prior or tuple(f * float(obj.mass) for f in MASS_PRIOR_FACTORS)
        if not 0 < lo <= hi < math.inf:
            raise ValueError(f"mass prior ({lo}, {hi}) [kg] must satisfy 0 < low <= high, "
                             "both finite")
        return Unknown(spec, kind, -1, -1, (float(lo), float(hi)))
    if rest not in COM_AXES:
        raise ValueError(f"unknown parameter spec {spec!r}: use com:x, com:y or com:z "
                         "(an axis of the object frame O)")
    axis = COM_AXES.index(rest)
    c = float(obj.com[axis])
    lo, hi = prior or (c - COM_PRIOR_HALF_WIDTH, c + COM_PRIOR_HALF_WIDTH)
    if not -math.inf < lo <= hi < math.inf:
        raise ValueError(f"{spec} prior ({lo}, {hi}) [m] must satisfy low <= high, both finite")
    return Unknown(spec, kind, -1, axis, (float(lo), float(hi)))


def check_unknown_set(specs: tuple[str, ...] | list[str]) -> None:
    """Refuse a set of unknowns that samples one parameter twice: a spec given twice, or one
    for every finger ("tendon", "curvature") beside one finger's ("tendon:thumb")."""
    seen = set()
    for spec in specs:
        if spec in seen:
            raise ValueError(f"unknown {spec!r} is given twice")
        seen.add(spec)
    for spec in specs:
        kind, _, rest = spec.partition(":")
        if kind in ("tendon", "curvature") and not rest:
            mine = [s for s in specs if s.startswith(kind + ":")]
            if mine:
                raise ValueError(f"unknown {spec!r} (every finger's) and {mine[0]!r} sample "
                                 "the same parameter: give one or the other")


def _parse_curvature(spec: str, rest: str, model: HandModel,
                     prior: tuple[float, float] | None, obj: ObjectParams | None) -> Unknown:
    """The object's local "curvature" at every contact or at one finger's (`parse_unknown`)."""
    if obj is None:
        raise ValueError(f"unknown parameter spec {spec!r}: the curvature needs the object "
                         "believed (its surface)")
    finger = model.finger_index(rest) if rest else -1
    lo, hi = prior or (0.0, max(2.0 * obj.surface.curvature, CURVATURE_PRIOR_TOP))
    if not 0 <= lo <= hi < math.inf:
        raise ValueError(f"{spec} prior ({lo}, {hi}) [1/m] must satisfy 0 <= low <= high, "
                         "both finite")
    return Unknown(spec, "curvature", finger, -1, (float(lo), float(hi)))


def unknown_values(state: ParticleState, u: Unknown) -> np.ndarray:
    """(P,) the particles' values of unknown `u` [SI units]."""
    if u.kind == "noise":
        return state.noise
    if u.kind == "mass":
        return state.object_mass
    if u.kind == "com":
        return state.object_com[:, u.joint]
    if u.kind == "curvature":
        return state.surface_curvature[:, max(u.finger, 0)]
    if u.kind == "stiffness":
        return state.stiffness[:, u.finger, u.joint]
    if u.kind == "length":
        return state.segments[:, u.finger, u.joint]
    return state.tendon[:, max(u.finger, 0)]


def set_unknown(state: ParticleState, u: Unknown, values: np.ndarray) -> None:
    """Write (P,) values of unknown `u` into `state` (in place; the object's unknowns need
    the particles to hold their own object, `hold_unknowns`)."""
    if u.kind == "noise":
        state.noise[:] = values
    elif u.kind == "mass":
        state.object_mass[:] = values
    elif u.kind == "com":
        state.object_com[:, u.joint] = values
    elif u.kind == "curvature":
        if u.finger < 0:
            state.surface_curvature[:, :] = values[:, None]
        else:
            state.surface_curvature[:, u.finger] = values
    elif u.kind == "stiffness":
        state.stiffness[:, u.finger, u.joint] = values
    elif u.kind == "length":
        state.segments[:, u.finger, u.joint] = values
    elif u.finger < 0:
        state.tendon[:, :] = values[:, None]
    else:
        state.tendon[:, u.finger] = values


def draw_prior(rng: np.random.Generator, u: Unknown, n: int,
               shape: str = "uniform") -> np.ndarray:
    """(n,) draws of unknown `u` over its prior (low, high): uniform, or for a scale unknown
    (`LOG_PRIOR_KINDS`) with `shape` "log-uniform", uniform in its logarithm
    (`FilterConfig.prior_shape`)."""
    lo, hi = u.prior
    if shape == "log-uniform" and u.kind in LOG_PRIOR_KINDS:
        return np.exp(rng.uniform(math.log(lo), math.log(hi), n))
    return rng.uniform(lo, hi, n)


def hold_unknowns(state: ParticleState, unknowns: Sequence[Unknown],
                  obj: ObjectParams) -> None:
    """With the object's unknowns, each particle carries its own object (mass and centre of
    mass, or surface curvature), starting from `obj`'s."""
    if any(u.kind in ("mass", "com") for u in unknowns):
        state.hold_object(obj)
    if any(u.kind == "curvature" for u in unknowns):
        state.hold_surface(obj)


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
    onto a few dozen particles (METHOD.md 8.2); tempering keeps the particle set alive while
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
    """METHOD.md 3 convergence measure: mean over joint angles of the 95% interval width [deg].

    theta_samples: (P, N*K) or (P, N, K) angles [rad] of equally weighted particles."""
    t = np.asarray(theta_samples).reshape(len(theta_samples), -1)
    q = np.quantile(t, [0.025, 0.975], axis=0)
    return float(np.degrees(np.mean(q[1] - q[0])))


# --------------------------------------------------------------------------- config and records

CONTACT_PRIORS = ("pad", "surface")
# How the scale unknowns are drawn over their priors (`FilterConfig.prior_shape`).
PRIOR_SHAPES = ("uniform", "log-uniform")
JITTER_KERNELS = ("gaussian", "copula", "copula-joints", "copula-scales",
                  "copula-joints-scales", "log-scales", "log-springs")
LOG_PRIOR_KINDS = ("stiffness", "tendon", "mass")
# The scale unknowns whose evidence is a deflection that goes as 1/k (a joint's spring, the
# tendon's): a likelihood near symmetric in 1/k is skewed on k and close to symmetric on
# log k. The object's mass loads the hand linearly, and on its logarithm its estimates
# moved down, worse on two objects of four. "log-springs" draws the springs on their
# logarithms (docs/RESULTS.md 5, session 41).
SPRING_KINDS = ("stiffness", "tendon")

# A prior of which no particle settles at the grasp command is drawn again this many times in
# all: a small filter's unlucky draw (1000 particles in a task's check) is not a lost grasp.
PRIOR_DRAWS = 3


@dataclass(frozen=True)
class FilterConfig:
    """Particle filter settings (units in brackets).

    Attributes:
        n_particles: P (the paper: 60,000).
        seed: seed of the filter's np.random.Generator (all its randomness).
        theta_spread: prior std of the joint angles about the nominal grasp [rad].
        contact_spread: prior std of the pad contact angles (alpha, beta) [rad].
        contact_prior: what the contact angles are drawn about: "pad", the nominal grasp's
            contacts (the pad's inner face unless the guess says otherwise); "surface",
            where each particle's own pads would touch an object of the local surface's
            shape (`vlr.surface.surface_contact_normals`: a sphere's or a cylinder's radius,
            a box's faces, oriented by the observed POM; with a curvature unknown, each
            particle's own), for three fingers; else "pad".
        unknowns: unknown-parameter specs (`parse_unknown`).
        priors: optional uniform prior (low, high) per unknown spec.
        prior_shape: how the scale unknowns (`LOG_PRIOR_KINDS`: a spring, the tendon, the
            object's mass; positive, with default priors a factor either way of the
            nominal) are drawn over their (low, high): "uniform", or "log-uniform", uniform
            in the logarithm, whose median is the geometric mean (the nominal, for the
            default priors): a uniform draw on 0.25-4x the nominal puts its median at 2.1x
            and two thirds of its mass above 1.5x (docs/RESULTS.md 5, session 35). Other
            unknowns are drawn uniform either way.
        unknown_warmup: for the grasp's update and the first `unknown_warmup - 1` actions the
            unknowns are drawn afresh from their prior after each resampling, so that while
            the joints and contacts are still spread the likelihood does not select them (a
            stiffer spring damps the motion a wrong configuration predicts: docs/RESULTS.md
            5, session 35); 0: off.
        unknown_discount: delta in (0, 1], the discount factor of West and Harrison's
            artificial evolution of the unknowns: after each Liu-West draw the jittered
            particles' unknowns spread about their mean by 1/sqrt(delta) more, so the
            posterior's memory of old observations fades (about 1/(1 - delta) actions), for
            an estimate the first actions, whose joints were still spread, may have misled.
            Measured not a win on the spring row: its lean is not the first actions' memory
            (docs/RESULTS.md 5, session 37); 1: off.
        ess_fraction: tempering keeps ESS >= this fraction of P after weighting.
        jitter_h: Liu-West kernel bandwidth h. METHOD.md 8.2 found about 0.2; measured here
            on the synthetic world (20k particles, 5 seeds per case, docs/RESULTS.md 1),
            coverage of the known hand / unknown stiffness / NH1 went 0.90 / 0.77 / 0.53 at
            0.2, 0.97 / 0.86 / 0.53 at 0.3 and 0.97 / 0.91 / 0.78 at 0.4, at the cost of a
            few more iterations: the wider kernel keeps exploring the contact-angle ridges.
        jitter_kernel: "log-springs" (the default since session 41), Liu and West's kernel
            on the springs' logarithms (`SPRING_KINDS`: a joint's spring, the tendon;
            positive, their evidence a deflection that goes as 1/k; Liu and West 2001
            move a positive parameter on its logarithm) and on every other dimension's
            values: the spring row's lean halved, every row without a spring unknown
            drawn as by "gaussian" (docs/RESULTS.md 5, session 41); "log-scales", the
            object's mass on its logarithm too (it moves the mass's estimates 7-16% down:
            the apple's and the wine glass's worse, the flat screwdriver's better);
            "gaussian", the kernel on every dimension's values, which makes every
            marginal Gaussian over repeated draws (its median drifts to its mean: a joint
            cut at its open stop drifts off it, a skewed spring up); "copula", on each
            dimension's normal scores (`vlr.copula`), which keeps the marginals' shapes
            (session 39); "copula-joints", on the joint angles' scores and the other
            dimensions' values; "copula-scales", on the scale unknowns'
            (`LOG_PRIOR_KINDS`) scores and the rest's values; "copula-joints-scales", on
            both's scores (session 40).
        liu_west_shrink: shrink towards the mean by sqrt(1 - h^2) so jitter keeps variance.
        ci_threshold_deg: convergence when the mean 95% interval width of the joint angles
            falls below this [deg] (METHOD.md 3).
        motion: motion-model settings.
        init_jump_theta: jump limit of the initial projection to equilibrium at u_0 [rad]
            (the prior is wider than one action).
        project_jitter: settle jittered particles at the current command and re-anchor
            them (`ParticleFilter._project`); off reproduces plain Liu-West jitter.
        jitter_keep_parent: the first copy of each resampled particle is kept as it was and
            only its duplicates are jittered (`ParticleFilter._jitter`).
        observation: likelihood scales.
        anneal_stages: the most weighting stages per observation. When tempering holds the
            exponent beta below 1 (the likelihood is sharp against the particle spread: the
            grasp's observation, a surprising action), the rest of the likelihood is not
            thrown away: the particles are resampled, their states BEFORE the motion step
            jittered (Liu-West) and moved again (the action re-solved, or the prior
            re-settled), and weighted by the likelihood to the remaining exponent, until the
            exponents sum to 1 or the stages are spent (annealed importance sampling with
            resample-move steps; Deutscher et al. 2000, Chopin 2002). Each stage costs one
            motion solve of the moved particles. 1: the remainder is dropped.
    """

    n_particles: int = 60_000
    seed: int = 0
    theta_spread: float = float(np.radians(3.0))
    contact_spread: float = 0.15
    contact_prior: str = "pad"
    unknowns: tuple[str, ...] = ()
    priors: dict[str, tuple[float, float]] = field(default_factory=dict)
    prior_shape: str = "uniform"
    unknown_warmup: int = 0
    unknown_discount: float = 1.0
    ess_fraction: float = 0.1
    jitter_h: float = 0.4
    jitter_kernel: str = "log-springs"
    liu_west_shrink: bool = True
    ci_threshold_deg: float = 2.0
    motion: MotionConfig = field(default_factory=MotionConfig)
    init_jump_theta: float = 1.0
    project_jitter: bool = True
    jitter_keep_parent: bool = True
    observation: ObservationModel = field(default_factory=ObservationModel)
    anneal_stages: int = 1

    def __post_init__(self) -> None:
        if isinstance(self.unknown_warmup, bool) or not (
                isinstance(self.unknown_warmup, int) and self.unknown_warmup >= 0):
            raise ValueError(f"unknown_warmup {self.unknown_warmup!r} must be an integer >= 0")
        if not 0.0 < self.unknown_discount <= 1.0:
            raise ValueError(f"unknown_discount {self.unknown_discount!r} must be in (0, 1]")
        if self.jitter_kernel not in JITTER_KERNELS:
            raise ValueError(f"jitter_kernel {self.jitter_kernel!r}: expected one of "
                             f"{JITTER_KERNELS}")
        if self.prior_shape not in PRIOR_SHAPES:
            raise ValueError(f"prior_shape {self.prior_shape!r}: expected one of "
                             f"{PRIOR_SHAPES}")
        if self.contact_prior not in CONTACT_PRIORS:
            raise ValueError(f"contact_prior {self.contact_prior!r}: expected one of "
                             f"{CONTACT_PRIORS}")
        if isinstance(self.anneal_stages, bool) or not (
                isinstance(self.anneal_stages, int) and self.anneal_stages >= 1):
            raise ValueError(f"anneal_stages {self.anneal_stages!r} must be an integer >= 1")


@dataclass(frozen=True)
class Summary:
    """Per-dimension mean, median and 95% interval of a particle set.

    The mean minimizes the expected squared error, the median the expected absolute error
    (the paper's measure, METHOD.md 6). They part where the posterior is skewed, as for a
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
    before jitter (None for a prediction-only step). ci_deg: the convergence measure.
    """

    iteration: int
    command: np.ndarray
    prior: Summary
    posterior: Summary | None
    ess: float
    beta: float
    n_invalid: int
    ci_deg: float
    stages: int = 1


def _liu_west(x: np.ndarray, a: float, h: float, rng: np.random.Generator) -> np.ndarray:
    """x' = a x + (1 - a) mean + h L eps, L L^T the covariance of `x` (P, D) (METHOD.md 8.2)."""
    mean = x.mean(axis=0)
    cov = np.cov(x, rowvar=False)
    d = cov.shape[0]
    scale = np.sqrt(np.maximum(np.diag(cov), 0.0)) + 1e-12
    corr = cov / np.outer(scale, scale) + 1e-9 * np.eye(d)
    chol = np.linalg.cholesky(corr) * scale[:, None]
    eps = rng.standard_normal(x.shape)
    return a * x + (1.0 - a) * mean + h * eps @ chol.T


# --------------------------------------------------------------------------- the filter

class ParticleFilter:
    """Algorithm 1 over `ParticleState`s, with the motion model of `vlr.motion`."""

    def __init__(self, model: HandModel, obj: ObjectParams,
                 config: FilterConfig | None = None) -> None:
        self.model = model
        self.config = config or FilterConfig()
        self.motion = MotionModel(model, obj, self.config.motion)
        self.obs_model = self.config.observation
        check_unknown_set(self.config.unknowns)
        self.unknowns = tuple(parse_unknown(s, model, self.config.priors.get(s), obj)
                              for s in self.config.unknowns)
        self.rng = np.random.default_rng(self.config.seed)
        self.state: ParticleState | None = None
        self.history: list[IterationRecord] = []
        self.iteration = 0
        self.command: np.ndarray | None = None
        self._project_cfg = replace(self.config.motion, jump_theta=self.config.init_jump_theta,
                                    jump_pos=0.05)
        self.project_status = np.zeros(5, dtype=np.int64)
        self.newton_iterations: dict[str, float] = {}
        self.recoveries = 0  # times every particle failed and the prior was resampled
        self.prior_redraws = 0  # prior draws of which no particle settled (`initialize`)
        self._before: tuple[np.ndarray, np.ndarray] | None = None  # POM poses before an action
        # The particles before the last motion step and the command they were at (None: the
        # prior's draws before their settle), for the resample-move stages of `anneal_stages`.
        self._pre: tuple[ParticleState, np.ndarray | None] | None = None
        self._init_cfg = replace(self.config.motion, jump_theta=self.config.init_jump_theta,
                                 jump_pos=0.05, max_iter=max(self.config.motion.max_iter, 100))
        # Seconds per phase of the last iteration (motion, observation, weights, resampling,
        # jitter, summary), for `vlr bench`.
        self.timings: dict[str, float] = {}

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

    # ---- Algorithm 1

    def initialize(self, observation: PoseObservation, command: np.ndarray,
                   nominal_theta: np.ndarray, nominal_contact: np.ndarray) -> IterationRecord:
        """Sample the prior about the nominal grasp and weight it by the first observation.

        Joint angles ~ N(nominal_theta, theta_spread); pad contact angles ~ N(nominal_contact,
        contact_spread); unknowns ~ uniform priors. Each particle takes the observed POM pose
        and derives its anchors from its own contacts, then settles to equilibrium at the
        known command u_0 (METHOD.md 3: a focused prior that still covers the truth).

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
                f"none of the {self.config.n_particles} prior particles settled at the grasp "
                f"command in {PRIOR_DRAWS} draws (solve status counts "
                f"{self.init_status.tolist()}): the nominal guess or its spread misses this "
                "grasp, or the filter is too small")
        return self._update(observation)

    def _sample_prior(self, observation: PoseObservation, command: np.ndarray,
                      nominal_theta: np.ndarray, nominal_contact: np.ndarray) -> None:
        """The prior of `initialize`, settled at `command` (module docstring)."""
        cfg, m, rng = self.config, self.model, self.rng
        p = cfg.n_particles
        nf = m.n_fingers
        state = ParticleState.nominal(m, p, nominal_theta, np.zeros((nf, 3)) + [0, 1, 0],
                                      np.asarray(observation.position, dtype=float),
                                      np.asarray(observation.rotation, dtype=float))
        state.theta += rng.normal(0.0, cfg.theta_spread, state.theta.shape)
        spread = rng.normal(0.0, cfg.contact_spread, (p, nf, 2))
        self._hold_object(state)
        for u in self.unknowns:
            set_unknown(state, u, draw_prior(rng, u, p, cfg.prior_shape))
        centre = np.asarray(nominal_contact, dtype=float)[None]
        if cfg.contact_prior == "surface":
            # After the unknowns: a link's length moves its pad, a curvature its surface.
            normals = surface_contact_normals(m, self.motion.obj.surface, state.theta,
                                              state.segments, state.rot,
                                              self.motion.contact_rho(state))
            if normals is not None:
                centre = np.stack(angles_from_normals(normals), axis=-1)
        ab = centre + spread
        state.normals[...] = normals_from_angles(ab[..., 0], ab[..., 1])
        state.anchor_to_pose(m)
        self.state = state
        self.command = np.asarray(command, dtype=float).copy()
        self._pre = (state.copy(), None) if cfg.anneal_stages > 1 else None
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
        # The POM poses before the action: each particle's predicted motion over it scales
        # the likelihood's model error when `observation.motion_fraction` > 0.
        self._before = ((self.state.pos.copy(), self.state.rot.copy())
                        if self.obs_model.motion_fraction > 0 else None)
        self._pre = ((self.state.copy(), previous) if self.config.anneal_stages > 1
                     else None)
        _, iters = self.motion.solve(self.state, self.command, u_from=previous)
        # Median Newton iterations of the action solve and of the post-jitter settle
        # (`vlr bench` reports them: they are what a filter iteration costs).
        self.newton_iterations = {"action": float(np.median(iters))}
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
        self._before = None      # new particles: no motion of theirs to speak of
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
        # Eq. 5 likelihood, tempered (METHOD.md 8.2).
        t = time.perf_counter()
        log_lik = self._log_likelihood(state, observation)
        tm["observation"] = time.perf_counter() - t
        t = time.perf_counter()
        w, beta = temper(log_lik, cfg.ess_fraction)
        tm["weights"] = time.perf_counter() - t
        # The rest of a tempered likelihood in resample-move stages (`anneal_stages`).
        stages = 1
        t = time.perf_counter()
        while beta < 1.0 - 1e-9 and stages < cfg.anneal_stages and self._pre is not None:
            self.state = state = self._move(systematic_resample(w, self.rng))
            w, b = temper(self._log_likelihood(state, observation), cfg.ess_fraction,
                          max_beta=1.0 - beta)
            beta, stages = beta + b, stages + 1
        self._pre = None
        if stages > 1:
            x = self.pack(state)
        tm["anneal"] = time.perf_counter() - t
        ess = effective_sample_size(w)
        # Resample (systematic), then jitter.
        t = time.perf_counter()
        idx = systematic_resample(w, self.rng)
        self.state = state = state.take(idx)
        x = x[idx]
        tm["resampling"] = time.perf_counter() - t
        t = time.perf_counter()
        posterior = Summary.of(x)
        ci = self.ci_deg(x)
        tm["summary"] += time.perf_counter() - t
        t = time.perf_counter()
        if self.iteration < cfg.unknown_warmup:
            self._redraw_unknowns(x)
        self._jitter(x, idx)
        tm["jitter"] = time.perf_counter() - t
        rec = IterationRecord(self.iteration, self.command, prior, posterior, ess, beta,
                              n_invalid, ci, stages)
        self.history.append(rec)
        return rec

    def _redraw_unknowns(self, x: np.ndarray) -> None:
        """The unknowns' columns of `x` drawn afresh from their priors (`unknown_warmup`)."""
        base = x.shape[1] - len(self.unknowns)
        for j, u in enumerate(self.unknowns):
            x[:, base + j] = draw_prior(self.rng, u, len(x), self.config.prior_shape)

    def _log_likelihood(self, state: ParticleState, observation: PoseObservation) -> np.ndarray:
        """Eq. 5 per particle; with `motion_fraction`, its scales grow with each particle's
        predicted POM motion over the action (from `self._before`); with `sigma_tension`,
        each particle's predicted tendon tensions at the current command are weighed too."""
        motion = None
        if self._before is not None:
            pos0, rot0 = self._before
            motion = (np.linalg.norm(state.pos - pos0, axis=-1), rotation_angle(rot0, state.rot))
        tensions = (self.motion.tensions(state, self.command)
                    if self.obs_model.sigma_tension > 0 else None)
        return self.obs_model.log_likelihood(state, observation, motion, tensions)

    def _move(self, idx: np.ndarray) -> ParticleState:
        """One resample-move stage (`FilterConfig.anneal_stages`): the particles `idx` (a
        systematic resample) as they were before the motion step, jittered by the Liu-West
        kernel and moved again. Before an action: jittered and settled at the old command
        (`_jitter`), then the action solved again. At the grasp: the prior's draws jittered,
        anchored at the observed pose and settled again. The first copy of each parent is not
        jittered and keeps its motion. Returns the particles after the motion step."""
        pre, u_prev = self._pre
        pre = pre.take(idx)
        post = self.state.take(idx)
        x = self.pack(pre)
        if u_prev is None:
            x_new, moved = self._kernel(x, idx)
            rows = np.arange(len(idx)) if moved is None else np.flatnonzero(moved)
            sub = pre.take(rows)
            self.unpack(x_new[rows], sub)
            sub.anchor_to_pose(self.model)
            pre.put(rows, sub)
            sub = sub.copy()
            self.motion.solve(sub, self.command, self._init_cfg)
        else:
            state, command = self.state, self.command
            self.state, self.command = pre, u_prev
            try:
                moved = self._jitter(x, idx)
            finally:
                self.state, self.command = state, command
            rows = np.arange(len(idx)) if moved is None else np.flatnonzero(moved)
            sub = pre.take(rows)
            self.motion.solve(sub, self.command, u_from=u_prev)
        post.put(rows, sub)
        self._pre = (pre, u_prev)
        if self._before is not None:
            self._before = (pre.pos.copy(), pre.rot.copy())
        return post

    def _kernel(self, x: np.ndarray,
                parents: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray | None]:
        """Liu-West draw over the sampled dimensions (METHOD.md 8.2).

        x' = a x + (1 - a) mean + h L eps, with L L^T the particle covariance and
        a = sqrt(1 - h^2): the kernel adds h^2 of the variance and the shrink removes it.
        With `jitter_kernel` "copula" the draw is made on each dimension's normal scores
        (`vlr.copula`), which keeps the marginals' shapes (a joint cut at its stop);
        "copula-joints" on the joint angles' scores alone, "copula-scales" on the scale
        unknowns', "copula-joints-scales" on both (`_score_columns`); "log-springs" (the
        default) on the springs' logarithms (x -> log x, the draw, exp), "log-scales" on
        every scale unknown's: a fixed transform where the scores follow the particles'
        own ranks.
        Returns x' and the rows that moved (None: all; with `jitter_keep_parent` the first
        copy of each resampled parent stays as it was)."""
        cfg = self.config
        h = cfg.jitter_h
        a = np.sqrt(1.0 - h * h) if cfg.liu_west_shrink else 1.0
        on_scores = self._score_columns(x)
        if on_scores.any():
            # The chosen columns on their normal scores, the rest as they are. A run of
            # columns is taken as a slice: a view sums in the order the kernels' earlier
            # branches did, so their draws stay the same to the bit.
            idx = np.flatnonzero(on_scores)
            cols = (slice(idx[0], idx[-1] + 1) if idx[-1] - idx[0] + 1 == len(idx)
                    else idx)
            scores = NormalScores.fit(x[:, cols])
            y = x.copy()
            y[:, cols] = scores.to_normal(x[:, cols])
            x_new = _liu_west(y, a, h, self.rng)
            x_new[:, cols] = scores.from_normal(x_new[:, cols])
        elif cfg.jitter_kernel in ("log-scales", "log-springs"):
            kinds = SPRING_KINDS if cfg.jitter_kernel == "log-springs" else LOG_PRIOR_KINDS
            on_log = self._scale_columns(x.shape[1], kinds)
            y = x.copy()
            y[:, on_log] = np.log(x[:, on_log])
            x_new = _liu_west(y, a, h, self.rng)
            x_new[:, on_log] = np.exp(x_new[:, on_log])
        else:
            x_new = _liu_west(x, a, h, self.rng)
        mean = x.mean(axis=0)
        moved = None
        if cfg.jitter_keep_parent and parents is not None:
            # Systematic resampling returns sorted indexes, so copies are contiguous.
            first = np.ones(len(parents), dtype=bool)
            first[1:] = parents[1:] != parents[:-1]
            x_new[first] = x[first]
            moved = ~first
        base = x.shape[1] - len(self.unknowns)
        if cfg.unknown_discount < 1.0 and self.unknowns:
            # Artificial evolution: only the jittered rows, since a kept parent's state is
            # the equilibrium of its own unknowns and is not settled again.
            rows = slice(None) if moved is None else moved
            u_mean = mean[base:]
            x_new[rows, base:] = u_mean + (x_new[rows, base:] - u_mean) / np.sqrt(
                cfg.unknown_discount)
        # Keep unknowns inside their priors (reflect at the bounds).
        for j, u in enumerate(self.unknowns):
            lo, hi = u.prior
            col = x_new[:, base + j]
            col = np.where(col < lo, 2 * lo - col, col)
            x_new[:, base + j] = np.clip(np.where(col > hi, 2 * hi - col, col), lo, hi)
        return x_new, moved

    def _score_columns(self, x: np.ndarray) -> np.ndarray:
        """Which of the sampled dimensions of `x` (P, D) the Liu-West draw makes on normal
        scores (`FilterConfig.jitter_kernel`): a boolean mask over the D columns."""
        kernel = self.config.jitter_kernel
        n_columns = x.shape[1]
        mask = np.zeros(n_columns, dtype=bool)
        if kernel == "copula":
            mask[:] = True
            return mask
        if kernel in ("copula-joints", "copula-joints-scales"):
            mask[:self.model.n_fingers * self.model.n_joints] = True
        if kernel in ("copula-scales", "copula-joints-scales"):
            mask |= self._scale_columns(n_columns, LOG_PRIOR_KINDS)
        return mask

    def _scale_columns(self, n_columns: int, kinds: tuple[str, ...]) -> np.ndarray:
        """The columns of the unknowns of these `kinds` (scale unknowns: positive) among
        `n_columns` sampled dimensions, the unknowns last: a boolean mask."""
        mask = np.zeros(n_columns, dtype=bool)
        base = n_columns - len(self.unknowns)
        for j, u in enumerate(self.unknowns):
            mask[base + j] = u.kind in kinds
        return mask

    def _jitter(self, x: np.ndarray, parents: np.ndarray | None = None) -> np.ndarray | None:
        """Liu-West kernel (`_kernel`) on `self.state` at `self.command`, then re-anchor and
        settle (`_project`). Returns the rows that moved (None: all)."""
        state = self.state
        residuals = state.contact_residuals(self.model)
        x_new, moved = self._kernel(x, parents)
        self.unpack(x_new, state)
        # The POM keeps its pose; the anchors follow the jittered contacts, each contact
        # keeping its penalty stretch (the grasp force).
        state.anchor_to_pose(self.model, residuals)
        if self.config.project_jitter:
            self._project(state, moved)
        return moved

    def _project(self, state: ParticleState, moved: np.ndarray | None = None) -> None:
        """Settle jittered particles to equilibrium at the current command, then re-anchor.

        A jittered configuration is off its equilibrium (Eq. 9): left as is, the next motion
        solve first travels back to it, several degrees and millimetres (measured: 10-25
        Newton iterations at 0.2-0.4 mm actions), and its predicted POM motion mixes that
        trek with the action's effect, so most jittered particles lose their weight. Settling
        at u_t and re-deriving the anchors against the pre-jitter POM pose (METHOD.md 8.2)
        keeps each particle's POM where it was observed, so the next update weighs only the
        action's effect, and the next solve is short.

        `moved` (P,) bool: only these particles were jittered; the others are still at their
        equilibrium and are left alone (with the measured ESS, about half the particles)."""
        if moved is None:
            moved = np.ones(state.n, dtype=bool)
        idx = np.flatnonzero(moved)
        sub = state.take(idx)
        status, iters = self.motion.solve(sub, self.command, self._project_cfg)
        self.project_status = np.bincount(status, minlength=5)
        self.project_status[0] += state.n - len(idx)
        self.newton_iterations["settle"] = float(np.median(iters)) if len(idx) else 0.0
        residuals = sub.contact_residuals(self.model)
        sub.pos[...] = state.pos[idx]
        sub.rot[...] = state.rot[idx]
        sub.anchor_to_pose(self.model, residuals)
        state.put(idx, sub)

    # ---- summaries

    def ci_deg(self, x: np.ndarray) -> float:
        """Mean 95% interval width over joint angles [deg] (METHOD.md 3)."""
        n_th = self.model.n_fingers * self.model.n_joints
        return interval_width_deg(x[:, :n_th]) if len(x) else float("inf")

    @property
    def converged(self) -> bool:
        return bool(self.history) and self.history[-1].ci_deg < self.config.ci_threshold_deg
