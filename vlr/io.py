"""Result files: written to a temporary file and renamed, never left half-written.

`atomic_path(path)` is the one place this is done: JSON (`write_json_atomic`), text
(`write_text_atomic`), and anything a library writes to a path (`np.savez`, `fig.savefig`)
go through it. Files end up readable by all (0644): results and pictures are for sharing,
and mkstemp's 0600 would hide them on a shared filesystem.
"""

from __future__ import annotations

import builtins
import contextlib
import json
import os
import select
import sys
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np

from vlr.errors import UserError

__all__ = ["atomic_path", "write_text_atomic", "write_json_atomic", "read_line",
           "check_output_dir", "check_output_file"]

_STDIN_PENDING = bytearray()   # bytes read from stdin past the last line returned


def _default(o: Any) -> Any:
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, np.generic):
        return o.item()
    raise TypeError(f"cannot write {type(o).__name__} to JSON")


@contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """A temporary path next to `path` (same suffix, so writers that go by it still work)
    to write to; renamed onto `path` when the block succeeds, removed when it does not."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=path.suffix, dir=path.parent)
    os.close(fd)
    try:
        yield Path(tmp)
        os.chmod(tmp, 0o644)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def _dir_problem(path: Path) -> str | None:
    """Why `path` cannot be used as a folder to write in, or None: it is created if
    missing and a probe file written and removed in it, which finds every way it can fail
    (a file there or above it, no permission, a read-only filesystem) as the run would;
    the folders it created are removed again, so that a run refused later for another
    reason leaves nothing behind."""
    if path.exists() and not path.is_dir():
        return "is a file, not a folder"
    for parent in path.parents:
        if parent.exists():
            if not parent.is_dir():
                return f"{parent} is a file, not a folder"
            break
    created = [p for p in (path, *path.parents) if not p.exists()]
    try:
        path.mkdir(parents=True, exist_ok=True)
        fd, probe = tempfile.mkstemp(prefix=".probe.tmp-", dir=path)
        os.close(fd)
        os.unlink(probe)
    except OSError as e:
        return f"cannot write there ({e.strerror or e})"
    finally:
        for folder in created:  # deepest first
            with contextlib.suppress(OSError):
                folder.rmdir()
    return None


def check_output_dir(path: str | Path, flag: str = "--out") -> Path:
    """`path` as a folder the run can write to, created if missing; a UserError naming
    `flag` and the path otherwise. Called before any computation, so that a bad `--out` is
    one line at the start, not a traceback after the whole run."""
    path = Path(path)
    problem = _dir_problem(path)
    if problem:
        raise UserError(f"{flag} {path}: {problem}")
    return path


def check_output_file(path: str | Path, flag: str) -> Path:
    """`path` as a file the run can write at its end: not a folder, and its folder
    writable (created if missing); a UserError naming `flag` and the path otherwise."""
    path = Path(path)
    if path.is_dir():
        problem: str | None = "is a folder, not a file"
    elif path.parent.exists() and not path.parent.is_dir():
        problem = f"{path.parent} is a file, not a folder"
    else:
        problem = _dir_problem(path.parent)
    if problem:
        raise UserError(f"{flag} {path}: {problem}")
    return path


def write_text_atomic(path: str | Path, text: str) -> Path:
    """Write `text` (UTF-8) to `path` atomically; return the path."""
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return Path(path)


def _strict(o: Any) -> Any:
    """`o` with NaN and infinities as None: strict JSON has no NaN, and other readers
    (JavaScript, jq) reject the `NaN` Python's json writes by default."""
    if isinstance(o, dict):
        return {k: _strict(v) for k, v in o.items()}
    if isinstance(o, list | tuple):
        return [_strict(v) for v in o]
    if isinstance(o, np.ndarray):
        return _strict(o.tolist())
    if isinstance(o, float | np.floating):
        return float(o) if np.isfinite(o) else None
    return o


def write_json_atomic(path: str | Path, data: Any) -> None:
    """Write `data` as strict JSON (a non-finite number becomes null) to `path` atomically
    (temp file in the same folder, then rename)."""
    text = json.dumps(_strict(data), indent=2, default=_default, allow_nan=False)
    write_text_atomic(path, text + "\n")


def read_line(prompt: str) -> str:
    """`input(prompt)` that a signal can interrupt: the wait for the line is in short
    `select`s, so the main thread returns to Python often. A signal the kernel delivers to
    another thread (numba's, BLAS's) only sets a flag that the main thread acts on when it
    runs Python, and a plain `input` blocked in read() would never see it; a run waiting at
    a prompt with torque on must still end on SIGTERM. Where stdin has no file descriptor
    (captured), this is `input`. Raises EOFError at the end of the input."""
    try:
        fd = sys.stdin.fileno()
    except (AttributeError, OSError, ValueError):
        return builtins.input(prompt)
    sys.stdout.write(prompt)
    sys.stdout.flush()
    while b"\n" not in _STDIN_PENDING:
        if not select.select([fd], [], [], 0.1)[0]:
            continue
        chunk = os.read(fd, 4096)
        if not chunk:
            if not _STDIN_PENDING:
                raise EOFError
            break
        _STDIN_PENDING.extend(chunk)
    line, _, rest = bytes(_STDIN_PENDING).partition(b"\n")
    _STDIN_PENDING[:] = rest
    return line.decode(errors="replace").rstrip("\r")
