"""One import namespace: the installed distribution's only top-level name is `vlr`, and the
folders sim/, tasks/, hardware/ and models/ import as `vlr.sim`, `vlr.tasks`, `vlr.hardware`
and `vlr.models`, so that a user's `models.py` (or `sim.py`, `tasks.py`, `hardware.py`) in
the working folder shadows nothing."""

from __future__ import annotations

import subprocess
import sys
import textwrap
from importlib import metadata


def test_the_distribution_installs_vlr_alone():
    dist = metadata.distribution("vlr-testbed")
    assert (dist.read_text("top_level.txt") or "").split() == ["vlr"]
    for ep in dist.entry_points:
        assert ep.value.startswith("vlr."), ep   # every plug-in under the one namespace


def test_user_modules_named_like_the_folders_change_nothing(tmp_path):
    for name in ("models", "sim", "tasks", "hardware"):
        (tmp_path / f"{name}.py").write_text(f"raise ImportError('the user {name}.py')\n")
    script = textwrap.dedent("""
        import gymnasium as gym
        import vlr.tasks
        from vlr import models
        from vlr.sim.backend import SimHand
        from vlr.hardware.config import load_config
        from vlr.cli import main

        gym.register_envs(vlr.tasks)
        env = gym.make("vlr/MarbleMaze-v2", identify=False, n_runs=1)
        env.reset(seed=0)
        env.close()
        assert (models.ROOT / "hands" / "modelo.yaml").is_file()
        assert main(["identify", "--backend", "synthetic", "--particles", "200",
                     "--max-iterations", "1", "--quiet", "--out", "run"]) == 0
        print("ok")
    """)
    out = subprocess.run([sys.executable, "-c", script], cwd=tmp_path, capture_output=True,
                         text=True, timeout=600)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.strip().endswith("ok")
    assert (tmp_path / "run" / "result.json").is_file()


def test_an_id_makes_without_importing_the_package_first(tmp_path):
    """gymnasium's `module:id` form imports the registering module itself."""
    script = ('import gymnasium as gym\n'
              'env = gym.make("vlr.tasks:vlr/Handwriting-v2", identify=False, word="I")\n'
              'print(type(env.unwrapped).__module__)\n')
    out = subprocess.run([sys.executable, "-c", script], cwd=tmp_path, capture_output=True,
                         text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.strip() == "vlr.tasks.handwriting"
