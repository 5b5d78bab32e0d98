"""Build the AprilTag 36h11 textures that the objects carry on their bottom faces.

Each PNG is the 8x8-cell marker (black border included) inside a one-cell white border,
upscaled with nearest-neighbour so MuJoCo's texture filtering keeps the cell edges sharp.
The black square is 8/10 of the texture's side: an object's `tag_size` is that black square
(what pose estimation needs), and its texture side is tag_size * 10 / 8.

Usage: python -m vlr.models.make_tags [IDS...]   (default: the ids of every object spec)
"""

from __future__ import annotations

import sys
from pathlib import Path

import cv2
import numpy as np
from vlr.models import ROOT

TAG_DIR = ROOT / "assets" / "tags"
CELLS_BLACK = 8     # marker with its black border, in cells
CELLS_TEXTURE = 10  # plus a one-cell white border
PIXELS_PER_CELL = 32
TEXTURE_PER_BLACK = CELLS_TEXTURE / CELLS_BLACK


def tag_image(tag_id: int, pixels_per_cell: int = PIXELS_PER_CELL) -> np.ndarray:
    """The texture of tag `tag_id` (uint8, grey), white border included."""
    dictionary = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_APRILTAG_36h11)
    marker = cv2.aruco.generateImageMarker(dictionary, int(tag_id), CELLS_BLACK)
    padded = np.full((CELLS_TEXTURE, CELLS_TEXTURE), 255, np.uint8)
    padded[1:-1, 1:-1] = marker
    return np.kron(padded, np.ones((pixels_per_cell, pixels_per_cell), np.uint8))


def tag_path(tag_id: int) -> Path:
    return TAG_DIR / f"tag36h11_{tag_id:03d}.png"


def write_tag(tag_id: int) -> Path:
    TAG_DIR.mkdir(parents=True, exist_ok=True)
    path = tag_path(tag_id)
    rgb = cv2.cvtColor(tag_image(tag_id), cv2.COLOR_GRAY2BGR)
    cv2.imwrite(str(path), rgb)
    return path


def main(argv: list[str]) -> None:
    if argv:
        ids = [int(a) for a in argv]
    else:
        import yaml

        ids = sorted({int(yaml.safe_load(p.read_text())["tag_id"])
                      for p in (ROOT / "objects").glob("*.yaml")})
    for i in ids:
        print(write_tag(i))


if __name__ == "__main__":
    main(sys.argv[1:])
