"""Sweeps: many identification trials (objects x hands x unknowns x seeds x settings), each
result streamed into its own file, and one table rebuilt from those files.

A sweep is a YAML file (or the equivalent `vlr sweep` flags):

    name: synthetic-identification     # optional, for the table's title
    out: runs/sweep-synthetic          # output folder
    seeds: [0, 1, 2, 3, 4]             # or "0-4"
    settings:                          # common to every trial (`vlr.settings`)
      world.backend: synthetic
      filter.particles: 60000
    cases:                             # optional list of named setting overrides
      - {name: known hand}             # (a case's `group` pools it with others in the summary)
      - {name: thumb distal stiffness, filter.unknowns: [stiffness:thumb.distal]}
    grid: {world.object: [apple, wine_glass]}   # optional cartesian product over settings

Settings are the keys of the settings tree (`vlr.settings`), dotted as above or nested
(`settings: {filter: {particles: 60000}}`), the same keys as `vlr identify --set`; a setting
a file leaves out takes its backend's default. Trials = cases x grid x seeds.

Each finished trial is written atomically to `OUT/trials/<id>.json` (its settings and its
result, or its error), so an interrupted sweep resumes without repeating a finished trial
(`--resume`); `OUT/table.csv` (one row per trial) and `OUT/summary.csv` + `OUT/summary.md`
(mean and sd over seeds per case, and per value of every setting that varies within a case,
such as a grid key), with `OUT/boxplots.png` (errors per case and object,
`vlr.plots.boxplots`), are rebuilt from those files alone.
"""

from __future__ import annotations

import csv
import hashlib
import io
import itertools
import json
import logging
import math
import re
import traceback
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from vlr import smoke
from vlr.errors import UserError
from vlr.executors import run_local, run_ray
from vlr.io import write_json_atomic, write_text_atomic
from vlr.settings import Settings, load_settings

__all__ = ["Trial", "SweepSpec", "load_sweep", "parse_seeds", "expand", "run_one",
           "failure_record", "pending", "collect", "remove_temp_files", "write_tables",
           "COLUMNS", "run_local", "run_ray"]

_LOG = logging.getLogger(__name__)


@dataclass(frozen=True)
class Trial:
    """One trial of a sweep: its case name, its settings tree, and the group its case is
    pooled into in the summary (None: none)."""

    case: str
    settings: Settings
    group: str | None = None

    @property
    def id(self) -> str:
        """Readable and unique: case, object, hand, seed and a hash of every setting in
        effect, so that a trial run under other settings (a default changed since) is a new
        trial, never a finished one to skip."""
        s = self.settings
        flat = {k: v for k, v in s.flat().items() if k != "seed"}
        blob = json.dumps({"case": self.case, **flat}, sort_keys=True, default=str)
        digest = hashlib.sha1(blob.encode()).hexdigest()[:8]
        slug = "".join(ch if ch.isalnum() else "-" for ch in self.case.lower()).strip("-")
        w = s.world
        return f"{slug}_{_file_safe(w.object)}_{_file_safe(w.hand)}_s{s.seed}_{digest}"


def _file_safe(name: str) -> str:
    """A model name as it is, a spec file's path with its separators made dashes: the id is
    a file name, and `hand: ../my_hand.yaml` must not make folders under OUT/trials."""
    return "".join(ch if ch.isalnum() or ch in "_.-" else "-" for ch in str(name))


@dataclass(frozen=True)
class SweepSpec:
    """A parsed sweep (module docstring)."""

    name: str
    out: Path
    seeds: tuple[int, ...]
    settings: dict[str, Any]
    cases: tuple[dict[str, Any], ...]
    grid: dict[str, list[Any]]


# More seeds than this in one list or range is a typo ("0-100000000"), not a plan.
MAX_SEEDS = 10_000


