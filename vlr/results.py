"""What one identification trial writes: the `result.json` summary (errors against the
truth at the final iteration, coverage, timing), `history.npz` and `convergence.png`. Shared
by `vlr identify`, `vlr sweep` and the tasks through `vlr.run`."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from vlr.model_check import verdict

__all__ = ["summarize", "write_outputs", "COVERAGE_TOLERANCE_DEG"]

# A joint angle counts as covered "within tolerance" when the truth lies at most this far
# outside its 95% interval. Why: a joint resting on its stop sits 0.01-0.08 degrees beyond
# it in the sim (MuJoCo's soft limit) and a little less far in the model (its stop
# penalty), so the interval of a joint the filter has pinned to the stop can miss the truth
# by 0.005 degrees (wine glass, seed 2, the thumb's proximal joint: truth -20.072, interval
# -20.068 to -20.058). 0.1 degree is 1/20 of the convergence criterion's 2 degrees and half
# the camera's rotation error. The strict figure stays `coverage`.
COVERAGE_TOLERANCE_DEG = 0.1


def summarize(result, model, settings, wall: float, final_truth=None) -> dict:
    """The result.json content: errors against the truth at the final iteration.

    `settings` (`vlr.settings.Settings`) name the trial; all of them are written too. The
    estimator's hypotheses are its particles or the UKF's sigma points; `timing.filter_s` is
    the filter's time over the whole trial (its updates, not the world's rendering)."""
    n, k = model.n_fingers, model.n_joints
    w = settings.world
    out: dict = {"backend": w.backend, "object": w.object, "hand": w.hand,
                 "true_hand": w.true_hand, "estimator": settings.filter.estimator,
                 "particles": (settings.filter.particles if settings.filter.estimator == "pf"
                               else None),
                 "hypotheses": int(result.hypotheses),
                 "seed": settings.seed, "unknowns": list(settings.filter.unknowns),
                 "converged": bool(result.converged), "iterations": int(result.iterations),
                 "converged_at": result.converged_at,
                 "grasp_lost_at": result.grasp_lost_at,
                 "estimates": {name: vars(e) for name, e in result.theta.items()},
                 "unknown_estimates": {name: vars(e) for name, e in result.unknowns.items()},
                 "timing": {"filter_s_per_iteration_median": float(np.median(result.seconds)),
                            "filter_s": float(np.sum(result.seconds)), "wall_s": wall}}
    # Whether the model explains what the filter saw (`vlr.model_check`): from the
    # filter's own predictions, never the truth.
    out["model_check"] = verdict([r.surprise for r in result.history],
                                 settings.filter.model_check,
                                 settings.filter.observation.sigma_tension_n > 0)
    out["model_check"]["parts_by_iteration"] = [
        [None if not np.isfinite(x) else round(float(x), 3) for x in getattr(r, "parts", ())]
        for r in result.history]
    # Per iteration (the grasp's update first): the convergence measure, and against the
    # truth the mean proximal error, so that a table can read either at any iteration.
    out["ci_deg_by_iteration"] = [round(float(r.ci_deg), 4) for r in result.history]
    # The tendon commands the hand reported [mm], so that `vlr crb --replay` can follow the
    # actions a trial took (active exploration's are not a seed's random stream).
    out["commands_mm_by_iteration"] = [[round(float(x) * 1e3, 9) for x in r.command]
                                       for r in result.history]
    # Each unknown's posterior median per iteration (SI units), with or without a truth: the
    # errors below lose their sign, and whether an estimate comes down from above or up from
    # below is what tells a prior's pull from the model's.
    specs = list(result.unknowns)
    if specs and result.history:
        tail = len(specs)
        out["unknown_median_by_iteration"] = {
            spec: [float(f"{(r.posterior or r.prior).median[j - tail]:.5g}")
                   for r in result.history]
            for j, spec in enumerate(specs)}
    if result.scores:
        out["proximal_deg_by_iteration"] = [
            round(float(sc.theta_error_deg.reshape(n, k)[:, 0].mean()), 4)
            for sc in result.scores]
        if result.scores[-1].theta_error_median_deg is not None:
            out["proximal_median_deg_by_iteration"] = [
                round(float(sc.theta_error_median_deg.reshape(n, k)[:, 0].mean()), 4)
                for sc in result.scores]
            # Every joint's mean error, the paper's "joints" figure of the novel-finger rows,
            # so that one long trial gives the rows at any shorter budget.
            out["joint_median_deg_by_iteration"] = [
                round(float(sc.theta_error_median_deg.mean()), 4) for sc in result.scores]
        # Each unknown's error per iteration (SI units): how far the budget was from enough.
        if result.scores[-1].unknown_error:
            out["unknown_error_by_iteration"] = {
                spec: [float(f"{abs(sc.unknown_error[spec]):.4g}") for sc in result.scores]
                for spec in result.scores[-1].unknown_error}
        if result.scores[-1].unknown_error_median:
            out["unknown_error_median_by_iteration"] = {
                spec: [float(f"{abs(sc.unknown_error_median[spec]):.4g}")
                       for sc in result.scores]
                for spec in result.scores[-1].unknown_error_median}
        s = result.scores[-1]
        errors = _errors(s.theta_error_deg.reshape(n, k), s.unknown_error, model)
        if final_truth is not None:
            from vlr.kinematics import contact_in_distal

            c_true = contact_in_distal(model, final_truth.normals[None],
                                       final_truth.segments[None])[0]
            err_c = np.linalg.norm(result.contacts - c_true, axis=-1) * 1e3
            if np.all(np.isfinite(err_c)):  # a finger without contact has no contact error
                errors["contact_mm_mean"] = float(err_c.mean())
        out["errors"] = errors
        if s.theta_error_median_deg is not None:
            # The same figures for the posterior median, the estimate that minimizes the
            # absolute error the paper reports (vlr.filter.Summary).
            out["errors_median"] = _errors(s.theta_error_median_deg.reshape(n, k),
                                           s.unknown_error_median or {}, model)
        first = result.scores[0]
        if first.theta_prior_covered is not None:
            # Scoring only: the share of true joints inside the grasp prior's 95% interval.
            # Low, the guess (filter.guess_theta_deg) or its spread missed the grasp, and the
            # filter's answer says more of the guess than of the hand.
            out["prior_coverage"] = float(np.mean(first.theta_prior_covered))
        covered = list(s.theta_covered) + list(s.unknown_covered.values())
        out["coverage"] = float(np.mean(covered))
        if s.theta_miss_deg is not None:
            near = list(s.theta_miss_deg <= COVERAGE_TOLERANCE_DEG)
            out["coverage_tolerant"] = float(np.mean(near + list(s.unknown_covered.values())))
            names = [f"{f}.{j}" for f in model.names for j in range(k)]
            out["truth_theta"] = dict(zip(names, s.theta_true.tolist(), strict=True))
            out["miss_deg"] = dict(zip(names, s.theta_miss_deg.tolist(), strict=True))
    return out


def _errors(err: np.ndarray, unknown_error: dict[str, float], model) -> dict:
    """The error figures of one point estimate: joint errors [deg] (fingers x joints) and
    each unknown's absolute error (lengths, mass and centre of mass in mm and g)."""
    errors: dict = {"proximal_deg_mean": float(err[:, 0].mean()),
                    "distal_deg_mean": float(err[:, 1:].mean()),
                    # The paper's "joints" figure of the novel-finger rows: every joint.
                    "joint_deg_mean": float(err.mean()),
                    "proximal_deg": dict(zip(model.names, err[:, 0].tolist(), strict=True))}
    lengths, stiff = {}, {}
    for spec, e in unknown_error.items():
        kind, _, rest = spec.partition(":")
        if kind == "length":  # a finger's mean over its unknown lengths
            lengths.setdefault(rest.split(".")[0], []).append(abs(e) * 1e3)
            errors.setdefault("link_length_mm_by_joint", {})[rest] = abs(e) * 1e3
        elif kind == "stiffness":
            stiff[rest] = abs(e)
        elif kind == "mass":
            errors["object_mass_g"] = abs(e) * 1e3
        elif kind == "com":
            errors.setdefault("object_com_mm", {})[rest] = abs(e) * 1e3
        elif kind == "curvature":  # "all": one curvature at every contact
            errors.setdefault("curvature_per_m", {})[rest or "all"] = abs(e)
    if lengths:
        errors["link_length_mm"] = {f: float(np.mean(v)) for f, v in lengths.items()}
    if stiff:
        errors["stiffness"] = stiff
    return errors


