"""The Jacobian controller (Eq. 10-12): pose errors, the two step rules, the numerical
Jacobian of the motion model, the camera-fitted correction, and the closed loop on the
synthetic world (where the model is the world, so the VLR's Jacobian is right)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from vlr.controller import (
    ControllerConfig,
    JacobianController,
    dls_step,
    numerical_jacobian,
    observed_motion,
    pose_error,
    reach,
    reachable_motion,
    rotation_log,
    row_weights,
    transpose_step,
)
from vlr.observation import PomObservation


def test_rotation_log_matches_scipy_including_small_and_near_pi_angles():
    rng = np.random.default_rng(0)
    vecs = [rng.normal(size=3) for _ in range(20)]
    vecs += [np.array([1e-9, -2e-9, 3e-9]), np.array([0.0, 0.0, np.pi - 1e-9]),
             np.array([np.pi, 0.0, 0.0]) * (1 - 1e-12)]
    for v in vecs:
        v = v if np.linalg.norm(v) <= np.pi else v / np.linalg.norm(v) * 3.0
        r = Rotation.from_rotvec(v).as_matrix()
        got = rotation_log(r)
        # near pi the axis sign is ambiguous: compare the rotations, not the vectors
        np.testing.assert_allclose(Rotation.from_rotvec(got).as_matrix(), r, atol=1e-7)
        if np.linalg.norm(v) < 3.0:
            np.testing.assert_allclose(got, v, atol=1e-9)


def test_pose_error_is_target_minus_current_in_the_palm_frame():
    r0 = Rotation.from_rotvec([0.1, -0.2, 0.3]).as_matrix()
    w = np.array([0.01, 0.02, -0.03])
    r1 = Rotation.from_rotvec(w).as_matrix() @ r0    # a spatial rotation of r0
    e = pose_error([0.0, 0.0, 0.06], r0, [0.001, -0.002, 0.06], r1)
    np.testing.assert_allclose(e[:3], [0.001, -0.002, 0.0], atol=1e-15)
    np.testing.assert_allclose(e[3:], w, atol=1e-12)
    np.testing.assert_allclose(pose_error(np.zeros(3), r0, np.ones(3), None)[3:], 0.0)
    a = PomObservation(np.zeros(3), r0)
    b = PomObservation(np.array([0.0, 0.001, 0.0]), r1)
    np.testing.assert_allclose(observed_motion(a, b), [0, 0.001, 0, *w], atol=1e-12)


def test_weights_of_eq12_are_per_mm_and_alpha_per_degree():
    w = row_weights("full", alpha=9.5)
    np.testing.assert_allclose(w[:3], 1e3)
    np.testing.assert_allclose(w[3:], 9.5 / np.radians(1.0))
    assert row_weights("position").shape == (3,) and row_weights("orientation").shape == (3,)


def test_step_rules_reduce_the_error_of_a_linear_plant():
    rng = np.random.default_rng(1)
    jac = rng.normal(size=(3, 3)) * 5.0 + np.eye(3) * 8.0
    target = np.array([0.3, -0.2, 0.1])
    for rule in ("transpose", "dls"):
        x = np.zeros(3)
        norms = []
        for _ in range(60):
            e = target - jac @ x
            norms.append(np.linalg.norm(e))
            x = x + (transpose_step(jac, e) if rule == "transpose"
                     else dls_step(jac, e, damping=1e-3))
        assert norms[-1] < 1e-3 * norms[0], rule
    # DLS with vanishing damping is the exact solve on a square, well-conditioned J
    e = rng.normal(size=3)
    np.testing.assert_allclose(dls_step(jac, e, 1e-9), np.linalg.solve(jac, e), rtol=1e-6)


def test_step_scales_the_whole_change_to_the_step_limit_and_keeps_its_direction():
    ctl = JacobianController(ControllerConfig(rows="position", method="dls", damping=1e-6,
                                              gain=1.0, max_step=0.2e-3))
    jac = np.zeros((6, 3))
    jac[:3] = np.eye(3) * 2.0                    # 2 mm of POM per mm of tendon
    du = ctl.step(jac, np.array([0.004, -0.002, 0.0, 0, 0, 0]))   # wants (2, -1, 0) mm
    np.testing.assert_allclose(du, [0.2e-3, -0.1e-3, 0.0], atol=1e-12)


def test_step_holds_a_tendon_at_its_bound_and_solves_for_the_others():
    """An active set: tendon 0 may not pull more than 0.05 mm; the other tendons make up
    what they can, which beats clipping the unconstrained step."""
    ctl = JacobianController(ControllerConfig(rows="position", method="dls", damping=1e-6,
                                              gain=1.0, max_step=1e-3,
                                              max_motion_pos=1.0))
    jac = np.zeros((6, 3))
    jac[:3] = [[2.0, 1.0, 0.0], [0.0, 2.0, 0.0], [0.0, 0.0, 2.0]]
    err = np.array([0.6e-3, 0.0, 0.2e-3, 0, 0, 0])
    lo, hi = np.full(3, -1e-3), np.array([0.05e-3, 1e-3, 1e-3])
    du = ctl.step(jac, err, bounds=(lo, hi))
    assert du[0] == pytest.approx(0.05e-3)
    clipped = np.clip(ctl.step(jac, err), lo, hi)
    left = np.linalg.norm(err[:3] - jac[:3] @ du)
    assert left < np.linalg.norm(err[:3] - jac[:3] @ clipped) - 1e-6
    np.testing.assert_allclose(du[2], 0.1e-3, rtol=1e-6)


def test_reachable_motion_levels_by_rotation_rows_and_predicts_the_position_it_costs():
    """The orientation rows fix the tendon change; the position it brings along is read off
    the same Jacobian. A band that binds holds its tendon at the limit."""
    rng = np.random.default_rng(3)
    jac = rng.normal(size=(6, 3)) * np.array([5.0] * 3 + [80.0] * 3)[:, None]  # m/m, rad/m
    du_true = np.array([0.3e-3, -0.1e-3, 0.2e-3])
    err = jac @ du_true
    wide = (np.full(3, -1e-3), np.full(3, 1e-3))
    du, motion = reachable_motion(jac, err, "orientation", wide)
    np.testing.assert_allclose(du, du_true, atol=1e-9)
    np.testing.assert_allclose(motion[:3], err[:3], atol=1e-9)
    tight = (np.full(3, -1e-3), np.array([0.1e-3, 1e-3, 1e-3]))
    du, motion = reachable_motion(jac, err, "orientation", tight)
    assert du[0] == pytest.approx(0.1e-3)
    np.testing.assert_allclose(motion, jac @ du)
    with pytest.raises(ValueError, match="must hold zero"):
        reachable_motion(jac, err, "orientation", (np.full(3, 1e-4), np.full(3, 1e-3)))


def test_rows_without_yaw_ignore_a_yaw_error_that_full_rows_chase():
    """A cup is symmetric about the palm normal: with "full_no_yaw" a yaw error alone asks
    for no tendon change and does not keep `done` from holding, where "full" moves the
    tendons for it (0.05 mm for half a degree here, a step that turns the cup's tilt too)."""
    jac = np.array([[2.0, -1.0, 1.0], [1.0, -3.0, -3.0], [-1.5, -1.0, -0.6],
                    [45.0, 12.0, 3.0], [6.0, -41.0, 54.0], [-0.3, 1.7, -1.2]])  # m/m, rad/m
    yaw = np.array([0.0, 0.0, 0.0, 0.0, 0.0, np.radians(0.5)])
    full = JacobianController(ControllerConfig(rows="full", alpha=9.5))
    no_yaw = JacobianController(ControllerConfig(rows="full_no_yaw", alpha=9.5))
    assert np.max(np.abs(full.step(jac, yaw))) > 0.04e-3
    np.testing.assert_allclose(no_yaw.step(jac, yaw), 0.0, atol=1e-15)
    assert no_yaw.done(yaw) and not full.done(yaw)
    assert row_weights("full_no_yaw", 9.5).shape == (5,) and row_weights("tilt").shape == (2,)


def test_a_tendon_that_reverses_takes_smaller_steps_until_it_keeps_its_sign():
    """A step that overshoots chatters: a 1-D plant that moves twice what the Jacobian says
    (a slip the VLR underestimates) flips the error's sign every step at gain 1, for ever.
    With `reversal_shrink` the chatter's steps shrink and the error ends small; a tendon
    that then keeps its sign grows its steps back."""
    jac = np.zeros((6, 1))
    jac[0, 0] = 2.0                               # the VLR: 2 mm of POM per mm of tendon

    def run(shrink: float) -> tuple[float, JacobianController]:
        ctl = JacobianController(ControllerConfig(rows="position", method="dls",
                                                  damping=1e-6, gain=1.0, max_step=1e-3,
                                                  max_motion_pos=1.0,
                                                  reversal_shrink=shrink))
        x, target = 0.0, 0.3e-3
        ctl.smallest = 1.0
        for _ in range(20):
            du = float(ctl.step(jac, np.array([target - x, 0, 0, 0, 0, 0]))[0])
            x += 4.0 * du                         # the plant: 4 mm per mm
            if ctl.step_scale is not None:
                ctl.smallest = min(ctl.smallest, float(ctl.step_scale[0]))
        return abs(target - x), ctl

    plain, _ = run(1.0)
    damped, ctl = run(0.5)
    assert plain == pytest.approx(0.3e-3)         # it never settles
    assert damped < 0.01 * plain
    assert ctl.smallest <= 0.5
    ctl.step(jac, np.array([-1e-3, 0, 0, 0, 0, 0]))
    ctl.step(jac, np.array([1e-3, 0, 0, 0, 0, 0]))   # a reversal shrinks the scale
    assert ctl.step_scale[0] < 1.0
    for _ in range(4):                           # a consistent sign grows the scale back
        ctl.step(jac, np.array([1e-3, 0, 0, 0, 0, 0]))
    assert ctl.step_scale[0] == 1.0
    with pytest.raises(ValueError, match="reversal_shrink 0"):
        ControllerConfig(reversal_shrink=0.0)


def test_config_rejects_unknown_rows_and_methods():
    with pytest.raises(ValueError, match="rows"):
        ControllerConfig(rows="yaw")
    with pytest.raises(ValueError, match="method"):
        ControllerConfig(method="newton")


def test_secant_fit_and_update_recover_a_linear_map_the_vlr_misses():
    rng = np.random.default_rng(2)
    true = rng.normal(size=(6, 3)) * 4.0
    d = rng.uniform(-0.4e-3, 0.4e-3, (15, 3))
    ctl = JacobianController(ControllerConfig(secant=True))
    ctl.fit(d, d @ true.T, jacobian=np.zeros((6, 3)))   # a VLR that sees no motion at all
    np.testing.assert_allclose(ctl.jacobian, true, rtol=1e-4, atol=1e-4)
    # Broyden updates learn the map along the moves made
    ctl = JacobianController(ControllerConfig(secant=True, secant_updates=True))
    ctl.fit(np.zeros((0, 3)), np.zeros((0, 6)), jacobian=np.zeros((6, 3)))
    for _ in range(60):
        du = rng.uniform(-0.3e-3, 0.3e-3, 3)
        ctl.learn(du, true @ du)
    np.testing.assert_allclose(ctl.jacobian, true, atol=1e-3 * np.abs(true).max())
    fixed = JacobianController(ControllerConfig(secant=True))   # fit only: learn is a no-op
    fixed.fit(d, d @ true.T, jacobian=np.zeros((6, 3)))
    before = fixed.jacobian.copy()
    fixed.learn(d[0], np.ones(6))
    np.testing.assert_array_equal(fixed.jacobian, before)
    off = JacobianController(ControllerConfig(secant=False))
    off.fit(d, d @ true.T, jacobian=np.zeros((6, 3)))
    assert off.correction is None and np.all(off.jacobian == 0)


@pytest.fixture(scope="module")
def identified_synthetic():
    """A synthetic world and a filter identified on it (small, quick)."""
    from vlr.filter import FilterConfig
    from vlr.identify import LoopConfig, identify
    from vlr.kinematics import HandModel
    from vlr.motion import MotionConfig, ObjectParams
    from vlr.spec import load_hand, load_object
    from vlr.synthetic import SyntheticConfig, SyntheticWorld

    model = HandModel.from_spec(load_hand("modelo"))
    obj = ObjectParams.from_spec(load_object("apple"))
    world = SyntheticWorld(model, obj, SyntheticConfig(seed=0))
    box = {}
    # The synthetic world's own model (pinned contacts), its prior about the pads' contacts.
    cfg = FilterConfig(particles=1500, motion=MotionConfig(rolling=False), contact_prior="pad")
    identify(world, world.observe, model, obj, world.nominal, cfg,
             LoopConfig(max_iterations=12), seed=0, watch=lambda pf, rec: box.update(pf=pf))
    return world, box["pf"]


def test_numerical_jacobian_predicts_the_worlds_motion(identified_synthetic):
    world, _ = identified_synthetic
    state = world.state.copy()
    jac = numerical_jacobian(world.motion, state, world.commands, n_particles=1)
    assert jac.shape == (6, 3)
    np.testing.assert_array_equal(state.pos, world.state.pos)   # the state is not changed
    du = np.array([0.05e-3, -0.03e-3, 0.04e-3])
    p0, r0 = world.state.pos[0].copy(), world.state.rot[0].copy()
    world.apply(du)
    moved = pose_error(p0, r0, world.state.pos[0], world.state.rot[0])
    world.apply(-du)
    np.testing.assert_allclose(jac @ du, moved, atol=0.1 * np.abs(moved).max())


@pytest.mark.parametrize("method", ["dls", "transpose"])
def test_reach_brings_the_pom_to_a_target_on_the_synthetic_world(identified_synthetic, method):
    world, pf = identified_synthetic
    start = world.observe()
    target = start.position + np.array([0.3e-3, -0.2e-3, 0.0])
    ctl = JacobianController(ControllerConfig(rows="position", method=method,
                                              tolerance_pos=0.12e-3, max_steps=25))
    result = reach(world, world.observe, pf, target, None, ctl)
    assert result.reached, (method, result.error)
    true_error = np.linalg.norm(world.truth().position - target)
    assert true_error < 0.25e-3
    # back to the start, so the second method starts from the same place
    reach(world, world.observe, pf, start.position, None, ctl)
