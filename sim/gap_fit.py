"""`vlr gap --fit UNKNOWN`: which value of an unknown does the motion model want, given the
simulator's TRUE states?

The filter identifies a parameter (a joint spring, a link length, the object's mass...) by
the motion it predicts (Eq. 4, 9). If the model itself, started at the sim's true
configuration, predicts the sim's motions best with another value than the truth, no
estimator can find the truth: the model leans. If it predicts them best at the truth, a
lean of the filter's estimate is the estimator's (its other unknowns, its prior, its
posterior's shape), not the model's.

The profile: each candidate value is one particle (vectorized), every particle at the true
state with only that parameter changed (contacts re-anchored to the true pose). Its cost is
the sum over actions of the squared motion errors in the likelihood's units (Eq. 12 without
the turn: position over `sigma_pos`, orientation over `sigma_rot`), or, with a turn scale
s > 0, minus twice the filter's own log-likelihood with the turn term (Eq. 12 with the
covariance D + s^2 v v^T and its normalisation, `vlr.observation.ObservationModel`), each
particle's predicted pose put where the true motion from its own start would take it:

* per action ("restart"): each action predicted from the true state before it, as
  `vlr gap`'s per-action ratio;
* open loop: all actions predicted in sequence from the first true state, each particle
  carrying its own state; each action's predicted motion against the true one (as the
  filter's particles, which never see the truth again).

A sim-only tool (it reads ground truth); the estimator never runs it.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from vlr.errors import UserError
from vlr.kinematics import HandModel
from vlr.motion import MotionModel, ParticleState
from vlr.observation import ObservationConfig, ObservationModel, PomObservation
from vlr.unknowns import hold_unknowns, parse_unknown, set_unknown, unknown_values

__all__ = ["likelihood_cost", "motion_errors", "profile_unknown"]


def _angles_deg(r: np.ndarray) -> np.ndarray:
    """(P,) rotation angles [deg] of (P, 3, 3) rotations."""
    c = (np.trace(r, axis1=1, axis2=2) - 1.0) / 2.0
    return np.degrees(np.arccos(np.clip(c, -1.0, 1.0)))


def motion_errors(p0: np.ndarray, r0: np.ndarray, p1: np.ndarray, r1: np.ndarray,
                  t0, t1) -> tuple[np.ndarray, np.ndarray]:
    """(P,) position [m] and orientation [deg] errors of the particles' predicted motions
    (p0, r0) -> (p1, r1) against the true one t0 -> t1 (`sim.gap._motion_error`, vectorized)."""
    dp_pred, dp_true = p1 - p0, t1.position - t0.position
    dr_pred = r1 @ np.swapaxes(r0, 1, 2)
    dr_true = t1.rotation @ t0.rotation.T
    return (np.linalg.norm(dp_pred - dp_true, axis=1),
            _angles_deg(dr_pred @ dr_true.T[None]))


def likelihood_cost(st: ParticleState, p0: np.ndarray, r0: np.ndarray, t0, t1,
                    obs_model: ObservationModel) -> np.ndarray:
    """(P,) minus twice the filter's log-likelihood (Eq. 12 with the turn term) of each
    particle's predicted motion (p0, r0) -> (st.pos, st.rot) against the true one t0 -> t1.

    The likelihood weighs a pose against one observed pose. Each particle is moved by the
    difference between the true start and its own (p0, r0), so that its error is its motion's
    error (as `motion_errors`) while the turn's axis comes from its own contacts."""
    shifted = st.copy()
    # R' = R1 R0^T R_t0: the particle's predicted rotation over the action, applied to the
    # true start; the anchors are in the object frame and follow the pose.
    shifted.rot = st.rot @ np.swapaxes(r0, 1, 2) @ t0.rotation[None]
    shifted.pos = st.pos - p0 + t0.position[None]
    obs = PomObservation(position=t1.position, rotation=t1.rotation)
    return -2.0 * obs_model.log_likelihood(shifted, obs)


