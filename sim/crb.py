"""`vlr crb`: how narrow an honest filter's intervals can be, from the simulator's true grasp
(`vlr.information`).

The paper's convergence criterion is the mean 95% interval of the joint angles under 2 degrees
(docs/METHOD.md 3), met in 15 actions on the real hand. This tool linearises the filter's OWN
model (the one `vlr identify` builds for the same settings: its prior, unknowns and likelihood
scales) at the simulator's true configuration after the grasp, follows the actions `vlr identify
--seed` takes (or, with `--candidates`, an oracle that picks each action to narrow the bound the
most; with `--replay`, the actions a finished trial took, e.g. active exploration's), and
reports the Bayesian Cramér-Rao floor of that measure after each action, at the likelihood's
scales and at the camera's own accuracy. It needs a world with ground truth, the sim or the
synthetic world (where the model is the world, so the floor is what a perfect model allows): it
reads the truth to choose the linearisation point; the estimator never runs it.
"""

from __future__ import annotations

import argparse
import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from vlr.errors import UserError
from vlr.explore import ActionStream
from vlr.hand import GraspError, report_commands
from vlr.io import check_output_file

__all__ = ["CrbSettings", "crb_report", "format_report", "register", "CAMERA_SIGMA"]

# The rendered camera's pose accuracy (docs/CAMERA.md: 0.04-0.06 mm and 0.15-0.25 degree at
# 640x480): the scales of a model with no error at all.
CAMERA_SIGMA = (0.05, 0.2)


def _sim_trial():
    from vlr.settings import load_settings

    return load_settings({"world.backend": "sim", "filter.particles": 1000,
                          "loop.max_iterations": 20})


@dataclass(frozen=True)
class CrbSettings:
    """One bound: the trial it bounds and the bound's own settings.

    Attributes:
        trial: the trial's settings tree (`vlr.settings.Settings`, backend "sim" or
            "synthetic"): its object, hands, unknowns, prior, likelihood scales and seed
            (its actions); `loop.max_iterations` is the number of actions. Its particle
            count does not matter.
        candidates: 0 follows `vlr identify`'s random actions; K > 0 picks each action among
            K random candidates as the one that narrows the bound most (an oracle: it knows
            the truth, so no filter can choose better from those candidates).
        relative_step: central-difference step over each prior spread (`vlr.information`).
        target_deg: the convergence criterion [deg] (docs/METHOD.md 3).
        budget: the actions at which the scales that would just meet the criterion are
            reported (the paper's 15.1 iterations).
        replay: the tendon commands [m] a trial reported, the grasp's first
            (`commands_mm_by_iteration` of its result); when given, the bound follows
            these actions instead (`replay_commands`).
    """

    trial: Any = field(default_factory=_sim_trial)
    candidates: int = 0
    relative_step: float = 0.02
    target_deg: float = 2.0
    budget: int = 15
    replay: tuple[tuple[float, ...], ...] = ()

    def __post_init__(self) -> None:
        if self.trial.world.backend not in ("sim", "synthetic"):
            raise UserError(f"backend {self.trial.world.backend!r}: the bound is linearised "
                            "at the true grasp; use the sim or the synthetic world")
        if not isinstance(self.candidates, int) or self.candidates < 0:
            raise UserError(f"candidates {self.candidates!r} must be an integer >= 0")
        if not 0 < self.relative_step < 0.5:
            raise UserError(f"relative step {self.relative_step!r} must be in (0, 0.5)")
        if not self.target_deg > 0:
            raise UserError(f"target {self.target_deg!r} deg must be > 0")
        if not isinstance(self.budget, int) or self.budget < 1:
            raise UserError(f"budget {self.budget!r} must be an integer >= 1")
        if self.replay and self.candidates:
            raise UserError("replay follows a trial's own actions; candidates pick new ones: "
                            "give one")

    @property
    def actions(self) -> int:
        if self.replay:
            return len(self.replay) - 1
        return self.trial.loop.max_iterations


