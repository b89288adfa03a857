"""The package's exceptions: one base, and user-facing errors that read as one line naming the file and the problem.

:class:`BuildingParserError` is the base of every exception the package raises on
purpose: :class:`UserError` (a mistake in the user's input, exit status 2),
:class:`SettingsError` (a bad ``buildingparser.*`` setting, a :class:`UserError`)
and :class:`tiles.tasks.TaskFailures` (tasks that kept failing, exit status 1).
"""
from __future__ import annotations

import os
from typing import Any


class BuildingParserError(Exception):
    """Base of the exceptions buildingparser raises on purpose (catch this to catch them all)."""


class UserError(BuildingParserError):
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

    def __reduce__(self):
        """Pickle with the constructor's arguments (a task's error travels from a worker to the client)."""
        return type(self), (self.path, self.message)


class IncompleteStoreError(UserError):
    """A store whose build never finished (no ``complete`` flag in its metadata)."""


class SettingsError(UserError):
    """A ``buildingparser.*`` setting that is unknown or whose value is not what it must be.

    Parameters
    ----------
    key
        The full setting name, e.g. ``buildingparser.crf.time-limit``.
    value
        The value found.
    expected
        What the value must be, e.g. ``a number > 0``.
    hint
        The whole message when ``expected`` is None (an unknown key: ``unknown setting ... (did you mean ...?)``).
    """

    def __init__(self, key: str, value: Any = None, expected: str | None = None, hint: str | None = None):
        self.key, self.value, self.expected, self.hint = key, value, expected, hint
        if expected is not None:
            message = f"setting {key} = {_show(value)}: must be {expected}"
        else:
            message = hint or f"setting {key} = {_show(value)}: not accepted"
        super().__init__(None, message)

    def __reduce__(self):
        """Pickle with the constructor's arguments."""
        return type(self), (self.key, self.value, self.expected, self.hint)


def _show(value: Any) -> str:
    """A setting's value as the user wrote it (YAML-like: null, true, strings unquoted)."""
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "true" if value else "false"
    return repr(value) if isinstance(value, str) and (value == "" or value.strip() != value) else str(value)
