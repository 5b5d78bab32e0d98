"""Precise in-hand manipulation with the identified VLR: the Jacobian controller (Eq. 10-12).

Chaining the motion model Gamma (Eq. 4, 9) and the observation model Lambda (Eq. 5) gives
Upsilon: tendon change Delta l -> POM motion Delta phi. Its 6x3 Jacobian (Eq. 10) is taken
numerically on the identified VLR: central differences of the equilibrium POM pose of a few
posterior particles (`vlr.motion.MotionModel.solve`), averaged. A control step (Eq. 11) is
either the transpose step Delta l = k J^T Delta phi or, as an alternative, damped least
squares Delta l = (J^T J + lambda^2 I)^-1 J^T Delta phi. It is applied iteratively like a
proportional controller: act, re-observe the POM with the camera, let the particle filter
update the VLR (contacts roll), repeat until the error is below a set precision or the step
budget is spent (`reach`).

Sub-dimensions (docs/METHOD.md 5): rows are truncated to position (handwriting) or orientation
(maze), or all six are kept with the weighted error of Eq. 12,
Delta phi' = [Delta x, Delta y, Delta z, alpha Delta roll, alpha Delta pitch, alpha Delta yaw].
Ours: "full_no_yaw" and "tilt" drop the yaw row (about the palm normal) for an object that is
symmetric about it (a cup held level).
Units of Eq. 12 are our choice (the paper does not give them): millimetres and degrees, so
alpha = 9.5 makes one degree weigh as much as 9.5 mm (the cups use 0.7: tasks/cups.py).

Pose errors: position target - current in the palm frame [m]; rotation as the rotation vector
of R_target R_current^T in the palm frame [rad] (the spatial, left-multiplied convention, the
same one the Jacobian's rotation rows use).

The controller sees tendon commands and camera poses only, through the filter it is given.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from vlr.motion import MotionModel, ParticleState
from vlr.observation import PoseObservation

__all__ = [
    "ROWS",
    "ControllerConfig",
    "rotation_log",
    "pose_error",
    "observed_motion",
    "row_weights",
    "sample_particles",
    "numerical_jacobian",
    "reachable_motion",
    "transpose_step",
    "dls_step",
    "JacobianController",
    "ReachStep",
    "ReachResult",
    "reach",
]

# Row sets of Delta phi = [x, y, z, rx, ry, rz] (docs/METHOD.md 5: sub-dimensions).
ROWS: dict[str, tuple[int, ...]] = {
    "position": (0, 1, 2),
    "orientation": (3, 4, 5),
    "full": (0, 1, 2, 3, 4, 5),
    # Yaw dropped (rotation about the palm normal): an object symmetric about the axis the
    # palm faces (a cup held level) does not care about it, and three tendons barely turn
    # it, so a yaw error asks for large tendon changes that do nothing else (docs/TASKS.md).
    "full_no_yaw": (0, 1, 2, 3, 4),
    "tilt": (3, 4),
}
_MM = 1e-3                      # Eq. 12 length unit [m] (our choice, module docstring)
_DEG = float(np.radians(1.0))   # Eq. 12 angle unit [rad]


@dataclass(frozen=True)
class ControllerConfig:
    """Settings of the Jacobian controller (units in brackets).

    Attributes:
        rows: "position" | "orientation" | "full" | "full_no_yaw" | "tilt" (the rows of J
            and Delta phi kept, `ROWS`).
        method: "transpose" (Eq. 11) or "dls" (damped least squares).
        alpha: orientation weight of Eq. 12 [mm per degree] (the paper: 9.5 for cup stacking,
            in units it does not give; our cups: 0.7); used with the rows that
            mix position and rotation ("full", "full_no_yaw").
        gain: proportional gain on the step (1 = the full step the linear model asks for).
        damping: lambda of the damped least-squares step, in the units of Eq. 12 (mm, deg
            per mm of tendon); small against the singular values of J.
        max_step: largest tendon change per step [m], each tendon (the whole vector is
            scaled, so the direction is kept).
        tolerance_pos: stop when the position error is below this [m] (rows with position).
        tolerance_rot: stop when the rotation error is below this [rad] (rows with rotation).
        max_steps: step budget of `reach`.
        jacobian_eps: tendon perturbation of the central differences [m].
        jacobian_particles: particles of the posterior the Jacobian is averaged over (evenly
            spaced through the resampled set; 1 = the first).
        secant: learn a correction C of the VLR's Jacobian from the camera (ours, not the
            paper's): after each move Delta l with observed POM motion Delta phi, Broyden's
            rank-one update C += (Delta phi - (J_vlr + C) Delta l) Delta l^T / |Delta l|^2,
            so J = J_vlr + C. The VLR's Jacobian keeps changing as the filter updates; C
            carries what the camera saw that the VLR does not explain (an imperfect
            identification, e.g. a tendon the VLR believes slack).
        secant_updates: also update C after every move (Broyden), not only from the batch
            given to `fit`. Off by default: with stick-slip at the contacts, a small move's
            secant misleads more than it teaches (measured in docs/TASKS.md).
        secant_min_step: moves smaller than this [m] are too noisy to learn from.
        max_motion_pos: trust region (ours): a step is scaled down so that the POM motion
            the Jacobian predicts for it is at most this [m] ...
        max_motion_rot: ... and this [rad]. Where the grasp is very sensitive (a tendon
            that tips the object by degrees per 0.1 mm) a full step would overshoot.
        reversal_shrink: a tendon whose step reverses its previous step's sign has its
            steps scaled by this from then on (ours, as in Rprop); each step that keeps its
            sign grows the scale back by 1 / sqrt(this), up to 1. Stick-slip at the contacts
            makes a proportional step chatter about a target it cannot hold (docs/TASKS.md);
            1 turns it off.
    """

    rows: str = "position"
    method: str = "dls"
    alpha: float = 1.0
    gain: float = 0.8
    damping: float = 0.5
    max_step: float = 0.4e-3
    tolerance_pos: float = 0.1e-3
    tolerance_rot: float = float(np.radians(0.2))
    max_steps: int = 20
    jacobian_eps: float = 0.05e-3
    jacobian_particles: int = 16
    secant: bool = False
    secant_updates: bool = False
    secant_min_step: float = 0.02e-3
    max_motion_pos: float = 0.5e-3
    max_motion_rot: float = float(np.radians(0.5))
    reversal_shrink: float = 1.0

    def __post_init__(self) -> None:
        if self.rows not in ROWS:
            raise ValueError(f"rows {self.rows!r}: use one of {sorted(ROWS)}")
        if self.method not in ("transpose", "dls"):
            raise ValueError(f"method {self.method!r}: use 'transpose' or 'dls'")
        if not (self.max_step > 0 and self.jacobian_eps > 0 and self.jacobian_particles >= 1):
            raise ValueError("max_step, jacobian_eps and jacobian_particles must be positive")
        # The trust region divides by these; a zero gain or a negative damping is no step.
        if not (self.max_motion_pos > 0 and self.max_motion_rot > 0 and self.gain > 0
                and self.damping >= 0 and self.max_steps >= 0):
            raise ValueError("max_motion_pos, max_motion_rot and gain must be positive, "
                             "damping and max_steps >= 0")
        if not 0 < self.reversal_shrink <= 1:
            raise ValueError(f"reversal_shrink {self.reversal_shrink!r} must be in (0, 1]")


# --------------------------------------------------------------------------- pose errors

def rotation_log(r: np.ndarray) -> np.ndarray:
    """Rotation vector (3,) [rad] of a rotation matrix (3, 3): the SO(3) logarithm.

    Uses the skew part for small angles (accurate where arccos of the trace is not) and the
    symmetric part near pi."""
    r = np.asarray(r, dtype=float)
    w = 0.5 * np.array([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]])
    s = np.linalg.norm(w)
    c = 0.5 * (np.trace(r) - 1.0)
    angle = np.arctan2(s, c)
    if s < 1e-12:
        if c > 0:
            return w  # identity: the skew part is the (vanishing) rotation vector
        # angle ~ pi: axis from the symmetric part (R + I) / 2 = a a^T
        m = 0.5 * (r + np.eye(3))
        a = m[np.argmax(np.diag(m))]
        return np.pi * a / np.linalg.norm(a)
    return w * (angle / s)


def pose_error(position: np.ndarray, rotation: np.ndarray, target_position: np.ndarray,
               target_rotation: np.ndarray | None) -> np.ndarray:
    """Delta phi (6,): target minus current position [m], then the rotation vector of
    R_target R_current^T [rad], both in the palm frame. A target without a rotation gives a
    zero rotation error (position-only tasks)."""
    dp = np.asarray(target_position, dtype=float) - np.asarray(position, dtype=float)
    if target_rotation is None:
        dr = np.zeros(3)
    else:
        dr = rotation_log(np.asarray(target_rotation) @ np.asarray(rotation).T)
    return np.concatenate([dp, dr])


def row_weights(rows: str, alpha: float = 1.0) -> np.ndarray:
    """The diagonal of Eq. 12's weighting for the kept rows, in the units of Eq. 12:
    1/mm on position rows, alpha/deg on rotation rows (module docstring)."""
    w = np.array([1 / _MM] * 3 + [alpha / _DEG] * 3)
    return w[list(ROWS[rows])]


def observed_motion(before: PoseObservation, after: PoseObservation) -> np.ndarray:
    """The POM motion between two camera poses (6,): position change [m], then the rotation
    vector of R_after R_before^T [rad] (the convention of the Jacobian's rows)."""
    return pose_error(before.position, before.rotation, after.position, after.rotation)


# --------------------------------------------------------------------------- Eq. 10

def sample_particles(state: ParticleState, n: int) -> ParticleState:
    """`n` valid particles evenly spaced through the (resampled, equally weighted) set."""
    idx = np.flatnonzero(state.valid)
    if idx.size == 0:
        raise FloatingPointError("no valid particle to take the Jacobian on")
    pick = idx[np.linspace(0, idx.size - 1, min(n, idx.size)).round().astype(int)]
    return state.take(pick)


def numerical_jacobian(motion: MotionModel, state: ParticleState, command: np.ndarray,
                       eps: float = 0.05e-3, n_particles: int = 16,
                       max_iter: int = 200) -> np.ndarray:
    """J = [dUpsilon/dl_1 .. dUpsilon/dl_N] (6, N) of the identified VLR (Eq. 10).

    Upsilon chains Gamma (Eq. 4, 9: equilibrium at the commands) and Lambda (Eq. 5: the POM
    pose). Central differences at `command` +- eps e_j on each of `n_particles` posterior
    particles, averaged over the particles whose every solve succeeded. Rows: position [m/m],
    then rotation vector [rad/m] of R(u + eps) R(u - eps)^T. The filter's state is not changed.
    """
    u = np.asarray(command, dtype=float)
    # A perturbation smaller than an action converges slowly near a tendon's slack kink or
    # a joint stop: allow more Newton iterations than the filter's per-action budget.
    cfg = replace(motion.config, max_iter=max(motion.config.max_iter, max_iter))
    base = sample_particles(state, n_particles)
    # Settle the sample at the current command first: after the filter's jitter a particle
    # is slightly off its equilibrium, and that offset is not the tendon's doing.
    motion.solve(base, u, cfg)
    n = u.size
    plus, minus = [], []
    ok = base.valid.copy()
    for j in range(n):
        for sign, out in ((+1.0, plus), (-1.0, minus)):
            st = base.copy()
            du = np.zeros(n)
            du[j] = sign * eps
            motion.solve(st, u + du, cfg)
            ok &= st.valid
            out.append(st)
    if not ok.any():
        raise FloatingPointError("every Jacobian solve failed")
    jac = np.zeros((6, n, int(ok.sum())))
    for j in range(n):
        p, m = plus[j], minus[j]
        jac[:3, j] = ((p.pos[ok] - m.pos[ok]) / (2 * eps)).T
        rel = np.einsum("pab,pcb->pac", p.rot[ok], m.rot[ok])
        jac[3:, j] = (np.array([rotation_log(r) for r in rel]) / (2 * eps)).T
    return jac.mean(axis=-1)


# --------------------------------------------------------------------------- Eq. 11-12

def transpose_step(jac: np.ndarray, error: np.ndarray, gain: float = 1.0) -> np.ndarray:
    """Eq. 11: Delta l = k J^T Delta phi, in the weighted units of Eq. 12.

    The scalar k is the step that minimises |Delta phi - J Delta l| along J^T Delta phi,
    k = <e, J J^T e> / |J J^T e|^2 (Buss, "Introduction to inverse kinematics with Jacobian
    transpose ...", 2004), times `gain`; a fixed k would need retuning for every grasp."""
    g = jac.T @ error
    jg = jac @ g
    denom = float(jg @ jg)
    if denom <= 0.0:
        return np.zeros(jac.shape[1])
    return gain * (float(error @ jg) / denom) * g


def dls_step(jac: np.ndarray, error: np.ndarray, damping: float,
             gain: float = 1.0) -> np.ndarray:
    """Damped least squares: Delta l = k (J^T J + lambda^2 I)^-1 J^T Delta phi (the
    alternative to Eq. 11 that docs/METHOD.md 5 names)."""
    n = jac.shape[1]
    return gain * np.linalg.solve(jac.T @ jac + damping**2 * np.eye(n), jac.T @ error)


class JacobianController:
    """One control step from the filter's current VLR and the camera's POM pose.

    `act` returns the tendon change for the error between an observed POM pose and a target;
    the Jacobian is retaken on the filter's posterior every call (the filter keeps updating
    between calls, since contacts roll)."""

    def __init__(self, config: ControllerConfig | None = None) -> None:
        self.config = config or ControllerConfig()
        self.last_jacobian: np.ndarray | None = None   # J_vlr of the last `act`
        self.correction: np.ndarray | None = None      # C of the secant update (6, N)
        self._last_step: np.ndarray | None = None      # the last `step`, for reversals
        self.step_scale: np.ndarray | None = None      # per tendon (`reversal_shrink`)

    @property
    def jacobian(self) -> np.ndarray | None:
        """The Jacobian the last step used: J_vlr, plus C when `secant` is on."""
        if self.last_jacobian is None:
            return None
        if self.correction is None:
            return self.last_jacobian
        return self.last_jacobian + self.correction

    def fit(self, deltas: np.ndarray, motions: np.ndarray, jacobian: np.ndarray,
            ridge: float = 1e-12) -> None:
        """Least-squares correction C from a batch of moves (`secant`), e.g. the
        identification's exploratory actions: C = R D^T (D D^T + mu I)^-1 with D the tendon
        changes (N, K) [m], R = motions - J_vlr D (6, K), `ridge` mu [m^2]. Sets
        `last_jacobian` to `jacobian` (J_vlr there). A no-op for C unless `config.secant`."""
        self.last_jacobian = np.asarray(jacobian, dtype=float)
        d = np.asarray(deltas, dtype=float).T
        m = np.asarray(motions, dtype=float).T
        if not self.config.secant or d.shape[1] == 0:
            return
        r = m - self.last_jacobian @ d
        self.correction = r @ d.T @ np.linalg.inv(d @ d.T + ridge * np.eye(d.shape[0]))

    def learn(self, delta: np.ndarray, motion: np.ndarray,
              jacobian: np.ndarray | None = None) -> None:
        """Secant (Broyden) update of the correction C from one move (`secant`): `delta`
        the tendon change [m], `motion` the POM motion the camera saw (6,) [m, rad]
        (`observed_motion`), `jacobian` J_vlr at the move (default: the last one taken).
        A no-op unless `config.secant` and `config.secant_updates`."""
        cfg = self.config
        jv = self.last_jacobian if jacobian is None else jacobian
        d = np.asarray(delta, dtype=float)
        if not (cfg.secant and cfg.secant_updates) or jv is None:
            return
        if float(np.max(np.abs(d))) < cfg.secant_min_step:
            return
        if self.correction is None:
            self.correction = np.zeros_like(jv)
        residual = np.asarray(motion, dtype=float) - (jv + self.correction) @ d
        self.correction += np.outer(residual, d) / float(d @ d)

    def error(self, observation: PoseObservation, target_position: np.ndarray,
              target_rotation: np.ndarray | None = None) -> np.ndarray:
        """Delta phi (6,) [m, rad] (`pose_error`)."""
        return pose_error(observation.position, observation.rotation, target_position,
                          target_rotation)

    def done(self, error: np.ndarray) -> bool:
        """The kept rows are within the set precision."""
        cfg = self.config
        rows = ROWS[cfg.rows]
        ok = True
        if any(r < 3 for r in rows):
            ok &= bool(np.linalg.norm(error[:3]) <= cfg.tolerance_pos)
        rot = [r for r in rows if r >= 3]
        if rot:
            ok &= bool(np.linalg.norm(error[rot]) <= cfg.tolerance_rot)
        return ok

    def step(self, jacobian: np.ndarray, error: np.ndarray,
             bounds: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
        """Tendon change (N,) [m] for a 6xN Jacobian and a 6-vector error (Eq. 11-12),
        scaled down as a whole so no tendon moves more than `max_step` and the predicted
        POM motion stays in the trust region (`max_motion_pos`, `max_motion_rot`).

        `bounds` (low, high) (N,) [m], each low <= 0 <= high, are limits on the change (a
        band the commands must stay in): a tendon whose step would cross its limit is held
        at it and the step is solved again for the other tendons on the error left (an
        active set), so that a tendon stuck at its limit does not block the others."""
        cfg = self.config
        rows = list(ROWS[cfg.rows])
        w = row_weights(cfg.rows, cfg.alpha)
        jw = w[:, None] * jacobian[rows] * _MM   # weighted units per mm of tendon
        ew = w * error[rows]
        n = jacobian.shape[1]
        lo, hi = ((np.full(n, -np.inf), np.full(n, np.inf)) if bounds is None else
                  (np.asarray(bounds[0], dtype=float) / _MM,
                   np.asarray(bounds[1], dtype=float) / _MM))
        du = np.zeros(n)
        free = np.ones(n, dtype=bool)
        for _ in range(n):
            rest = ew - jw[:, ~free] @ du[~free]
            if cfg.method == "transpose":
                du[free] = transpose_step(jw[:, free], rest, cfg.gain)
            else:
                du[free] = dls_step(jw[:, free], rest, cfg.damping, cfg.gain)
            out = free & ((du < lo) | (du > hi))
            if not out.any():
                break
            du[out] = np.clip(du[out], lo[out], hi[out])
            free &= ~out
            if not free.any():
                break
        du = du * _MM
        biggest = float(np.max(np.abs(du))) if du.size else 0.0
        if biggest > cfg.max_step:
            du *= cfg.max_step / biggest
        pred = jacobian @ du
        moved = (float(np.linalg.norm(pred[:3])) / cfg.max_motion_pos,
                 float(np.linalg.norm(pred[3:])) / cfg.max_motion_rot)
        if max(moved) > 1.0:
            du /= max(moved)
        return self._damp_reversals(du)

    def _damp_reversals(self, du: np.ndarray) -> np.ndarray:
        """Scale each tendon's step by its `step_scale`, which shrinks by `reversal_shrink`
        when the step reverses the last one's sign and grows back while it does not."""
        shrink = self.config.reversal_shrink
        if shrink >= 1.0:
            return du
        if self.step_scale is None or self.step_scale.shape != du.shape:
            self.step_scale = np.ones_like(du)
        if self._last_step is not None and self._last_step.shape == du.shape:
            reversed_ = du * self._last_step < 0
            self.step_scale = np.where(reversed_, self.step_scale * shrink,
                                       np.minimum(1.0, self.step_scale / np.sqrt(shrink)))
        self._last_step = du.copy()
        return du * self.step_scale

    def act(self, motion: MotionModel, state: ParticleState, command: np.ndarray,
            observation: PoseObservation, target_position: np.ndarray,
            target_rotation: np.ndarray | None = None,
            bounds: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
        """The tendon change (N,) [m] towards the target: Jacobian (Eq. 10) on the filter's
        particles at the current command, then `step` (with its optional `bounds`)."""
        cfg = self.config
        try:
            self.last_jacobian = numerical_jacobian(motion, state, command, cfg.jacobian_eps,
                                                    cfg.jacobian_particles)
        except FloatingPointError:
            if self.last_jacobian is None:
                raise
            # Every sampled particle's solve failed here (a stop or a slack tendon close
            # by): keep the last Jacobian; the camera still closes the loop.
        return self.step(self.jacobian, self.error(observation, target_position,
                                                   target_rotation), bounds)


def reachable_motion(jacobian: np.ndarray, error: np.ndarray, rows: str,
                     bounds: tuple[np.ndarray, np.ndarray],
                     alpha: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """The tendon change (N,) [m] within `bounds` (low, high) that best achieves the kept
    `rows` of `error` (6,) [m, rad] by the linear model J (6xN, Eq. 10), weighted as Eq. 12,
    and the whole POM motion J du (6,) it predicts. Three tendons cannot choose all six
    dimensions: a task that fixes some of them (the cups' level orientation) reads the rest
    of the pose the grasp will take from this. A bounded least-squares problem
    (scipy.optimize.lsq_linear), in millimetres of tendon for conditioning."""
    from scipy.optimize import lsq_linear

    keep = list(ROWS[rows])
    w = row_weights(rows, alpha)
    jw = w[:, None] * np.asarray(jacobian, dtype=float)[keep] * _MM
    ew = w * np.asarray(error, dtype=float)[keep]
    lo = np.asarray(bounds[0], dtype=float) / _MM
    hi = np.asarray(bounds[1], dtype=float) / _MM
    if np.any(lo > 0) or np.any(hi < 0):
        raise ValueError(f"bounds {lo} .. {hi} mm must hold zero")
    # lsq_linear wants low < high: a tendon pinned at zero gets a sliver of room.
    hi = np.maximum(hi, lo + 1e-12)
    du = lsq_linear(jw, ew, bounds=(lo, hi)).x * _MM
    return du, np.asarray(jacobian, dtype=float) @ du


# --------------------------------------------------------------------------- the loop

@dataclass(frozen=True)
class ReachStep:
    """One iteration of `reach`: the error before the step [m, rad] and the change made."""

    error: np.ndarray
    delta: np.ndarray
    command: np.ndarray


@dataclass
class ReachResult:
    """Outcome of `reach`: reached (within precision), final error (6,), and the steps."""

    reached: bool
    error: np.ndarray
    observation: Any
    steps: list[ReachStep] = field(default_factory=list)


def reach(world: Any, observer: Callable[[], PoseObservation | None], pf: Any,
          target_position: np.ndarray, target_rotation: np.ndarray | None = None,
          controller: JacobianController | None = None,
          observation: PoseObservation | None = None,
          limit: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None) -> ReachResult:
    """Drive the POM to a target like a proportional controller (docs/METHOD.md 5).

    Each iteration: error from the latest camera pose; stop if within precision; Jacobian
    on the filter's VLR (Eq. 10); step (Eq. 11-12); apply it; observe; let the filter update
    the VLR with the new command and pose (`pf.step`).

    Args:
        world: moves the tendons: `apply(delta)` returning the commands or an object with
            `.commands` (`vlr.hand.Hand`, `vlr.synthetic.SyntheticWorld`).
        observer: returns the POM pose, or None when the tag is not seen.
        pf: the particle filter after identification (`vlr.filter.ParticleFilter`).
        target_position: (3,) [m]; target_rotation: (3, 3) or None.
        controller: the controller (default settings if None).
        observation: the latest pose, if the caller has one (else `observer()` is called).
        limit: optional (commands, delta) -> delta that keeps commands in a safe band.
    """
    ctl = controller or JacobianController()
    cfg = ctl.config
    obs = observation if observation is not None else observer()
    if obs is None:
        raise RuntimeError("the tag is not seen: no pose to control")
    u = np.asarray(pf.command, dtype=float).copy()
    steps: list[ReachStep] = []
    err = ctl.error(obs, target_position, target_rotation)
    for _ in range(cfg.max_steps):
        if ctl.done(err):
            break
        du = ctl.act(pf.motion, pf.state, u, obs, target_position, target_rotation)
        if limit is not None:
            du = limit(u, du)
        report = world.apply(du)
        u_new = np.asarray(getattr(report, "commands", report), dtype=float).copy()
        applied, u = u_new - u, u_new
        steps.append(ReachStep(err, applied, u))
        new = observer()
        if new is not None:
            ctl.learn(applied, observed_motion(obs, new))
        pf.step(u, new)
        obs = new if new is not None else obs
        err = ctl.error(obs, target_position, target_rotation)
    return ReachResult(reached=ctl.done(err), error=err, observation=obs, steps=steps)

