"""Observation model Lambda (Eq. 5): each particle's predicted POM pose and the likelihood of
an observed one.

The object frame O has its origin at the POM (spec.py), so a particle's POM pose is its object
pose (p, R), which the motion model's equilibrium keeps consistent with forward kinematics of
the VLR: contacts by the finger chains (Eq. 2), POM through the virtual links E^C to the
contacts (Eq. 1, 3; `pom_forward_kinematics` recomputes it that way for N >= 3).

Noise model: independent Gaussians on the position error [m] and on the rotation angle of
R_obs^T R_pred [rad]. The scales are perception accuracy (about 0.05 mm and 0.2 degree,
METHOD.md 8.2) plus model error; the defaults 0.5 mm and 1 degree are deliberately wider,
because a likelihood narrower than the model-world gap makes the filter confidently wrong
(trials in the sim with rolling contacts, whose gap is smaller, take 0.35 mm and 0.7 degree,
`vlr.trial.ROLLING_SIGMA`, or by default 0.2 mm and 0.4 degree with the turn term below,
`vlr.trial.ROLLING_TURN_SIGMA`).

Process noise that grows with the action's size (issue #5, model term (c)): the model-world
gap is a fraction of the motion an action causes (`vlr gap`'s per-action ratio), so with
`motion_fraction` kappa > 0 each particle's scales become
sigma^2 + (kappa * its predicted motion)^2, position and rotation alike, its motion being the
POM's displacement and rotation angle over the action. Since the scales then differ between
particles, the likelihood keeps its normalisation, -log sigma_pos - log sigma_rot: without
it, particles predicting large motions would be favoured for their wide tolerance.

The grasp's turn (issue #5, section 5 of RESULTS.md): `vlr gap` finds 94-99% of the model's
per-action pose error along one direction of the 6-D pose, the object turning in its grip
about the axis from the opposed finger's contact (the thumb) to the mean of the others'
contacts. With `sigma_turn` s > 0 the pose error e = (p_pred - p_obs, rotvec(R_pred R_obs^T))
is Gaussian with covariance

    Sigma = D + s^2 v v^T,  D = diag(sigma_pos^2 I_3, sigma_rot^2 I_3),
    v = (a x (p - q), a),

v the POM's motion per radian of turn about the unit axis a through the point q (each
particle's own contacts, `grasp_turn`). By Sherman-Morrison,

    e^T Sigma^-1 e = e^T D^-1 e - s^2 (v^T D^-1 e)^2 / (1 + s^2 v^T D^-1 v),
    log det Sigma = log det D + log(1 + s^2 v^T D^-1 v),

so the base scales can be narrow (the camera plus what is left off the turn) while a turn of
the size the model gets wrong costs little.

Tendon tensions (session 17): where the hand reads each tendon's tension T (N,) [N] beside
the pose (`TensionedObservation`; the sim's static tensions, `vlr.hand.ApplyReport`), with
`sigma_tension` s_T > 0 the likelihood multiplies by independent Gaussians on each tension,
-0.5 sum_i ((T_pred,i - T_i) / s_T)^2, T_pred the particle's own k_t max(0, u - s(theta))
(Eq. 7 compliant, `vlr.motion.MotionModel.tensions`). The tension is the springs' torque
through the pulleys, so it reads the joint angles directly, where the pose's information lies
mostly along the object's turn (docs/RESULTS.md 2, "What would converge in 15").

The model error's size (session 25): the scales above are set for the worst of the objects,
and a trial on an object the model gets right weighs its observations as loosely as one on
an object it gets wrong. With the "noise" unknown (`vlr.filter.parse_unknown`) each particle
carries a factor s on every pose scale (`ParticleState.noise`; the tension's scale is a
sensor's and keeps its own), the covariance becomes s^2 Sigma, and

    log p = -e^T Sigma^-1 e / (2 s^2) - 6 log s + (the terms above),

the normalisation -6 log s charging a wide tolerance for its width (the Occam factor of a
hierarchical noise scale). The filter then identifies the size of the model's error with
the rest of the particle: the posterior over s follows the residuals of the particles that
fit. A bias the other unknowns can absorb leaves small residuals and so is not seen by s;
that is the risk of a narrower likelihood, and why the trials measure coverage.

Heavy tails (session 38): `vlr gap`'s per-action errors are heavy-tailed (its medians a half to
a third of its means: a few actions that slip or roll where the model sticks carry most of
it), and a Gaussian wide enough for those is wider than the typical action needs. With
`dof` nu > 0 the pose's term is a multivariate Student t with the same scale matrix
(Sigma, or s^2 Sigma with the noise unknown),

    log p = -(nu + 6) / 2 log(1 + q / nu) + (the normalisations above),  q = e^T Sigma^-1 e,

the marginal of a Gaussian whose precision is Gamma(nu/2, nu/2)-distributed afresh on every
observation: an action the model gets badly wrong costs a particle log q, not q. nu -> inf
is the Gaussian; 0 keeps it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np
from scipy.spatial.transform import Rotation

from vlr.kinematics import HandModel, pom_from_contacts
from vlr.motion import ParticleState

# The pose error's dimensions (position and rotation, 3 each): a factor s on every pose scale
# multiplies the Gaussian's normalisation by s^-6.
POSE_DIMS = 6

__all__ = ["PoseObservation", "PomObservation", "TensionedObservation", "ObservationModel",
           "rotation_angle", "rotation_error", "grasp_turn", "pom_forward_kinematics"]


class PoseObservation(Protocol):
    """Anything with a POM `position` (3,) [m] and `rotation` (3, 3) in the palm frame, such as
    `vlr.perception.Observation`."""

    position: np.ndarray
    rotation: np.ndarray


@dataclass(frozen=True)
class PomObservation:
    """An observed POM pose in the palm frame: position (3,) [m], rotation (3, 3) R_PO."""

    position: np.ndarray
    rotation: np.ndarray


@dataclass(frozen=True)
class TensionedObservation:
    """An observed POM pose with the hand's tendon tensions read at the same rest: position
    (3,) [m], rotation (3, 3) R_PO, tensions (N,) [N] in the hand's finger order."""

    position: np.ndarray
    rotation: np.ndarray
    tensions: np.ndarray


