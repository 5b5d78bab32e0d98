"""How much the sim's own outcome of an action depends on how fast it is made
(docs/RESULTS.md section 5, session 38).

A one-off diagnostic, not part of the package. Walks `vlr gap`'s random actions (the seed's
stream) in the sim at a reference ramp; before each action it snapshots the whole MuJoCo
state, makes the same command change at each other ramp time from that snapshot, and
restores it. Per action it compares the object's motion under each ramp with the
reference's, as `vlr gap` compares the model's: the difference over the reference motion,
in position and orientation. A quasi-static model predicts one outcome per action, so
where the sim's outcomes differ by a share of the motion, that share is part of any
quasi-static model's gap at the one ramp or the other. `--hold S` also lets the reference
outcome stand S more seconds at its command (the sim's creep after its settle).

    MUJOCO_GL=egl python docs/scripts/sim_rate_probe.py apple 0 [--actions 30]
        [--reference 0.1] [--ramps 0.05 0.5 2.0] [--hold 4] [--noslip 10] [--timestep 0.001]
        [--json FILE]
"""

import argparse
import json
from dataclasses import replace
from pathlib import Path

import mujoco
import numpy as np
from scipy.spatial.transform import Rotation

import sim.model as sim_model
from sim.backend import SimHand, SimOptions
from sim.gap import GapSettings
from vlr.explore import ExplorationRange, random_action
from vlr.observation import rotation_error


def _motion(a, b) -> tuple[np.ndarray, np.ndarray]:
    """The object's translation [m] and rotation vector [rad] from truth a to truth b."""
    return b.position - a.position, rotation_error(b.rotation @ a.rotation.T, np.eye(3))


def _hold(hand: SimHand, seconds: float) -> None:
    for _ in range(int(round(seconds / hand.model.opt.timestep))):
        mujoco.mj_step(hand.model, hand.data)


def probe(obj: str, seed: int, actions: int, reference: float, ramps: list[float],
          hold: float) -> tuple[dict[str, list[tuple[float, float]]], list[tuple[float, float]]]:
    """Per action and per comparison: (position ratio, orientation ratio) to the reference;
    and per action the reference motion (position [mm], orientation [deg])."""
    s = GapSettings(object=obj, seed=seed, actions=actions)
    # The settle's quiet window is counted in steps: keep it 30 ms whatever the step.
    window = max(1, round(SimOptions.settle_window * 0.001 / sim_model.TIMESTEP))
    options = SimOptions(width=64, height=48, ramp_time=reference, settle_window=window)
    out: dict[str, list[tuple[float, float]]] = {f"ramp {r:g} s": [] for r in ramps}
    if hold > 0:
        out[f"hold {hold:g} s"] = []
    motion: list[tuple[float, float]] = []
    with SimHand(object=obj, seed=seed, options=options) as hand:
        hand.grasp()
        rng = np.random.default_rng(seed + 1)                  # vlr gap's action stream
        explore = ExplorationRange(s.action_range[0], s.action_range[1],
                                   max(s.band, s.action_range[1]))
        center = hand.commands.copy()
        snapshot = mujoco.MjData(hand.model)
        for _ in range(actions):
            delta = random_action(rng, hand.commands, center, explore)
            a, u0 = hand.scoring_truth(), hand.commands.copy()
            mujoco.mj_copyData(snapshot, hand.model, hand.data)
            others = {}
            for r in ramps:
                hand.options = replace(options, ramp_time=r)
                hand.apply(delta)
                others[f"ramp {r:g} s"] = hand.scoring_truth()
                mujoco.mj_copyData(hand.data, hand.model, snapshot)
                hand._u = u0.copy()
            hand.options = options
            report = hand.apply(delta)
            b = hand.scoring_truth()
            if not report.grasp_held:
                break
            dp, dw = _motion(a, b)
            motion.append((float(np.linalg.norm(dp) * 1e3),
                           float(np.degrees(np.linalg.norm(dw)))))
            if hold > 0:
                mujoco.mj_copyData(snapshot, hand.model, hand.data)
                _hold(hand, hold)
                others[f"hold {hold:g} s"] = hand.scoring_truth()
                mujoco.mj_copyData(hand.data, hand.model, snapshot)
            for name, c in others.items():
                cp, cw = _motion(a, c)
                out[name].append((float(np.linalg.norm(cp - dp) / np.linalg.norm(dp)),
                                  float(np.linalg.norm(rotation_error(
                                      _rot(cw) @ _rot(dw).T, np.eye(3)))
                                      / np.linalg.norm(dw))))
    return out, motion


def _rot(w: np.ndarray) -> np.ndarray:
    return Rotation.from_rotvec(w).as_matrix()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("object")
    ap.add_argument("seed", type=int)
    ap.add_argument("--actions", type=int, default=30)
    ap.add_argument("--reference", type=float, default=0.1)
    ap.add_argument("--ramps", type=float, nargs="+", default=[0.05, 0.5, 2.0])
    ap.add_argument("--hold", type=float, default=4.0)
    ap.add_argument("--noslip", type=int, default=sim_model.NOSLIP_ITERATIONS)
    ap.add_argument("--timestep", type=float, default=sim_model.TIMESTEP,
                    help="the sim's step [s] (sim.model.TIMESTEP)")
    ap.add_argument("--json", type=Path, default=None,
                    help="write the per-action motion and ratios here")
    args = ap.parse_args()
    if args.actions < 1:
        ap.error(f"--actions {args.actions}: at least one action")
    for r in [args.reference, *args.ramps]:
        if not r > 0:
            ap.error(f"ramp time {r}: must be > 0 s")
    if not 0 < args.timestep <= 0.002:
        ap.error(f"--timestep {args.timestep}: must be in (0, 0.002] s (solref 4 ms)")
    sim_model.NOSLIP_ITERATIONS = args.noslip          # read when the scene is built
    sim_model.TIMESTEP = args.timestep
    out, motion = probe(args.object, args.seed, args.actions, args.reference, args.ramps,
                        args.hold)
    print(f"{args.object} {args.seed}, reference ramp {args.reference:g} s, noslip "
          f"{args.noslip}, step {args.timestep * 1e3:g} ms: the sim's own outcome against the "
          "reference's, over its motion (mean / median over the actions, position | "
          "orientation)")
    for name, rows in out.items():
        r = np.array(rows)
        print(f"  {name:12s} {r[:, 0].mean():.3f} / {np.median(r[:, 0]):.3f} | "
              f"{r[:, 1].mean():.3f} / {np.median(r[:, 1]):.3f}   ({len(r)} actions)")
    if args.json is not None:
        rows = [{"action": k + 1, "motion_position_mm": m[0], "motion_orientation_deg": m[1],
                 **{name: {"ratio_position": out[name][k][0],
                           "ratio_orientation": out[name][k][1]} for name in out}}
                for k, m in enumerate(motion)]
        tmp = args.json.with_suffix(args.json.suffix + ".tmp")
        tmp.write_text(json.dumps({"object": args.object, "seed": args.seed,
                                   "reference_ramp": args.reference, "noslip": args.noslip,
                                   "timestep": args.timestep,
                                   "per_action": rows}, indent=1))
        tmp.replace(args.json)


if __name__ == "__main__":
    main()
