"""Model data: MJCF, finger/object specs, meshes and tag textures (see models/README.md).

This package holds data only; `ROOT` is its folder.
"""

from pathlib import Path

ROOT = Path(__file__).resolve().parent
