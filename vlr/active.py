"""Active exploration (METHOD.md 8.2; issue 5 item 4): among candidate tendon changes, take
the most informative one.

The paper explored with random actions. Two measures of an action's information, each
computed from the motion model's predictions (Eq. 9) on a random subset of the particles, so
that a choice costs `candidates` solves of `subset` particles:

* "spread": the hypotheses predict different outcomes: the particles' predicted POM poses,
  in units of the likelihood's scales (Eq. 5), spread the most. A cheap proxy for the
  expected information gain about every sampled dimension alike.
* "variance": the joint angles' expected posterior spread after the action is the smallest.
  The subset's predicted joint angles theta and POM poses y give, by the linear-Gaussian
  (ensemble Kalman) update, the posterior covariance C_tt - C_ty (C_yy + R)^-1 C_yt, R the
  likelihood's scales; the score is the mean of its standard deviations, the quantity the
  convergence measure (METHOD.md 3) is the 95% interval of. `vlr crb --candidates` showed
  that choosing among random candidates by that measure (with the truth known) halves the
  floor of the intervals on the apple, wine glass and toy block (docs/RESULTS.md 5).

With the likelihood's turn term (`ObservationModel.sigma_turn` s > 0) both measures use its
covariance R = D + s^2 v v^T, v the subset's mean turn direction (`vlr.observation.grasp_turn`):
an action whose outcomes differ only along the object's turn in its grip, where the model's
own error lies, is worth little; one that moves the pose off the turn is worth a lot. `vlr crb
--candidates 8 --sigma-turn 1.0` puts the floor of the intervals after 15 actions on the
apple at 1.96 degrees this way, against 4.43 for random actions (seeds 0-2; docs/RESULTS.md 5).

The most informative actions lie near a fold of the grasp, where a fingertip may leave the
object (the gelatin box's seed 0 loses its left fingertip to the first active action). With
`min_normal_force` > 0 (rolling contacts), a candidate after which some finger's predicted
normal force (`MotionModel.normal_forces`, median over the subset) falls under it is passed
over; if every candidate is, the one whose weakest finger keeps the most force is taken.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from vlr.explore import ExplorationRange, random_action
from vlr.observation import grasp_turn, rotation_error

__all__ = ["ActiveExploration", "CRITERIA", "noise_covariance", "prediction_spread",
           "expected_joint_sd", "choose_action"]

CRITERIA = ("spread", "variance")


@dataclass(frozen=True)
class ActiveExploration:
    """Settings of the active choice.

    Attributes:
        candidates: random candidate actions drawn per step (`vlr.explore.random_action`).
        subset: particles predicted per candidate.
        model_error: kappa, the model's expected error as a fraction of the motion a
            candidate causes; the spread is then measured against sigma^2 + (kappa x the
            subset's mean predicted POM motion)^2, so that a large action, whose outcome the
            model predicts worst, is not chosen for its size alone. 0 = the likelihood's
            fixed scales (the choice measured on the synthetic world).
        criterion: "spread" or "variance" (module docstring).
        min_normal_force: [N] pass over a candidate after which a finger's median predicted
            normal force falls under this (module docstring); 0 = no screen. Needs rolling
            contacts in the motion model.
    """

    candidates: int = 8
    subset: int = 256
    model_error: float = 0.0
    criterion: str = "spread"
    min_normal_force: float = 0.0

    def __post_init__(self) -> None:
        for name in ("candidates", "subset"):
            v = getattr(self, name)
            if not isinstance(v, int) or isinstance(v, bool) or v < 1:
                raise ValueError(f"active exploration {name} {v!r} must be an integer >= 1")
        if (isinstance(self.model_error, bool) or not isinstance(self.model_error, int | float)
                or not 0 <= self.model_error < 10):
            raise ValueError(f"active exploration model_error {self.model_error!r} must be a "
                             "number in [0, 10)")
        if (isinstance(self.min_normal_force, bool)
                or not isinstance(self.min_normal_force, int | float)
                or not 0 <= self.min_normal_force < 100):
            raise ValueError(f"active exploration min_normal_force {self.min_normal_force!r} "
                             "must be a number of newtons in [0, 100)")
        if self.criterion not in CRITERIA:
            raise ValueError(f"active exploration criterion {self.criterion!r}: expected one "
                             f"of {', '.join(CRITERIA)}")


def noise_covariance(sigma_pos: float, sigma_rot: float, turn: np.ndarray | None = None,
                     sigma_turn: float = 0.0) -> np.ndarray:
    """(6, 6) the likelihood's covariance of a POM pose error (position [m], rotation vector
    [rad]): D = diag(sigma_pos^2 I, sigma_rot^2 I) (Eq. 5), plus sigma_turn^2 v v^T with v
    (6,) the turn direction when the turn term is on (`vlr.observation`)."""
    r = np.diag([sigma_pos**2] * 3 + [sigma_rot**2] * 3)
    if sigma_turn > 0 and turn is not None:
        v = np.asarray(turn, dtype=float)
        r = r + sigma_turn**2 * np.outer(v, v)
    return r


def prediction_spread(pos: np.ndarray, rot: np.ndarray, sigma_pos: float,
                      sigma_rot: float, turn: np.ndarray | None = None,
                      sigma_turn: float = 0.0) -> float:
    """Spread of predicted POM poses in likelihood units, trace(R^-1 C_yy): with the fixed
    scales, the summed variance of the positions over sigma_pos^2 plus that of the rotation
    vectors about the first pose over sigma_rot^2 (Eq. 5's scales); R takes the turn term
    when `sigma_turn` > 0 (`noise_covariance`)."""
    if len(pos) < 2:
        return 0.0
    y = np.concatenate([pos, _rotvecs(rot)], axis=1)
    c_yy = np.cov(y, rowvar=False, bias=True)
    r = noise_covariance(sigma_pos, sigma_rot, turn, sigma_turn)
    return float(np.trace(np.linalg.solve(r, c_yy)))


def _rotvecs(rot: np.ndarray) -> np.ndarray:
    """Rotation vectors [rad] of R R_0^T for `rot` (P, 3, 3): the palm-frame turn from the
    first pose, the frame of the likelihood's rotation error (`rotation_error`)."""
    return rotation_error(rot, rot[:1])


def expected_joint_sd(theta: np.ndarray, pos: np.ndarray, rot: np.ndarray, sigma_pos: float,
                      sigma_rot: float, turn: np.ndarray | None = None,
                      sigma_turn: float = 0.0) -> float:
    """Mean over joints of the joint angles' posterior standard deviation [rad] once the POM
    pose is observed, by the ensemble's linear-Gaussian update (module docstring, "variance").

    theta (P, J) predicted joint angles [rad]; pos (P, 3) [m], rot (P, 3, 3) predicted POM
    poses; sigma_pos [m], sigma_rot [rad] the likelihood's scales; turn (6,) and sigma_turn
    [rad] its turn term (`noise_covariance`)."""
    n = len(pos)
    if n < 2:
        return float("inf")
    t = theta.reshape(n, -1)
    y = np.concatenate([pos, _rotvecs(rot)], axis=1)
    t = t - t.mean(axis=0)
    y = y - y.mean(axis=0)
    c_tt, c_ty, c_yy = (a.T @ b / (n - 1) for a, b in ((t, t), (t, y), (y, y)))
    r = noise_covariance(sigma_pos, sigma_rot, turn, sigma_turn)
    post = c_tt - c_ty @ np.linalg.solve(c_yy + r, c_ty.T)
    return float(np.sqrt(np.clip(np.diag(post), 0.0, None)).mean())


def choose_action(pf, rng: np.random.Generator, commands: np.ndarray, center: np.ndarray,
                  explore: ExplorationRange, settings: ActiveExploration) -> np.ndarray:
    """The candidate tendon change that is the most informative by `settings.criterion` over
    a random subset of the filter's valid particles (`pf`: a `vlr.filter.ParticleFilter`).
    Falls back to the first candidate when no particle is valid or every prediction fails."""
    cands = [random_action(rng, commands, center, explore) for _ in range(settings.candidates)]
    valid = np.flatnonzero(pf.state.valid)
    if len(valid) == 0:
        return cands[0]
    idx = rng.choice(valid, size=min(settings.subset, len(valid)), replace=False)
    base = pf.state.take(idx)
    obs = pf.config.observation
    screen = settings.min_normal_force > 0
    if screen and not pf.motion.config.rolling:
        raise ValueError("active exploration's min_normal_force needs rolling contacts")
    best, best_score = cands[0], -np.inf
    safest, safest_force = cands[0], -np.inf
    k = settings.model_error
    for delta in cands:
        st = base.copy()
        pf.motion.solve(st, commands + delta, u_from=commands)
        ok = st.valid
        if screen and ok.any():
            weakest = float(np.median(_normal_forces(pf, st)[ok], axis=0).min())
            if weakest > safest_force:
                safest, safest_force = delta, weakest
            if weakest < settings.min_normal_force:
                continue
        sp, sr = obs.sigma_pos, obs.sigma_rot
        if k > 0 and ok.any():
            moved = np.linalg.norm(st.pos[ok] - base.pos[ok], axis=-1).mean()
            turned = Rotation.from_matrix(np.einsum("pba,pbc->pac", base.rot[ok],
                                                    st.rot[ok])).magnitude().mean()
            sp, sr = np.hypot(sp, k * moved), np.hypot(sr, k * turned)
        turn = None
        if obs.sigma_turn > 0 and ok.any():
            turn = grasp_turn(st.pos[ok], st.rot[ok], st.anchors[ok], obs.opposed).mean(axis=0)
        if settings.criterion == "variance":
            score = -expected_joint_sd(st.theta[ok], st.pos[ok], st.rot[ok], sp, sr, turn,
                                       obs.sigma_turn)
        else:
            score = prediction_spread(st.pos[ok], st.rot[ok], sp, sr, turn, obs.sigma_turn)
        if score > best_score:
            best, best_score = delta, score
    if screen and best_score == -np.inf:
        return safest
    return best


def _normal_forces(pf, st) -> np.ndarray:
    """(P, N) each contact's predicted normal force [N] (`MotionModel.normal_forces`)."""
    from vlr.surface import surface_normals

    m = surface_normals(pf.model, st.theta, st.normals, st.rot)
    return pf.motion.normal_forces(st, pf.motion.rolling_frames(st, m))
