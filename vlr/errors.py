"""Errors a user can fix: the CLI prints them as one line, without a traceback."""


class UserError(Exception):
    """A bad argument, file or setting, named in the message."""


class Interrupted(KeyboardInterrupt):
    """SIGINT, SIGTERM or SIGHUP while a hand runs: ends the run like Ctrl-C (torque off,
    one line, exit 128 + `signum`)."""

    def __init__(self, signum: int) -> None:
        super().__init__()
        self.signum = int(signum)
