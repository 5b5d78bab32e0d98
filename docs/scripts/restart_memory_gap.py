"""Does the model's own friction state, carried across `vlr gap`'s restart, close the
orientation gap? (docs/RESULTS.md section 5, "The restart carrying the model's own friction
state", session 31.)

A one-off diagnostic, not part of the package. `vlr gap`'s friction rung restarts every
action from the true configuration settled with glued contacts: every pad starts at zero spin
torque and with the glued settle's tangential loads, where the sim's pads carry their
history. A filter's particle carries its own. Each action is predicted with the friction rung
and session 27's terms (8 substeps, stops at 17 N m/rad, exact cylinders), the sim ramped over
0.1 s, from the true configuration in five arms:

* `settle`: `vlr gap`'s measure (the issue's);
* `settle, memory`: the same with spin memory (`vlr gap --spin-memory`): within an action
  each substep keeps the pads' spin torques, the restart zeroes them;
* `settle + spin`: settled, then each pad's spin torque the model's own at the end of its
  prediction of the previous action, relaxed at the old command;
* `own loads`: each contact's stretch the model's own at the end of its previous prediction
  (carried in the object's frame, as `--start sim-loads` carries the sim's), relaxed at the
  old command, no settle;
* `own loads + spin`: both.

Every arm but the first has spin memory on.

The carried arms take their state from the model's prediction in the same arm; the first
action, or one after a failed solve, starts from the settle. The relax is measured out of the
action's motion. Sim ground truth: scoring, never the estimator.

    MUJOCO_GL=egl python docs/scripts/restart_memory_gap.py apple,wine_glass,toy_block,\\
        flat_screwdriver,gelatin_box 0,1,2
"""

import argparse
import math
from dataclasses import replace

import numpy as np

from sim.gap import _ALL, OBJECTS, GapSettings, _motion_error, _pose, _start, _state, record_actions
from vlr.kinematics import HandModel
from vlr.motion import MotionConfig, MotionModel, ObjectParams

ARMS = ("settle", "settle, memory", "settle + spin", "own loads", "own loads + spin")


def _models(rec, settings: GapSettings,
            memory: bool) -> tuple[HandModel, MotionModel, MotionConfig]:
    model = HandModel.from_spec(rec.hand_spec)
    cfg = MotionConfig(terms=_ALL, rolling_substeps=settings.rolling_substeps,
                       exact_cylinder=settings.exact_cylinder,
                       limit_stiffness=settings.limit_stiffness,
                       slide_friction=settings.slide_friction,
                       spin_friction=settings.spin_friction, spin_memory=memory)
    settle = replace(cfg, jump_theta=1.0, jump_pos=0.05, max_iter=200)
    return model, MotionModel(model, ObjectParams.from_spec(rec.object_spec), cfg), settle


def ratios(rec, settings: GapSettings, arm: str) -> list[float]:
    """The per-action orientation ratios of one arm (module docstring)."""
    model, motion, settle = _models(rec, settings, memory=arm != "settle")
    out, memory = [], None  # memory: (stretch in O (N, 3) [m], spin torques (1, N) [N m])
    loads, spin = arm.startswith("own loads"), arm.endswith("spin")
    for k in range(len(rec.commands) - 1):
        t0, t1 = rec.truths[k], rec.truths[k + 1]
        if memory is not None and loads:
            st = _state(model, t0)
            st.anchor_to_pose(model, np.einsum("ij,nj->ni", st.rot[0], memory[0])[None])
        else:
            st = _start(motion, settle, model, rec, k, "settle")
        if memory is not None and spin:
            st.spin_torque[:] = memory[1]
        if memory is not None and (loads or spin):
            motion.solve(st, rec.commands[k], u_from=rec.commands[k])  # relax, measured out
        p0, r0 = _pose(st)
        motion.solve(st, rec.commands[k + 1], u_from=rec.commands[k])
        memory = None
        if st.valid[0]:
            p1, r1 = _pose(st)
            _, e_r, _, m_r = _motion_error(p0, r0, p1, r1, t0, t1)
            out.append(e_r / m_r if m_r > 0 else math.nan)
            stretch = np.einsum("ji,nj->ni", st.rot[0], st.contact_residuals(model)[0])
            memory = (stretch, st.spin_torque.copy())
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("objects", help=f"comma list ({', '.join(OBJECTS)})")
    ap.add_argument("seeds", help="comma list of seeds")
    a = ap.parse_args()
    objects = a.objects.split(",")
    try:
        seeds = [int(s) for s in a.seeds.split(",")]
    except ValueError:
        ap.error(f"seeds {a.seeds!r}: expected a comma list of integers, e.g. 0,1,2")
    bad = [o for o in objects if o not in OBJECTS]
    if bad:
        ap.error(f"unknown object(s) {bad}: expected {', '.join(OBJECTS)}")
    means: dict[str, list[float]] = {arm: [] for arm in ARMS}
    for obj in objects:
        for seed in seeds:
            settings = GapSettings(object=obj, seed=seed, ramp_time=0.1, rolling_substeps=8,
                                   limit_stiffness=17.0, exact_cylinder=True)
            rec = record_actions(settings)
            row = {arm: ratios(rec, settings, arm) for arm in ARMS}
            for arm, v in row.items():
                means[arm].append(float(np.nanmean(v)))
            print(f"{obj:17s} seed {seed}: orientation ratio mean (median) "
                  + ", ".join(f"{arm} {np.nanmean(v):.3f} ({np.nanmedian(v):.3f})"
                              for arm, v in row.items()), flush=True)
    print("over the object-seeds: mean (how many over 0.10) "
          + ", ".join(f"{arm} {np.mean(v):.3f} ({int(np.sum(np.array(v) > 0.10))})"
                      for arm, v in means.items()))


if __name__ == "__main__":
    main()
