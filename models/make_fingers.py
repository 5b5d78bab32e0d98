"""Generate the visual meshes (STL) of the original finger and the novel fingers NF1-NF5.

Each link mesh is in its own link frame (vlr/spec.py): the link starts at its joint axis and
runs along +z; +y is the inward (flexion) side. Collision uses the spec's primitives (a box per
link and the spherical pad), so these meshes are for looks and for the 3D view; a user's
finger YAML may point at its own collision meshes too.

The novel fingers differ clearly in shape (the paper's NF1-NF3 have proximal links of 40, 50,
50 mm): NF1 a short straight finger, NF2 a finger with a hooked distal tip, NF3 a wide
paddle-shaped distal link.

Usage: python -m vlr.models.make_fingers
"""

from __future__ import annotations

import numpy as np
import trimesh
from vlr.models import ROOT

MESH_DIR = ROOT / "assets" / "fingers"


def _bar(length: float, width: float, thickness: float, start: float = 0.0) -> trimesh.Trimesh:
    box = trimesh.creation.box(extents=[width, thickness, length])
    box.apply_translation([0, 0, start + length / 2])
    return box


def _knuckle(width: float, radius: float) -> trimesh.Trimesh:
    cyl = trimesh.creation.cylinder(radius=radius, height=width, sections=24)
    cyl.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, [0, 1, 0]))
    return cyl


def proximal_mesh(length: float, width: float) -> trimesh.Trimesh:
    parts = [_bar(length - 0.008, width, 0.012, 0.004), _knuckle(width, 0.007)]
    top = _knuckle(width * 0.8, 0.006)
    top.apply_translation([0, 0, length])
    parts.append(top)
    return trimesh.util.concatenate(parts)


def distal_mesh(kind: str, length: float, width: float, pad_center, pad_radius: float
                ) -> trimesh.Trimesh:
    pad = trimesh.creation.icosphere(subdivisions=3, radius=pad_radius)
    pad.apply_translation(pad_center)
    if kind == "straight":
        body = _bar(length * 0.7, width, 0.012, 0.0)
    elif kind == "hook":
        body = _bar(length * 0.6, width * 0.8, 0.010, 0.0)
        hook = _bar(0.016, width * 0.8, 0.010, 0.0)
        hook.apply_transform(trimesh.transformations.rotation_matrix(0.9, [-1, 0, 0]))
        hook.apply_translation([0, 0, length * 0.6])
        body = trimesh.util.concatenate([body, hook])
    elif kind == "paddle":
        body = _bar(length * 0.75, width * 1.5, 0.008, 0.0)
    else:
        raise ValueError(f"unknown distal shape {kind!r}")
    return trimesh.util.concatenate([body, pad])


# name: (proximal length, distal length, distal kind, pad centre, pad radius, width)
FINGERS = {
    "modelo": (0.062, 0.046, "straight", (0.0, 0.003, 0.032), 0.012, 0.018),
    "nf1": (0.040, 0.040, "straight", (0.0, 0.003, 0.027), 0.012, 0.018),
    "nf2": (0.050, 0.052, "hook", (0.0, 0.004, 0.036), 0.012, 0.016),
    "nf3": (0.050, 0.038, "paddle", (0.0, 0.002, 0.024), 0.012, 0.022),
    "nf4": (0.070, 0.050, "straight", (0.0, 0.003, 0.036), 0.010, 0.018),
    "nf5": (0.055, 0.040, "paddle", (0.0, 0.005, 0.026), 0.015, 0.020),
}


def main() -> None:
    MESH_DIR.mkdir(parents=True, exist_ok=True)
    for name, (lp, ld, kind, pc, pr, w) in FINGERS.items():
        proximal_mesh(lp, w).export(MESH_DIR / f"{name}_proximal.stl")
        distal_mesh(kind, ld, w, pc, pr).export(MESH_DIR / f"{name}_distal.stl")
        print(f"{name}: {MESH_DIR / name}_{{proximal,distal}}.stl")


if __name__ == "__main__":
    main()
