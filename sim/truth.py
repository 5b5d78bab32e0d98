"""Ground truth of the simulated hand, for scoring only (never an input to the estimator).

Contacts: MuJoCo may report several points for one finger-object touch (a face contact); we
report their normal-force-weighted centre and the pad region it lies on.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import mujoco
import numpy as np

if TYPE_CHECKING:
    from vlr.sim.backend import SimHand


@dataclass(frozen=True)
class FingerTruth:
    """One finger's true state. Frames: palm P, distal link D (vlr/spec.py).

    Attributes:
        angles: physical (proximal, distal) joint angles [rad].
        contact_palm: force-weighted contact point in the palm frame [m] (NaN if none).
        contact_distal: the same point in the distal frame D [m].
        contact_force: total normal force [N].
        contact_region: "pad", "distal_link", "proximal_link" or "none".
        virtual_distal_length: distal joint axis to contact [m] (docs/METHOD.md 2).
        virtual_distal_angle: angle of the virtual distal link in the finger plane, measured
            like the joint angles (0 = straight up, positive = flexed) [rad].
        tendon_length: MuJoCo tendon length [m]; tension [N]; command [m].
    """

    angles: np.ndarray
    contact_palm: np.ndarray
    contact_distal: np.ndarray
    contact_force: float
    contact_region: str
    virtual_distal_length: float
    virtual_distal_angle: float
    tendon_length: float
    tension: float
    command: float
    stiffness: tuple[float, float]
    link_lengths: tuple[float, float]


@dataclass(frozen=True)
class GroundTruth:
    fingers: dict[str, FingerTruth]
    pom_position: np.ndarray     # POM (tag centre) in the palm frame [m]
    pom_rotation: np.ndarray     # object frame O in the palm frame (3x3)
    time: float


@dataclass(frozen=True)
class ContactSummary:
    """Who touches the object. `fingertip_touch`: through the pad or the distal link."""

    finger_touch: dict[str, bool]
    fingertip_touch: dict[str, bool]
    palm_touch: bool
    points: dict[str, list[tuple[np.ndarray, float, str]]]


def _palm_pose(hand: SimHand) -> tuple[np.ndarray, np.ndarray]:
    b = hand.model.body("palm").id
    return hand.data.xpos[b].copy(), hand.data.xmat[b].reshape(3, 3).copy()


def contact_summary(hand: SimHand) -> ContactSummary:
    """Which fingers touch the object (pad or link), and whether the palm does."""
    m, d = hand.model, hand.data
    obj_body = hand._obj_body
    palm_geom = m.geom("palm").id
    points: dict[str, list] = {s: [] for s in hand.slots}
    palm_touch = False
    force = np.zeros(6)
    for i in range(d.ncon):
        c = d.contact[i]
        b1, b2 = m.geom_bodyid[c.geom1], m.geom_bodyid[c.geom2]
        if obj_body not in (b1, b2):
            continue
        other = c.geom2 if b1 == obj_body else c.geom1
        if other == palm_geom:
            palm_touch = True
            continue
        name = m.geom(other).name
        if "/" not in name:
            continue
        slot, region = name.split("/", 1)
        if slot not in points:
            continue
        mujoco.mj_contactForce(m, d, i, force)
        points[slot].append((c.pos.copy(), float(force[0]), region))
    touch = {s: len(p) > 0 for s, p in points.items()}
    tip = {s: any(r in ("pad", "distal_link") for _, _, r in p) for s, p in points.items()}
    return ContactSummary(finger_touch=touch, fingertip_touch=tip, palm_touch=palm_touch,
                          points=points)


def pad_forces(hand: SimHand) -> np.ndarray:
    """(fingers, 3) total contact force of each finger on the object, palm frame [N]: the
    sim's contact loads (`vlr gap --start sim-loads`), zero for a finger off the object."""
    m, d = hand.model, hand.data
    r_palm = _palm_pose(hand)[1]
    out, f6 = np.zeros((len(hand.slots), 3)), np.zeros(6)
    for i in range(d.ncon):
        c = d.contact[i]
        b1, b2 = m.geom_bodyid[c.geom1], m.geom_bodyid[c.geom2]
        if hand._obj_body not in (b1, b2):
            continue
        slot = m.geom(c.geom2 if b1 == hand._obj_body else c.geom1).name.split("/")[0]
        if slot not in hand.slots:
            continue
        mujoco.mj_contactForce(m, d, i, f6)
        f_world = c.frame.reshape(3, 3).T @ f6[:3]  # MuJoCo's: on geom2, from geom1
        out[hand.slots.index(slot)] += r_palm.T @ (-f_world if b1 == hand._obj_body
                                                    else f_world)
    return out


def read_truth(hand: SimHand) -> GroundTruth:
    m, d = hand.model, hand.data
    p0, R0 = _palm_pose(hand)
    summary = contact_summary(hand)
    fingers = {}
    for i, slot in enumerate(hand.slots):
        spec = hand.true_spec.mounts[i].finger
        angles = d.qpos[hand._qadr[i]].copy()
        pts = summary.points[slot]
        dist_body = m.body(f"{slot}/distal").id
        pd, Rd = d.xpos[dist_body], d.xmat[dist_body].reshape(3, 3)
        if pts:
            f = np.array([p[1] for p in pts])
            w = f / f.sum() if f.sum() > 0 else np.full(len(pts), 1 / len(pts))
            world = np.sum([wi * p[0] for wi, p in zip(w, pts, strict=True)], axis=0)
            # The region of the strongest point names the centre's region.
            region = pts[int(np.argmax(f))][2]
            region = {"pad": "pad", "distal_link": "distal_link",
                      "proximal_link": "proximal_link"}.get(region, region)
            total = float(f.sum())
        else:
            world = np.full(3, np.nan)
            region, total = "none", 0.0
        c_palm = R0.T @ (world - p0)
        c_dist = Rd.T @ (world - pd)
        # In D, the link points along +z and flexes towards +y: the virtual link's angle
        # relative to D is atan2(y, z); add the physical joint angles to get it in F.
        vlen = float(np.hypot(c_dist[1], c_dist[2]))
        vang = float(angles.sum() + np.arctan2(c_dist[1], c_dist[2]))
        fingers[slot] = FingerTruth(
            angles=angles, contact_palm=c_palm, contact_distal=c_dist, contact_force=total,
            contact_region=region, virtual_distal_length=vlen,
            virtual_distal_angle=vang - angles[0],
            tendon_length=float(d.ten_length[hand._tendon[i]]),
            tension=float(-d.actuator_force[hand._act[i]]), command=float(hand._u[i]),
            stiffness=spec.stiffness, link_lengths=(spec.proximal_length, spec.distal_length))
    ob = hand._obj_body
    pom = R0.T @ (d.xpos[ob] - p0)
    rot = R0.T @ d.xmat[ob].reshape(3, 3)
    return GroundTruth(fingers=fingers, pom_position=pom, pom_rotation=rot, time=float(d.time))
