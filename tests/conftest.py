import os

import pytest

os.environ.setdefault("MUJOCO_GL", "egl")
os.environ.setdefault("PYOPENGL_PLATFORM", "egl")
# As `vlr` and `sim` set it, before any test renders: a process forked after llvmpipe's
# threads started hangs (tests/test_task_conventions.py forks workers).
os.environ.setdefault("LP_NUM_THREADS", "0")

# A tiny sweep for tests/test_sweep*.py: 2 cases x 2 seeds of the synthetic world, seconds.
TINY_SWEEP = """\
name: tiny
seeds: 0-1
settings: {world.backend: synthetic, filter.particles: 200, loop.max_iterations: 2}
cases:
  - {name: known hand}
  - {name: stiffness, filter.unknowns: ["stiffness:thumb.distal"],
     world.options.true_stiffness: {thumb.distal: 0.045}}
"""


@pytest.fixture
def sweep_file(tmp_path):
    """TINY_SWEEP in tmp_path/sweep.yaml, writing to tmp_path/out (--out overrides it)."""
    path = tmp_path / "sweep.yaml"
    path.write_text(TINY_SWEEP + f"out: {tmp_path / 'out'}\n")
    return path
