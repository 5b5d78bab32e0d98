"""Where the project's log records go when `vlr` runs: stderr, one short line each.

The packages log through `logging.getLogger(__name__)`; the CLI calls `configure` once per
run with the level of its global flags (INFO by default, `-v` DEBUG, `-q` WARNING). Lines
read `[hardware] message`, by package (`vlr.hardware.bus` reads `hardware`), with the level
named from WARNING up, so
that the lines the real hand printed before logging existed read the same.
"""

from __future__ import annotations

import logging
import sys

__all__ = ["PACKAGES", "configure", "level_for", "progress_bar"]

#: The loggers configured: the project's packages only, so that a dependency's INFO records
#: (numba, matplotlib, ray) stay as quiet as their authors meant.
PACKAGES = ("vlr",)

#: The folders installed under `vlr` whose records are named by their own package.
_SUBPACKAGES = ("sim", "hardware", "tasks", "models")

_handler: logging.Handler | None = None


class _StderrHandler(logging.StreamHandler):
    """A handler writing to whatever `sys.stderr` is when a record comes, not when it was
    made: a test's captured stream, once closed, must not swallow a later run's lines."""

    def __init__(self) -> None:
        super().__init__(sys.stderr)

    @property
    def stream(self):
        return sys.stderr

    @stream.setter
    def stream(self, value) -> None:  # StreamHandler sets it; the property reads sys.stderr
        pass


class _ShortFormatter(logging.Formatter):
    """`[package] message`, `[package] WARNING: message`; with `full_names` (at DEBUG, where
    the module says where to look) the logger's whole name."""

    def __init__(self, full_names: bool = False) -> None:
        super().__init__()
        self.full_names = full_names

    def format(self, record: logging.LogRecord) -> str:
        parts = record.name.split(".")
        short = parts[1] if len(parts) > 1 and parts[1] in _SUBPACKAGES else parts[0]
        name = record.name if self.full_names else short
        level = f"{record.levelname}: " if record.levelno >= logging.WARNING else ""
        text = f"[{name}] {level}{record.getMessage()}"
        if record.exc_info:
            text += "\n" + self.formatException(record.exc_info)
        return text


def level_for(verbose: int = 0, quiet: int = 0) -> int:
    """The level of `-v` / `-q` counts: INFO, DEBUG with -v, WARNING with -q (-qq ERROR)."""
    steps = {-2: logging.ERROR, -1: logging.WARNING, 0: logging.INFO, 1: logging.DEBUG}
    return steps[max(-2, min(1, verbose - quiet))]


def configure(level: int = logging.INFO) -> None:
    """Send the project's records at `level` and above to stderr (`sys.stderr` as it is at
    each record). Calling it again replaces the handler it added."""
    global _handler
    handler = _StderrHandler()
    handler.setFormatter(_ShortFormatter(full_names=level <= logging.DEBUG))
    for name in PACKAGES:
        logger = logging.getLogger(name)
        if _handler is not None:
            logger.removeHandler(_handler)
        logger.addHandler(handler)
        logger.setLevel(level)
        # A dependency may install a root handler (`import dm_control.mjcf` does, through
        # absl): propagated, every record would print twice.
        logger.propagate = False
    _handler = handler


def progress_bar(quiet: bool = False, **kwargs):
    """A tqdm progress bar on stderr, or one that draws nothing: with `quiet` (a command's
    --quiet), under `vlr -q` (the project's loggers above INFO), or when stderr is not a
    terminal (tqdm's `disable=None`), where a bar's frames would fill a log file."""
    from tqdm import tqdm

    off = quiet or logging.getLogger("vlr").getEffectiveLevel() > logging.INFO
    return tqdm(disable=True if off else None, **kwargs)
