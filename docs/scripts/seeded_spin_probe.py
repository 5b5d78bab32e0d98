"""Does the sim's stored spin torque explain the restarted orientation gap? (docs/RESULTS.md
section 5, "The pads' spin memory", session 26.)

A one-off diagnostic, not part of the package. `vlr gap`'s random actions on each object
(seed SEED). Each action is predicted with the friction rung and spin memory from the truth
re-settled (glued, as `vlr gap` does), in two arms:

* `zero`: the pads start at zero spin torque (what `vlr gap` can know);
* `sim`: each pad starts with the spin torque the sim's pad holds at that state (MuJoCo's
  torsional contact force, which has the model's sign convention: a pad slipping at its
  cone holds a torque of the sign of its spin, 60 of 63 such contacts on three objects);
* `loads`, `loads + sim`: no settle; each pad's stretch is the sim's contact force on the
  object (`true_loads_probe.py`, session 10), the spin torques zero or the sim's.

`--smoothing EPS ...` (session 29) runs the `loads` and `loads + sim` arms with the spin
friction's curve rounded over EPS [rad] (`MotionConfig.spin_smoothing`, 1 mrad by default):
the pad's stick made as compliant in torsion as EPS makes it (tangent stiffness mu_t N /
EPS), against the sim's soft torsional friction.

Both arms first relax at the old command (the command change's first step) and measure the
action's motion from there, so the seeded torques' own rebalancing is not counted as the
action's. Sim ground truth: this is scoring, never the estimator.

    MUJOCO_GL=egl python docs/scripts/seeded_spin_probe.py 0
    MUJOCO_GL=egl python docs/scripts/seeded_spin_probe.py 0 --smoothing 0.001 0.002 0.003 0.005
"""

import argparse
import math
import sys
from dataclasses import replace

import numpy as np

from sim.gap import OBJECTS, _angle_deg, _state
from vlr.kinematics import HandModel
from vlr.motion import MotionModel, ObjectParams

sys.path.insert(0, "docs/scripts")
import pad_spin_probe  # noqa: E402
from pad_spin_probe import FRICTION, SETTLE  # noqa: E402

MEMORY = replace(FRICTION, spin_memory=True)


def record(obj: str, seed: int, actions: int = 30):
    """`pad_spin_probe.record`, the spin torques [N m] per state and finger taken out."""
    spec, obj_spec, slots, commands, truths, loads, forces = pad_spin_probe.record(
        obj, seed, actions)
    torques = np.array([[lo.get(sl, (0.0, 0.0, 0.0))[1] * 1e-3 for sl in slots]
                        for lo in loads])
    return spec, obj_spec, commands, truths, torques, forces


ARMS = ("zero", "sim", "loads", "loads + sim")


def ratios(spec, obj_spec, commands, truths, torques, forces, arm: str,
           smoothing: float = MEMORY.spin_smoothing) -> list[float]:
    model = HandModel.from_spec(spec)
    mm = MotionModel(model, ObjectParams.from_spec(obj_spec),
                     replace(MEMORY, spin_smoothing=smoothing))
    out = []
    for k in range(len(commands) - 1):
        t0, t1 = truths[k], truths[k + 1]
        st = _state(model, t0)
        if arm.startswith("loads"):  # the stretch times k_c is minus the force on the object
            st.anchor_to_pose(model, (-forces[k] / MEMORY.contact_stiffness)[None])
        else:
            mm.solve(st, commands[k], SETTLE)
        if arm.endswith("sim"):
            st.spin_torque[0] = torques[k]
        mm.solve(st, commands[k], u_from=commands[k])  # relax at the old command
        r0 = st.rot[0].copy()
        mm.solve(st, commands[k + 1], u_from=commands[k])
        if not st.valid[0]:
            continue
        true_turn = _angle_deg(t1.rotation @ t0.rotation.T)
        err = _angle_deg((st.rot[0] @ r0.T) @ (t1.rotation @ t0.rotation.T).T)
        out.append(err / true_turn if true_turn > 0 else math.nan)
    return out


def main(seed: int, smoothing: list[float] | None = None) -> None:
    for obj in OBJECTS:
        rec = record(obj, seed)
        if smoothing:
            r = {f"{arm}, {eps * 1e3:g} mrad": ratios(*rec, arm=arm, smoothing=eps)
                 for eps in smoothing for arm in ("loads", "loads + sim")}
        else:
            r = {arm: ratios(*rec, arm=arm) for arm in ARMS}
        print(f"{obj:17s} seed {seed}: orientation ratio mean (median; solves) "
              + ", ".join(f"{arm} {np.nanmean(v):.3f} ({np.nanmedian(v):.3f}; {len(v)})"
                          for arm, v in r.items()), flush=True)


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("seed", type=int, nargs="?", default=0)
    ap.add_argument("--smoothing", type=float, nargs="+", default=None)
    a = ap.parse_args()
    if a.smoothing and not all(eps > 0 for eps in a.smoothing):
        ap.error(f"--smoothing {a.smoothing}: each rounding [rad] must be > 0")
    main(a.seed, a.smoothing)
