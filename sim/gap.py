"""The model-world gap, measured from the simulator's true state (docs/METHOD.md 8.1; the
command is `vlr gap`, sim/gap_cli.py).

The filter can only be as right as its motion model (Eq. 4, 9). This diagnostic starts the
model at the simulator's TRUE configuration (joint angles, contact points, object pose) and
the TRUE hand parameters, so that what remains is the model's own error:

* per action: the model's equilibrium at the command before the action and at the command
  after it give its predicted POM motion; its error against the simulator's motion, over the
  size of that motion, is the per-action gap ratio (position and orientation);
* static: the model's equilibrium at the current command against the simulator's
  configuration (joint angles, POM pose);
* open-loop drift: all actions predicted in sequence from the first true state, never
  refreshed; the tag's error at the end over the total true motion (`drift_ratio`), and
  the per-action ratios along that path (`open_loop_ratio_*`: the model carrying its own
  contact loads and places from action to action, as a filter's particle does);
* the turn (`turn`): each per-action error split into the object's turn about the grasp's
  axis (`vlr.observation.grasp_turn`) and the rest, position and orientation: the scales of
  the likelihood's `sigma_turn` and of its base;
* the tendon tensions (`tension`): the model's error on each action's tension change against
  the tensions the sim reports (`ApplyReport.tensions`), and at its settle on the true state:
  the scale of the likelihood's `sigma_tension`.

Where each prediction starts (`GapSettings.start`): "settle", the true configuration settled
at the command with glued contacts; or "sim-loads", the true
configuration with each contact's stretch set to the sim's own contact force on the object
(`sim.truth.pad_forces`), relaxed at the command. The sim's contacts carry loads from their
history (which side of its cone a contact sits on, how the squeeze between the side fingers
is shared) that no settle can know; "sim-loads" measures how much of the gap that is.

Each model term is switched on in turn (`LADDER`), so each one's share is a measured figure.
This is a sim-only tool (it reads ground truth); the estimator never runs it.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace

import numpy as np
from vlr.sim.gap_fit import profile_unknown
from vlr.sim.pads import FILTER_SLIDE_FRICTION, TORSION_FRICTION

from vlr.errors import UserError
from vlr.explore import ActionStream
from vlr.identify import LoopConfig
from vlr.kinematics import HandModel
from vlr.motion import (
    STATUS,
    MotionConfig,
    MotionModel,
    ObjectParams,
    ParticleState,
)
from vlr.observation import grasp_turn, rotation_error

__all__ = ["LADDER", "ladder_for", "filter_rung", "GapSettings", "record_actions", "measure_gap",
           "gap_report", "format_report", "OBJECTS"]

_BASE = ("springs", "tendon", "limits", "contacts")
_ALL = _BASE + ("link_gravity", "object_gravity")
# Model terms switched on in turn, each a setting of the one motion model (`vlr.motion.
# MotionConfig`): (name, energy terms, rolling contacts, the pads' sliding friction mu (None:
# none), their torsional friction mu_t [m]). The pads' coefficients are the sim's
# (`vlr.sim.pads`): known, like the pad's radius; the sliding's mu is the filter's, twice the
# sim's (`FILTER_SLIDE_FRICTION`), so that the last rung is the sim identification's model.
LADDER: tuple[tuple[str, tuple[str, ...], bool, float | None, float], ...] = (
    ("fixed contacts, no weights", _BASE, False, None, 0.0),
    ("+ link weights", _BASE + ("link_gravity",), False, None, 0.0),
    ("+ object weight", _ALL, False, None, 0.0),
    ("+ rolling", _ALL, True, None, 0.0),
    ("+ pad spin", _ALL, True, None, TORSION_FRICTION),
    ("+ sliding", _ALL, True, FILTER_SLIDE_FRICTION, TORSION_FRICTION),
)


def ladder_for(motion: MotionConfig) -> tuple:
    """`LADDER` with the pads' coefficients of `motion` where it has them: `vlr gap --set
    filter.motion.friction=1.5` measures the sliding rung at mu 1.5, so that the filter's
    rung (`filter_rung`) is the model the filter runs with those settings."""
    spin = motion.spin_friction if motion.spin_friction > 0 else TORSION_FRICTION
    rungs = []
    for name, terms, rolling, mu, mu_t in LADDER:
        if mu is not None:  # the sliding rung: the filter's own pads when it slides
            sliding = motion.friction is not None
            mu, mu_t = ((motion.friction, motion.spin_friction) if sliding
                        else (FILTER_SLIDE_FRICTION, spin))
        elif mu_t > 0:
            mu_t = spin
        rungs.append((name, terms, rolling, mu, mu_t))
    return tuple(rungs)


def filter_rung(motion: MotionConfig) -> str:
    """The rung that is the filter's own model: its contacts and the pads' friction."""
    if not motion.rolling:
        return "+ object weight"
    if motion.friction is not None:
        return "+ sliding"
    return "+ pad spin" if motion.spin_friction > 0 else "+ rolling"


OBJECTS = ("apple", "wine_glass", "toy_block", "flat_screwdriver", "gelatin_box")
STARTS = ("settle", "sim-loads")


@dataclass(frozen=True)
class GapSettings:
    """One gap measurement.

    Attributes:
        object, hand: spec names or files.
        seed: seeds the random actions (the same actions as `vlr identify --seed`).
        actions: random actions to make.
        drift_actions: actions predicted open loop for the drift (the first ones).
        loop: the loop's settings, whose exploratory actions these are (the action range
            and band; `vlr.explore.ActionStream`, the stream of `vlr identify`).
        motion: the model's settings (`vlr.motion.MotionConfig`; each rung switches its
            terms, rolling and friction); None: the sim identification's own (the sim
            backend's defaults, `vlr.settings.load_settings`).
        start: where each prediction starts (module docstring): "settle" or "sim-loads".
        ramp_time: how long the sim takes to make each command change [s]
            (`sim.backend.SimOptions.ramp_time`); None: the sim identification's own
            (`sim.backend.SimWorldOptions`).
        fit: an unknown ("stiffness:thumb.distal", as `vlr identify --unknown`) whose value
            the model wants is profiled on every rung (`sim.gap_fit`); None: no profile.
        fit_range: the profile's (low, high) [SI units]; None: the unknown's default prior.
        fit_points: the profile's values.
        fit_sigma: the profile cost's units, position [mm] and orientation [deg]: the sim
            trials' likelihood scales.
        fit_turn_deg: > 0: the profile's cost is the filter's likelihood with this turn
            scale [deg] (`sim.gap_fit.likelihood_cost`; the sim trials' is 1); 0: squared
            motion errors without the turn.
    """

    object: str = "apple"
    hand: str = "modelo"
    seed: int = 0
    actions: int = 30
    drift_actions: int = 15
    loop: LoopConfig = LoopConfig()
    motion: MotionConfig | None = None
    start: str = "settle"
    ramp_time: float | None = None
    fit: str | None = None
    fit_range: tuple[float, float] | None = None
    fit_points: int = 25
    fit_sigma: tuple[float, float] = (0.2, 0.4)
    fit_turn_deg: float = 0.0

    def __post_init__(self) -> None:
        if not isinstance(self.fit_points, int) or self.fit_points < 2:
            raise UserError(f"fit points {self.fit_points!r} must be an integer >= 2")
        if not (math.isfinite(self.fit_turn_deg) and self.fit_turn_deg >= 0):
            raise UserError(f"fit turn {self.fit_turn_deg!r} [deg] must be finite and >= 0")
        if self.fit_range is not None:
            lo, hi = self.fit_range
            if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
                raise UserError(f"fit range ({lo}, {hi}) must be finite with low < high")
        if self.motion is None:
            from vlr.settings import load_settings

            object.__setattr__(self, "motion",
                               load_settings({"world.backend": "sim"}).filter.motion)
        if self.ramp_time is None:
            from vlr.sim.backend import SimWorldOptions

            object.__setattr__(self, "ramp_time", SimWorldOptions.ramp_time)
        if (isinstance(self.ramp_time, bool) or not isinstance(self.ramp_time, int | float)
                or not (math.isfinite(self.ramp_time) and 0 < self.ramp_time <= 2.0)):
            raise UserError(f"ramp time {self.ramp_time!r} s must be in (0, 2]")
        if self.start not in STARTS:
            raise UserError(f"start {self.start!r}: expected one of {', '.join(STARTS)}")
        if not isinstance(self.actions, int) or self.actions < 1:
            raise UserError(f"actions {self.actions!r} must be an integer >= 1")
        if not isinstance(self.drift_actions, int) or self.drift_actions < 1:
            raise UserError(f"drift actions {self.drift_actions!r} must be an integer >= 1")


@dataclass(frozen=True)
class Recording:
    """What the simulator did: commands u_0..u_n [m], the true state after each
    (`vlr.synthetic.Truth`, from `SimHand.scoring_truth`) and the tendon tensions it reported
    (`ApplyReport.tensions`) [N], and each finger's contact force on the object after each
    (`sim.truth.pad_forces`, palm frame) [N]."""

    hand_spec: object
    object_spec: object
    commands: list[np.ndarray]
    truths: list
    dropped_at: int | None
    tensions: list[np.ndarray] = field(default_factory=list)
    forces: list[np.ndarray] = field(default_factory=list)


def record_actions(settings: GapSettings) -> Recording:
    """Grasp in the simulator and make the random actions, recording the truth after each.

    Stops early if the fingertip grasp is lost (`dropped_at`: the action that lost it)."""
    from vlr.sim.backend import SimHand, SimOptions
    from vlr.sim.truth import pad_forces

    options = SimOptions(ramp_time=settings.ramp_time)
    with SimHand(object=settings.object, hand=settings.hand, seed=settings.seed,
                 options=options) as hand:
        grasp = hand.grasp()
        commands, tensions = [grasp.commands], [grasp.tensions]
        truths, forces = [hand.scoring_truth()], [pad_forces(hand)]
        actions = ActionStream.of_trial(settings.loop, settings.seed, commands[0])
        dropped = None
        for k in range(1, settings.actions + 1):
            report = hand.apply(actions.random(commands[-1]))
            t = hand.scoring_truth()
            if not report.grasp_held or not np.isfinite(t.normals).all():
                dropped = k
                break
            commands.append(report.commands)
            tensions.append(report.tensions)
            truths.append(t)
            forces.append(pad_forces(hand))
        return Recording(hand.true_spec, hand.object_spec, commands, truths, dropped, tensions,
                         forces)


def _state(model: HandModel, truth) -> ParticleState:
    """One particle at the true configuration (`ParticleState.at_truth`)."""
    return ParticleState.at_truth(model, truth)


def _start(motion: MotionModel, settle: MotionConfig, model: HandModel, rec: Recording,
           k: int, start: str) -> ParticleState:
    """The model's state before action k+1 (`GapSettings.start`): the true configuration
    settled at u_k with glued contacts, or with each contact's stretch the sim's contact
    force, relaxed at u_k (the command change's first step with no change)."""
    st = _state(model, rec.truths[k])
    _settle_at(motion, settle, model, rec, st, k, start)
    return st


def _settle_at(motion: MotionModel, settle: MotionConfig, model: HandModel, rec: Recording,
               st: ParticleState, k: int, start: str) -> None:
    """`_start` on states already at the true configuration before action k+1 (in place)."""
    if start == "sim-loads":
        # The penalty's stretch times k_c is the force on the pad: minus the pad's on the object.
        st.anchor_to_pose(model, np.broadcast_to(
            -rec.forces[k] / motion.config.contact_stiffness, (st.n, *rec.forces[k].shape)))
        motion.solve(st, rec.commands[k], u_from=rec.commands[k])
    else:
        motion.solve(st, rec.commands[k], settle)


def _angle_deg(r: np.ndarray) -> float:
    c = (np.trace(r) - 1.0) / 2.0
    return math.degrees(math.acos(min(1.0, max(-1.0, c))))


def _pose(st: ParticleState) -> tuple[np.ndarray, np.ndarray]:
    return st.pos[0].copy(), st.rot[0].copy()


def _motion_error(p0, r0, p1, r1, t0, t1) -> tuple[float, float, float, float]:
    """Predicted motion (p0, r0) -> (p1, r1) against the true one t0 -> t1: position error
    [m], orientation error [deg], true position motion [m], true rotation [deg]."""
    dp_pred, dp_true = p1 - p0, t1.position - t0.position
    dr_pred, dr_true = r1 @ r0.T, t1.rotation @ t0.rotation.T
    return (float(np.linalg.norm(dp_pred - dp_true)), _angle_deg(dr_pred @ dr_true.T),
            float(np.linalg.norm(dp_true)), _angle_deg(dr_true))


def _turn_split(v: np.ndarray, p0, r0, p1, r1, t0, t1) -> tuple[float, float, float]:
    """The error of a predicted motion split along the grasp's turn v (6,) [m/rad, rad/rad]
    (module docstring): the turn's error [deg] and what is left, position [mm] and
    orientation [deg]."""
    e_p = (p1 - p0) - (t1.position - t0.position)
    e_r = rotation_error((r1 @ r0.T) @ (t1.rotation @ t0.rotation.T).T, np.eye(3))
    turn = float(e_r @ v[3:])
    return (math.degrees(turn), float(np.linalg.norm(e_p - turn * v[:3])) * 1e3,
            math.degrees(float(np.linalg.norm(e_r - turn * v[3:]))))


def _tension_errors(rec: Recording, k: int, before: np.ndarray, after: np.ndarray) -> dict:
    """The model's tendon tensions against the sim's over action k+1 (RMS over the fingers,
    [N]): the error on their change, the sim's change, and the error of the model's tensions
    at its settle on the true state (NaN without a recording of tensions)."""
    if len(rec.tensions) <= k + 1 or rec.tensions[k] is None or rec.tensions[k + 1] is None:
        return dict.fromkeys(("tension_change_error_n", "tension_change_n",
                              "tension_static_error_n"), math.nan)
    change = rec.tensions[k + 1] - rec.tensions[k]
    return {"tension_change_error_n": _rms((after - before) - change),
            "tension_change_n": _rms(change),
            "tension_static_error_n": _rms(before - rec.tensions[k])}


def _rms(values) -> float:
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    return float(np.sqrt(np.mean(v ** 2))) if v.size else math.nan


def _turn_summary(rows: list[dict]) -> dict:
    """RMS over the actions of the per-action errors and of their split (`_turn_split`)."""
    def rms(key: str) -> float:
        v = np.array([r[key] for r in rows], dtype=float)
        return float(np.sqrt(np.mean(v ** 2))) if v.size else math.nan

    return {"turn_error_deg_rms": rms("turn_error_deg"),
            "rest_position_mm_rms": rms("rest_position_mm"),
            "rest_orientation_deg_rms": rms("rest_orientation_deg"),
            "position_mm_rms": rms("error_position_mm"),
            "orientation_deg_rms": rms("error_orientation_deg")}


def measure_gap(rec: Recording, terms: tuple[str, ...], settings: GapSettings,
                rolling: bool = True, friction: float | None = None,
                spin_friction: float = 0.0) -> dict:
    """Per-action, static and drift gap of the motion model with `terms`, rolling or pinned
    contacts, the pads' sliding friction mu `friction` (None: none) and torsional friction
    mu_t `spin_friction` [m] (module docstring). The settles to the true states are
    frictionless (the model's own equilibrium there): the pads' friction acts over the
    actions measured."""
    model = HandModel.from_spec(rec.hand_spec)
    obj = ObjectParams.from_spec(rec.object_spec)
    # The turn's axis runs from the thumb (`vlr.observation.grasp_turn`), as the filter's
    # turn term does; a hand without one has no turn split (NaN), not another finger's.
    thumb = model.finger_index("thumb") if "thumb" in model.names else None
    cfg = replace(settings.motion, terms=terms, rolling=rolling, friction=friction,
                  spin_friction=spin_friction)
    motion = MotionModel(model, obj, cfg)
    # The static settle may travel further than an action may (the model's own equilibrium).
    settle = replace(cfg, jump_theta=1.0, jump_pos=0.05, max_iter=200, friction=None,
                     spin_friction=0.0)
    rows, static = [], []
    for k in range(len(rec.commands) - 1):
        t0, t1 = rec.truths[k], rec.truths[k + 1]
        st = _start(motion, settle, model, rec, k, settings.start)
        p0, r0 = _pose(st)
        t_model0 = motion.tensions(st, rec.commands[k])[0]
        v = (grasp_turn(st.pos, st.rot, st.anchors, thumb)[0] if thumb is not None
             else np.full(6, math.nan))
        static.append((float(np.linalg.norm(p0 - t0.position)),
                       _angle_deg(r0 @ t0.rotation.T),
                       float(np.degrees(np.abs(st.theta[0] - t0.theta)).mean())))
        status, iters = motion.solve(st, rec.commands[k + 1], u_from=rec.commands[k])
        ok = bool(st.valid[0])
        p1, r1 = _pose(st)
        e_p, e_r, m_p, m_r = _motion_error(p0, r0, p1, r1, t0, t1)
        tension = _tension_errors(rec, k, t_model0, motion.tensions(st, rec.commands[k + 1])[0])
        turn, rest_p, rest_r = _turn_split(v, p0, r0, p1, r1, t0, t1)
        rows.append({"action": k + 1, "ok": ok, "status": STATUS[int(status[0])],
                     "newton_iterations": int(iters[0]), "error_position_mm": e_p * 1e3,
                     "error_orientation_deg": e_r, "turn_error_deg": turn,
                     "rest_position_mm": rest_p, "rest_orientation_deg": rest_r,
                     "motion_position_mm": m_p * 1e3,
                     "motion_orientation_deg": m_r,
                     "ratio_position": e_p / m_p if m_p > 0 else math.nan,
                     "ratio_orientation": e_r / m_r if m_r > 0 else math.nan, **tension})
    ok_rows = [r for r in rows if r["ok"]]

    def stat(key: str, fn) -> float:
        v = [r[key] for r in ok_rows if np.isfinite(r[key])]
        return float(fn(v)) if v else math.nan

    drift = _drift(motion, settle, model, rec, settings.drift_actions, settings.start)
    s = np.array(static) if static else np.full((1, 3), math.nan)
    fit = {}
    if settings.fit:
        values = (None if settings.fit_range is None
                  else np.linspace(*settings.fit_range, settings.fit_points))
        fit = {"fit": profile_unknown(
            rec, model, motion, settings.fit,
            lambda st, k: _settle_at(motion, settle, model, rec, st, k, settings.start),
            values, settings.fit_points, settings.fit_sigma, settings.fit_turn_deg)}
    return {
        "terms": list(terms),
        "actions": len(rows),
        "failed_solves": len(rows) - len(ok_rows),
        "ratio_position_mean": stat("ratio_position", np.mean),
        "ratio_position_median": stat("ratio_position", np.median),
        "ratio_orientation_mean": stat("ratio_orientation", np.mean),
        "ratio_orientation_median": stat("ratio_orientation", np.median),
        "error_position_mm_mean": stat("error_position_mm", np.mean),
        "error_orientation_deg_mean": stat("error_orientation_deg", np.mean),
        **drift,
        "turn": _turn_summary(ok_rows),
        "tension": {key: _rms([r[key] for r in ok_rows])
                    for key in ("tension_change_error_n", "tension_change_n",
                                "tension_static_error_n")},
        "static": {"position_mm_mean": float(s[:, 0].mean() * 1e3),
                   "orientation_deg_mean": float(s[:, 1].mean()),
                   "joint_deg_mean": float(s[:, 2].mean())},
        "per_action": rows,
        **fit,
    }


def _drift(motion: MotionModel, settle: MotionConfig, model: HandModel, rec: Recording,
           n: int, start: str = "settle") -> dict:
    """Open-loop prediction of the first `n` actions from the first true state.

    Besides the drift, the per-action gap along that path (`open_loop_ratio_*`): each
    predicted action's motion against the true one, the model carrying its own state (its
    contacts' loads and places) from action to action as a filter's particle does, where
    the per-action gap restarts every action from the truth re-settled with glued contacts."""
    n = min(n, len(rec.commands) - 1)
    st = _start(motion, settle, model, rec, 0, start)
    p0, r0 = _pose(st)
    total_p = total_r = 0.0
    ratios = []
    for k in range(1, n + 1):
        pa, ra = _pose(st)
        motion.solve(st, rec.commands[k], u_from=rec.commands[k - 1])
        a, b = rec.truths[k - 1], rec.truths[k]
        total_p += float(np.linalg.norm(b.position - a.position))
        total_r += _angle_deg(b.rotation @ a.rotation.T)
        if st.valid[0]:
            pb, rb = _pose(st)
            e_p, e_r, m_p, m_r = _motion_error(pa, ra, pb, rb, a, b)
            ratios.append((e_p / m_p if m_p > 0 else math.nan,
                           e_r / m_r if m_r > 0 else math.nan))
    if n == 0 or not st.valid[0]:
        return {"drift_actions": n, "drift_ratio": math.nan,
                "drift_ratio_orientation": math.nan}
    p1, r1 = _pose(st)
    e_p, e_r, _, _ = _motion_error(p0, r0, p1, r1, rec.truths[0], rec.truths[n])
    r = np.array(ratios)
    return {"drift_actions": n, "drift_ratio": e_p / total_p if total_p > 0 else math.nan,
            "drift_ratio_orientation": e_r / total_r if total_r > 0 else math.nan,
            "drift_position_mm": e_p * 1e3, "drift_orientation_deg": e_r,
            "open_loop_ratio_position_mean": float(np.nanmean(r[:, 0])),
            "open_loop_ratio_orientation_mean": float(np.nanmean(r[:, 1])),
            "open_loop_ratio_orientation_median": float(np.nanmedian(r[:, 1]))}


def gap_report(settings: GapSettings, ladder: tuple | None = None) -> dict:
    """Record the actions once, then measure every rung of `ladder` (default: `ladder_for`
    the settings' model) on them. The top-level ratios are the filter's model's
    (`filter_rung`), else the last rung's."""
    ladder = ladder_for(settings.motion) if ladder is None else ladder
    t0 = time.perf_counter()
    if settings.fit:
        check_fit(settings)
    rec = record_actions(settings)
    if len(rec.commands) < 2:
        raise UserError(f"{settings.object}: the grasp was lost at the first action; "
                        "nothing to measure")
    configs = [{"name": name, "friction": friction, "spin_friction": spin,
                **measure_gap(rec, terms, settings, rolling, friction, spin)}
               for name, terms, rolling, friction, spin in ladder]
    full = next((c for c in configs if c["name"] == filter_rung(settings.motion)),
                configs[-1])
    true_p = [np.linalg.norm(b.position - a.position) * 1e3
              for a, b in zip(rec.truths, rec.truths[1:], strict=False)]
    true_r = [_angle_deg(b.rotation @ a.rotation.T)
              for a, b in zip(rec.truths, rec.truths[1:], strict=False)]
    return {
        "object": settings.object, "hand": settings.hand, "seed": settings.seed,
        "actions": len(rec.commands) - 1, "grasp_lost_at": rec.dropped_at,
        "motion": {k: v for k, v in vars(settings.motion).items() if k != "terms"},
        "filter_rung": filter_rung(settings.motion),
        "start": settings.start,
        "ramp_time": settings.ramp_time,
        "true_motion": {"position_mm_mean": float(np.mean(true_p)),
                        "orientation_deg_mean": float(np.mean(true_r))},
        "ratio_position_mean": full["ratio_position_mean"],
        "ratio_orientation_mean": full["ratio_orientation_mean"],
        "drift_ratio": full["drift_ratio"],
        "drift_ratio_orientation": full["drift_ratio_orientation"],
        **({"fit": full["fit"]} if "fit" in full else {}),
        "configs": configs,
        "seconds": time.perf_counter() - t0,
    }


def check_fit(settings: GapSettings) -> None:
    """Refuse a `fit` the hand or the object cannot take, before the sim runs."""
    from vlr.spec import load_hand, load_object
    from vlr.unknowns import parse_unknown

    model = HandModel.from_spec(load_hand(settings.hand))
    try:
        parse_unknown(settings.fit, model,
                      obj=ObjectParams.from_spec(load_object(settings.object)))
    except (KeyError, ValueError) as exc:
        raise UserError(f"--fit {settings.fit!r}: {exc}") from None


def format_report(rep: dict) -> str:
    """A table a person reads: one row per model rung."""
    head = (f"{rep['object']} ({rep['hand']}), seed {rep['seed']}: {rep['actions']} actions, "
            f"true motion {rep['true_motion']['position_mm_mean']:.2f} mm / "
            f"{rep['true_motion']['orientation_deg_mean']:.2f} deg per action"
            + ("; each action from the sim's contact loads"
               if rep.get("start") == "sim-loads" else "")
            + f"; the sim's commands ramped over {rep['ramp_time']:g} s"
            + (f"; grasp lost at action {rep['grasp_lost_at']}" if rep["grasp_lost_at"] else ""))
    cols = f"{'model':28s} {'ratio pos':>10s} {'ratio ori':>10s} {'drift pos':>10s} " \
           f"{'drift ori':>10s} {'static mm':>10s} {'static deg':>10s} {'joint deg':>10s} " \
           f"{'open pos':>10s} {'open ori':>10s}"
    lines = [head, cols]
    for c in rep["configs"]:
        s = c["static"]
        name = c["name"] + (f" (mu {c['friction']:g})" if c.get("friction") is not None else "")
        lines.append(f"{name:28s} {c['ratio_position_mean']:10.3f} "
                     f"{c['ratio_orientation_mean']:10.3f} {c['drift_ratio']:10.3f} "
                     f"{c['drift_ratio_orientation']:10.3f} {s['position_mm_mean']:10.2f} "
                     f"{s['orientation_deg_mean']:10.2f} {s['joint_deg_mean']:10.2f} "
                     f"{c.get('open_loop_ratio_position_mean', math.nan):10.3f} "
                     f"{c.get('open_loop_ratio_orientation_mean', math.nan):10.3f}"
                     + (f"  ({c['failed_solves']} failed solves)" if c["failed_solves"] else ""))
    lines.append("open pos / ori: the per-action ratios along the open-loop path of the drift "
                 "(the model carrying its own state, as a particle does)")
    lines.append(f"{'per-action error, RMS':28s} {'pos mm':>10s} {'ori deg':>10s} "
                 f"{'turn deg':>10s} {'rest mm':>10s} {'rest deg':>10s}")
    for c in rep["configs"]:
        t = c["turn"]
        lines.append(f"{c['name']:28s} {t['position_mm_rms']:10.3f} "
                     f"{t['orientation_deg_rms']:10.3f} {t['turn_error_deg_rms']:10.3f} "
                     f"{t['rest_position_mm_rms']:10.3f} {t['rest_orientation_deg_rms']:10.3f}")
    lines.append("turn: the object's turn about the grasp's axis (thumb to the other "
                 "contacts; nan for a hand without a thumb); rest: the error left off it")
    lines.append(f"{'tendon tensions, RMS [N]':28s} {'change err':>10s} {'change':>10s} "
                 f"{'static err':>10s}")
    for c in rep["configs"]:
        t = c.get("tension", {})
        lines.append(f"{c['name']:28s} {t.get('tension_change_error_n', math.nan):10.3f} "
                     f"{t.get('tension_change_n', math.nan):10.3f} "
                     f"{t.get('tension_static_error_n', math.nan):10.3f}")
    lines.append("tensions: the model's error on each action's tension change (the sim's "
                 "change beside it) and at its settle on the true state, RMS over the fingers")
    fits = [(c["name"], c["fit"]) for c in rep["configs"] if "fit" in c]
    if fits:
        f0 = fits[0][1]
        lines.append(f"{'fit of ' + f0['unknown']:28s} {'restart':>10s} {'open loop':>10s} "
                     f"{'truth':>10s}   ({len(f0['values'])} values "
                     f"{f0['values'][0]:.4g}-{f0['values'][-1]:.4g})")
        for name, f in fits:
            lines.append(f"{name:28s} {f['best_restart']:10.4g} {f['best_open_loop']:10.4g} "
                         f"{f['truth']:10.4g}"
                         + (f"  ({f['failed']} values failed)" if f["failed"] else ""))
        turn = f0.get("sigma_turn_deg", 0.0)
        how = (f"the filter's likelihood with a {turn:g} deg turn" if turn > 0
               else "squared errors")
        lines.append(f"fit: the value whose predicted motions cost least ({how} over "
                     f"{f0['sigma_pos_mm']:g} mm and {f0['sigma_rot_deg']:g} deg), each action "
                     "from the true state (restart) or all in sequence (open loop)")
    return "\n".join(lines)
