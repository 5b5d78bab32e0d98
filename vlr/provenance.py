"""Which code a result came from: the git commit of the checkout `vlr` is imported from.

A sweep's trial record carries it (`vlr.sweep.run_one`), so a table's figures name the
commit they ran at instead of a note written by hand. Outside a git checkout (an installed
wheel, a Ray worker's unpacked working_dir) it is None.
"""

from __future__ import annotations

import functools
import subprocess
from pathlib import Path

__all__ = ["code_version"]

_ROOT = Path(__file__).resolve().parent.parent


@functools.lru_cache(maxsize=1)
def code_version() -> dict[str, str | bool] | None:
    """{"commit": full hash, "dirty": tracked files changed since it} of the checkout, once
    per process; None where there is no git or no checkout."""
    def git(*args: str) -> str:
        return subprocess.run(["git", "-C", str(_ROOT), *args], capture_output=True,
                              text=True, check=True, timeout=10).stdout.strip()

    try:
        # Only the checkout vlr lives in: an installed copy inside some other repository
        # (a venv in a checkout) is not that repository's code.
        if Path(git("rev-parse", "--show-toplevel")).resolve() != _ROOT:
            return None
        commit = git("rev-parse", "HEAD")
        dirty = bool(git("status", "--porcelain", "--untracked-files=no"))
    except (OSError, subprocess.SubprocessError):
        return None
    return {"commit": commit, "dirty": dirty}
