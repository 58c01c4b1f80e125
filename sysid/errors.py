"""Error types shared by the whole project.

Every error a user can cause with bad input derives from :class:`InputError`. Its message is one line
that names the offending file, array or parameter and the problem; the CLI prints it to stderr and exits
with status 2, never a traceback.
"""

from __future__ import annotations


class InputError(ValueError):
    """Bad user input (file, array, parameter). The message is a single line meant for the user."""

    def __init__(self, message: str):
        # One line, always: collapse any embedded newlines so the CLI prints exactly one line.
        super().__init__(" ".join(str(message).split()))


class DataError(InputError):
    """A data file or array is unusable (missing, unknown format, NaN/inf, unequal lengths, ...)."""


class ConfigError(InputError):
    """An unknown or out-of-range configuration value (parameter, effect, identifier option)."""


class DivergenceWarning(RuntimeWarning):
    """A free-run simulation diverged (non-finite or beyond its bound) and was stopped."""


class OrderSearchWarning(UserWarning):
    """An automatic order (or FIR tap count) choice landed on the last point of its grid, or no order of the grid
    came near the least-squares FIR on the hold-out: a larger order or another structure may fit better."""
