"""User-facing errors.

Every problem a user can fix (a bad config key, a missing file, an empty volume, an artifact of the
wrong kind) raises :class:`FiberpipeError`. The CLI turns it into one line on stderr and a non-zero
exit status; only ``--debug`` shows a traceback.
"""

from __future__ import annotations


class FiberpipeError(Exception):
    """A problem the user can fix; its message is shown as one line, without a traceback."""

    exit_code = 2

    def __init__(self, message: str, *, where: str | None = None):
        self.where = where
        self.message = message
        super().__init__(f"{where}: {message}" if where else message)


class ConfigError(FiberpipeError):
    """A config file that is not valid (unknown key, wrong type, impossible value, bad unit)."""


class InputError(FiberpipeError):
    """An input file or volume that cannot be used (missing, empty, NaN, wrong dimensionality)."""


class ArtifactError(FiberpipeError):
    """An artifact of the wrong kind, an unknown schema version, or a damaged file."""


class SimulationDiverged(FiberpipeError):
    """A simulation stopped because it diverged; the message holds the diagnosis, ``step`` and
    ``time_s`` where the solver found it (None where not known)."""

    exit_code = 3

    def __init__(self, message: str = "", step: int | None = None, time_s: float | None = None):
        super().__init__(message)
        self.step = step
        self.time_s = time_s
