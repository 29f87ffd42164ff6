"""Errors that describe a user's mistake (bad input, bad file) rather than a bug.

The CLI prints their message and exits with their `exit_status` (2), without a traceback.
"""


class NfrDrakeError(Exception):
    """Base class of the errors the CLI reports as a one-line message and exit status 2."""

    exit_status = 2


class Interrupted(NfrDrakeError):
    """A run stopped by a signal after saving what it had done: exit status 128 + signal number
    (130 for SIGINT, 143 for SIGTERM), as a shell reports a process killed by that signal."""

    def __init__(self, message: str, signum: int):
        super().__init__(message)
        self.exit_status = 128 + signum


class CaptureSetError(NfrDrakeError):
    """A capture set (transforms.json and its images) is missing, malformed or inconsistent."""


class DatasetError(NfrDrakeError):
    """A rendered dataset folder is missing, malformed or was written with another configuration."""


class ConfigError(NfrDrakeError, ValueError):
    """An option or configuration value is out of range or inconsistent."""
