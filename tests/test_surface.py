"""The rolling term's local surfaces (`vlr.surface.local_centres`, `pad_gaps`)."""

import numpy as np
import pytest

from vlr.surface import LocalSurface, local_centres, pad_gaps

RHO, PAD = 0.016, 0.012
CYLINDER = LocalSurface("cylinder", RHO, (1.0, 0.0, 0.0))


def contacts() -> tuple[np.ndarray, np.ndarray]:
    """(1, 2, 3) anchors and outward normals in O: one on the side, one on an end face."""
    anchors = np.array([[[0.01, 0.0, RHO], [0.05, 0.0, 0.0]]])
    normals = np.array([[[0.0, 0.0, 1.0], [1.0, 0.0, 0.0]]])
    return anchors, normals


def test_every_contact_is_held_to_a_sphere_of_the_local_radius():
    """A cylinder's side contact and its end face's alike: the local centre a - rho m."""
    anchors, m = contacts()
    centres = local_centres(CYLINDER, anchors, m)
    assert centres.shape == anchors.shape
    np.testing.assert_allclose(centres[0, 0], [0.01, 0.0, 0.0], atol=1e-15)  # on the axis
    np.testing.assert_allclose(centres, anchors - RHO * m)
    # A contact's own radius (an unknown curvature) replaces the surface's.
    rho = np.array([[0.02, 0.05]])
    np.testing.assert_allclose(local_centres(CYLINDER, anchors, m, rho),
                               anchors - rho[..., None] * m)


@pytest.mark.parametrize("along", [0.0, 1e-3, 4e-3])
def test_a_pad_moved_along_a_cylinders_axis_opens_the_spheres_gap(along):
    """Held to a sphere of the cylinder's radius, a pad rolled along the axis opens a gap of
    sqrt(d^2 + s^2) - d (about s^2 / (2 (rho + r))), which the penalty turns into a force:
    a micrometre, 1 N at k_c 1e6, for s = 0.24 mm."""
    anchors, m = contacts()
    sink = 2e-6
    pad = anchors[:, :1] + (PAD - sink) * m[:, :1] + [along, 0.0, 0.0]
    sphere = local_centres(CYLINDER, anchors[:, :1], m[:, :1])
    opened = pad_gaps(pad, sphere, RHO + PAD)[0, 0] + sink
    d = RHO + PAD - sink
    assert opened == pytest.approx(np.hypot(d, along) - d, rel=1e-9, abs=1e-15)


def test_a_surface_with_another_curvature():
    from vlr.surface import FLAT_CURVATURE, contact_radii

    assert LocalSurface("sphere", 0.04).curvature == pytest.approx(25.0)
    assert LocalSurface("plane").curvature == 0.0
    assert LocalSurface("plane").with_curvature(25.0) == LocalSurface("sphere", 0.04)
    assert CYLINDER.with_curvature(50.0) == LocalSurface("cylinder", 0.02, CYLINDER.axis)
    assert LocalSurface("sphere", 0.04).with_curvature(0.0).kind == "plane"
    with pytest.raises(ValueError, match="-1"):
        CYLINDER.with_curvature(-1.0)
    # at or below a plane's curvature, the plane's 10 m
    np.testing.assert_allclose(contact_radii(np.array([0.0, FLAT_CURVATURE, 20.0])),
                               [10.0, 10.0, 0.05])
