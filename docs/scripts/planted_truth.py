"""Does the truth, planted among the particles, survive the filter's updates? (docs/RESULTS.md,
sections 1 and 5.)

A one-off diagnostic, not part of the package. The synthetic world (seed 0) with pinned or
rolling contacts, the filter with the same model, 400 particles of which 50 are set to the
true state; then 8 random actions. After each update: how many particles are still exactly
the truth (every packed coordinate within 1e-6). With `--no-follow` the motion model does not
follow large moves (`MotionConfig.follow_substeps` 0), as before session 5.

    MUJOCO_GL=egl python docs/scripts/planted_truth.py [--rolling] [--no-follow]
"""

import argparse
from dataclasses import replace

import numpy as np

from vlr.filter import FilterConfig, ParticleFilter
from vlr.kinematics import HandModel
from vlr.motion import MotionConfig, ObjectParams
from vlr.spec import load_hand
from vlr.synthetic import SyntheticConfig, SyntheticWorld, random_action

FIELDS = ("theta", "normals", "anchors", "pos", "rot", "segments", "stiffness", "tendon",
          "valid")


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("--rolling", action="store_true")
    p.add_argument("--no-follow", action="store_true")
    args = p.parse_args()
    model = HandModel.from_spec(load_hand("modelo"))
    obj = ObjectParams(mass=0.12, com=(0.0, 0.0, 0.03))
    mc = MotionConfig().with_rolling(args.rolling)
    world = SyntheticWorld(model, obj, SyntheticConfig(seed=0, motion=mc))
    u = world.grasp()
    fmc = replace(mc, follow_substeps=0) if args.no_follow else mc
    pf = ParticleFilter(model, obj, FilterConfig(n_particles=400, seed=0, motion=fmc))
    pf.initialize(world.observe(), u, world.nominal.theta, world.nominal.contact)
    for name in FIELDS:
        getattr(pf.state, name)[:50] = getattr(world.state, name)[0]
    rng = np.random.default_rng(1)
    kept = []
    for _ in range(8):
        u = world.apply(random_action(rng, 3))
        pf.step(u, world.observe())
        distance = np.abs(pf.pack(pf.state) - pf.pack(world.state)[0]).max(axis=1)
        kept.append(int((distance < 1e-6).sum()))
    print(f"{'rolling' if args.rolling else 'pinned'} contacts, following "
          f"{'off' if args.no_follow else 'on'}: copies of the truth after each of 8 updates "
          f"(50 planted): {kept}")


if __name__ == "__main__":
    main()
