"""How the command line shows messages: the package's ``logging`` records on stderr, one plain line each.

The engine and the tile store only log (``logging.getLogger(__name__)``); the
command line decides where it goes: INFO and above on stderr as
``buildingparser: message`` (``-v`` adds DEBUG, ``-q`` keeps warnings and
errors only and turns progress bars off), and ``run`` also keeps every
message, DEBUG included, with timestamps, in ``buildingparser.log`` in its
output folder.  See docs/design/pipeline.md.
"""
from __future__ import annotations

import argparse
import contextlib
import logging
import os
import shutil
import sys
import warnings
from collections.abc import Iterator
from typing import Any

import dask

from tiles import paths
from tiles.leftovers import temporary_folder

PROG = "buildingparser"
PACKAGES = ("engine", "tiles")  # the loggers the command line shows
LOG_FILE = "buildingparser.log"

logger = logging.getLogger(__name__)


def add_verbosity_options(parser: argparse.ArgumentParser) -> None:
    """``-v/--verbose`` and ``-q/--quiet`` (every subcommand has them)."""
    g = parser.add_mutually_exclusive_group()
    g.add_argument("-v", "--verbose", action="store_true", help="also show debugging messages")
    g.add_argument("-q", "--quiet", action="store_true", help="show only warnings and errors (no progress bars)")


def verbosity(args: argparse.Namespace) -> int:
    """1 for ``--verbose``, -1 for ``--quiet``, else 0."""
    return 1 if getattr(args, "verbose", False) else -1 if getattr(args, "quiet", False) else 0


class LineFormatter(logging.Formatter):
    """``buildingparser: message``; ``buildingparser: warning: message`` and ``... error: ...`` above INFO."""

    def format(self, record: logging.LogRecord) -> str:
        tag = "error: " if record.levelno >= logging.ERROR else "warning: " if record.levelno >= logging.WARNING else ""
        return f"{PROG}: {tag}{record.getMessage()}"


class ConsoleHandler(logging.StreamHandler):
    """A stream handler that writes through ``tqdm.write``, so a message never breaks a progress bar."""

    def emit(self, record: logging.LogRecord) -> None:
        try:
            from tqdm import tqdm

            tqdm.write(self.format(record), file=self.stream)
            self.flush()
        except RecursionError:
            raise
        except Exception:  # noqa: BLE001 - logging's own convention
            self.handleError(record)


def _one_line_warning(message, category, filename, lineno, file=None, line=None) -> None:
    logger.warning("%s", message)


@contextlib.contextmanager
def _attached(handler: logging.Handler, level: int) -> Iterator[None]:
    """``handler`` on the package's loggers for the block, their level lowered to ``level`` if needed."""
    loggers = [logging.getLogger(name) for name in PACKAGES]
    saved = [lg.level for lg in loggers]
    for lg in loggers:
        lg.addHandler(handler)
        lg.setLevel(level if lg.level == logging.NOTSET else min(lg.level, level))
    try:
        yield
    finally:
        for lg, old in zip(loggers, saved):
            lg.removeHandler(handler)
            lg.setLevel(old)


@contextlib.contextmanager
def console_logging(verbose: int = 0) -> Iterator[None]:
    """The package's messages on stderr for the block (and Python warnings as one line each).

    Parameters
    ----------
    verbose
        0: INFO and above; 1: DEBUG too; -1: warnings and errors only, and no progress bars.
    """
    level = logging.DEBUG if verbose > 0 else logging.WARNING if verbose < 0 else logging.INFO
    handler = ConsoleHandler(sys.stderr)
    handler.setFormatter(LineFormatter())
    handler.setLevel(level)
    shown = warnings.showwarning
    warnings.showwarning = _one_line_warning
    quiet = {"buildingparser.progress": "never"} if verbose < 0 else {}
    try:
        with _attached(handler, level), dask.config.set(quiet):
            yield
    finally:
        warnings.showwarning = shown


@contextlib.contextmanager
def run_log(out: str, storage_options: dict[str, Any] | None = None) -> Iterator[str | None]:
    """Every message of the package, DEBUG included, with timestamps, into ``OUT/buildingparser.log``.

    The file is this run's (an earlier run's is replaced); an error that ends the
    block is written into it with its traceback (stderr shows one line).  For a
    URL the file is written locally and copied there at the end.  Yields the
    local path of the file (None when the output folder is a file: the run says so).
    """
    local = paths.is_local(out)
    tmpdir = None
    try:
        if local:
            folder = paths.local_path(paths.normalize(out))
            os.makedirs(folder, exist_ok=True)
        else:
            folder = tmpdir = temporary_folder("log")
        handler = logging.FileHandler(os.path.join(folder, LOG_FILE), mode="w", encoding="utf-8",
                                      errors="backslashreplace")  # an input path need not be UTF-8
    except OSError:
        yield None  # not a folder we can write into: the run itself reports it
        return
    handler.setFormatter(logging.Formatter("%(asctime)s %(levelname)-7s %(name)s: %(message)s"))
    handler.setLevel(logging.DEBUG)
    try:
        with _attached(handler, logging.DEBUG):
            try:
                yield handler.baseFilename
            except BaseException as exc:
                handler.handle(logger.makeRecord(logger.name, logging.ERROR, __file__, 0, "%s: %s",
                                                 (type(exc).__name__, exc), sys.exc_info()))
                raise
    finally:
        handler.close()
        if local:
            from engine.pipeline.outfolder import record_written

            with contextlib.suppress(OSError):
                record_written(out, [LOG_FILE])
        if tmpdir is not None:
            with contextlib.suppress(Exception):  # the log is a by-product: never lose a run for it
                fs, root = paths.filesystem(out, storage_options)
                fs.put_file(handler.baseFilename, f"{root.rstrip('/')}/{LOG_FILE}")
            shutil.rmtree(tmpdir, ignore_errors=True)
