"""Numba kernels of the motion model (Eq. 6-9), internal to `vlr.motion`.

* `records`: the named records every kernel takes (the hand's constants, the particles, the
  solver's settings, the local surface, scratch);
* `chain`: a finger's planar chain (Eq. 2) and the energy terms of the hand alone (Eq. 6, 7,
  the joint stops, gravity);
* `contacts`: the contacts (Eq. 8): pinned, or rolling exactly within one solve with the
  pads' Coulomb friction;
* `arrow`: the Newton system's arrow-structured linear algebra;
* `solve`: one action per particle by primal-dual Newton from the stored tangent, and the
  batched entry points.
"""
