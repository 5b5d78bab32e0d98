"""How wide a sweep's intervals are against its errors (docs/RESULTS.md 5, session 25).

For every joint of every trial: z = (posterior median - truth) / (95% interval width / 3.92),
the error in units of the standard deviation the interval implies. For a calibrated Gaussian
posterior the median |z| is 0.67; well under it, the intervals are wider than the errors
need (the likelihood too loose for this case); over it, narrower. Per case, the median |z|
of the proximal and of the distal joints, their median error and interval width. Reads the
trial records a sweep writes (OUT/trials/*.json); a one-off analysis, not part of the package.

    python docs/scripts/calibration.py runs/sweep-sim-60k-surface
"""

import argparse
import json
import sys
from collections import defaultdict
from pathlib import Path

import numpy as np


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("out", type=Path, help="a sweep's output folder")
    args = p.parse_args()
    paths = sorted((args.out / "trials").glob("*.json"))
    if not paths:
        sys.exit(f"{args.out}: no trial records in {args.out / 'trials'}")
    rows: dict[str, list[tuple[int, float, float]]] = defaultdict(list)
    for path in paths:
        rec = json.loads(path.read_text())
        if rec.get("status") != "ok":
            continue
        r = rec["result"]
        for key, truth in r["truth_theta"].items():
            e = r["estimates"][key]
            width = e["high"] - e["low"]
            err = e["median"] - truth
            z = abs(err) / (width / 3.92) if width > 0 else np.inf
            rows[rec["case"]].append((int(key.split(".")[1]), np.degrees(abs(err)),
                                      np.degrees(width), z))
    print(f"{'case':44s} {'joint':8s} {'|err| median':>12s} {'width median':>12s} "
          f"{'|z| median':>10s}  (0.67 if calibrated)")
    for case, v in rows.items():
        for j, name in ((0, "proximal"), (1, "distal")):
            a = np.array([x[1:] for x in v if x[0] == j])
            print(f"{case[:44]:44s} {name:8s} {np.median(a[:, 0]):12.2f} "
                  f"{np.median(a[:, 1]):12.2f} {np.median(a[:, 2]):10.2f}")


if __name__ == "__main__":
    main()
