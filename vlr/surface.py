"""Rolling contacts: the object's local surface at each contact and the contact update
(docs/METHOD.md 8.2, "Rolling").

A fingertip pad is a sphere of known radius. Within one action the motion model pins each
pad's material contact point to the object's (Eq. 8 as a penalty): the pad pivots about it.
For a pad rolling without slip that is exact to first order, since the instantaneous motion
of a rolling contact is a rotation about the contact point; what the pin misses is that the
contact itself travels, over the pad and over the object. Without the update the pivot stays
at the grasp's contact points, and over a sequence of actions the prediction drifts (8-9% of
the motion over 15 actions in a feasibility study, under 2% with rolling).

`roll_contacts` is that update, applied after each solve: the new contact is where the pad
sphere now touches the object's LOCAL surface at the previous contact. The local surface is
described by its kind and curvature (known from the object, `LocalSurface.from_spec`) and
anchored at each particle's own contact point and normal, so the filter needs no global
object model: a plane (a box face: exact), a sphere of radius rho (the apple), or a cylinder
of radius rho about an axis fixed in O (the wine glass's bowl, the screwdriver's handle, a
cup's wall). Treating a sphere as flat was measured to raise the per-action gap to 0.11.

Known limits: sliding is not modelled (friction is assumed to hold), nor is the second-order
error within one action (`MotionConfig.rolling_substeps` splits an action to shrink it).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from vlr.kinematics import HandModel, contact_points, plane_rotation
from vlr.spec import ObjectSpec

__all__ = ["LocalSurface", "surface_normals", "local_centres", "pad_gaps", "roll_contacts",
           "contact_radii", "FLAT_CURVATURE"]

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
        """The radius of the local sphere the motion model's rolling term uses [m]: the
        sphere's own, a cylinder's (a sphere of its radius: exact around the axis, too
        curved along it; `local_centres`), and 10 m for a plane (flat within 0.1% of a pad's
        travel; an infinite radius has no centre to hold fixed: `FLAT_CURVATURE`)."""
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


def surface_normals(model: HandModel, theta: np.ndarray, normals: np.ndarray,
                    rot: np.ndarray) -> np.ndarray:
    """(P, N, 3) the object's outward surface normal at each contact, in O: minus the pad's
    outward normal there (the surfaces are tangent at a contact)."""
    n_palm = np.einsum("pnab,pnb->pna", _distal_rotations(model, theta), normals)
    return -np.einsum("pba,pnb->pna", rot, n_palm)


def _side_normals(surface: LocalSurface, m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A cylinder's outward normals m (..., 3) made normal to its axis, and whether each
    contact is on the side (normal within 60 degrees of normal to the axis; else an end
    face, flat)."""
    axis = np.asarray(surface.axis, dtype=float)
    m_side = m - np.einsum("...i,i->...", m, axis)[..., None] * axis
    side_len = np.linalg.norm(m_side, axis=-1, keepdims=True)
    on_side = side_len > 0.5
    return m_side / np.where(on_side, side_len, 1.0), on_side


def local_centres(surface: LocalSurface, anchors: np.ndarray, m: np.ndarray,
                  rho: np.ndarray | None = None) -> np.ndarray:
    """What the motion model's rolling term holds each pad to, in O: the local centre of
    curvature a - rho m (the local sphere's, `LocalSurface.kernel_radius`; a cylinder's side
    is held to a sphere of its radius: exact across the axis, too curved along it, which
    measured no worse than holding the pad to the axis, docs/DECISIONS.md). (P, N, 3); `m`
    the object's outward normals at the contacts `anchors` (`surface_normals`); `rho` (P, N)
    each contact's own radius of curvature [m] (an unknown curvature, `contact_radii`), None:
    the surface's."""
    r = surface.kernel_radius if rho is None else np.asarray(rho, dtype=float)[..., None]
    return anchors - r * m


def contact_radii(curvature: np.ndarray) -> np.ndarray:
    """Each contact's radius of curvature in the rolling term [m] from its curvature [1/m]
    (`ParticleState.surface_curvature`): 1 / kappa, a plane's (`FLAT_CURVATURE`) at or below
    it."""
    return 1.0 / np.maximum(np.asarray(curvature, dtype=float), FLAT_CURVATURE)


