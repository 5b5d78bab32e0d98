"""The object's local surface at each contact (docs/METHOD.md 8.2, "Rolling").

A fingertip pad is a sphere of known radius. The motion model's rolling contact
(`vlr.kernels.contacts`) holds each pad on the object's LOCAL surface at its contact, a
primitive fixed in O: a plane (a box face: exact), a sphere of radius rho (the apple), or a
cylinder of radius rho about an axis fixed in O (the wine glass's bowl, the screwdriver's
handle, a cup's wall). It is described by its kind and curvature (known from the object,
`LocalSurface.from_spec`) and anchored at each particle's own contact point and normal, so
the filter needs no global object model. Treating a sphere as flat was measured to raise
the per-action gap to 0.11.

`surface_contact_normals` places the contacts where one such object would touch every pad:
the filter's contact prior.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from vlr.kinematics import HandModel, contact_points, plane_rotation
from vlr.spec import ObjectSpec

__all__ = ["LocalSurface", "contact_radii", "surface_contact_normals", "FLAT_CURVATURE"]

KINDS = ("plane", "sphere", "cylinder")

# The curvature the rolling term gives a plane [1/m]: a sphere of 10 m is flat within 0.1% of
# a pad's travel, and an infinite radius has no centre to hold fixed. An unknown curvature
# at or below it is a plane.
FLAT_CURVATURE = 0.1


@dataclass(frozen=True)
class LocalSurface:
    """The object's surface near a contact.

    Attributes:
        kind: "plane", "sphere" (radius rho) or "cylinder" (radius rho about `axis`).
        radius: rho [m]; ignored for a plane.
        axis: the cylinder's axis in the object frame O (unit vector).
    """

    kind: str = "plane"
    radius: float = math.inf
    axis: tuple[float, float, float] = (0.0, 0.0, 1.0)

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ValueError(f"local surface kind {self.kind!r}: expected one of {KINDS}")
        if self.kind != "plane" and not (0 < self.radius < math.inf):
            raise ValueError(f"local surface radius {self.radius!r} m must be positive and "
                             f"finite for a {self.kind}")
        a = np.asarray(self.axis, dtype=float)
        if a.shape != (3,) or not np.isclose(np.linalg.norm(a), 1.0):
            raise ValueError(f"local surface axis {self.axis!r} must be a unit 3-vector")

    @property
    def kernel_radius(self) -> float:
        """Each contact's radius of curvature as the motion model's kernels take it [m]:
        the sphere's or the cylinder's own; a plane's 1 / `FLAT_CURVATURE`, at and above
        which a contact is flat (`contact_radii`)."""
        return 1.0 / FLAT_CURVATURE if self.kind == "plane" else self.radius

    @property
    def curvature(self) -> float:
        """1 / rho [1/m]: 0 for a plane; a cylinder's across its axis."""
        return 0.0 if self.kind == "plane" else 1.0 / self.radius

    def with_curvature(self, kappa: float) -> LocalSurface:
        """This surface with curvature `kappa` [1/m]: a plane at or below `FLAT_CURVATURE`;
        a cylinder keeps its axis; a plane bent is a sphere."""
        if not (math.isfinite(kappa) and kappa >= 0):
            raise ValueError(f"curvature {kappa!r} 1/m must be finite and >= 0")
        if kappa <= FLAT_CURVATURE:
            return LocalSurface("plane")
        kind = "cylinder" if self.kind == "cylinder" else "sphere"
        return LocalSurface(kind, 1.0 / kappa, self.axis)

    @classmethod
    def from_spec(cls, spec: ObjectSpec) -> LocalSurface:
        """The surface the fingertips touch, from the object's primitive shape (the
        builders in sim/model.py): a box's faces are planes, a sphere is a sphere, a
        cylinder's side (vertical, or along x_O when `extras.horizontal`) a cylinder. A mesh
        object falls back to a plane (its local curvature is not known to the spec)."""
        if spec.shape == "sphere":
            return cls("sphere", float(spec.size[0]))
        if spec.shape == "cylinder":
            axis = (1.0, 0.0, 0.0) if spec.extras.get("horizontal") else (0.0, 0.0, 1.0)
            return cls("cylinder", float(spec.size[0]), axis)
        return cls("plane")


def _distal_rotations(model: HandModel, theta: np.ndarray) -> np.ndarray:
    """(P, N, 3, 3) rotation of each distal frame D in the palm frame."""
    return np.einsum("nab,pnbc->pnac", model.base_rot, plane_rotation(theta.sum(axis=-1)))


def contact_radii(curvature: np.ndarray) -> np.ndarray:
    """Each contact's radius of curvature in the rolling term [m] from its curvature [1/m]
    (`ParticleState.surface_curvature`): 1 / kappa, a plane's (`FLAT_CURVATURE`) at or below
    it."""
    return 1.0 / np.maximum(np.asarray(curvature, dtype=float), FLAT_CURVATURE)


