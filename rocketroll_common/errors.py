"""The error types of every rocketroll layer.

A command line turns any :class:`RocketrollError` into one line on stderr and
exit code 2; anything else is a bug and keeps its traceback.
"""

from __future__ import annotations

__all__ = ["Interrupted", "RocketrollError", "SettingError", "UsageError"]


class RocketrollError(Exception):
    """Base of the errors a user can cause (bad files, bad arguments)."""


class UsageError(RocketrollError, ValueError):
    """A command-line argument, or a combination of them, is invalid."""


class SettingError(UsageError):
    """One field of a settings dataclass is invalid; ``setting`` names it.

    The command lines built from the dataclass
    (:mod:`rocketroll_common.settings`) report it under the option's flag.
    """

    def __init__(self, setting: str, problem: str) -> None:
        super().__init__(f"{setting}: {problem}")
        self.setting = setting
        self.problem = problem

    def __reduce__(self) -> tuple[type[SettingError], tuple[str, str], dict[str, object]]:
        """Pickled with its own arguments and its state, notes included (an error raised in a
        worker process crosses back whole)."""
        return type(self), (self.setting, self.problem), dict(vars(self))


class Interrupted(KeyboardInterrupt):
    """Ctrl-C, with what the interrupted work left behind (e.g. a resumable checkpoint).

    A command line prints ``PROG: interrupted: MESSAGE`` and exits with 130.
    """
