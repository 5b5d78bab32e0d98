"""Two settings' trials compared seed by seed, from sweep tables (docs/RESULTS.md section 5,
session 40).

A one-off reader, not part of the package. Each side is one or more sweep tables
(OUT/table.csv or committed docs/results/*.csv); a trial of side B is paired with the
trial of side A of the same case and seed, the case's name in B taken with `--suffix`
removed (so "apple, mass, copula-scales" pairs with "apple, mass"). For the chosen error
column it prints, per case and over all pairs, each side's mean and on how many pairs B is
lower (better) or higher.

    python docs/scripts/paired_trials.py --a docs/results/sim-scales-075.csv \
        --b docs/results/jitter-copula-joints-known.csv --column joints_deg
    python docs/scripts/paired_trials.py --a docs/results/jitter-copula-scales-mass.csv \
        --b docs/results/jitter-copula-scales-mass.csv --suffix ", copula-scales" \
        --column object_mass_g_median
"""

import argparse
import csv
from pathlib import Path

import numpy as np

from vlr.errors import UserError


def read(paths: list[Path], column: str) -> dict[tuple[str, int], float]:
    """{(case, seed): value of `column`} over the tables; a missing file or column is named."""
    out: dict[tuple[str, int], float] = {}
    for path in paths:
        if not path.is_file():
            raise UserError(f"{path}: no such file")
        with path.open(newline="") as f:
            rows = list(csv.DictReader(f))
        for name in ("case", "seed", column):
            if rows and name not in rows[0]:
                raise UserError(f"{path}: no column {name!r} (not a sweep table?)")
        for r in rows:
            if r.get(column) not in (None, ""):
                try:
                    out[(r["case"], int(r["seed"]))] = float(r[column])
                except ValueError:
                    raise UserError(f"{path}: case {r['case']!r} seed {r['seed']!r}: "
                                    f"{column} {r[column]!r} is not a number") from None
    return out


def pairs(a: dict, b: dict, suffix: str) -> dict[str, list[tuple[float, float]]]:
    """{case: [(A's value, B's value) per seed]} for B's trials whose case ends with
    `suffix` (every trial when it is empty) and has a match in A."""
    out: dict[str, list[tuple[float, float]]] = {}
    for (case, seed), vb in sorted(b.items()):
        if suffix and not case.endswith(suffix):
            continue
        base = case[: len(case) - len(suffix)] if suffix else case
        if (base, seed) in a:
            out.setdefault(base, []).append((a[(base, seed)], vb))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--a", type=Path, nargs="+", required=True, help="side A's tables")
    ap.add_argument("--b", type=Path, nargs="+", required=True, help="side B's tables")
    ap.add_argument("--column", required=True, help="an error column, e.g. joints_deg")
    ap.add_argument("--suffix", default="", help="taken off B's case names to pair them")
    args = ap.parse_args()
    try:
        found = pairs(read(args.a, args.column), read(args.b, args.column), args.suffix)
        if not found:
            raise UserError("no trial of B has a trial of A of the same case and seed")
    except UserError as exc:
        raise SystemExit(f"error: {exc}") from None
    every = [p for ps in found.values() for p in ps]
    for case, ps in [*found.items(), ("all", every)]:
        v = np.array(ps)
        lower, higher = int(np.sum(v[:, 1] < v[:, 0])), int(np.sum(v[:, 1] > v[:, 0]))
        print(f"{case} | {len(v)} pairs | A {v[:, 0].mean():.4g} | B {v[:, 1].mean():.4g} "
              f"| B lower on {lower}, higher on {higher}")


if __name__ == "__main__":
    main()
