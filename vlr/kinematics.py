"""VLR kinematics (Eq. 1-3): finger chains, joint positions, contact points, POM pose.

Frames and signs are those of `vlr.spec`: every joint of finger i turns about -x_F, so in the
finger frame F a chain is planar (x_F is constant along it) and a positive angle flexes it
inwards (towards +y_F). A joint angle of 0 points the link up, along z_F.

Nothing here assumes three fingers or two joints: a `HandModel` holds N chains of K joints
each (K equal across fingers, so that particles stack as (P, N, K) arrays). For K = 2 the
chains come from `FingerSpec`; for other K, build `Chain`s directly.

Array layout used across `vlr` (P particles, N fingers, K joints):
    theta    (P, N, K)  physical joint angles [rad]
    segments (P, N, K)  segments[..., k] for k < K-1: length of link k (joint k to joint k+1);
                        segments[..., K-1]: the pad centre's offset along z_D in the distal
                        frame [m]. Per particle, so that unknown lengths can be sampled.
    normals  (P, N, 3)  unit pad normals n in the distal frame D; the contact point is
                        pad_center + pad_radius * n (spec.py).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from vlr.kernels.chain import contact_points_batch
from vlr.kernels.records import Hand
from vlr.spec import FingerSpec, HandSpec

__all__ = [
    "Chain",
    "HandModel",
    "plane_rotation",
    "joint_positions",
    "contact_points",
    "contact_in_distal",
    "normals_from_angles",
    "angles_from_normals",
    "pom_from_contacts",
    "virtual_links",
]


@dataclass(frozen=True)
class Chain:
    """A finger as a serial chain of K hinges about -x_F (docs/METHOD.md 1; Eq. 2).

    Attributes (units in brackets), one entry per joint k = 0..K-1 unless noted:
        lengths: K-1 link lengths, joint k to joint k+1 [m].
        pad_center: pad sphere centre in the distal (last-joint) frame D [m].
        pad_radius: pad sphere radius [m].
        pulley_radii: tendon moment arms r_k [m] (Eq. 7).
        stiffness: torsional spring rates k_k [N m/rad] (Eq. 6).
        rest_angles: spring rest angles [rad].
        limits: (lo, hi) per joint [rad]; lo is the open stop.
        link_masses: [kg].
        link_coms: centre of mass of link k in its own frame (at joint k, rotated by the
            cumulative angle) [m].
    """

    lengths: tuple[float, ...]
    pad_center: tuple[float, float, float]
    pad_radius: float
    pulley_radii: tuple[float, ...]
    stiffness: tuple[float, ...]
    rest_angles: tuple[float, ...]
    limits: tuple[tuple[float, float], ...]
    link_masses: tuple[float, ...]
    link_coms: tuple[tuple[float, float, float], ...]

    def __post_init__(self) -> None:
        k = len(self.pulley_radii)
        sizes = {len(self.stiffness), len(self.rest_angles), len(self.limits),
                 len(self.link_masses), len(self.link_coms)}
        if k < 1 or sizes != {k} or len(self.lengths) != k - 1:
            raise ValueError(f"chain needs K per-joint entries and K-1 lengths; got K={k}, "
                             f"per-joint sizes {sorted(sizes)}, {len(self.lengths)} lengths")

    @property
    def n_joints(self) -> int:
        return len(self.pulley_radii)

    @classmethod
    def from_finger(cls, f: FingerSpec) -> Chain:
        """The two-joint chain of a `FingerSpec` (proximal, distal)."""
        return cls(lengths=(f.proximal_length,), pad_center=tuple(f.pad_center),
                   pad_radius=f.pad_radius, pulley_radii=tuple(f.pulley_radii),
                   stiffness=tuple(f.stiffness), rest_angles=tuple(f.rest_angles),
                   limits=tuple(tuple(lim) for lim in f.limits),
                   link_masses=tuple(f.link_masses),
                   link_coms=tuple(tuple(c) for c in f.link_coms))


def _mount_rotation(yaw: float) -> np.ndarray:
    # Same as FingerMount.rotation: columns x_F, y_F, z_F in the palm frame.
    y = np.array([np.cos(yaw), np.sin(yaw), 0.0])
    z = np.array([0.0, 0.0, 1.0])
    return np.column_stack([np.cross(y, z), y, z])


@dataclass(frozen=True)
class HandModel:
    """N chains of K joints on the palm, as stacked arrays for batched kernels.

    Attributes:
        names: finger slot names, e.g. ("thumb", "left", "right").
        chains: one `Chain` per finger.
        base_pos: (N, 3) finger frame origins in the palm frame [m].
        base_rot: (N, 3, 3) R_PF, columns x_F, y_F, z_F in the palm frame.
        tendon_stiffness: series stiffness of drive plus line [N/m] (docs/METHOD.md 8.2).
    """

    names: tuple[str, ...]
    chains: tuple[Chain, ...]
    base_pos: np.ndarray
    base_rot: np.ndarray
    tendon_stiffness: float

    @cached_property
    def kernel_record(self) -> Hand:
        """The hand's constants as the kernels take them (`vlr.kernels.records.Hand`),
        gravity zero (`vlr.motion` sets its own)."""
        lim = self.limits
        c = np.ascontiguousarray
        return Hand(base_pos=c(self.base_pos, dtype=float), base_rot=c(self.base_rot, dtype=float),
                    radii=c(self.radii), rest=c(self.rest), lo=c(lim[..., 0]), hi=c(lim[..., 1]),
                    link_mass=c(self.link_masses), link_com=c(self.link_coms),
                    pad_xy=c(self.pad_center[:, :2]), pad_r=c(self.pad_radius, dtype=float),
                    gravity=np.zeros(3))

    def __post_init__(self) -> None:
        ks = {c.n_joints for c in self.chains}
        if len(ks) != 1:
            raise ValueError(f"all fingers need the same number of joints, got {sorted(ks)}")
        if len(self.names) != len(self.chains):
            raise ValueError("one name per chain")

    @classmethod
    def from_spec(cls, spec: HandSpec) -> HandModel:
        """Build from a `HandSpec`: finger bases from the mounts, chains from the fingers."""
        if spec.spread != 0.0:
            # spec.py does not say how the spread joint moves the side mounts; refuse rather
            # than silently ignore it.
            raise NotImplementedError(f"hand {spec.name}: spread {spec.spread} != 0 is not "
                                      "modelled")
        return cls(names=spec.finger_names,
                   chains=tuple(Chain.from_finger(m.finger) for m in spec.mounts),
                   base_pos=np.array([m.position for m in spec.mounts], dtype=float),
                   base_rot=np.array([m.rotation() for m in spec.mounts], dtype=float),
                   tendon_stiffness=float(spec.tendon_stiffness))

    @classmethod
    def from_chains(cls, names: tuple[str, ...], chains: tuple[Chain, ...],
                    positions: np.ndarray, yaws: np.ndarray,
                    tendon_stiffness: float) -> HandModel:
        """Build from chains and mount positions [m] / yaws [rad] (same yaw rule as spec.py)."""
        return cls(names=tuple(names), chains=tuple(chains),
                   base_pos=np.asarray(positions, dtype=float).reshape(len(chains), 3),
                   base_rot=np.array([_mount_rotation(y) for y in yaws]),
                   tendon_stiffness=float(tendon_stiffness))

    # ---- stacked per-joint arrays (N, K) and friends

    @property
    def n_fingers(self) -> int:
        return len(self.chains)

    @property
    def n_joints(self) -> int:
        return self.chains[0].n_joints

    def finger_index(self, name: str) -> int:
        if name not in self.names:
            raise ValueError(f"no finger {name!r}; fingers are {list(self.names)}")
        return self.names.index(name)

    def joint_index(self, name: str) -> int:
        """Joint by name: "proximal" (0), "distal" (K-1), "middle" (1 if K == 3) or an int."""
        k = self.n_joints
        table = {"proximal": 0, "distal": k - 1}
        if k == 3:
            table["middle"] = 1
        if name in table:
            return table[name]
        if name.isdigit() and int(name) < k:
            return int(name)
        raise ValueError(f"no joint {name!r}; joints are {sorted(table)} or 0..{k - 1}")

    def _stack(self, attr: str) -> np.ndarray:
        return np.array([getattr(c, attr) for c in self.chains], dtype=float)

    @property
    def radii(self) -> np.ndarray:
        return self._stack("pulley_radii")

    @property
    def stiffness(self) -> np.ndarray:
        return self._stack("stiffness")

    @property
    def rest(self) -> np.ndarray:
        return self._stack("rest_angles")

    @property
    def limits(self) -> np.ndarray:
        """(N, K, 2) joint ranges [rad]."""
        return self._stack("limits")

    @property
    def link_masses(self) -> np.ndarray:
        return self._stack("link_masses")

    @property
    def link_coms(self) -> np.ndarray:
        """(N, K, 3)."""
        return self._stack("link_coms")

    @property
    def pad_center(self) -> np.ndarray:
        """(N, 3) nominal pad centres in D [m]."""
        return self._stack("pad_center")

    @property
    def pad_radius(self) -> np.ndarray:
        return self._stack("pad_radius")

    @property
    def segments(self) -> np.ndarray:
        """(N, K) nominal segments: K-1 link lengths, then the pad centre's z_D offset [m]."""
        return np.array([list(c.lengths) + [c.pad_center[2]] for c in self.chains])

    def tendon_takeup(self, theta: np.ndarray) -> np.ndarray:
        """s(theta) = sum_k r_k (theta_k - lo_k) (Eq. 7) [m]; theta (..., N, K) -> (..., N)."""
        return np.sum(self.radii * (np.asarray(theta) - self.limits[..., 0]), axis=-1)


