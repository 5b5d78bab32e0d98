"""Motion model Gamma (Eq. 4) by energy minimisation (Eq. 6-9), batched over particles.

Formulation (docs/METHOD.md 8.1-8.2; the choice is ours):

* State of one particle: physical joint angles theta (N, K); each finger's contact point on
  its pad sphere (pad_center + pad_radius * n, n in the distal frame D); the contact points
  in the object frame O ("anchors"), which hold the POM to the contact set (Eq. 1, 8) and,
  by how far each sits from its pad's contact, the contact's forces; the object pose
  (p, R) = the POM pose in the palm frame; and the equilibrium's tangent dx/du (`tangent`),
  the first guess of the next action.
* Unknowns of a solve: theta and the object pose (6 dof). Eq. 8 (rigid grasp) is a stiff
  compliant constraint rather than a hard one: the side fingers move only in their planes,
  so hard contact equalities are rank-deficient (docs/METHOD.md 8.2).
* Energy (Eq. 9's objective, compliant form): springs 1/2 k (theta - rest)^2 (Eq. 6); series
  tendon 1/2 k_t max(0, u - s(theta))^2 with s = sum r_k (theta_k - lo_k) (Eq. 7 with
  compliance); joint stops as stiff one-sided penalties; gravity of the object and of the
  finger links under a configurable gravity vector in the palm frame; and the contacts.
* Contacts (`vlr.kernels.contacts`): rolling (the default) or pinned. Rolling, each pad
  sphere touches the object's local surface primitive (a sphere, a cylinder or a plane,
  `vlr.surface`); the contact travels over both surfaces and its slip over the action is
  measured exactly to third order in the action (the midpoint rule), so one solve makes an
  action; the pads' Coulomb friction (`MotionConfig.friction`) bounds the tangential force
  by mu times the normal force (a smoothed maximum dissipation potential, the normal force
  held at its prediction). Pinned, the pad's contact point is glued to its anchor.
* Solver (`vlr.kernels.solve`): primal-dual Newton on the exact Hessian (arrow structure,
  Schur complement) from the stored tangent's prediction, Levenberg-Marquardt with a line
  search where Newton's steps grow. A particle whose solve fails (non-finite, no
  convergence, or a jump larger than an action can cause) is flagged in `status`; the
  filter gives it zero weight.

The kernels take named records (`vlr.kernels.records`) built here; `vlr.kernels.reference`
is a plain NumPy energy the tests check them against.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np

from vlr.kernels import records as rec
from vlr.kernels import solve as ksolve
from vlr.kernels.contacts import STICK_ZONE
from vlr.kernels.frames import object_points, palm_points
from vlr.kernels.resample import gather_sorted
from vlr.kinematics import HandModel, contact_in_distal, contact_points
from vlr.spec import ObjectSpec
from vlr.surface import FLAT_CURVATURE, LocalSurface, contact_radii

__all__ = [
    "TERMS",
    "STATUS",
    "MotionConfig",
    "ObjectParams",
    "ParticleState",
    "MotionModel",
    "rotvec_to_matrix",
    "contacts_in_distal",
]

# Energy terms by name. "contacts" is Eq. 8 (rigid grasp): rolling or pinned.
TERMS = ("springs", "tendon", "limits", "link_gravity", "object_gravity", "contacts")

PREDICT = True

STATUS = {rec.OK: "ok", rec.NONFINITE: "non-finite", rec.NO_CONVERGENCE: "no convergence",
          rec.JUMP: "jump", rec.INACTIVE: "inactive"}


@dataclass(frozen=True)
class MotionConfig:
    """Settings of the motion model (units in brackets).

    Attributes:
        terms: energy terms to include (`TERMS`).
        rolling: rolling contacts (module docstring) instead of pinned ones; needs
            "contacts" among the terms.
        friction: the pads' Coulomb friction coefficient mu with rolling contacts: a
            contact's tangential force is at most mu times its normal force, beyond which
            it slides. A sliding solve that leaves the jump limits stops there (a slide
            running away) and is not followed up in finer steps; the filter's settles are
            glued, and at each update every particle's stretch is let go (`vlr.filter`,
            docs/DECISIONS.md, the internal forces). The sim's pads have mu 1; the sim's
            filter holds its hypotheses' grasps with a margin, mu 2 (its default). None: the
            contacts roll and never slide.
        spin_friction: the pads' torsional friction coefficient mu_t [m] with rolling
            contacts: a pad sticks about its contact normal until the torque reaches mu_t
            times its normal force, then spins (`vlr.kernels.contacts.spin`); over an
            action only, its limit held at the predicted normal force. 0: pads spin freely.
        follow_substeps: a particle whose solve of an action fails by a jump or no
            convergence is solved again from its start in this many equal steps, each held
            to the jump limits: a large but continuous move is followed, a jump to another
            branch still fails. 0 turns it off; a settle never follows. The synthetic world
            calls a move a snap by the same test (`vlr.synthetic`).
        contact_stiffness: the contacts' stiffness k_c [N/m], the gap's and the pads'
            stick's: 3e5 N/m leaves 33 um of penetration at 10 N. The sim's pads are
            softer still (about 2e4); at 1e6 the model's actions moved the object less than
            the sim's do (docs/DECISIONS.md).
        limit_stiffness: one-sided joint-stop penalty [N m/rad]; 100 lets a spring preload
            of ~0.02 N m sink 0.01 degree into a stop.
        gravity: gravity vector in the palm frame [m/s^2]; default palm up.
        max_iter: energy evaluations (each with its Newton step) per solve.
        tol_theta: convergence: largest angle step [rad] (also the rotation's). The step
            under it is taken and ends the solve; so does a step a tenth of the one before
            when the next would be under a tenth of the tolerance (Newton's quadratic
            convergence). 2e-4 rad lands the POM poses the likelihood weighs some 50 times
            under its finest scales (0.2 mm, 0.4 degree; docs/DECISIONS.md).
        tol_pos: convergence: object position step [m]; 20 um, with tol_theta.
        max_step_theta: step limit per Newton iteration [rad].
        max_step_pos: step limit per Newton iteration [m].
        jump_theta: a solve that moves any joint more than this is another branch [rad].
        jump_pos: ... or moves the POM more than this [m].
        mu0: Levenberg-Marquardt's initial damping, where Newton's steps grow (relative to
            the Hessian's diagonal).
    """

    terms: tuple[str, ...] = ("springs", "tendon", "limits", "link_gravity",
                              "object_gravity", "contacts")
    rolling: bool = True
    friction: float | None = None
    spin_friction: float = 0.0
    follow_substeps: int = 16
    contact_stiffness: float = 3e5
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
        unknown = set(self.terms) - set(TERMS)
        if unknown:
            raise ValueError(f"unknown energy terms {sorted(unknown)}; known: {sorted(TERMS)}"
                             " (rolling contacts: rolling=True)")
        if self.rolling and "contacts" not in self.terms:
            raise ValueError("rolling moves the contacts of the 'contacts' term: it needs "
                             "'contacts' too")
        if not (isinstance(self.follow_substeps, int) and self.follow_substeps >= 0):
            raise ValueError(f"follow_substeps {self.follow_substeps!r} must be an integer "
                             ">= 0")
        if self.friction is not None and not (isinstance(self.friction, int | float)
                                              and math.isfinite(self.friction)
                                              and self.friction > 0):
            raise ValueError(f"friction {self.friction!r} must be > 0 (null: no sliding)")
        if not (isinstance(self.spin_friction, int | float)
                and math.isfinite(self.spin_friction) and self.spin_friction >= 0):
            raise ValueError(f"spin_friction {self.spin_friction!r} m must be >= 0")
        for name in ("contact_stiffness", "limit_stiffness", "tol_theta", "tol_pos",
                     "max_step_theta", "max_step_pos", "jump_theta", "jump_pos", "mu0"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"{name} {v!r} must be finite and > 0")
        if not (isinstance(self.max_iter, int) and self.max_iter >= 1):
            raise ValueError(f"max_iter {self.max_iter!r} must be an integer >= 1")

    def record(self) -> rec.Settings:
        """The kernels' settings record (`vlr.kernels.records.Settings`)."""
        t = set(self.terms)
        return rec.Settings(
            kc=float(self.contact_stiffness), klim=float(self.limit_stiffness),
            tol_theta=float(self.tol_theta), tol_pos=float(self.tol_pos),
            max_step_theta=float(self.max_step_theta), max_step_pos=float(self.max_step_pos),
            jump_theta=float(self.jump_theta), jump_pos=float(self.jump_pos),
            mu0=float(self.mu0),
            friction=math.inf if self.friction is None else float(self.friction),
            spin=float(self.spin_friction) if self.rolling else 0.0,
            max_iter=int(self.max_iter),
            follow=int(self.follow_substeps), springs="springs" in t, tendon="tendon" in t,
            limits="limits" in t, link_gravity="link_gravity" in t,
            object_gravity="object_gravity" in t, contacts="contacts" in t,
            rolling=bool(self.rolling))


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
        anchors: (P, N, 3) contact points in the object frame O [m] (the POM's anchor);
            how far each sits from its pad's contact carries the contact's forces.
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
        tangent: (P, rows, N) each particle's equilibrium derivative by the commands, the
            next action's first guess (`vlr.kernels.records.tangent_rows`); None: none yet.
        spin: (P, N) each pad's spin carried from its last action [rad], the torsional
            friction's stick (`MotionConfig.spin_friction`); None: none yet.
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
    tangent: np.ndarray | None = None
    spin: np.ndarray | None = None

    @property
    def n(self) -> int:
        return self.theta.shape[0]

    def take(self, idx: np.ndarray) -> ParticleState:
        """A new state of the particles `idx` (resampling), arrays copied and contiguous."""
        return ParticleState(**{f.name: _map(getattr(self, f.name),
                                             lambda a: np.ascontiguousarray(a[idx]))
                                for f in fields(self)})

    def resample(self, idx: np.ndarray) -> None:
        """Replace each particle by the particle `idx` names, in place; idx (P,) sorted, as
        systematic resampling gives it (`vlr.kernels.resample`: no allocation). An array
        that is not this state's own (a view) is copied as `take` does."""
        idx = np.asarray(idx, dtype=np.int64)
        if len(idx) != self.n or (len(idx) > 1 and np.any(idx[1:] < idx[:-1])):
            raise ValueError(f"resample: needs {self.n} sorted indexes, got {len(idx)}"
                             f"{'' if len(idx) != self.n else ' unsorted'}")
        for f in fields(self):
            a = getattr(self, f.name)
            if a is None:
                continue
            if a.flags.owndata and a.flags.c_contiguous and a.flags.writeable:
                gather_sorted(a.reshape(self.n, -1), idx)
            else:
                setattr(self, f.name, np.ascontiguousarray(a[idx]))

    def put(self, idx: np.ndarray, other: ParticleState) -> None:
        """Write the particles of `other` into the places `idx` of this state (in place)."""
        for f in fields(self):
            mine, theirs = getattr(self, f.name), getattr(other, f.name)
            if f.name in ("tangent", "spin") and (mine is None) != (theirs is None):
                if theirs is None:
                    mine[idx] = 0.0
                    continue
                mine = np.zeros((self.n,) + theirs.shape[1:])
                setattr(self, f.name, mine)
            elif (mine is None) != (theirs is None):
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

        `residuals` r (P, N, 3) [m] (`contact_residuals`, palm frame) keep each contact's
        stretch, i.e. the grasp forces; without them (r = 0) the particle loses its squeeze
        and is no longer at equilibrium: measured on the synthetic world, a particle AT the
        truth then moved by 0.5 degrees when settled again, every iteration."""
        c = self.contacts(model)
        if residuals is not None:
            c += residuals
        self.anchors = object_points(c, self.pos, self.rot)

    def contact_residuals(self, model: HandModel) -> np.ndarray:
        """(P, N, 3) anchor minus contact point in the palm frame, R a_i + p - p_i [m]: the
        stretch of the contacts (Eq. 8 as a stiff spring), k_c times it the force."""
        return palm_points(self.anchors, self.pos, self.rot) - self.contacts(model)


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


def hand_record(model: HandModel, gravity) -> rec.Hand:
    """The kernels' record of the hand's constants (`vlr.kernels.records.Hand`) under
    `gravity` [m/s^2] in the palm frame."""
    return model.kernel_record._replace(gravity=np.asarray(gravity, dtype=float))


def surface_record(surface: LocalSurface) -> rec.Surface:
    """The kernels' record of the object's local surface (`vlr.kernels.records.Surface`)."""
    kind = {"plane": rec.SURF_PLANE, "sphere": rec.SURF_SPHERE,
            "cylinder": rec.SURF_CYLINDER}[surface.kind]
    return rec.Surface(kind=kind, radius=float(surface.kernel_radius),
                       axis=np.asarray(surface.axis, dtype=float),
                       flat_radius=1.0 / FLAT_CURVATURE)


class MotionModel:
    """Gamma: (state, u) -> equilibrium state (Eq. 4, 9), batched over particles.

    Args:
        model: the hand; obj: the object (its mass, centre of mass and local surface).
        config: the model's settings.
    """

    def __init__(self, model: HandModel, obj: ObjectParams,
                 config: MotionConfig | None = None) -> None:
        if model.n_joints != rec.JOINTS:
            raise ValueError(f"the motion kernels model fingers of {rec.JOINTS} joints "
                             f"(vlr.kernels.records.JOINTS); this hand's have "
                             f"{model.n_joints}")
        self.model = model
        self.obj = obj
        self.config = config or MotionConfig()
        # The particles of the last solve that needed the follow-up of a large move.
        self.followed = np.zeros(0, dtype=bool)
        self._hand = hand_record(model, self.config.gravity)
        self._surface = surface_record(obj.surface)
        self._settings = self.config.record()
        self._own: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}

    def contact_rho(self, state: ParticleState) -> np.ndarray | None:
        """(P, N) each contact's radius of curvature [m] when the particles carry their own
        curvature (`ParticleState.surface_curvature`), else None: this model's surface."""
        if state.surface_curvature is None:
            return None
        return contact_radii(state.surface_curvature)

    def object_arrays(self, state: ParticleState) -> tuple[np.ndarray, np.ndarray]:
        """(P,) object masses [kg] and (P, 3) centres of mass in O [m]: the particles' own
        (an unknown object), else this model's object for every particle."""
        mass, com, _ = self._shared(state.n)
        if state.object_mass is not None:
            mass = np.ascontiguousarray(state.object_mass, dtype=float)
        if state.object_com is not None:
            com = np.ascontiguousarray(state.object_com, dtype=float)
        return mass, com

    def _shared(self, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """This model's object and surface for n particles, built once per count."""
        if n not in self._own:
            nf = self.model.n_fingers
            self._own = {n: (np.full(n, float(self.obj.mass)),
                             np.tile(np.asarray(self.obj.com, dtype=float), (n, 1)),
                             np.full((n, nf), self.obj.surface.kernel_radius))}
        return self._own[n]

    def particles(self, state: ParticleState) -> rec.Particles:
        """The kernels' record of `state` (its arrays, not copies: solves write into it);
        a state without a tangent or a carried spin gets one of zeros."""
        mass, com = self.object_arrays(state)
        rho = self.contact_rho(state)
        if rho is None:
            rho = self._shared(state.n)[2]
        if state.tangent is None or state.tangent.shape[0] != state.n:
            state.tangent = rec.empty_tangent(state.n, self.model.n_fingers,
                                              self.model.n_joints)
        if state.spin is None or state.spin.shape[0] != state.n:
            state.spin = np.zeros((state.n, self.model.n_fingers))
        return rec.Particles(theta=state.theta, seg=state.segments, nrm=state.normals,
                             anc=state.anchors, pos=state.pos, rot=state.rot,
                             stiff=state.stiffness, kt=state.tendon, mass=mass, com=com,
                             rho=np.ascontiguousarray(rho, dtype=float),
                             tangent=state.tangent, spin=state.spin, valid=state.valid)

    def solve(self, state: ParticleState, u: np.ndarray, config: MotionConfig | None = None,
              u_from: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Move every valid particle to its equilibrium at tendon commands `u` (Eq. 9).

        From each particle's current configuration (and its stored tangent's prediction),
        in place: theta, pos, rot, the contacts (normals and anchors) and the tangent;
        particles whose solve fails are marked invalid (state.valid = False).

        Args:
            state: particles; arrays must be C-contiguous float64.
            u: (N,) tendon commands [m].
            config: optional override (e.g. looser jump limits for the initial settle).
            u_from: (N,) the commands the particles are at equilibrium under: the action
                u_from -> u. None: a settle, the particles brought to equilibrium at u from
                where they are.
        Returns:
            status (P,) int8 codes (`STATUS`), evaluations (P,) int32: the energy
            evaluations of each solve, each with its Newton step.
        """
        cfg = self._settings if config is None else config.record()
        if u_from is None:
            # A settle has no path to follow: its follow-up would only be the same solve
            # again with more evaluations.
            cfg = cfg._replace(follow=0)
        if config is not None and tuple(config.gravity) != tuple(self.config.gravity):
            hand = hand_record(self.model, config.gravity)
        else:
            hand = self._hand
        n = self.model.n_fingers
        u1 = np.ascontiguousarray(u, dtype=float).reshape(n)
        u0 = u1 if u_from is None else np.ascontiguousarray(u_from, dtype=float).reshape(n)
        status = np.empty(state.n, dtype=np.int8)
        evals = np.zeros(state.n, dtype=np.int32)
        self.followed = np.zeros(state.n, dtype=np.bool_)
        ksolve.solve_batch(self.particles(state), hand, self._surface, cfg, u0, u1,
                           u_from is not None and PREDICT,
                           rec.Outcome(status, evals, self.followed))
        return status, evals

    def evaluate(self, state: ParticleState, q: int, u: np.ndarray, theta=None, pos=None,
                 rot=None, multipliers: np.ndarray | str | None = None
                 ) -> tuple[float, np.ndarray, np.ndarray]:
        """Energy [J], gradient (N K + 6,) and dense Hessian of particle q at (theta, pos,
        rot) (default: where it is), its solve started where it is, in the solver's
        coordinates (theta, dp, dw). `multipliers`: the contacts' forces the Hessian's
        curvature terms weigh, (N, 4) (gap, tangential force); None: the start's (as a
        solve's first step); "primal": the forces at (theta, pos, rot) themselves, which
        makes the Hessian the energy's own. For tests and diagnostics."""
        nf = self.model.n_fingers
        th = np.ascontiguousarray(state.theta[q] if theta is None else theta, dtype=float)
        p = np.ascontiguousarray(state.pos[q] if pos is None else pos, dtype=float)
        R = np.ascontiguousarray(state.rot[q] if rot is None else rot, dtype=float)
        u = np.asarray(u, dtype=float)
        if isinstance(multipliers, str):
            lam = self.contact_forces(state, q, u, th, p, R)
        elif multipliers is None:
            lam = np.full((nf, rec.N_LAM), np.nan)
        else:
            lam = np.asarray(multipliers, dtype=float)
        e, gA, gC, A, B, C, _ = self._evaluate(state, q, u, th, p, R, lam)
        nk = self.model.n_joints
        n = nf * nk
        H = np.zeros((n + 6, n + 6))
        for i in range(nf):
            sl = slice(i * nk, (i + 1) * nk)
            H[sl, sl] = A[i]
            H[sl, n:] = B[i]
            H[n:, sl] = B[i].T
        H[n:, n:] = C
        return float(e), np.concatenate([gA.ravel(), gC]), H

    def _evaluate(self, state, q, u, th, p, R, lam):
        e, sc = ksolve.evaluate_at(q, self.particles(state), self.kernel_model(),
                                   rec.Pose(th, p, R), u, lam)
        return e, sc.gA, sc.gC, sc.A, sc.B, sc.C, sc.vals

    def kernel_model(self) -> rec.Model:
        """The kernels' record of the hand, the object's surface and the solver's settings
        (`vlr.kernels.records.Model`)."""
        return rec.Model(self._hand, self._surface, self._settings)

    def contact_forces(self, state: ParticleState, q: int, u: np.ndarray, th: np.ndarray,
                       p: np.ndarray, R: np.ndarray) -> np.ndarray:
        """Particle q's contacts' forces at (th, p, R), (N, 4) [N]: k_c g and the stretch's
        force (the stick's k_c z, or the pads' friction's at the start's normal force). For
        tests and diagnostics."""
        cfg = self.config
        kc = cfg.contact_stiffness
        nan = np.full((self.model.n_fingers, rec.N_LAM), np.nan)
        vals = self._evaluate(state, q, u, th, p, R, nan)[-1]
        lam = kc * vals
        if cfg.rolling and cfg.friction is not None:
            start = self._evaluate(state, q, u, state.theta[q], state.pos[q], state.rot[q],
                                   nan)[-1]
            for i in range(self.model.n_fingers):
                cap = cfg.friction * max(0.0, -kc * start[i, 0])
                z = vals[i, 1:]
                if cap > 1e-9:
                    eps = max(cap / kc, STICK_ZONE)
                    lam[i, 1:] = cap * z / math.sqrt(z @ z + eps * eps)
                else:
                    lam[i, 1:] = 0.0
        return lam

    def tensions(self, state: ParticleState, u: np.ndarray) -> np.ndarray:
        """Tendon tensions k_t max(0, u - s(theta)) [N], (P, N) (Eq. 7, compliant)."""
        s = self.model.tendon_takeup(state.theta)
        return state.tendon * np.maximum(0.0, np.asarray(u) - s)


def contacts_in_distal(motion: MotionModel, state: ParticleState) -> np.ndarray:
    """(P, N, 3) contact points in each finger's distal frame D [m]."""
    return contact_in_distal(motion.model, state.normals, state.segments)