def replay_commands(record: dict, where: str) -> tuple[Any, tuple[tuple[float, ...], ...]]:
    """The settings and the reported tendon commands [m] of a finished trial's record: a
    `vlr sweep` trial file (its "settings" and its result's `commands_mm_by_iteration`) or
    the `result.json` of `vlr identify --out` (both at its top level)."""
    settings = record.get("settings")
    result = record.get("result") if isinstance(record.get("result"), dict) else record
    cmds = result.get("commands_mm_by_iteration")
    if not isinstance(settings, dict) or not cmds:
        raise UserError(f"{where}: not a trial record with its commands (a sweep's "
                        "runs/SWEEP/trials/*.json or vlr identify's result.json, written "
                        "since the commands were recorded; re-run the trial)")
    try:
        u = np.asarray(cmds, dtype=float)
    except (TypeError, ValueError):  # ragged rows or not numbers
        u = np.empty(0)
    if u.ndim != 2 or not np.isfinite(u).all():
        raise UserError(f"{where}: commands_mm_by_iteration must be rows of finite numbers")
    from vlr.settings import load_settings

    try:
        trial = load_settings(settings)
    except UserError as exc:
        raise UserError(f"{where}: {exc}") from None
    return trial, tuple(map(tuple, u * 1e-3))


def _bound(trace, sigma: tuple[float, float, float, float]):
    """The trace's bound at scales (sigma_pos [m], sigma_rot [rad], sigma_turn [rad],
    sigma_tension [N]; 0 = no turn term, tensions not observed)."""
    return trace.bound(sigma[0], sigma[1], sigma_turn=sigma[2], sigma_tension=sigma[3])


def _scale_for(trace, sigma: tuple[float, ...], target: float) -> float:
    """The factor c for which scales c * sigma just give a mean width of `target` now: nan
    if no scales do (the prior's width left by unobserved directions stays above it), inf if
    any do."""
    def width(c: float) -> float:
        return _bound(trace, tuple(c * x for x in sigma)).mean_width_deg

    lo, hi = 1e-3, 1e3
    if width(lo) > target:
        return math.nan
    if width(hi) < target:
        return math.inf
    for _ in range(60):
        mid = math.sqrt(lo * hi)
        lo, hi = (mid, hi) if width(mid) < target else (lo, mid)
    return lo


def crb_report(s: CrbSettings) -> dict:
    """Grasp in the sim, then follow the actions (module docstring); the bound after each."""
    from vlr.filter import ParticleFilter
    from vlr.information import InformationTrace, truth_vector
    from vlr.world import open_world

    t_start = time.perf_counter()
    ts = s.trial
    ob = ts.filter.observation
    world = open_world(ts)
    try:
        pf = ParticleFilter(world.model, world.obj, ts.filter, ts.seed)
        sigma = (pf.obs_model.sigma_pos, pf.obs_model.sigma_rot, pf.obs_model.sigma_turn,
                 pf.obs_model.sigma_tension)
        # The camera's pose accuracy; tensions, where observed, at the trial's own scale.
        camera = (CAMERA_SIGMA[0] * 1e-3, math.radians(CAMERA_SIGMA[1]), 0.0, sigma[3])
        u = report_commands(world.world.grasp())
        if s.replay and (len(s.replay[0]) != len(u)
                         or not np.allclose(u, s.replay[0], rtol=0, atol=1e-9)):
            raise UserError(f"the replayed trial's grasp commands {np.round(s.replay[0], 6)} "
                            f"differ from the sim's {np.round(u, 6)}: not the same trial")
        truth = world.truth()
        if (any(u.kind == "curvature" for u in pf.unknowns)
                and getattr(truth, "surface_curvature", None) is None):
            raise UserError(f"unknown 'curvature': object {ts.world.object!r} is a mesh, whose "
                            "curvature the sim does not know; the bound needs its true value")
        trace = InformationTrace(pf, truth_vector(pf, truth), truth.position, truth.rotation,
                                 u, s.relative_step)
        actions = ActionStream.of_trial(ts.loop, ts.seed, u)  # vlr identify's actions
        rows = [_row(trace, sigma, camera)]
        scale_at_budget = None
        lost = None
        for k in range(1, s.actions + 1):
            if s.replay:
                delta = np.asarray(s.replay[k]) - u
            elif s.candidates:
                delta = _oracle(trace, actions, u, s.candidates, sigma)
            else:
                delta = actions.random(u)
            try:
                report = world.world.apply(delta)
            except GraspError:  # the synthetic world refuses a snap-through
                lost = k
                break
            if not getattr(report, "grasp_held", True):
                lost = k
                break
            u = report_commands(report)
            if s.replay and not np.allclose(u, s.replay[k], rtol=0, atol=1e-9):
                raise UserError(f"the sim answered replayed action {k} with commands "
                                f"{np.round(u, 6)}, the trial recorded {np.round(s.replay[k], 6)}"
                                ": not the same trial")
            trace.act(u)
            rows.append(_row(trace, sigma, camera))
            if k == s.budget:
                scale_at_budget = _scale_for(trace, sigma, s.target_deg)
        last = _bound(trace, sigma)
    finally:
        world.close()

    def first_under(key: str) -> int | None:
        return next((r["actions"] for r in rows if r[key] < s.target_deg), None)

    return {
        "object": ts.world.object, "hand": ts.world.hand, "true_hand": ts.world.true_hand,
        "unknowns": list(ts.filter.unknowns), "seed": ts.seed,
        "actions": ("replay" if s.replay else "oracle" if s.candidates else "random"),
        "candidates": s.candidates,
        "sigma_pos_mm": ob.sigma_pos_mm, "sigma_rot_deg": ob.sigma_rot_deg,
        "sigma_turn_deg": ob.sigma_turn_deg, "sigma_tension_n": ob.sigma_tension_n,
        "camera_sigma": list(CAMERA_SIGMA), "prior_spread_deg": ts.filter.theta_spread_deg,
        "relative_step": s.relative_step, "target_deg": s.target_deg,
        "grasp_lost_at": lost,
        "first_under_target": first_under("mean_width_deg"),
        "first_under_target_camera": first_under("mean_width_deg_camera"),
        "budget": s.budget,
        "scale_to_meet_at_budget": scale_at_budget,
        "joint_width_deg": dict(zip(pf.dim_names, last.joint_width_deg.tolist(),
                                    strict=False)),
        "unknown_std": dict(zip([u.spec for u in pf.unknowns], last.unknown_std.tolist(),
                                strict=True)),
        "by_action": rows,
        "seconds": time.perf_counter() - t_start,
    }


