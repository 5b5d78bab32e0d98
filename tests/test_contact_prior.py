"""The "surface" contact prior: each particle's pads where they would touch an object of the
local surface's shape (`vlr.surface.surface_contact_normals`, `FilterConfig.contact_prior`)."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from vlr.filter import FilterConfig, ParticleFilter
from vlr.kinematics import HandModel, angles_from_normals, contact_points
from vlr.motion import MotionConfig, ObjectParams
from vlr.spec import load_hand
from vlr.surface import LocalSurface, _distal_rotations, surface_contact_normals

MODEL = HandModel.from_spec(load_hand("modelo"))
THETA = np.radians([[-12.0, 20.0], [-8.0, 12.0], [-10.0, 18.0]])[None]   # (1, 3, 2)
SEGMENTS = MODEL.segments[None]
ROT = Rotation.from_euler("xyz", [0.1, -0.05, 0.3]).as_matrix()


def _palm(normals_d: np.ndarray) -> np.ndarray:
    return np.einsum("pnab,pnb->pna", _distal_rotations(MODEL, THETA), normals_d)


def test_a_sphere_s_centre_is_rho_plus_the_pad_radius_from_every_pad_centre():
    rho = 0.04
    n_d = surface_contact_normals(MODEL, LocalSurface("sphere", rho), THETA, SEGMENTS, ROT)
    centres = contact_points(MODEL, THETA, np.zeros((1, 3, 3)), SEGMENTS)[0]
    # Each pad's contact lies on the line to the sphere's centre, rho + r away.
    o = centres + (rho + MODEL.pad_radius)[:, None] * _palm(n_d)[0]
    assert np.ptp(o, axis=0).max() < 1e-9
    # ... on the side the pads' inner faces look to.
    inner = _distal_rotations(MODEL, THETA)[0, :, :, 1]
    assert np.all(np.einsum("na,na->n", inner, o - centres) > 0)


def test_a_cylinder_s_normals_cross_its_axis_and_meet_on_it():
    axis_o = np.array([1.0, 0.0, 0.0])
    n_d = surface_contact_normals(MODEL, LocalSurface("cylinder", 0.016, tuple(axis_o)),
                                  THETA, SEGMENTS, ROT)
    n_p = _palm(n_d)[0]
    axis = ROT @ axis_o
    np.testing.assert_allclose(n_p @ axis, 0.0, atol=1e-9)
    # Across the axis, the lines from the pad centres along their normals meet at one point.
    c = contact_points(MODEL, THETA, np.zeros((1, 3, 3)), SEGMENTS)[0]
    c = c - np.outer(c @ axis, axis)
    dist = [np.linalg.norm(np.cross(n_p[i], (c[(i + 1) % 3] - c[i]))) for i in range(3)]
    assert min(dist) > 0                                   # not a degenerate layout
    a = np.stack([np.eye(3) - np.outer(n, n) for n in n_p])
    meet = np.linalg.lstsq(a.reshape(9, 3), np.concatenate([m @ p for m, p in zip(a, c,
                                                                               strict=True)]),
                           rcond=None)[0]
    for i in range(3):
        along = meet - c[i]
        assert np.linalg.norm(along - (along @ n_p[i]) * n_p[i]) < 1e-9


def test_each_particles_own_curvature_places_its_contacts():
    """With a curvature unknown (`ParticleState.surface_curvature`) each particle's contacts
    follow its own radius: a believed plane's particle with a curvature touches a ball of
    that radius, one as flat as a plane the faces; a cylinder keeps its axis."""
    theta = np.repeat(THETA, 2, axis=0)
    seg = np.repeat(SEGMENTS, 2, axis=0)
    rho = np.array([[0.04] * 3, [10.0] * 3])
    mixed = surface_contact_normals(MODEL, LocalSurface("plane"), theta, seg, ROT, rho)
    ball = surface_contact_normals(MODEL, LocalSurface("sphere", 0.04), THETA, SEGMENTS, ROT)
    box = surface_contact_normals(MODEL, LocalSurface("plane"), THETA, SEGMENTS, ROT)
    np.testing.assert_allclose(mixed[0], ball[0], atol=1e-12)
    np.testing.assert_array_equal(mixed[1], box[0])
    cyl = LocalSurface("cylinder", 0.016, (1.0, 0.0, 0.0))
    own = surface_contact_normals(MODEL, cyl, THETA, SEGMENTS, ROT, np.full((1, 3), 0.016))
    np.testing.assert_allclose(own, surface_contact_normals(MODEL, cyl, THETA, SEGMENTS, ROT),
                               atol=1e-12)


def test_a_box_s_pads_lie_on_the_faces_they_look_at():
    n_d = surface_contact_normals(MODEL, LocalSurface("plane"), THETA, SEGMENTS, ROT)
    n_p = _palm(n_d)[0]
    faces = np.concatenate([ROT, -ROT], axis=1).T            # the six outward face normals
    inner = _distal_rotations(MODEL, THETA)[0, :, :, 1]
    for i in range(3):
        looked_at = faces[np.argmin(faces @ inner[i])]
        np.testing.assert_allclose(n_p[i], -looked_at, atol=1e-12)


def test_the_surface_prior_centres_the_contacts_and_a_bad_prior_is_named():
    with pytest.raises(ValueError, match="contact_prior 'face'"):
        FilterConfig(contact_prior="face")
    obj = ObjectParams(mass=0.07, com=(0.0, 0.0, 0.04), surface=LocalSurface("sphere", 0.0375))
    nominal_theta = np.radians([[-10.0, 15.0]] * 3)
    obs = type("Obs", (), {"position": np.array([0.0, 0.0, 0.06]), "rotation": np.eye(3)})()
    spread = {}
    for prior in ("pad", "surface"):
        # Pinned contacts: the prior's settle leaves each drawn contact where it was drawn.
        cfg = FilterConfig(particles=400, contact_prior=prior,
                           motion=MotionConfig(rolling=False))
        pf = ParticleFilter(MODEL, obj, cfg, seed=3)
        pf._sample_prior(obs, np.zeros(3), nominal_theta, np.zeros((3, 2)))
        spread[prior] = np.degrees(np.stack(angles_from_normals(pf.state.normals), -1))
    # The pad prior sits about the inner face; the sphere's puts the side fingers' contacts
    # off their planes, opposite each other (beta), as a ball between them does.
    assert abs(np.median(spread["pad"][:, 1:, 1])) < 2.0
    betas = np.median(spread["surface"][:, 1:, 1], axis=0)
    assert betas[0] * betas[1] < 0 and min(abs(betas)) > 10.0


@pytest.mark.parametrize("obj", ["apple", "wine_glass", "gelatin_box", "flat_screwdriver"])
def test_from_the_sim_s_true_joint_angles_the_surface_gives_its_true_contacts(obj):
    """Scoring only: the sim's true joint angles in, its true pad contacts out. The pad prior's
    centre, the inner face, is 33 degrees off on the apple and the wine glass (beta) and 89 on
    the screwdriver's wrapped thumb (alpha)."""
    from vlr.sim.backend import SimHand

    from vlr.spec import load_object

    with SimHand(obj, seed=0) as hand:
        hand.grasp()
        t = hand.scoring_truth()
    surface = LocalSurface.from_spec(load_object(obj))
    n_d = surface_contact_normals(MODEL, surface, t.theta[None], t.segments[None], t.rotation)
    got = np.degrees(np.stack(angles_from_normals(n_d[0]), -1))
    true = np.degrees(np.stack(angles_from_normals(t.normals), -1))
    np.testing.assert_allclose(got, true, atol=2.0)
