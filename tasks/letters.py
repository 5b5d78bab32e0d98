"""A single-stroke block font for the handwriting task: S, C, I, E, N (and a few more).

Each letter is one polyline in a unit box (x right, y up; height 1, width 0.7) that the POM
traces without lifting; a stroke may run back over itself (E's middle bar). Waypoints are
the polyline's corners plus points inserted so that no two consecutive waypoints are further
apart than a given spacing (docs/METHOD.md 6: "waypoints of S, C, I, E, N, C, E").
"""

from __future__ import annotations

import numpy as np

__all__ = ["STROKES", "WIDTH", "letter_waypoints"]

WIDTH = 0.7  # letter width / height


def _arc(cx: float, cy: float, rx: float, ry: float, a0: float, a1: float,
         n: int) -> list[tuple[float, float]]:
    a = np.radians(np.linspace(a0, a1, n))
    return [(cx + rx * np.cos(t), cy + ry * np.sin(t)) for t in a]


# One polyline per letter, unit height, width WIDTH (x in [0, 0.7], y in [0, 1]).
STROKES: dict[str, list[tuple[float, float]]] = {
    "S": (_arc(0.35, 0.75, 0.35, 0.25, 20, 270, 6)
          + _arc(0.35, 0.25, 0.35, 0.25, 90, -160, 6)[1:]),
    "C": _arc(0.4, 0.5, 0.35, 0.5, 50, 310, 7),
    "I": [(0.35, 1.0), (0.35, 0.5), (0.35, 0.0)],
    "E": [(0.7, 1.0), (0.0, 1.0), (0.0, 0.5), (0.55, 0.5), (0.0, 0.5), (0.0, 0.0),
          (0.7, 0.0)],
    "N": [(0.0, 0.0), (0.0, 1.0), (0.7, 0.0), (0.7, 1.0)],
    "L": [(0.0, 1.0), (0.0, 0.0), (0.7, 0.0)],
    "O": _arc(0.35, 0.5, 0.35, 0.5, 90, 450, 9),
    "V": [(0.0, 1.0), (0.35, 0.0), (0.7, 1.0)],
}


def letter_waypoints(letter: str, height: float, spacing: float) -> np.ndarray:
    """Waypoints (M, 2) of `letter` scaled to `height` [m], centred on the origin, with
    points inserted so that consecutive waypoints are at most `spacing` [m] apart."""
    key = letter.upper()
    if key not in STROKES:
        raise ValueError(f"letter {letter!r} is not in the font; letters: "
                         f"{''.join(sorted(STROKES))}")
    pts = (np.array(STROKES[key], dtype=float) - [WIDTH / 2, 0.5]) * height
    out = [pts[0]]
    for a, b in zip(pts[:-1], pts[1:], strict=True):
        n = max(1, int(np.ceil(np.linalg.norm(b - a) / spacing - 1e-9)))
        out += [a + (b - a) * (k / n) for k in range(1, n + 1)]
    return np.array(out)
