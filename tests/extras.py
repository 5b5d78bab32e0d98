"""Skip marks for tests that need an optional extra (pyproject.toml), naming the extra."""

from __future__ import annotations

from importlib.util import find_spec

import pytest

needs_hardware = pytest.mark.skipif(
    find_spec("dynamixel_sdk") is None or find_spec("serial") is None,
    reason="the real hand's motor bus needs the hardware extra (pip install -e '.[hardware]')")
needs_cluster = pytest.mark.skipif(
    find_spec("ray") is None,
    reason="Ray sweeps need the cluster extra (pip install -e '.[cluster]')")
