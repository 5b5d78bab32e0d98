"""`vlr model-check-calibrate`: the model check's thresholds, measured on trials the model
explains.

The model check (docs/METHOD.md 9) flags a trial whose statistic is above a threshold that
goes with the likelihood's scales; each backend's default was measured on the known hand over
objects it grasps well. On a hand or at scales of your own, identify the known hand on such
objects (five trials or more: several objects, a few seeds each), then

    vlr model-check-calibrate runs/apple runs/mug runs/box      # `vlr identify` outputs
    vlr model-check-calibrate runs/my-sweep --group "known hand" # a sweep's output folder
    vlr model-check-calibrate runs/my-sweep --out check.yaml     # and write the settings

It reads each result's object and `model_check.statistic` and prints the threshold by the
rule (`vlr.model_check.threshold_by_rule`: the median plus three times the statistic's
spread between the objects and within each), one for the
trials that read the camera alone (`filter.model_check.threshold`) and one for those that
weighed the tendons' tensions too (`threshold_tensions`), with the `--set` that applies it;
`--out` writes them as a settings file for `vlr identify --settings`. The trials must share
their backend and their likelihood's scales, which the threshold goes with.
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from vlr.errors import UserError

#: The settings a threshold goes with: trials read at others cannot share one.
SCALE_KEYS = ("world.backend", "filter.observation.sigma_pos_mm",
              "filter.observation.sigma_rot_deg", "filter.observation.sigma_turn_deg")
TENSION_KEY = "filter.observation.sigma_tension_n"


def register(sub: argparse._SubParsersAction) -> None:
    """Add the `model-check-calibrate` subcommand (entry point group vlr.commands)."""
    p = sub.add_parser("model-check-calibrate",
                       help="measure the model check's thresholds on trials the model explains",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("runs", nargs="+", help="result.json files, `vlr identify` output folders "
                   "or sweep output folders (their trials/*.json)")
    p.add_argument("--group", help="of a sweep's trials, only those of this group or case "
                   "(e.g. 'known hand')")
    p.add_argument("--out", help="write the thresholds to this settings YAML file")
    p.set_defaults(func=run)


def _records(path: Path, group: str | None = None) -> list[tuple[Path, dict[str, Any]]]:
    """(file, result) of every finished trial at `path` (of a sweep's, those whose group or
    case is `group`, when given)."""
    if path.is_dir():
        if (path / "result.json").is_file():
            files = [path / "result.json"]
        elif (path / "trials").is_dir():
            files = sorted(p for p in (path / "trials").glob("*.json")
                           if not p.name.startswith("."))
        else:
            raise UserError(f"{path}: neither a result.json nor a sweep's trials/ folder in it")
    elif path.is_file():
        files = [path]
    else:
        raise UserError(f"{path}: no such file or folder")
    out = []
    for f in files:
        try:
            data = json.loads(f.read_text())
        except (OSError, ValueError) as exc:
            raise UserError(f"{f}: not a readable JSON result ({exc})") from None
        if not isinstance(data, dict):
            raise UserError(f"{f}: not a result (a JSON object with model_check)")
        if "status" in data:  # a sweep's trial record; a failed trial has no result
            if data.get("status") != "ok" or group not in (None, data.get("group"),
                                                           data.get("case")):
                continue
            result = data.get("result")
            if not isinstance(result, dict):
                raise UserError(f"{f}: a finished trial record without its result")
            settings, data = data.get("settings", {}), dict(result)
            data.setdefault("settings", settings)
        if (not isinstance(data.get("model_check"), dict)
                or not isinstance(data.get("settings"), dict)):
            raise UserError(f"{f}: no model_check and settings in it (a `vlr identify` "
                            "result.json or a sweep's trial record)")
        stat = data["model_check"].get("statistic")
        if stat is not None and (isinstance(stat, bool) or not isinstance(stat, int | float)):
            raise UserError(f"{f}: model_check.statistic = {stat!r} is not a number")
        out.append((f, data))
    return out


def thresholds(paths: list[str], group: str | None = None) -> dict[str, Any]:
    """The rule's thresholds over the trials at `paths`: per kind ("threshold" for the camera
    alone, "threshold_tensions" with the tensions weighed) the trials, their objects, their
    statistics' median and the threshold; and the scales they share."""
    from vlr import smoke
    from vlr.model_check import (
        MIN_CALIBRATION_TRIALS,
        MIN_OBJECT_TRIALS,
        calibration_objects,
        threshold_by_rule,
    )

    trials = [rec for p in paths for rec in _records(Path(p), group)]
    if not trials:
        raise UserError(f"{' '.join(paths)}: no finished trials"
                        + (f" of group or case {group!r}" if group else ""))
    scales = {k: trials[0][1]["settings"].get(k) for k in SCALE_KEYS}
    kinds: dict[str, list[tuple[str, float]]] = {"threshold": [], "threshold_tensions": []}
    tension_scale: tuple[Path, float] | None = None
    undecided = 0
    for f, res in trials:
        mine = {k: res["settings"].get(k) for k in SCALE_KEYS}
        if mine != scales:
            bad = next(k for k in SCALE_KEYS if mine[k] != scales[k])
            raise UserError(f"{f}: {bad} = {mine[bad]!r}, where {trials[0][0]} has "
                            f"{scales[bad]!r}: a threshold goes with one backend's scales")
        stat = res["model_check"].get("statistic")
        if stat is None or not math.isfinite(stat):
            undecided += 1
            continue
        sigma_t = res["settings"].get(TENSION_KEY) or 0.0
        kind = "threshold_tensions" if sigma_t > 0 else "threshold"
        if sigma_t > 0:
            tension_scale = tension_scale or (f, sigma_t)
            if sigma_t != tension_scale[1]:
                raise UserError(f"{f}: {TENSION_KEY} = {sigma_t!r}, where {tension_scale[0]} "
                                f"has {tension_scale[1]!r}: a threshold goes with one scale")
        obj = res.get("object") or res["settings"].get("world.object")
        kinds[kind].append((str(obj), float(stat)))
    out: dict[str, Any] = {"scales": scales, "undecided": undecided, "kinds": {},
                           "tension_scale_n": tension_scale[1] if tension_scale else None}
    for kind, pairs in kinds.items():
        if not pairs:
            continue
        need = smoke.cap(MIN_CALIBRATION_TRIALS, smoke.TRIALS)
        objects, short = calibration_objects([o for o, _ in pairs])
        left = [(o, sum(p == o for p, _ in pairs)) for o in short]
        kept = [(o, x) for o, x in pairs if o in objects]
        if len(kept) < need or len(objects) < 2:
            raise UserError(f"{len(pairs)} decided trials on {len(objects) + len(short)} "
                            f"object(s) for {kind}: the rule needs at least {need} on two "
                            f"objects or more, {smoke.cap(MIN_OBJECT_TRIALS, 1)} on each "
                            "(several objects, a few seeds each)")
        pairs = kept
        names, stats = [o for o, _ in pairs], [x for _, x in pairs]
        out["kinds"][kind] = {"trials": len(pairs), "objects": len(objects),
                              "median": float(np.median(stats)), "left_out": left,
                              "threshold": round(threshold_by_rule(names, stats), 2)}
    return out


