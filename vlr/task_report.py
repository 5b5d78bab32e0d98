"""Summaries of `vlr task` runs over seeds: the headline figure of each task (the paper's
measures), mean and SD over the runs, the per-run values and the successes, as the Markdown
rows of docs/TASKS.md and a CSV with one row per run.

Reads only `result.json` dictionaries, so it lives in `vlr` (the CLI writes the summary of
`vlr task --seeds`) while `python -m vlr.tasks.report DIR ...` prints the same rows for folders
of earlier runs.
"""

from __future__ import annotations

import csv
import io
from pathlib import PurePath
from typing import Any

import numpy as np

__all__ = ["HEADLINES", "PAPER", "policy_label", "summarize", "summary_markdown",
           "summary_csv"]

# Headline figures per task: (key in result.json "errors", label, unit).
HEADLINES: dict[str, list[tuple[str, str, str]]] = {
    "handwriting": [("position_mm_mean", "position error", "mm")],
    "maze": [("orientation_deg_mean", "orientation error", "deg")],
    "cups": [("position_mm_mean", "position error at release", "mm"),
             ("rotation_deg_mean", "rotation error at release", "deg")],
}

# The paper's hardware figures (docs/METHOD.md 6), beside ours in the summary.
PAPER: dict[tuple[str, str], str] = {
    ("handwriting", "position_mm_mean"): "0.42 ± 0.34",
    ("maze", "orientation_deg_mean"): "1.20 ± 1.38",
    ("cups", "position_mm_mean"): "2.1 ± 0.92",
    ("cups", "rotation_deg_mean"): "5.16 ± 1.83",
}


def _successes(task: str, rs: list[dict[str, Any]]) -> str:
    if task == "maze":
        out = f"solved {sum(bool(r.get('solved')) for r in rs)}/{len(rs)}"
    elif task == "handwriting":
        out = (f"waypoints reached {sum(r.get('waypoints_reached', 0) for r in rs)}/"
               f"{sum(r.get('waypoints_scored', 0) for r in rs)}")
    elif task == "cups":
        placed = sum(r.get("cups", 4) for r in rs)   # cups to stack per run
        out = f"cups stacked {sum(r.get('cups_stacked', 0) for r in rs)}/{placed}"
    else:
        out = ""
    lost = sum(bool(r.get("grasp_lost")) for r in rs)
    return out + (f", grasp lost in {lost}" if lost else "")


def policy_label(spec: str) -> str:
    """A run's policy as the summary names it: "baseline", a module's `MODULE:NAME`, a
    file's `FILE.py:NAME` without its folder."""
    where, sep, attr = spec.rpartition(":")
    return f"{PurePath(where).name}:{attr}" if sep else spec


def summarize(results: list[dict[str, Any]]) -> list[str]:
    """Markdown rows: task | seeds | figure (mean +- SD over runs, and per-run values) |
    successes. One row per headline figure of each task and policy present (`vlr task
    --policy`; the task column names a policy other than the baseline), so that runs of
    two policies are never pooled."""
    rows = []
    groups = sorted({(r["task"], r.get("policy", "baseline")) for r in results},
                    key=lambda g: (g[0], g[1] != "baseline", g[1]))
    for task, policy in groups:
        rs = sorted((r for r in results
                     if r["task"] == task and r.get("policy", "baseline") == policy),
                    key=lambda r: r["seed"])
        seeds = ",".join(str(r["seed"]) for r in rs)
        name = task if policy == "baseline" else f"{task}, policy {policy_label(policy)}"
        for key, label, unit in HEADLINES.get(task, []):
            v = np.array([r["errors"][key] for r in rs], dtype=float)
            per = ", ".join(f"{x:.2f}" for x in v)
            rows.append(f"| {name} | {seeds} | {label} {v.mean():.2f} +- {v.std():.2f} {unit} "
                        f"({per}) | {_successes(task, rs)} |")
    return rows


def summary_markdown(results: list[dict[str, Any]], failed: dict[int, str] | None = None,
                     title: str | None = None) -> str:
    """The summary as a Markdown document: the rows of `summarize`, the paper's figures, and
    the seeds that failed (seed -> reason)."""
    lines = [f"# {title}", ""] if title else []
    if results:
        lines += ["| task | seeds | mean +- SD over runs (per run) | successes |",
                  "|---|---|---|---|", *summarize(results), ""]
        paper = [f"{label}: {PAPER[(r_task, key)]} {unit}"
                 for r_task in sorted({r["task"] for r in results})
                 for key, label, unit in HEADLINES.get(r_task, []) if (r_task, key) in PAPER]
        if paper:
            lines += ["The paper (hardware): " + "; ".join(paper) + ".", ""]
    for seed, reason in sorted((failed or {}).items()):
        lines.append(f"- seed {seed} failed: {reason}")
    return "\n".join(lines).rstrip() + "\n"


def summary_csv(results: list[dict[str, Any]]) -> str:
    """One row per run: task, seed, every float in `errors`, the successes' counts, the wall
    time and the policy."""
    keys = sorted({k for r in results for k, v in r.get("errors", {}).items()
                   if isinstance(v, int | float) and not isinstance(v, bool)})
    extra = ["solved", "cups_stacked", "waypoints_reached", "waypoints_scored", "grasp_lost"]
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["task", "seed", *keys, *extra, "wall_s", "policy"])
    for r in sorted(results, key=lambda r: (r["task"], r.get("policy", "baseline"),
                                            r["seed"])):
        e = r.get("errors", {})
        w.writerow([r["task"], r["seed"], *[e.get(k, "") for k in keys],
                    *[r.get(k, "") for k in extra], r.get("timing", {}).get("wall_s", ""),
                    r.get("policy", "baseline")])
    return buf.getvalue()
