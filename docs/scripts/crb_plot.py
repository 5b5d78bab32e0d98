"""The filter's 95% joint interval against its Cramér-Rao floor, action by action
(docs/RESULTS.md section 2, "What limits the intervals").

A one-off plot, not part of the package. Reads `vlr crb --sweep ... --json` reports (random
and oracle actions) and a sweep folder whose trials recorded `ci_deg_by_iteration`, and draws
for each object one panel: the filter's mean interval per seed, the floor at the likelihood's
and at the camera's scales (random actions), the oracle's floor (medians over the seeds, the
runs that lost their grasp left out), and the 2-degree criterion.

    python docs/scripts/crb_plot.py docs/results/crb-random.json docs/results/crb-oracle8.json \
        runs/sweep-sim-active-variance --out docs/img/crb.png
"""

import argparse
import json
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

OBJECTS = ("apple", "wine glass", "gelatin box", "flat screwdriver")


def floors(path: Path, key: str) -> dict[tuple[str, int], np.ndarray]:
    """(case, seed) -> the floor [deg] after 0..n actions."""
    trials = json.loads(path.read_text())["trials"]
    return {(t["case"], t["seed"]): np.array([r[key] for r in t["by_action"]]) for t in trials}


def filter_intervals(out: Path) -> dict[tuple[str, int], np.ndarray]:
    """(object case, seed) -> the filter's mean 95% interval [deg] after 0..n actions, from
    the sweep's random-action cases ("apple, random")."""
    res = {}
    for f in sorted((out / "trials").glob("*.json")):
        rec = json.loads(f.read_text())
        name = rec["case"]
        if rec.get("status") != "ok" or not name.endswith(", random"):
            continue
        res[(name.removesuffix(", random"), rec["settings"]["seed"])] = np.array(
            rec["result"]["ci_deg_by_iteration"])
    return res


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("random", type=Path, help="vlr crb --sweep JSON, random actions")
    ap.add_argument("oracle", type=Path, help="vlr crb --sweep JSON, --candidates K")
    ap.add_argument("sweep", type=Path, help="sweep folder with the filter's random trials")
    ap.add_argument("--out", type=Path, default=Path("crb.png"))
    args = ap.parse_args()
    for p in (args.random, args.oracle, args.sweep):
        if not p.exists():
            raise SystemExit(f"{p}: not found")
    lik, cam = floors(args.random, "mean_width_deg"), floors(args.random, "mean_width_deg_camera")
    orc = floors(args.oracle, "mean_width_deg")
    filt = filter_intervals(args.sweep)
    fig, axes = plt.subplots(1, len(OBJECTS), figsize=(4 * len(OBJECTS), 3.6), sharey=True)
    for ax, obj in zip(axes, OBJECTS, strict=True):
        for (case, seed), ci in sorted(filt.items()):
            if case == obj:
                ax.plot(ci, color="tab:blue", lw=1, alpha=0.8,
                        label="filter, 10k particles" if seed == 0 else None)
        for series, color, label in ((lik, "tab:red", "floor, likelihood 0.35 mm / 0.7 deg"),
                                     (orc, "tab:orange", "floor, oracle actions (8)"),
                                     (cam, "tab:green", "floor, camera 0.05 mm / 0.2 deg")):
            runs = [v for (case, _), v in series.items() if case == obj]
            n = max(len(v) for v in runs)  # the oracle may lose a grasp: those runs end early
            ax.plot(np.median([v for v in runs if len(v) == n], axis=0), color=color, lw=2,
                    label=label)
        ax.axhline(2.0, color="k", ls="--", lw=1, label="paper's criterion, 2 deg")
        ax.axvline(15, color="0.6", ls=":", lw=1)
        ax.set_title(obj)
        ax.set_xlabel("actions")
        ax.set_yscale("log")
        ax.set_ylim(0.3, 40)
    axes[0].set_ylabel("mean 95% joint interval [deg]")
    axes[-1].legend(fontsize=7, loc="upper right")
    fig.tight_layout()
    fig.savefig(args.out, dpi=110)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
