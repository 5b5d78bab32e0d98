"""`vlr gap --json` reports, one row per object and seed: the full model's (last rung's)
per-action ratios, its open-loop drift and its failed solves, as CSV (docs/RESULTS.md
section 5, session 30: `docs/results/gap-ramp.csv`). Besides the issue's measure, the mean
of the per-action ratios, the pooled ratio: the actions' summed error over their summed true
motion (the solved actions), which an action that hardly moves the object cannot inflate.

A reader, not part of the package. Each report is a `vlr gap --object all --json` file (or
one object's); LABEL=FILE names the setting it was measured with.

    python docs/scripts/gap_table.py "terms 27, ramp 0.1=/tmp/s27-s0.json" ... [--out FILE]
"""

import argparse
import csv
import io
import json
import sys
from pathlib import Path

from vlr.io import write_text_atomic

COLUMNS = ("setting", "object", "seed", "ramp_time", "start", "actions", "ratio_position",
           "ratio_orientation", "pooled_position", "pooled_orientation", "drift_position",
           "drift_orientation", "failed_solves")


def _pooled(per_action: list[dict], kind: str) -> float:
    """Summed error over summed true motion of the solved actions (`kind`: "position" or
    "orientation")."""
    unit = "mm" if kind == "position" else "deg"
    ok = [a for a in per_action if a["ok"]]
    motion = sum(a[f"motion_{kind}_{unit}"] for a in ok)
    return sum(a[f"error_{kind}_{unit}"] for a in ok) / motion if motion > 0 else float("nan")


def rows(label: str, path: str) -> list[dict]:
    try:
        rep = json.loads(Path(path).read_text())
    except (OSError, json.JSONDecodeError) as exc:
        sys.exit(f"{path}: not a readable vlr gap report ({exc})")
    out = []
    for o in rep.get("objects", [rep]):
        if "configs" not in o:
            sys.exit(f"{path}: not a vlr gap report (no 'configs')")
        c = o["configs"][-1]
        out.append({"setting": label, "object": o["object"], "seed": o["seed"],
                    "ramp_time": o.get("ramp_time", 0.05), "start": o.get("start", "settle"),
                    "actions": o["actions"],
                    "ratio_position": round(c["ratio_position_mean"], 4),
                    "ratio_orientation": round(c["ratio_orientation_mean"], 4),
                    "pooled_position": round(_pooled(c["per_action"], "position"), 4),
                    "pooled_orientation": round(_pooled(c["per_action"], "orientation"), 4),
                    "drift_position": round(c["drift_ratio"], 4),
                    "drift_orientation": round(c["drift_ratio_orientation"], 4),
                    "failed_solves": c["failed_solves"]})
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("reports", nargs="+", metavar="LABEL=FILE")
    ap.add_argument("--out", help="write the CSV here (default: print it)")
    args = ap.parse_args()
    if args.out and not Path(args.out).resolve().parent.is_dir():
        ap.error(f"--out {args.out}: its folder does not exist")
    table = []
    for item in args.reports:
        label, sep, path = item.rpartition("=")
        if not sep or not label:
            ap.error(f"{item!r}: expected LABEL=FILE")
        table += rows(label, path)
    buf = io.StringIO()
    w = csv.DictWriter(buf, COLUMNS)
    w.writeheader()
    w.writerows(table)
    if args.out:
        write_text_atomic(args.out, buf.getvalue())
    else:
        print(buf.getvalue(), end="")
    by = {}
    for r in table:
        by.setdefault((r["setting"], r["ramp_time"]), []).append(r)
    for (label, ramp), rs in by.items():
        ori = [r["ratio_orientation"] for r in rs]
        pooled = [r["pooled_orientation"] for r in rs]
        drift = [r["drift_orientation"] for r in rs]
        print(f"{label}, ramp {ramp:g} s: {len(rs)} object-seeds, orientation mean "
              f"{sum(ori) / len(ori):.3f}, "
              f"{sum(v > 0.10 for v in ori)} over 0.10; pooled {sum(pooled) / len(pooled):.3f}, "
              f"{sum(v > 0.10 for v in pooled)} over 0.10; drift in orientation at most "
              f"{max(drift):.3f}, {sum(v > 0.05 for v in drift)} over 0.05", file=sys.stderr)


if __name__ == "__main__":
    main()
