"""Per-joint signed errors (estimate minus truth, degrees) of a sweep's trials, by case, for
the posterior mean and median, and the joints' truths: the figures of docs/RESULTS.md 5,
"The posterior median as the estimate" (distal joints on their stops, NF1's shift). Reads
the trial records a sweep wrote (`OUT/trials/*.json`); scoring only, after the fact.

    python docs/scripts/joint_errors.py runs/sweep-sim-60k-surface [--on-stop-deg 0.1]
"""

import argparse
import json
import sys
from pathlib import Path

import numpy as np


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", type=Path, help="a sweep's output folder")
    ap.add_argument("--on-stop-deg", type=float, default=0.1,
                    help="a distal joint whose truth is within this of 0 rests on its open stop")
    args = ap.parse_args()
    paths = sorted((args.out / "trials").glob("*.json"))
    if not paths:
        sys.exit(f"no trial records in {args.out / 'trials'}")
    by_case: dict[str, list[dict]] = {}
    for p in paths:
        rec = json.loads(p.read_text())
        if rec.get("status") == "ok" and "truth_theta" in rec["result"]:
            by_case.setdefault(rec["case"], []).append(rec["result"])
    for case, results in by_case.items():
        print(f"{case} ({len(results)} trials): joint  truth  mean-err  median-err  "
              "[min .. max over trials, degrees]; joints on their stop")
        for joint in results[0]["truth_theta"]:
            truth = np.degrees([r["truth_theta"][joint] for r in results])
            est = {k: np.degrees([r["estimates"][joint][k] for r in results]) - truth
                   for k in ("mean", "median", "high")}
            # The distal joints' open stop is at 0 (models/fingers); the proximal's at -20.
            on = (np.abs(truth) < args.on_stop_deg) & (not joint.endswith(".0"))
            stop = (f"{on.sum()} on stop: median {est['median'][on].min():+.2f} .. "
                    f"{est['median'][on].max():+.2f}, mean {est['mean'][on].min():+.2f} .. "
                    f"{est['mean'][on].max():+.2f}, the interval's top "
                    f"{est['high'][on].min():+.1f} .. {est['high'][on].max():+.1f}"
                    if on.any() else "")
            print(f"  {joint:8s} {truth.min():6.1f} .. {truth.max():5.1f}  "
                  f"{est['mean'].min():+5.1f} .. {est['mean'].max():+5.1f}  "
                  f"{est['median'].min():+5.1f} .. {est['median'].max():+5.1f}  {stop}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
