"""The unscented Kalman filter over the particle filter's state (`filter.estimator: ukf`).

The same self-identification as `vlr.filter.ParticleFilter` (Algorithm 1), with a Gaussian
belief in place of the particles: filterpy's `UnscentedKalmanFilter` with van der Merwe's
scaled sigma points (`vlr.filter.UnscentedConfig`) over the same sampled dimensions (joint
angles, the two contact angles per pad, the unknowns; the springs on their logarithms, as the
particle filter jitters them). Its hypotheses are the 2D + 1 sigma points, D the dimensions.

One iteration:

* Gamma (Eq. 4, 9): the sigma points of the last posterior, each unpacked into a
  `ParticleState` anchored to the current estimate of the POM pose and settled at the
  previous command like a jittered particle (`GraspFilter._project`), are moved by the
  action in ONE batched solve (`MotionModel.solve(state, u, u_from=previous)`); the
  unscented transform of the moved sigma points is the prior (`UnscentedKalmanFilter.predict`
  with a process model that moves every sigma point at once).
* Lambda (Eq. 5): each moved sigma point's POM pose (p, R) is its predicted observation,
  a 6-vector (p, rotation vector of R). The residual composes rotations (the rotation
  vector of R_a R_b^T, the likelihood's `rotation_error`) and the mean of rotations is the
  weighted mean on the tangent space about the central sigma point (`pose_mean`). The
  measurement noise is the likelihood's own Gaussian: diag(sigma_pos^2 I, sigma_rot^2 I),
  plus sigma_turn^2 v v^T with the turn term (v at the central sigma point,
  `vlr.observation.grasp_turn`), plus sigma_tension^2 I on the tendon tensions when they
  are weighed. The update pairs each moved sigma point with its own predicted pose (filterpy
  draws the prior's sigma points again in `predict`: the pose is not a function of the
  state alone, it follows from the solve).
* The POM estimate the next sigma points are anchored to: the predicted pose mean corrected
  by the same gain, (S - R) S^-1 times the innovation (the predicted mean without a frame).

Bounds (docs/IDENTIFY.md): a sigma point beyond a joint stop is left to the model's stops,
the stiff springs of Eq. 9's limit term, as the particle filter's jittered particles are:
the settle brings it back to where its stop balances the grasp. Clipping the sigma points to
the stops and projecting the mean onto them was measured and is worse (docs/RESULTS.md):
the clipped sigma points move alike and the covariance collapses onto the stop. A sigma
point outside an unknown's prior is clipped to it (a spring or a length has no model beyond
it), and so is the posterior mean.

A sigma point whose solve fails takes its mirror partner's motion reflected about the
central one (x_0 + (x_0 - x_partner)); if both fail, that direction carries its spread
through the step unmoved and its pose is the central one's, so it learns nothing from the
observation; if the central one fails, the mean of the solved pairs stands in for it. If
every sigma point fails, the prior's covariance is drawn again at the current command, about
the last estimate's joints and contacts and the unknowns' priors (as the particle filter
draws its prior again), else about the grasp's prior.

What it cannot carry, refused in one line (`check_estimator`): a surface's curvature, whose
effect on the pose goes as its radius 1/kappa, unbounded at the prior's flat end and cut
off below `vlr.surface.FLAT_CURVATURE` (no Gaussian fits it); and active exploration, which
scores actions by the spread of sampled particles' predictions.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable

import numpy as np
from filterpy.kalman import MerweScaledSigmaPoints, UnscentedKalmanFilter
from scipy.linalg import LinAlgError, cholesky
from scipy.spatial.transform import Rotation

from vlr.active import noise_covariance
from vlr.errors import UserError
from vlr.filter import FilterConfig, GraspFilter, IterationRecord, Summary
from vlr.kinematics import HandModel
from vlr.model_check import nis_surprise
from vlr.motion import STATUS, ObjectParams, ParticleState
from vlr.observation import PoseObservation, grasp_turn
from vlr.unknowns import set_unknown

__all__ = ["CARRIED_KINDS", "Z95", "UnscentedFilter", "check_estimator", "check_carried",
           "pose_vector",
           "pose_residual", "pose_mean", "pose_add", "psd_sqrt"]

# The kinds of unknowns the UKF carries (`vlr.unknowns`); the springs and the tendon on
# their logarithms.
CARRIED_KINDS = ("stiffness", "tendon", "length", "mass", "com")
# A Gaussian's 97.5% quantile: its 95% interval is the mean +- Z95 standard deviations.
Z95 = 1.959963984540054
_OK = next(code for code, name in STATUS.items() if name == "ok")
# The floor of the covariance's eigenvalues (filter units: rad^2, m^2, log-units^2, kg^2).
_EIGEN_FLOOR = 1e-14


def check_estimator(config: FilterConfig, exploration: str = "random") -> None:
    """Refuse in one line what the chosen estimator cannot do (module docstring): the UKF
    with a curvature unknown, or with active exploration."""
    if config.estimator != "ukf":
        return
    check_carried(config.unknowns)
    if exploration == "active":
        raise UserError("loop.exploration active ranks actions by the spread of sampled "
                        "particles, and the ukf estimator has sigma points: use random, or "
                        "filter.estimator: pf")


def check_carried(unknowns: Iterable[str]) -> None:
    """Refuse in one line an unknown the UKF does not carry (`CARRIED_KINDS`)."""
    for spec in unknowns:
        kind = spec.partition(":")[0]
        if kind not in CARRIED_KINDS:
            raise UserError(f"filter.unknowns {spec!r}: the ukf estimator cannot carry a "
                            f"{kind} (its effect goes as 1/{kind}, unbounded at a flat "
                            "surface: no Gaussian fits it); use filter.estimator: pf")


# --------------------------------------------------------------------------- the pose chart

def pose_vector(pos: np.ndarray, rot: np.ndarray) -> np.ndarray:
    """(H, 6) POM poses as (position [m], rotation vector [rad]) rows."""
    rv = Rotation.from_matrix(np.asarray(rot, dtype=float).reshape(-1, 3, 3)).as_rotvec()
    return np.concatenate([np.asarray(pos, dtype=float).reshape(-1, 3), rv], axis=1)


def pose_residual(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a - b for pose rows (`pose_vector`, any further entries, e.g. tensions, plain): the
    position difference, the rotation vector of R_a R_b^T (palm frame, as
    `vlr.observation.rotation_error`), the rest's difference. filterpy's `residual_z`."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    out = a - b
    rel = Rotation.from_rotvec(a[..., 3:6]) * Rotation.from_rotvec(b[..., 3:6]).inv()
    out[..., 3:6] = rel.as_rotvec()
    return out


def pose_add(z: np.ndarray, dz: np.ndarray) -> np.ndarray:
    """z + dz for pose rows: the inverse of `pose_residual` (pose_add(b, a - b) = a)."""
    z, dz = np.asarray(z, dtype=float), np.asarray(dz, dtype=float)
    out = z + dz
    out[..., 3:6] = (Rotation.from_rotvec(dz[..., 3:6])
                     * Rotation.from_rotvec(z[..., 3:6])).as_rotvec()
    return out


def pose_mean(sigmas: np.ndarray, weights: np.ndarray, iterations: int = 5) -> np.ndarray:
    """The weighted mean of pose rows (`pose_vector`): positions and further entries by their
    weighted sum, the rotations by the weighted mean of their rotation vectors about the
    current mean, iterated from the first row's (the weights may be negative, as the scaled
    sigma points' central one is; they sum to 1). filterpy's `z_mean_fn`."""
    sigmas = np.asarray(sigmas, dtype=float)
    w = np.asarray(weights, dtype=float)
    mean = w @ sigmas
    mean[3:6] = sigmas[0, 3:6]
    for _ in range(iterations):
        step = w @ pose_residual(sigmas, mean[None])[:, 3:6]
        mean[3:6] = (Rotation.from_rotvec(step) * Rotation.from_rotvec(mean[3:6])).as_rotvec()
        if np.linalg.norm(step) < 1e-12:
            break
    return mean


def psd_sqrt(a: np.ndarray) -> np.ndarray:
    """U with U^T U = a, upper Cholesky (filterpy's sigma points take its rows); for a matrix
    that round-off or a negative central weight left indefinite, from its eigenvalues
    clipped at 0."""
    a = 0.5 * (a + a.T)
    try:
        return cholesky(a)
    except LinAlgError:
        w, v = np.linalg.eigh(a)
        return np.sqrt(np.maximum(w, 0.0))[:, None] * v.T


def _psd(p: np.ndarray) -> np.ndarray:
    """The covariance symmetrised, its eigenvalues floored (`_EIGEN_FLOOR`)."""
    p = 0.5 * (p + p.T)
    w, v = np.linalg.eigh(p)
    if w.min() >= _EIGEN_FLOOR:
        return p
    return (v * np.maximum(w, _EIGEN_FLOOR)) @ v.T


def _in_order(rows: np.ndarray) -> Callable[..., np.ndarray]:
    """filterpy's `hx`, which it calls once per sigma point in their order: the predicted
    observation each sigma point's own solve gave."""
    it: Iterable[np.ndarray] = iter(rows)
    return lambda *_: next(it)


class _BatchUKF(UnscentedKalmanFilter):
    """filterpy's UKF whose process model moves every sigma point in one call: `fx` takes
    the (2D + 1, D) sigma points and returns them moved (one batched solve of Eq. 9)."""

    def compute_process_sigmas(self, dt, fx=None, **fx_args):  # noqa: ARG002 (filterpy's)
        sigmas = self.points_fn.sigma_points(self.x, self.P)
        self.sigmas_f = np.asarray((fx or self.fx)(sigmas, **fx_args), dtype=float)


class _AllFailed(FloatingPointError):
    """No sigma point (and no pair of them) solved."""


# --------------------------------------------------------------------------- the filter

class UnscentedFilter(GraspFilter):
    """The unscented Kalman filter of the self-identification (module docstring).

    Args:
        model: the hand the user believes in.
        obj: the object believed (`vlr.motion.ObjectParams`).
        config: the filter's settings (`filter.ukf`; `particles`, `ess_fraction` and
            `jitter_h` unused).
        seed: unused: the filter draws nothing at random (the actions have their own seed).
    """

    def __init__(self, model: HandModel, obj: ObjectParams,
                 config: FilterConfig | None = None, seed: int = 0) -> None:
        super().__init__(model, obj, config, seed)
        check_carried(self.config.unknowns)
        c = self.config.ukf
        d = len(self.dim_names)
        if d + c.kappa <= 0:
            raise UserError(f"filter.ukf.kappa {c.kappa:g}: the sigma points need "
                            f"dimensions + kappa > 0, and there are {d} dimensions")
        self.points = MerweScaledSigmaPoints(d, c.alpha, c.beta, c.kappa, sqrt_method=psd_sqrt)
        self.kf = _BatchUKF(dim_x=d, dim_z=6, dt=1.0, hx=None, fx=None, points=self.points,
                            z_mean_fn=pose_mean, residual_z=pose_residual)
        n_th = model.n_fingers * model.n_joints
        q = np.zeros(d)
        q[:n_th] = np.radians(c.process_theta_deg) ** 2
        q[n_th:n_th + 2 * model.n_fingers] = np.radians(c.process_contact_deg) ** 2
        self.kf.Q = np.diag(q)
        self._log = self._spring_columns(d)
        self._lo, self._hi = self._bounds()
        self.pose: np.ndarray | None = None     # the POM estimate (`pose_vector` row)
        self._sigmas: np.ndarray | None = None  # the sigma points `self.state` holds
        self._residuals: np.ndarray | None = None  # the grasp's squeeze (contact stretch)
        self._prior_mean: np.ndarray | None = None
        self._prior_cov: np.ndarray | None = None

    # ---- coordinates and bounds

    def _to_filter(self, x: np.ndarray) -> np.ndarray:
        """Sampled dimensions -> the filter's coordinates (the springs' logarithms)."""
        y = np.array(x, dtype=float)
        with np.errstate(invalid="ignore", divide="ignore"):
            y[..., self._log] = np.log(y[..., self._log])
        return y

    def _from_filter(self, y: np.ndarray) -> np.ndarray:
        x = np.array(y, dtype=float)
        x[..., self._log] = np.exp(x[..., self._log])
        return x

    def _bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """(D,) lower and upper bounds in the filter's coordinates: each unknown's prior; none
        on the joints (the model's stops act, module docstring) or the contact angles."""
        n = len(self.dim_names) - len(self.unknowns)
        lo = np.concatenate([np.full(n, -np.inf), [u.prior[0] for u in self.unknowns]])
        hi = np.concatenate([np.full(n, np.inf), [u.prior[1] for u in self.unknowns]])
        return self._to_filter(lo), self._to_filter(hi)

    def _prior(self, observation: PoseObservation, nominal_theta: np.ndarray,
               nominal_contact: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The Gaussian prior in the filter's coordinates: the particle filter's prior's
        mean and variance per dimension (joint angles about the guess with
        `theta_spread`; contact angles about the pad's or the surface's contact of the
        guess with `contact_spread`; each unknown's uniform prior's mean and variance, of its
        logarithm for a spring)."""
        cfg, m = self.config, self.model
        mean_u, var_u = [], []
        for u in self.unknowns:
            lo, hi = u.prior
            if u.kind in ("stiffness", "tendon") and hi > lo:
                # log X for X uniform on [lo, hi]: E and E^2 from x ln x - x and
                # x (ln^2 x - 2 ln x + 2).
                m1 = (hi * np.log(hi) - hi - lo * np.log(lo) + lo) / (hi - lo)
                f = lambda x: x * (np.log(x) ** 2 - 2 * np.log(x) + 2)  # noqa: E731
                mean_u.append(m1)
                var_u.append((f(hi) - f(lo)) / (hi - lo) - m1 * m1)
            elif u.kind in ("stiffness", "tendon"):
                mean_u.append(np.log(lo))
                var_u.append(0.0)
            else:
                mean_u.append(0.5 * (lo + hi))
                var_u.append((hi - lo) ** 2 / 12.0)
        one = ParticleState.nominal(m, 1, nominal_theta, np.zeros((m.n_fingers, 3)) + [0, 1, 0],
                                    np.asarray(observation.position, dtype=float),
                                    np.asarray(observation.rotation, dtype=float))
        self._hold_object(one)
        n_fixed = len(self.dim_names) - len(self.unknowns)
        at_mean = self._from_filter(np.concatenate([np.zeros(n_fixed), mean_u]))[n_fixed:]
        for j, u in enumerate(self.unknowns):  # a length moves the pad the surface touches
            set_unknown(one, u, at_mean[j:j + 1])
        centre = self._contact_centre(one, nominal_contact)[0]
        mean = np.concatenate([np.ravel(nominal_theta), np.ravel(centre), mean_u])
        var = np.concatenate([np.full(m.n_fingers * m.n_joints, cfg.theta_spread ** 2),
                              np.full(2 * m.n_fingers, cfg.contact_spread ** 2), var_u])
        return mean, np.diag(np.maximum(var, _EIGEN_FLOOR))

    # ---- Algorithm 1

    def initialize(self, observation: PoseObservation, command: np.ndarray,
                   nominal_theta: np.ndarray, nominal_contact: np.ndarray) -> IterationRecord:
        """The Gaussian prior about the nominal grasp (`_prior`): its sigma points take the
        observed POM pose, derive their anchors from their own contacts and settle at u_0
        (as the particle filter's prior does); their unscented transform is weighed by the
        first observation.

        Args:
            observation: first POM pose (palm frame).
            command: u_0 (N,) [m].
            nominal_theta: (N, K) [rad]; nominal_contact: (N, 2) (alpha, beta) [rad].
        """
        self.command = np.asarray(command, dtype=float).copy()
        self._prior_mean, self._prior_cov = self._prior(observation, nominal_theta,
                                                        nominal_contact)
        try:
            return self._start(observation, self._prior_mean)
        except _AllFailed:
            raise FloatingPointError(
                f"none of the {self.points.num_sigmas()} sigma points of the prior settled at "
                "the grasp command: the nominal guess or its spread misses this grasp"
                ) from None

    def _start(self, observation: PoseObservation, mean: np.ndarray) -> IterationRecord:
        """The prior's covariance about `mean`, its sigma points settled at the current
        command from the observed pose (`initialize`, and a recovery), then the update.

        The contact angles' prior is one Gaussian about the guess's contacts: drawing each
        sigma point's about its own fingers' touch of the surface, as each particle's are,
        was measured no better (docs/RESULTS.md)."""
        self.kf.x, self.kf.P = mean.copy(), self._prior_cov.copy()
        self.pose = pose_vector(observation.position, observation.rotation)[0]
        self._residuals = None

        def settle(sigmas: np.ndarray) -> tuple[ParticleState, np.ndarray]:
            state = self._hypotheses(sigmas)
            status, _ = self.motion.solve(state, self.command, self._init_cfg)
            return state, status

        t0 = time.perf_counter()
        moved = self._predict(settle)
        self.timings = {"motion": time.perf_counter() - t0}
        return self._update(observation, moved)

    def step(self, command: np.ndarray, observation: PoseObservation | None) -> IterationRecord:
        """One iteration for the new absolute command u_t (N,) [m] (module docstring);
        `observation` None (the camera dropped the frame) makes it a prediction-only step."""
        if self.state is None:
            raise RuntimeError("initialize() first")
        previous = self.command
        self.command = np.asarray(command, dtype=float).copy()
        self.iteration += 1

        def act(sigmas: np.ndarray) -> tuple[ParticleState, np.ndarray]:
            if not np.array_equal(sigmas, self._sigmas):
                raise RuntimeError("the sigma points moved are not the ones settled")
            status, iters = self.motion.solve(self.state, self.command, u_from=previous)
            self.newton_iterations["action"] = float(np.median(iters))
            return self.state, status

        t0 = time.perf_counter()
        try:
            moved = self._predict(act)
        except _AllFailed:
            if observation is None:
                raise FloatingPointError("every sigma point failed to solve the action, "
                                         "and no observation came to start again from"
                                         ) from None
            return self._recover(observation)
        self.timings = {"motion": time.perf_counter() - t0}
        return self._update(observation, moved)

    def _recover(self, observation: PoseObservation) -> IterationRecord:
        """Every sigma point failed (module docstring): the prior's covariance drawn again at
        the current command and observation, about the last estimate's joints and contacts
        with the unknowns at their priors' centres (as the particle filter's prior is drawn
        again), else about the grasp's prior itself."""
        self.recoveries += 1
        n = len(self.dim_names) - len(self.unknowns)
        last = np.concatenate([self.kf.x[:n], self._prior_mean[n:]])
        for mean in (last, self._prior_mean):
            try:
                return self._start(observation, mean)
            except _AllFailed:
                continue
        raise FloatingPointError("every sigma point failed to settle, about the last estimate "
                                 "and about the grasp's prior: the hypotheses lost the grasp")

    def _hypotheses(self, sigmas: np.ndarray) -> ParticleState:
        """The sigma points (filter coordinates) as a `ParticleState`: the unknowns clipped to
        their priors, at the current POM estimate, anchors from their own contacts (with
        the grasp's squeeze where known: the last solved central sigma point's contact
        stretch)."""
        m = self.model
        x = self._from_filter(np.clip(sigmas, self._lo, self._hi))
        nf, nk = m.n_fingers, m.n_joints
        state = ParticleState.nominal(m, len(x), np.zeros((nf, nk)),
                                      np.zeros((nf, 3)) + [0, 1, 0], self.pose[:3],
                                      Rotation.from_rotvec(self.pose[3:6]).as_matrix())
        self.unpack(x, state)
        residuals = (None if self._residuals is None
                     else np.broadcast_to(self._residuals, (state.n, nf, 3)))
        state.anchor_to_pose(m, residuals)
        return state

    def _predict(self, move: Callable[[np.ndarray], tuple[ParticleState, np.ndarray]]
                 ) -> dict:
        """filterpy's predict with Gamma applied to every sigma point in one call (`move`:
        sigma points -> their moved `ParticleState` and solve status); returns the moved
        sigma points, their predicted observations and how many failed."""
        box: dict = {}

        def fx(sigmas: np.ndarray) -> np.ndarray:
            state, status = move(sigmas)
            y, z, failed = self._moved(sigmas, state, status)
            box.update(y=y, z=z, failed=failed, state=state)
            return y

        self.kf.predict(fx=fx)
        self.kf.P = _psd(self.kf.P)
        self.kf.sigmas_f = box["y"]  # each paired with its own predicted pose (module doc)
        return box

    def _moved(self, sigmas: np.ndarray, state: ParticleState,
               status: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
        """The moved sigma points in the filter's coordinates and their predicted
        observations (pose rows, then the tensions when weighed), failed ones filled in from
        their mirror partners (module docstring); and how many failed."""
        y = self._to_filter(self.pack(state))
        z = pose_vector(state.pos, state.rot)
        if self.obs_model.sigma_tension > 0:
            z = np.concatenate([z, self.motion.tensions(state, self.command)], axis=1)
        ok = ((np.asarray(status) == _OK) & state.valid & np.isfinite(y).all(axis=1)
              & np.isfinite(z).all(axis=1))
        failed = int((~ok).sum())
        if ok[0]:  # the grasp's squeeze the next sigma points keep (`_hypotheses`)
            self._residuals = state.contact_residuals(self.model)[0].copy()
        d = y.shape[1]
        partner = np.concatenate([[0], np.arange(d + 1, 2 * d + 1), np.arange(1, d + 1)])
        if not ok[0]:
            pairs = np.flatnonzero(ok[1:d + 1] & ok[d + 1:]) + 1
            if not len(pairs):
                raise _AllFailed("no sigma point pair solved")
            rows = np.concatenate([pairs, pairs + d])
            y[0] = y[rows].mean(axis=0)
            z[0] = pose_mean(z[rows], np.full(len(rows), 1.0 / len(rows)))
            ok[0] = True
        for k in np.flatnonzero(~ok):
            j = partner[k]
            if ok[j]:
                y[k] = 2 * y[0] - y[j]
                z[k] = pose_add(z[0], -pose_residual(z[j], z[0]))
            else:
                y[k] = y[0] + (sigmas[k] - sigmas[0])
                z[k] = z[0]
        return y, z, failed

    def _update(self, observation: PoseObservation | None, moved: dict) -> IterationRecord:
        """The Kalman update by the observation (Eq. 5's Gaussian as R), the POM estimate,
        the record; then the next sigma points, settled at the current command."""
        t = time.perf_counter()
        kf = self.kf
        kf.x = np.clip(kf.x, self._lo, self._hi)
        prior = self._summary(kf.x, kf.P)
        z_rows = moved["z"]
        w = self.points.Wm
        if observation is None:
            self.pose = pose_mean(z_rows[:, :6], w)
            rec = IterationRecord(self.iteration, self.command, prior, None, float("nan"),
                                  float("nan"), moved["failed"], self._ci(kf.P))
        else:
            z_obs = pose_vector(observation.position, observation.rotation)[0]
            tensions = getattr(observation, "tensions", None)
            weigh = self.obs_model.sigma_tension > 0 and tensions is not None
            if weigh:
                z_obs = np.concatenate([z_obs, np.asarray(tensions, dtype=float)])
            rows = z_rows if weigh else z_rows[:, :6]
            r = self._noise(moved["state"], weigh)
            kf.update(z_obs, R=r, hx=_in_order(rows))
            # The POM estimate: the predicted pose corrected by its own share of the gain.
            zp = pose_mean(rows, w)
            gain = np.linalg.solve(kf.S.T, (kf.S - r).T).T
            self.pose = pose_add(zp, gain @ kf.y)[:6]
            kf.x = np.clip(kf.x, self._lo, self._hi)
            kf.P = _psd(kf.P)
            post = self._summary(kf.x, kf.P)
            # The classical model check: the innovation's NIS against chi2(d)
            # (`vlr.model_check`).
            surprise = nis_surprise(float(kf.y @ kf.SI @ kf.y), len(kf.y))
            rec = IterationRecord(self.iteration, self.command, prior, post, float("nan"), 1.0,
                                  moved["failed"], self._ci(kf.P), surprise)
        self.timings["update"] = time.perf_counter() - t
        self.history.append(rec)
        self._redraw()
        return rec

    def _noise(self, state: ParticleState, tensions: bool) -> np.ndarray:
        """R: the likelihood's covariance (`vlr.active.noise_covariance`, Eq. 5's scales and
        the turn term at the central sigma point), the tensions' beside it."""
        obs = self.obs_model
        turn = None
        if obs.sigma_turn > 0:
            turn = grasp_turn(state.pos[:1], state.rot[:1], state.anchors[:1], obs.opposed)[0]
            if not np.isfinite(turn).all():
                turn = None
        r = noise_covariance(obs.sigma_pos, obs.sigma_rot, turn, obs.sigma_turn)
        if tensions:
            n = self.model.n_fingers
            r = np.block([[r, np.zeros((6, n))],
                          [np.zeros((n, 6)), obs.sigma_tension ** 2 * np.eye(n)]])
        return r

    def _redraw(self) -> None:
        """The posterior's sigma points at the POM estimate, settled at the current command
        (`GraspFilter._project`): the next action moves these."""
        sigmas = self.points.sigma_points(self.kf.x, self.kf.P)
        state = self._hypotheses(sigmas)
        t = time.perf_counter()
        self._project(state)
        self.timings["settle"] = time.perf_counter() - t
        self.state, self._sigmas = state, sigmas

    # ---- summaries

    def _summary(self, y: np.ndarray, p: np.ndarray) -> Summary:
        """Mean, median and 95% interval of the Gaussian (y, P), in SI units: a spring's
        log-normal median exp(mu), mean exp(mu + s^2 / 2) and interval exp(mu +- 1.96 s).
        An unknown's interval is cut at its prior's bounds (it has no mass beyond); a joint's
        is not (the stops are stiff springs, a joint on one sinks past it)."""
        sd = np.sqrt(np.maximum(np.diag(p), 0.0))
        low, high, mean = y - Z95 * sd, y + Z95 * sd, y.copy()
        mean[self._log] = y[self._log] + 0.5 * sd[self._log] ** 2
        u = slice(len(y) - len(self.unknowns), len(y))
        low[u], high[u] = np.maximum(low[u], self._lo[u]), np.minimum(high[u], self._hi[u])
        mean[u] = np.clip(mean[u], self._lo[u], self._hi[u])
        f = self._from_filter
        return Summary(mean=f(mean), low=f(low), high=f(high), median=f(y))

    def _ci(self, p: np.ndarray) -> float:
        """The convergence measure (docs/METHOD.md 3): the mean 95% interval width of the
        joint angles, 2 x 1.96 standard deviations [deg]."""
        n_th = self.model.n_fingers * self.model.n_joints
        sd = np.sqrt(np.maximum(np.diag(p)[:n_th], 0.0))
        return float(np.degrees(np.mean(2 * Z95 * sd)))

    def summarize(self, values: np.ndarray) -> Summary:
        """The unscented transform of a quantity of the sigma points (`self.state`): mean
        and standard deviation by the sigma points' weights, the 95% interval +- 1.96 sd."""
        v = np.asarray(values, dtype=float).reshape(len(values), -1)
        mean = self.points.Wm @ v
        sd = np.sqrt(np.maximum(self.points.Wc @ (v - mean) ** 2, 0.0))
        return Summary(mean=mean, low=mean - Z95 * sd, high=mean + Z95 * sd, median=mean)
