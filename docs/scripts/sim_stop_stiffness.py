"""The sim's joint stops: how stiff MuJoCo makes them (docs/RESULTS.md section 5, session 27;
models/README.md).

A one-off diagnostic, not part of the package. MuJoCo's joint limits are soft constraints: at
rest under a torque they hold k = K d / (1 - d) m_eff, with K = 1 / (d^2 tau^2 zeta^2) from
solref (tau, zeta) and solimp's d, and m_eff = 1 / (M^-1)_jj the joint's effective inertia.
Prints, at OBJECT's grasp (hand HAND), each finger joint's angle against its range, m_eff
and that stiffness, and every active limit's penetration and torque.

    MUJOCO_GL=egl python docs/scripts/sim_stop_stiffness.py flat_screwdriver [modelo]
"""

import sys

import mujoco
import numpy as np

from sim.backend import SimHand


def main(obj: str, hand_name: str) -> None:
    with SimHand(object=obj, hand=hand_name, seed=0) as hand:
        hand.grasp()
        m, d = hand.model, hand.data
        m_inv = np.zeros((m.nv, m.nv))
        mujoco.mj_solveM(m, d, m_inv, np.eye(m.nv))
        for j in range(m.njnt):
            if m.jnt_type[j] != mujoco.mjtJoint.mjJNT_HINGE:
                continue
            name = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_JOINT, j)
            dof = m.jnt_dofadr[j]
            m_eff = 1.0 / m_inv[dof, dof]
            tau, zeta = m.jnt_solref[j]
            dmax = m.jnt_solimp[j][1]
            k = dmax / (1.0 - dmax) * m_eff / (dmax**2 * tau**2 * zeta**2)
            lo, hi = np.degrees(m.jnt_range[j])
            q = np.degrees(d.qpos[m.jnt_qposadr[j]])
            print(f"{name:16s} q {q:7.2f} deg in [{lo:6.1f}, {hi:6.1f}]  m_eff {m_eff:.2e} "
                  f"kg m^2  stop stiffness {k:6.1f} N m/rad")
        for i in range(d.nefc):
            if d.efc_type[i] == mujoco.mjtConstraint.mjCNSTR_LIMIT_JOINT:
                name = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_JOINT, d.efc_id[i])
                pen, f = -d.efc_pos[i], d.efc_force[i]
                print(f"active limit {name}: {np.degrees(pen):.3f} deg past its stop under "
                      f"{f:.4f} N m ({f / pen:.1f} N m/rad)")


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "flat_screwdriver",
         sys.argv[2] if len(sys.argv) > 2 else "modelo")
