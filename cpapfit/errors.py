"""The project's own exceptions: errors a user can cause, each with a message that says what to do.

The command line prints ``str(error)`` as one line on stderr and exits with code 2.
"""


class CpapfitError(Exception):
    """Base class of every error the user can cause or fix."""


class InputError(CpapfitError):
    """A file is missing, empty, truncated, unreadable or holds impossible values."""


class NoStockSeat(InputError):
    """No stock size tried finds a seat on the face (its wall runs round the mask axis over it from none)."""


class UnitsError(CpapfitError):
    """The scan's size fits no supported unit, or the stated unit is implausible."""


class QualityError(CpapfitError):
    """The scan is not good enough for a mask (a quality gate refuses): rescan."""
