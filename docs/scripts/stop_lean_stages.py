"""Where a joint's lean off its open stop comes from, stage by stage (docs/RESULTS.md section
5, session 39).

A one-off diagnostic, not part of the package. Near a distal joint's open stop the
posterior median leans 2-4 degrees off it (the spring row's right distal joint, session 37;
the flat screwdriver's left distal joint, session 38), more than a Gaussian cut at the stop
moves a median. Each filter iteration changes the particles in three stages: the motion
step (the action solved per particle), the update (weights, resampling) and the jitter (the
Liu-West kernel, then the settle at the command). This runs one trial of a sweep file's
case with a `watch` that reads the joint's particles after each stage, joins the sim's
truth afterwards (scoring only: the filter never sees it), and prints per iteration the
median's error after each stage and the share of particles on the stop, then the lean's
change summed per stage.

    MUJOCO_GL=egl python docs/scripts/stop_lean_stages.py docs/sweeps/screwdriver-guess.yaml \
        --case "flat screwdriver, stops at 5 N m/rad" --seed 0 --joint left.1 [--json FILE]
    python docs/scripts/stop_lean_stages.py --show FILE --joint right.1
"""

import argparse
import json
import os
import tempfile
from pathlib import Path

import numpy as np

from vlr.errors import UserError
from vlr.sweep import expand, load_sweep
from vlr.trial import identify_trial

ON_STOP_DEG = 0.25  # a particle within this of the open stop counts as on it


def run(sweep: Path, case: str, seed: int, particles: int | None) -> dict:
    """Run the trial; return every joint's per-iteration rows ({"joints": {name: rows}}):
    the lean (median minus truth) after each stage [deg], the 95% interval above the stop
    [deg] and the share on the stop, after the jitter. "motion" summarizes the particles
    whose solve succeeded; the others, every particle."""
    trials = [t for t in expand(load_sweep(sweep)) if t.case == case and t.settings.seed == seed]
    if not trials:
        cases = sorted({t.case for t in expand(load_sweep(sweep))})
        raise UserError(f"no trial of case {case!r} with seed {seed} in {sweep}; cases: {cases}")
    settings = trials[0].settings
    if particles is not None:
        settings = type(settings).from_dict({**settings.to_dict(), "particles": particles})
    stages: list[dict] = []

    def watch(pf, rec) -> None:
        m = pf.model
        n = m.n_fingers * m.n_joints
        stop = m.limits[..., 0].ravel()
        after = pf.pack(pf.state)[:, :n]
        stages.append({
            "motion": rec.prior.median[:n],
            "update": None if rec.posterior is None else rec.posterior.median[:n],
            "jitter": np.median(after, axis=0),
            "mean": after.mean(axis=0),
            "low": np.quantile(after, 0.025, axis=0) - stop,
            "high": np.quantile(after, 0.975, axis=0) - stop,
            "on_stop": np.mean(after < stop + np.radians(ON_STOP_DEG), axis=0),
        })

    trial = identify_trial(settings, watch=watch)
    m = trial.model
    names = [f"{f}.{k}" for f in m.names for k in range(m.n_joints)]
    stop = m.limits[..., 0].ravel()
    joints = {}
    for j, name in enumerate(names):
        rows = []
        for i, (s, t) in enumerate(zip(stages, trial.truths, strict=True)):
            truth = float(t.theta.ravel()[j])
            row = {"iteration": i, "truth_deg": float(np.degrees(truth - stop[j])),
                   "on_stop": float(s["on_stop"][j])}
            for key in ("motion", "update", "jitter", "mean"):
                v = s[key]
                row[key] = None if v is None else float(np.degrees(v[j] - truth))
            for key in ("low", "high"):
                row[key] = float(np.degrees(s[key][j]))
            rows.append(row)
        joints[name] = rows
    return {"sweep": str(sweep), "case": case, "seed": seed, "particles": settings.particles,
            "stop_deg": dict(zip(names, np.degrees(stop).round(3).tolist(), strict=True)),
            "joints": joints}


def attribution(rows: list[dict]) -> dict[str, float]:
    """The final lean (median minus truth after the last jitter) split into the sum of each
    stage's change of the lean: motion (the truth moves too), update, jitter; plus the
    grasp's (iteration 0's motion row is the settled prior)."""
    out = {"grasp": rows[0]["jitter"], "motion": 0.0, "update": 0.0, "jitter": 0.0}
    for prev, r in zip(rows, rows[1:], strict=False):
        out["motion"] += r["motion"] - prev["jitter"]
        upd = r["update"] if r["update"] is not None else r["motion"]
        out["update"] += upd - r["motion"]
        out["jitter"] += r["jitter"] - upd
    out["final"] = rows[-1]["jitter"]
    return out


def show(res: dict, joint: str) -> None:
    if joint not in res["joints"]:
        raise UserError(f"--joint {joint!r}: the hand's joints are {list(res['joints'])}")
    rows = res["joints"][joint]
    print(f"{res['case']}, seed {res['seed']}, joint {joint} (stop at "
          f"{res['stop_deg'][joint]:.1f} deg), {res['particles']} particles; "
          "lean = median - truth [deg]")
    print("iter | truth above stop | after motion | after update | after jitter | mean | "
          "95% above stop | on stop")
    for r in rows:
        upd = "" if r["update"] is None else f"{r['update']:+.2f}"
        print(f"{r['iteration']:4d} | {r['truth_deg']:6.2f} | {r['motion']:+.2f} | {upd} | "
              f"{r['jitter']:+.2f} | {r['mean']:+.2f} | "
              f"{r['low']:.1f}-{r['high']:.1f} | {r['on_stop']:.2f}")
    a = attribution(rows)
    print("lean's change summed per stage: " + ", ".join(f"{k} {v:+.2f}" for k, v in a.items()))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("sweep", type=Path, nargs="?")
    ap.add_argument("--case")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--joint", default="left.1", help="FINGER.JOINT, e.g. left.1")
    ap.add_argument("--particles", type=int, default=None, help="override the sweep's")
    ap.add_argument("--json", type=Path, default=None, help="write the rows here")
    ap.add_argument("--show", type=Path, default=None, help="print a JSON written before")
    args = ap.parse_args()
    try:
        if args.show is not None:
            if not args.show.is_file():
                raise UserError(f"--show {args.show}: no such file")
            try:
                res = json.loads(args.show.read_text())
            except json.JSONDecodeError as exc:
                raise UserError(f"--show {args.show}: not JSON ({exc})") from None
            if not isinstance(res, dict) or "joints" not in res:
                raise UserError(f"--show {args.show}: not a file this script wrote")
            show(res, args.joint)
            return
        if args.sweep is None or args.case is None:
            raise UserError("give a sweep file and --case (or --show FILE)")
        if not args.sweep.is_file():
            raise UserError(f"sweep file {args.sweep}: no such file")
        if args.json is not None and not args.json.parent.is_dir():
            raise UserError(f"--json {args.json}: no folder {args.json.parent}")
        res = run(args.sweep, args.case, args.seed, args.particles)
        show(res, args.joint)
    except UserError as exc:
        raise SystemExit(f"error: {exc}") from None
    if args.json is not None:
        fd, tmp = tempfile.mkstemp(dir=args.json.parent, suffix=".tmp")
        with os.fdopen(fd, "w") as fh:
            json.dump(res, fh, indent=1)
        os.replace(tmp, args.json)


if __name__ == "__main__":
    main()