def _row(trace, sigma, camera) -> dict:
    b, c = _bound(trace, sigma), _bound(trace, camera)
    return {"actions": trace.actions, "mean_width_deg": b.mean_width_deg,
            "mean_width_deg_camera": c.mean_width_deg, "one_sided": trace.one_sided,
            "unknown_std": b.unknown_std.tolist()}


def _oracle(trace, actions: ActionStream, u, k: int, sigma) -> np.ndarray:
    """Of k random candidates, the one whose bound after it is narrowest (first if every
    preview fails)."""
    cands = [actions.random(u) for _ in range(k)]
    best, best_w = cands[0], math.inf
    for d in cands:
        b = trace.preview(u + d, *sigma)
        if b is not None and b.mean_width_deg < best_w:
            best, best_w = d, b.mean_width_deg
    return best


def format_report(rep: dict) -> str:
    """The bound against actions, a line a person reads, per row."""
    who = rep["object"] + (f", {rep['true_hand']} (filter: {rep['hand']})"
                           if rep["true_hand"] else f", {rep['hand']}")
    head = (f"{who}, seed {rep['seed']}, {rep['actions']} actions"
            + (f" of {rep['candidates']} candidates" if rep["candidates"] else "")
            + f": floor of the mean 95% joint interval [deg] at the likelihood's "
            f"{rep['sigma_pos_mm']} mm / {rep['sigma_rot_deg']} deg"
            + (f" + a {rep['sigma_turn_deg']} deg turn" if rep.get("sigma_turn_deg") else "")
            + (f" + tensions at {rep['sigma_tension_n']} N" if rep.get("sigma_tension_n")
               else "")
            + " and at the camera's "
            f"{rep['camera_sigma'][0]} mm / {rep['camera_sigma'][1]} deg")
    lines = [head, f"{'actions':>8s} {'likelihood':>11s} {'camera':>8s}"
             + "".join(f" {'sd ' + n:>26s}" for n in rep["unknown_std"])]
    for r in rep["by_action"]:
        lines.append(f"{r['actions']:8d} {r['mean_width_deg']:11.2f} "
                     f"{r['mean_width_deg_camera']:8.2f}"
                     + "".join(f" {v:26.4g}" for v in r["unknown_std"]))
    t = rep["target_deg"]
    lines.append(f"under {t} deg: at action {rep['first_under_target']} (likelihood), "
                 f"{rep['first_under_target_camera']} (camera)")
    c = rep["scale_to_meet_at_budget"]
    if c is not None and not math.isfinite(c):
        lines.append(f"after {rep['budget']} actions "
                     + ("no scales bring it under " if math.isnan(c) else "any scales keep it "
                        "under ") + f"{t} deg")
    elif c is not None:
        lines.append(f"to be under {t} deg after {rep['budget']} actions the scales must be "
                     f"at most {c:.2f}x the likelihood's: {c * rep['sigma_pos_mm']:.3f} mm / "
                     f"{c * rep['sigma_rot_deg']:.3f} deg"
                     + (f" / a {c * rep['sigma_turn_deg']:.3f} deg turn"
                        if rep.get("sigma_turn_deg") else "")
                     + (f" / tensions {c * rep['sigma_tension_n']:.3f} N"
                        if rep.get("sigma_tension_n") else ""))
    if rep["grasp_lost_at"]:
        lines.append(f"grasp lost at action {rep['grasp_lost_at']}")
    return "\n".join(lines)