def parse_seeds(value: Any) -> tuple[int, ...]:
    """Seeds from a list, an int, or a string like "0-4" or "0,3,7"; at most MAX_SEEDS.

    A range's size is checked before the range is built: "0-100000000" would otherwise
    become a list of a hundred million seeds, then as many trials to expand."""
    usage = f"seeds {value!r}: use e.g. 0-4 or 0,1,2"
    if isinstance(value, bool):
        raise UserError(usage)
    if isinstance(value, int):
        out: list[Any] = [value]
    elif isinstance(value, list | tuple):
        out = list(value)
    elif isinstance(value, str):
        out = []
        count = 0
        for part in value.split(","):
            part = part.strip()
            lo, sep, hi = part.partition("-")
            try:
                first, last = (int(lo), int(hi)) if sep else (int(part), int(part))
            except ValueError:
                raise UserError(usage) from None
            if last < first:
                raise UserError(f"seeds {value!r}: the range {part!r} is reversed; write "
                                f"{last}-{first}")
            count += last - first + 1
            if count <= MAX_SEEDS:
                out += range(first, last + 1)
        if count > MAX_SEEDS:
            raise UserError(f"seeds {value!r}: {count:,} seeds, more than the limit of "
                            f"{MAX_SEEDS:,}")
    else:
        raise UserError(usage)
    if len(out) > MAX_SEEDS:
        raise UserError(f"seeds: {len(out):,} seeds, more than the limit of {MAX_SEEDS:,}")
    # int("3") is fine; 1.5 or true is not a seed (int() would quietly make them 1).
    if not all((isinstance(s, int) and not isinstance(s, bool)) or isinstance(s, str)
               for s in out):
        raise UserError(usage)
    try:
        seeds = tuple(int(s) for s in out)
    except ValueError:
        raise UserError(usage) from None
    if not seeds:
        raise UserError("a sweep needs at least one seed")
    if min(seeds) < 0:
        raise UserError(f"{usage} (seeds are >= 0)")
    return tuple(smoke.first(seeds))


def load_sweep(path: str | Path, out: str | Path | None = None) -> SweepSpec:
    """Read a sweep YAML file (module docstring); `out` overrides its output folder."""
    from vlr.settings import read_yaml_mapping

    path = Path(path)
    raw = read_yaml_mapping(path, "sweep file")
    bad = sorted(set(raw) - {"name", "out", "seeds", "settings", "cases", "grid"})
    if bad:
        raise UserError(f"sweep file {str(path)!r}: unknown key(s) {bad}; known: name, out, "
                        "seeds, settings, cases, grid")
    where = f"sweep file {str(path)!r}"
    settings = raw.get("settings") or {}
    if not isinstance(settings, dict):
        raise UserError(f"{where}: settings must be a mapping, e.g. {{world.backend: synthetic}}")
    cases = raw.get("cases") or [{}]
    if not isinstance(cases, list) or not all(isinstance(c, dict) for c in cases):
        raise UserError(f"{where}: cases must be a list of mappings, e.g. "
                        "[{name: known hand}, {name: stiffness, filter.unknowns: [...]}]")
    grid = raw.get("grid") or {}
    if not isinstance(grid, dict) or not all(isinstance(v, list) and v
                                             for v in grid.values()):
        raise UserError(f"{where}: grid must map settings to non-empty lists, e.g. "
                        "{world.object: [apple, wine_glass]}")
    if any("seed" in d for d in (settings, grid, *cases)):
        raise UserError(f"{where}: give seeds with the top-level seeds:, not as a setting")
    target = out or raw.get("out")
    if not target:
        raise UserError(f"{where}: give an output folder (out: or --out)")
    if not isinstance(target, str | Path):
        raise UserError(f"{where}: out {target!r} must be a folder path")
    return SweepSpec(name=str(raw.get("name", path.stem)), out=Path(target),
                     seeds=parse_seeds(raw.get("seeds", 0)), settings=dict(settings),
                     cases=tuple(cases), grid=grid)


def expand(spec: SweepSpec) -> list[Trial]:
    """Every trial of the sweep, in a stable order; settings validated up front."""
    keys = list(spec.grid)
    trials: list[Trial] = []
    for case in spec.cases:
        case = dict(case)
        name = str(case.pop("name", "trial"))
        group = case.pop("group", None)
        for values in itertools.product(*(spec.grid[k] for k in keys)):
            for seed in spec.seeds:
                try:
                    settings = load_settings(spec.settings, case,
                                             dict(zip(keys, values, strict=True)),
                                             {"seed": seed})
                except UserError as exc:
                    raise UserError(f"case {name!r}: {exc}") from None
                trials.append(Trial(name, settings, None if group is None else str(group)))
    seen: dict[str, str] = {}
    for t in trials:
        if t.id in seen:
            raise UserError(f"cases {seen[t.id]!r} and {t.case!r} define the same trial "
                            f"({t.settings.world.object}, seed {t.settings.seed}): give one "
                            "of them other settings or another name")
        seen[t.id] = t.case
    _check_names(trials)
    return smoke.first(trials, smoke.TRIALS)


