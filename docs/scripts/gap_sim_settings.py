"""Whether the orientation gap left is the sim's or the model's (docs/RESULTS.md section 5,
"The orientation gap, looked at again").

A one-off diagnostic, not part of the package. Records `vlr gap`'s random actions (seed's
stream, 30 actions) in the sim with some of its settings changed, then measures the motion
model's per-action gap on each recording, restarted from the truth as `vlr gap` does, for
the rolling, cone-return and friction rungs. Per rung: the per-action ratios (position /
orientation, the issue's measure), the RMS of the orientation error about the palm's axes
(x: across the palm, the object's pitch; y: from the thumb to the other fingers, the turn in
the grip; z: up) and the gain of the predicted turn about the grasp's axis
(`vlr.observation.grasp_turn`) over the true one, least squares over the actions.

    MUJOCO_GL=egl python docs/scripts/gap_sim_settings.py [--objects apple,...] [--seeds 0]
        [--ramp-time 0.05 0.2] [--noslip 10 50] [--spin-friction 0.001]
        [--settle-spin 0.001 --settle-time 4]

`--ramp-time` [s] is `SimOptions.ramp_time` (how fast a command change is made),
`--noslip` MuJoCo's noslip iterations (`sim.model.NOSLIP_ITERATIONS`), `--spin-friction` the
model's torsional friction coefficient [m] in the friction rung. `--settle-spin` [rad/s]
(session 29) makes the sim's settle also wait for the object's angular speed to fall under
it, which `SimHand._settle` does not check, for up to `--settle-time` [s] (the default 2).
"""

import argparse
import types
from dataclasses import replace

import mujoco
import numpy as np

import sim.model as sim_model
from sim.backend import SimHand, SimOptions
from sim.gap import _ALL, GapSettings, Recording
from vlr.explore import ExplorationRange, random_action
from vlr.kinematics import HandModel
from vlr.motion import MotionConfig, MotionModel, ObjectParams, ParticleState
from vlr.observation import grasp_turn, rotation_error


def _settle_with_spin(hand: SimHand, spin: float) -> bool:
    """`SimHand._settle`, also waiting for the object's angular speed under `spin` [rad/s]."""
    opts, m, d = hand.options, hand.model, hand.data
    quiet, o = 0, hand._obj_dof
    for _ in range(int(opts.settle_time_max / m.opt.timestep)):
        mujoco.mj_step(m, d)
        quiet = quiet + 1 if (np.abs(d.qvel[hand._dadr]).max() < opts.settle_qvel
                              and np.abs(d.qvel[o:o + 3]).max() < opts.settle_objvel
                              and np.abs(d.qvel[o + 3:o + 6]).max() < spin) else 0
        if quiet >= opts.settle_window:
            return True
    return False


def record(obj: str, seed: int, ramp_time: float, actions: int = 30,
           settle_spin: float | None = None,
           settle_time: float = SimOptions.settle_time_max) -> tuple[Recording, int]:
    """`sim.gap.record_actions` with a ramp time (and a settle that waits for the object's
    spin, if given); also counts the settles that timed out."""
    s = GapSettings(object=obj, seed=seed, actions=actions)
    options = SimOptions(width=64, height=48, ramp_time=ramp_time,   # no frames needed
                         settle_time_max=settle_time)
    with SimHand(object=obj, seed=seed, options=options) as hand:
        if settle_spin is not None:
            hand._settle = types.MethodType(lambda h: _settle_with_spin(h, settle_spin), hand)
        grasp = hand.grasp()
        commands, tensions, truths = [grasp.commands], [grasp.tensions], [hand.scoring_truth()]
        rng = np.random.default_rng(seed + 1)                  # vlr gap's action stream
        explore = ExplorationRange(s.action_range[0], s.action_range[1],
                                   max(s.band, s.action_range[1]))
        center, unsettled, dropped = commands[0].copy(), 0, None
        for k in range(1, actions + 1):
            report = hand.apply(random_action(rng, commands[-1], center, explore))
            truth = hand.scoring_truth()
            if not report.grasp_held or not np.isfinite(truth.normals).all():
                dropped = k
                break
            unsettled += not report.settled
            commands.append(report.commands)
            tensions.append(report.tensions)
            truths.append(truth)
        return (Recording(hand.true_spec, hand.object_spec, commands, truths, dropped,
                          tensions), unsettled)