def summary_table(reports: list[tuple[str, dict]]) -> str:
    """Markdown, one row per case: the floor after the budget and after the last action (mean
    +- SD over the seeds that got there: oracle actions can lose the grasp) at the
    likelihood's and the camera's scales, the seeds whose floor meets the criterion, and the
    likelihood scales that would meet it at the budget."""
    cases: dict[str, list[dict]] = {}
    for case, rep in reports:
        cases.setdefault(case, []).append(rep)

    def ms(v: list[float]) -> str:
        v = [x for x in v if x is not None and math.isfinite(x)]
        return f"{np.mean(v):.2f} ± {np.std(v):.2f}" if v else "-"

    def at(rep: dict, k: int, key: str) -> float | None:
        return next((r[key] for r in rep["by_action"] if r["actions"] == k), None)

    b = reports[0][1]["budget"] if reports else 15
    lines = [f"| case | floor after {b}, likelihood [deg] | after {b}, camera | after the last "
             "action, likelihood | seeds under the criterion (likelihood / camera) | scales "
             f"that meet it after {b}, x the likelihood's | unknowns' SD after the last | "
             "grasps lost |",
             "|---|---|---|---|---|---|---|---|"]
    for case, reps in cases.items():
        last = [r["by_action"][-1]["mean_width_deg"] for r in reps if not r["grasp_lost_at"]]
        lost = [f"seed {r['seed']} at action {r['grasp_lost_at']}" for r in reps
                if r["grasp_lost_at"]]
        under = sum(r["first_under_target"] is not None for r in reps)
        under_c = sum(r["first_under_target_camera"] is not None for r in reps)
        sds = "; ".join(f"{name} {np.mean([r['unknown_std'][name] for r in reps]):.3g}"
                        for name in reps[0]["unknown_std"])
        lines.append(f"| {case} | {ms([at(r, b, 'mean_width_deg') for r in reps])} | "
                     f"{ms([at(r, b, 'mean_width_deg_camera') for r in reps])} | {ms(last)} | "
                     f"{under}/{len(reps)} / {under_c}/{len(reps)} | "
                     f"{ms([r['scale_to_meet_at_budget'] for r in reps])} | {sds} | "
                     f"{', '.join(lost) or 'none'} |")
    return "\n".join(lines)


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("crb", help="the Cramér-Rao floor of the filter's intervals along a "
                       "trial's actions, from the simulator's true grasp")
    p.add_argument("--sweep", default=None, metavar="FILE",
                   help="bound every trial of a sweep file (its cases and seeds; the "
                   "trial options below are then ignored)")
    p.add_argument("--replay", nargs="+", default=None, metavar="TRIAL",
                   help="bound along the actions finished trials took: `vlr sweep` trial "
                   "files (runs/SWEEP/trials/*.json) or `vlr identify`'s result.json, with "
                   "their own settings (the trial options below are then ignored)")
    p.add_argument("--object", default="apple", help="object name or spec file")
    p.add_argument("--hand", default="modelo", help="the filter's hand (default modelo)")
    p.add_argument("--true-hand", default=None, help="the sim's hand when it differs")
    p.add_argument("--unknown", action="append", default=[], metavar="SPEC",
                   help="an unknown parameter, as `vlr identify --unknown` (repeatable)")
    p.add_argument("--seed", type=int, default=0, help="the trial's seed (its actions)")
    p.add_argument("--actions", type=int, default=20, help="actions (default 20)")
    p.add_argument("--candidates", type=int, default=0, metavar="K",
                   help="oracle actions: each the best of K random candidates (default 0: "
                   "vlr identify's random actions)")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="any setting of the trial, as `vlr identify --set` (e.g. "
                   "filter.observation.sigma_turn_deg=0.5); with --sweep or --replay, on top "
                   "of theirs")
    p.add_argument("--relative-step", type=float, default=0.02,
                   help="finite-difference step over each prior spread (default 0.02)")
    p.add_argument("--json", default=None, metavar="FILE", help="write the report as JSON")
    p.set_defaults(func=_main)


