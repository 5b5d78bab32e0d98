"""Identification accuracy as a regression test: reduced versions of the sweeps in
docs/RESULTS.md. Thresholds sit between the measured figure and the paper's criterion, so a
regression in accuracy or coverage fails them; never loosen one to pass (docs/RESULTS.md has
the full-size figures)."""

import numpy as np
import pytest

from vlr.run import run_identification
from vlr.settings import load_settings

pytestmark = pytest.mark.slow

# The sim's grasp guess, (-10, 15) +- 10 degrees (its backend's default), given explicitly.
SIM_GUESS = {"filter.guess_theta_deg": [-10.0, 15.0], "filter.theta_spread_deg": 10.0}


def _run(*layers: dict) -> dict:
    """The result.json of one identification (`vlr.run.run_identification`)."""
    return run_identification(load_settings(*layers)).summary


def test_synthetic_known_hand_converges_to_the_truth():
    # Measured (6k particles, seed 0): criterion met at iteration 13, proximal 0.20 deg,
    # coverage 1.0.
    r = _run({"world.backend": "synthetic", "filter.particles": 6000, "seed": 0})
    assert r["converged"] and r["converged_at"] <= 20
    assert r["errors"]["proximal_deg_mean"] < 1.0
    assert r["coverage"] >= 5 / 6 and r["coverage_tolerant"] == 1.0


def test_synthetic_unknown_thumb_distal_stiffness():
    # Measured (6k, seed 0, true 0.045 N m/rad): criterion met at iteration 27, proximal
    # 0.99 deg, stiffness error 0.0033 N m/rad (the 60k sweep: 0.0013 +- 0.0011); the prior
    # spans 0.0075-0.12.
    r = _run({"world.backend": "synthetic", "filter.particles": 6000, "seed": 0,
              "filter.unknowns": ["stiffness:thumb.distal"],
              "world.options.true_stiffness": {"thumb.distal": 0.045},
              "loop.max_iterations": 60})
    assert r["converged"]
    assert r["errors"]["proximal_deg_mean"] < 1.0
    assert r["errors"]["stiffness"]["thumb.distal"] < 0.03


def test_synthetic_nh1_unknown_link_lengths():
    # Measured (6k, seed 0): proximal 0.40 deg, length error 0.82 mm (mean of proximal and
    # pad offset); the prior spans 31-81 mm for the 40 mm NF1 proximal link. At 6k the
    # joint intervals reach the criterion's 2 degrees near the 40-action budget (seed 0:
    # 1.99 at best over the last ten, converged at 37).
    r = _run({"world.backend": "synthetic", "filter.particles": 6000, "seed": 0,
              "world.true_hand": "nh1",
              "filter.unknowns": ["length:left.proximal", "length:left.distal"]})
    assert min(r["ci_deg_by_iteration"][-10:]) < 1.25 * 2.0
    assert r["errors"]["proximal_deg_mean"] < 2.0
    assert r["errors"]["link_length_mm"]["left"] < 2.0


# Measured (3k particles, seed 0, 12 actions, at the sim's defaults: rolling contacts with the
# pads' spin friction and sliding at mu 2, the likelihood 0.2 mm / 0.4 deg + a 1.0-deg turn,
# the surface contact prior, the model's joint stops at 17 N m/rad and the sim's commands
# ramped over 0.1 s): apple proximal 0.46 deg, gelatin box 0.13, coverage 0.83 both (1.0
# within 0.1 deg: the thumb's proximal joint sits on its stop), contacts 0.86 and 0.64 mm;
# seed 1 1.27 and 0.06 deg, coverage 1.0, contacts 1.38 and 0.72 mm. The defaults'
# alternatives measured: docs/DECISIONS.md.
@pytest.mark.parametrize("obj, max_proximal_deg", [("apple", 2.0), ("gelatin_box", 2.0)])
def test_sim_from_rendered_frames(obj, max_proximal_deg):
    """Reduced sim regression: rendered frames, 3k particles, 12 actions."""
    r = _run({"world.backend": "sim", "world.object": obj, "filter.particles": 3000, "seed": 0,
              "loop.max_iterations": 12}, SIM_GUESS)
    err = r["errors"]
    assert np.isfinite(err["proximal_deg_mean"])
    assert err["proximal_deg_mean"] < max_proximal_deg
    assert r["coverage"] >= 5 / 6 and r["coverage_tolerant"] == 1.0
    # The pad contacts, found since the surface contact prior (the pad prior: 4-5 mm on the
    # apple, 1-2 on the gelatin box).
    assert err["contact_mm_mean"] < 3.0


def test_sim_unknown_thumb_distal_stiffness():
    # Measured (3k particles, 20 actions, the sim's defaults, seeds 0-4): the replaced
    # spring (true 0.045 N m/rad, the filter's nominal 0.030) found to 0.0028, 0.0070,
    # 0.0010, 0.0024 and 0.0044 (median 0.0028; the paper 0.0026), every 95% interval holding
    # it. The figures move by up to 0.0015 between CPUs, and one seed at 3k particles
    # scatters by a factor 2: hence the median of five. The prior's mean (uniform,
    # 0.0075-0.12) is 0.019 off.
    errors, covered = [], 0
    for seed in range(5):
        r = _run({"world.backend": "sim", "world.object": "toy_block",
                  "world.true_hand": "modelo_thumb45", "filter.particles": 3000, "seed": seed,
                  "loop.max_iterations": 20, "filter.unknowns": ["stiffness:thumb.distal"]},
                 SIM_GUESS)
        est = r["unknown_estimates"]["stiffness:thumb.distal"]
        covered += est["low"] <= 0.045 <= est["high"]
        errors.append(r["errors"]["stiffness"]["thumb.distal"])
    assert covered >= 4
    assert np.median(errors) < 0.005


