"""Numba kernels of the motion model (Eq. 6-9), internal to `vlr.motion`, and of the
particles' other per-iteration passes.

* `records`: the named records every kernel takes (the hand's constants, the particles, the
  solver's settings, the local surface, scratch);
* `chain`: a finger's planar chain (Eq. 2) and the energy terms of the hand alone (Eq. 6, 7,
  the joint stops, gravity);
* `contacts`: the contacts (Eq. 8): pinned, or rolling exactly within one solve with the
  pads' Coulomb friction;
* `arrow`: the Newton system's arrow-structured linear algebra;
* `solve`: one action per particle by primal-dual Newton from the stored tangent, and the
  batched entry points;
* `likelihood`: the pose likelihood's terms (Eq. 5 with the grasp's turn, `vlr.observation`);
* `frames`: the contacts between the palm and object frames (the anchors, `vlr.motion`);
* `resample`: resampling the particles' arrays in place.

The kernels' on-disk cache (numba's `cache=True`) is keyed here on the whole folder's
source: numba keys a function's cache on its own file only, so an edit of `contacts.py`
alone (a `git pull`) left `solve.py`'s kernels, which compile the contacts into themselves,
running the old contacts from the cache.
"""

from __future__ import annotations

import hashlib
import logging
from pathlib import Path

import numba
from numba.core import caching

_FOLDER = Path(__file__).resolve().parent


def source_stamp(folder: Path = _FOLDER) -> str:
    """SHA-256 of a folder's Python sources (names and contents): for this one, the
    kernels' cache key."""
    digest = hashlib.sha256()
    for path in sorted(folder.glob("*.py")):
        digest.update(path.name.encode())
        digest.update(path.read_bytes())
    return digest.hexdigest()


_STAMP = source_stamp()


def _folder_keyed(base: type) -> type:
    """numba's cache locator `base`, for this folder's functions only, keyed on the
    folder's source (`source_stamp`) instead of the function's file alone."""

    class FolderKeyedLocator(base):
        @classmethod
        def from_function(cls, py_func, py_file):
            if Path(py_file).resolve().parent != _FOLDER:
                return None
            return super().from_function(py_func, py_file)

        def get_source_stamp(self):
            return _STAMP

    FolderKeyedLocator.__name__ = FolderKeyedLocator.__qualname__ = f"Kernels{base.__name__}"
    return FolderKeyedLocator


def _register() -> None:
    """Put the folder-keyed locators first in numba's list (numba's own names: `CacheImpl`
    from 0.68, `_CacheImpl` before; the project allows 0.61-0.68)."""
    impl = getattr(caching, "CacheImpl", None) or getattr(caching, "_CacheImpl", None)
    mixin = getattr(caching, "_SourceFileBackedLocatorMixin", None)
    classes = getattr(impl, "_locator_classes", None)
    if mixin is None or not isinstance(classes, list):
        logging.getLogger(__name__).warning(
            "numba %s: its cache locators are not where vlr.kernels expects them; after an "
            "edit of one kernel file, remove vlr/kernels/__pycache__/*.nb*", numba.__version__)
        return
    if not any(c.__name__.startswith("Kernels") for c in classes):
        classes[:0] = [_folder_keyed(c) for c in classes if issubclass(c, mixin)]


# Before the kernel modules import: numba picks a function's locator when it is decorated.
_register()
