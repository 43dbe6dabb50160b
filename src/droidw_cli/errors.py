"""User-facing errors.

Anything a user can cause (a missing file, a malformed trajectory, a bad
calibration) raises :class:`UserError`.  The CLI turns it into one line on
stderr and exit code 2, with no traceback.
"""


class UserError(Exception):
    """An error caused by the user's input, reported as one clear line."""


class ConfigError(UserError):
    """A configuration file or ``--set`` override is invalid."""


class InputError(UserError):
    """An input file (video, images, trajectory, calibration) is unusable."""
