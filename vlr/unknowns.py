"""The unknown physical parameters a filter samples beside the VLR (docs/METHOD.md 3).

An unknown is named by a spec string (`filter.unknowns`): a joint's spring
"stiffness:thumb.distal" [N m/rad], a link's length "length:left.proximal" [m] (a "distal"
length is the pad centre's offset along the distal link, `vlr.kinematics`), the series
tendon stiffness of every finger "tendon" or one finger's "tendon:thumb" [N/m], the object's
"mass" [kg], a coordinate of its centre of mass in O "com:z" [m], and the local curvature of
its surface at every contact "curvature" or at one finger's "curvature:thumb" [1/m]. Known
parameters are not sampled. Each unknown has a uniform prior (low, high) in its SI unit.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from vlr.kinematics import HandModel
from vlr.motion import ObjectParams, ParticleState

__all__ = ["Unknown", "parse_unknown", "check_unknown_set", "unknown_values", "set_unknown",
           "draw_prior", "hold_unknowns", "SPRING_KINDS", "MASS_PRIOR_FACTORS",
           "COM_PRIOR_HALF_WIDTH", "CURVATURE_PRIOR_TOP"]

# The object's unknowns' default priors (ours): its mass 0.25-4x the spec's, as a spring's;
# a coordinate of its centre of mass within 15 mm of the spec's, a third of the apple's
# radius: a user's guess of where an object's weight sits, not a measurement.
MASS_PRIOR_FACTORS = (0.25, 4.0)
COM_PRIOR_HALF_WIDTH = 0.015
COM_AXES = ("x", "y", "z")
# The curvature's (ours): uniform on [0, 2 kappa] about the believed surface's kappa = 1/rho,
# and up to at least 50 /m (a 20 mm radius, the tightest of the test objects' bar the
# screwdriver's handle): a believed plane may be a ball, a believed ball may be flat.
CURVATURE_PRIOR_TOP = 50.0
# The unknowns whose evidence is a deflection that goes as 1/k (a joint's spring, the
# tendon's): the filter's jitter draws them on their logarithms (`vlr.filter`).
SPRING_KINDS = ("stiffness", "tendon")


@dataclass(frozen=True)
class Unknown:
    """One unknown physical parameter sampled as a particle dimension.

    Attributes:
        spec: the spec string, e.g. "stiffness:thumb.distal".
        kind: "stiffness" | "length" | "tendon" | "mass" | "com" | "curvature".
        finger: finger index, or -1 for all fingers ("tendon", "curvature": one value at
            every contact) and the object's "mass" and "com".
        joint: joint index (stiffness, length), the axis of O ("com": 0, 1, 2), else -1.
        prior: (low, high) of the uniform prior [SI units].
    """

    spec: str
    kind: str
    finger: int
    joint: int
    prior: tuple[float, float]


def parse_unknown(spec: str, model: HandModel,
                  prior: tuple[float, float] | None = None,
                  obj: ObjectParams | None = None) -> Unknown:
    """Parse an unknown's spec (module docstring); the object's unknowns need `obj`, the
    object believed.

    Default priors (ours): stiffness 0.25-4x nominal; length 0.5-1.3x nominal (a replaced
    finger may be much shorter: NF1 is 40 mm against 62 mm); tendon stiffness 0.5-2x nominal;
    the object's mass `MASS_PRIOR_FACTORS` times the believed, a coordinate of its centre of
    mass the believed +- `COM_PRIOR_HALF_WIDTH` (the weight's potential, Eq. 9); the local
    curvature at the contacts (the rolling term's rho, docs/METHOD.md 8.2) 0 to the larger of
    twice the believed and `CURVATURE_PRIOR_TOP`. A curvature keeps the believed surface's
    kind: a cylinder's is across its axis, and a believed plane with a curvature is a sphere.
    """
    kind, _, rest = spec.partition(":")
    if kind in ("mass", "com"):
        return _parse_object_unknown(spec, kind, rest, prior, obj)
    if kind == "curvature":
        return _parse_curvature(spec, rest, model, prior, obj)
    if kind == "tendon":
        finger = model.finger_index(rest) if rest else -1
        nominal = model.tendon_stiffness
        lo, hi = prior or (0.5 * nominal, 2.0 * nominal)
        return Unknown(spec, kind, finger, -1, _positive_prior(spec, lo, hi))
    if kind not in ("stiffness", "length") or "." not in rest:
        raise ValueError(f"unknown parameter spec {spec!r}; use stiffness:FINGER.JOINT, "
                         "length:FINGER.JOINT, tendon, tendon:FINGER, mass, com:x|y|z, "
                         "curvature or curvature:FINGER")
    fname, jname = rest.split(".", 1)
    i, k = model.finger_index(fname), model.joint_index(jname)
    if kind == "stiffness":
        nominal = model.stiffness[i, k]
        lo, hi = prior or (0.25 * nominal, 4.0 * nominal)
    else:
        nominal = model.segments[i, k]
        lo, hi = prior or (0.5 * nominal, 1.3 * nominal)
    return Unknown(spec, kind, i, k, _positive_prior(spec, lo, hi))


def _positive_prior(spec: str, lo: float, hi: float) -> tuple[float, float]:
    """A spring rate's or a length's prior: 0 < low <= high, both finite."""
    if not 0 < lo <= hi < math.inf:
        raise ValueError(f"{spec} prior ({lo}, {hi}) must satisfy 0 < low <= high, both "
                         "finite")
    return float(lo), float(hi)


def _parse_object_unknown(spec: str, kind: str, rest: str, prior: tuple[float, float] | None,
                          obj: ObjectParams | None) -> Unknown:
    """The object's "mass" or "com:AXIS" (`parse_unknown`)."""
    if obj is None:
        raise ValueError(f"unknown parameter spec {spec!r}: the object's unknowns need the "
                         "object believed (its spec's mass and centre of mass)")
    if kind == "mass":
        if rest:
            raise ValueError(f"unknown parameter spec {spec!r}: 'mass' is the object's, "
                             "it takes no finger")
        lo, hi = prior or tuple(f * float(obj.mass) for f in MASS_PRIOR_FACTORS)
        if not 0 < lo <= hi < math.inf:
            raise ValueError(f"mass prior ({lo}, {hi}) [kg] must satisfy 0 < low <= high, "
                             "both finite")
        return Unknown(spec, kind, -1, -1, (float(lo), float(hi)))
    if rest not in COM_AXES:
        raise ValueError(f"unknown parameter spec {spec!r}: use com:x, com:y or com:z "
                         "(an axis of the object frame O)")
    axis = COM_AXES.index(rest)
    c = float(obj.com[axis])
    lo, hi = prior or (c - COM_PRIOR_HALF_WIDTH, c + COM_PRIOR_HALF_WIDTH)
    if not -math.inf < lo <= hi < math.inf:
        raise ValueError(f"{spec} prior ({lo}, {hi}) [m] must satisfy low <= high, both finite")
    return Unknown(spec, kind, -1, axis, (float(lo), float(hi)))


def _parse_curvature(spec: str, rest: str, model: HandModel,
                     prior: tuple[float, float] | None, obj: ObjectParams | None) -> Unknown:
    """The object's local "curvature" at every contact or at one finger's (`parse_unknown`)."""
    if obj is None:
        raise ValueError(f"unknown parameter spec {spec!r}: the curvature needs the object "
                         "believed (its surface)")
    finger = model.finger_index(rest) if rest else -1
    lo, hi = prior or (0.0, max(2.0 * obj.surface.curvature, CURVATURE_PRIOR_TOP))
    if not 0 <= lo <= hi < math.inf:
        raise ValueError(f"{spec} prior ({lo}, {hi}) [1/m] must satisfy 0 <= low <= high, "
                         "both finite")
    return Unknown(spec, "curvature", finger, -1, (float(lo), float(hi)))


def check_unknown_set(specs: Sequence[str]) -> None:
    """Refuse a set of unknowns that samples one parameter twice: a spec given twice, or one
    for every finger ("tendon", "curvature") beside one finger's ("tendon:thumb")."""
    seen = set()
    for spec in specs:
        if spec in seen:
            raise ValueError(f"unknown {spec!r} is given twice")
        seen.add(spec)
    for spec in specs:
        kind, _, rest = spec.partition(":")
        if kind in ("tendon", "curvature") and not rest:
            mine = [s for s in specs if s.startswith(kind + ":")]
            if mine:
                raise ValueError(f"unknown {spec!r} (every finger's) and {mine[0]!r} sample "
                                 "the same parameter: give one or the other")


def unknown_values(state: ParticleState, u: Unknown) -> np.ndarray:
    """(P,) the particles' values of unknown `u` [SI units]."""
    if u.kind == "mass":
        return state.object_mass
    if u.kind == "com":
        return state.object_com[:, u.joint]
    if u.kind == "curvature":
        return state.surface_curvature[:, max(u.finger, 0)]
    if u.kind == "stiffness":
        return state.stiffness[:, u.finger, u.joint]
    if u.kind == "length":
        return state.segments[:, u.finger, u.joint]
    return state.tendon[:, max(u.finger, 0)]


def set_unknown(state: ParticleState, u: Unknown, values: np.ndarray) -> None:
    """Write (P,) values of unknown `u` into `state` (in place; the object's unknowns need
    the particles to hold their own object, `hold_unknowns`)."""
    if u.kind == "mass":
        state.object_mass[:] = values
    elif u.kind == "com":
        state.object_com[:, u.joint] = values
    elif u.kind == "curvature":
        if u.finger < 0:
            state.surface_curvature[:, :] = values[:, None]
        else:
            state.surface_curvature[:, u.finger] = values
    elif u.kind == "stiffness":
        state.stiffness[:, u.finger, u.joint] = values
    elif u.kind == "length":
        state.segments[:, u.finger, u.joint] = values
    elif u.finger < 0:
        state.tendon[:, :] = values[:, None]
    else:
        state.tendon[:, u.finger] = values


def draw_prior(rng: np.random.Generator, u: Unknown, n: int) -> np.ndarray:
    """(n,) draws of unknown `u`, uniform over its prior (low, high)."""
    lo, hi = u.prior
    return rng.uniform(lo, hi, n)


def hold_unknowns(state: ParticleState, unknowns: Sequence[Unknown],
                  obj: ObjectParams) -> None:
    """With the object's unknowns, each particle carries its own object (mass and centre of
    mass, or surface curvature), starting from `obj`'s."""
    if any(u.kind in ("mass", "com") for u in unknowns):
        state.hold_object(obj)
    if any(u.kind == "curvature" for u in unknowns):
        state.hold_surface(obj)
