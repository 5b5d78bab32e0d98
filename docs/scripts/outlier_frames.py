"""The known hand from rendered frames when some frames' tag pose is wrong
(docs/RESULTS.md section 5, session 38).

A one-off diagnostic, not part of the package. A planar tag's pose has two solutions, and
on a real camera the wrong one sometimes wins (a small or far tag, a near-frontal view): the
pose comes out tilted by several degrees about an axis in the tag's plane, its centre
nearly where it was. The sim's ideal renders never do that. Here each frame the filter
receives is, with probability RATE, tilted by FLIP degrees about a random axis in the tag's
plane through its centre (its own random stream, seeded by the trial's seed); the trial is
otherwise `vlr identify`'s (the sim's defaults, the trial settings below). Per trial it
prints the posterior median's proximal error, strict coverage and the mean 95% joint
interval after 15 actions, and appends a row to `--csv`. `--summarize` prints the arms'
means, split by whether the grasp's frame was tilted, beside untilted baselines.

    MUJOCO_GL=egl python docs/scripts/outlier_frames.py --objects apple,wine_glass \
        --seeds 0-4 --rate 0.1 --flip 5 [--dof 4 --scale 1.581] [--csv FILE]
    python docs/scripts/outlier_frames.py --summarize docs/results/outlier-frames.csv \
        --baseline docs/results/sim-scales-075.csv \
        --baseline "docs/results/likelihood-t-core.csv#t4 core"

Rows are appended to `--csv` one trial at a time, so an interrupted run keeps the trials it
finished (a file of other columns is refused).
"""

import argparse
import csv
import math
from dataclasses import is_dataclass, replace
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from vlr.errors import UserError
from vlr.observation import PomObservation
from vlr.sweep import parse_seeds
from vlr.trial import TrialSettings, identify_trial

BASE = (0.2, 0.4, 1.0)      # the sim's scales: mm, deg, turn deg (vlr.trial.ROLLING_TURN_SIGMA)
GUESS = {"flat_screwdriver": (-10, 70, -10, 15, -10, 15)}


def tilted(obs, rng: np.random.Generator, flip_deg: float):
    """The observation turned by flip_deg about a random axis in the tag's plane (the
    object frame's x-y plane), through its centre."""
    a = rng.uniform(0, 2 * math.pi)
    axis = obs.rotation @ np.array([math.cos(a), math.sin(a), 0.0])
    turn = Rotation.from_rotvec(math.radians(flip_deg) * axis).as_matrix()
    if is_dataclass(obs):
        return replace(obs, rotation=turn @ obs.rotation)
    return PomObservation(obs.position, turn @ obs.rotation)


def run(obj: str, seed: int, args) -> dict:
    k = args.scale
    settings = TrialSettings(
        backend="sim", object=obj, particles=args.particles, seed=seed, max_iterations=20,
        rolling=True, sigma_pos_mm=BASE[0] * k, sigma_rot_deg=BASE[1] * k,
        sigma_turn_deg=BASE[2] * k, likelihood_dof=args.dof,
        nominal_theta_deg=GUESS.get(obj, (-10, 15)), prior_spread_deg=10,
        contact_prior="surface", limit_stiffness=17.0, ramp_time=0.1)
    rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(38,)))
    count = {"frames": 0, "tilted": []}

    def through(w):
        inner = w.observer

        def observer():
            obs = inner()
            if obs is None:
                return None
            count["frames"] += 1
            if rng.random() < args.rate:
                count["tilted"].append(count["frames"] - 1)   # 0: the grasp's frame
                return tilted(obs, rng, args.flip)
            return obs
        return observer

    s = identify_trial(settings, observe_through=through).summary
    ci = s.get("ci_deg_by_iteration", [])
    return {"object": obj, "seed": seed, "dof": args.dof, "scale": k, "rate": args.rate,
            "flip_deg": args.flip, "frames": count["frames"], "tilted": len(count["tilted"]),
            "tilted_frames": ";".join(str(k) for k in count["tilted"]),
            "proximal_deg_median": s["errors_median"]["proximal_deg_mean"],
            "coverage": s["coverage"], "coverage_tolerant": s["coverage_tolerant"],
            "ci_deg_at_15": ci[15] if len(ci) > 15 else float("nan")}


KNOWN = ("apple", "wine glass", "gelatin box", "flat screwdriver")


