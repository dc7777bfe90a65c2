"""Error types: every message names the file, row or field at fault."""

from __future__ import annotations


class SurgeError(Exception):
    """Base class for errors surge reports to a user as one line."""


class DataError(SurgeError, ValueError):
    """A user's input file (or a saved artefact) is malformed."""

    def __init__(self, message: str, *, path: object = None, row: int | None = None) -> None:
        where = ""
        if path is not None:
            where = f"{path}"
            if row is not None:
                where += f", row {row}"
            where += ": "
        super().__init__(where + message)
        self.path = path
        self.row = row


class ConfigError(SurgeError, ValueError):
    """A bad option: unknown policy or scenario, missing data directory, bad value."""
