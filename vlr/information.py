"""How much an identification run can know: the Bayesian Cramér-Rao bound of the filter's
own model along a command sequence (docs/METHOD.md 3, 8.2): the floor of the paper's
convergence measure.

The filter's state is the vector x of its sampled dimensions (`ParticleFilter.pack`: joint
angles, pad contact angles, unknowns). A particle takes the observed POM pose at the grasp,
settles at u_0 and is moved by every action (Eq. 4, 9); its predicted POM poses
y_t = Gamma/Lambda(x; u_0..u_t) (Eq. 5) are what the camera's poses weigh. With the
likelihood's Gaussian scales (sigma_pos, sigma_rot), the information about x after t
actions is

    J_t = P_0^-1 + sum_{s <= t} H_s^T R^-1 H_s,   H_s = dy_s / dx,
    R = diag(sigma_pos^2 I_3, sigma_rot^2 I_3),

P_0 the prior's covariance (the filter's spreads; a uniform unknown's variance). Where the
likelihood also weighs the tendon tensions (`ObservationModel.sigma_tension` s_T), each
observation adds G_s^T G_s / s_T^2, G_s = dT_s / dx the tensions' derivatives. With the
likelihood's turn term (`ObservationModel.sigma_turn`) R_s = R + s^2 v_s v_s^T, v_s the
grasp's turn at action s (`vlr.observation.grasp_turn`), and by Sherman-Morrison
H^T R_s^-1 H = H^T R^-1 H - s^2 w w^T / (1 + s^2 v^T R^-1 v), w = H^T R^-1 v. The mean
squared error of any estimate of the joint angles at t, over the observation noise, is at
least G_t J_t^-1 G_t^T, G_t = d theta_t / dx (van Trees' inequality, linearised at x), so a
posterior whose 95% intervals hold the truth as often as they claim is not narrower on
average than 3.92 of those standard deviations: the paper's convergence measure (docs/METHOD.md
3) has a floor that depends only on the model, the actions and the scales, not on the
particle count.

Derivatives are central differences over the filter's own motion model, batched as
particles (1 + 2D of them), each dimension stepped by `relative_step` of its prior
spread. J splits into a position part and a rotation part, so one run gives the bound at
every pair of scales (and, from the kept H_s and v_s, at every turn scale).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.spatial.transform import Rotation

from vlr.filter import ParticleFilter
from vlr.motion import STATUS, ParticleState
from vlr.observation import grasp_turn

__all__ = ["prior_std", "init_motion_config", "truth_vector", "InformationTrace", "Bound"]

WIDTH_95 = 2.0 * 1.959963984540054  # a Gaussian's 95% interval in standard deviations


def prior_std(pf: ParticleFilter) -> np.ndarray:
    """(D,) the filter's prior spread per sampled dimension (`ParticleFilter.initialize`):
    the joint angles' and the contact angles' Gaussian spreads, a uniform unknown's
    standard deviation (high - low) / sqrt(12)."""
    m, cfg = pf.model, pf.config
    s = [np.full(m.n_fingers * m.n_joints, cfg.theta_spread),
         np.full(2 * m.n_fingers, cfg.contact_spread)]
    s += [np.array([(u.prior[1] - u.prior[0]) / np.sqrt(12.0)]) for u in pf.unknowns]
    return np.concatenate(s)


def precise(motion):
    """`motion` (a `MotionConfig`) at tolerances fine enough for central differences: the
    filter's (`MotionConfig.tol_theta`) leave the end states a few micrometres off, which
    the likelihood cannot see but a difference of 2% of a prior spread can."""
    return replace(motion, tol_theta=min(motion.tol_theta, 1e-7),
                   tol_pos=min(motion.tol_pos, 1e-8))


def init_motion_config(pf: ParticleFilter):
    """The motion settings of the filter's settle at the grasp (`ParticleFilter.initialize`),
    `precise`."""
    c = pf.config
    return precise(replace(c.motion, jump_theta=c.init_jump_theta, jump_pos=0.05,
                           max_iter=max(c.motion.max_iter, 100)))


def truth_vector(pf: ParticleFilter, truth) -> np.ndarray:
    """(D,) the filter's sampled dimensions at a true state (`vlr.synthetic.Truth` or the
    sim's): joint angles, pad contacts and the unknowns' true values. For bounds only: the
    filter itself never sees it."""
    return pf.pack(ParticleState.at_truth(pf.model, truth))[0]


@dataclass(frozen=True)
class Bound:
    """The bound after some actions, at one pair of likelihood scales.

    Attributes:
        actions: actions taken (0: the grasp's observation only).
        joint_width_deg: (N*K,) narrowest 95% interval of each joint angle [deg].
        mean_width_deg: their mean: the floor of the paper's convergence measure.
        unknown_std: (U,) standard deviation bound of each unknown [SI units].
    """

    actions: int
    joint_width_deg: np.ndarray
    mean_width_deg: float
    unknown_std: np.ndarray


class InformationTrace:
    """The information about x accumulated along a command sequence (module docstring).

    Args:
        pf: the filter whose model, prior and unknowns are bounded (its particles unused).
        x: (D,) the linearisation point: the sampled dimensions at the grasp.
        position, rotation: the POM pose the particles take at the grasp [m], (3, 3).
        command: u_0 (N,) [m].
        relative_step: central-difference step as a fraction of each prior spread.
    """

    def __init__(self, pf: ParticleFilter, x: np.ndarray, position: np.ndarray,
                 rotation: np.ndarray, command: np.ndarray, relative_step: float = 0.02):
        if not 0 < relative_step < 1:
            raise ValueError(f"relative_step {relative_step!r} must be in (0, 1)")
        self.pf = pf
        self.x = np.asarray(x, dtype=float)
        self.scale = prior_std(pf)
        if self.x.shape != self.scale.shape:
            raise ValueError(f"x has {self.x.size} dimensions, the filter samples "
                             f"{self.scale.size} ({', '.join(pf.dim_names)})")
        self.step_size = relative_step
        d = self.x.size
        offsets = np.zeros((1 + 2 * d, d))
        offsets[1:d + 1] = np.eye(d) * relative_step
        offsets[d + 1:] = -np.eye(d) * relative_step
        m = pf.model
        st = ParticleState.nominal(m, 1 + 2 * d, np.zeros((m.n_fingers, m.n_joints)),
                                   np.zeros((m.n_fingers, 3)) + [0, 1, 0],
                                   np.asarray(position, float), np.asarray(rotation, float))
        pf.unpack(self.x[None] + offsets * self.scale[None], st)
        st.anchor_to_pose(m)
        status, _ = pf.motion.solve(st, np.asarray(command, float), init_motion_config(pf))
        self._check(st, status, "the grasp's settle")
        self.state = st
        self.command = np.asarray(command, float).copy()
        self.actions = 0
        # Information in prior-normalised coordinates v = (x - x0) / scale.
        self.info_pos = np.zeros((d, d))
        self.info_rot = np.zeros((d, d))
        # Each observation's H (6, D) and the grasp's turn v (6,) there, for the turn term.
        self.opposed = pf.obs_model.opposed
        self._jacobians: list[np.ndarray] = []
        self._turns: list[np.ndarray] = []
        self.info_tension = np.zeros((d, d))  # sum of G_s^T G_s (module docstring)
        self._add(st)

    @property
    def dims(self) -> int:
        return self.x.size

    def _check(self, st: ParticleState, status: np.ndarray, what: str) -> None:
        """A failed solve of one side of a difference leaves that dimension's one-sided
        difference (`_pairs`); the linearisation point's, or both sides', is an error."""
        d = self.dims
        both = ~st.valid[1:d + 1] & ~st.valid[d + 1:]
        if st.valid[0] and not both.any():
            return
        bad = [self.pf.dim_names[i] for i in np.flatnonzero(both)]
        codes = sorted({STATUS[int(c)] for c in status[~st.valid]})
        # Where the point itself fails, the model cannot follow the actions from this grasp,
        # and no step size helps.
        raise FloatingPointError(
            f"{what}: {int((~st.valid).sum())} of {st.n} solves failed ({', '.join(codes)})"
            + (" at the linearisation point itself: the model does not follow the actions "
               "from this grasp" if not st.valid[0] else
               f"; both steps of {', '.join(bad)}: try a smaller relative_step"))

    def _pairs(self, st: ParticleState) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Per dimension the particles (a, b) whose difference over `span` is its derivative:
        the central difference, or a one-sided one where a step's solve failed."""
        d, h = self.dims, self.step_size
        plus, minus = 1 + np.arange(d), 1 + d + np.arange(d)
        ok_p, ok_m = st.valid[plus], st.valid[minus]
        a = np.where(ok_p, plus, 0)
        b = np.where(ok_m, minus, 0)
        span = np.where(ok_p & ok_m, 2 * h, h)
        return a, b, span

    def pose_jacobian(self, st: ParticleState | None = None) -> tuple[np.ndarray, np.ndarray]:
        """dy/dv of the POM position [m] and rotation vector [rad], (3, D) each."""
        st = self.state if st is None else st
        a, b, span = self._pairs(st)
        jp = (st.pos[a] - st.pos[b]).T / span
        rel = np.einsum("pab,pcb->pac", st.rot[a], st.rot[b])
        jr = Rotation.from_matrix(rel).as_rotvec().T / span
        return jp, jr

    @property
    def one_sided(self) -> int:
        """Dimensions whose derivative is one-sided now (a step's solve failed)."""
        d = self.dims
        return int((self.state.valid[1:d + 1] != self.state.valid[d + 1:]).sum())

    def _observation(self, st: ParticleState,
                     command: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """H (6, D) of the POM pose at `st`, the grasp's turn v (6,) there, and G (N, D) of
        the tendon tensions at `command`."""
        jp, jr = self.pose_jacobian(st)
        v = grasp_turn(st.pos[:1], st.rot[:1], st.anchors[:1], self.opposed)[0]
        t = self.pf.motion.tensions(st, command)
        a, b, span = self._pairs(st)
        return np.vstack([jp, jr]), v, (t[a] - t[b]).T / span

    def _add(self, st: ParticleState) -> None:
        h, v, g = self._observation(st, self.command)
        self.info_pos += h[:3].T @ h[:3]
        self.info_rot += h[3:].T @ h[3:]
        self.info_tension += g.T @ g
        self._jacobians.append(h)
        self._turns.append(v)

    def _turn_information(self, h: np.ndarray, v: np.ndarray, sigma_pos: float,
                          sigma_rot: float, sigma_turn: float) -> np.ndarray:
        """What the turn term takes off the information of observations H (K, 6, D) with
        turns v (K, 6): sum_k s^2 w_k w_k^T / (1 + s^2 v_k^T R^-1 v_k) (module docstring)."""
        r_inv = np.repeat([sigma_pos ** -2, sigma_rot ** -2], 3)
        s2 = sigma_turn ** 2
        w = np.einsum("kad,ka->kd", h, v * r_inv)
        g = 1.0 + s2 * (v * v * r_inv).sum(axis=-1)
        return s2 * np.einsum("kd,ke,k->de", w, w, 1.0 / g)

    def output_jacobian(self, st: ParticleState | None = None) -> np.ndarray:
        """(N*K + U, D): d(theta_t, unknowns)/dv at the current state."""
        st = self.state if st is None else st
        d = self.dims
        a, b, span = self._pairs(st)
        th = st.theta.reshape(st.n, -1)
        g = (th[a] - th[b]).T / span
        u = len(self.pf.unknowns)
        gu = np.zeros((u, d))
        cols = d - u + np.arange(u)
        gu[np.arange(u), cols] = self.scale[cols]  # the unknowns do not move
        return np.vstack([g, gu])

    def act(self, command: np.ndarray) -> None:
        """Move the linearisation by one action to `command` and add its observation."""
        command = np.asarray(command, float)
        status, _ = self.pf.motion.solve(self.state, command, precise(self.pf.config.motion),
                                         u_from=self.command)
        self._check(self.state, status, f"action {self.actions + 1}")
        self.command = command.copy()
        self.actions += 1
        self._add(self.state)

    def bound(self, sigma_pos: float, sigma_rot: float,
              extra: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
              st: ParticleState | None = None, sigma_turn: float = 0.0,
              sigma_tension: float = 0.0) -> Bound:
        """The bound now at scales sigma_pos [m], sigma_rot [rad], the turn's sigma_turn
        [rad] and the tensions' sigma_tension [N] (0: tensions not observed; module
        docstring). `extra`, `st`: H (6, D), the turn v (6,) and the tensions' G (N, D) of a
        previewed action, and its state."""
        ip = self.info_pos if extra is None else self.info_pos + extra[0][:3].T @ extra[0][:3]
        ir = self.info_rot if extra is None else self.info_rot + extra[0][3:].T @ extra[0][3:]
        info = np.eye(self.dims) + ip / sigma_pos**2 + ir / sigma_rot**2
        if sigma_turn > 0:
            h, v = np.array(self._jacobians), np.array(self._turns)
            if extra is not None:
                h = np.concatenate([h, extra[0][None]])
                v = np.concatenate([v, extra[1][None]])
            info -= self._turn_information(h, v, sigma_pos, sigma_rot, sigma_turn)
        if sigma_tension > 0:
            it = self.info_tension if extra is None else self.info_tension + extra[2].T @ extra[2]
            info += it / sigma_tension**2
        g = self.output_jacobian(st)
        cov = g @ np.linalg.solve(info, g.T)
        sd = np.sqrt(np.maximum(np.diag(cov), 0.0))
        n_th = self.pf.model.n_fingers * self.pf.model.n_joints
        width = np.degrees(WIDTH_95 * sd[:n_th])
        return Bound(self.actions + (extra is not None), width, float(width.mean()),
                     sd[n_th:])

    def preview(self, command: np.ndarray, sigma_pos: float, sigma_rot: float,
                sigma_turn: float = 0.0, sigma_tension: float = 0.0) -> Bound | None:
        """The bound if the next action went to `command` (the trace unchanged); None if a
        solve failed."""
        st = self.state.copy()
        status, _ = self.pf.motion.solve(st, np.asarray(command, float),
                                         precise(self.pf.config.motion), u_from=self.command)
        try:
            self._check(st, status, "preview")
        except FloatingPointError:
            return None
        command = np.asarray(command, float)
        return self.bound(sigma_pos, sigma_rot, self._observation(st, command), st, sigma_turn,
                          sigma_tension)