def _overrides(args: argparse.Namespace) -> dict:
    from vlr.settings import parse_assignment

    return {**dict(parse_assignment(t) for t in args.set), "filter.particles": 1000}


def _trials(args: argparse.Namespace) -> list[tuple[str, Any]]:
    from vlr.settings import apply_layer, load_settings
    from vlr.sweep import expand, load_sweep

    if args.actions < 1:
        raise UserError(f"--actions {args.actions} must be >= 1")
    if args.sweep:
        return [(t.case, apply_layer(t.settings, _overrides(args)))
                for t in expand(load_sweep(args.sweep))]
    return [("trial", load_settings({
        "world.backend": "sim", "world.object": args.object, "world.hand": args.hand,
        "world.true_hand": args.true_hand, "filter.unknowns": list(args.unknown),
        "seed": args.seed, "loop.max_iterations": args.actions}, _overrides(args)))]


def _replays(args: argparse.Namespace) -> list[tuple[str, Any, tuple]]:
    """(case, settings, commands) of each trial file (`replay_commands`)."""
    import json
    from pathlib import Path

    from vlr.settings import apply_layer

    out = []
    for path in args.replay:
        try:
            record = json.loads(Path(path).read_text())
        except FileNotFoundError:
            raise UserError(f"--replay {path}: no such file") from None
        except (json.JSONDecodeError, UnicodeDecodeError) as exc:
            raise UserError(f"--replay {path}: not JSON ({exc})") from None
        if not isinstance(record, dict):
            raise UserError(f"--replay {path}: not a trial record")
        t, u = replay_commands(record, f"--replay {path}")
        out.append((str(record.get("case", "trial")), apply_layer(t, _overrides(args)), u))
    return out


def _main(args: argparse.Namespace) -> int:

    from vlr.io import write_json_atomic

    if args.json:
        check_output_file(args.json, "--json")
    if args.replay:
        if args.sweep:
            raise UserError("give --sweep or --replay, not both")
        settings = [(case, CrbSettings(trial=t, candidates=args.candidates,
                                       relative_step=args.relative_step, replay=u))
                    for case, t, u in _replays(args)]
    else:
        settings = [(case, CrbSettings(trial=t, candidates=args.candidates,
                                       relative_step=args.relative_step))
                    for case, t in _trials(args)]
    many = bool(args.sweep) or len(settings) > 1
    reports, failed = [], []
    for case, s in settings:
        try:
            rep = crb_report(s)
        except FloatingPointError as exc:
            msg = f"{case}, seed {s.trial.seed}: the bound could not be linearised: {exc}"
            if not many:
                raise UserError(msg) from None
            # One trial's model that cannot be differenced does not void the sweep's others.
            print(f"skipped: {msg}\n", flush=True)
            failed.append({"case": case, "seed": s.trial.seed, "error": str(exc)})
            continue
        print(format_report(rep) + "\n", flush=True)
        reports.append((case, rep))
    if many:
        print(summary_table(reports))
        if failed:
            print(f"{len(failed)} trial(s) skipped: "
                  + "; ".join(f"{f['case']} seed {f['seed']}" for f in failed))
    if args.json:
        write_json_atomic(args.json, reports[0][1] if not many else
                          {"sweep": args.sweep, "replay": args.replay,
                           "trials": [{"case": c, **r} for c, r in reports],
                           "skipped": failed})
        print(f"wrote {args.json}")
    return 0
