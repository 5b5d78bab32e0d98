"""`vlr gap`: the model-world gap from the simulator's true state (`sim.gap`), per object and
seed, model term by term, as a report, JSON and a CSV table.

    vlr gap --object all --seeds 0-2 --csv gap.csv
"""

from __future__ import annotations

import argparse
import csv
import io
import math
from dataclasses import replace

from vlr.sim.gap import OBJECTS, STARTS, GapSettings, filter_rung, format_report, gap_report

from vlr.errors import UserError

__all__ = ["register", "table_rows", "CSV_COLUMNS"]

CSV_COLUMNS = ("rung", "friction", "spin_friction", "object", "seed", "ramp_time", "start",
               "actions", "ratio_position",
               "ratio_orientation", "pooled_position", "pooled_orientation", "drift_position",
               "drift_orientation", "failed_solves")


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("gap", help="the model-world gap from the simulator's true state: "
                       "per-action, static and open-loop drift, model term by term",
                       description=__doc__,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--object", default="apple",
                   help=f"object name or spec file, a comma list, or 'all' ({', '.join(OBJECTS)})")
    p.add_argument("--hand", default="modelo", help="hand name or spec file (default modelo)")
    p.add_argument("--seeds", default="0", help="seeds of the random actions, e.g. 0-2 "
                   "(default 0; vlr identify's actions for the same seed)")
    p.add_argument("--actions", type=int, default=30, help="random actions (default 30)")
    p.add_argument("--drift-actions", type=int, default=15,
                   help="actions predicted open loop for the drift (default 15)")
    p.add_argument("--start", choices=STARTS, default="settle",
                   help="where each prediction starts: the true configuration settled with "
                   "glued contacts (default), or with the sim's own contact loads as the "
                   "contacts' stretch, relaxed (sim-loads)")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="a setting of the model, as `vlr identify --set filter.motion.KEY=V` "
                   "(e.g. filter.motion.limit_stiffness=100), or the sim's "
                   "world.options.ramp_time; the pads' coefficients set here are the "
                   "spin and sliding rungs' own")
    p.add_argument("--fit", metavar="UNKNOWN",
                   help="profile the value of an unknown the model wants from the true "
                   "states, on every rung (as --unknown: stiffness:thumb.distal, "
                   "length:left.proximal, mass, ...)")
    p.add_argument("--fit-range", metavar="LOW,HIGH", type=_pair,
                   help="the profile's range [SI units] (default: the unknown's prior)")
    p.add_argument("--fit-points", type=int, default=GapSettings.fit_points,
                   help=f"the profile's values (default {GapSettings.fit_points})")
    p.add_argument("--fit-turn-deg", type=float, default=0.0, metavar="DEG",
                   help="cost the profile with the filter's likelihood and this turn scale "
                   "(the sim trials' is 1; default 0: squared motion errors, no turn)")
    p.add_argument("--json", help="write the reports (per object and seed, per rung) as JSON")
    p.add_argument("--csv", help="write the table: one row per object, seed and rung")
    p.set_defaults(func=run)