def _baseline(spec: str) -> tuple[str, list[dict]]:
    """`TABLE#SETTING`: a sweep table's known-hand rows of one setting (the case name after
    its object: "" for the plain object, e.g. "t4 core"), untilted runs to compare with."""
    path, _, setting = spec.partition("#")
    names = {o if not setting else f"{o}, {setting}" for o in KNOWN}
    rows = [r for r in csv.DictReader(Path(path).open())
            if r["case"] in names and not r.get("true_hand") and r["status"] == "ok"]
    if not rows:
        raise SystemExit(f"--baseline {spec!r}: no known-hand rows of that setting")
    return spec, rows


def summarize(paths: list[Path], baselines: list[str]) -> None:
    """Per arm (nu, scale, flip): the mean over trials, all of them, those whose grasp frame
    (the one the prior is drawn about) was clean, and those whose grasp frame was tilted;
    beside each, the baselines' untilted means over the same seeds."""
    rows = [r for p in paths for r in csv.DictReader(p.open())]
    bases = [_baseline(b) for b in baselines]
    arms = dict.fromkeys((r["dof"], r["scale"], r["flip_deg"], r["rate"]) for r in rows)
    print("nu, scale, flip [deg], rate | trials | proximal, median [deg] | coverage strict / "
          "within 0.1 deg | 95% interval after 15 [deg] | untilted, same seeds: proximal, "
          "strict coverage")

    def mean(key: str, sel: list[dict]) -> float:
        return float(np.nanmean([float(r[key]) for r in sel]))

    for arm in arms:
        group = [r for r in rows if (r["dof"], r["scale"], r["flip_deg"], r["rate"]) == arm]
        first = [r for r in group if "0" in r["tilted_frames"].split(";")]
        for name, sel in (("all", group), ("grasp frame clean",
                                           [r for r in group if r not in first]),
                          ("grasp frame tilted", first)):
            if not sel:
                continue
            seeds = {r["seed"] for r in sel}
            untilted = "; ".join(
                f"{spec}: {mean('proximal_deg_median', b):.2f}, {mean('coverage', b):.2f}"
                for spec, base in bases if (b := [r for r in base if r["seed"] in seeds]))
            print(f"{', '.join(arm)} {name} | {len(sel)} | "
                  f"{mean('proximal_deg_median', sel):.2f} | {mean('coverage', sel):.2f} / "
                  f"{mean('coverage_tolerant', sel):.2f} | {mean('ci_deg_at_15', sel):.2f} | "
                  f"{untilted}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--objects", default="apple,wine_glass,gelatin_box,flat_screwdriver")
    ap.add_argument("--seeds", default="0-4")
    ap.add_argument("--particles", type=int, default=10000)
    ap.add_argument("--rate", type=float, default=0.1, help="share of frames tilted")
    ap.add_argument("--flip", type=float, default=5.0, help="the tilt [deg]")
    ap.add_argument("--dof", type=float, default=0.0, help="the likelihood's nu (0 Gaussian)")
    ap.add_argument("--scale", type=float, default=1.0, help="factor on the sim's scales")
    ap.add_argument("--csv", type=Path, default=None)
    ap.add_argument("--summarize", type=Path, nargs="+", default=None, metavar="CSV",
                    help="print the arms' means from these CSVs and stop")
    ap.add_argument("--baseline", action="append", default=[], metavar="TABLE#SETTING",
                    help="with --summarize: a sweep table's untilted known-hand runs of one "
                    "setting to print beside each arm (e.g. docs/results/sim-scales-075.csv)")
    args = ap.parse_args()
    try:
        seeds = parse_seeds(args.seeds)
    except UserError as e:
        ap.error(str(e))
    if args.summarize:
        summarize(args.summarize, args.baseline)
        return
    if not 0 <= args.rate <= 1:
        ap.error(f"--rate {args.rate}: a share of frames must be in [0, 1]")
    if not args.scale > 0:
        ap.error(f"--scale {args.scale}: must be > 0")
    for obj in args.objects.split(","):
        for seed in seeds:
            row = run(obj, seed, args)
            print(" ".join(f"{k}={v:.3f}" if isinstance(v, float) else f"{k}={v}"
                           for k, v in row.items()), flush=True)
            if args.csv is not None:
                new = not args.csv.exists()
                if not new:
                    with args.csv.open() as f:
                        header = next(csv.reader(f), [])
                    if header != list(row):
                        raise SystemExit(f"--csv {args.csv}: its columns are not this "
                                         "script's; choose another file")
                with args.csv.open("a", newline="") as f:
                    w = csv.DictWriter(f, fieldnames=list(row))
                    if new:
                        w.writeheader()
                    w.writerow(row)


if __name__ == "__main__":
    main()
