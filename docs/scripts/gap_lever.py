"""What the remaining orientation gap is (docs/RESULTS.md section 5, "The gap that is left").

A one-off diagnostic, not part of the package. From `vlr gap --json` reports (default: the
committed docs/results/gap*.json), per object, seed and model rung:

- the per-action orientation ratio three ways: the mean of the per-action ratios (the
  report's `ratio_orientation_mean`, the issue's measure), their median, and the aggregate
  (the summed errors over the summed true rotations);
- the "lever": the median over actions of position error / orientation error [mm per rad],
  and the correlation of the two errors over the actions. A lever that is the same on every
  seed, with a correlation near 1, says the model's per-action error is a rotation of the
  object about a point that far from the tag.

    python docs/scripts/gap_lever.py [REPORT.json ...]
"""

import argparse
import glob
import json

import numpy as np


def rows(report: dict):
    """(object, seed, rung, mean, median, aggregate, lever_mm, correlation) per model rung."""
    for obj in report.get("objects", [report]):
        for cfg in obj["configs"]:
            acts = [a for a in cfg["per_action"] if a.get("ok")]
            if len(acts) < 3:
                continue
            ep = np.array([a["error_position_mm"] for a in acts])
            eo = np.array([a["error_orientation_deg"] for a in acts])
            mo = np.array([a["motion_orientation_deg"] for a in acts])
            yield (obj["object"], obj["seed"], cfg["name"], float(np.mean(eo / mo)),
                   float(np.median(eo / mo)), float(eo.sum() / mo.sum()),
                   float(np.median(ep / np.radians(eo))), float(np.corrcoef(ep, eo)[0, 1]))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("reports", nargs="*", help="vlr gap --json files")
    args = ap.parse_args()
    paths = args.reports or sorted(glob.glob("docs/results/gap*.json"))
    print("| object | seed | rung | ori. ratio mean | median | aggregate | lever [mm] | corr. |")
    print("|---|---|---|---|---|---|---|---|")
    for path in paths:
        with open(path) as f:
            report = json.load(f)
        for r in rows(report):
            if r[2] in ("+ rolling", "+ friction"):
                print(f"| {r[0]} | {r[1]} | {r[2]} | {r[3]:.3f} | {r[4]:.3f} | {r[5]:.3f} "
                      f"| {r[6]:.0f} | {r[7]:.2f} |")


if __name__ == "__main__":
    main()