def measure(rec: Recording, cfg: MotionConfig) -> dict:
    """Per-action gap restarted from the truth (`sim.gap.measure_gap`'s loop), by axis."""
    model = HandModel.from_spec(rec.hand_spec)
    motion = MotionModel(model, ObjectParams.from_spec(rec.object_spec), cfg)
    settle = replace(cfg, jump_theta=1.0, jump_pos=0.05, max_iter=200)
    thumb = model.finger_index("thumb")
    rp, ro, axes, turn_true, turn_pred, failed = [], [], [], [], [], 0
    for k in range(len(rec.commands) - 1):
        a, b = rec.truths[k], rec.truths[k + 1]
        st = ParticleState.at_truth(model, a)
        motion.solve(st, rec.commands[k], settle)
        p0, r0 = st.pos[0].copy(), st.rot[0].copy()
        v = grasp_turn(st.pos, st.rot, st.anchors, thumb)[0]
        motion.solve(st, rec.commands[k + 1], u_from=rec.commands[k])
        if not st.valid[0]:
            failed += 1
            continue
        p1, r1 = st.pos[0], st.rot[0]
        w_true = rotation_error(b.rotation @ a.rotation.T, np.eye(3))
        w_pred = rotation_error(r1 @ r0.T, np.eye(3))
        w_err = rotation_error((r1 @ r0.T) @ (b.rotation @ a.rotation.T).T, np.eye(3))
        dp_true = b.position - a.position
        rp.append(np.linalg.norm((p1 - p0) - dp_true) / np.linalg.norm(dp_true))
        ro.append(np.linalg.norm(w_err) / np.linalg.norm(w_true))
        axes.append(np.degrees(w_pred - w_true))
        turn_true.append(float(w_true @ v[3:]))
        turn_pred.append(float(w_pred @ v[3:]))
    t, p = np.array(turn_true), np.array(turn_pred)
    return {"ratio_position": float(np.mean(rp)), "ratio_orientation": float(np.mean(ro)),
            "axis_rms_deg": np.sqrt(np.mean(np.array(axes) ** 2, axis=0)),
            "turn_gain": float(t @ p / (t @ t)), "failed": failed}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--objects", default="apple,wine_glass,toy_block,flat_screwdriver,"
                                         "gelatin_box")
    ap.add_argument("--seeds", default="0")
    ap.add_argument("--ramp-time", type=float, nargs="+", default=[0.05])
    ap.add_argument("--noslip", type=int, nargs="+", default=[sim_model.NOSLIP_ITERATIONS])
    ap.add_argument("--spin-friction", type=float, default=0.001)
    ap.add_argument("--settle-spin", type=float, default=None)
    ap.add_argument("--settle-time", type=float, default=SimOptions.settle_time_max)
    args = ap.parse_args()
    if args.settle_spin is not None and not args.settle_spin > 0:
        ap.error(f"--settle-spin {args.settle_spin}: an angular speed [rad/s] must be > 0")
    if not args.settle_time > 0:
        ap.error(f"--settle-time {args.settle_time}: a time [s] must be > 0")
    base = MotionConfig(terms=_ALL)
    rungs = (("rolling", base), ("cone return", replace(base, cone_return=1.0)),
             ("friction", replace(base, slide_friction=1.0, spin_friction=args.spin_friction)))
    print("object, seed, sim setting | per rung: ratio position / orientation, "
          "orientation error RMS about x, y, z [deg], turn gain")
    for obj in args.objects.split(","):
        for seed in (int(s) for s in args.seeds.split(",")):
            for noslip in args.noslip:
                sim_model.NOSLIP_ITERATIONS = noslip     # read when the scene is built
                for ramp in args.ramp_time:
                    rec, unsettled = record(obj, seed, ramp, settle_spin=args.settle_spin,
                                             settle_time=args.settle_time)
                    cells = []
                    for name, cfg in rungs:
                        m = measure(rec, cfg)
                        x, y, z = m["axis_rms_deg"]
                        cells.append(f"{name} {m['ratio_position']:.3f} / "
                                     f"{m['ratio_orientation']:.3f}, {x:.2f} {y:.2f} {z:.2f}, "
                                     f"{m['turn_gain']:.2f}"
                                     + (f" ({m['failed']} failed)" if m["failed"] else ""))
                    dropped = "" if rec.dropped_at is None else f", dropped at {rec.dropped_at}"
                    print(f"{obj} {seed}, ramp {ramp:g} s, noslip {noslip} ({unsettled} "
                          f"settles timed out{dropped}) | " + " | ".join(cells), flush=True)


if __name__ == "__main__":
    main()