def _check_names(trials: list[Trial]) -> None:
    """A misspelt object, hand or unknown is one error now, not a failed trial per seed."""
    from vlr.kinematics import HandModel
    from vlr.spec import SpecError, load_hand, load_object
    from vlr.world import check_estimator, check_unknowns

    seen: set = set()
    for t in trials:
        s, w = t.settings, t.settings.world
        key = (w.object, w.hand, w.true_hand, s.filter.unknowns,
               json.dumps(s.filter.priors, sort_keys=True), s.filter.estimator,
               s.loop.exploration)
        if key in seen:
            continue
        seen.add(key)
        try:
            load_object(w.object)
            model = HandModel.from_spec(load_hand(w.hand))
            if w.true_hand:
                load_hand(w.true_hand)
            check_unknowns(s, model)
            check_estimator(s)
        except (SpecError, FileNotFoundError, UserError) as exc:
            raise UserError(f"case {t.case!r}: {exc}") from None


def trial_path(out: Path, trial: Trial) -> Path:
    return out / "trials" / f"{trial.id}.json"


def read_record(path: Path) -> dict[str, Any]:
    """One trial record; a file that is not one (cut short, edited by hand, a full disk) is
    a UserError naming it."""
    try:
        rec = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise UserError(f"trial record {path} is not valid JSON ({exc})") from None
    if not isinstance(rec, dict) or "status" not in rec:
        raise UserError(f"trial record {path} has no 'status'")
    return rec


def pending(trials: Iterable[Trial], out: Path, retry_failed: bool = False) -> list[Trial]:
    """Trials without a readable record (and failed ones, if asked).

    A record that cannot be read (cut short by a crash on a filesystem that does not rename
    atomically, or edited by hand) is a trial to run again, with a warning naming it: it must
    not stop the sweep it belongs to from resuming."""
    todo = []
    for t in trials:
        p = trial_path(out, t)
        if not p.exists():
            todo.append(t)
            continue
        try:
            status = read_record(p).get("status")
        except UserError as exc:
            _LOG.warning("%s: running that trial again", exc)
            todo.append(t)
            continue
        if retry_failed and status != "ok":
            todo.append(t)
    return todo


def _record(trial: Trial) -> dict[str, Any]:
    """What every record of `trial` holds, whatever became of it."""
    from vlr.provenance import code_version

    return {"id": trial.id, "case": trial.case, "group": trial.group,
            "settings": trial.settings.flat(), "code": code_version()}


def failure_record(trial: Trial, error: str) -> dict[str, Any]:
    """The record of a trial that produced no result (the executor's worker died): the same
    fields as `run_one`'s failed trials, so the tables list it and `--retry-failed` reruns
    it."""
    return {**_record(trial), "status": "error", "error": error}


def run_one(trial: Trial, out: Path, keep_files: bool = False,
            write: bool = True) -> dict[str, Any]:
    """Run one trial and write its record atomically (unless `write` is False); a failure is
    recorded, not raised.

    Runs in a worker process (top-level function: picklable) or a Ray task
    (`vlr.executors`). Seeds fix its numbers whichever worker runs it."""
    from vlr.run import run_identification

    record = _record(trial)
    try:
        run = run_identification(trial.settings)
        if keep_files:
            run.write(out / "trials" / trial.id)
        result = dict(run.summary)
        result.pop("settings", None)
        record.update(status="ok", result=result)
    except Exception as exc:  # noqa: BLE001 - a sweep reports a failed trial and goes on
        record.update(status="error", error=f"{type(exc).__name__}: {exc}",
                      traceback=traceback.format_exc(limit=6))
    if write:
        write_json_atomic(trial_path(out, trial), record)
    return record


