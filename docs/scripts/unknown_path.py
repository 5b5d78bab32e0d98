"""Each unknown's error along a sweep's trials, at chosen action counts (docs/RESULTS.md
section 2, "The stiffness row with 40 actions").

A one-off reader, not part of the package. For every finished trial of a sweep folder it
reads `unknown_error_by_iteration` from the trial record (entry 0 is the grasp's update,
entry n the error after n actions; SI units) and prints, per case and unknown, the error at
each asked action count per seed, and the mean and sd over seeds. With `--median` it reads
the posterior median's errors instead, every joint's mean error [deg] as the unknown
`joints` and the replaced proximal links' mean error [mm] as `proximal links [mm]`, the
paper's figures (trials recorded since session 28). Several sweep folders pool their seeds
per case (session 29: seeds 0-4 of one sweep and held-out seeds 5-9 of another, the same
cases); a seed found twice is an error.

    python docs/scripts/unknown_path.py runs/sweep-sim-60k-stiffness-40 [--at 15 20 30 40]
    python docs/scripts/unknown_path.py runs/sweep-sim-60k-surface-stops-40 \
        runs/sweep-sim-60k-surface-stops-40-heldout --median --at 20 30 40
    python docs/scripts/unknown_path.py runs/sweep-sim-60k-log-scales --median --at 35 \
        --seeds 5-14
"""

import argparse
import json
from pathlib import Path

import numpy as np


def paths(out: Path, median: bool = False):
    """(case, seed, unknown, errors per iteration) of each finished trial in OUT/trials."""
    for f in sorted((out / "trials").glob("*.json")):
        rec = json.loads(f.read_text())
        if rec.get("status") != "ok":
            continue
        res = rec["result"]
        key = "unknown_error_median_by_iteration" if median else "unknown_error_by_iteration"
        if median and "joint_median_deg_by_iteration" not in res:
            raise SystemExit(f"{f} has no posterior-median path: recorded before session 28")
        by_it = res.get(key) or {}   # none for a trial without unknowns
        for spec, errs in by_it.items():
            yield rec["case"], rec["settings"]["seed"], spec, errs
        if median:
            yield rec["case"], rec["settings"]["seed"], "joints", \
                res["joint_median_deg_by_iteration"]
            prox = [v for spec, v in by_it.items() if spec.endswith(".proximal")]
            if prox:  # the paper's link figure: the replaced proximal links' mean [mm]
                yield rec["case"], rec["settings"]["seed"], "proximal links [mm]", \
                    list(np.mean(np.array(prox), axis=0) * 1e3)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", type=Path, nargs="+", help="sweep output folders (seeds pooled)")
    ap.add_argument("--at", type=int, nargs="+", default=[15, 20, 30, 40],
                    help="action counts (default 15 20 30 40)")
    ap.add_argument("--median", action="store_true",
                    help="the posterior median's errors, and every joint's mean error [deg]")
    ap.add_argument("--seeds", default=None, metavar="SEEDS",
                    help="only these seeds, e.g. 5-14 (a held-out set; default all)")
    args = ap.parse_args()
    keep = None
    if args.seeds is not None:
        from vlr.errors import UserError
        from vlr.sweep import parse_seeds
        try:
            keep = set(parse_seeds(args.seeds))
        except UserError as e:
            ap.error(str(e))
    for out in args.out:
        if not (out / "trials").is_dir():
            ap.error(f"{str(out)!r} has no trials/ folder: not a sweep's output folder")
    groups: dict[tuple[str, str], dict[int, list[float]]] = {}
    for out in args.out:
        for case, seed, spec, errs in paths(out, args.median):
            if keep is not None and seed not in keep:
                continue
            row = [errs[n] if n < len(errs) else float("nan") for n in args.at]
            print(f"{case} | {spec} | seed {seed} | "
                  + " ".join(f"{n}: {e:.4g}" for n, e in zip(args.at, row, strict=True)))
            seeds = groups.setdefault((case, spec), {})
            if seed in seeds:
                ap.error(f"{case!r} seed {seed} is in more than one folder ({out})")
            seeds[seed] = row
    for (case, spec), seeds in groups.items():
        a = np.array(list(seeds.values()))
        print(f"{case} | {spec} | {len(seeds)} seeds | " + " ".join(
            f"{n}: {np.nanmean(a[:, j]):.4f} ± {np.nanstd(a[:, j], ddof=1):.4f}"
            for j, n in enumerate(args.at)))


if __name__ == "__main__":
    main()
