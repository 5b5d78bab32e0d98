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


def test_a_cylinders_side_is_held_to_its_axis_and_an_end_face_to_a_sphere():
    anchors, m = contacts()
    centres, axes = local_centres(CYLINDER, anchors, m)
    assert centres.shape == axes.shape == anchors.shape
    np.testing.assert_allclose(centres[0, 0], [0.01, 0.0, 0.0], atol=1e-15)  # on the axis
    np.testing.assert_allclose(axes[0, 0], CYLINDER.axis)
    np.testing.assert_allclose(centres[0, 1], anchors[0, 1] - RHO * m[0, 1])  # the end face
    np.testing.assert_allclose(axes[0, 1], 0.0)
    # A contact's own radius (an unknown curvature) replaces the surface's.
    rho = np.array([[0.02, 0.05]])
    np.testing.assert_allclose(local_centres(CYLINDER, anchors, m, rho)[0],
                               anchors - rho[..., None] * m, atol=1e-15)
    # A sphere has no axes.
    assert not local_centres(LocalSurface("sphere", RHO), anchors, m)[1].any()


@pytest.mark.parametrize("along", [0.0, 1e-3, 4e-3])
def test_a_pad_moved_along_a_cylinders_axis_keeps_its_gap(along):
    """Held to the axis, a pad rolled along it keeps its gap (a sphere of the cylinder's
    radius would open sqrt(d^2 + s^2) - d, a force of k_c times that)."""
    anchors, m = contacts()
    sink = 2e-6
    pad = anchors[:, :1] + (PAD - sink) * m[:, :1] + [along, 0.0, 0.0]
    local, axes = local_centres(CYLINDER, anchors[:, :1], m[:, :1])
    assert pad_gaps(pad, local, RHO + PAD, axes)[0, 0] == pytest.approx(-sink, abs=1e-15)
    d = RHO + PAD - sink
    sphere = pad_gaps(pad, local, RHO + PAD)[0, 0] + sink
    assert sphere == pytest.approx(np.hypot(d, along) - d, rel=1e-9, abs=1e-15)


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
