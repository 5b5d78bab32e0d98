"""`python -m vlr.precompile` (run by `make install`) leaves nothing for the first real run to
compile: the demo's path after it adds no entry to numba's cache."""

import os
import subprocess
import sys
from pathlib import Path


def _cache_entries(folder: Path) -> set[str]:
    return {p.name for p in folder.rglob("*") if p.suffix in (".nbi", ".nbc")}


def test_demo_after_precompile_compiles_nothing(tmp_path):
    cache = tmp_path / "numba-cache"
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache), VLR_SMOKE="1", MUJOCO_GL="egl")
    done = subprocess.run([sys.executable, "-m", "vlr.precompile"], env=env,
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    assert "compiling the particle filter's kernels once" in done.stdout
    before = _cache_entries(cache)
    assert before, "precompile wrote no cache"
    vlr = Path(sys.executable).with_name("vlr")
    done = subprocess.run([str(vlr), "demo", "--out", str(tmp_path / "demo")], env=env,
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    assert _cache_entries(cache) == before, sorted(_cache_entries(cache) - before)