def write_outputs(out: Path, result, summary: dict, model, truths: list | None = None) -> None:
    """result.json, history.npz and convergence.png, each written atomically. A previous
    run's result.json, the mark of a finished run, is removed first and the new one written
    last: a run killed while writing leaves no folder that looks finished."""
    from vlr.io import atomic_path, write_json_atomic

    out.mkdir(parents=True, exist_ok=True)
    (out / "result.json").unlink(missing_ok=True)
    n, k = model.n_fingers, model.n_joints
    post = [r.posterior or r.prior for r in result.history]
    hist = {"iteration": np.array([r.iteration for r in result.history]),
            "mean": np.array([p.mean for p in post]),
            "median": np.array([p.median for p in post]),
            "low": np.array([p.low for p in post]),
            "high": np.array([p.high for p in post]),
            "ess": np.array([r.ess for r in result.history]),
            "ci_deg": np.array([r.ci_deg for r in result.history]),
            "command": np.array([r.command for r in result.history]),
            "seconds": np.array(result.seconds)}
    if result.scores:
        hist["theta_error_deg"] = np.array([s.theta_error_deg for s in result.scores])
    if truths:
        hist["truth_theta"] = np.array([t.theta.ravel() for t in truths])
    unknowns = list(result.unknowns)
    if result.scores and unknowns:
        # the truth of each unknown per iteration: the scored estimate minus its error
        base = hist["mean"].shape[1] - len(unknowns)
        # (NaN for an unknown without a true value: a mesh object's curvature)
        hist["truth_unknowns"] = np.array(
            [[hist["mean"][i, base + j] - sc.unknown_error.get(spec, np.nan)
              for j, spec in enumerate(unknowns)] for i, sc in enumerate(result.scores)])
    with atomic_path(out / "history.npz") as tmp:
        np.savez_compressed(tmp, **hist)
    _plot(out / "convergence.png", hist, model, n, k, unknowns)
    write_json_atomic(out / "result.json", summary)