def rotation_angle(r_a: np.ndarray, r_b: np.ndarray) -> np.ndarray:
    """Angle of R_a^T R_b [rad], batched over leading axes.

    Uses ||R_a - R_b||_F = 2 sqrt(2) sin(angle / 2), accurate for small angles (arccos of the
    trace is not)."""
    d = np.linalg.norm(np.asarray(r_a) - np.asarray(r_b), axis=(-2, -1))
    return 2.0 * np.arcsin(np.clip(d / (2.0 * np.sqrt(2.0)), 0.0, 1.0))


def rotation_error(r_pred: np.ndarray, r_obs: np.ndarray) -> np.ndarray:
    """Rotation vector [rad] of R_pred R_obs^T (the palm-frame turn from the observed to the
    predicted orientation), batched over leading axes: (..., 3)."""
    rel = np.einsum("...ab,...cb->...ac", np.asarray(r_pred), np.asarray(r_obs))
    shape = rel.shape[:-2]
    return Rotation.from_matrix(rel.reshape(-1, 3, 3)).as_rotvec().reshape(*shape, 3)


def grasp_turn(pos: np.ndarray, rot: np.ndarray, anchors: np.ndarray,
               opposed: int = 0) -> np.ndarray:
    """(P, 6) v: the POM's motion (position [m], rotation [rad]) per radian of the object
    turning in its grip (module docstring): about the unit axis a from the opposed finger's
    contact c_o to the mean of the other contacts, through c_o, v = (a x (p - c_o), a).

    Args:
        pos, rot: (P, 3), (P, 3, 3) POM poses.
        anchors: (P, N, 3) the contacts in the object frame (`ParticleState.anchors`).
        opposed: index of the finger that opposes the others (the thumb)."""
    pos = np.asarray(pos, dtype=float)
    c = pos[:, None, :] + np.einsum("pab,pnb->pna", rot, anchors)
    n = c.shape[1]
    if not 0 <= opposed < n or n < 3:
        raise ValueError(f"opposed finger {opposed!r}: needs 0 <= opposed < {n} and >= 3 "
                         "fingers")
    others = np.delete(c, opposed, axis=1).mean(axis=1)
    a = others - c[:, opposed]
    a /= np.linalg.norm(a, axis=-1, keepdims=True)
    return np.concatenate([np.cross(a, pos - c[:, opposed]), a], axis=-1)