def profile_unknown(rec, model: HandModel, motion: MotionModel, spec: str,
                    start: Callable[[ParticleState, int], None],
                    values: np.ndarray | None = None, points: int = 25,
                    sigma: tuple[float, float] = (0.2, 0.4), turn_deg: float = 0.0) -> dict:
    """The cost of each candidate value of unknown `spec` over the recording (module
    docstring).

    Args:
        rec: `sim.gap.Recording`.
        model, motion: the model's hand (the true one) and motion model.
        spec: an unknown as `vlr identify --unknown` takes it ("stiffness:thumb.distal").
        start: puts a state at the true configuration before action k+1 at command u_k
            (`sim.gap`'s start, in place).
        values: the candidates; None: `points` values across the unknown's default prior.
        sigma: the cost's units, position [mm] and orientation [deg].

    Returns:
        {"unknown", "truth", "values", "cost_restart", "cost_open_loop", "best_restart",
        "best_open_loop", "actions", "failed"}; "failed" counts candidates whose solve
        failed along the open-loop path (their cost is NaN); a best is NaN where the cost
        does not depend on the value (`_argmin`).
    """
    try:
        u = parse_unknown(spec, model, obj=motion.obj)
    except (KeyError, ValueError) as exc:
        raise UserError(f"--fit {spec!r}: {exc}") from None
    if values is None:
        if not (isinstance(points, int) and points >= 2):
            raise UserError(f"fit points {points!r} must be an integer >= 2")
        values = np.linspace(u.prior[0], u.prior[1], points)
    values = np.asarray(values, dtype=float)
    n = len(values)
    s_p, s_r = sigma
    obs_model = (ObservationModel(ObservationConfig(sigma_pos_mm=s_p, sigma_rot_deg=s_r,
                                                    sigma_turn_deg=turn_deg), model)
                 if turn_deg > 0 else None)

    def cost(st: ParticleState, p0, r0, t0, t1) -> np.ndarray:
        if obs_model is not None:
            return np.where(st.valid, likelihood_cost(st, p0, r0, t0, t1, obs_model), np.nan)
        e_p, e_r = motion_errors(p0, r0, st.pos, st.rot, t0, t1)
        return np.where(st.valid, (e_p * 1e3 / s_p) ** 2 + (e_r / s_r) ** 2, np.nan)

    def at_truth(k: int) -> ParticleState:
        st = ParticleState.at_truth(model, rec.truths[k]).take(np.zeros(n, dtype=int))
        if (u.kind in ("mass", "com") and st.object_mass is None) or (
                u.kind == "curvature" and st.surface_curvature is None):
            hold_unknowns(st, [u], motion.obj)
        set_unknown(st, u, values)
        st.anchor_to_pose(model)  # a changed length keeps the true pose, as jitter does
        return st

    truth = _true_value(rec, u, model, motion)
    cost_restart = np.zeros(n)
    for k in range(len(rec.commands) - 1):
        st = at_truth(k)
        start(st, k)
        p0, r0 = st.pos.copy(), st.rot.copy()
        motion.solve(st, rec.commands[k + 1], u_from=rec.commands[k])
        cost_restart += cost(st, p0, r0, rec.truths[k], rec.truths[k + 1])
    st = at_truth(0)
    start(st, 0)
    cost_open = np.zeros(n)
    for k in range(1, len(rec.commands)):
        pa, ra = st.pos.copy(), st.rot.copy()
        motion.solve(st, rec.commands[k], u_from=rec.commands[k - 1])
        # A particle whose solve failed stays NaN to the end (its cost is not comparable).
        cost_open += cost(st, pa, ra, rec.truths[k - 1], rec.truths[k])
    cost_open = np.where(st.valid, cost_open, np.nan)
    return {"unknown": spec, "truth": truth, "values": values.tolist(),
            "sigma_pos_mm": s_p, "sigma_rot_deg": s_r, "sigma_turn_deg": turn_deg,
            "cost_restart": cost_restart.tolist(), "cost_open_loop": cost_open.tolist(),
            "best_restart": _argmin(values, cost_restart),
            "best_open_loop": _argmin(values, cost_open),
            "actions": len(rec.commands) - 1, "failed": int((~st.valid).sum())}


def _true_value(rec, u, model: HandModel, motion: MotionModel) -> float:
    """The unknown's true value: the true hand's, or the object's from the sim's truth (else
    from its spec, as the model holds it)."""
    st = ParticleState.at_truth(model, rec.truths[0])
    if (u.kind in ("mass", "com") and st.object_mass is None) or (
            u.kind == "curvature" and st.surface_curvature is None):
        hold_unknowns(st, [u], motion.obj)
    return float(unknown_values(st, u)[0])


def _argmin(values: np.ndarray, cost: np.ndarray) -> float:
    """The value of least cost; NaN if none solved or the cost does not depend on the value
    (a rung without the term the unknown enters, e.g. the mass without the object's weight)."""
    ok = np.isfinite(cost)
    if not ok.any() or np.ptp(cost[ok]) <= 1e-9 * max(1.0, float(np.abs(cost[ok]).max())):
        return math.nan
    return float(values[ok][np.argmin(cost[ok])])
