"""Move-by-move trace of one cup's correction under the planned in-hand target
(docs/TASKS.md, "The in-hand target"): the Jacobian the plan used, the planned shift, and for
every move the action, the camera's error to the target and the tag motion the camera saw
against the motion that Jacobian predicted.

A one-off diagnostic, not part of the package. Runs cup2 only (`n_cups=1`) at the env's
defaults with the VLR baseline; the camera's view only, as the policy sees it.

    MUJOCO_GL=egl python docs/scripts/cups_plan_trace.py --seed 0
    MUJOCO_GL=egl python docs/scripts/cups_plan_trace.py --seed 0 --level-about tag
    # the defaults before session 12's grasp guess and per-move updates:
    MUJOCO_GL=egl python docs/scripts/cups_plan_trace.py --seed 0 \
        --option nominal_theta_deg=None --option prior_spread_deg=3 \
        --controller secant_updates=False
"""

import argparse
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np

import tasks
from tasks.baseline import fitted_jacobian
from vlr.commands.task import parse_options
from vlr.controller import observed_motion, pose_error
from vlr.errors import UserError


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--level-about", default="plan", choices=("plan", "tag", "grip"))
    ap.add_argument("--option", action="append", default=[], metavar="KEY=VALUE",
                    help="an env option, as `vlr task --option`")
    ap.add_argument("--controller", action="append", default=[], metavar="KEY=VALUE",
                    help="a controller setting of the baseline, as `vlr task --controller`")
    args = ap.parse_args()
    options = parse_options(args.option)
    changes = parse_options(args.controller, "--controller")
    np.set_printoptions(precision=3, suppress=True)
    env = gym.make(tasks.CUP_STACKING, n_cups=1, level_about=args.level_about, **options)
    u = env.unwrapped
    obs, info = env.reset(seed=args.seed)
    jac = fitted_jacobian(u, u.controller_config)
    print("Jacobian, position rows [mm per mm of tendon]:\n", jac[:3])
    print("Jacobian, rotation rows [deg per mm of tendon]:\n", np.degrees(jac[3:]) * 1e-3)
    goal_pos, goal_rot = u.goal
    print("target shift [mm]", (goal_pos - np.asarray(u.observation.position)) * 1e3)
    policy = u.baseline(**changes)
    start = u.commands.copy()
    print("action [mm] | error: position [mm], rotation [deg] | tag moved [mm] | "
          "predicted [mm]")
    while True:
        a = policy(obs)
        before, held = u.observation, u.commands.copy()
        obs, reward, terminated, truncated, info = env.step(a)
        if terminated or truncated:
            break
        e = pose_error(u.observation.position, u.observation.rotation, goal_pos, goal_rot)
        moved = observed_motion(before, u.observation)
        print(a * 1e3, e[:3] * 1e3, np.degrees(e[3:]), moved[:3] * 1e3, (jac @ a)[:3] * 1e3)
    rec = u.records[-1]
    print("commands before the last move, from the correction's start [mm]:",
          (held - start) * 1e3)
    print({k: round(v, 2) if isinstance(v, float) else v for k, v in rec.items()
           if k != "before_correction"})
    env.close()


if __name__ == "__main__":
    try:
        main()
    except UserError as exc:   # a bad --option or --controller: one line, no traceback
        sys.exit(f"{Path(__file__).name}: error: {exc}")