# Display units of the unknowns by kind: (scale from SI, what it is, unit).
_UNKNOWN_UNITS = {"stiffness": (1.0, "stiffness", "N m/rad"), "length": (1e3, "length", "mm"),
                  "tendon": (1e-3, "tendon stiffness", "N/mm"),
                  "mass": (1e3, "object mass", "g"),
                  "com": (1e3, "centre of mass in O", "mm"),
                  "curvature": (1.0, "surface curvature", "1/m")}


def unknown_units(spec: str) -> tuple[float, str, str]:
    """(scale from SI, what it is, unit) to show an unknown ("mass", "length:left.distal",
    ...) in: grams, millimetres, N/mm; SI for a kind without one."""
    return _UNKNOWN_UNITS.get(spec.partition(":")[0], (1.0, spec, ""))


def _plot(path: Path, hist: dict, model, n: int, k: int, unknowns: list[str] = ()) -> None:
    """One panel per finger's proximal joint, then one per extra unknown: the estimate, its
    95% interval and, where scored, the truth."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    it = hist["iteration"]
    cols = n + len(unknowns)
    fig, axes = plt.subplots(1, cols, figsize=(4 * cols, 3.2), squeeze=False)
    base = hist["mean"].shape[1] - len(unknowns)
    for j, spec in enumerate(unknowns):
        ax = axes[0, n + j]
        scale, what, unit = unknown_units(spec)
        label = f"{what} [{unit}]" if unit else what
        c = base + j
        ax.fill_between(it, scale * hist["low"][:, c], scale * hist["high"][:, c], alpha=0.3)
        ax.plot(it, scale * hist["mean"][:, c])
        if "truth_unknowns" in hist:
            ax.plot(it, scale * hist["truth_unknowns"][:, j], "k--")
        ax.set_title(spec)
        ax.set_xlabel("iteration")
        ax.set_ylabel(label)
    for i, name in enumerate(model.names):
        ax = axes[0, i]
        j = i * k
        ax.fill_between(it, np.degrees(hist["low"][:, j]), np.degrees(hist["high"][:, j]),
                        alpha=0.3, label="95% interval")
        ax.plot(it, np.degrees(hist["mean"][:, j]), label="estimate")
        if "truth_theta" in hist:
            ax.plot(it, np.degrees(hist["truth_theta"][:, j]), "k--", label="ground truth")
        ax.set_title(f"{name} proximal")
        ax.set_xlabel("iteration")
        ax.set_ylabel("angle [deg]")
    axes[0, 0].legend(loc="best", fontsize=8)
    fig.tight_layout()
    from vlr.plots import _save

    _save(fig, path)  # atomically (vlr.io.atomic_path), and the figure closed


def write_result_files(out: Path, run) -> None:
    """Every file of one identification (`vlr.run.Identification`): result.json,
    history.npz, convergence.png."""
    write_outputs(Path(out), run.result, run.summary, run.model, run.truths)