def pad_gaps(centre: np.ndarray, local: np.ndarray, reach: np.ndarray | float) -> np.ndarray:
    """(...) the rolling term's gap: each pad centre's distance from its local centre of
    curvature `local`, less the reach rho + r (negative: the pad sinks in). One frame."""
    return np.linalg.norm(centre - local, axis=-1) - reach


def roll_contacts(model: HandModel, surface: LocalSurface, theta: np.ndarray,
                  normals: np.ndarray, anchors: np.ndarray, pos: np.ndarray, rot: np.ndarray,
                  segments: np.ndarray, normals_before: np.ndarray,
                  slide_friction: float = math.inf,
                  rho: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Move each contact to where the pad now touches the object's local surface.

    Args:
        theta, normals, anchors, pos, rot, segments: the particles after a fixed-contact
            solve (`vlr.motion.ParticleState` arrays).
        normals_before: (P, N, 3) the object's surface normals at the contacts in O before
            that solve (`surface_normals`): material to the object, so the solve left them.
        slide_friction: mu; a contact whose tangential stretch carries more than mu times
            its normal force (both k_c times a stretch) has slid: its stretch is returned
            onto the friction cone (the return mapping of elasto-plastic friction). inf: no
            contact slides.
        rho: (P, N) each contact's own radius of curvature [m] (`contact_radii`: an unknown
            curvature; a plane of the surface's kind becomes a sphere of it), None: the
            surface's. A contact as flat as a plane's (`FLAT_CURVATURE`) keeps its normal.
    Returns:
        (normals, anchors): the new pad normals in D and contact points in O. The POM pose
        is unchanged, and so are the rolling term's residuals (the pad-to-surface gap and the
        tangential offset of the contact points): they carry the contact forces, so the
        state stays at equilibrium; zeroing them would drop the grasp's squeeze and friction.
    """
    radius = model.pad_radius[None, :, None]
    centre_palm = contact_points(model, theta, np.zeros_like(normals), segments)
    centre = np.einsum("pba,pnb->pna", rot, centre_palm - pos[:, None, :])
    contact = np.einsum("pba,pnb->pna", rot,
                        contact_points(model, theta, normals, segments) - pos[:, None, :])
    # The residuals as the motion model's rolling term sees them (its local sphere).
    d = contact - anchors
    tangential = d - np.sum(d * normals_before, axis=-1, keepdims=True) * normals_before
    local = local_centres(surface, anchors, normals_before, rho)
    reach = surface.kernel_radius if rho is None else np.asarray(rho, dtype=float)
    gap = pad_gaps(centre, local, reach + radius[..., 0])[..., None]
    if math.isfinite(slide_friction):
        cap = slide_friction * np.maximum(0.0, -gap)
        t = np.linalg.norm(tangential, axis=-1, keepdims=True)
        tangential = tangential * np.where(t > cap, cap / np.where(t > 0, t, 1.0), 1.0)
    m = normals_before
    if surface.kind == "plane" and rho is None:
        out = m
    else:
        r = surface.radius if rho is None else np.asarray(rho, dtype=float)[..., None]
        if surface.kind == "cylinder":
            axis = np.asarray(surface.axis, dtype=float)
            m_side, on_side = _side_normals(surface, m)    # an end face is flat
            d = centre - (anchors - r * m_side)    # from the local axis of curvature
            d = d - np.einsum("pni,i->pn", d, axis)[..., None] * axis
            d_len = np.linalg.norm(d, axis=-1, keepdims=True)
            out = np.where(on_side, d / np.where(d_len > 0, d_len, 1.0), m)
        else:
            d = centre - (anchors - r * m)    # from the local centre of curvature
            out = d / np.linalg.norm(d, axis=-1, keepdims=True)
        if rho is not None:
            out = np.where(r >= 1.0 / FLAT_CURVATURE, m, out)
    new_anchors = centre - (radius + gap) * out - tangential
    n_palm = -np.einsum("pab,pnb->pna", rot, out)
    new_normals = np.einsum("pnba,pnb->pna", _distal_rotations(model, theta), n_palm)
    return (np.ascontiguousarray(new_normals / np.linalg.norm(new_normals, axis=-1,
                                                               keepdims=True)),
            np.ascontiguousarray(new_anchors))


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
