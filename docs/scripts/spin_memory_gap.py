"""The pads' spin memory measured by `vlr gap` (docs/RESULTS.md section 5, session 26): the
friction rung with and without `MotionConfig.spin_memory`, every object, seeds 0-2, 30
actions, all 30 predicted open loop too (the model carrying its own state, as a particle
does). Writes one CSV row per object, seed and arm; prints the means.

    MUJOCO_GL=egl python docs/scripts/spin_memory_gap.py docs/results/spin-memory-gap.csv

The same figures, one object and seed at a time, with the whole ladder: `vlr gap --object
OBJECT --seed S --drift-actions 30 [--spin-memory]`.
"""

import csv
import io
import sys
from dataclasses import replace

import numpy as np

from sim.gap import LADDER, OBJECTS, GapSettings, gap_report
from vlr.io import write_text_atomic

FIELDS = ("ratio_position_mean", "ratio_orientation_mean", "open_loop_ratio_position_mean",
          "open_loop_ratio_orientation_mean", "open_loop_ratio_orientation_median",
          "drift_ratio", "drift_ratio_orientation", "failed_solves")


def main(out: str) -> None:
    rows = []
    for seed in (0, 1, 2):
        for obj in OBJECTS:
            base = GapSettings(object=obj, seed=seed, actions=30, drift_actions=30)
            for memory in (False, True):
                rep = gap_report(replace(base, spin_memory=memory), LADDER[-1:])
                c = rep["configs"][-1]
                rows.append({"object": obj, "seed": seed, "spin_memory": memory,
                             **{k: c[k] for k in FIELDS}})
                print(obj, seed, memory, {k: round(c[k], 3) for k in FIELDS[:5]}, flush=True)
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(("object", "seed", "spin_memory") + FIELDS)
    for r in rows:
        w.writerow([r["object"], r["seed"], r["spin_memory"]]
                   + [f"{r[k]:.4f}" if isinstance(r[k], float) else r[k] for k in FIELDS])
    write_text_atomic(out, buf.getvalue())
    for memory in (False, True):
        sel = [r for r in rows if r["spin_memory"] == memory]
        print(f"spin memory {memory}: means over {len(sel)} object-seeds",
              {k: round(float(np.mean([r[k] for r in sel])), 3) for k in FIELDS[:5]})
    on = [r for r in rows if r["spin_memory"]]
    off = [r for r in rows if not r["spin_memory"]]
    for k in ("ratio_orientation_mean", "open_loop_ratio_orientation_mean"):
        print(f"{k}: lower with memory on {sum(a[k] < b[k] for a, b in zip(on, off, strict=True))} "
              f"of {len(on)}")


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit("usage: python docs/scripts/spin_memory_gap.py OUT.csv")
    main(sys.argv[1])
