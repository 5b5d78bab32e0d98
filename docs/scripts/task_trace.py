"""Move-by-move trace of the baseline controller on a task (docs/TASKS.md: maze seed 1's
snap and chatter, the small cups' stall at the band's release limit).

A one-off diagnostic, not part of the package. Runs the env at its defaults with the VLR
baseline and prints, for every step: the run or cup, the action [mm], the commands relative
to the task's centre [mm] and the reward (minus the camera's task error). With `--cup`, only
that cup's steps of a cup-stacking episode are printed.

    MUJOCO_GL=egl python docs/scripts/task_trace.py maze --seed 1
    MUJOCO_GL=egl python docs/scripts/task_trace.py cups --seed 0 --cup cup5 --band 0.25 1.2
"""

import argparse

import gymnasium as gym
import numpy as np

import tasks

IDS = {"maze": tasks.MARBLE_MAZE, "cups": tasks.CUP_STACKING, "handwriting": tasks.HANDWRITING}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("task", choices=sorted(IDS))
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--cup", default=None, help="cups: print this cup's steps only")
    ap.add_argument("--band", nargs=2, type=float, metavar=("RELEASE", "PULL"),
                    help="command band [mm], one release for every tendon (default: the env's)")
    args = ap.parse_args()
    kw = {"command_band": (args.band[0] * 1e-3, args.band[1] * 1e-3)} if args.band else {}
    env = gym.make(IDS[args.task], **kw)
    u = env.unwrapped
    obs, info = env.reset(seed=args.seed)
    policy = u.baseline()
    while True:
        a = policy(obs)
        where = info.get("cup", getattr(u, "run", ""))
        obs, reward, term, trunc, info = env.step(a)
        if args.cup is None or where == args.cup:
            print(f"{where} action {np.round(a * 1e3, 2)} mm, commands - centre "
                  f"{np.round((u.commands - u.center) * 1e3, 2)} mm, reward {reward:.2f}")
        if term or trunc:
            break
    print(u.metrics()["errors"])


if __name__ == "__main__":
    main()
