"""The tool's one exception hierarchy.

Every error a user can cause derives from :class:`AcsError`. The CLI turns it into a
one-line message and an exit code; anything else is a bug and keeps its traceback.

- :class:`InputError` (exit 2): the input is malformed, missing or inconsistent.
- :class:`DegenerateMotionError` (exit 3): the input is well formed, but the recorded
  motion cannot determine the answer (hinge joint, too little rotation, ...).
"""

from __future__ import annotations

from pathlib import Path


class AcsError(Exception):
    """Base class of every error the tool reports to its user."""

    exit_code = 1

    def __init__(self, message: str, *, path: str | Path | None = None, line: int | None = None):
        self.message = message
        self.path = None if path is None else str(path)
        self.line = line
        super().__init__(self.one_line())

    def one_line(self) -> str:
        """The message as the CLI prints it: ``path:line: message``."""
        where = ""
        if self.path is not None:
            where = self.path if self.line is None else f"{self.path}:{self.line}"
            where += ": "
        return where + " ".join(self.message.split())


class InputError(AcsError, ValueError):
    """Bad input: a file that cannot be read, a wrong shape, a missing key (exit 2)."""

    exit_code = 2


class DegenerateMotionError(AcsError):
    """The motion cannot determine the answer (exit 3).

    Parameters
    ----------
    message : str
        What cannot be determined and what motion to record instead.
    details : dict, optional
        Machine-readable facts (singular values, hinge axis, ...) for artifacts.
    """

    exit_code = 3

    def __init__(
        self,
        message: str,
        *,
        details: dict[str, object] | None = None,
        path: str | Path | None = None,
    ):
        self.details = dict(details or {})
        super().__init__(message, path=path)
