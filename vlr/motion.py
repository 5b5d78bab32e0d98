"""Motion model Gamma (Eq. 4) by energy minimisation (Eq. 6-9), batched over particles.

Formulation (docs/METHOD.md 8.1-8.2; the choice is ours):

* State of one particle: physical joint angles theta (N, K); each finger's contact point fixed
  in its distal frame D, on the pad sphere (pad_center + pad_radius * n); the contact points'
  locations in the object frame O ("anchors"), which pin the POM rigidly to the contact set
  (Eq. 1, 8); and the object pose (p, R) = the POM pose in the palm frame.
* Unknowns of the solve: theta and the object pose (6 dof). Eq. 8 (rigid grasp, fixed
  contacts) is a stiff penalty 1/2 k_c |FK contact_i(theta) - (p + R a_i)|^2 rather than a
  hard constraint: the side fingers move only in their planes, so hard contact equalities are
  rank-deficient (docs/METHOD.md 8.2), while a penalty with damped Newton is not troubled by it.
* Energy (Eq. 9's objective, compliant form): springs 1/2 k (theta - rest)^2 (Eq. 6); series
  tendon 1/2 k_t max(0, u - s(theta))^2 with s = sum r_k (theta_k - lo_k) (Eq. 7 with
  compliance); joint limits as stiff one-sided penalties; gravity potential of the object and
  of the finger links under a configurable gravity vector in the palm frame.
* Rolling (term "rolling", docs/METHOD.md 8.2; `vlr.surface`): instead of pinning the contact,
  each pad sphere touches the object's local surface (a sphere of the object's curvature
  about a centre fixed in O: one equation) and the previous contact points do not slip
  tangentially (two), as stiff penalties. The pin is rolling only to first order; its energy
  misses the force-times-curvature stiffness of a rolling pad, which decides how far a soft
  grasp moves (measured by `vlr gap`). After each solve the contacts move to where the pads
  now touch (`vlr.surface.roll_contacts`).
* Solver: per-particle Levenberg-Marquardt on the exact Hessian (arrow structure, Schur
  complement), warm-started from the particle's previous configuration, with a step limit.
  A particle whose solve fails (non-finite, no convergence, or a jump larger than an action
  can cause) is flagged in `status`; the filter gives it zero weight.

Energy terms are named in `MotionConfig.terms`; each has a numba kernel in
`vlr._energy_kernels` and a NumPy reference here (`reference_energy`), used by the tests.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace

import numpy as np

from vlr import _energy_kernels as kern
from vlr.kinematics import HandModel, contact_in_distal, contact_points, plane_rotation
from vlr.spec import ObjectSpec
from vlr.surface import (
    FLAT_CURVATURE,
    LocalSurface,
    contact_radii,
    local_centres,
    pad_gaps,
    roll_contacts,
    surface_normals,
)

__all__ = [
    "TERMS",
    "STATUS",
    "MotionConfig",
    "PadFriction",
    "ObjectParams",
    "ParticleState",
    "MotionModel",
    "rotvec_to_matrix",
    "reference_energy",
    "contacts_in_distal",
]

# Energy terms by name -> kernel code. "contacts" is Eq. 8 (rigid grasp) as a penalty.
TERMS: dict[str, int] = {
    "springs": kern.SPRINGS,
    "tendon": kern.TENDON,
    "limits": kern.LIMITS,
    "link_gravity": kern.LINK_GRAVITY,
    "object_gravity": kern.OBJECT_GRAVITY,
    "contacts": kern.CONTACTS,
    "rolling": kern.ROLLING,
}

# Where the object's mass and centre of mass sit in `MotionModel._shared` (the kernel's
# arguments after the hand's): replaced per call by the particles' own (`_shared_for`).
_OBJECT_MASS, _OBJECT_COM = 10, 11

# A frictional solve first relaxes the grasp at the old command, with this many times the
# iterations of a solve (`MotionModel._solve`).
RELAX_ITERATIONS = 8

PREDICT = True

STATUS = {kern.OK: "ok", kern.NONFINITE: "non-finite", kern.NO_CONVERGENCE: "no convergence",
          kern.JUMP: "jump", kern.INACTIVE: "inactive"}


@dataclass(frozen=True)
class MotionConfig:
    """Settings of the motion model (units in brackets).

    Attributes:
        terms: energy terms to include (keys of `TERMS` but "rolling").
        rolling: rolling contacts (module docstring, `vlr.surface`) instead of pinned ones;
            needs "contacts" among the terms.
        rolling_substeps: with rolling, a command change given its start
            (`MotionModel.solve(..., u_from=)`) is split into this many solves, the contacts
            rolled after each: within a solve the previous contact points are held, which
            is exact only while the pad turns little (measured by `vlr gap`).
        follow_substeps: a particle whose solve of a command change (`solve(...,
            u_from=)`) does not converge or leaves the jump limits is solved again from
            its start in this many equal steps, each held to the jump limits: a large but
            continuous move is followed, a jump to another branch still fails. 0 turns it
            off. The synthetic world calls a move a snap by the same test (`vlr.synthetic`).
        contact_stiffness: penalty k_c tying contacts to anchors [N/m]. 1e6 N/m leaves
            10 um of penetration at 10 N.
        limit_stiffness: one-sided joint-limit penalty [N m/rad]; 100 lets a spring preload
            of ~0.02 N m sink 0.01 degree into a stop.
        gravity: gravity vector in the palm frame [m/s^2]; default palm up.
        max_iter: Newton iterations (including rejected LM trials) per solve.
        tol_theta: convergence: largest angle step [rad] (also used for the rotation step).
            The step under it is taken, and Newton's convergence there is quadratic, so the
            end state is far closer than the step: at 2e-4 rad (0.011 degree) the POM poses
            the likelihood weighs land within 0.004 mm and 0.004 degree of a 1e-7 rad solve
            on 99% of a filter's particles, some 50 times under its finest scales (0.2 mm,
            0.4 degree), where tighter tolerances cost iterations it cannot see
            (docs/DECISIONS.md).
        tol_pos: convergence: object position step [m]; 20 um, with tol_theta.
        max_step_theta: step limit per Newton iteration [rad].
        max_step_pos: step limit per Newton iteration [m].
        jump_theta: a solve that moves any joint more than this is another branch [rad].
        jump_pos: ... or moves the POM more than this [m].
        mu0: initial Levenberg-Marquardt damping (relative to the Hessian diagonal).
    """

    terms: tuple[str, ...] = ("springs", "tendon", "limits", "link_gravity",
                              "object_gravity", "contacts")
    rolling: bool = True
    rolling_substeps: int = 4
    follow_substeps: int = 16
    contact_stiffness: float = 1e6
    limit_stiffness: float = 100.0
    gravity: tuple[float, float, float] = (0.0, 0.0, -9.81)
    max_iter: int = 30
    tol_theta: float = 2e-4
    tol_pos: float = 2e-5
    max_step_theta: float = 0.1
    max_step_pos: float = 0.005
    jump_theta: float = 0.25
    jump_pos: float = 0.01
    mu0: float = 1e-6

    def __post_init__(self) -> None:
        object.__setattr__(self, "terms", tuple(self.terms))
        known = set(TERMS) - {"rolling"}
        unknown = set(self.terms) - known
        if unknown:
            raise ValueError(f"unknown energy terms {sorted(unknown)}; known: {sorted(known)}"
                             " (rolling contacts: rolling=True)")
        if self.rolling and "contacts" not in self.terms:
            raise ValueError("rolling moves the contacts of the 'contacts' term: it needs "
                             "'contacts' too")
        if not (isinstance(self.follow_substeps, int) and self.follow_substeps >= 0):
            raise ValueError(f"follow_substeps {self.follow_substeps!r} must be an integer "
                             ">= 0")
        if not (isinstance(self.rolling_substeps, int) and self.rolling_substeps >= 1):
            raise ValueError(f"rolling_substeps {self.rolling_substeps!r} must be an "
                             "integer >= 1")
        for name in ("contact_stiffness", "limit_stiffness", "tol_theta", "tol_pos",
                     "max_step_theta", "max_step_pos", "jump_theta", "jump_pos", "mu0"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"{name} {v!r} must be finite and > 0")
        if not (isinstance(self.max_iter, int) and self.max_iter >= 1):
            raise ValueError(f"max_iter {self.max_iter!r} must be an integer >= 1")

    def flags(self) -> np.ndarray:
        out = np.zeros(kern.N_TERMS, dtype=np.int64)
        for t in self.terms:
            out[TERMS[t]] = 1
        if self.rolling:
            out[kern.ROLLING] = 1
        return out

    def params(self, friction: PadFriction | None = None) -> np.ndarray:
        """The kernel's parameter vector, with the pads' `friction` (None: none)."""
        friction = friction or PadFriction()
        prm = np.zeros(kern.N_PRM)
        prm[kern.P_KC] = self.contact_stiffness
        prm[kern.P_KLIM] = self.limit_stiffness
        prm[kern.P_TOL_TH] = self.tol_theta
        prm[kern.P_TOL_P] = self.tol_pos
        prm[kern.P_MAX_DTH] = self.max_step_theta
        prm[kern.P_MAX_DP] = self.max_step_pos
        prm[kern.P_JUMP_TH] = self.jump_theta
        prm[kern.P_JUMP_P] = self.jump_pos
        prm[kern.P_MU0] = self.mu0
        prm[kern.P_KSPIN] = friction.spin_stiffness
        prm[kern.P_SLIDE_FRICTION] = friction.slide
        prm[kern.P_SPIN_FRICTION] = friction.spin
        prm[kern.P_SPIN_EPS] = friction.spin_smoothing
        return prm


@dataclass(frozen=True)
class PadFriction:
    """The pads' friction in the rolling contacts: a term of `vlr gap`'s model ladder
    (sim/gap.py), which measures what each term of the model explains; not a setting of the
    filter (measured, not adopted: docs/DECISIONS.md).

    Attributes:
        slide: the pads' sliding friction coefficient mu: a contact sticks (the penalty k_c)
            until its tangential force reaches mu times its normal force, then slides; after
            each solve its stretch is returned onto the cone (`vlr.surface.roll_contacts`).
            The normal force is each contact's penalty stretch, updated during the first
            half of the Newton iterations so that the grasp can wedge. inf: never slides.
        spin: the pads' torsional friction coefficient mu_t [m]: a pad sticks about its
            contact normal until the spin torque reaches mu_t times its normal force, then
            slips (rate-independent Coulomb friction as an incremental dissipation
            potential, `vlr._energy_kernels._evaluate`); 0 lets them spin freely.
        spin_stiffness: the pad's elastic torsional stiffness about the contact normal
            [N m/rad]; 0: none.
        spin_smoothing: the spin [rad] over which the friction's |s| is rounded off (Newton
            needs a smooth energy); the stick's compliance is tau_max over it.

    Friction acts on a command change (`MotionModel.solve(..., u_from=)`) only: a settle has
    no history, so its contacts stick and spin freely. The sim's pads have mu 1.0 and mu_t
    1 mm (`vlr.sim.pads`).
    """

    slide: float = math.inf
    spin: float = 0.0
    spin_stiffness: float = 0.0
    spin_smoothing: float = 1e-3

    def __post_init__(self) -> None:
        if not self.slide > 0:
            raise ValueError(f"slide friction {self.slide!r} must be > 0 (inf: no sliding)")
        if not (np.isfinite(self.spin) and self.spin >= 0):
            raise ValueError(f"spin friction {self.spin!r} m must be >= 0")
        if not (np.isfinite(self.spin_stiffness) and self.spin_stiffness >= 0):
            raise ValueError(f"spin stiffness {self.spin_stiffness!r} N m/rad must be >= 0")
        if not (np.isfinite(self.spin_smoothing) and self.spin_smoothing > 0):
            raise ValueError(f"spin smoothing {self.spin_smoothing!r} rad must be > 0")

    @property
    def on(self) -> bool:
        """Sliding or torsional friction (not the elastic spin stiffness alone)."""
        return math.isfinite(self.slide) or self.spin > 0


@dataclass(frozen=True)
class ObjectParams:
    """What the motion model needs of the object: mass [kg], centre of mass in O [m] and the
    local surface the fingertips roll on (`vlr.surface`)."""

    mass: float
    com: tuple[float, float, float]
    surface: LocalSurface = LocalSurface()

    @classmethod
    def from_spec(cls, spec: ObjectSpec) -> ObjectParams:
        return cls(mass=float(spec.mass), com=tuple(float(c) for c in spec.com),
                   surface=LocalSurface.from_spec(spec))


@dataclass
class ParticleState:
    """Particles as stacked arrays (P particles, N fingers, K joints).

    Attributes:
        theta: (P, N, K) physical joint angles [rad].
        normals: (P, N, 3) unit pad normals in D: the contact point on the pad.
        anchors: (P, N, 3) contact points in the object frame O [m] (the POM's anchor).
        pos: (P, 3) POM position in the palm frame [m].
        rot: (P, 3, 3) POM rotation R_PO.
        segments: (P, N, K) link lengths, last entry the pad centre's z_D [m]
            (`vlr.kinematics`).
        stiffness: (P, N, K) joint spring rates [N m/rad].
        tendon: (P, N) series tendon stiffness [N/m].
        valid: (P,) False once a solve failed: zero weight.
        object_mass: (P,) the object's mass [kg] when it is an unknown ("mass",
            `vlr.filter.parse_unknown`); None: the motion model's `ObjectParams`.
        object_com: (P, 3) the object's centre of mass in O [m] when an unknown ("com:x",
            ...); None: the motion model's.
        surface_curvature: (P, N) the object's local curvature 1 / rho at each contact
            [1/m] when an unknown ("curvature", "curvature:FINGER"); None: the motion
            model's `LocalSurface` (`vlr.surface.contact_radii`).
    """

    theta: np.ndarray
    normals: np.ndarray
    anchors: np.ndarray
    pos: np.ndarray
    rot: np.ndarray
    segments: np.ndarray
    stiffness: np.ndarray
    tendon: np.ndarray
    valid: np.ndarray
    object_mass: np.ndarray | None = None
    object_com: np.ndarray | None = None
    surface_curvature: np.ndarray | None = None

    @property
    def n(self) -> int:
        return self.theta.shape[0]

    def take(self, idx: np.ndarray) -> ParticleState:
        """A new state of the particles `idx` (resampling), arrays copied and contiguous."""
        return ParticleState(**{f.name: _map(getattr(self, f.name),
                                             lambda a: np.ascontiguousarray(a[idx]))
                                for f in fields(self)})

    def put(self, idx: np.ndarray, other: ParticleState) -> None:
        """Write the particles of `other` into the places `idx` of this state (in place)."""
        for f in fields(self):
            mine, theirs = getattr(self, f.name), getattr(other, f.name)
            if (mine is None) != (theirs is None):
                raise ValueError(f"put: {f.name} is per particle in one state, not the other")
            if mine is not None:
                mine[idx] = theirs

    def copy(self) -> ParticleState:
        return ParticleState(**{f.name: _map(getattr(self, f.name), np.copy)
                                for f in fields(self)})

    def hold_object(self, obj: ObjectParams) -> None:
        """Give every particle its own object mass and centre of mass, `obj`'s to start
        (for the object's unknowns, `vlr.filter.parse_unknown`)."""
        if self.object_mass is None:
            self.object_mass = np.full(self.n, float(obj.mass))
        if self.object_com is None:
            self.object_com = np.tile(np.asarray(obj.com, dtype=float), (self.n, 1))

    def hold_surface(self, obj: ObjectParams) -> None:
        """Give every contact of every particle its own local curvature, `obj`'s surface's
        to start (for the curvature unknowns, `vlr.filter.parse_unknown`)."""
        if self.surface_curvature is None:
            self.surface_curvature = np.full(self.theta.shape[:2], obj.surface.curvature)

    @classmethod
    def nominal(cls, model: HandModel, n: int, theta: np.ndarray, normals: np.ndarray,
                pos: np.ndarray, rot: np.ndarray) -> ParticleState:
        """n particles with the model's nominal parameters at the given configuration; the
        anchors follow from the contacts and the POM pose (see `anchor_to_pose`)."""
        nf, nk = model.n_fingers, model.n_joints
        st = cls(theta=np.broadcast_to(theta, (n, nf, nk)).astype(float).copy(),
                 normals=np.broadcast_to(normals, (n, nf, 3)).astype(float).copy(),
                 anchors=np.zeros((n, nf, 3)),
                 pos=np.broadcast_to(pos, (n, 3)).astype(float).copy(),
                 rot=np.broadcast_to(rot, (n, 3, 3)).astype(float).copy(),
                 segments=np.broadcast_to(model.segments, (n, nf, nk)).copy(),
                 stiffness=np.broadcast_to(model.stiffness, (n, nf, nk)).copy(),
                 tendon=np.full((n, nf), model.tendon_stiffness),
                 valid=np.ones(n, dtype=bool))
        st.anchor_to_pose(model)
        return st

    @classmethod
    def at_truth(cls, model: HandModel, truth) -> ParticleState:
        """One particle at a true state (`vlr.synthetic.Truth` or the sim's): its joint
        angles, pad contacts, POM pose and physical parameters (segments, stiffness, tendon),
        the anchors from the true contacts and pose. For diagnostics and scoring
        (`vlr gap`, `vlr crb`), never for the filter."""
        st = cls.nominal(model, 1, truth.theta, truth.normals, truth.position, truth.rotation)
        st.segments[0] = truth.segments
        st.stiffness[0] = truth.stiffness
        st.tendon[0] = truth.tendon
        if getattr(truth, "object_mass", None) is not None:
            st.object_mass = np.array([float(truth.object_mass)])
            st.object_com = np.asarray(truth.object_com, dtype=float).reshape(1, 3).copy()
        if getattr(truth, "surface_curvature", None) is not None:
            st.surface_curvature = np.full((1, model.n_fingers), float(truth.surface_curvature))
        st.anchor_to_pose(model)
        return st

    def contacts(self, model: HandModel) -> np.ndarray:
        """(P, N, 3) contact points in the palm frame by forward kinematics (Eq. 2)."""
        return contact_points(model, self.theta, self.normals, self.segments)

    def anchor_to_pose(self, model: HandModel, residuals: np.ndarray | None = None) -> None:
        """Re-derive the anchors so that the current POM pose (pos, rot) matches the current
        contacts: a_i = R^T (p_i + r_i - p). Used at initialisation and after jitter, so that a
        jittered particle predicts the POM it had before (docs/METHOD.md 8.2: a fixed anchor
        biased the estimates by 3-5 degrees).

        `residuals` r (P, N, 3) [m] (`contact_residuals`, palm frame) keep each contact
        penalty's stretch, i.e. the grasp forces; without them (r = 0) the particle loses its
        squeeze and is no longer at equilibrium: measured on the synthetic world, a particle
        AT the truth then moved by 0.5 degrees when settled again, every iteration."""
        c = self.contacts(model)
        if residuals is not None:
            c = c + residuals
        self.anchors = np.ascontiguousarray((c - self.pos[:, None, :]) @ self.rot)

    def contact_residuals(self, model: HandModel) -> np.ndarray:
        """(P, N, 3) anchor minus contact point in the palm frame, R a_i + p - p_i [m]: the
        stretch of the contact penalty (Eq. 8 as a stiff spring), k_c times it the force."""
        anchors_palm = self.anchors @ np.swapaxes(self.rot, -1, -2) + self.pos[:, None, :]
        return anchors_palm - self.contacts(model)


def _map(a: np.ndarray | None, f) -> np.ndarray | None:
    return None if a is None else f(a)


def rotvec_to_matrix(w: np.ndarray) -> np.ndarray:
    """Rodrigues: rotation vector (..., 3) -> rotation matrix (..., 3, 3)."""
    w = np.asarray(w, dtype=float)
    ang = np.linalg.norm(w, axis=-1)[..., None, None]
    k = np.zeros(w.shape[:-1] + (3, 3))
    k[..., 0, 1], k[..., 0, 2], k[..., 1, 2] = -w[..., 2], w[..., 1], -w[..., 0]
    k = k - np.swapaxes(k, -1, -2)
    with np.errstate(invalid="ignore", divide="ignore"):
        a = np.where(ang > 1e-12, np.sin(ang) / ang, 1.0)
        b = np.where(ang > 1e-12, (1 - np.cos(ang)) / ang**2, 0.5)
    return np.eye(3) + a * k + b * (k @ k)


class MotionModel:
    """Gamma: (state, u) -> equilibrium state (Eq. 4, 9), batched over particles.

    Args:
        model: the hand; obj: the object (its mass, centre of mass and local surface).
        config: the model's settings.
        friction: the pads' friction with rolling contacts (`PadFriction`; `vlr gap` only).
    """

    def __init__(self, model: HandModel, obj: ObjectParams,
                 config: MotionConfig | None = None,
                 friction: PadFriction | None = None) -> None:
        self.model = model
        self.obj = obj
        self.config = config or MotionConfig()
        self.friction = friction or PadFriction()
        # The particles of the last solve that needed the follow-up of a large move.
        self.followed = np.zeros(0, dtype=bool)
        lim = model.limits
        self._shared = (
            np.ascontiguousarray(model.base_pos), np.ascontiguousarray(model.base_rot),
            np.ascontiguousarray(model.radii), np.ascontiguousarray(model.rest),
            np.ascontiguousarray(lim[..., 0]), np.ascontiguousarray(lim[..., 1]),
            np.ascontiguousarray(model.link_masses), np.ascontiguousarray(model.link_coms),
            np.ascontiguousarray(model.pad_center[:, :2]),
            np.ascontiguousarray(model.pad_radius),
            float(obj.mass), np.asarray(obj.com, dtype=float),   # per particle: _shared_for
            np.asarray(self.config.gravity, dtype=float))
        self._flags = self.config.flags()
        self._prm = self._params(self.config)
        self._prm_settle = self._params(self.config, history=False)
        self._no_roll = np.zeros((1, model.n_fingers, kern.N_RL))
        surf = obj.surface
        self._surface = np.zeros(kern.N_SRF)
        self._surface[kern.S_KIND] = {"plane": kern.SURF_PLANE, "sphere": kern.SURF_SPHERE,
                                      "cylinder": kern.SURF_CYLINDER}[surf.kind]
        self._surface[kern.S_RADIUS] = surf.radius
        self._surface[kern.S_KERNEL] = surf.kernel_radius
        self._surface[kern.S_AXIS:kern.S_AXIS + 3] = surf.axis
        self._surface[kern.S_FLAT_RADIUS] = 1.0 / FLAT_CURVATURE
        self._own_object: dict[int, tuple[np.ndarray, np.ndarray]] = {}

    def _params(self, cfg: MotionConfig, history: bool = True) -> np.ndarray:
        """The kernel's parameters; without `history` (a settle) without friction."""
        friction = self.friction
        if not history:
            friction = replace(friction, slide=math.inf, spin=0.0)
        return cfg.params(friction)

    def rolling_frames(self, state: ParticleState, normals_o: np.ndarray | None = None,
                       forces: bool = True) -> np.ndarray:
        """(P, N, `kern.N_RL`) what the rolling term holds fixed during a solve: each
        contact's local centre of curvature in O, a - rho m (`vlr.surface.local_centres`),
        its normal in the palm frame, R m (m: the object's outward normal at the contact, in
        O), the finger's summed joint angles, the object's rotation (for the spin term), the
        contact's normal force (`normal_forces`; it sets the friction's limits; 0 if not
        `forces`) and the local radius of curvature (`contact_rho`). `normals_o`: m if
        already computed (`vlr.surface.surface_normals`)."""
        m = (surface_normals(self.model, state.theta, state.normals, state.rot)
             if normals_o is None else normals_o)
        out = np.empty(m.shape[:2] + (kern.N_RL,))
        rho = self.contact_rho(state)
        out[..., kern.RL_CENTRE:kern.RL_CENTRE + 3] = local_centres(
            self.obj.surface, state.anchors, m, rho)
        out[..., kern.RL_RHO] = self.obj.surface.kernel_radius if rho is None else rho
        out[..., kern.RL_NORMAL:kern.RL_NORMAL + 3] = np.einsum("pab,pnb->pna", state.rot, m)
        out[..., kern.RL_PHI] = state.theta.sum(axis=-1)
        out[..., kern.RL_ROT:kern.RL_ROT + 9] = state.rot.reshape(-1, 1, 9)
        out[..., kern.RL_FORCE] = self.normal_forces(state, out) if forces else 0.0
        return out

    def normal_forces(self, state: ParticleState, frames: np.ndarray) -> np.ndarray:
        """(P, N) each contact's normal force in the rolling term [N]: k_c times how far the
        pad sphere sinks into the object's local sphere (the rolling `frames`' centres in O,
        radii rho), 0 where they part."""
        centre = contact_points(self.model, state.theta, np.zeros_like(state.normals),
                                state.segments)
        local = state.pos[:, None, :] + np.einsum(
            "pab,pnb->pna", state.rot, frames[..., kern.RL_CENTRE:kern.RL_CENTRE + 3])
        gap = pad_gaps(centre, local, frames[..., kern.RL_RHO] + self.model.pad_radius)
        return self.config.contact_stiffness * np.maximum(0.0, -gap)

    def contact_rho(self, state: ParticleState) -> np.ndarray | None:
        """(P, N) each contact's radius of curvature [m] when the particles carry their own
        curvature (`ParticleState.surface_curvature`), else None: this model's surface."""
        if state.surface_curvature is None:
            return None
        return contact_radii(state.surface_curvature)

    def object_arrays(self, state: ParticleState) -> tuple[np.ndarray, np.ndarray]:
        """(P,) object masses [kg] and (P, 3) centres of mass in O [m]: the particles' own
        (an unknown object), else this model's object for every particle."""
        n = state.n
        if n not in self._own_object:  # built once per particle count, not every solve
            self._own_object = {n: (np.full(n, float(self.obj.mass)),
                                    np.tile(np.asarray(self.obj.com, dtype=float), (n, 1)))}
        mass, com = self._own_object[n]
        if state.object_mass is not None:
            mass = np.ascontiguousarray(state.object_mass, dtype=float)
        if state.object_com is not None:
            com = np.ascontiguousarray(state.object_com, dtype=float)
        return mass, com

    def _shared_for(self, cfg: MotionConfig, state: ParticleState) -> tuple:
        """The kernel's shared arrays for `cfg` and `state`: the model's own, but with the
        gravity a per-call config asks for, and the particles' object masses and centres of
        mass."""
        shared = list(self._shared)
        shared[_OBJECT_MASS], shared[_OBJECT_COM] = self.object_arrays(state)
        shared[-1] = np.asarray(cfg.gravity, dtype=float)
        return tuple(shared)

    def solve(self, state: ParticleState, u: np.ndarray, config: MotionConfig | None = None,
              u_from: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Move every valid particle to its equilibrium at tendon commands `u` (Eq. 9).

        Warm-starts from each particle's current configuration and updates theta, pos, rot
        in place (and, with rolling, the contacts: normals and anchors); particles whose
        solve fails are marked invalid (state.valid = False).

        Args:
            state: particles; arrays must be C-contiguous float64.
            u: (N,) tendon commands [m].
            config: optional override (e.g. looser jump limits for the initial projection).
            u_from: (N,) the commands the particles are at; with rolling and
                `rolling_substeps` > 1, the change is made in that many rolled solves, and
                a particle whose solve fails by a jump or no convergence is followed in
                `follow_substeps` steps.
        Returns:
            status (P,) int8 codes (`STATUS`), iterations (P,) int32 (summed over substeps).
        """
        cfg = config or self.config
        if u_from is None or not (cfg.rolling and self.friction.on):
            return self._solve_path(state, u, cfg, config is not None, u_from)
        # The pads' friction (`vlr gap`'s rung): its relax and normal forces run in NumPy.
        follow = cfg.follow_substeps > 1
        start = state.copy() if follow else None
        status, iters = self._solve(state, u, cfg, config is not None, u_from)
        if follow:
            self._follow(state, start, u, u_from, cfg, status, iters)
        return status, iters

    def _solve_path(self, state: ParticleState, u: np.ndarray, cfg: MotionConfig,
                    custom: bool, u_from: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
        """`solve` without the pads' friction, whole in one kernel call
        (`vlr._energy_kernels.solve_path_batch`): the rolling substeps, the contacts rolled
        after each, and the follow-up of a large move, particle by particle."""
        history = u_from is not None
        prm = (self._params(cfg, history) if custom
               else self._prm if history else self._prm_settle)
        flags = cfg.flags() if custom else self._flags
        n = self.model.n_fingers
        u = np.ascontiguousarray(u, dtype=float).reshape(n)
        u0 = u if u_from is None else np.ascontiguousarray(u_from, dtype=float).reshape(n)
        substeps = cfg.rolling_substeps if (cfg.rolling and history) else 1
        follow = cfg.follow_substeps if history else 0
        rho = self.contact_rho(state)
        has_rho = rho is not None
        rho = (np.ascontiguousarray(rho, dtype=float) if has_rho
               else np.zeros((1, n)))
        roll = (np.empty((state.n, n, kern.N_RL)) if cfg.rolling else self._no_roll)
        status = np.empty(state.n, dtype=np.int8)
        iters = np.zeros(state.n, dtype=np.int32)
        self.followed = np.zeros(state.n, dtype=np.bool_)
        kern.solve_path_batch(state.theta, state.segments, state.normals, state.anchors, roll,
                              state.pos, state.rot, state.stiffness, state.tendon, u0, u,
                              substeps, follow, cfg.rolling, PREDICT, rho, has_rho,
                              self._surface,
                              *self._shared_for(cfg, state), flags, prm, int(cfg.max_iter),
                              state.valid, status, iters, self.followed)
        return status, iters

    def _solve(self, state: ParticleState, u: np.ndarray, cfg: MotionConfig, custom: bool,
               u_from: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
        """One solve of every valid particle at u (`solve`), rolled in substeps if asked."""
        history = u_from is not None
        prm = (self._params(cfg, history) if custom
               else self._prm if history else self._prm_settle)
        flags = cfg.flags() if custom else self._flags
        u = np.ascontiguousarray(u, dtype=float).reshape(self.model.n_fingers)
        steps = cfg.rolling_substeps if (cfg.rolling and u_from is not None) else 1
        targets = [u] if steps == 1 else [
            np.ascontiguousarray(np.asarray(u_from, dtype=float) + (u - u_from) * (j / steps))
            for j in range(1, steps + 1)]
        status = np.empty(state.n, dtype=np.int8)
        iters = np.zeros(state.n, dtype=np.int32)
        it = np.empty(state.n, dtype=np.int32)
        step_status = np.empty(state.n, dtype=np.int8)
        budgets = [int(cfg.max_iter)] * len(targets)
        slide = self.friction.slide
        if history and cfg.rolling and math.isfinite(slide):
            # A settle holds its contacts whatever the force. Friction first returns their
            # stretch onto the cone, as the world's contacts would have slid, and lets the
            # grasp find its frictional equilibrium at the old command: after a settle that
            # can be a large move (measured: a joint 11 degrees, 170 iterations), after a
            # frictional solve it takes one or two iterations.
            self.roll(state, surface_normals(self.model, state.theta, state.normals,
                                             state.rot), slide)
            targets = [np.ascontiguousarray(u_from, dtype=float)] + targets
            budgets = [RELAX_ITERATIONS * int(cfg.max_iter)] + budgets
        for j, target in enumerate(targets):
            before = surface_normals(self.model, state.theta, state.normals, state.rot) \
                if cfg.rolling else None
            # Only friction reads the normal forces (a settle has none).
            roll = (self.rolling_frames(state, before,
                                        forces=history and self.friction.on)
                    if cfg.rolling else self._no_roll)
            kern.solve_batch(state.theta, state.segments, state.normals, state.anchors,
                             roll, state.pos, state.rot, state.stiffness, state.tendon, target,
                             *self._shared_for(cfg, state), flags, prm, budgets[j],
                             state.valid, step_status, it)
            iters += it
            # A particle keeps the status of the substep it failed in (later ones say only
            # "inactive"), so that `_follow` sees a jump or no convergence as such.
            if j == 0:
                status[:] = step_status
            else:
                status[state.valid] = step_status[state.valid]
            state.valid &= step_status == kern.OK
            if cfg.rolling:
                self.roll(state, before, slide if history else math.inf)
        return status, iters

    def _follow(self, state: ParticleState, start: ParticleState, u: np.ndarray,
                u_from: np.ndarray, cfg: MotionConfig, status: np.ndarray,
                iters: np.ndarray) -> None:
        """Solve the particles whose one solve failed by a jump or no convergence again from
        `start`, in `cfg.follow_substeps` steps (`MotionConfig.follow_substeps`); those that
        pass every step replace their failure (status, iterations and state, in place)."""
        idx = np.flatnonzero((status == kern.JUMP) | (status == kern.NO_CONVERGENCE))
        if not len(idx):
            return
        sub = start.take(idx)
        u_from = np.asarray(u_from, dtype=float)
        n = cfg.follow_substeps
        # The steep stretch of a path near a fold takes more iterations per step than a
        # whole ordinary action (measured: 30 did not converge, 60 did, on 16 steps).
        cfg = replace(cfg, max_iter=2 * cfg.max_iter)
        u_prev = u_from
        spent = np.zeros(len(idx), dtype=np.int32)
        for j in range(1, n + 1):
            target = u_from + (np.asarray(u, dtype=float) - u_from) * (j / n)
            _, it = self._solve(sub, target, cfg, True, u_prev)
            spent += it
            u_prev = target
        ok = sub.valid
        iters[idx] += spent
        if ok.any():
            state.put(idx[ok], sub.take(np.flatnonzero(ok)))
            status[idx[ok]] = kern.OK

    def roll(self, state: ParticleState, normals_before: np.ndarray,
             slide_friction: float = math.inf) -> None:
        """Move the valid particles' contacts to where their pads now touch the object
        (`vlr.surface.roll_contacts`), a contact's stretch returned onto its friction cone
        (`slide_friction`)."""
        ok = state.valid
        if not ok.any():
            return
        rho = self.contact_rho(state)
        n, a = roll_contacts(self.model, self.obj.surface, state.theta[ok], state.normals[ok],
                             state.anchors[ok], state.pos[ok], state.rot[ok],
                             state.segments[ok], normals_before[ok], slide_friction,
                             None if rho is None else rho[ok])
        if ok.all():
            state.normals, state.anchors = n, a
        else:
            state.normals[ok], state.anchors[ok] = n, a

    def evaluate(self, state: ParticleState, q: int, u: np.ndarray,
                 roll: np.ndarray | None = None) -> tuple[float, np.ndarray, np.ndarray]:
        """Energy [J], gradient (N K + 6,) and dense Hessian of particle q, in the solver's
        coordinates (theta, dp, dw). `roll`: the (N, 21) rolling frames (`rolling_frames`),
        needed with the rolling term. For tests and diagnostics."""
        if roll is None:
            roll = self.rolling_frames(state)[q] if self.config.rolling else self._no_roll[0]
        nf, nk = self.model.n_fingers, self.model.n_joints
        gA, gC = np.empty((nf, nk)), np.empty(6)
        A, B, C = np.empty((nf, nk, nk)), np.empty((nf, nk, 6)), np.empty((6, 6))
        shared = list(self._shared)
        mass, com = self.object_arrays(state)
        shared[_OBJECT_MASS], shared[_OBJECT_COM] = float(mass[q]), com[q]
        e = kern.evaluate_one(state.theta[q], state.segments[q], state.normals[q],
                              state.anchors[q], np.ascontiguousarray(roll, dtype=float),
                              state.pos[q], state.rot[q],
                              state.stiffness[q], state.tendon[q],
                              np.asarray(u, dtype=float), *shared, self._flags,
                              self._prm, gA, gC, A, B, C)
        n = nf * nk
        H = np.zeros((n + 6, n + 6))
        for i in range(nf):
            sl = slice(i * nk, (i + 1) * nk)
            H[sl, sl] = A[i]
            H[sl, n:] = B[i]
            H[n:, sl] = B[i].T
        H[n:, n:] = C
        return float(e), np.concatenate([gA.ravel(), gC]), H

    def tensions(self, state: ParticleState, u: np.ndarray) -> np.ndarray:
        """Tendon tensions k_t max(0, u - s(theta)) [N], (P, N) (Eq. 7, compliant)."""
        s = self.model.tendon_takeup(state.theta)
        return state.tendon * np.maximum(0.0, np.asarray(u) - s)


def pad_spins(model: HandModel, roll: np.ndarray, theta: np.ndarray,
              rot: np.ndarray) -> np.ndarray:
    """(P, N) each pad's spin against the object about the contact normal since the rolling
    frames `roll` (P, N, N_RL) were taken [rad]: s = n . (omega_O - omega_D), omega_O =
    vee(sym(R R0^T)), omega_D = -(sum theta - sum theta_0) x_F (the kernel's `_spin_rate`)."""
    r0 = roll[..., kern.RL_ROT:kern.RL_ROT + 9].reshape(roll.shape[:2] + (3, 3))
    w = np.einsum("pab,pncb->pnac", rot, r0)
    omega = 0.5 * np.stack([w[..., 2, 1] - w[..., 1, 2], w[..., 0, 2] - w[..., 2, 0],
                            w[..., 1, 0] - w[..., 0, 1]], axis=-1)
    n = roll[..., kern.RL_NORMAL:kern.RL_NORMAL + 3]
    return (np.sum(n * omega, axis=-1) + (theta.sum(axis=-1) - roll[..., kern.RL_PHI])
            * np.einsum("pna,na->pn", n, model.base_rot[:, :, 0]))


def reference_energy(motion: MotionModel, state: ParticleState, q: int, u: np.ndarray,
                     theta: np.ndarray, pos: np.ndarray, rot: np.ndarray,
                     roll: np.ndarray | None = None) -> float:
    """Plain NumPy energy of particle q at configuration (theta, pos, rot), term by term
    (Eq. 6, 7 compliant, 8 penalty or rolling with the (N, 21) frames `roll` and the pads'
    friction, limits, gravity). The independent reference the vectorised kernel is tested
    against."""
    m, cfg = motion.model, motion.config
    if roll is None and cfg.rolling:
        roll = motion.rolling_frames(state)[q]
    g = np.asarray(cfg.gravity, dtype=float)
    theta = np.asarray(theta, dtype=float)
    lim = m.limits
    e = 0.0
    if "springs" in cfg.terms:
        e += 0.5 * np.sum(state.stiffness[q] * (theta - m.rest) ** 2)
    if "limits" in cfg.terms:
        over = np.maximum(0.0, lim[..., 0] - theta) + np.maximum(0.0, theta - lim[..., 1])
        e += 0.5 * cfg.limit_stiffness * np.sum(over**2)
    if "tendon" in cfg.terms:
        slack = np.maximum(0.0, np.asarray(u) - m.tendon_takeup(theta))
        e += 0.5 * np.sum(state.tendon[q] * slack**2)
    if "link_gravity" in cfg.terms:
        seg = state.segments[q]
        phi = np.cumsum(theta, axis=-1)
        q_f = np.zeros(theta.shape + (3,))
        for k in range(1, m.n_joints):
            q_f[:, k, 1] = q_f[:, k - 1, 1] + seg[:, k - 1] * np.sin(phi[:, k - 1])
            q_f[:, k, 2] = q_f[:, k - 1, 2] + seg[:, k - 1] * np.cos(phi[:, k - 1])
        com_f = q_f + np.einsum("nkab,nkb->nka", plane_rotation(phi), m.link_coms)
        com_p = m.base_pos[:, None, :] + np.einsum("nab,nkb->nka", m.base_rot, com_f)
        e -= np.sum(m.link_masses * (com_p @ g))
    if "object_gravity" in cfg.terms:
        mass, com = motion.object_arrays(state)
        e -= mass[q] * g @ (pos + rot @ com[q])
    if "contacts" in cfg.terms and cfg.rolling:
        c = contact_points(m, theta, state.normals[q], state.segments[q])
        d = c - (pos + state.anchors[q] @ rot.T)
        n = roll[:, 3:6]
        tangential = d - np.sum(d * n, axis=-1, keepdims=True) * n
        centre = contact_points(m, theta, np.zeros_like(state.normals[q]), state.segments[q])
        gap = pad_gaps(centre, pos + roll[:, kern.RL_CENTRE:kern.RL_CENTRE + 3] @ rot.T,
                       roll[:, kern.RL_RHO] + m.pad_radius)
        kc = cfg.contact_stiffness
        e += 0.5 * kc * np.sum(gap**2)
        spin = np.zeros(len(roll))
        fr = motion.friction
        if fr.spin_stiffness > 0 or fr.spin > 0:
            spin = pad_spins(m, roll[None], theta[None], rot[None])[0]
        e += 0.5 * fr.spin_stiffness * np.sum(spin**2)
        t2 = np.sum(tangential**2, axis=-1)
        mu, mu_t = fr.slide, fr.spin
        if mu_t > 0:
            eps = fr.spin_smoothing
            tau = mu_t * roll[:, kern.RL_FORCE]
            e += np.sum(tau * (np.sqrt(spin**2 + eps**2) - eps))
        cap = mu * roll[:, kern.RL_FORCE] if math.isfinite(mu) else np.full(len(roll), math.inf)
        z = np.sqrt(t2)
        with np.errstate(invalid="ignore"):
            e += np.sum(np.where(kc * z <= cap, 0.5 * kc * t2, cap * z - 0.5 * cap**2 / kc))
    elif "contacts" in cfg.terms:
        c = contact_points(m, theta, state.normals[q], state.segments[q])
        target = pos + state.anchors[q] @ rot.T
        e += 0.5 * cfg.contact_stiffness * np.sum((c - target) ** 2)
    return float(e)


def contacts_in_distal(motion: MotionModel, state: ParticleState) -> np.ndarray:
    """(P, N, 3) contact points in each finger's distal frame D [m]."""
    return contact_in_distal(motion.model, state.normals, state.segments)