# `vlr.io.atomic_path`'s temporary files: "." + the file's stem + "." + mkstemp's 8 random
# characters + the file's suffix. A killed writer leaves one behind.
_TEMP_FILE = re.compile(r"^\..+\.[A-Za-z0-9_]{8}\.[A-Za-z0-9]+$")


def remove_temp_files(out: Path) -> int:
    """Remove the temporary files of atomic writes that a kill interrupted, in OUT (the
    tables), OUT/trials (the records) and OUT/trials/<id> (`--keep-files`); how many.

    They are never read as results (records are found by their trials' ids, `collect`
    skips dot files); removing them keeps a resumed folder the one an uninterrupted run
    leaves. Called before any trial of the sweep runs, when nothing of it is writing."""
    trials = out / "trials"
    folders = [out, trials, *(trials.iterdir() if trials.is_dir() else ())]
    removed = 0
    for folder in folders:
        if not folder.is_dir():
            continue
        for p in folder.iterdir():
            if p.is_file() and _TEMP_FILE.match(p.name):
                p.unlink(missing_ok=True)
                removed += 1
    return removed


# --------------------------------------------------------------------------- tables

PAPER_ITERATIONS = 15   # docs/METHOD.md 6: the paper converged in 15.1 +- 3.6 iterations

# Per-trial columns: (header, path into the record). Paths name keys of result.json.
COLUMNS: list[tuple[str, tuple[str, ...]]] = [
    ("case", ("case",)), ("group", ("group",)), ("backend", ("settings", "world.backend")),
    ("object", ("settings", "world.object")), ("hand", ("settings", "world.hand")),
    ("true_hand", ("settings", "world.true_hand")),
    ("estimator", ("settings", "filter.estimator")),
    ("particles", ("settings", "filter.particles")),
    ("seed", ("settings", "seed")), ("status", ("status",)),
    ("converged", ("result", "converged")), ("iterations", ("result", "converged_at")),
    ("proximal_deg", ("result", "errors", "proximal_deg_mean")),
    ("distal_deg", ("result", "errors", "distal_deg_mean")),
    ("contact_mm", ("result", "errors", "contact_mm_mean")),
    ("coverage", ("result", "coverage")),
    ("coverage_tolerant", ("result", "coverage_tolerant")),
    ("prior_coverage", ("result", "prior_coverage")),
    ("s_per_iteration", ("result", "timing", "filter_s_per_iteration_median")),
    ("s_per_trial", ("result", "timing", "filter_s")),
    ("grasp_lost_at", ("result", "grasp_lost_at")),
    ("model_check", ("result", "model_check", "verdict")),
    ("model_check_statistic", ("result", "model_check", "statistic")),
    ("model_check_from", ("result", "model_check", "first_action_flagged")),
]


def _get(d: Any, path: tuple[str, ...]) -> Any:
    for k in path:
        if not isinstance(d, dict) or k not in d:
            return None
        d = d[k]
    return d


def _at_paper_budget(rec: dict[str, Any], key: str) -> Any:
    """A per-iteration figure after the paper's 15 actions (the grasp's update is entry 0),
    or at the stop of a trial that converged before."""
    by_it = _get(rec, ("result", key)) or []
    if len(by_it) > PAPER_ITERATIONS:
        return by_it[PAPER_ITERATIONS]
    if by_it and _get(rec, ("result", "converged")):
        return by_it[-1]
    return None


def _object_unknowns(row: dict[str, Any], errors: dict[str, Any], suffix: str) -> None:
    """The object's unknowns' absolute errors (`vlr.results`): its mass [g], each
    coordinate of its centre of mass asked for [mm] and its surface's curvature [1/m], at
    every contact ("all") or at a finger's."""
    if errors.get("object_mass_g") is not None:
        row[f"object_mass_g{suffix}"] = errors["object_mass_g"]
    for axis, v in (errors.get("object_com_mm") or {}).items():
        row[f"object_com_mm{suffix}.{axis}"] = v
    for where, v in (errors.get("curvature_per_m") or {}).items():
        row[f"curvature_per_m{suffix}.{where}"] = v


