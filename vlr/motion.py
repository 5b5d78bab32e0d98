"""Motion model Gamma (Eq. 4) by energy minimisation (Eq. 6-9), batched over particles.

Formulation (METHOD.md 8.1-8.2; the choice is ours):

* State of one particle: physical joint angles theta (N, K); each finger's contact point fixed
  in its distal frame D, on the pad sphere (pad_center + pad_radius * n); the contact points'
  locations in the object frame O ("anchors"), which pin the POM rigidly to the contact set
  (Eq. 1, 8); and the object pose (p, R) = the POM pose in the palm frame.
* Unknowns of the solve: theta and the object pose (6 dof). Eq. 8 (rigid grasp, fixed
  contacts) is a stiff penalty 1/2 k_c |FK contact_i(theta) - (p + R a_i)|^2 rather than a
  hard constraint: the side fingers move only in their planes, so hard contact equalities are
  rank-deficient (METHOD.md 8.2), while a penalty with damped Newton is not troubled by it.
* Energy (Eq. 9's objective, compliant form): springs 1/2 k (theta - rest)^2 (Eq. 6); series
  tendon 1/2 k_t max(0, u - s(theta))^2 with s = sum r_k (theta_k - lo_k) (Eq. 7 with
  compliance); joint limits as stiff one-sided penalties; gravity potential of the object and
  of the finger links under a configurable gravity vector in the palm frame.
* Rolling (term "rolling", METHOD.md 8.2; `vlr.surface`): instead of pinning the contact,
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
_OBJECT_MASS, _OBJECT_COM = 11, 12

# A frictional solve first relaxes the grasp at the old command, with this many times the
# iterations of a solve (`MotionModel._solve`).
RELAX_ITERATIONS = 8

STATUS = {kern.OK: "ok", kern.NONFINITE: "non-finite", kern.NO_CONVERGENCE: "no convergence",
          kern.JUMP: "jump", kern.INACTIVE: "inactive"}


@dataclass(frozen=True)
class MotionConfig:
    """Settings of the motion model (units in brackets).

    Attributes:
        terms: energy terms to include (keys of `TERMS`).
        contact_stiffness: penalty k_c tying contacts to anchors [N/m]. 1e6 N/m leaves
            10 um of penetration at 10 N; METHOD.md 8.2 used 1e7 (1e4 N/mm), which this
            solver also handles, with more rejected line-search trials.
        limit_stiffness: one-sided joint-limit penalty [N m/rad]; 100 lets a spring preload
            of ~0.02 N m sink 0.01 degree into a stop.
        gravity: gravity vector in the palm frame [m/s^2]; default palm up.
        max_iter: Newton iterations (including rejected LM trials) per solve.
        tol_theta: convergence: largest angle step [rad] (also used for the rotation step).
        tol_pos: convergence: object position step [m].
        max_step_theta: step limit per Newton iteration [rad].
        max_step_pos: step limit per Newton iteration [m].
        jump_theta: a solve that moves any joint more than this is another branch [rad].
        jump_pos: ... or moves the POM more than this [m].
        mu0: initial Levenberg-Marquardt damping (relative to the Hessian diagonal).
        rolling_substeps: with "rolling" in `terms`, a command change given its start
            (`MotionModel.solve(..., u_from=)`) is split into this many solves, the contacts
            rolled after each: within a solve the previous contact points are held, which
            is exact only while the pad turns little (measured by `vlr gap`).
        spin_stiffness: with rolling, the pad's torsional stiffness about the contact
            normal [N m/rad]; 0 lets the object spin freely on the pads.
        slide_friction: with rolling, the pads' sliding friction coefficient mu: a contact
            sticks (the penalty k_c) until its tangential force reaches mu times its normal
            force, then slides; after each solve its stretch is returned onto the cone
            (`vlr.surface.roll_contacts`). The normal force is each contact's penalty
            stretch, updated during the first half of the Newton iterations so that the
            grasp can wedge. inf: contacts never slide (the model before friction). The
            sim's pads have 1.0 (`sim.pads.SLIDE_FRICTION`).
        spin_friction: with rolling, the pads' torsional friction coefficient mu_t [m]: a
            pad sticks about its contact normal until the spin torque reaches mu_t times
            its normal force, then slips (rate-independent Coulomb friction as an
            incremental dissipation potential, `vlr._energy_kernels._evaluate`). The sim's pads
            have 1 mm (`sim.pads.TORSION_FRICTION`); 0 lets them spin freely.
            Friction acts on a command change (`solve(..., u_from=)`) only: a settle has no
            history, so its contacts stick and spin freely as before.
        cone_return: with rolling and without the pads' friction in the energy, the
            sliding friction coefficient mu of one return-map step after each action: the
            command change (`solve(..., u_from=)`) is solved with glued contacts, then each
            contact's stretch is returned onto its cone mu N (`vlr.surface.roll_contacts`)
            and the grasp settled again, glued, at the new command. The settle loads the
            contacts again, less than before: one step goes part of the way from the glued
            equilibrium to the frictional one (repeated, the steps converge to it; on the
            test grasp one step goes about a third of the way). Measured by `vlr gap` as
            its own rung (RESULTS.md 5); its cost is one settle, where the friction's Huber
            energy costs 3-5x the solve. inf: off. The sim's pads have 1.0
            (`sim.pads.SLIDE_FRICTION`).
        spin_memory: with the pads' torsional friction, each pad keeps the spin torque its
            stick held at the end of a command change into the next one
            (`ParticleState.spin_torque`), as its tangential stick keeps its force in the
            stretch: a pad that slipped one way slips on at once under more of the same
            torque and sticks through twice the cone the other way. False: every command
            change starts each pad at zero spin torque, so a particle's first step at the
            old command rebalances the torques it dropped. A settle spins the pads freely
            and zeroes them either way.
        exact_cylinder: with rolling, a pad on a cylinder's side is held at rho + r from
            the cylinder's local axis, as it is; False: from the centre of a sphere of the
            cylinder's radius, exact across the axis and too curved along it (with a 12 mm
            pad on the screwdriver's 16 mm handle a roll along the axis would turn the
            object 1.75 times too far). Spheres and planes are the same either way.
        spin_smoothing: the spin [rad] over which the friction's |s| is rounded off
            (Newton needs a smooth energy); the stick's compliance is tau_max over it.
        follow_substeps: a particle whose solve of a command change (`solve(...,
            u_from=)`) does not converge or leaves the jump limits is solved again from
            its start in this many equal steps, each held to the jump limits: a large but
            continuous move is followed, a jump to another branch still fails. Measured on
            the pinned synthetic grasp: a 0.3 mm action turned a joint 38 degrees
            continuously, and the one-solve test dropped the truth. 0 turns it off. The
            synthetic world calls a move a snap by the same test (`vlr.synthetic`).
        link_scaling: a link whose length a particle hypothesizes (an unknown length,
            `vlr.filter.Unknown`) has the nominal link's make: its mass and its centre of
            mass along the link scale with the length (the distal link with its pad's
            offset). False: every link keeps the nominal mass and centre of mass whatever
            its length. Nominal lengths are unchanged either way. Off by default: on
            NH1 it did not move the pad offset's error (docs/RESULTS.md section 2).
    """

    terms: tuple[str, ...] = ("springs", "tendon", "limits", "link_gravity",
                              "object_gravity", "contacts")
    rolling_substeps: int = 4
    spin_stiffness: float = 0.0
    slide_friction: float = math.inf
    spin_friction: float = 0.0
    spin_memory: bool = False
    exact_cylinder: bool = False
    cone_return: float = math.inf
    spin_smoothing: float = 1e-3
    follow_substeps: int = 16
    contact_stiffness: float = 1e6
    limit_stiffness: float = 100.0
    gravity: tuple[float, float, float] = (0.0, 0.0, -9.81)
    max_iter: int = 30
    tol_theta: float = 1e-6
    tol_pos: float = 1e-7
    max_step_theta: float = 0.1
    max_step_pos: float = 0.005
    jump_theta: float = 0.25
    jump_pos: float = 0.01
    mu0: float = 1e-6
    link_scaling: bool = False

    def __post_init__(self) -> None:
        known = set(TERMS)
        unknown = set(self.terms) - known
        if unknown:
            raise ValueError(f"unknown energy terms {sorted(unknown)}; known: {sorted(known)}")
        if "rolling" in self.terms and "contacts" not in self.terms:
            raise ValueError("the 'rolling' term moves the contacts of the 'contacts' term: "
                             "it needs 'contacts' too")
        if not (np.isfinite(self.spin_stiffness) and self.spin_stiffness >= 0):
            raise ValueError(f"spin_stiffness {self.spin_stiffness!r} N m/rad must be >= 0")
        if not (self.slide_friction > 0):
            raise ValueError(f"slide_friction {self.slide_friction!r} must be > 0 (inf: no "
                             "sliding)")
        if not (self.cone_return > 0):
            raise ValueError(f"cone_return {self.cone_return!r} must be > 0 (inf: off)")
        if not (np.isfinite(self.spin_friction) and self.spin_friction >= 0):
            raise ValueError(f"spin_friction {self.spin_friction!r} m must be >= 0")
        if not (np.isfinite(self.spin_smoothing) and self.spin_smoothing > 0):
            raise ValueError(f"spin_smoothing {self.spin_smoothing!r} rad must be > 0")
        if not (isinstance(self.follow_substeps, int) and self.follow_substeps >= 0):
            raise ValueError(f"follow_substeps {self.follow_substeps!r} must be an integer "
                             ">= 0")
        if not (isinstance(self.rolling_substeps, int) and self.rolling_substeps >= 1):
            raise ValueError(f"rolling_substeps {self.rolling_substeps!r} must be an "
                             "integer >= 1")

    @property
    def rolling(self) -> bool:
        return "rolling" in self.terms

    @property
    def friction(self) -> bool:
        """Rolling contacts with the pads' friction (sliding or torsional) on."""
        return self.rolling and (math.isfinite(self.slide_friction) or self.spin_friction > 0)

    def with_rolling(self, on: bool = True) -> MotionConfig:
        """This configuration with the rolling term switched on (or off)."""
        from dataclasses import replace
        terms = tuple(t for t in self.terms if t != "rolling")
        return replace(self, terms=terms + (("rolling",) if on else ()))

    def flags(self) -> np.ndarray:
        out = np.zeros(kern.N_TERMS, dtype=np.int64)
        for t in self.terms:
            out[TERMS[t]] = 1
        return out

    def params(self) -> np.ndarray:
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
        prm[kern.P_KSPIN] = self.spin_stiffness
        prm[kern.P_SLIDE_FRICTION] = self.slide_friction
        prm[kern.P_SPIN_FRICTION] = self.spin_friction
        prm[kern.P_SPIN_EPS] = self.spin_smoothing
        return prm


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
        noise: (P,) each particle's factor on the likelihood's pose scales (1: the scales
            as configured; `vlr.observation`); sampled when the model error's size is an
            unknown ("noise", `vlr.filter.parse_unknown`). The motion model ignores it.
        spin_torque: (P, N) the spin torque each pad's torsional friction holds [N m]
            (`MotionConfig.spin_memory`; 0 without it).
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
    noise: np.ndarray
    spin_torque: np.ndarray
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
                 valid=np.ones(n, dtype=bool), noise=np.ones(n),
                 spin_torque=np.zeros((n, nf)))
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
        jittered particle predicts the POM it had before (METHOD.md 8.2: a fixed anchor
        biased the estimates by 3-5 degrees).

        `residuals` r (P, N, 3) [m] (`contact_residuals`, palm frame) keep each contact
        penalty's stretch, i.e. the grasp forces; without them (r = 0) the particle loses its
        squeeze and is no longer at equilibrium: measured on the synthetic world, a particle
        AT the truth then moved by 0.5 degrees when settled again, every iteration."""
        c = self.contacts(model)
        if residuals is not None:
            c = c + residuals
        self.anchors = np.ascontiguousarray(
            np.einsum("pji,pnj->pni", self.rot, c - self.pos[:, None, :]))

    def contact_residuals(self, model: HandModel) -> np.ndarray:
        """(P, N, 3) anchor minus contact point in the palm frame, R a_i + p - p_i [m]: the
        stretch of the contact penalty (Eq. 8 as a stiff spring), k_c times it the force."""
        anchors_palm = np.einsum("pij,pnj->pni", self.rot, self.anchors) + self.pos[:, None, :]
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
    """Gamma: (state, u) -> equilibrium state (Eq. 4, 9), batched over particles."""

    def __init__(self, model: HandModel, obj: ObjectParams,
                 config: MotionConfig | None = None) -> None:
        self.model = model
        self.obj = obj
        self.config = config or MotionConfig()
        lim = model.limits
        self._shared = (
            np.ascontiguousarray(model.base_pos), np.ascontiguousarray(model.base_rot),
            np.ascontiguousarray(model.radii), np.ascontiguousarray(model.rest),
            np.ascontiguousarray(lim[..., 0]), np.ascontiguousarray(lim[..., 1]),
            np.ascontiguousarray(model.link_masses), np.ascontiguousarray(model.link_coms),
            np.ascontiguousarray(model.segments if self.config.link_scaling
                                 else np.zeros_like(model.segments)),   # lseg: [8]
            np.ascontiguousarray(model.pad_center[:, :2]),
            np.ascontiguousarray(model.pad_radius),
            float(obj.mass), np.asarray(obj.com, dtype=float),   # per particle: _shared_for
            np.asarray(self.config.gravity, dtype=float))
        self._flags = self.config.flags()
        self._prm = self._params(self.config)
        self._lseg_off = np.zeros_like(self._shared[8])
        self._lseg_on = np.ascontiguousarray(model.segments)
        self._prm_settle = self._params(self.config, history=False)
        self._no_roll = np.zeros((1, model.n_fingers, kern.N_RL))
        self._own_object: dict[int, tuple[np.ndarray, np.ndarray]] = {}

    def _params(self, cfg: MotionConfig, history: bool = True) -> np.ndarray:
        """The kernel's parameters; without `history` (a settle) without friction."""
        if not history:
            cfg = replace(cfg, slide_friction=math.inf, spin_friction=0.0)
        return cfg.params()

    def rolling_frames(self, state: ParticleState, normals_o: np.ndarray | None = None,
                       forces: bool = True, exact_cylinder: bool | None = None) -> np.ndarray:
        """(P, N, 21) what the rolling term holds fixed during a solve: each contact's local
        centre of curvature in O, a - rho m (and a cylinder's axis with `exact_cylinder`,
        by default the model's `MotionConfig.exact_cylinder`; `vlr.surface.local_centres`),
        its normal in the palm frame, R m (m: the
        object's outward normal at the contact, in O), the finger's summed joint angles, the
        object's rotation (for the spin term), the contact's normal force
        (`normal_forces`; it sets the friction's limits; 0 if not `forces`) and the spin
        torque the pad holds (`ParticleState.spin_torque`), and the local radius of curvature
        (`contact_rho`). `normals_o`: m if already computed (`vlr.surface.surface_normals`)."""
        m = (surface_normals(self.model, state.theta, state.normals, state.rot)
             if normals_o is None else normals_o)
        out = np.empty(m.shape[:2] + (kern.N_RL,))
        rho = self.contact_rho(state)
        (out[..., kern.RL_CENTRE:kern.RL_CENTRE + 3],
         out[..., kern.RL_AXIS:kern.RL_AXIS + 3]) = local_centres(
            self.obj.surface, state.anchors, m,
            self.config.exact_cylinder if exact_cylinder is None else exact_cylinder, rho)
        out[..., kern.RL_RHO] = self.obj.surface.kernel_radius if rho is None else rho
        out[..., kern.RL_NORMAL:kern.RL_NORMAL + 3] = np.einsum("pab,pnb->pna", state.rot, m)
        out[..., kern.RL_PHI] = state.theta.sum(axis=-1)
        out[..., kern.RL_ROT:kern.RL_ROT + 9] = state.rot.reshape(-1, 1, 9)
        out[..., kern.RL_FORCE] = self.normal_forces(state, out) if forces else 0.0
        out[..., kern.RL_SPIN_TORQUE] = state.spin_torque
        return out

    def _store_spin_torques(self, state: ParticleState, roll: np.ndarray,
                            cfg: MotionConfig) -> None:
        """`MotionConfig.spin_memory`: each valid particle's pad spin torques at the end of
        a frictional solve, f'(s) of the kernel's torsional friction at the spin s since
        the solve's start (`roll`: its frames, the normal forces as the solve left them)."""
        ok = state.valid
        rl = roll[ok]
        spin = pad_spins(self.model, rl, state.theta[ok], state.rot[ok])
        tau = cfg.spin_friction * rl[..., kern.RL_FORCE]
        eps = cfg.spin_smoothing
        t = np.clip(np.divide(rl[..., kern.RL_SPIN_TORQUE], tau, out=np.zeros_like(tau),
                              where=tau > 0), -kern.SPIN_MEMORY_CLIP, kern.SPIN_MEMORY_CLIP)
        x = spin + eps * t / np.sqrt(1.0 - t * t)
        state.spin_torque[ok] = tau * x / np.sqrt(x * x + eps * eps)

    def normal_forces(self, state: ParticleState, frames: np.ndarray) -> np.ndarray:
        """(P, N) each contact's normal force in the rolling term [N]: k_c times how far the
        pad sphere sinks into the object's local sphere or cylinder (the rolling `frames`'
        centres and axes in O, radii rho), 0 where they part."""
        centre = contact_points(self.model, state.theta, np.zeros_like(state.normals),
                                state.segments)
        local = state.pos[:, None, :] + np.einsum(
            "pab,pnb->pna", state.rot, frames[..., kern.RL_CENTRE:kern.RL_CENTRE + 3])
        axes = np.einsum("pab,pnb->pna", state.rot, frames[..., kern.RL_AXIS:kern.RL_AXIS + 3])
        gap = pad_gaps(centre, local, axes, frames[..., kern.RL_RHO] + self.model.pad_radius)
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
        gravity and the link scaling a per-call config asks for, and the particles' object
        masses and centres of mass."""
        shared = list(self._shared)
        shared[8] = self._lseg_on if cfg.link_scaling else self._lseg_off
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
        follow = u_from is not None and cfg.follow_substeps > 1
        start = state.copy() if follow else None
        status, iters = self._solve(state, u, cfg, config is not None, u_from)
        if follow:
            self._follow(state, start, u, u_from, cfg, status, iters)
        if (u_from is not None and cfg.rolling and not cfg.friction
                and math.isfinite(cfg.cone_return)):
            self._cone_return(state, u, cfg, config is not None, status, iters)
        return status, iters

    def _cone_return(self, state: ParticleState, u: np.ndarray, cfg: MotionConfig,
                     custom: bool, status: np.ndarray, iters: np.ndarray) -> None:
        """`MotionConfig.cone_return`: the valid particles' contact stretch returned onto
        the cone, then a glued settle at `u` (in place; a particle that fails the settle
        takes its status)."""
        if not state.valid.any():
            return
        self.roll(state, surface_normals(self.model, state.theta, state.normals, state.rot),
                  cfg.cone_return, cfg.exact_cylinder)
        was = state.valid.copy()
        st2, it2 = self._solve(state, u, cfg, custom, None)
        iters += it2
        lost = was & ~state.valid
        status[lost] = st2[lost]

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
        if history and cfg.rolling and math.isfinite(cfg.slide_friction):
            # A settle holds its contacts whatever the force. Friction first returns their
            # stretch onto the cone, as the world's contacts would have slid, and lets the
            # grasp find its frictional equilibrium at the old command: after a settle that
            # can be a large move (measured: a joint 11 degrees, 170 iterations), after a
            # frictional solve it takes one or two iterations.
            self.roll(state, surface_normals(self.model, state.theta, state.normals,
                                             state.rot), cfg.slide_friction,
                      cfg.exact_cylinder)
            targets = [np.ascontiguousarray(u_from, dtype=float)] + targets
            budgets = [RELAX_ITERATIONS * int(cfg.max_iter)] + budgets
        for j, target in enumerate(targets):
            before = surface_normals(self.model, state.theta, state.normals, state.rot) \
                if cfg.rolling else None
            # Only friction reads the normal forces (a settle has none).
            roll = (self.rolling_frames(state, before, forces=history and cfg.friction,
                                        exact_cylinder=cfg.exact_cylinder)
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
                if history and cfg.spin_memory and cfg.spin_friction > 0:
                    self._store_spin_torques(state, roll, cfg)
                elif not history:
                    state.spin_torque[state.valid] = 0.0  # the settle's pads spin freely
                self.roll(state, before, cfg.slide_friction if history else math.inf,
                          cfg.exact_cylinder)
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
             slide_friction: float = math.inf, exact_cylinder: bool | None = None) -> None:
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
                             self.config.exact_cylinder if exact_cylinder is None
                             else exact_cylinder, None if rho is None else rho[ok])
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
    frames `roll` (P, N, 21) were taken [rad]: s = n . (omega_O - omega_D), omega_O =
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
        scale = seg / m.segments if cfg.link_scaling else np.ones_like(seg)
        coms = m.link_coms.copy()
        coms[..., 2] *= scale
        com_f = q_f + np.einsum("nkab,nkb->nka", plane_rotation(phi), coms)
        com_p = m.base_pos[:, None, :] + np.einsum("nab,nkb->nka", m.base_rot, com_f)
        e -= np.sum(m.link_masses * scale * (com_p @ g))
    if "object_gravity" in cfg.terms:
        mass, com = motion.object_arrays(state)
        e -= mass[q] * g @ (pos + rot @ com[q])
    if "contacts" in cfg.terms and "rolling" in cfg.terms:
        c = contact_points(m, theta, state.normals[q], state.segments[q])
        d = c - (pos + state.anchors[q] @ rot.T)
        n = roll[:, 3:6]
        tangential = d - np.sum(d * n, axis=-1, keepdims=True) * n
        centre = contact_points(m, theta, np.zeros_like(state.normals[q]), state.segments[q])
        gap = pad_gaps(centre, pos + roll[:, kern.RL_CENTRE:kern.RL_CENTRE + 3] @ rot.T,
                       roll[:, kern.RL_AXIS:kern.RL_AXIS + 3] @ rot.T,
                       roll[:, kern.RL_RHO] + m.pad_radius)
        kc = cfg.contact_stiffness
        e += 0.5 * kc * np.sum(gap**2)
        spin = np.zeros(len(roll))
        if cfg.spin_stiffness > 0 or cfg.spin_friction > 0:
            spin = pad_spins(m, roll[None], theta[None], rot[None])[0]
        e += 0.5 * cfg.spin_stiffness * np.sum(spin**2)
        t2 = np.sum(tangential**2, axis=-1)
        mu, mu_t = cfg.slide_friction, cfg.spin_friction
        if mu_t > 0:
            eps = cfg.spin_smoothing
            tau = mu_t * roll[:, kern.RL_FORCE]
            s0 = np.array([kern.spin_offset(q0, t0, eps)
                           for q0, t0 in zip(roll[:, kern.RL_SPIN_TORQUE], tau, strict=True)])
            e += np.sum(tau * (np.sqrt((spin + s0)**2 + eps**2) - np.sqrt(s0**2 + eps**2)))
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