def run(args: argparse.Namespace) -> int:
    from vlr import smoke
    from vlr.io import check_output_file, write_text_atomic
    from vlr.model_check import MIN_OBJECT_TRIALS

    need = smoke.cap(MIN_OBJECT_TRIALS, 1)
    if args.out:
        check_output_file(args.out, "--out")
    res = thresholds(args.runs, args.group)
    sc = res["scales"]
    print(f"{sc['world.backend']} backend, likelihood scales {sc[SCALE_KEYS[1]]} mm / "
          f"{sc[SCALE_KEYS[2]]} deg / turn {sc[SCALE_KEYS[3]]} deg"
          + (f"; {res['undecided']} undecided trials left out" if res["undecided"] else ""))
    lines = []
    for kind, k in res["kinds"].items():
        what = (f"camera and tensions ({res['tension_scale_n']} N)"
                if kind == "threshold_tensions" else "camera")
        print(f"{what}: {k['trials']} trials on {k['objects']} objects, statistic median "
              f"{k['median']:.3f} -> --set filter.model_check.{kind}={k['threshold']:.2f}"
              + "".join(f"; left out: {o} ({n} decided trial{'s' * (n > 1)}, "
                        f"fewer than {need})" for o, n in k["left_out"]))
        lines.append(f"filter.model_check.{kind}: {k['threshold']:.2f}")
    if args.out:
        cmd = " ".join(args.runs) + (f" --group '{args.group}'" if args.group else "")
        write_text_atomic(args.out, f"# vlr model-check-calibrate {cmd}\n"
                          + "\n".join(lines) + "\n")
        print(f"wrote {args.out} (vlr identify --settings {args.out})")
    return 0