def _unknown_estimates(row: dict[str, Any], estimates: dict[str, Any]) -> None:
    """The unknowns' estimates themselves (posterior median and 95% interval), in grams,
    millimetres, 1/m, N m/rad and N/m: `mass_g.median`, `com_x_mm.low`,
    `curvature_all.high`, `length_left.proximal_mm.median`, `spring_thumb.distal.median`,
    `tendon_all_n_per_m.median`, ... The errors above lose their sign and whether the
    interval held the truth."""
    for spec, e in estimates.items():
        kind, _, where = spec.partition(":")
        names = {"mass": ("mass_g", 1e3), "com": (f"com_{where}_mm", 1e3),
                 "curvature": (f"curvature_{where or 'all'}", 1.0),
                 "length": (f"length_{where}_mm", 1e3), "stiffness": (f"spring_{where}", 1.0),
                 "tendon": (f"tendon_{where or 'all'}_n_per_m", 1.0)}
        if kind not in names or not isinstance(e, dict):
            continue
        name, scale = names[kind]
        for stat in ("median", "low", "high"):
            if e.get(stat) is not None:
                row[f"{name}.{stat}"] = e[stat] * scale


def _proximal_links_mm(errors: dict[str, Any]) -> float | None:
    """The mean error over the proximal links alone. The paper's novel-finger unknown is the
    proximal link (docs/METHOD.md 3, 6); the pad's offset along the distal link is ours (our novel
    fingers change it too), so the paper's figure is compared with this, shown beside the
    mean over both."""
    by_joint = errors.get("link_length_mm_by_joint") or {}
    proximal = [v for joint, v in by_joint.items() if joint.endswith(".proximal")]
    return float(np.mean(proximal)) if proximal else None


def _row(rec: dict[str, Any]) -> dict[str, Any]:
    row = {name: _get(rec, path) for name, path in COLUMNS}
    # Records from before the estimator was a setting ran the particle filter; the unscented
    # Kalman filter has sigma points, not `filter.particles`.
    row["estimator"] = row["estimator"] or "pf"
    if row["estimator"] != "pf":
        row["particles"] = None
    row["proximal_deg_at_15"] = _at_paper_budget(rec, "proximal_deg_by_iteration")
    # The paper's "joints" figure (its NH rows): every joint's error together. Records from
    # before it was written hold the proximal and distal means of two-joint fingers.
    errors = _get(rec, ("result", "errors")) or {}
    joints = errors.get("joint_deg_mean")
    if joints is None and None not in (errors.get("proximal_deg_mean"),
                                       errors.get("distal_deg_mean")):
        joints = (errors["proximal_deg_mean"] + errors["distal_deg_mean"]) / 2
    row["joints_deg"] = joints
    # The convergence measure itself (docs/METHOD.md 3), at the end and after the paper's budget,
    # for comparison with its floor (`vlr crb`).
    ci = _get(rec, ("result", "ci_deg_by_iteration")) or []
    row["ci_deg"] = ci[-1] if ci else None
    row["ci_deg_at_15"] = ci[PAPER_ITERATIONS] if len(ci) > PAPER_ITERATIONS else None
    for finger, v in (errors.get("link_length_mm") or {}).items():
        row[f"length_mm.{finger}"] = v
    if (links := _proximal_links_mm(errors)) is not None:
        row["proximal_link_mm"] = links
    for joint, v in (errors.get("stiffness") or {}).items():
        row[f"stiffness.{joint}"] = v
    _object_unknowns(row, errors, "")
    _unknown_estimates(row, _get(rec, ("result", "unknown_estimates")) or {})
    # The same figures of the posterior median (vlr.filter.Summary), where recorded.
    median = _get(rec, ("result", "errors_median")) or {}
    if median:
        row["proximal_deg_median"] = median.get("proximal_deg_mean")
        row["joints_deg_median"] = median.get("joint_deg_mean")
        row["proximal_deg_median_at_15"] = _at_paper_budget(
            rec, "proximal_median_deg_by_iteration")
        if (links := _proximal_links_mm(median)) is not None:
            row["proximal_link_mm_median"] = links
        for joint, v in (median.get("stiffness") or {}).items():
            row[f"stiffness_median.{joint}"] = v
        _object_unknowns(row, median, "_median")
    # The code it ran at (`vlr.provenance`).
    if (code := rec.get("code")) is not None:
        row["commit"] = code["commit"][:12] + ("+dirty" if code.get("dirty") else "")
    if rec.get("status") != "ok":
        row["error"] = rec.get("error")
    return row


