"""Where NH1's joint error comes from: the shape of the posterior over NF1's joints
(docs/RESULTS.md section 5, "NH1's joints: a ridge the camera does not see", session 31).

A one-off diagnostic, not part of the package. It runs the NH1 row of
`docs/sweeps/sim-60k-ramp.yaml` (the sim, rendered frames, 60,000 particles, the left finger
NF1 with both lengths unknown) for ACTIONS random actions, keeps the particle cloud after the
last update (`vlr.trial.identify_trial`'s `watch` hook, which must not change the filter),
and prints the left finger's posterior: quantiles of its joints and lengths, their
correlations, and the proximal joint and the lengths binned by the distal joint. The truth is
printed beside them, for scoring only. `--save FILE` keeps the cloud (.npz).

    MUJOCO_GL=egl python docs/scripts/nh1_ridge.py --seed 0 --actions 20
"""

import argparse
from pathlib import Path

import numpy as np
import yaml

from vlr.io import atomic_path
from vlr.trial import TrialSettings, identify_trial

SWEEP = Path(__file__).resolve().parents[1] / "sweeps" / "sim-60k-ramp.yaml"
LEFT = 1  # the left finger's index in the Model O's slots (thumb, left, right)


def settings(seed: int, actions: int, particles: int) -> TrialSettings:
    """The NH1 case of `SWEEP` at this seed, budget and particle count."""
    sweep = yaml.safe_load(SWEEP.read_text())
    case = next(c for c in sweep["cases"] if c.get("true_hand") == "nh1")
    d = {**sweep["settings"], **{k: v for k, v in case.items() if k != "name"},
         "seed": seed, "max_iterations": actions, "particles": particles}
    return TrialSettings.from_dict(d)


def report(theta: np.ndarray, segments: np.ndarray, truth: dict) -> None:
    """The left finger's posterior (angles [deg], lengths [mm]) against its truth."""
    tp, td = np.degrees(theta[:, LEFT, 0]), np.degrees(theta[:, LEFT, 1])
    lp, ld = segments[:, LEFT, 0] * 1e3, segments[:, LEFT, 1] * 1e3
    q = (2.5, 25, 50, 75, 97.5)
    print(f"quantiles {q}; truth: proximal {np.degrees(truth['left.0']):.2f}, "
          f"distal {np.degrees(truth['left.1']):.2f} deg (NF1's lengths 40 and 27 mm)")
    for name, v in (("proximal joint [deg]", tp), ("distal joint [deg]", td),
                    ("proximal link [mm]", lp), ("pad offset [mm]", ld)):
        print(f"  {name:21s} " + " ".join(f"{x:7.2f}" for x in np.percentile(v, q)))
    print(f"  on the distal stop (under 0.5 deg): {np.mean(td < 0.5):.2f} of the particles")
    c = np.corrcoef([tp, td, lp, ld])
    print(f"correlations: proximal-distal joints {c[0, 1]:+.2f}, distal joint-proximal link "
          f"{c[1, 2]:+.2f}, distal joint-pad offset {c[1, 3]:+.2f}, the two lengths "
          f"{c[2, 3]:+.2f}")
    print("distal joint [deg]  particles  proximal joint  proximal link  pad offset (medians)")
    for lo, hi in ((-1, 0.5), (0.5, 3), (3, 6), (6, 10), (10, 15), (15, 20), (20, 90)):
        m = (td >= lo) & (td < hi)
        if m.any():
            print(f"  {lo:5.1f} .. {hi:4.1f}  {m.sum():9d}  {np.median(tp[m]):14.2f}  "
                  f"{np.median(lp[m]):13.2f}  {np.median(ld[m]):10.2f}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--actions", type=int, default=20)
    ap.add_argument("--particles", type=int, default=60000)
    ap.add_argument("--save", type=Path, help="keep the cloud here (a .npz file)")
    a = ap.parse_args()
    if a.actions < 1 or a.particles < 100:
        ap.error(f"--actions {a.actions} --particles {a.particles}: need >= 1 and >= 100")
    # Checked before a 5-minute trial; np.savez adds ".npz" to a name without it.
    if a.save and (a.save.suffix != ".npz" or not a.save.resolve().parent.is_dir()):
        ap.error(f"--save {a.save}: expected a .npz file in an existing folder")
    cloud: dict[str, np.ndarray] = {}

    def watch(pf, rec) -> None:
        cloud["theta"], cloud["segments"] = pf.state.theta.copy(), pf.state.segments.copy()

    run = identify_trial(settings(a.seed, a.actions, a.particles), watch=watch)
    truth = run.summary["truth_theta"]
    if a.save:
        with atomic_path(a.save) as tmp:
            np.savez(tmp, **cloud)
    report(cloud["theta"], cloud["segments"], truth)


if __name__ == "__main__":
    main()
