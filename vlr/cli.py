"""The `vlr` command line.

Subcommands come from two places: those of the core (`vlr/`), and those that backends and
tasks contribute through the `vlr.commands` entry-point group (see pyproject.toml). That keeps
the dependency direction one way: the core never imports `vlr.sim` or `vlr.hardware`; they
plug in.
"""

from __future__ import annotations

import argparse
import os
import signal
import sys
from importlib.metadata import entry_points

from vlr.errors import UserError

# Headless rendering is the project's choice, not the user's (EGL on Mesa on CPU).
os.environ.setdefault("MUJOCO_GL", "egl")
os.environ.setdefault("PYOPENGL_PLATFORM", "egl")

COMMAND_GROUP = "vlr.commands"


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="vlr", description="Self-identification of hand-object systems with VLRs.")
    # Their own dests: a subcommand's defaults overwrite the namespace's values of the same
    # name, and several subcommands have a --quiet (no progress bar) of their own.
    parser.add_argument("-v", "--verbose", dest="log_verbose", action="count", default=0,
                        help="log more: DEBUG lines on stderr (before the command: vlr -v ...)")
    parser.add_argument("-q", dest="log_quiet", action="count", default=0,
                        help="log less: warnings and errors only (-qq: errors only)")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    eps = sorted(entry_points(group=COMMAND_GROUP), key=lambda ep: ep.name)
    for ep in eps:
        try:
            register = ep.load()
        except ImportError as exc:  # an optional plug-in whose dependencies are absent
            p = sub.add_parser(ep.name, help=f"(unavailable: {exc})")
            p.set_defaults(func=lambda args, exc=exc: _unavailable(exc))
            continue
        register(sub)
    return parser


def _unavailable(exc: Exception) -> int:
    raise UserError(f"this command is unavailable: {exc}")


def main(argv: list[str] | None = None) -> int:
    try:
        return _main(argv)
    except BrokenPipeError:
        # The reader went away (`vlr identify --help | head`): silence the interpreter's
        # flush of stdout at exit, as the Python docs' note on SIGPIPE does.
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return 1


def _main(argv: list[str] | None) -> int:
    from vlr.hand import CommandError, GraspError
    from vlr.logs import configure, level_for
    from vlr.memory import keep_freed_memory
    from vlr.spec import SpecError

    parser = build_parser()
    args = parser.parse_args(argv)
    configure(level_for(args.log_verbose, args.log_quiet))
    keep_freed_memory()
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    try:
        return int(args.func(args) or 0)
    except (UserError, SpecError, FileNotFoundError, GraspError, CommandError) as exc:
        print(f"vlr {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt as exc:  # Ctrl-C, or SIGTERM/SIGHUP on the real hand
        print(f"vlr {args.command}: interrupted", file=sys.stderr)
        return 128 + getattr(exc, "signum", signal.SIGINT)


if __name__ == "__main__":
    sys.exit(main())
