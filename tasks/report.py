"""Summarise `vlr task` runs: `python -m tasks.report DIR [DIR ...]` reads each DIR/result.json
and prints, per task, the mean and SD over runs of each headline error and the successes,
as the Markdown rows of docs/TASKS.md."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

# Headline figures per task: (key in result.json "errors", label, unit).
HEADLINES = {
    "handwriting": [("position_mm_mean", "position error", "mm")],
    "maze": [("orientation_deg_mean", "orientation error", "deg")],
    "cups": [("position_mm_mean", "position error at release", "mm"),
             ("rotation_deg_mean", "rotation error at release", "deg")],
}


def summarize(results: list[dict]) -> list[str]:
    """Markdown rows: task | runs | figure (mean +- SD over runs, and per-run values) |
    successes."""
    rows = []
    for task in sorted({r["task"] for r in results}):
        rs = sorted((r for r in results if r["task"] == task), key=lambda r: r["seed"])
        seeds = ",".join(str(r["seed"]) for r in rs)
        for key, label, unit in HEADLINES.get(task, []):
            v = np.array([r["errors"][key] for r in rs])
            per = ", ".join(f"{x:.2f}" for x in v)
            extra = ""
            if task == "maze":
                extra = f"solved {sum(bool(r.get('solved')) for r in rs)}/{len(rs)}"
            elif task == "handwriting":
                extra = (f"waypoints reached {sum(r['waypoints_reached'] for r in rs)}/"
                         f"{sum(r['waypoints_scored'] for r in rs)}")
            elif task == "cups":
                extra = f"cups stacked {sum(r.get('cups_stacked', 0) for r in rs)}/{4 * len(rs)}"
            lost = sum(bool(r.get("grasp_lost")) for r in rs)
            if lost:
                extra += f", grasp lost in {lost}"
            rows.append(f"| {task} | {seeds} | {label} {v.mean():.2f} +- {v.std():.2f} {unit} "
                        f"({per}) | {extra} |")
    return rows


def main(argv: list[str] | None = None) -> int:
    dirs = [Path(a) for a in (argv if argv is not None else sys.argv[1:])]
    results = []
    for d in dirs:
        f = d / "result.json" if d.is_dir() else d
        if f.is_file() and f.suffix == ".json":
            results.append(json.loads(f.read_text()))
    if not results:
        print("no result.json found", file=sys.stderr)
        return 2
    print("| task | seeds | mean +- SD over runs (per run) | successes |")
    print("|---|---|---|---|")
    print("\n".join(summarize(results)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
