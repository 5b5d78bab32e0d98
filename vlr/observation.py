"""Observation model Lambda (Eq. 5): each particle's predicted POM pose and the likelihood of
an observed one.

The object frame O has its origin at the POM (spec.py), so a particle's POM pose is its object
pose (p, R), which the motion model's equilibrium keeps consistent with forward kinematics of
the VLR: contacts by the finger chains (Eq. 2), POM through the virtual links E^C to the
contacts (Eq. 1, 3; `pom_forward_kinematics` recomputes it that way for N >= 3).

Noise model: independent Gaussians on the position error [m] and on the rotation of
R_pred R_obs^T [rad]. The scales are perception accuracy (about 0.05 mm and 0.2 degree,
docs/METHOD.md 8.2) plus model error: a likelihood narrower than the model-world gap makes
the filter confidently wrong. Each backend sets its own (`vlr.backends`; the measured
figures in docs/DECISIONS.md).

The grasp's turn: `vlr gap` finds nearly all of the model's per-action pose error along one
direction of the 6-D pose, the object turning in its grip about the axis from the opposed
finger's contact (the thumb) to the mean of the others' contacts. With `sigma_turn` s > 0
the pose error e = (p_pred - p_obs, rotvec(R_pred R_obs^T)) is Gaussian with covariance

    Sigma = D + s^2 v v^T,  D = diag(sigma_pos^2 I_3, sigma_rot^2 I_3),
    v = (a x (p - q), a),

v the POM's motion per radian of turn about the unit axis a through the point q (each
particle's own contacts, `grasp_turn`). By Sherman-Morrison,

    e^T Sigma^-1 e = e^T D^-1 e - s^2 (v^T D^-1 e)^2 / (1 + s^2 v^T D^-1 v),
    log det Sigma = log det D + log(1 + s^2 v^T D^-1 v),

so the base scales can be narrow (the camera plus what is left off the turn) while a turn of
the size the model gets wrong costs little.

Tendon tensions: where the hand reads each tendon's tension T (N,) [N] beside the pose
(`TensionedObservation`; the sim's static tensions, `vlr.hand.ApplyReport`), with
`sigma_tension` s_T > 0 the likelihood multiplies by independent Gaussians on each tension,
-0.5 sum_i ((T_pred,i - T_i) / s_T)^2, T_pred the particle's own k_t max(0, u - s(theta))
(Eq. 7 compliant, `vlr.motion.MotionModel.tensions`). The tension is the springs' torque
through the pulleys, so it reads the joint angles directly, where the pose's information lies
mostly along the object's turn.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

import numpy as np
from scipy.spatial.transform import Rotation

from vlr.kernels.likelihood import Observed, Scales, Terms, pose_terms
from vlr.kinematics import HandModel, pom_from_contacts
from vlr.motion import ParticleState

__all__ = ["PoseObservation", "PomObservation", "TensionedObservation", "ObservationConfig",
           "ObservationModel", "rotation_angle", "rotation_error", "grasp_turn",
           "pom_forward_kinematics"]


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
class ObservationConfig:
    """The likelihood's scales (Eq. 5; module docstring).

    Attributes:
        sigma_pos_mm: position noise scale [mm] (perception ~0.05 plus model error).
        sigma_rot_deg: rotation noise scale [deg] (perception ~0.2 plus model error).
        sigma_turn_deg: the model error of the object's turn in its grip [deg]; 0 = no turn
            term. Needs a finger named "thumb", the turn axis's start.
        sigma_tension_n: the scale of each tendon tension's error [N]; 0 = tensions not
            weighed (the hand must report them: the sim does, the real hand with a `tension`
            calibration, hardware/README.md).
    """

    sigma_pos_mm: float = 0.5
    sigma_rot_deg: float = 1.0
    sigma_turn_deg: float = 0.0
    sigma_tension_n: float = 0.0

    def __post_init__(self) -> None:
        for name in ("sigma_pos_mm", "sigma_rot_deg"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"{name} {v!r} must be > 0")
        for name in ("sigma_turn_deg", "sigma_tension_n"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise ValueError(f"{name} {v!r} must be >= 0 (0: off)")


class ObservationModel:
    """Lambda (Eq. 5) with the Gaussian pose likelihood of `config` (module docstring).

    Args:
        config: the scales.
        model: the hand; the turn term's axis runs from its finger named "thumb".
    """

    def __init__(self, config: ObservationConfig | None = None,
                 model: HandModel | None = None) -> None:
        self.config = config or ObservationConfig()
        c = self.config
        self.sigma_pos = c.sigma_pos_mm * 1e-3
        self.sigma_rot = float(np.radians(c.sigma_rot_deg))
        self.sigma_turn = math.radians(c.sigma_turn_deg)
        self.sigma_tension = float(c.sigma_tension_n)
        names = tuple(model.names) if model is not None else ("thumb",)
        # The finger opposing the others, the turn axis's start.
        self.opposed = names.index("thumb") if "thumb" in names else 0
        if self.sigma_turn > 0 and "thumb" not in names:
            raise ValueError(f"sigma_turn_deg {c.sigma_turn_deg:g}: the turn's axis runs from "
                             f"a finger named 'thumb'; the fingers are {list(names)}")

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
                       tensions: np.ndarray | None = None) -> np.ndarray:
        """log p(obs | particle) up to a constant (Eq. 5 with Gaussian noise), (P,);
        -inf for invalid particles, so a failed solve gets zero weight, never NaN.

        `tensions`: each particle's predicted tendon tensions [N], (P, N); weighed against
        the observation's when `sigma_tension` > 0 and it has them (module docstring)."""
        quad, log_norm = self._pose_terms(state, obs)
        ll = -0.5 * quad + log_norm
        observed = getattr(obs, "tensions", None)
        if self.sigma_tension > 0 and tensions is not None and observed is not None:
            r = (np.asarray(tensions) - np.asarray(observed)[None, :]) / self.sigma_tension
            ll = ll - 0.5 * (r * r).sum(axis=-1)
        return np.where(state.valid & np.isfinite(ll), ll, -np.inf)

    def _pose_terms(self, state: ParticleState,
                    obs: PoseObservation) -> tuple[np.ndarray, np.ndarray]:
        """The pose's term of `log_likelihood` (Eq. 5): with the turn, Gaussian with the
        turn's covariance D + s^2 v v^T (module docstring), normalised against D alone; as
        (quadratic form, log normalisation), (P,) each, log p = -quad / 2 + log_norm. One
        pass over the particles (`vlr.kernels.likelihood`); a failed solve's row or a pose
        not finite gets quad = inf."""
        pos, rot = self.predict(state)
        n, n_f = len(pos), state.anchors.shape[1]
        if self.sigma_turn > 0 and not (0 <= self.opposed < n_f and n_f >= 3):
            raise ValueError(f"the turn term's opposed finger {self.opposed}: needs "
                             f"0 <= opposed < {n_f} and >= 3 fingers")
        quad, log_norm = np.empty(n), np.empty(n)
        pose_terms(np.ascontiguousarray(pos, dtype=float), np.ascontiguousarray(rot, dtype=float),
                   np.ascontiguousarray(state.anchors, dtype=float),
                   np.ascontiguousarray(state.valid, dtype=np.bool_),
                   # copies: an observation's arrays may be read-only (the camera's), a
                   # type of its own to the kernel
                   Observed(np.array(obs.position, dtype=float).reshape(3),
                            np.array(obs.rotation, dtype=float).reshape(3, 3)),
                   Scales(np.array([self.sigma_pos ** -2, self.sigma_rot ** -2]),
                          float(self.sigma_turn ** 2), int(self.opposed)),
                   Terms(quad, log_norm))
        return quad, log_norm
