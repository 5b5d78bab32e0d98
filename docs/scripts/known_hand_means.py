"""The known hand's row of the paper's table, per setting, from sweep tables
(docs/RESULTS.md section 5, sessions 37-38).

A one-off reader, not part of the package. From one or more sweep tables (OUT/table.csv or
a committed docs/results/*.csv) it groups the known-hand trials (no unknowns, no true hand)
by the case's setting (the case name with its object taken out, e.g. "apple, t4" -> "t4")
and prints per group the mean over objects and seeds of the posterior median's proximal
error after the trial's actions and after 15, strict and within-0.1-degree coverage, the
mean 95% joint interval after 15 and the trials that converged.

    python docs/scripts/known_hand_means.py runs/sweep-likelihood-t/table.csv \
        docs/results/sim-scales-075.csv [--seeds 0-4]
"""

import argparse
import csv
from pathlib import Path

import numpy as np

from vlr.errors import UserError
from vlr.sweep import parse_seeds

OBJECTS = ("apple", "wine glass", "gelatin box", "flat screwdriver")


def _setting(case: str) -> str | None:
    """The case's setting with its object taken out; None if not a known-hand object case."""
    for obj in OBJECTS:
        if case == obj or case.startswith(obj + ", "):
            return case[len(obj) + 2:] or "(default)"
    return None


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("tables", type=Path, nargs="+")
    ap.add_argument("--seeds", default=None, help="keep these seeds only, e.g. 0-4")
    args = ap.parse_args()
    try:
        keep = None if args.seeds is None else set(parse_seeds(args.seeds))
    except UserError as e:
        ap.error(str(e))
    missing = [str(p) for p in args.tables if not p.is_file()]
    if missing:
        ap.error(f"no such table: {', '.join(missing)}")
    groups: dict[tuple[str, str], list[dict]] = {}
    for path in args.tables:
        for r in csv.DictReader(path.open()):
            setting = _setting(r["case"])
            if (setting is None or r.get("status") != "ok" or r.get("true_hand")
                    or (keep is not None and int(r["seed"]) not in keep)):
                continue
            groups.setdefault((path.name, setting), []).append(r)
    print("table | setting | trials (objects) | proximal, median, after all / after 15 [deg] "
          "| coverage strict / within 0.1 deg | 95% interval after 15 [deg] | converged")
    for (name, setting), rows in groups.items():
        def col(key: str, rows: list[dict] = rows) -> float:
            return float(np.mean([float(r[key]) for r in rows]))
        objects = len({r["object"] for r in rows})
        converged = sum(r["converged"] == "True" for r in rows)
        print(f"{name} | {setting} | {len(rows)} ({objects}) | {col('proximal_deg_median'):.2f} "
              f"/ {col('proximal_deg_median_at_15'):.2f} | {col('coverage'):.2f} / "
              f"{col('coverage_tolerant'):.2f} | {col('ci_deg_at_15'):.2f} | {converged}")


if __name__ == "__main__":
    main()
