"""Random exploratory tendon actions (docs/METHOD.md 3, 8.1), sized by the tension they cause.

At a series stiffness of 20 N/mm a 0.2-0.4 mm change moves a tendon's tension by 4-8 N, the
size that a study found informative without dropping the object; 1-2 mm actions dropped it.
Commands stay within a band around the grasp command, so a long random walk neither
slackens a tendon nor crushes the object: a step that would leave the band is mirrored.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from vlr.identify import LoopConfig


@dataclass(frozen=True)
class ExplorationRange:
    """Magnitudes of random tendon changes [m] and the band around the grasp command [m]."""

    low: float = 0.0002
    high: float = 0.0004
    band: float = 0.0004

    def __post_init__(self) -> None:
        if not (0 <= self.low <= self.high) or not np.isfinite(self.high):
            raise ValueError(f"exploration range ({self.low}, {self.high}) m needs "
                             "0 <= low <= high")
        if self.band < self.high:
            raise ValueError(f"exploration band {self.band} m must be >= the largest step "
                             f"{self.high} m")

    @classmethod
    def for_stiffness(cls, tendon_stiffness: float, tension_low: float = 4.0,
                      tension_high: float = 8.0) -> ExplorationRange:
        """The range whose steps change a taut tendon's tension by tension_low..high [N]."""
        low, high = tension_low / tendon_stiffness, tension_high / tendon_stiffness
        return cls(low=low, high=high, band=high)


def random_action(rng: np.random.Generator, commands: np.ndarray, center: np.ndarray,
                  rng_range: ExplorationRange) -> np.ndarray:
    """A random tendon change: each finger |delta| uniform in [low, high], random sign,
    mirrored when it would leave `center` +- band."""
    n = len(commands)
    mag = rng.uniform(rng_range.low, rng_range.high, n)
    sign = rng.choice([-1.0, 1.0], n)
    delta = sign * mag
    out = np.abs(commands + delta - center) > rng_range.band
    delta[out] = -delta[out]
    return delta


@dataclass
class ActionStream:
    """The exploratory actions of one trial, as `vlr identify` makes them: a generator
    seeded by the trial's `seed + 1` (the filter draws from `seed`), the magnitudes and the
    band of the loop's settings (`loop.action_range_mm`, `loop.action_band_mm`), the band
    about the grasp command. `vlr crb`, `vlr gap` and `vlr bench` take their actions from
    this too, so that one seed means the same actions in each."""

    rng: np.random.Generator
    explore: ExplorationRange
    center: np.ndarray

    @classmethod
    def of_trial(cls, loop: LoopConfig, seed: int, grasp_commands: np.ndarray) -> ActionStream:
        """The stream of the trial with these loop settings and seed, grasped at
        `grasp_commands` [m]."""
        lo, hi = (v * 1e-3 for v in loop.action_range_mm)
        return cls(np.random.default_rng(seed + 1),
                   ExplorationRange(low=lo, high=hi, band=max(loop.action_band_mm * 1e-3, hi)),
                   np.array(grasp_commands, dtype=float))

    def random(self, commands: np.ndarray) -> np.ndarray:
        """The next random action from `commands` (`random_action`)."""
        return random_action(self.rng, commands, self.center, self.explore)
