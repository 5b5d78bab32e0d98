"""The motion kernels' on-disk cache is keyed on the whole kernels folder (`vlr.kernels`):
numba keys a function's cache on its own file, and the kernels compile their sibling files'
code into themselves."""

from __future__ import annotations

import importlib.util
import shutil
from pathlib import Path

import vlr.kernels as kernels
from vlr.kernels import chain, contacts, solve


def test_every_kernel_is_cached_under_the_folder_s_stamp():
    stamp = kernels.source_stamp()
    for kernel in (solve.solve_batch, solve.evaluate, contacts.rolled,
                   chain.contact_points_batch):
        assert kernel._cache._impl.locator.get_source_stamp() == stamp


def test_the_stamp_follows_any_file_of_the_folder(tmp_path):
    copy = tmp_path / "kernels"
    shutil.copytree(Path(kernels.__file__).parent, copy,
                    ignore=shutil.ignore_patterns("__pycache__"))
    assert kernels.source_stamp(copy) == kernels.source_stamp()
    with open(copy / "contacts.py", "a") as f:
        f.write("\n# an edit of one file\n")
    assert kernels.source_stamp(copy) != kernels.source_stamp()


def test_a_function_elsewhere_keeps_numba_s_own_key(tmp_path):
    module = tmp_path / "elsewhere.py"
    module.write_text("from numba import njit\n\n\n@njit(cache=True)\ndef one(x):\n"
                      "    return x + 1\n")
    spec = importlib.util.spec_from_file_location("elsewhere", module)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    locator = mod.one._cache._impl.locator
    assert not type(locator).__name__.startswith("Kernels")
    assert locator.get_source_stamp() != kernels.source_stamp()