def collect(out: Path, trials: Iterable[Trial] | None = None,
            skip_unreadable: bool = False) -> list[dict[str, Any]]:
    """The records of the sweep's trials found in OUT/trials (all of them if trials is None),
    in the sweep's order.

    A record that cannot be read is a UserError naming it, or, with `skip_unreadable` (the
    tables a run writes as it ends, an interrupted one included), left out with a warning:
    its trial is run again on `--resume`."""
    if trials is None:
        paths = sorted(p for p in (out / "trials").glob("*.json")
                       if not p.name.startswith("."))
    else:
        paths = [trial_path(out, t) for t in trials]
    records = []
    for p in paths:
        if not p.exists():
            continue
        try:
            records.append(read_record(p))
        except UserError as exc:
            if not skip_unreadable:
                raise UserError(f"{exc}: delete it, or rerun the sweep with --resume, to "
                                "run that trial again") from None
            _LOG.warning("%s: left out of the tables (--resume runs that trial again)", exc)
    return records


def _fmt(values: list[float], digits: int) -> str:
    v = [x for x in values if x is not None and math.isfinite(x)]
    if not v:
        return "-"
    if len(v) == 1:
        return f"{v[0]:.{digits}f}"
    return f"{np.mean(v):.{digits}f} ± {np.std(v, ddof=1):.{digits}f}"


SUMMARY_COLUMNS = [("proximal [deg]", "proximal_deg", 2),
                   ("proximal at 15 [deg]", "proximal_deg_at_15", 2),
                   ("distal [deg]", "distal_deg", 2),
                   ("joints [deg]", "joints_deg", 2),
                   ("95% interval at 15 [deg]", "ci_deg_at_15", 2),
                   ("contact [mm]", "contact_mm", 2), ("iterations", "iterations", 1),
                   ("coverage", "coverage", 2), ("coverage (0.1 deg)", "coverage_tolerant", 2),
                   ("model check statistic", "model_check_statistic", 2),
                   ("s/iteration", "s_per_iteration", 2),
                   ("filter s/trial", "s_per_trial", 1),
                   ("proximal link error [mm]", "proximal_link_mm", 2),
                   ("proximal, median [deg]", "proximal_deg_median", 2),
                   ("proximal at 15, median [deg]", "proximal_deg_median_at_15", 2),
                   ("joints, median [deg]", "joints_deg_median", 2),
                   ("proximal link error, median [mm]", "proximal_link_mm_median", 2)]


# What the summary is always split by (row columns, and the settings they come from);
# `varying_settings` adds a sweep's grid keys.
SUMMARY_KEYS = ("case", "backend", "object", "hand", "true_hand", "estimator", "particles")
_SUMMARY_SETTINGS = ("world.backend", "world.object", "world.hand", "world.true_hand",
                     "filter.estimator", "filter.particles")


def varying_settings(records: list[dict[str, Any]]) -> list[str]:
    """The settings, the seed aside, that differ between the trials of one case: a sweep's
    grid keys (`grid: {filter.jitter_h: [0.4, 0.2]}`). Each gets a column in the tables and splits
    the summary, so that a grid's values are not averaged together."""
    by_case: dict[Any, list[dict[str, Any]]] = {}
    for r in records:
        by_case.setdefault(r.get("case"), []).append(r.get("settings") or {})
    keys: set[str] = set()
    for settings in by_case.values():
        for k in set().union(*settings) - {"seed", *_SUMMARY_SETTINGS}:
            if len({json.dumps(st.get(k), sort_keys=True) for st in settings}) > 1:
                keys.add(k)
    return sorted(keys)


def _setting(rec: dict[str, Any], key: str) -> Any:
    v = (rec.get("settings") or {}).get(key)
    return json.dumps(v) if isinstance(v, list | dict) else v


