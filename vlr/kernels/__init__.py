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

The kernels' on-disk cache (numba's `cache=True`) is keyed here on the whole folder's
source: numba keys a function's cache on its own file only, so an edit of `contacts.py`
alone (a `git pull`) left `solve.py`'s kernels, which compile the contacts into themselves,
running the old contacts from the cache.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

from numba.core.caching import CacheImpl, _SourceFileBackedLocatorMixin

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


# Before the kernel modules import: numba picks a function's locator when it is decorated.
if not any(c.__name__.startswith("Kernels") for c in CacheImpl._locator_classes):
    CacheImpl._locator_classes[:0] = [
        _folder_keyed(c) for c in CacheImpl._locator_classes
        if issubclass(c, _SourceFileBackedLocatorMixin)]
