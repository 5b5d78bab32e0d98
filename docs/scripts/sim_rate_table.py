"""The model's per-action orientation gap beside the sim's own indeterminacy
(docs/RESULTS.md section 5, session 38).

A one-off reader, not part of the package. Joins, per object, seed and action, the sim's own
outcome under other ramp times (`docs/scripts/sim_rate_probe.py --json`) with `vlr gap`'s
per-action ratios of the friction rung (`vlr gap --json`, one or more labelled runs at the
probe's reference ramp), checks that both walked the same path (the true motion of every
action agrees), writes the joined rows as CSV and prints per object-seed: the model's mean
and median ratio, the sim's own (the larger of its 0.05 s and 0.5 s outcomes against the
0.1 s reference), how many actions the sim itself leaves more than 0.10 apart, and the
model's mean on those and on the rest.

    python docs/scripts/sim_rate_table.py --probes DIR --gap settle=FILE ... [--gap ...]
        [--out docs/results/sim-rate.csv]
"""

import argparse
import csv
import json
from pathlib import Path

import numpy as np

AMBIGUOUS = 0.10           # the per-action bound, applied to the sim against itself
NEAR = ("ramp 0.05 s", "ramp 0.5 s")


def _gap_actions(path: Path) -> dict[tuple[str, int], dict[int, dict]]:
    runs = json.loads(path.read_text())
    runs = runs["objects"] if "objects" in runs else [runs]     # `--object all` or one
    return {(r["object"], r["seed"]): {a["action"]: a for a in r["configs"][-1]["per_action"]}
            for r in runs}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--probes", type=Path, required=True)
    ap.add_argument("--gap", action="append", required=True, metavar="LABEL=FILE")
    ap.add_argument("--out", type=Path, default=None)
    args = ap.parse_args()
    gaps: dict[str, dict] = {}
    for item in args.gap:
        label, _, file = item.partition("=")
        if not file:
            ap.error(f"--gap {item!r}: use LABEL=FILE")
        gaps[label] = {}
        for f in file.split(","):
            if not Path(f).is_file():
                ap.error(f"--gap {item!r}: no such file {f!r}")
            gaps[label].update(_gap_actions(Path(f)))
    if not args.probes.is_dir():
        ap.error(f"--probes {args.probes}: not a folder")
    rows = []
    for probe in sorted(args.probes.glob("*.json")):
        p = json.loads(probe.read_text())
        if "per_action" not in p or "reference_ramp" not in p:
            continue
        key = (p["object"], p["seed"])
        for a in p["per_action"]:
            row = {"object": key[0], "seed": key[1], "action": a["action"],
                   "motion_orientation_deg": a["motion_orientation_deg"],
                   "sim_near_ramps": max(a[n]["ratio_orientation"] for n in NEAR),
                   "sim_ramp_2s": a["ramp 2 s"]["ratio_orientation"],
                   "sim_hold_4s": a["hold 4 s"]["ratio_orientation"]}
            for label, g in gaps.items():
                ga = g.get(key, {}).get(a["action"])
                if ga is None or not ga["ok"]:
                    row[f"model_{label}"] = float("nan")
                    continue
                if abs(ga["motion_orientation_deg"] - a["motion_orientation_deg"]) > 1e-6:
                    raise SystemExit(f"{key} action {a['action']}: the probe and vlr gap "
                                     "walked different paths (their true motions differ)")
                row[f"model_{label}"] = ga["ratio_orientation"]
            rows.append(row)
    if not rows:
        raise SystemExit(f"no probe JSONs in {args.probes}")
    if args.out is not None:
        tmp = args.out.with_suffix(args.out.suffix + ".tmp")
        with tmp.open("w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=list(rows[0]))
            w.writeheader()
            w.writerows({k: (round(v, 5) if isinstance(v, float) else v)
                         for k, v in r.items()} for r in rows)
        tmp.replace(args.out)
    for label in gaps:
        col = f"model_{label}"
        print(f"== vlr gap '{label}', friction rung, orientation ratio per action")
        print("object seed | model mean / median | sim's own near 0.1 s: mean / median, "
              f"actions over {AMBIGUOUS} | model's mean on those / on the rest")
        all_g, all_a = [], []
        for key in dict.fromkeys((r["object"], r["seed"]) for r in rows):
            sel = [r for r in rows if (r["object"], r["seed"]) == key and np.isfinite(r[col])]
            g = np.array([r[col] for r in sel])
            a = np.array([r["sim_near_ramps"] for r in sel])
            amb = a > AMBIGUOUS
            all_g += list(g)
            all_a += list(a)
            on = f"{g[amb].mean():.3f}" if amb.any() else "-"
            print(f"{key[0]} {key[1]} | {g.mean():.3f} / {np.median(g):.3f} | {a.mean():.3f} / "
                  f"{np.median(a):.3f}, {int(amb.sum())} | {on} / {g[~amb].mean():.3f}")
        g, a = np.array(all_g), np.array(all_a)
        amb = a > AMBIGUOUS
        print(f"all {len(g)} actions | {g.mean():.3f} / {np.median(g):.3f} | {a.mean():.3f} / "
              f"{np.median(a):.3f}, {int(amb.sum())} | {g[amb].mean():.3f} / "
              f"{g[~amb].mean():.3f}; those {int(amb.sum())} carry "
              f"{g[amb].sum() / g.sum():.2f} of the summed ratios")


if __name__ == "__main__":
    main()