def test_sim_unknown_object_mass():
    # Measured (3k particles, 20 actions, the sim's defaults, seeds 0 and 1): the apple's
    # mass (68 g) found to 6.1 and 0.4 g off, intervals 24-97 and 26-121 g, proximal 0.22 and
    # 0.52 deg. The prior (uniform, 17-272 g) has its mean 77 g off; its 95%
    # interval is 242 g wide. The camera weighs the object only roughly: `vlr crb` bounds the
    # mass's sd after 20 actions at about 18 g, so one seed scatters by that; hence two.
    errors = []
    for seed in (0, 1):
        r = _run({"world.backend": "sim", "world.object": "apple", "filter.particles": 3000,
                  "seed": seed, "loop.max_iterations": 20, "filter.unknowns": ["mass"]},
                 SIM_GUESS)
        est = r["unknown_estimates"]["mass"]
        assert est["low"] <= 0.068 <= est["high"]
        assert est["high"] - est["low"] < 0.12       # 73-95 g measured, the prior's 242 g
        assert r["errors"]["proximal_deg_mean"] < 2.0
        errors.append(r["errors"]["object_mass_g"])
    assert np.mean(errors) < 25.0


def test_sim_unknown_curvature_of_an_apple_believed_flat():
    # Measured (3k particles, seed 0, 20 actions, the sim's defaults): the filter believes the
    # apple (a 37.5 mm ball, 26.7 /m) flat; with its curvature unknown (prior 0-50 /m) the
    # contacts are found to 1.62 mm, proximal 0.50 deg, curvature interval 7.6-31.3 /m. The
    # camera tells the curvature only roughly: `vlr crb` bounds its sd after 20 actions at
    # 11-12 /m against the prior's 14.4 (docs/RESULTS.md); what it wins is each particle's
    # pads on its own ball.
    r = _run({"world.backend": "sim", "world.object": "apple", "filter.particles": 3000,
              "seed": 0, "loop.max_iterations": 20, "filter.object.curvature": 0.0,
              "filter.unknowns": ["curvature"]}, SIM_GUESS)
    est = r["unknown_estimates"]["curvature"]
    assert r["errors"]["contact_mm_mean"] < 2.0
    assert est["low"] <= 1 / 0.0375 <= est["high"]
    assert est["high"] - est["low"] < 40.0      # 24 measured, the prior's 95% 47.5
    assert r["errors"]["proximal_deg_mean"] < 1.0


def test_sim_nh1_unknown_link_lengths():
    # Measured (3k, seed 0, 12 actions, the sim's defaults): NF1's proximal link (true 40 mm,
    # the Model O's 62) 2.7 mm off, interval 32.1-42.2 mm, where the prior's mean (uniform,
    # 31-81 mm) is 15.8 mm off; proximal angles 0.88 deg. (The pad offset, true 27 mm against
    # 32, ends 7.1 mm off, its interval 24.5-40.9 mm holding it: 12 actions tell it little,
    # so it is not asserted.)
    r = _run({"world.backend": "sim", "world.object": "apple", "world.true_hand": "nh1",
              "filter.particles": 3000, "seed": 0, "loop.max_iterations": 12,
              "filter.unknowns": ["length:left.proximal", "length:left.distal"]}, SIM_GUESS)
    est = r["unknown_estimates"]["length:left.proximal"]
    assert r["errors"]["link_length_mm_by_joint"]["left.proximal"] < 6.0
    assert est["low"] <= 0.040 <= est["high"]
    assert r["errors"]["proximal_deg_mean"] < 3.0


def test_sim_ukf_thumb_distal_stiffness():
    # The unscented Kalman filter's row of docs/RESULTS.md (section 2; docs/sweeps/
    # estimators.yaml): the thumb's replaced distal spring on the toy block after 35 actions,
    # the sim's defaults, seed 0. Measured: the spring (true 0.045 N m/rad) found to 0.0015,
    # interval 0.038-0.049, proximal 0.48 deg, contacts 1.05 mm, coverage 1.0, 0.3 s of
    # filter for the trial (the particle filter at 60,000: 0.0011 +- 0.0007 over seeds 0-4,
    # some 34 s, docs/RESULTS.md).
    r = _run({"world.backend": "sim", "world.object": "toy_block",
              "world.true_hand": "modelo_thumb45", "filter.estimator": "ukf", "seed": 0,
              "loop.max_iterations": 35, "loop.min_iterations": 35,
              "filter.unknowns": ["stiffness:thumb.distal"]}, SIM_GUESS)
    est = r["unknown_estimates"]["stiffness:thumb.distal"]
    assert est["low"] <= 0.045 <= est["high"]
    assert r["errors"]["stiffness"]["thumb.distal"] < 0.004
    assert r["errors"]["proximal_deg_mean"] < 2.0
    assert r["errors"]["contact_mm_mean"] < 2.0
    assert r["coverage"] >= 6 / 7
    assert r["timing"]["filter_s"] < 10.0     # the UKF's point: its whole trial in seconds
