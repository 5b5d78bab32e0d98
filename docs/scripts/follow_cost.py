"""What following large moves costs (docs/RESULTS.md, sections 1 and 3).

A one-off diagnostic, not part of the package. The filter on `vlr bench`'s world (synthetic,
seed 0, its action stream), per action: the share of particles whose one solve fails (a jump
or no convergence) and is followed in `MotionConfig.follow_substeps` steps, the share of those
that the steps bring through, the extra Newton iterations per particle, and the motion step's
time. Then the median seconds per iteration over 15 actions with following off and on.

    MUJOCO_GL=egl python docs/scripts/follow_cost.py [--particles 6000]
"""

import argparse
import time
from dataclasses import replace

import numpy as np

import vlr.motion as motion
from vlr._energy_kernels import JUMP, NO_CONVERGENCE, OK
from vlr.filter import FilterConfig, ParticleFilter
from vlr.kinematics import HandModel
from vlr.motion import MotionConfig, ObjectParams
from vlr.spec import load_hand
from vlr.synthetic import SyntheticConfig, SyntheticWorld, random_action

MODEL = HandModel.from_spec(load_hand("modelo"))
OBJ = ObjectParams(mass=0.12, com=(0.0, 0.0, 0.03))


def run(n: int, actions: int, follow: int, log: list | None = None) -> list[float]:
    """Seconds per filter iteration; `log` collects one row per followed solve."""
    world = SyntheticWorld(MODEL, OBJ, SyntheticConfig(seed=0, snap_theta=np.pi))
    u = world.grasp()
    cfg = FilterConfig(n_particles=n, seed=0,
                       motion=replace(MotionConfig(), follow_substeps=follow))
    pf = ParticleFilter(MODEL, OBJ, cfg)
    pf.initialize(world.observe(), u, world.nominal.theta, world.nominal.contact)
    rng = np.random.default_rng(1)
    seconds = []
    for _ in range(actions):
        u = world.apply(random_action(rng, 3))
        t0 = time.perf_counter()
        pf.step(u, world.observe())
        seconds.append(time.perf_counter() - t0)
        if log is not None:
            log.append(("motion", pf.timings["motion"]))
    return seconds


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("--particles", type=int, default=6000)
    args = p.parse_args()
    rows: list = []
    follow = motion.MotionModel._follow

    def counted(self, state, start, u, u_from, cfg, status, iters):
        failed = (status == JUMP) | (status == NO_CONVERGENCE)
        before = int(iters.sum())
        follow(self, state, start, u, u_from, cfg, status, iters)
        if state.n >= 100:  # the filter's solves, not the world's one particle
            rows.append(("follow", state.n, int(failed.sum()),
                         int((failed & (status == OK)).sum()), int(iters.sum()) - before))

    motion.MotionModel._follow = counted
    run(args.particles, 6, 16, rows)
    motion.MotionModel._follow = follow
    print(f"{args.particles} particles, per action (the settle's solves have no start command "
          "and are never followed):")
    pending = None
    for row in rows:
        if row[0] == "follow":
            pending = row
            continue
        if pending is None:
            print(f"  no failed solve; motion {row[1]:.2f} s")
            continue
        _, n, failed, through, extra = pending
        print(f"  one solve failed for {100 * failed / n:4.1f}% of the particles, "
              f"{100 * through / max(failed, 1):3.0f}% of those followed through; "
              f"{extra / n:5.1f} extra iterations per particle; motion {row[1]:.2f} s")
        pending = None
    n = args.particles // 2
    off = np.median(run(n, 15, 0))
    on = np.median(run(n, 15, 16))
    print(f"{n} particles, 15 actions, median s per iteration: following off {off:.3f}, "
          f"on {on:.3f} ({on / off:.2f}x)")


if __name__ == "__main__":
    main()
