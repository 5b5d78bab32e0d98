"""Identification accuracy as a regression test (issue #4): reduced versions of the sweeps in
docs/RESULTS.md. Thresholds sit between the measured figure and the paper's criterion, so a
regression in accuracy or coverage fails them; never loosen one to pass (docs/RESULTS.md has
the full-size figures)."""

import numpy as np
import pytest

from vlr.trial import TrialSettings, run_trial

pytestmark = pytest.mark.slow


def _run(**kw) -> dict:
    return run_trial(TrialSettings(**kw))


def test_synthetic_known_hand_converges_to_the_truth():
    # Measured (6k particles, seed 0, commit 4a721b1): criterion met at iteration 13,
    # proximal 0.08 deg, coverage 1.0.
    r = _run(backend="synthetic", particles=6000, seed=0)
    assert r["converged"] and r["converged_at"] <= 20
    assert r["errors"]["proximal_deg_mean"] < 1.0
    assert r["coverage"] >= 5 / 6 and r["coverage_tolerant"] == 1.0


def test_synthetic_unknown_thumb_distal_stiffness():
    # Measured (6k, seed 0, true 0.045 N m/rad; the world redraws this seed's truth twice, a
    # grasp at a fold): criterion met at iteration 52, proximal 0.55 deg, stiffness error
    # 0.0026 N m/rad (the 60k sweep: 0.0013 +- 0.0011); the prior spans 0.0075-0.12.
    r = _run(backend="synthetic", particles=6000, seed=0, unknowns=("stiffness:thumb.distal",),
             true_stiffness={"thumb.distal": 0.045}, max_iterations=60)
    assert r["converged"]
    assert r["errors"]["proximal_deg_mean"] < 1.0
    assert r["errors"]["stiffness"]["thumb.distal"] < 0.03


def test_synthetic_nh1_unknown_link_lengths():
    # Measured (6k, seed 0, commit 4a721b1): criterion met at iteration 39, proximal 0.71 deg,
    # length error 0.53 mm (mean of proximal and pad offset); the prior spans 31-81 mm for
    # the 40 mm NF1 proximal link.
    r = _run(backend="synthetic", particles=6000, seed=0, true_hand="nh1",
             unknowns=("length:left.proximal", "length:left.distal"))
    assert r["converged"]
    assert r["errors"]["proximal_deg_mean"] < 2.0
    assert r["errors"]["link_length_mm"]["left"] < 2.0


# Measured (3k particles, seed 0, 12 actions; rolling contacts at the sim's default likelihood since
# session 17, 0.2 mm / 0.4 deg + a 1.0-deg turn, the surface contact prior since session 20, the
# model's joint stops at 17 N m/rad since session 28 and the sim's commands ramped over 0.1 s since
# session 30): apple proximal 0.19 deg, gelatin box 0.26, coverage 0.83 each (1.0 within 0.1 deg:
# the thumb's proximal joint sits on its stop), contacts 0.75 and 1.0 mm; seed 1 0.60 and 0.24,
# coverage 1.0. With the 50 ms ramp (sessions 28-29): 0.50 and 0.32 deg, contacts 1.7 and 1.0 mm;
# seed 1 0.38 and 0.32. With the stops at 100 (sessions 20-27): 0.60 and 0.80 deg, contacts 1.4 and
# 1.2 mm; seed 1 0.33 and 0.16. With the pad prior (sessions 17-19): 0.64 and 0.55 deg, seed 1 0.51
# and 0.34. At 0.35 mm / 0.7 deg without the turn (sessions 8-16): 0.70 and 0.55 deg; seed 1 0.51
# and 0.34 with the turn, 1.19 and 1.01 without. Pinned at 0.5 mm / 1 deg (commit 4a721b1) they were
# 1.83 and 0.96 deg.
@pytest.mark.parametrize("obj, max_proximal_deg", [("apple", 2.0), ("gelatin_box", 2.0)])
def test_sim_from_rendered_frames(obj, max_proximal_deg):
    """Reduced sim regression: rendered frames, 3k particles, 12 actions."""
    r = _run(backend="sim", object=obj, particles=3000, seed=0, max_iterations=12,
             nominal_theta_deg=(-10.0, 15.0), prior_spread_deg=10.0)
    err = r["errors"]
    assert np.isfinite(err["proximal_deg_mean"])
    assert err["proximal_deg_mean"] < max_proximal_deg
    assert r["coverage"] >= 5 / 6 and r["coverage_tolerant"] == 1.0
    # The pad contacts, found since the surface contact prior (the pad prior: 4-5 mm on the
    # apple, 1-2 on the gelatin box).
    assert err["contact_mm_mean"] < 3.0


