"""Where the truth sits in the particle cloud, action by action, in the synthetic world
(docs/RESULTS.md section 5, session 42).

A one-off diagnostic, not part of the package. It runs one trial of a sweep file's case in
the synthetic world, whose truth is a motion-model state, and after each update prints:

- the log-likelihood of the observation under the truth's own state (`ll_truth`) against
  the particles' best and median (`ll_max`, `ll_median`). A truth that scores below every
  particle points at a model-world gap; one that scores as well as the best, while lying
  outside the cloud, at the filter losing the truth's region (particle impoverishment);
- the share of the cloud's 95% intervals (per dimension) that hold the truth, and the three
  dimensions where the truth is furthest from the median, in the cloud's standard
  deviations (z);
- `shadow`: the truth at the grasp propagated by the filter's own motion model with the
  trial's commands, against the world's truth (POM position [mm], largest joint angle
  [deg]). Zero means the world moves exactly as the filter's model predicts.

The truth is read for this report only; the filter never sees it. Scoring-only.

    python docs/scripts/truth_in_cloud.py docs/sweeps/synthetic-h.yaml \
        --case "synthetic, h 0.4" --seed 0 [--set particles=3000] [--csv out.csv]
"""

import argparse
import csv
import json
from pathlib import Path

import numpy as np

from vlr.errors import UserError
from vlr.sweep import expand, load_sweep
from vlr.trial import identify_trial

COLUMNS = ("iteration", "beta", "ess", "ll_truth", "ll_max", "ll_median", "coverage",
           "shadow_mm", "shadow_deg", "worst")


def pick_settings(sweep: Path, case: str, seed: int, overrides: list[str]):
    """The TrialSettings of `case` at `seed` in the sweep file, with `key=json` overrides."""
    trials = [t for t in expand(load_sweep(sweep)) if t.case == case and t.settings.seed == seed]
    if not trials:
        cases = sorted({t.case for t in expand(load_sweep(sweep))})
        raise UserError(f"{sweep}: no trial of case {case!r} at seed {seed}; cases: {cases}")
    settings = trials[0].settings.to_dict()
    for item in overrides:
        key, sep, value = item.partition("=")
        if not sep or key not in settings:
            raise UserError(f"--set {item!r}: give KEY=VALUE with KEY a trial setting")
        try:
            settings[key] = json.loads(value)
        except json.JSONDecodeError:
            settings[key] = value
    from vlr.trial import TrialSettings

    s = TrialSettings(**settings)
    if s.backend != "synthetic":
        raise UserError(f"backend {s.backend!r}: the truth is a model state only in the "
                        "synthetic world")
    return s


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("sweep", type=Path)
    ap.add_argument("--case", required=True)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    ap.add_argument("--csv", type=Path, default=None)
    args = ap.parse_args()
    if args.csv is not None and not args.csv.parent.is_dir():
        raise UserError(f"--csv {args.csv}: no folder {args.csv.parent}")
    settings = pick_settings(args.sweep, args.case, args.seed, args.set)
    rows: list[dict] = []
    box: dict = {}

    def through(world):
        def observe():
            box["obs"] = world.observer()
            box["truth"] = world.world.state.copy()
            return box["obs"]
        return observe

    def watch(pf, rec):
        obs, truth = box["obs"], box["truth"]
        shadow_mm = shadow_deg = 0.0
        if "shadow" not in box:
            box["shadow"], box["u"] = truth.copy(), pf.command.copy()
        else:
            sh = box["shadow"]
            pf.motion.solve(sh, pf.command, u_from=box["u"])
            box["u"] = pf.command.copy()
            shadow_mm = float(np.linalg.norm(sh.pos[0] - truth.pos[0]) * 1e3)
            shadow_deg = float(np.degrees(np.abs(sh.theta[0] - truth.theta[0]).max()))
        before, pf._before = pf._before, None   # the pose term alone, for both
        ll_truth = float(pf._log_likelihood(truth, obs)[0])
        ll = pf._log_likelihood(pf.state, obs)
        pf._before = before
        x, xt = pf.pack(pf.state), pf.pack(truth)[0]
        lo, hi = np.percentile(x, [2.5, 97.5], axis=0)
        z = (xt - np.median(x, axis=0)) / np.maximum(x.std(axis=0), 1e-12)
        worst = " ".join(f"{pf.dim_names[j]}:{z[j]:+.1f}" for j in np.argsort(-np.abs(z))[:3])
        row = {"iteration": rec.iteration, "beta": round(float(rec.beta), 3),
               "ess": round(float(rec.ess), 1), "ll_truth": round(ll_truth, 2),
               "ll_max": round(float(ll.max()), 2),
               "ll_median": round(float(np.median(ll)), 2),
               "coverage": round(float(((xt >= lo) & (xt <= hi)).mean()), 2),
               "shadow_mm": round(shadow_mm, 4), "shadow_deg": round(shadow_deg, 4),
               "worst": worst}
        rows.append(row)
        print("  ".join(f"{k} {row[k]}" for k in COLUMNS), flush=True)

    identify_trial(settings, watch=watch, observe_through=through)
    if args.csv is not None:
        tmp = args.csv.with_suffix(args.csv.suffix + ".tmp")
        with tmp.open("w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=COLUMNS)
            w.writeheader()
            w.writerows(rows)
        tmp.replace(args.csv)
    late = rows[len(rows) // 2:]
    print(f"second half: truth beats the best particle on "
          f"{sum(r['ll_truth'] > r['ll_max'] for r in late)} of {len(late)} updates; "
          f"the truth's log-likelihood above the median particle's by "
          f"{np.mean([r['ll_truth'] - r['ll_median'] for r in late]):+.2f} per update; "
          f"median coverage {np.median([r['coverage'] for r in late]):.2f}; "
          f"largest shadow {max(r['shadow_mm'] for r in rows):.4f} mm")


if __name__ == "__main__":
    try:
        main()
    except UserError as exc:
        raise SystemExit(f"error: {exc}") from None
