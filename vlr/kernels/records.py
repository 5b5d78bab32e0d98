"""The named records the motion kernels take, and the layout of their small arrays.

Numba compiles a namedtuple of arrays and numbers as one typed argument, so a kernel reads
`hand.pad_r[i]` or `cfg.kc` instead of a position in a list of 40 arguments. Built once per
motion model (`Hand`, `Surface`, `Settings`) or per call (`Particles`) by `vlr.motion`.
"""

from __future__ import annotations

from collections import namedtuple

import numpy as np

# The hand's constants (N fingers, K joints): base_pos (N, 3) and base_rot (N, 3, 3) place
# each finger frame F in the palm; radii (N, K) the tendon's pulleys (Eq. 7); rest, lo, hi
# (N, K) the springs' rest angles and the stops; link_mass (N, K), link_com (N, K, 3);
# pad_xy (N, 2) the pad centre's x and y in D (its z is the particle's last segment);
# pad_r (N,) the pad sphere's radius; gravity (3,) in the palm frame [m/s^2].
Hand = namedtuple("Hand", "base_pos base_rot radii rest lo hi link_mass link_com pad_xy "
                          "pad_r gravity")

# The particles (P of them), the arrays of `vlr.motion.ParticleState`: theta (P, N, K),
# seg (P, N, K), nrm (P, N, 3) the pad normals in D, anc (P, N, 3) the anchors in O,
# pos (P, 3), rot (P, 3, 3), stiff (P, N, K), kt (P, N), mass (P,), com (P, 3), rho (P, N)
# each contact's radius of curvature, tangent (P, N_TANGENT, N) the equilibrium's
# derivative by the commands (`TANGENT_*`), spin (P, N) each pad's carried spin [rad] (the
# torsional friction's stick, `vlr.kernels.contacts.spin`), valid (P,) bool.
Particles = namedtuple("Particles", "theta seg nrm anc pos rot stiff kt mass com rho "
                                    "tangent spin valid")

# A particle's iterate in a solve: the joint angles th (N, K), the POM's position p (3,)
# and rotation R (3, 3); views of `Particles` at one index, or a trial point in `Scratch`.
Pose = namedtuple("Pose", "th p R")

# What a particle's Newton steps hold fixed, views of `Particles` at one index: seg, nrm,
# anc, stiff, kt, mass, com, rho.
Body = namedtuple("Body", "seg nrm anc stiff kt mass com rho")

# The object's local surface (`vlr.surface.LocalSurface`): kind (SURF_*), radius [m], axis
# (3,) a cylinder's in O, flat_radius: a contact radius at or above it is a plane.
Surface = namedtuple("Surface", "kind radius axis flat_radius")

# The solver's settings (`vlr.motion.MotionConfig`), numbers only.
Settings = namedtuple("Settings", "kc klim tol_theta tol_pos max_step_theta max_step_pos "
                                  "jump_theta jump_pos mu0 friction spin max_iter follow "
                                  "springs tendon limits link_gravity object_gravity "
                                  "contacts rolling")

# What every particle's solve reads: the hand's constants (`Hand`), the object's surface
# (`Surface`) and the solver's settings (`Settings`).
Model = namedtuple("Model", "hand surface cfg")

# What a batch of solves reports per particle (`vlr.kernels.solve.solve_batch`): status
# (P,) int8 (OK ... INACTIVE), evals (P,) int32 the energy evaluations, followed (P,) bool
# the follow-up in sub-steps was tried.
Outcome = namedtuple("Outcome", "status evals followed")

# One thread's buffers for a particle's solve (`vlr.kernels.solve.make_scratch`): the
# arrow system's gradient gA (N, K), gC (6,) and Hessian blocks A, B, C with their
# factors (Ainv, X, S, La) and the step (dth, dc, y); the finger chain's sines, cosines
# and joint positions (sphi, cphi, qy, qz, `chain.finger_chain`); the contacts' work
# arrays (jk ... MD); their constraints and rows (vals, jac); the multipliers (lam, lam0
# at the start) and the solve's context (ctx, `CTX_*`); the start x0 (th0, p0, R0), a
# trial point (tht, pt, Rt), a saved state for the follow-up (th_s ... R_s) and the
# commands (u_from, u_to; u_b the solve's, du its change).
Scratch = namedtuple("Scratch", "gA gC A B C Ainv X S La y dth dc sphi cphi qy qz jk dm jz t3 gj "
                                "KO RD RD0 MO MD vals jac lam lam0 ctx th0 p0 R0 Rt tht pt "
                                "th_s nrm_s anc_s p_s R_s u_from u_to u_b du")

# The joints of a finger in the motion kernels: the Model O's two, every `FingerSpec`'s. A
# count known when the kernels compile lets LLVM unroll their loops over a finger's joints
# (and the 8 columns of a finger's block); read from the arrays' shapes it cost 18% of an
# energy evaluation and 26% of an arrow solve (docs/DECISIONS.md). The fingers' count stays
# the arrays'.
JOINTS = 2

SURF_PLANE, SURF_SPHERE, SURF_CYLINDER = 0, 1, 2

# Solver status codes (per particle).
OK, NONFINITE, NO_CONVERGENCE, JUMP, INACTIVE = 0, 1, 2, 3, 4

# A solve's context, per contact (N, N_CTX): what the solve holds fixed from its start x0.
# The local primitive (CTX_KIND: SURF_*), its centre or axis point o in O (3), a cylinder's
# axis or a plane's normal in O (3), its radius rho; the contact on the object at x0, c_O0 in
# O (3), and on the pad, c_D0 in D (3); the finger's summed angle phi0; the contact normal
# at x0 in the palm frame n0 (3), whose tangent plane the slip is measured in; the
# tangential stretch at x0 in O, t0 (3), carried by the object's turn; the normal force
# the friction's limit is held at, lambda_n (inf: none); the pad's torsional friction's
# limit mu_t lambda_n [N m] (0: none); the pad's spin carried from the last solve [rad].
(CTX_KIND, CTX_O, CTX_DIR, CTX_RHO, CTX_CO0, CTX_CD0, CTX_PHI0, CTX_N0, CTX_T0,
 CTX_CAP, CTX_SPIN, CTX_PSI0) = (0, 1, 4, 7, 8, 11, 14, 15, 18, 21, 22, 23)
N_CTX = 24

# The multipliers of one contact (N, N_LAM): the gap's force sigma = k_c g (negative when
# the pad presses) and the tangential force (3, palm).
LAM_N, LAM_T, N_LAM = 0, 1, 4

# Rows of a particle's tangent (N_TANGENT, N): d x / d u (the N K joint angles, the object's
# position (3) and rotation vector (3)), then d lambda / d u per contact (N_LAM each).
TANGENT_X = 0


def tangent_rows(n_fingers: int, n_joints: int) -> int:
    """Rows of a particle's stored tangent (`Particles.tangent`)."""
    return n_fingers * n_joints + 6 + n_fingers * N_LAM


def empty_tangent(n: int, n_fingers: int, n_joints: int) -> np.ndarray:
    """(n, rows, N) zeros: no tangent yet, so the first solve starts from x0."""
    return np.zeros((n, tangent_rows(n_fingers, n_joints), n_fingers))