def plane_rotation(phi: np.ndarray) -> np.ndarray:
    """Rotation by `phi` about -x (the flexion axis), shape (..., 3, 3).

    A point (x, y, z) maps to (x, y cos phi + z sin phi, -y sin phi + z cos phi): a link
    along +z tips towards +y for phi > 0 (spec.py).
    """
    c, s = np.cos(phi), np.sin(phi)
    out = np.zeros(np.shape(phi) + (3, 3))
    out[..., 0, 0] = 1.0
    out[..., 1, 1] = c
    out[..., 1, 2] = s
    out[..., 2, 1] = -s
    out[..., 2, 2] = c
    return out


def _segments(model: HandModel, theta: np.ndarray, segments: np.ndarray | None) -> np.ndarray:
    return np.broadcast_to(model.segments if segments is None else segments, theta.shape)


def joint_positions(model: HandModel, theta: np.ndarray,
                    segments: np.ndarray | None = None) -> np.ndarray:
    """Joint origins q_i^k in the palm frame (the E^J chain, Eq. 2).

    Args:
        theta: (..., N, K) joint angles [rad].
        segments: (..., N, K) per-particle segments (module docstring); None = nominal.
    Returns:
        (..., N, K, 3) positions [m]; index 0 is the base joint.
    """
    theta = np.asarray(theta, dtype=float)
    seg = _segments(model, theta, segments)
    phi = np.cumsum(theta, axis=-1)
    # q_{k+1} = q_k + L_k (0, sin phi_k, cos phi_k) in F
    step = np.zeros(theta.shape + (3,))
    step[..., 1] = seg * np.sin(phi)
    step[..., 2] = seg * np.cos(phi)
    q_f = np.zeros_like(step)
    q_f[..., 1:, :] = np.cumsum(step[..., :-1, :], axis=-2)
    return model.base_pos[:, None, :] + np.einsum("nab,...nkb->...nka", model.base_rot, q_f)


