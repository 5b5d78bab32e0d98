"""How stiff the sim's pad contacts are (docs/RESULTS.md section 5, "The gap that is left").

A one-off diagnostic, not part of the package. Grasps each object (seed 0) and prints, per
pad contact, MuJoCo's penetration, normal force, their ratio (the contact's secant stiffness
[N/m], to compare with the motion model's penalty `MotionConfig.contact_stiffness`) and the
tangential force.

    MUJOCO_GL=egl python docs/scripts/pad_stiffness.py [OBJECT ...]
"""

import sys

import mujoco
import numpy as np

from sim.backend import SimHand

OBJECTS = ("apple", "wine_glass", "toy_block", "flat_screwdriver", "gelatin_box")


def main() -> None:
    for obj in sys.argv[1:] or OBJECTS:
        with SimHand(object=obj, hand="modelo", seed=0) as hand:
            hand.grasp()
            m, d = hand.model, hand.data
            for i in range(d.ncon):
                c = d.contact[i]
                names = [mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_GEOM, g) or ""
                         for g in (c.geom1, c.geom2)]
                pad = next((n for n in names if n.endswith("/pad")), None)
                if pad is None:
                    continue
                f = np.zeros(6)
                mujoco.mj_contactForce(m, d, i, f)
                depth = -c.dist
                print(f"{obj:17s} {pad:11s} penetration {depth * 1e3:.3f} mm, normal "
                      f"{f[0]:.2f} N, stiffness {f[0] / max(depth, 1e-12):8.0f} N/m, "
                      f"tangential {np.hypot(f[1], f[2]):.2f} N")


if __name__ == "__main__":
    main()
