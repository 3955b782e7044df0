"""Error types shared by every ``rocketroll`` layer and its command line.

The CLI turns any :class:`RocketrollError` into one line on stderr and exit
code 2; anything else is a bug and keeps its traceback.
"""

from __future__ import annotations

__all__ = ["RocketrollError", "UsageError"]


class RocketrollError(Exception):
    """Base of the errors a user can cause (bad files, bad arguments)."""


class UsageError(RocketrollError, ValueError):
    """A command-line argument, or a combination of them, is invalid."""
