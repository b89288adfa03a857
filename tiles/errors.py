"""User-facing errors: one line that names the file and the problem."""
from __future__ import annotations

import os


class UserError(Exception):
    """A mistake in the user's input: reported as one line, exit status 2, no traceback.

    Parameters
    ----------
    path
        The file, folder or URL the problem is about (``None`` when it is about no file).
    message
        What is wrong, in a short sentence without a trailing full stop.
    """

    def __init__(self, path: str | os.PathLike | None, message: str):
        self.path = None if path is None else os.fspath(path)
        self.message = message
        super().__init__(self.line())

    def line(self) -> str:
        """The one-line form printed by the command line."""
        return f"{self.path}: {self.message}" if self.path else self.message


class IncompleteStoreError(UserError):
    """A store whose build never finished (no ``complete`` flag in its metadata)."""