def surface_contact_normals(model: HandModel, surface: LocalSurface, theta: np.ndarray,
                            segments: np.ndarray, rot: np.ndarray,
                            rho: np.ndarray | None = None) -> np.ndarray | None:
    """(P, N, 3) pad normals in D where each particle's pads would touch one object of the
    local surface's shape, or None where that shape does not fix them (not three fingers).

    A prior for the contacts that follows each particle's own fingers (`ParticleFilter`'s
    "surface" contact prior): a pad of radius r touching a sphere of radius rho has its centre
    rho + r from the sphere's centre, and its contact on the line between the two centres; so
    the three pad centres c_i fix the sphere's centre o (|o - c_i| = rho + r_i, the root on
    the side the pads' inner faces look to), and each contact normal is (o - c_i) / |o - c_i|.
    A cylinder is the same problem in the plane across its axis (the axis's direction from
    the observed POM rotation `rot`, its radius known; three points over-fix the 2-D centre,
    so the two difference equations alone place it). A box's pads lie on its faces: each
    pad's normal is minus the outward face normal it looks at. Only the object's local
    surface (kind, radius, axis in O: `LocalSurface.from_spec`) and the observed POM rotation
    are used, never the object's placement.

    Args:
        theta: (P, N, K) joint angles [rad]; segments: (P, N, K) (`vlr.kinematics`).
        rot: (P, 3, 3) or (3, 3) the observed POM rotation R_PO.
        rho: (P, N) each particle's own radius of curvature at each contact [m] (an unknown
            curvature, `contact_radii`), None: the surface's. A particle of a believed
            plane whose contacts are curved touches a sphere of its radius, and one whose
            contacts are all flat the faces.
    """
    theta = np.asarray(theta, dtype=float)
    p, n = theta.shape[:2]
    if n != 3:
        return None
    rot = np.broadcast_to(np.asarray(rot, dtype=float), (p, 3, 3))
    rd = _distal_rotations(model, theta)                           # (P, N, 3, 3) R_PD
    c = contact_points(model, theta, np.zeros(theta.shape[:2] + (3,)), segments)
    inner = rd[..., 1]                                             # each pad's +y_D in P
    if rho is None:
        if surface.kind == "plane":
            n_palm = _face_normals(rot, inner)
        else:
            n_palm = _curved_normals(surface, c, surface.radius + model.pad_radius[None, :],
                                     rot, inner)
    else:
        reach = np.asarray(rho, dtype=float) + model.pad_radius[None, :]
        bent = surface if surface.kind != "plane" else LocalSurface("sphere", 1.0)
        n_palm = _curved_normals(bent, c, reach, rot, inner)
        if surface.kind == "plane":
            flat = np.all(np.asarray(rho) >= 1.0 / FLAT_CURVATURE, axis=-1)
            n_palm = np.where(flat[:, None, None], _face_normals(rot, inner), n_palm)
    n_d = np.einsum("pnba,pnb->pna", rd, n_palm)
    return n_d / np.linalg.norm(n_d, axis=-1, keepdims=True)


def _face_normals(rot: np.ndarray, inner: np.ndarray) -> np.ndarray:
    """(P, N, 3) in P: minus the outward normal of the box face each pad looks at
    (`surface_contact_normals`)."""
    faces = np.concatenate([rot, -rot], axis=-1)                   # (P, 3, 6) outward normals
    facing = np.einsum("pna,pak->pnk", inner, faces)
    best = np.argmin(facing, axis=-1)                              # the face a pad looks at
    return -np.take_along_axis(faces.transpose(0, 2, 1)[:, None], best[..., None, None],
                               axis=2)[:, :, 0]


def _curved_normals(surface: LocalSurface, c: np.ndarray, rho: np.ndarray, rot: np.ndarray,
                    inner: np.ndarray) -> np.ndarray:
    """(P, N, 3) in P: from each pad centre c_i towards the centre (or axis) of the sphere
    (or cylinder) that the three pads touch, rho (1 or P, N) = the radius + the pad's
    (`surface_contact_normals`)."""
    if surface.kind == "cylinder":
        axis = np.einsum("pab,b->pa", rot, np.asarray(surface.axis, dtype=float))
        c = c - np.einsum("pna,pa->pn", c, axis)[..., None] * axis[:, None]
    # |o - c_i|^2 = rho_i^2, less the first: 2 (c_i - c_0) . o = b_i (two planes).
    a_mat = 2.0 * (c[:, 1:] - c[:, :1])                            # (P, 2, 3)
    b = (np.sum(c[:, 1:] ** 2, -1) - np.sum(c[:, :1] ** 2, -1)
         - rho[:, 1:] ** 2 + rho[:, :1] ** 2)                       # (P, 2)
    # Their least-norm solution o0 plus a line along m, the normal of the pad centres'
    # plane (of the cross-axis plane for a cylinder, where o lies in it).
    o0 = np.einsum("pij,pj->pi", np.linalg.pinv(a_mat), b)
    m = np.cross(a_mat[:, 0], a_mat[:, 1])
    m /= np.maximum(np.linalg.norm(m, axis=-1, keepdims=True), 1e-12)
    if surface.kind == "cylinder":
        o = o0 - np.einsum("pa,pa->p", o0, axis)[:, None] * axis   # in the cross plane
    else:
        # |o0 + t m - c_0|^2 = rho_0^2; the root on the side the inner faces look to.
        d0 = o0 - c[:, 0]
        half_b = np.sum(d0 * m, -1)
        disc = half_b ** 2 - (np.sum(d0 * d0, -1) - rho[:, 0] ** 2)
        side = np.sign(np.einsum("pna,pa->p", inner, m))
        side = np.where(side == 0, 1.0, side)
        t = -half_b + side * np.sqrt(np.maximum(disc, 0.0))
        o = o0 + t[:, None] * m
    d = o[:, None, :] - c
    return d / np.maximum(np.linalg.norm(d, axis=-1, keepdims=True), 1e-12)