def contact_in_distal(model: HandModel, normals: np.ndarray,
                      segments: np.ndarray | None = None) -> np.ndarray:
    """Contact point in the distal frame D: pad_center + pad_radius * n (spec.py) [m].

    Args:
        normals: (..., N, 3) unit pad normals in D.
        segments: (..., N, K); its last entry replaces pad_center's z (module docstring).
    """
    normals = np.asarray(normals, dtype=float)
    centre = np.broadcast_to(model.pad_center, normals.shape).copy()
    if segments is not None:
        centre[..., 2] = np.asarray(segments)[..., -1]
    return centre + model.pad_radius[:, None] * normals


def contact_points(model: HandModel, theta: np.ndarray, normals: np.ndarray,
                   segments: np.ndarray | None = None) -> np.ndarray:
    """Contact points p_i in the palm frame by forward kinematics (Eq. 2).

    Args:
        theta: (..., N, K) [rad]; normals: (..., N, 3); segments: (..., N, K) or None.
    Returns:
        (..., N, 3) [m].
    """
    theta = np.asarray(theta, dtype=float)
    seg = _segments(model, theta, segments)
    normals = np.asarray(normals, dtype=float)
    if theta.ndim == 3 and normals.shape == theta.shape[:2] + (3,):
        # Particles (P, N, K): one pass of a kernel, not a dozen NumPy temporaries.
        out = np.empty(normals.shape)
        contact_points_batch(np.ascontiguousarray(theta), np.ascontiguousarray(seg),
                             np.ascontiguousarray(normals), model.kernel_record, out)
        return out
    q = joint_positions(model, theta, seg)[..., -1, :]
    c_d = contact_in_distal(model, normals, seg)
    phi = np.sum(theta, axis=-1)
    c_f = np.einsum("...ab,...b->...a", plane_rotation(phi), c_d)
    return q + np.einsum("nab,...nb->...na", model.base_rot, c_f)