def pom_forward_kinematics(model: HandModel,
                           state: ParticleState) -> tuple[np.ndarray, np.ndarray]:
    """POM pose by forward kinematics of the VLR (Eq. 1-3, 5): contacts from the joint angles,
    then the rigid fit of the anchors. Needs N >= 3 fingers."""
    return pom_from_contacts(state.contacts(model), state.anchors)


@dataclass(frozen=True)
class ObservationModel:
    """Lambda (Eq. 5) with a Gaussian pose-error likelihood.

    Attributes:
        sigma_pos: position noise scale [m] (perception ~5e-5 plus model error).
        sigma_rot: rotation-angle noise scale [rad] (perception ~0.0035 plus model error).
        motion_fraction: kappa, the model error as a fraction of each particle's predicted
            motion over the action (module docstring); 0 = fixed scales.
        sigma_turn: s, the model error of the object's turn in its grip [rad] (module
            docstring); 0 = no turn term.
        opposed: the finger opposing the others (the thumb's index), which sets the turn's
            axis.
        sigma_tension: s_T, the scale of each tendon tension's error [N] (module docstring);
            0 = tensions not weighed.
        dof: nu, the pose error's Student-t degrees of freedom (module docstring, "Heavy
            tails"); 0 = Gaussian.
    """

    sigma_pos: float = 0.5e-3
    sigma_rot: float = float(np.radians(1.0))
    motion_fraction: float = 0.0
    sigma_turn: float = 0.0
    opposed: int = 0
    sigma_tension: float = 0.0
    dof: float = 0.0

    def __post_init__(self) -> None:
        for name in ("sigma_pos", "sigma_rot"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} {getattr(self, name)!r} must be > 0")
        if not self.motion_fraction >= 0:
            raise ValueError(f"motion_fraction {self.motion_fraction!r} must be >= 0")
        if not (np.isfinite(self.sigma_turn) and self.sigma_turn >= 0):
            raise ValueError(f"sigma_turn {self.sigma_turn!r} must be >= 0")
        if not (np.isfinite(self.sigma_tension) and self.sigma_tension >= 0):
            raise ValueError(f"sigma_tension {self.sigma_tension!r} must be >= 0")
        if not (np.isfinite(self.dof) and self.dof >= 0):
            raise ValueError(f"dof {self.dof!r} must be >= 0 (0: Gaussian)")
        if self.sigma_turn > 0 and self.motion_fraction > 0:
            raise ValueError("sigma_turn and motion_fraction are two models of the same "
                             "error: set one")

    def predict(self, state: ParticleState) -> tuple[np.ndarray, np.ndarray]:
        """Predicted POM pose of every particle: position (P, 3), rotation (P, 3, 3)."""
        return state.pos, state.rot

    def errors(self, state: ParticleState,
               obs: PoseObservation) -> tuple[np.ndarray, np.ndarray]:
        """Position error [m] and rotation angle error [rad] of each particle, (P,) each."""
        pos, rot = self.predict(state)
        e_pos = np.linalg.norm(pos - np.asarray(obs.position)[None, :], axis=-1)
        e_rot = rotation_angle(rot, np.asarray(obs.rotation)[None, :, :])
        return e_pos, e_rot

    def log_likelihood(self, state: ParticleState, obs: PoseObservation,
                       motion: tuple[np.ndarray, np.ndarray] | None = None,
                       tensions: np.ndarray | None = None) -> np.ndarray:
        """log p(obs | particle) up to a constant (Eq. 5 with Gaussian noise), (P,);
        -inf for invalid particles, so a failed solve gets zero weight, never NaN.

        `motion`: each particle's predicted POM displacement [m] and rotation angle [rad]
        over the action, (P,) each; used when `motion_fraction` > 0 (module docstring).
        `tensions`: each particle's predicted tendon tensions [N], (P, N); weighed against
        the observation's when `sigma_tension` > 0 and it has them (module docstring).
        `state.noise` (P,), where the state has it: each particle's factor on the pose's
        scales (module docstring, "The model error's size")."""
        quad, log_norm = self._pose_terms(state, obs, motion)
        noise = getattr(state, "noise", None)
        if noise is None:
            ll = self._kernel(quad) + log_norm
        else:
            s = np.asarray(noise, dtype=float)
            ll = self._kernel(quad / (s * s)) + log_norm - POSE_DIMS * np.log(s)
        observed = getattr(obs, "tensions", None)
        if self.sigma_tension > 0 and tensions is not None and observed is not None:
            r = (np.asarray(tensions) - np.asarray(observed)[None, :]) / self.sigma_tension
            ll = ll - 0.5 * (r * r).sum(axis=-1)
        return np.where(state.valid & np.isfinite(ll), ll, -np.inf)

    def _kernel(self, quad: np.ndarray) -> np.ndarray:
        """The pose term's log density in its Mahalanobis square q: -q / 2 (Gaussian) or
        -(nu + 6) / 2 log(1 + q / nu) (Student t; module docstring, "Heavy tails")."""
        if self.dof > 0:
            return -0.5 * (self.dof + POSE_DIMS) * np.log1p(quad / self.dof)
        return -0.5 * quad

    def _pose_terms(self, state: ParticleState, obs: PoseObservation,
                    motion: tuple[np.ndarray, np.ndarray] | None
                    ) -> tuple[np.ndarray, np.ndarray | float]:
        """The pose's term of `log_likelihood` (Eq. 5) as its quadratic form and its log
        normalisation (relative to the configured scales): log p = -quad / 2 + log_norm."""
        if self.sigma_turn > 0:
            return self._turn_terms(state, obs)
        e_pos, e_rot = self.errors(state, obs)
        if self.motion_fraction > 0 and motion is not None:
            k = self.motion_fraction
            s_pos = np.sqrt(self.sigma_pos ** 2 + (k * np.asarray(motion[0])) ** 2)
            s_rot = np.sqrt(self.sigma_rot ** 2 + (k * np.asarray(motion[1])) ** 2)
            return ((e_pos / s_pos) ** 2 + (e_rot / s_rot) ** 2,
                    -np.log(s_pos / self.sigma_pos) - np.log(s_rot / self.sigma_rot))
        return (e_pos / self.sigma_pos) ** 2 + (e_rot / self.sigma_rot) ** 2, 0.0

    def _turn_terms(self, state: ParticleState,
                    obs: PoseObservation) -> tuple[np.ndarray, np.ndarray]:
        """Gaussian with the turn's covariance D + s^2 v v^T (module docstring), normalised
        against D alone: (quadratic form, log normalisation), (P,) each."""
        pos, rot = self.predict(state)
        # A failed solve's pose may be NaN or degenerate, which the rotation vector refuses;
        # its weight is -inf anyway (`log_likelihood`).
        ok = np.asarray(state.valid) & np.isfinite(rot).all(axis=(1, 2))
        rot = np.where(ok[:, None, None], rot, np.eye(3))
        e = np.concatenate([pos - np.asarray(obs.position)[None, :],
                            rotation_error(rot, np.asarray(obs.rotation)[None, :, :])], axis=-1)
        d_inv = np.repeat([self.sigma_pos ** -2, self.sigma_rot ** -2], 3)
        v = grasp_turn(pos, rot, state.anchors, self.opposed)
        s2 = self.sigma_turn ** 2
        vde = (v * d_inv * e).sum(axis=-1)
        g = 1.0 + s2 * (v * d_inv * v).sum(axis=-1)
        return (e * e * d_inv).sum(axis=-1) - s2 * vde ** 2 / g, -0.5 * np.log(g)
