"""The thumb spring's Cramér-Rao floor on the toy block at several likelihood scales
(docs/RESULTS.md section 5, session 36).

A one-off report, not part of the package. For each seed (its random actions) and each set
of likelihood scales, `vlr crb` bounds the standard deviation of the thumb's distal
stiffness after every action, linearised at the true grasp (the stiffness row's trial:
modelo_thumb45 in the sim, the filter's nominal modelo, the guess -10/15 degrees with a 10
degree spread, 40 actions). An unbiased estimator at the floor errs by sqrt(2/pi) of it on
average; that is the figure to hold the filter's mean absolute error against. Writes one
JSON with each seed's floor at the reported action counts and their means.

    MUJOCO_GL=egl python docs/scripts/spring_floor.py OUT.json [SEEDS]     # SEEDS e.g. 0-14
"""

import json
import math
import sys
import tempfile
from pathlib import Path

import numpy as np

from vlr.cli import main as vlr
from vlr.io import write_json_atomic

# (name, sigma_pos_mm, sigma_rot_deg, sigma_turn_deg): the sim's likelihood, two narrower
# ones (docs/sweeps/spring-scales.yaml), and the camera's own noise with no model error.
SCALES = [("likelihood (0.2 mm, 0.4 deg, 1 deg turn)", 0.2, 0.4, 1.0),
          ("0.75x (0.15 mm, 0.3 deg, 0.75 deg turn)", 0.15, 0.3, 0.75),
          ("0.5x (0.1 mm, 0.2 deg, 0.5 deg turn)", 0.1, 0.2, 0.5),
          ("the camera's (0.05 mm, 0.2 deg, no turn)", 0.05, 0.2, 0.0)]
AT = (5, 15, 20, 30, 35, 40)


def floor(seed: int, pos: float, rot: float, turn: float, tmp: Path) -> dict[int, float]:
    """The stiffness floor's standard deviation [N m/rad] after each action count in AT."""
    out = tmp / f"crb-{seed}-{pos}-{rot}-{turn}.json"
    rc = vlr(["crb", "--object", "toy_block", "--true-hand", "modelo_thumb45",
              "--unknown", "stiffness:thumb.distal", "--nominal-theta-deg", "-10", "15",
              "--prior-spread-deg", "10", "--seed", str(seed), "--actions", "40",
              "--sigma-pos-mm", str(pos), "--sigma-rot-deg", str(rot),
              "--sigma-turn", str(turn), "--json", str(out)])
    if rc != 0:
        raise SystemExit(f"vlr crb failed for seed {seed}")
    rows = json.loads(out.read_text())["by_action"]
    sd = {r["actions"]: r["unknown_std"][0] for r in rows}
    return {a: sd[a] for a in AT if a in sd}


def main(path: str, seeds: list[int]) -> None:
    report: dict = {"object": "toy_block", "true_hand": "modelo_thumb45",
                    "unknown": "stiffness:thumb.distal", "truth": 0.045, "seeds": seeds,
                    "actions": list(AT), "scales": []}
    with tempfile.TemporaryDirectory() as tmp:
        for name, pos, rot, turn in SCALES:
            per_seed = [floor(s, pos, rot, turn, Path(tmp)) for s in seeds]
            mean_sd = {a: float(np.mean([f[a] for f in per_seed if a in f])) for a in AT}
            report["scales"].append({
                "name": name, "sigma_pos_mm": pos, "sigma_rot_deg": rot,
                "sigma_turn_deg": turn,
                "sd_by_seed": [{str(a): round(v, 6) for a, v in f.items()} for f in per_seed],
                "sd_mean": {str(a): round(v, 6) for a, v in mean_sd.items()},
                "unbiased_mean_abs_error": {str(a): round(math.sqrt(2 / math.pi) * v, 6)
                                            for a, v in mean_sd.items()}})
            print(f"{name}: sd " + ", ".join(f"{a}: {v:.4f}" for a, v in mean_sd.items()))
    write_json_atomic(Path(path), report)


def _seeds(text: str) -> list[int]:
    lo, _, hi = text.partition("-")
    return list(range(int(lo), int(hi or lo) + 1))


if __name__ == "__main__":
    main(sys.argv[1], _seeds(sys.argv[2] if len(sys.argv) > 2 else "0-14"))
