"""Does the per-action gap come from the history the model's restart drops? (docs/RESULTS.md
section 5, "What remains is in orientation").

A one-off diagnostic, not part of the package. `vlr gap` starts each action from the
simulator's configuration re-settled with glued contacts, so the contacts' loads are the
model's own equilibrium, not the ones the sim's contacts carry from earlier actions. Here the
model also starts from the sim's loads: each pad's contact force on the object (MuJoCo's
`mj_contactForce`, palm frame) set as the contact penalty's stretch, -F / k_c, without a
settle (`vlr gap --start sim-loads` since session 28 does it with a relax). Prints the
per-action gap ratio, position / orientation, for both starts.

    MUJOCO_GL=egl python docs/scripts/true_loads_probe.py [OBJECT] [ACTIONS] [friction]
"""

import sys
from dataclasses import replace

import numpy as np

from sim.backend import SimHand
from sim.gap import _ALL, GapSettings, _motion_error, _state
from sim.pads import SLIDE_FRICTION, TORSION_FRICTION
from sim.truth import pad_forces
from vlr.explore import ExplorationRange, random_action
from vlr.kinematics import HandModel
from vlr.motion import MotionConfig, MotionModel, ObjectParams


def main() -> None:
    obj = sys.argv[1] if len(sys.argv) > 1 else "apple"
    n = int(sys.argv[2]) if len(sys.argv) > 2 else 12
    friction = "friction" in sys.argv[3:]
    s = GapSettings(object=obj, actions=n)
    with SimHand(object=obj, hand="modelo", seed=s.seed) as hand:
        cmds, truths = [hand.grasp().commands], [hand.scoring_truth()]
        loads = [pad_forces(hand)]
        rng = np.random.default_rng(s.seed + 1)          # vlr gap's action stream
        explore = ExplorationRange(s.action_range[0], s.action_range[1],
                                   max(s.band, s.action_range[1]))
        for _ in range(n):
            cmds.append(hand.apply(random_action(rng, cmds[-1], cmds[0], explore)).commands)
            truths.append(hand.scoring_truth())
            loads.append(pad_forces(hand))
        spec, ospec = hand.true_spec, hand.object_spec
    model = HandModel.from_spec(spec)
    cfg = MotionConfig(terms=_ALL)
    if friction:
        cfg = replace(cfg, slide_friction=SLIDE_FRICTION, spin_friction=TORSION_FRICTION)
    motion = MotionModel(model, ObjectParams.from_spec(ospec), cfg)
    settle = replace(cfg, jump_theta=1.0, jump_pos=0.05, max_iter=200)
    ratios: dict[str, list] = {"glued re-settle (vlr gap)": [], "the sim's loads": []}
    for k in range(n):
        for name, v in ratios.items():
            st = _state(model, truths[k])
            if name.startswith("glued"):
                motion.solve(st, cmds[k], settle)
            else:   # the model's stretch times k_c is minus the force on the object
                st.anchor_to_pose(model, (-loads[k] / cfg.contact_stiffness)[None])
            p0, r0 = st.pos[0].copy(), st.rot[0].copy()
            motion.solve(st, cmds[k + 1], u_from=cmds[k])
            if not st.valid[0]:
                v.append((np.nan, np.nan))
                continue
            e_p, e_r, m_p, m_r = _motion_error(p0, r0, st.pos[0], st.rot[0], truths[k],
                                               truths[k + 1])
            v.append((e_p / m_p, e_r / m_r))
    for name, v in ratios.items():
        a = np.array(v)
        rung = "friction" if friction else "rolling"
        print(f"{obj}, {rung}, {name}: mean {np.nanmean(a[:, 0]):.3f}"
              f" / {np.nanmean(a[:, 1]):.3f}, median {np.nanmedian(a[:, 0]):.3f} / "
              f"{np.nanmedian(a[:, 1]):.3f}, failed solves {int(np.isnan(a[:, 0]).sum())}")


if __name__ == "__main__":
    main()
