"""How well the identified grasp predicts the cups' levelling move (docs/TASKS.md, "The in-hand
target"): the tendon change that best levels cup2 by the baseline's starting Jacobian, within
one move's bounds (what the plan uses) or the band's whole reach, and the POM motion it is
predicted to make by that Jacobian (the VLR's plus the camera-fitted correction), by the
VLR's Jacobian alone, and by the motion model itself (the equilibrium of 64 posterior
particles at the new commands, no linearization); then the move is made and the camera's
view of it is printed beside them.

A one-off diagnostic, not part of the package. The predictions read the camera and the
filter only; the last line scores the pose against the target with ground truth.

    # as measured in session 13, with the thumb's release then (0.5 mm):
    MUJOCO_GL=egl python docs/scripts/cups_levelling_probe.py --seed 0 --reach band \
        --option "command_band=((0.0005,0.00025,0.00025),0.0012)"
"""

import argparse
import sys
from dataclasses import replace
from pathlib import Path

import gymnasium as gym
import numpy as np

import tasks
from tasks.baseline import fitted_jacobian
from vlr.commands.task import parse_options
from vlr.controller import (
    numerical_jacobian,
    observed_motion,
    pose_error,
    reachable_motion,
    rotation_log,
    sample_particles,
)
from vlr.errors import UserError


def model_motion(pf, u: np.ndarray, du: np.ndarray, n: int = 64,
                 substeps: int = 4) -> tuple[np.ndarray, int]:
    """Mean POM motion (6,) [m, rad] of `n` posterior particles' equilibria from `u` to
    `u + du` (in `substeps` for Newton's sake), and how many particles solved."""
    motion = pf.motion
    cfg = replace(motion.config, max_iter=max(motion.config.max_iter, 200))
    st = sample_particles(pf.state, n)
    motion.solve(st, u, cfg)
    p0, r0 = st.pos.copy(), st.rot.copy()
    for k in range(1, substeps + 1):
        motion.solve(st, u + du * k / substeps, cfg)
    ok = st.valid
    rel = np.einsum("pab,pcb->pac", st.rot[ok], r0[ok])
    return (np.r_[(st.pos[ok] - p0[ok]).mean(0),
                  np.mean([rotation_log(r) for r in rel], axis=0)], int(ok.sum()))


def show(label: str, m: np.ndarray) -> None:
    print(f"{label:34s} position {m[:3] * 1e3} mm, rotation {np.degrees(m[3:])} deg")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--reach", choices=("move", "band"), default="move",
                    help="plan within one move's bounds (the env's) or the whole band")
    ap.add_argument("--option", action="append", default=[], metavar="KEY=VALUE",
                    help="an env option, as `vlr task --option`")
    args = ap.parse_args()
    np.set_printoptions(precision=2, suppress=True)
    env = gym.make(tasks.CUP_STACKING, n_cups=1, **parse_options(args.option)).unwrapped
    env.reset(seed=args.seed)
    cfg = env.controller_config
    pos, rot = np.asarray(env.observation.position), np.asarray(env.observation.rotation)
    err = pose_error(pos, rot, pos, env.goal[1])
    if args.reach == "move":
        bounds = env.action_bounds()
    else:
        release, pull = env.command_band
        bounds = (np.minimum(env.center - release - env.commands, 0.0),
                  np.maximum(env.center + pull - env.commands, 0.0))
    j_fit = fitted_jacobian(env, cfg)
    j_vlr = numerical_jacobian(env.pf.motion, env.pf.state, env.commands,
                               cfg.jacobian_eps, cfg.jacobian_particles)
    du, _ = reachable_motion(j_fit, err, "orientation", bounds)
    print(f"rotation to level {np.degrees(err[3:])} deg; levelling move {du * 1e3} mm "
          f"(bounds {bounds[0] * 1e3} .. {bounds[1] * 1e3} mm)")
    show("predicted, the plan's Jacobian", j_fit @ du)
    show("predicted, the VLR's Jacobian", j_vlr @ du)
    m, k = model_motion(env.pf, env.commands, du)
    show(f"predicted, the motion model ({k})", m)
    before, goal = env.observation, env.commands + du
    while np.max(np.abs(goal - env.commands)) > 1e-9 and not env.grasp_lost:
        env._apply(np.clip(goal - env.commands, -env.max_step, env.max_step))
    show("the camera saw", observed_motion(before, env.observation))
    print("ground truth after the move, against the target:", env._true_error())


if __name__ == "__main__":
    try:
        main()
    except UserError as exc:   # a bad --option or --controller: one line, no traceback
        sys.exit(f"{Path(__file__).name}: error: {exc}")
