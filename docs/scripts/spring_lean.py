"""The spring row's lean, per case of a sweep (docs/RESULTS.md section 5, sessions 36-37).

A one-off reader, not part of the package. From sweep tables (a sweep's OUT/table.csv or a
committed docs/results/*.csv) it prints per case the thumb spring's final posterior
median (mean, sd over seeds, how many above the truth), its 95% interval's mean width (and
the width over 3.92, a Gaussian's standard deviation) and how many hold the truth, and the
coverage columns. From sweep folders (OUT/trials/*.json, which keep each joint's estimate
and truth) it prints per case each joint's mean signed error of the posterior median
[deg], and for one joint its error where the truth lies near its open stop at 0 and
further, with their correlation.

    python docs/scripts/spring_lean.py docs/results/spring-scales.csv docs/results/spring-lean.csv
    python docs/scripts/spring_lean.py runs/sweep-spring-guess runs/sweep-spring-discount \
        [--joint right.1] [--near 3.5] [--exclude 0.5x]
"""

import argparse
import csv
import json
from pathlib import Path

import numpy as np

TRUTH = 0.045  # the sim's thumb distal spring on modelo_thumb45 [N m/rad]
SPRING = "spring_thumb.distal"


def from_tables(paths: list[Path]) -> None:
    for path in paths:
        rows = [r for r in csv.DictReader(path.open()) if r.get(f"{SPRING}.median")]
        cases: dict[str, list[dict]] = {}
        for r in rows:
            cases.setdefault(r["case"], []).append(r)
        for case, group in cases.items():
            med = np.array([float(r[f"{SPRING}.median"]) for r in group])
            lo = np.array([float(r[f"{SPRING}.low"]) for r in group])
            hi = np.array([float(r[f"{SPRING}.high"]) for r in group])
            held = int(((lo <= TRUTH) & (hi >= TRUTH)).sum())
            cov = np.mean([float(r["coverage"]) for r in group])
            tol = np.mean([float(r["coverage_tolerant"]) for r in group])
            print(f"{path.name} | {case} | {len(med)} seeds | estimate mean {med.mean():.4f} "
                  f"sd {med.std(ddof=1):.4f}, above the truth {int((med > TRUTH).sum())} | "
                  f"interval width {(hi - lo).mean():.4f} (sd {(hi - lo).mean() / 3.92:.4f}), "
                  f"holds the truth {held} | coverage {cov:.2f} / {tol:.2f}")


def from_trials(folders: list[Path], joint: str, near: float, exclude: list[str]) -> None:
    pooled_t, pooled_e = [], []
    for folder in folders:
        cases: dict[str, list[tuple[list[float], float, float]]] = {}
        names: list[str] = []
        for f in sorted((folder / "trials").glob("*.json")):
            rec = json.loads(f.read_text())
            if rec.get("status") != "ok" or any(x in rec["case"] for x in exclude):
                continue
            res = rec["result"]
            names = list(res["truth_theta"])
            err = [float(np.degrees(res["estimates"][n]["median"] - res["truth_theta"][n]))
                   for n in names]
            cases.setdefault(rec["case"], []).append(
                (err, float(np.degrees(res["truth_theta"][joint])),
                 float(np.degrees(res["estimates"][joint]["median"]
                                  - res["truth_theta"][joint]))))
        for case, group in cases.items():
            e = np.array([g[0] for g in group])
            print(f"{folder.name} | {case} | {len(group)} seeds | signed error [deg] "
                  + ", ".join(f"{n} {v:+.2f}" for n, v in zip(names, e.mean(axis=0),
                                                              strict=True)))
            _near_stop(f"{folder.name} | {case} | {joint}", [g[1] for g in group],
                       [g[2] for g in group], near)
            pooled_t += [g[1] for g in group]
            pooled_e += [g[2] for g in group]
    _near_stop(f"all | {joint}", pooled_t, pooled_e, near)


def _near_stop(label: str, truth: list[float], error: list[float], near: float) -> None:
    """A joint's mean error where its truth lies within `near` degrees of the stop at 0 and
    further, and the correlation of error and truth."""
    t, e = np.array(truth), np.array(error)
    if (t < near).sum() < 1 or (t >= near).sum() < 1:
        return
    print(f"{label} over {len(t)} trials: truth within {near:g} deg of the stop "
          f"({(t < near).sum()} trials, {t[t < near].min():.1f}-{t[t < near].max():.1f}) "
          f"error {e[t < near].mean():+.2f}; further ({(t >= near).sum()}) "
          f"{e[t >= near].mean():+.2f}; correlation {np.corrcoef(t, e)[0, 1]:.2f}")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("paths", nargs="+", type=Path, help="table CSVs or sweep folders")
    p.add_argument("--joint", default="right.1", help="the joint of the near-stop split")
    p.add_argument("--near", type=float, default=3.5, help="near the stop: truth below [deg]")
    p.add_argument("--exclude", nargs="+", action="extend", default=[],
                   help="skip cases naming any of these (repeatable)")
    args = p.parse_args()
    tables = [x for x in args.paths if x.is_file()]
    folders = [x for x in args.paths if x.is_dir()]
    missing = [x for x in args.paths if not x.exists()]
    if missing:
        raise SystemExit(f"no such table or sweep folder: {', '.join(map(str, missing))}")
    if tables:
        from_tables(tables)
    if folders:
        from_trials(folders, args.joint, args.near, args.exclude)


if __name__ == "__main__":
    main()
