"""The self-identification loop (Algorithm 1, docs/METHOD.md 3): grasp, observe, act, update until
the joint-angle intervals converge or the iteration budget runs out.

Backend-agnostic: the loop sees a `world` that moves tendons (`grasp()`, `apply(delta)`,
returning the commands or an object with `.commands`, like `vlr.hand.Hand`'s ApplyReport) and
an `observer` callable that returns the POM pose (anything with `.position` and `.rotation`,
e.g. `vlr.perception.observe(...)`'s Observation) or None when the tag is not seen. The
synthetic world plugs in directly (`observer=world.observe`); the sim or hardware plug in with
`observer=lambda: perception.observe(hand.grab_frame().image, ...)`.

Ground truth, if given, is used ONLY to score each iteration (errors, coverage); the filter
never sees it.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Literal, Protocol

import numpy as np

from vlr.active import ActiveExploration, choose_action
from vlr.errors import UserError
from vlr.explore import ActionStream
from vlr.filter import FilterConfig, GraspFilter, IterationRecord, ParticleFilter
from vlr.hand import GraspError, report_commands
from vlr.kinematics import HandModel, contact_in_distal, normals_from_angles
from vlr.motion import ObjectParams
from vlr.observation import PoseObservation, TensionedObservation
from vlr.synthetic import NominalGrasp, Truth

__all__ = ["ActingWorld", "LoopConfig", "Estimate", "Score", "IdentifyResult", "identify",
           "make_filter"]


class ActingWorld(Protocol):
    """What the loop needs of a hand: close on the object, and change tendon commands."""

    def grasp(self) -> Any: ...

    def apply(self, delta: np.ndarray) -> Any: ...


@dataclass(frozen=True)
class LoopConfig:
    """The loop's settings (units in the names).

    Attributes:
        max_iterations: actions after the first observation.
        min_iterations: do not stop on convergence before this many actions.
        action_range_mm: (low, high) magnitude of each tendon's exploratory change, random
            sign (`vlr.explore`; 0.2-0.4 mm: 4-8 N at 20 N/mm).
        action_band_mm: commands stay within this of the grasp command (at least the
            range's high end): a long random walk would slacken a tendon or crush the object.
        stop_on_convergence: stop once the 95% interval criterion holds (docs/METHOD.md 3).
        exploration: "random" (the paper) or "active" (`vlr.active`: the candidate whose
            predicted POM poses disagree most across the particles).
        active: settings of the active choice.
        first_observation_frames: frames to wait for the first tag detection after the
            grasp before giving up with a GraspError.
    """

    max_iterations: int = 40
    min_iterations: int = 0
    action_range_mm: tuple[float, float] = (0.2, 0.4)
    action_band_mm: float = 0.4
    stop_on_convergence: bool = True
    exploration: Literal["random", "active"] = "random"
    active: ActiveExploration = field(default_factory=ActiveExploration)
    first_observation_frames: int = 30

    def __post_init__(self) -> None:
        if self.max_iterations < 0:
            raise ValueError(f"max_iterations {self.max_iterations} must be >= 0")
        if not 0 <= self.min_iterations <= self.max_iterations:
            raise ValueError(f"min_iterations {self.min_iterations} must be in "
                             f"[0, max_iterations={self.max_iterations}]")
        lo, hi = self.action_range_mm
        if not 0 < lo <= hi <= 2.0:
            raise ValueError(f"action_range_mm {list(self.action_range_mm)} must be [low, "
                             "high] with 0 < low <= high <= 2 (larger moves drop objects)")
        if not (self.action_band_mm > 0 and self.action_band_mm < float("inf")):
            raise ValueError(f"action_band_mm {self.action_band_mm} must be > 0")
        if self.exploration not in ("random", "active"):
            raise ValueError(f"exploration {self.exploration!r}: use random or active")
        if self.first_observation_frames < 1:
            raise ValueError(f"first_observation_frames {self.first_observation_frames} "
                             "must be >= 1")


@dataclass(frozen=True)
class Estimate:
    """Posterior mean, 95% interval and median of one quantity."""

    mean: float
    low: float
    high: float
    median: float | None = None


@dataclass(frozen=True)
class Score:
    """Errors against ground truth at one iteration (scoring only)."""

    theta_error_deg: np.ndarray
    theta_covered: np.ndarray
    unknown_error: dict[str, float]
    unknown_covered: dict[str, bool]
    theta_miss_deg: np.ndarray | None = None
    theta_true: np.ndarray | None = None
    # The same errors of the posterior median (the estimate of least absolute error).
    theta_error_median_deg: np.ndarray | None = None
    unknown_error_median: dict[str, float] | None = None
    # Whether each true joint lies in the 95% interval of the step's prior (before the
    # weighting): at the grasp, whether the user's guess and spread held the truth at all.
    theta_prior_covered: np.ndarray | None = None


@dataclass
class IdentifyResult:
    """Outcome of `identify`.

    Attributes:
        converged: the interval criterion held at the end.
        iterations: actions taken; converged_at: first iteration meeting it (or None).
        theta: {"finger.k": Estimate} joint angles [rad].
        contacts: (N, 3) mean contact points in each distal frame [m].
        distal_virtual_length: {finger: Estimate} distal joint to contact [m] (Eq. 2).
        unknowns: {spec: Estimate} identified parameters (SI units).
        history: one IterationRecord per filter update.
        scores: per-iteration Score when ground truth was given (else empty).
        seconds: wall time of the filter updates per iteration.
        grasp_lost_at: the action after which the hand reported the fingertip grasp lost
            (`vlr.hand.ApplyReport.grasp_held`), None if it held; the run stops there,
            before that action's update (the model assumes a fingertip grasp).
        grasp_message: the hand's reason.
        hypotheses: the filter's particles, or the UKF's sigma points.
    """

    converged: bool
    iterations: int
    converged_at: int | None
    theta: dict[str, Estimate]
    contacts: np.ndarray
    distal_virtual_length: dict[str, Estimate]
    unknowns: dict[str, Estimate]
    history: list[IterationRecord]
    scores: list[Score]
    seconds: list[float]
    grasp_lost_at: int | None = None
    grasp_message: str = ""
    hypotheses: int = 0


def make_filter(model: HandModel, obj: ObjectParams, config: FilterConfig | None = None,
                seed: int = 0) -> GraspFilter:
    """The estimator `config.estimator` names: the particle filter ("pf") or the unscented
    Kalman filter ("ukf", `vlr.ukf`, imported only then)."""
    config = config or FilterConfig()
    if config.estimator == "ukf":
        from vlr.ukf import UnscentedFilter

        return UnscentedFilter(model, obj, config, seed)
    return ParticleFilter(model, obj, config, seed)


def _score(pf: GraspFilter, rec: IterationRecord, truth: Truth) -> Score:
    post = rec.posterior or rec.prior
    n_th = pf.model.n_fingers * pf.model.n_joints
    t = truth.theta.ravel()
    err = np.degrees(np.abs(post.mean[:n_th] - t))
    err_med = np.degrees(np.abs(post.median[:n_th] - t))
    cov = (post.low[:n_th] <= t) & (t <= post.high[:n_th])
    miss = np.degrees(np.maximum(np.maximum(post.low[:n_th] - t, t - post.high[:n_th]), 0.0))
    prior_cov = (rec.prior.low[:n_th] <= t) & (t <= rec.prior.high[:n_th])
    base = len(post.mean) - len(pf.unknowns)
    ue, uc, ue_med = {}, {}, {}
    for j, u in enumerate(pf.unknowns):
        if u.kind == "curvature" and getattr(truth, "surface_curvature", None) is None:
            continue  # a mesh object: the world does not say
        if u.kind == "stiffness":
            true = truth.stiffness[u.finger, u.joint]
        elif u.kind == "length":
            true = truth.segments[u.finger, u.joint]
        elif u.kind == "mass":
            true = truth.object_mass
        elif u.kind == "com":
            true = truth.object_com[u.joint]
        elif u.kind == "curvature":
            true = truth.surface_curvature
        else:
            true = truth.tendon[max(u.finger, 0)]
        ue[u.spec] = float(post.mean[base + j] - true)
        ue_med[u.spec] = float(post.median[base + j] - true)
        uc[u.spec] = bool(post.low[base + j] <= true <= post.high[base + j])
    return Score(err, cov, ue, uc, miss, t.copy(), err_med, ue_med, prior_cov)


def identify(world: ActingWorld, observer: Callable[[], PoseObservation | None],
             model: HandModel, obj: ObjectParams, nominal: NominalGrasp,
             filter_config: FilterConfig | None = None, loop: LoopConfig | None = None,
             seed: int = 0, truth: Callable[[], Truth] | None = None,
             progress: Callable[[IterationRecord], None] | None = None,
             watch: Callable[[GraspFilter, IterationRecord], None] | None = None,
             ) -> IdentifyResult:
    """Run Algorithm 1: grasp -> observe -> (act -> observe -> update)* until converged.

    Args:
        world: moves the tendons (`ActingWorld`).
        observer: returns the current POM pose, or None if not seen.
        model: the NOMINAL hand (what the user believes).
        obj: object mass and centre of mass.
        nominal: nominal grasp guess (angles, contacts) for the prior; its command is not used
            (the world's grasp() reports u_0).
        filter_config: the filter's settings (`filter.estimator`: the particle filter or
            the unscented Kalman filter, `make_filter`).
        loop: the loop's settings.
        seed: seeds the filter (`seed`) and the actions (`seed + 1`).
        truth: ground truth callable for SCORING ONLY.
        progress: called with each IterationRecord (e.g. a progress bar).
        watch: called with the filter and each IterationRecord after the update (e.g. a
            live 3D view of the particles); it must not change the filter.
    """
    cfg = loop or LoopConfig()
    if filter_config is not None and filter_config.estimator == "ukf":
        from vlr.ukf import check_estimator

        check_estimator(filter_config, cfg.exploration)
    pf = make_filter(model, obj, filter_config, seed)
    report = world.grasp()
    u = report_commands(report)
    weigh_tensions = pf.obs_model.sigma_tension > 0
    if weigh_tensions and getattr(report, "tensions", None) is None:
        raise UserError("the likelihood weighs tendon tensions (sigma_tension), and this "
                        "hand does not report them: set it to 0")
    tensions = getattr(report, "tensions", None)
    actions = ActionStream.of_trial(cfg, seed, u)
    obs = observer()
    tries = 1
    while obs is None:  # the filter needs one pose to anchor its particles
        if tries >= cfg.first_observation_frames:
            raise GraspError(f"the object's tag was not seen in {tries} frames after the "
                             "grasp: check the camera, the tag id and size, and the lighting")
        obs = observer()
        tries += 1
    scores: list[Score] = []
    seconds: list[float] = []
    t0 = time.perf_counter()
    if weigh_tensions:
        obs = _with_tensions(obs, tensions)
    rec = pf.initialize(obs, u, nominal.theta, nominal.contact)
    seconds.append(time.perf_counter() - t0)
    converged_at = None

    def after(rec: IterationRecord) -> None:
        if truth is not None:
            scores.append(_score(pf, rec, truth()))
        if progress is not None:
            progress(rec)
        if watch is not None:
            watch(pf, rec)

    after(rec)
    it = 0
    lost: tuple[int, str] | None = None
    while it < cfg.max_iterations:
        if pf.converged and converged_at is None:
            converged_at = it
        if pf.converged and cfg.stop_on_convergence and it >= cfg.min_iterations:
            break
        it += 1
        if cfg.exploration == "active":
            delta = choose_action(pf, actions.rng, u, actions.center, actions.explore,
                                  cfg.active)
        else:
            delta = actions.random(u)
        report = world.apply(delta)
        if not getattr(report, "grasp_held", True):
            # The fingertips no longer hold the object: the VLR's rigid grasp (Eq. 8) does
            # not hold, and an update would fit the model to a dropped or turned object.
            lost = (it, str(getattr(report, "message", "")))
            it -= 1
            break
        u = report_commands(report)
        obs = observer()
        if weigh_tensions and obs is not None:
            obs = _with_tensions(obs, getattr(report, "tensions", None))
        t0 = time.perf_counter()
        rec = pf.step(u, obs)
        seconds.append(time.perf_counter() - t0)
        after(rec)
    if pf.converged and converged_at is None:
        converged_at = it
    res = _result(pf, it, converged_at, scores, seconds)
    if lost is not None:
        res.grasp_lost_at, res.grasp_message = lost
    return res


def _with_tensions(obs: PoseObservation, tensions) -> PoseObservation:
    """The pose with the hand's tendon tensions beside it (`TensionedObservation`); the pose
    alone if the hand did not read them this time."""
    if tensions is None:
        return obs
    return TensionedObservation(np.asarray(obs.position), np.asarray(obs.rotation),
                                np.asarray(tensions, dtype=float))


def _result(pf: GraspFilter, iterations: int, converged_at: int | None,
            scores: list[Score], seconds: list[float]) -> IdentifyResult:
    m = pf.model
    # The estimate is the last posterior (resampled, before the jitter that prepares the
    # next step), the same set the scores and the convergence test read.
    last = pf.history[-1] if pf.history else None
    if last is not None:
        post = last.posterior or last.prior
    else:
        post = pf.summarize(pf.pack(pf.state))
    mean = post.mean
    names = pf.dim_names
    est = {n: Estimate(float(mean[j]), float(post.low[j]), float(post.high[j]),
                       float(post.median[j]))
           for j, n in enumerate(names)}
    n_th = m.n_fingers * m.n_joints
    theta = {f"{f}.{k}": est[f"theta:{f}.{k}"] for f in m.names for k in range(m.n_joints)}
    ab = mean[n_th:n_th + 2 * m.n_fingers].reshape(m.n_fingers, 2)
    segments = pf.summarize(pf.state.segments).mean.reshape(m.n_fingers, m.n_joints)
    contacts = contact_in_distal(m, normals_from_angles(ab[:, 0], ab[:, 1]), segments)
    c_all = contact_in_distal(m, pf.state.normals, pf.state.segments)
    lengths = pf.summarize(np.linalg.norm(c_all[..., 1:], axis=-1))
    dvl = {f: Estimate(float(lengths.mean[i]), float(lengths.low[i]), float(lengths.high[i]),
                       float(lengths.median[i]))
           for i, f in enumerate(m.names)}
    unknowns = {u.spec: est[u.spec] for u in pf.unknowns}
    return IdentifyResult(converged=pf.converged, iterations=iterations,
                          converged_at=converged_at, theta=theta, contacts=contacts,
                          distal_virtual_length=dvl, unknowns=unknowns, history=pf.history,
                          scores=scores, seconds=seconds, hypotheses=pf.state.n)
