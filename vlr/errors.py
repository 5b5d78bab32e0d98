"""Errors a user can fix: the CLI prints them as one line, without a traceback."""


class UserError(Exception):
    """A bad argument, file or setting, named in the message."""
