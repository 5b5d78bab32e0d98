"""Errors a user can fix: the CLI prints them as one line, without a traceback."""


class UserError(Exception):
    """A bad argument, file or setting, named in the message."""


class MissingExtra(UserError, ImportError):
    """An optional dependency is not installed; the message names the extra that brings it.

    An ImportError, so that a `vlr` plug-in needing it at import shows as unavailable in
    `vlr --help` (vlr.cli); a UserError, so that a command reaching it while it runs ends in
    one line rather than a traceback.
    """

    def __init__(self, module: str, extra: str, needed_by: str) -> None:
        super().__init__(f"{needed_by} needs {module}, from the optional extra {extra!r}: "
                         f"pip install -e '.[{extra}]'")
        self.name = module
        self.extra = extra


class Interrupted(KeyboardInterrupt):
    """SIGINT, SIGTERM or SIGHUP while a hand runs: ends the run like Ctrl-C (torque off,
    one line, exit 128 + `signum`)."""

    def __init__(self, signum: int) -> None:
        super().__init__()
        self.signum = int(signum)
