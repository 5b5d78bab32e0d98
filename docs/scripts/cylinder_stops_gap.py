"""Exact cylinders and the joint stops measured by `vlr gap` (docs/RESULTS.md section 5,
session 27). Seeds 0-2, 30 actions, the rolling and the friction rungs:

* on the cylinders (wine glass, flat screwdriver): the rolling term's pads held to a sphere
  of the cylinder's radius (the default) or to its axis (`MotionConfig.exact_cylinder`),
  each with and without the pads' spin memory (`MotionConfig.spin_memory`);
* on every object: the model's joint stops at 100 N m/rad (the default) and at 17, about
  the sim's distal stops (MuJoCo scales a limit's stiffness with the link's inertia: about
  120 N m/rad at the proximal joints, 18 at the distal ones).

Writes one CSV row per object, seed, arm and rung (with the median Newton iterations per
action); prints the means.

    MUJOCO_GL=egl python docs/scripts/cylinder_stops_gap.py docs/results/cylinder-stops-gap.csv

One object and seed at a time, with the whole ladder: `vlr gap --object OBJECT --seed S
[--exact-cylinder] [--spin-memory] [--limit-stiffness 17]`.
"""

import csv
import io
import sys
from dataclasses import replace

import numpy as np

from sim.gap import LADDER, OBJECTS, GapSettings, gap_report
from vlr.io import write_text_atomic

CYLINDERS = ("wine_glass", "flat_screwdriver")
ARMS = {
    "default": {},
    "exact cylinder": {"exact_cylinder": True},
    "spin memory": {"spin_memory": True},
    "spin memory + exact cylinder": {"spin_memory": True, "exact_cylinder": True},
    "stops 17": {"limit_stiffness": 17.0},
}
RUNGS = tuple(r for r in LADDER if r[0] in ("+ rolling", "+ friction"))
FIELDS = ("ratio_position_mean", "ratio_orientation_mean", "ratio_orientation_median",
          "open_loop_ratio_orientation_mean", "drift_ratio", "drift_ratio_orientation",
          "failed_solves", "newton_iterations_median")


def arms_for(obj: str) -> tuple[str, ...]:
    return tuple(ARMS) if obj in CYLINDERS else ("default", "stops 17")


def main(out: str) -> None:
    rows = []
    for seed in (0, 1, 2):
        for obj in OBJECTS:
            for arm in arms_for(obj):
                settings = replace(GapSettings(object=obj, seed=seed, actions=30),
                                   **ARMS[arm])
                rep = gap_report(settings, RUNGS)
                for c in rep["configs"]:
                    c = {**c, "newton_iterations_median": float(np.median(
                        [a["newton_iterations"] for a in c["per_action"]]))}
                    rows.append({"object": obj, "seed": seed, "arm": arm, "rung": c["name"],
                                 **{k: c[k] for k in FIELDS}})
                print(obj, seed, arm, [(r["rung"], round(r["ratio_orientation_mean"], 3))
                                       for r in rows[-len(RUNGS):]], flush=True)
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(("object", "seed", "arm", "rung") + FIELDS)
    for r in rows:
        w.writerow([r["object"], r["seed"], r["arm"], r["rung"]]
                   + [f"{r[k]:.4f}" if isinstance(r[k], float) else r[k] for k in FIELDS])
    write_text_atomic(out, buf.getvalue())
    for objs in (CYLINDERS, OBJECTS):
        for arm in ARMS:
            for rung, *_ in RUNGS:
                sel = [r for r in rows if r["object"] in objs and r["arm"] == arm
                       and r["rung"] == rung]
                if len(sel) == 3 * len(objs):
                    print(f"{'cylinders' if objs == CYLINDERS else 'all objects'}, {arm}, "
                          f"{rung}: means over {len(sel)} object-seeds",
                          {k: round(float(np.mean([r[k] for r in sel])), 3) for k in FIELDS})


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit("usage: python docs/scripts/cylinder_stops_gap.py OUT.csv")
    main(sys.argv[1])
