"""NH1 with larger exploratory actions (docs/RESULTS.md section 2, "NH1's actions").

A one-off probe, not part of the package. NH1's apple grasp moves the tag about half as far
per action as the Model O's (`vlr gap --object apple --hand nh1`), so this asks whether
larger random actions identify its left finger better. It runs `vlr.trial.run_trial` on the
NH1 row's settings (the sim, rendered frames, rolling contacts, the user's grasp guess, the
left finger's two lengths unknown) at a small particle count, with the identification's
action range and band (`action_range_mm`, `action_band_mm`: 0.2-0.4 mm within 0.4 mm by
default; `vlr identify --action-range-mm`) replaced, and prints each seed's errors.

    python docs/scripts/nh1_action_size.py --range 0.3 0.6 --band 0.6 --seeds 0 1 2
"""

import argparse

import vlr.trial


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--range", nargs=2, type=float, default=(0.2, 0.4), metavar=("LOW", "HIGH"),
                   help="action magnitudes [mm] (default 0.2 0.4, the identification's)")
    p.add_argument("--band", type=float, default=0.4, help="command band [mm] (default 0.4)")
    p.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2])
    p.add_argument("--particles", type=int, default=3000)
    p.add_argument("--actions", type=int, default=20)
    args = p.parse_args()
    lo, hi = args.range
    if not 0 < lo <= hi <= args.band:
        p.error(f"--range {lo} {hi} --band {args.band}: need 0 < LOW <= HIGH <= band [mm]")
    if args.particles < 10 or args.actions < 1:
        p.error(f"--particles {args.particles} must be >= 10, --actions {args.actions} >= 1")
    print(f"NH1, actions {args.range[0]}-{args.range[1]} mm within {args.band} mm, "
          f"{args.particles} particles, {args.actions} actions")
    print("seed  proximal [deg]  distal [deg]  left proximal link [mm]  pad offset [mm]  "
          "coverage")
    for seed in args.seeds:
        settings = vlr.trial.TrialSettings(
            backend="sim", object="apple", true_hand="nh1",
            unknowns=("length:left.proximal", "length:left.distal"),
            particles=args.particles, seed=seed, max_iterations=args.actions, rolling=True,
            nominal_theta_deg=(-10.0, 15.0), prior_spread_deg=10.0,
            action_range_mm=(lo, hi), action_band_mm=args.band)
        result = vlr.trial.run_trial(settings)
        if result.get("status", "ok") != "ok" or "errors" not in result:
            print(f"{seed:4d}  {result.get('status')}: {result.get('message', '')}")
            continue
        e = result["errors"]
        links = e["link_length_mm_by_joint"]
        print(f"{seed:4d}  {e['proximal_deg_mean']:14.2f}  {e['distal_deg_mean']:12.2f}  "
              f"{links['left.proximal']:23.2f}  {links['left.distal']:15.2f}  "
              f"{result['coverage']:8.2f}")


if __name__ == "__main__":
    main()
