"""How one tendon turns a picked cup, and how far a side tendon may release (docs/TASKS.md,
cup stacking: "0.4 mm of one side tendon turns it about 1.6 degrees", "releasing a side
tendon by 0.5 mm loses its fingertip").

A one-off diagnostic, not part of the package. Picks cup2 (seed 0, 1000 particles, 2
identification moves: the probe needs the grasp, not a good identification), then moves
each tendon alone by +-0.2 and +0.4 mm from the task's centre and back, printing the POM
motion the camera sees and whether the grasp held; then steps the commands to a few
release/pull combinations, printing the true tilt and the static tendon tensions [N].

    MUJOCO_GL=egl python docs/scripts/cups_tendon_probe.py
    MUJOCO_GL=egl python docs/scripts/cups_tendon_probe.py --thumb   # session 13

With `--thumb`: from the task's centre (the 0.3 mm squeeze on), go to the band's corner
(thumb -0.5, left -0.25, right +1.2 mm) and release the thumb further (0.8, 1.0, 1.3 mm),
printing the tilt, the tensions and whether the grasp held, until it does not.
"""

import argparse

import gymnasium as gym
import numpy as np

import tasks
from vlr.controller import pose_error


def pose(env):
    o = env.observation
    return np.asarray(o.position).copy(), np.asarray(o.rotation).copy()


def thumb() -> None:
    env = gym.make(tasks.CUP_STACKING, particles=1000, identify_iterations=2, n_cups=1,
                   command_band=(2e-3, 3e-3)).unwrapped
    env.reset(seed=0)
    print(f"start tilt {env._true_error()['tilt_deg']:.2f} deg")
    for t in (-0.5e-3, -0.8e-3, -1.0e-3, -1.3e-3):
        goal = env.center + np.array([t, -0.25e-3, 1.2e-3])
        while np.max(np.abs(goal - env.commands)) > 1e-9 and not env.grasp_lost:
            env._apply(np.clip(goal - env.commands, -0.4e-3, 0.4e-3))
        e = env._true_error()
        print(f"thumb {t * 1e3:+.1f}, left -0.25, right +1.2 mm from the centre: tilt "
              f"{e['tilt_deg']:.2f} deg, tensions {env.hand.static_tensions().round(1)} N, "
              f"grasp lost {env.grasp_lost}")
        if env.grasp_lost:
            break


def main() -> None:
    env = gym.make(tasks.CUP_STACKING, particles=1000, identify_iterations=2, n_cups=1,
                   command_band=(1e-3, 3e-3), squeeze=0.0).unwrapped
    env.reset(seed=0)
    for d in (0.2e-3, -0.2e-3, 0.4e-3):
        for i in range(3):
            p0, r0 = pose(env)
            a = np.zeros(3)
            a[i] = d
            env._apply(a)
            e = pose_error(*pose(env), p0, r0)
            print(f"tendon {i} {d * 1e3:+.1f} mm: POM moves {np.round(e[:3] * 1e3, 2)} mm, "
                  f"turns {np.round(np.degrees(e[3:]), 2)} deg, grasp lost {env.grasp_lost}")
            env._apply(-a)
    for target in ([0, 0, 0.4e-3], [0, 0, 0.8e-3], [0, 0, 1.2e-3], [0, 0.4e-3, -0.4e-3],
                   [0, 0.8e-3, -0.6e-3]):
        goal = env.center + np.array(target)
        while np.max(np.abs(goal - env.commands)) > 1e-9:
            env._apply(np.clip(goal - env.commands, -0.4e-3, 0.4e-3))
        t = env._true_error()
        print(f"commands - centre {np.round(np.array(target) * 1e3, 1)} mm: tilt "
              f"{t['tilt_deg']:.2f} deg, tensions {env.hand.static_tensions().round(1)} N, "
              f"grasp lost {env.grasp_lost}")


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--thumb", action="store_true",
                    help="release the thumb past the band's corner (session 13)")
    thumb() if ap.parse_args().thumb else main()
