"""Errors that describe a user's mistake (bad input, bad file) rather than a bug.

The CLI prints their message and exits with status 2, without a traceback.
"""


class NfrDrakeError(Exception):
    """Base class of the errors the CLI reports as a one-line message and exit status 2."""


class CaptureSetError(NfrDrakeError):
    """A capture set (transforms.json and its images) is missing, malformed or inconsistent."""


class DatasetError(NfrDrakeError):
    """A rendered dataset folder is missing, malformed or was written with another configuration."""


class ConfigError(NfrDrakeError, ValueError):
    """An option or configuration value is out of range or inconsistent."""
