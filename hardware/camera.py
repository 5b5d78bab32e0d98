"""Frame sources for the palm camera: an OpenCV device, or a fake for dry runs and tests.

A `FrameSource` is two methods (`read`, `close`), so a fake stands in for the device.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Protocol

import numpy as np
from vlr.hardware.errors import HardwareError


class CameraError(HardwareError):
    """The camera cannot be opened or stops delivering frames."""


class FrameSource(Protocol):
    """Latest-frame camera; its `name` (if it has one) is what messages call it."""

    def read(self) -> np.ndarray | None:
        """The newest image (H x W x 3, uint8), or None if none is available."""

    def close(self) -> None:
        """Release the device."""


class OpenCVCamera:
    """`cv2.VideoCapture(index)`, returning the latest frame, not a stale buffered one.

    Args:
        index: OpenCV device index (/dev/video<index> on Linux).
        width, height: requested image size [px] (the calibration's); a frame of another
            size raises `CameraError`.
        drain: frames grabbed and dropped before each retrieve: drivers that ignore
            CAP_PROP_BUFFERSIZE = 1 still queue a few frames.
    """

    def __init__(self, index: int, width: int | None = None, height: int | None = None,
                 drain: int = 2) -> None:
        import cv2  # only the real camera needs OpenCV's video I/O

        self._cv2 = cv2
        self.index = index
        self.name = f"camera {index} (/dev/video{index})"
        self.drain = drain
        self.size = (width, height) if width and height else None
        self.cap = cv2.VideoCapture(index)
        if not self.cap.isOpened():
            self.cap.release()
            raise CameraError(f"cannot open camera {index} (/dev/video{index}): is it plugged "
                              "in, used by another program, or is the index wrong? "
                              "(v4l2-ctl --list-devices lists cameras)")
        self.cap.set(cv2.CAP_PROP_BUFFERSIZE, 1)
        if width and height:
            self.cap.set(cv2.CAP_PROP_FRAME_WIDTH, width)
            self.cap.set(cv2.CAP_PROP_FRAME_HEIGHT, height)

    def read(self) -> np.ndarray | None:
        for _ in range(self.drain):
            self.cap.grab()
        if not self.cap.grab():
            return None
        ok, image = self.cap.retrieve()
        if not ok or image is None:
            return None
        if self.size is not None and (image.shape[1], image.shape[0]) != self.size:
            # The driver ignored the requested size: the calibration would not fit the image.
            raise CameraError(f"camera {self.index} delivers {image.shape[1]}x{image.shape[0]} "
                              f"frames, not the calibration's {self.size[0]}x{self.size[1]}: "
                              "calibrate at the size the camera delivers, or pick a size it "
                              "supports (v4l2-ctl --list-formats-ext)")
        return self._cv2.cvtColor(image, self._cv2.COLOR_BGR2RGB)

    def close(self) -> None:
        self.cap.release()


class FakeCamera:
    """A stand-in camera: a blank image, or whatever a callable returns.

    Args:
        width, height: size of the blank image [px].
        source: called for each frame; returns an image or None (a dropped frame).
        name: what messages call it.
    """

    def __init__(self, width: int = 640, height: int = 480,
                 source: Callable[[], np.ndarray | None] | None = None,
                 name: str = "the fake camera") -> None:
        self.name = name
        self.width, self.height = width, height
        self.source = source
        self.frames = 0
        self.closed = False

    def read(self) -> np.ndarray | None:
        if self.closed:
            raise CameraError("the fake camera is closed")
        self.frames += 1
        if self.source is not None:
            return self.source()
        return np.zeros((self.height, self.width, 3), dtype=np.uint8)

    def close(self) -> None:
        self.closed = True


def now() -> float:
    """Timestamp of a frame [s] (monotonic clock of the backend)."""
    return time.monotonic()
