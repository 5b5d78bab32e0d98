"""Is `vlr gap`'s friction rung inflated by where it measures an action from? (docs/RESULTS.md
section 5, session 27, "Not the measure's start".)

A one-off diagnostic, not part of the package. `vlr gap` measures each predicted action from
the glued settle at the true state, so the frictional relax at the old command (the solve's
first step) counts as the action's motion. Here each action is measured both ways on the same
actions (seeds 0-2, 30 actions, the friction rung): from the settle (`vlr gap`'s figure) and
from after a relax at the old command. Prints the per-action orientation ratio's mean per
object and seed, and the means over the 15 object-seeds.

    MUJOCO_GL=egl python docs/scripts/relaxed_start_gap.py
"""

from dataclasses import replace

import numpy as np

from sim.gap import _ALL, OBJECTS, GapSettings, _motion_error, _pose, _state, record_actions
from vlr.kinematics import HandModel
from vlr.motion import MotionConfig, MotionModel, ObjectParams

ARMS = ("settle", "relaxed")


def ratios(obj: str, seed: int) -> dict[str, float]:
    settings = GapSettings(object=obj, seed=seed, actions=30)
    rec = record_actions(settings)
    model = HandModel.from_spec(rec.hand_spec)
    cfg = replace(MotionConfig(terms=_ALL), slide_friction=settings.slide_friction,
                  spin_friction=settings.spin_friction)
    motion = MotionModel(model, ObjectParams.from_spec(rec.object_spec), cfg)
    settle = replace(cfg, jump_theta=1.0, jump_pos=0.05, max_iter=200)   # as `vlr gap`
    out: dict[str, list[float]] = {arm: [] for arm in ARMS}
    for k in range(len(rec.commands) - 1):
        t0, t1 = rec.truths[k], rec.truths[k + 1]
        for arm in ARMS:
            st = _state(model, t0)
            motion.solve(st, rec.commands[k], settle)
            if arm == "relaxed":
                motion.solve(st, rec.commands[k], u_from=rec.commands[k])
            p0, r0 = _pose(st)
            motion.solve(st, rec.commands[k + 1], u_from=rec.commands[k])
            if st.valid[0]:
                _, e_r, _, m_r = _motion_error(p0, r0, *_pose(st), t0, t1)
                out[arm].append(e_r / m_r)
    return {arm: float(np.mean(v)) for arm, v in out.items()}


def main() -> None:
    rows = []
    for seed in (0, 1, 2):
        for obj in OBJECTS:
            r = ratios(obj, seed)
            rows.append(r)
            print(f"{obj:17s} seed {seed}: orientation ratio from the settle {r['settle']:.3f}, "
                  f"from the relaxed start {r['relaxed']:.3f}", flush=True)
    print("means over", len(rows), "object-seeds:",
          {arm: round(float(np.mean([r[arm] for r in rows])), 3) for arm in ARMS},
          "; lower from the relaxed start on",
          sum(r["relaxed"] < r["settle"] for r in rows))


if __name__ == "__main__":
    main()
