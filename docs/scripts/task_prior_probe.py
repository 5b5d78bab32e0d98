"""How right the identification in a task's `reset` is: per finger, the true joint angles
(sim ground truth, read after the fact for scoring) against the posterior's mean and spread,
the tendon tensions the VLR believes, and the mean absolute joint error (docs/TASKS.md, "The
grasp guess of the tasks' identification").

A one-off diagnostic, not part of the package. Seed 0 unless `--seed`; env options as
`vlr task --option`.

    MUJOCO_GL=egl python docs/scripts/task_prior_probe.py cups
    MUJOCO_GL=egl python docs/scripts/task_prior_probe.py cups \\
        --option "nominal_theta_deg=(-10,15)" --option prior_spread_deg=10
"""

import argparse
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np

import tasks
from vlr.commands.task import parse_options
from vlr.errors import UserError

IDS = {"maze": tasks.MARBLE_MAZE, "cups": tasks.CUP_STACKING, "handwriting": tasks.HANDWRITING}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("task", choices=sorted(IDS))
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--option", action="append", default=[], metavar="KEY=VALUE")
    args = ap.parse_args()
    options = parse_options(args.option)
    env = gym.make(IDS[args.task], **options)
    u = env.unwrapped
    u.reset(seed=args.seed)
    np.set_printoptions(precision=1, suppress=True)
    st, truth = u.pf.state, u.hand.truth()
    errors = []
    for i, (name, finger) in enumerate(truth.fingers.items()):
        mean = np.degrees(st.theta[:, i].mean(axis=0))
        errors.append(np.abs(mean - np.degrees(finger.angles)))
        print(f"{name}: truth {np.degrees(finger.angles)} deg, posterior mean {mean} sd "
              f"{np.degrees(st.theta[:, i].std(axis=0))}, true tension {finger.tension:.1f} N")
    print("tensions the VLR believes [N]:", u.pf.motion.tensions(st, u.commands).mean(axis=0))
    print(f"mean absolute joint error: {np.mean(errors):.1f} deg")
    env.close()


if __name__ == "__main__":
    try:
        main()
    except UserError as exc:   # a bad --option or --controller: one line, no traceback
        sys.exit(f"{Path(__file__).name}: error: {exc}")
