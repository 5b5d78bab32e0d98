"""Which of the hand's and the object's parameters does the motion model want off their true
values? `vlr gap --fit` for each unknown in turn (docs/RESULTS.md section 5, session 35).

A one-off diagnostic, not part of the package. Records OBJECT's random actions for SEED once
(20 actions, the 0.1 s ramp), then profiles each unknown with the filter's model (rolling,
stops at 17 N m/rad) over its default prior (21 values) and prints the best value against
the truth, restart and open loop, and the restart cost at the truth beside the least.

    MUJOCO_GL=egl python docs/scripts/gap_fit_survey.py OBJECT SEED
"""

import sys
from dataclasses import replace

import numpy as np

from sim.gap import _ALL, GapSettings, measure_gap, record_actions

FINGERS, JOINTS = ("thumb", "left", "right"), ("proximal", "distal")
SPECS = (["tendon"] + [f"stiffness:{f}.{j}" for f in FINGERS for j in JOINTS]
         + [f"length:{f}.{j}" for f in FINGERS for j in JOINTS] + ["mass", "curvature"])


def main(obj: str, seed: int) -> None:
    base = GapSettings(object=obj, seed=seed, actions=20, drift_actions=2, ramp_time=0.1,
                       limit_stiffness=17.0, fit_points=21)
    rec = record_actions(base)
    for spec in SPECS:
        fit = measure_gap(rec, _ALL, replace(base, fit=spec))["fit"]
        truth = fit["truth"]
        values, cost = np.array(fit["values"]), np.array(fit["cost_restart"])
        ratio = fit["best_restart"] / truth if truth else float("nan")
        print(f"{obj} seed {seed} {spec:24s} truth {truth:9.4g}  best restart "
              f"{fit['best_restart']:9.4g} ({ratio:4.2f}x)  open loop "
              f"{fit['best_open_loop']:9.4g}  restart cost at the truth "
              f"{np.interp(truth, values, cost):6.0f}, least {np.nanmin(cost):6.0f}")


if __name__ == "__main__":
    main(sys.argv[1], int(sys.argv[2]))
