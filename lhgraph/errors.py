"""One exception hierarchy for lhgraph.

Every error a user can cause derives from :class:`LhgraphError`; the CLI turns it into one
line on stderr and the exit code stored on the class (2 for bad input).
"""

from __future__ import annotations

from pathlib import Path


class LhgraphError(Exception):
    """Base class of all lhgraph errors."""

    exit_code: int = 1


class InputError(LhgraphError):
    """Bad input (file content, configuration, command-line values): exit code 2.

    ``source`` names the file (or option) and ``where`` the row/key inside it, so the message
    reads ``file:where: problem``.
    """

    exit_code = 2

    def __init__(self, problem: str, source: str | Path | None = None, where: str | None = None):
        self.problem = problem
        self.source = None if source is None else str(source)
        self.where = where
        prefix = ""
        if self.source is not None:
            prefix = self.source + (f":{where}" if where else "") + ": "
        elif where:
            prefix = f"{where}: "
        super().__init__(prefix + problem)


class SolverError(LhgraphError):
    """The data cannot determine what was asked (e.g. a station never seen, no overlap)."""

    exit_code = 3


class DeviceError(LhgraphError):
    """The capture board or its link failed (no answer, refused command, damaged transfer):
    exit code 1."""

    exit_code = 1
