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


def yaml_problem(exc: Exception) -> str:
    """One line for a YAML parser error: what went wrong and where (PyYAML's own text spans several)."""
    problem = getattr(exc, "problem", None) or getattr(exc, "context", None)
    mark = getattr(exc, "problem_mark", None) or getattr(exc, "context_mark", None)
    if problem is None:
        text = str(exc).strip()
        return text.splitlines()[0] if text else type(exc).__name__
    where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark is not None else ""
    return f"{problem}{where}"