def normals_from_angles(alpha: np.ndarray, beta: np.ndarray) -> np.ndarray:
    """Unit pad normal in D from two angles [rad]: alpha in the finger plane from +y_D towards
    +z_D, beta out of the plane towards +x_D. alpha = beta = 0 is the inner face (+y_D)."""
    cb = np.cos(beta)
    return np.stack([np.sin(beta), cb * np.cos(alpha), cb * np.sin(alpha)], axis=-1)


def angles_from_normals(n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Inverse of `normals_from_angles`: (alpha, beta) [rad]."""
    n = np.asarray(n, dtype=float)
    return np.arctan2(n[..., 2], n[..., 1]), np.arcsin(np.clip(n[..., 0], -1.0, 1.0))


def pom_from_contacts(contacts: np.ndarray,
                      anchors: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """POM pose from the contact set through the virtual links E^C (Eq. 1, 3).

    The object frame O has its origin at the POM, so the anchors (contact points in O) fix the
    lengths of E^C; the pose (R, p) with contacts = p + R anchors is the least-squares rigid
    fit (Kabsch). Needs N >= 3 non-collinear contacts; with N = 2 the rotation about the
    contact axis is not fixed by the links (the motion model's equilibrium carries it).

    Args:
        contacts: (..., N, 3) in the palm frame; anchors: (..., N, 3) in O [m].
    Returns:
        position (..., 3) [m], rotation (..., 3, 3) R_PO.
    """
    contacts = np.asarray(contacts, dtype=float)
    anchors = np.asarray(anchors, dtype=float)
    if contacts.shape[-2] < 3:
        raise ValueError("the POM pose needs at least 3 contacts (N >= 3)")
    cc = contacts.mean(axis=-2)
    ca = anchors.mean(axis=-2)
    h = np.einsum("...ni,...nj->...ij", anchors - ca[..., None, :], contacts - cc[..., None, :])
    u, _, vt = np.linalg.svd(h)
    d = np.sign(np.linalg.det(np.einsum("...ij,...jk->...ik", u, vt).swapaxes(-1, -2)))
    fix = np.ones(h.shape[:-1])
    fix[..., -1] = d
    rot = np.einsum("...ji,...j,...kj->...ik", vt, fix, u)
    pos = cc - np.einsum("...ij,...j->...i", rot, ca)
    return pos, rot


def virtual_links(model: HandModel, theta: np.ndarray, normals: np.ndarray,
                  segments: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The distal virtual link of each finger (Eq. 2): distal joint to contact.

    Returns:
        length (..., N) [m] and virtual distal angle (..., N) [rad]: the physical distal
        angle plus the angle of the contact seen from the distal joint in the finger plane
        (0 when the contact lies on the distal link's axis).
    """
    seg = _segments(model, np.asarray(theta, dtype=float), segments)
    c_d = contact_in_distal(model, normals, seg)
    length = np.linalg.norm(c_d[..., 1:], axis=-1)
    offset = np.arctan2(c_d[..., 1], c_d[..., 2])
    return length, np.asarray(theta)[..., -1] + offset
