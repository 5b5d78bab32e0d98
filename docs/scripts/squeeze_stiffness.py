"""Is the replaced thumb spring missed because its joint works at its stop? (docs/RESULTS.md
section 2, the stiffness row.)

A one-off diagnostic, not part of the package. Runs the sim stiffness trial (true hand
modelo_thumb45, 10,000 particles, 20 actions, seeds 0-2) with every tendon pulled a further
`squeeze` mm right after the grasp (SimHand.grasp wrapped for this process only), and prints
the spring's estimate and interval, its error, the thumb's distal angle in the truth and the
proximal error.

    MUJOCO_GL=egl python docs/scripts/squeeze_stiffness.py 1.0 toy_block
    MUJOCO_GL=egl python docs/scripts/squeeze_stiffness.py 1.0 wine_glass
"""

import sys

import numpy as np

from sim.backend import SimHand
from vlr.trial import TrialSettings, identify_trial


def main() -> None:
    squeeze, obj = float(sys.argv[1]) * 1e-3, sys.argv[2]
    grasp = SimHand.grasp

    def squeezed(self):
        report = grasp(self)
        n = int(np.ceil(squeeze / 0.4e-3))
        for _ in range(n):
            report = self.apply(np.full(len(self.slots), squeeze / n))
        return report

    SimHand.grasp = squeezed
    for seed in (0, 1, 2):
        run = identify_trial(TrialSettings(
            backend="sim", object=obj, particles=10000, seed=seed, max_iterations=20,
            nominal_theta_deg=(-10, 15), prior_spread_deg=10, true_hand="modelo_thumb45",
            unknowns=("stiffness:thumb.distal",)))
        est = run.summary["unknown_estimates"]["stiffness:thumb.distal"]
        print(f"{obj} squeeze {squeeze * 1e3} mm seed {seed}: k {est['mean']:.4f} "
              f"[{est['low']:.4f}, {est['high']:.4f}], error "
              f"{run.summary['errors']['stiffness']['thumb.distal']:.4f}, thumb distal "
              f"{np.degrees(run.truths[-1].theta[0, 1]):.1f} deg, proximal error "
              f"{run.summary['errors']['proximal_deg_mean']:.2f} deg")


if __name__ == "__main__":
    main()
