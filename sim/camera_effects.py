"""Image degradations for the simulated palm camera: lens distortion, blur, exposure, noise,
dropped frames. Pure NumPy/OpenCV; all randomness through the caller's `np.random.Generator`.

Order, as in a camera: the optics distort and blur the scene, the exposure scales it, the
sensor adds noise, the ADC rounds and clips to 8 bits.

Lens distortion: MuJoCo renders an ideal pinhole image with the calibration's K. Each pixel
of the distorted output looks up the ideal image at its undistorted position
(`cv2.undistortPoints` with the same K as the new camera matrix), so the output is what a lens
with OpenCV coefficients `distortion` would see, and a calibration with
`dist = distortion` (see `distorted_calibration`) recovers the pose. With barrel distortion
(k1 < 0) the output's corners look outside the render and stay black.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, replace

import cv2
import numpy as np

from vlr.camera import CameraCalibration

__all__ = ["CameraEffects", "apply_effects", "distorted_calibration", "distortion_maps"]


@dataclass(frozen=True)
class CameraEffects:
    """Camera degradations; the defaults leave the image unchanged.

    Attributes:
        noise_std: Gaussian sensor noise, standard deviation [grey levels of 0..255].
        blur_sigma_px: Gaussian blur (defocus, optics) standard deviation [px].
        exposure_gain: multiplies intensities before noise (1 = as rendered) [-].
        distortion: OpenCV lens distortion (k1, k2, p1, p2, k3), or None for a pinhole.
        drop_rate: probability that a frame is lost [-], in [0, 1].
    """

    noise_std: float = 0.0
    blur_sigma_px: float = 0.0
    exposure_gain: float = 1.0
    distortion: tuple[float, float, float, float, float] | None = None
    drop_rate: float = 0.0

    def __post_init__(self) -> None:
        for name, lo in (("noise_std", 0.0), ("blur_sigma_px", 0.0)):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= lo):
                raise ValueError(f"CameraEffects.{name} = {v!r} must be a finite number >= 0")
        g = self.exposure_gain
        if not (isinstance(g, (int, float)) and math.isfinite(g) and g > 0):
            raise ValueError(f"CameraEffects.exposure_gain = {g!r} must be a finite number > 0")
        p = self.drop_rate
        if not (isinstance(p, (int, float)) and 0.0 <= p <= 1.0):
            raise ValueError(f"CameraEffects.drop_rate = {p!r} must be in [0, 1]")
        if self.distortion is not None:
            d = tuple(self.distortion)
            if len(d) != 5 or not all(isinstance(x, (int, float)) and math.isfinite(x)
                                      for x in d):
                raise ValueError(f"CameraEffects.distortion = {self.distortion!r} must be "
                                 "None or five finite numbers (k1, k2, p1, p2, k3)")
            object.__setattr__(self, "distortion", tuple(float(x) for x in d))


def distorted_calibration(calibration: CameraCalibration,
                          effects: CameraEffects | None) -> CameraCalibration:
    """The calibration that describes images after `effects`: `calibration` with
    dist = effects.distortion (unchanged if there is none). Give this one to the estimator."""
    if effects is None or effects.distortion is None:
        return calibration
    return replace(calibration, dist=np.asarray(effects.distortion, dtype=float))


@functools.lru_cache(maxsize=4)
def _maps_cached(K_bytes: bytes, dist: tuple[float, ...], width: int,
                 height: int) -> tuple[np.ndarray, np.ndarray]:
    K = np.frombuffer(K_bytes, dtype=np.float64).reshape(3, 3)
    u, v = np.meshgrid(np.arange(width, dtype=np.float64), np.arange(height, dtype=np.float64))
    pts = np.stack([u.ravel(), v.ravel()], axis=1).reshape(-1, 1, 2)
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 50, 1e-10)
    ideal = cv2.undistortPoints(pts, K, np.asarray(dist), None, K, criteria=criteria)
    ideal = ideal.reshape(height, width, 2).astype(np.float32)
    map_x, map_y = np.ascontiguousarray(ideal[..., 0]), np.ascontiguousarray(ideal[..., 1])
    map_x.setflags(write=False)
    map_y.setflags(write=False)
    return map_x, map_y


def distortion_maps(K: np.ndarray, distortion: tuple[float, ...], width: int,
                    height: int) -> tuple[np.ndarray, np.ndarray]:
    """cv2.remap maps (float32, H x W): for each distorted output pixel, where to read the
    ideal pinhole image. Cached per (K, distortion, size)."""
    return _maps_cached(np.ascontiguousarray(K, dtype=np.float64).tobytes(),
                        tuple(float(x) for x in distortion), int(width), int(height))


def apply_effects(image: np.ndarray, effects: CameraEffects, rng: np.random.Generator,
                  calibration: CameraCalibration) -> np.ndarray | None:
    """The rendered uint8 image (H, W) or (H, W, C) as the degraded camera delivers it, or
    None if the frame is dropped. Deterministic for a given Generator state; draws random
    numbers only for effects that are on.

    Args:
        image: ideal pinhole render, uint8, size calibration.width x calibration.height.
        effects: what to apply.
        rng: the source of all randomness (drops, noise).
        calibration: the IDEAL calibration of the render (its K defines the distortion
            warp; its own dist is ignored).
    """
    if image.dtype != np.uint8:
        raise ValueError(f"image dtype {image.dtype} must be uint8")
    if image.shape[:2] != (calibration.height, calibration.width):
        raise ValueError(f"image size {image.shape[1]}x{image.shape[0]} does not match the "
                         f"calibration's {calibration.width}x{calibration.height}")
    if effects.drop_rate > 0 and rng.random() < effects.drop_rate:
        return None
    out = image
    if effects.distortion is not None and any(effects.distortion):
        map_x, map_y = distortion_maps(calibration.K, effects.distortion, calibration.width,
                                       calibration.height)
        out = cv2.remap(out, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT,
                        borderValue=0)
    if effects.blur_sigma_px > 0:
        out = cv2.GaussianBlur(out, (0, 0), effects.blur_sigma_px,
                               borderType=cv2.BORDER_REFLECT)
    if effects.exposure_gain == 1.0 and effects.noise_std == 0:
        return out if out is not image else image.copy()
    f = out.astype(np.float32)
    if effects.exposure_gain != 1.0:
        f *= np.float32(effects.exposure_gain)
    if effects.noise_std > 0:
        f += np.float32(effects.noise_std) * rng.standard_normal(f.shape, dtype=np.float32)
    return np.clip(np.rint(f), 0, 255).astype(np.uint8)
