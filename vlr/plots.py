"""Trial pictures besides `convergence.png`: the particle cloud at chosen iterations, and box
plots of errors over many trials (for sweeps).

* `CloudRecorder` is a `watch(pf, rec)` hook for `vlr.identify.identify`: it keeps a small
  sample of each iteration's joint angles, so the picture can be drawn after the run (a few
  hundred kB for a 40-iteration run; no cost worth measuring against a filter update).
* `particle_cloud` draws, per finger, the sample projected on (proximal, distal) joint angle,
  one colour per chosen iteration, with the truth where known: the cloud shrinking onto the
  truth is the filter converging (docs/METHOD.md 3).
* `boxplots(rows, path)` draws the errors of many `result.json`s grouped by object and hand.

Pictures are written atomically (`vlr.io.atomic_path`).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["CloudRecorder", "pick_iterations", "particle_cloud", "BOX_METRICS", "boxplots"]


class CloudRecorder:
    """`watch(pf, rec)` hook keeping a uniform sample of the joint angles per iteration.

    Attributes:
        snapshots: {iteration: (S, N, K) joint angles [rad]}.
    """

    def __init__(self, sample: int = 1000, seed: int = 0) -> None:
        if sample < 1:
            raise ValueError(f"sample {sample} must be >= 1")
        self.sample = sample
        self._rng = np.random.default_rng(seed)
        self.snapshots: dict[int, np.ndarray] = {}

    def __call__(self, pf: Any, rec: Any) -> None:
        state = pf.state
        pool = np.flatnonzero(np.asarray(state.valid, dtype=bool))
        if pool.size == 0:
            return
        idx = self._rng.choice(pool, size=min(self.sample, pool.size), replace=False)
        self.snapshots[int(rec.iteration)] = state.theta[np.sort(idx)].copy()


def pick_iterations(available: Iterable[int], n: int = 4) -> list[int]:
    """Up to `n` iterations spread evenly from the first to the last available one."""
    its = sorted(set(int(i) for i in available))
    if len(its) <= n:
        return its
    picks = np.linspace(0, len(its) - 1, n).round().astype(int)
    return [its[i] for i in sorted(set(picks.tolist()))]


def _save(fig: Any, path: Path, dpi: int = 110) -> Path:
    import matplotlib.pyplot as plt

    from vlr.io import atomic_path

    try:
        with atomic_path(path) as tmp:
            fig.savefig(tmp, dpi=dpi)
    finally:
        plt.close(fig)
    return path


def _pyplot() -> Any:
    import matplotlib

    matplotlib.use("Agg")  # files only, never a window
    import matplotlib.pyplot as plt

    return plt


def particle_cloud(path: str | Path, snapshots: Mapping[int, np.ndarray],
                   names: Sequence[str], iterations: Sequence[int] | None = None,
                   truth: Mapping[int, np.ndarray] | None = None,
                   title: str = "particle cloud") -> Path:
    """Per finger, the particle sample's (proximal, distal) joint angles at chosen iterations.

    Args:
        path: the PNG to write.
        snapshots: {iteration: (S, N, K) joint angles [rad]} (`CloudRecorder.snapshots`).
        names: the N finger names.
        iterations: which to draw (default: `pick_iterations`, first to last); iterations
            without a snapshot are skipped.
        truth: optional {iteration: (N, K) true joint angles [rad]}, drawn as crosses.
        title: what the points are ("sigma points" for the unscented Kalman filter's).
    Returns:
        the path written.
    """
    plt = _pyplot()
    its = [i for i in (iterations if iterations is not None else pick_iterations(snapshots))
           if i in snapshots]
    if not its:
        raise ValueError(f"no snapshot at iterations {list(iterations or [])}; "
                         f"have {sorted(snapshots)}")
    n = len(names)
    colours = plt.get_cmap("viridis")(np.linspace(0.0, 0.9, len(its)))
    fig, axes = plt.subplots(1, n, figsize=(3.6 * n, 3.4), squeeze=False)
    for f, name in enumerate(names):
        ax = axes[0, f]
        for it, col in zip(its, colours, strict=True):
            th = np.degrees(snapshots[it][:, f, :])
            # The proximal joint and the last (distal) one: the pair the paper plots.
            # A few dozen sigma points drawn larger than thousands of particles.
            ax.scatter(th[:, 0], th[:, -1], s=3 if len(th) > 200 else 14, color=col,
                       alpha=0.35, linewidths=0, label=f"iteration {it}", rasterized=True)
            if truth is not None and it in truth:
                t = np.degrees(np.asarray(truth[it])[f])
                ax.plot(t[0], t[-1], "X", markerfacecolor=col, markeredgecolor="k",
                        markeredgewidth=0.8, markersize=10)
        ax.set_title(name)
        ax.xaxis.set_major_locator(plt.MaxNLocator(5))  # a narrow cloud's labels collide
        ax.set_xlabel("proximal [deg]")
        ax.set_ylabel("distal [deg]")
    handles, labels = axes[0, 0].get_legend_handles_labels()
    legend = axes[0, 0].legend(handles, labels, loc="best", fontsize=7, markerscale=3)
    for h in legend.legend_handles:
        h.set_alpha(1.0)
    if truth is not None:
        fig.suptitle(f"{title}; X: ground truth at the same iteration", fontsize=9)
    fig.tight_layout()
    return _save(fig, Path(path))


# (key in result.json's "errors", axis label); dict-valued keys are averaged over entries.
BOX_METRICS: tuple[tuple[str, str], ...] = (
    ("proximal_deg_mean", "proximal joint error [deg]"),
    ("distal_deg_mean", "distal joint error [deg]"),
    ("contact_mm_mean", "contact error [mm]"),
    ("link_length_mm", "link length error [mm]"),
    ("stiffness", "stiffness error [N m/rad]"),
)


def _metric(errors: Mapping[str, Any], key: str) -> float | None:
    v = errors.get(key)
    if isinstance(v, Mapping):
        vals = [float(x) for x in v.values()]
        return float(np.mean(vals)) if vals else None
    return None if v is None else float(v)


def boxplots(rows: Iterable[Mapping[str, Any]], path: str | Path) -> Path:
    """Box plots of the errors of many trials, one box per (object, hand), one panel per
    error kind present.

    Args:
        rows: per-trial result dicts in `result.json`'s format (`vlr identify`): keys
            "object", "hand" and "errors" (with "proximal_deg_mean" etc.). Trials without
            "errors" (no ground truth, e.g. hardware) are left out.
        path: the PNG to write.
    Returns:
        the path written.
    Raises:
        ValueError: no trial has errors against ground truth.
    """
    groups: dict[str, dict[str, list[float]]] = {}
    for row in rows:
        errors = row.get("errors")
        if not errors:
            continue
        label = f"{row.get('object', '?')}\n{row.get('hand', '?')}"
        g = groups.setdefault(label, {})
        for key, _ in BOX_METRICS:
            v = _metric(errors, key)
            if v is not None and np.isfinite(v):
                g.setdefault(key, []).append(v)
    if not groups:
        raise ValueError("no trial has errors against ground truth (result.json 'errors')")
    metrics = [(k, lab) for k, lab in BOX_METRICS if any(k in g for g in groups.values())]
    labels = sorted(groups)
    plt = _pyplot()
    fig, axes = plt.subplots(1, len(metrics), figsize=(max(3.2, 1.1 * len(labels) + 1.5)
                                                       * len(metrics), 3.8), squeeze=False)
    for ax, (key, axis_label) in zip(axes[0], metrics, strict=True):
        data = [groups[lab].get(key, []) for lab in labels]
        pos = [i + 1 for i, d in enumerate(data) if d]
        ax.boxplot([d for d in data if d], positions=pos, widths=0.6, showfliers=False)
        for p, d in zip(pos, [d for d in data if d], strict=True):  # every trial, fliers too
            ax.plot(np.full(len(d), p), d, ".", color="0.3", alpha=0.6)
        ax.set_xticks(range(1, len(labels) + 1), labels, fontsize=7)
        ax.set_xlim(0.4, len(labels) + 0.6)
        ax.set_ylabel(axis_label)
        ax.set_ylim(bottom=0)
        ax.set_title(f"n = {sum(len(d) for d in data)} trials", fontsize=8)
    fig.tight_layout()
    return _save(fig, Path(path))
