"""Where an unknown's 95% interval is symmetric: on its values or on its logarithm, from sweep
tables (docs/RESULTS.md section 5, session 41).

A one-off reader, not part of the package. For an unknown's columns `PREFIX.median`,
`PREFIX.low` and `PREFIX.high` (the posterior's median and 95% interval at the last action)
it prints per case the median over seeds of the interval's upper arm over its lower arm on the
values, (high - median) / (median - low), and on the logarithms; 1 is symmetric. A posterior
the likelihood barely shapes takes the shape of the filter's kernel: symmetric on the values
with the Gaussian kernel, on the logarithms with `log-scales`.

    python docs/scripts/interval_shape.py docs/results/jitter-copula-scales-mass.csv \
        docs/results/jitter-log-scales-mass.csv --unknown mass_g
"""

import argparse
import csv
from pathlib import Path

import numpy as np

from vlr.errors import UserError


def arms(path: Path, prefix: str) -> dict[str, list[tuple[float, float]]]:
    """{case: [(values' arm ratio, logs' arm ratio) per trial]} of one table."""
    if not path.is_file():
        raise UserError(f"table {path}: no such file")
    out: dict[str, list[tuple[float, float]]] = {}
    with path.open(newline="") as f:
        for row in csv.DictReader(f):
            try:
                med, lo, hi = (float(row[f"{prefix}.{k}"]) for k in ("median", "low", "high"))
            except KeyError:
                raise UserError(f"table {path}: no columns {prefix}.median/.low/.high") from None
            except ValueError:
                continue                              # a failed trial's empty cells
            if not lo < med < hi or lo <= 0:
                continue
            out.setdefault(row.get("case", "?"), []).append(
                ((hi - med) / (med - lo), np.log(hi / med) / np.log(med / lo)))
    return out


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("tables", nargs="+", type=Path)
    p.add_argument("--unknown", required=True, metavar="PREFIX",
                   help="the unknown's column prefix, e.g. mass_g or spring_thumb.distal")
    args = p.parse_args()
    try:
        for path in args.tables:
            for case, r in arms(path, args.unknown).items():
                v, g = np.median(np.array(r), axis=0)
                print(f"{case} | {len(r)} trials | values {v:.2f} | logarithms {g:.2f}")
    except UserError as e:
        raise SystemExit(f"interval_shape.py: {e}") from None


if __name__ == "__main__":
    main()