def summarize_rows(rows: list[dict[str, Any]],
                   grid: Iterable[str] = ()) -> list[dict[str, str]]:
    """Mean ± sd over seeds per (case, backend, object, hand, true hand, estimator,
    particles) and per value of each `grid` setting (`varying_settings`)."""
    key_names = (*SUMMARY_KEYS, *grid)
    groups: dict[tuple, list[dict[str, Any]]] = {}
    for r in rows:
        groups.setdefault(tuple(r.get(k) for k in key_names), []).append(r)
    out = []
    for key, rs in groups.items():
        ok = [r for r in rs if r.get("status") == "ok"]
        s = dict(zip(key_names, ["" if k is None else str(k) for k in key], strict=True))
        s["trials"] = f"{len(ok)}/{len(rs)}"
        s["converged"] = f"{sum(bool(r.get('converged')) for r in ok)}/{len(ok)}"
        s["grasps lost"] = f"{sum(r.get('grasp_lost_at') is not None for r in ok)}/{len(ok)}"
        # `vlr.model_check`: the trials whose model did not explain what the filter saw.
        checked = [r for r in ok if r.get("model_check") in ("consistent", "inconsistent")]
        s["model check flagged"] = (
            f"{sum(r['model_check'] == 'inconsistent' for r in checked)}/{len(checked)}"
            if checked else "-")
        for title, col, digits in SUMMARY_COLUMNS:
            s[title] = _fmt([r.get(col) for r in ok], digits)
        extra = sorted({k for r in ok for k in r if k.startswith(
            ("length_mm.", "stiffness.", "stiffness_median.", "object_mass_g",
             "object_com_mm", "curvature_per_m"))})
        for col in extra:
            digits = 4 if col.startswith("stiffness") else 2
            unit = ("N m/rad" if col.startswith("stiffness")
                    else "g" if col.startswith("object_mass")
                    else "1/m" if col.startswith("curvature") else "mm")
            s[f"{col} error [{unit}]"] = _fmt([r.get(col) for r in ok], digits)
        out.append(s)
    return out


def _csv_text(rows: list[dict[str, Any]]) -> str:
    cols: list[str] = []
    for r in rows:
        cols += [c for c in r if c not in cols]
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=cols, lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow(r)
    return buf.getvalue()


def markdown_table(summary: list[dict[str, str]]) -> str:
    """GitHub Markdown of the summary rows (columns that are empty everywhere dropped)."""
    if not summary:
        return "(no finished trials)\n"
    cols: list[str] = []
    for r in summary:
        cols += [c for c in r if c not in cols]
    cols = [c for c in cols if any(r.get(c) not in ("", "-", None) for r in summary)]
    lines = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    for r in summary:
        lines.append("| " + " | ".join(str(r.get(c, "")) for c in cols) + " |")
    return "\n".join(lines) + "\n"


def write_tables(out: Path, records: list[dict[str, Any]], title: str = "sweep",
                 note: str = "") -> dict[str, Path]:
    """table.csv (per trial), summary.csv and summary.md (per case), written atomically."""
    out.mkdir(parents=True, exist_ok=True)
    grid = varying_settings(records)
    rows = [{**_row(r), **{k: _setting(r, k) for k in grid}} for r in records]
    summary = summarize_rows(rows, grid)
    # Each group (cases pooled, e.g. the known hand over four objects) as one more row.
    grouped = [{**r, "case": r["group"], "object": "all"} for r in rows if r.get("group")]
    summary += summarize_rows(grouped, grid)
    paths = {"table": out / "table.csv", "summary_csv": out / "summary.csv",
             "summary_md": out / "summary.md"}
    write_text_atomic(paths["table"], _csv_text(rows))
    write_text_atomic(paths["summary_csv"], _csv_text(summary))
    failed = [r for r in rows if r.get("status") != "ok"]
    md = f"# {title}\n\n{note}{markdown_table(summary)}"
    if failed:
        md += "\nFailed trials:\n\n" + "".join(
            f"- {r['case']} {r['object']} seed {r['seed']}: {r.get('error')}\n" for r in failed)
    write_text_atomic(paths["summary_md"], md)
    ok = [r for r in records if r.get("status") == "ok" and r["result"].get("errors")]
    if ok:
        from vlr.plots import boxplots

        cases = {r["case"] for r in ok}
        box_rows = [{**r["result"], "object": (f"{r['case']}\n{r['result']['object']}"
                                               if len(cases) > 1
                                               else r["result"]["object"])} for r in ok]
        paths["boxplots"] = boxplots(box_rows, out / "boxplots.png")
    return paths