def test_sim_unknown_thumb_distal_stiffness():
    # Measured (3k particles, 20 actions, rolling, the sim's default likelihood with the turn
    # term, the surface contact prior, stops at 17, the 0.1 s ramp and the Liu-West draw on
    # the spring's logarithm, the default since session 41): the replaced spring (true 0.045
    # N m/rad, the filter's nominal 0.030) found to 0.0027, interval 0.039-0.057, proximal
    # 3.1 deg (seed 1: 0.0102, interval 0.046-0.065, missing it; the paper 0.0026). The
    # threshold fails the draw on the values (jitter_kernel "gaussian", the default before):
    # 0.0067, interval 0.043-0.061, proximal 5.1 deg (seed 1: 0.0071, interval 0.045-0.061).
    # Earlier, on the values: with the 50 ms ramp 0.0029, interval 0.040-0.057, proximal
    # 3.0 deg (seed 1: 0.0086, interval 0.046-0.061, missing it). With the stops at 100:
    # 0.0024, interval 0.038-0.058, proximal 4.5 deg (seed 1: 0.0106, interval 0.048-0.064).
    # With the pad prior: 0.0011, interval 0.033-0.056 (seed 1: 0.0053, interval
    # 0.044-0.058). At 0.35 mm / 0.7 deg without the turn: 0.0040, interval 0.035-0.065
    # (seed 1 0.0031). The prior's mean (uniform, 0.0075-0.12) is 0.019 off.
    r = _run(backend="sim", object="toy_block", true_hand="modelo_thumb45", particles=3000,
             seed=0, max_iterations=20, nominal_theta_deg=(-10.0, 15.0), prior_spread_deg=10.0,
             unknowns=("stiffness:thumb.distal",))
    est = r["unknown_estimates"]["stiffness:thumb.distal"]
    assert r["errors"]["stiffness"]["thumb.distal"] < 0.005
    assert est["low"] <= 0.045 <= est["high"]


def test_sim_unknown_object_mass():
    # Measured (3k particles, seed 0, 20 actions, the sim's defaults at session 32): the apple's
    # mass (68 g) found to 6.5 g, interval 25-98 g, proximal 0.33 deg, coverage 1.0 (seed 1:
    # 2.6 g, interval 25-123 g). The prior (uniform, 17-272 g) has its mean 77 g off; its
    # 95% interval is 242 g wide. The camera weighs the object only roughly: on this seed
    # `vlr crb` bounds the mass's sd after 20 actions at 18 g, a 95% interval of about 71 g
    # (docs/RESULTS.md 5, session 32).
    r = _run(backend="sim", object="apple", particles=3000, seed=0, max_iterations=20,
             nominal_theta_deg=(-10.0, 15.0), prior_spread_deg=10.0, unknowns=("mass",))
    est = r["unknown_estimates"]["mass"]
    assert r["errors"]["object_mass_g"] < 20.0
    assert est["low"] <= 0.068 <= est["high"]
    assert est["high"] - est["low"] < 0.12       # 73 g measured, the prior's 242 g
    assert r["errors"]["proximal_deg_mean"] < 2.0


def test_sim_unknown_curvature_of_an_apple_believed_flat():
    # Measured (3k particles, seed 0, 20 actions, the sim's defaults at session 33): the
    # filter believes the apple (a 37.5 mm ball, 26.7 /m) flat; with its curvature unknown
    # (prior 0-50 /m) the contacts are found to 0.60 mm (4.75 believed flat and known),
    # proximal 0.23 deg (0.28), curvature 21.9 /m, interval 7.8-36.2 (seed 1: 1.41 mm against
    # 4.32, 0.40 deg against 1.55, interval 8.4-39.7). The camera tells the curvature only
    # roughly: `vlr crb` bounds its sd after 20 actions at 11-12 /m against the prior's 14.4
    # (docs/RESULTS.md 5, session 33); what it wins is each particle's pads on its own ball.
    r = _run(backend="sim", object="apple", particles=3000, seed=0, max_iterations=20,
             nominal_theta_deg=(-10.0, 15.0), prior_spread_deg=10.0, object_curvature=0.0,
             unknowns=("curvature",))
    est = r["unknown_estimates"]["curvature"]
    assert r["errors"]["contact_mm_mean"] < 2.0
    assert est["low"] <= 1 / 0.0375 <= est["high"]
    assert est["high"] - est["low"] < 40.0      # 28 measured, the prior's 95% 47.5
    assert r["errors"]["proximal_deg_mean"] < 1.0


def test_sim_nh1_unknown_link_lengths():
    # Measured (3k, seed 0, 12 actions, rolling, the sim's default likelihood with the turn term,
    # the surface contact prior, stops at 17 and the 0.1 s ramp): NF1's proximal link (true 40 mm,
    # the Model O's 62) 3.4 mm off, interval 31.7-41.4 mm, where the prior's mean (uniform, 31-81
    # mm) is 15.8 mm off; proximal angles 1.33 deg (seed 1: 2.1 mm, 1.04 deg). With the 50 ms ramp:
    # 4.4 mm, interval 31.5-41.2 mm, 1.40 deg (seed 1: 2.1 mm, 1.12 deg). With the stops at 100: 3.5
    # mm, interval 31.3-43.8 mm, 1.71 deg (seed 1: 2.1 mm, 0.82 deg). With the pad prior: 1.8 mm,
    # interval 33.8-42.2, 1.17 deg (seed 1: 0.6 mm, 3.13 deg). At 0.35 mm / 0.7 deg without the
    # turn: 2.5 mm, interval 31.8-43.6, 1.25 deg (seed 1: 0.5 mm, 2.76 deg). (The pad offset, true
    # 27 mm against 32, ends 7.6 mm off (seed 1: 4.6; at the 50 ms ramp 7.9 and 4.3; at stops 100
    # 7.3 and 3.0; the pad prior 10.5), worse than the prior's 1.8 on seed 0: docs/RESULTS.md 2, so
    # it is not asserted.)
    r = _run(backend="sim", object="apple", true_hand="nh1", particles=3000, seed=0,
             max_iterations=12, nominal_theta_deg=(-10.0, 15.0), prior_spread_deg=10.0,
             unknowns=("length:left.proximal", "length:left.distal"))
    est = r["unknown_estimates"]["length:left.proximal"]
    assert r["errors"]["link_length_mm_by_joint"]["left.proximal"] < 6.0
    assert est["low"] <= 0.040 <= est["high"]
    assert r["errors"]["proximal_deg_mean"] < 3.0
