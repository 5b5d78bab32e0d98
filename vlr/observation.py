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
(trials in the sim with rolling contacts, whose gap is smaller, take 0.35 mm and 0.7 degree:
`vlr.trial.ROLLING_SIGMA`).

Process noise that grows with the action's size (issue #5, model term (c)): the model-world
gap is a fraction of the motion an action causes (`vlr gap`'s per-action ratio), so with
`motion_fraction` kappa > 0 each particle's scales become
sigma^2 + (kappa * its predicted motion)^2, position and rotation alike, its motion being the
POM's displacement and rotation angle over the action. Since the scales then differ between
particles, the likelihood keeps its normalisation, -log sigma_pos - log sigma_rot: without
it, particles predicting large motions would be favoured for their wide tolerance.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

from vlr.kinematics import HandModel, pom_from_contacts
from vlr.motion import ParticleState

__all__ = ["PoseObservation", "PomObservation", "ObservationModel", "rotation_angle",
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


def rotation_angle(r_a: np.ndarray, r_b: np.ndarray) -> np.ndarray:
    """Angle of R_a^T R_b [rad], batched over leading axes.

    Uses ||R_a - R_b||_F = 2 sqrt(2) sin(angle / 2), accurate for small angles (arccos of the
    trace is not)."""
    d = np.linalg.norm(np.asarray(r_a) - np.asarray(r_b), axis=(-2, -1))
    return 2.0 * np.arcsin(np.clip(d / (2.0 * np.sqrt(2.0)), 0.0, 1.0))


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
    """

    sigma_pos: float = 0.5e-3
    sigma_rot: float = float(np.radians(1.0))
    motion_fraction: float = 0.0

    def __post_init__(self) -> None:
        for name in ("sigma_pos", "sigma_rot"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} {getattr(self, name)!r} must be > 0")
        if not self.motion_fraction >= 0:
            raise ValueError(f"motion_fraction {self.motion_fraction!r} must be >= 0")

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
                       motion: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
        """log p(obs | particle) up to a constant (Eq. 5 with Gaussian noise), (P,);
        -inf for invalid particles, so a failed solve gets zero weight, never NaN.

        `motion`: each particle's predicted POM displacement [m] and rotation angle [rad]
        over the action, (P,) each; used when `motion_fraction` > 0 (module docstring)."""
        e_pos, e_rot = self.errors(state, obs)
        if self.motion_fraction > 0 and motion is not None:
            k = self.motion_fraction
            s_pos = np.sqrt(self.sigma_pos ** 2 + (k * np.asarray(motion[0])) ** 2)
            s_rot = np.sqrt(self.sigma_rot ** 2 + (k * np.asarray(motion[1])) ** 2)
            ll = (-0.5 * ((e_pos / s_pos) ** 2 + (e_rot / s_rot) ** 2)
                  - np.log(s_pos / self.sigma_pos) - np.log(s_rot / self.sigma_rot))
        else:
            ll = -0.5 * ((e_pos / self.sigma_pos) ** 2 + (e_rot / self.sigma_rot) ** 2)
        return np.where(state.valid & np.isfinite(ll), ll, -np.inf)
