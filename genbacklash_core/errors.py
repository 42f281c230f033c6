"""Exception types of genbacklash.

Every error the package raises on bad user input derives from :class:`GenBacklashError`,
which itself derives from :class:`ValueError`, so callers can catch either.
"""

from __future__ import annotations

__all__ = ["GenBacklashError", "NonFiniteInputError", "NotEnoughExcitationError"]


class GenBacklashError(ValueError):
    """Base class of all genbacklash errors about data, models or options."""


class NonFiniteInputError(GenBacklashError):
    """The data holds NaN or infinite samples."""


class NotEnoughExcitationError(GenBacklashError):
    """The data cannot identify the model: too short, constant, or without reversals."""