def _pair(text: str) -> tuple[float, float]:
    try:
        lo, hi = (float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: expected LOW,HIGH") from None
    return lo, hi


def _pooled(per_action: list[dict], kind: str) -> float:
    """Summed error over summed true motion of the solved actions ("position" or
    "orientation"): what an action that hardly moves the object cannot inflate."""
    unit = "mm" if kind == "position" else "deg"
    ok = [a for a in per_action if a["ok"]]
    motion = sum(a[f"motion_{kind}_{unit}"] for a in ok)
    return sum(a[f"error_{kind}_{unit}"] for a in ok) / motion if motion > 0 else math.nan


def table_rows(rep: dict) -> list[dict]:
    """One CSV row (`CSV_COLUMNS`) per rung of a `sim.gap.gap_report`, with the pads'
    sliding mu (empty: none) and torsional mu_t [m] it was measured at."""
    return [{"rung": c["name"], "friction": c.get("friction"),
             "spin_friction": c.get("spin_friction"), "object": rep["object"], "seed": rep["seed"],
             "ramp_time": rep["ramp_time"], "start": rep["start"], "actions": rep["actions"],
             "ratio_position": round(c["ratio_position_mean"], 4),
             "ratio_orientation": round(c["ratio_orientation_mean"], 4),
             "pooled_position": round(_pooled(c["per_action"], "position"), 4),
             "pooled_orientation": round(_pooled(c["per_action"], "orientation"), 4),
             "drift_position": round(c["drift_ratio"], 4),
             "drift_orientation": round(c["drift_ratio_orientation"], 4),
             "failed_solves": c["failed_solves"]} for c in rep["configs"]]


def _settings(args: argparse.Namespace) -> GapSettings:
    """The model and ramp of the sim's identification, with the --set overrides."""
    from vlr.sim.backend import SimWorldOptions

    from vlr import smoke
    from vlr.settings import load_settings, parse_assignment

    sets = dict(parse_assignment(t) for t in args.set)
    bad = [k for k in sets if not k.startswith(("filter.motion.", "world.options.ramp_time",
                                                "loop.action_range_mm", "loop.action_band_mm"))]
    if bad:
        raise UserError(f"--set {bad[0]}: vlr gap takes filter.motion.*, "
                        "world.options.ramp_time and loop.action_range_mm / action_band_mm")
    tree = load_settings({"world.backend": "sim"}, sets)
    ramp = tree.world.options.get("ramp_time", SimWorldOptions.ramp_time)
    return GapSettings(actions=smoke.cap(args.actions, smoke.ACTIONS),
                       drift_actions=smoke.cap(args.drift_actions, smoke.ACTIONS),
                       motion=tree.filter.motion, loop=tree.loop, start=args.start,
                       ramp_time=ramp,
                       fit=args.fit, fit_range=args.fit_range, fit_points=args.fit_points,
                       fit_turn_deg=args.fit_turn_deg)


def run(args: argparse.Namespace) -> int:
    from vlr.io import check_output_file, write_json_atomic, write_text_atomic
    from vlr.sweep import parse_seeds

    names = OBJECTS if args.object == "all" else tuple(
        o.strip() for o in args.object.split(",") if o.strip())
    if not names:
        raise UserError(f"--object {args.object!r} names no object")
    for flag in ("json", "csv"):
        path = getattr(args, flag)
        if path:
            check_output_file(path, f"--{flag}")
    seeds = parse_seeds(args.seeds)
    base = _settings(args)
    reports = []
    for name in names:
        for seed in seeds:
            rep = gap_report(replace(base, object=name, hand=args.hand, seed=seed))
            print(format_report(rep) + "\n", flush=True)
            reports.append(rep)
    rows = [r for rep in reports for r in table_rows(rep)]
    rung = filter_rung(base.motion)
    mine = [r for r in rows if r["rung"] == rung]
    if mine:
        ori = [r["ratio_orientation"] for r in mine]
        print(f"{rung} (the filter's model), {len(mine)} object-seeds: per-action "
              f"ratio position {min(r['ratio_position'] for r in mine):.3f}-"
              f"{max(r['ratio_position'] for r in mine):.3f}, orientation {min(ori):.3f}-"
              f"{max(ori):.3f}; drift at most "
              f"{max(r['drift_position'] for r in mine):.3f} / "
              f"{max(r['drift_orientation'] for r in mine):.3f}")
    if args.json:
        write_json_atomic(args.json, reports[0] if len(reports) == 1 else {"objects": reports})
        print(f"wrote {args.json}")
    if args.csv:
        buf = io.StringIO()
        w = csv.DictWriter(buf, CSV_COLUMNS, lineterminator="\n")
        w.writeheader()
        w.writerows(rows)
        write_text_atomic(args.csv, buf.getvalue())
        print(f"wrote {args.csv}")
    return 0
