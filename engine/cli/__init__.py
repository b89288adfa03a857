"""The ``buildingparser`` command line: one subcommand per step of the pipeline.

Subcommands live in this package, one module each, discovered at start:
a module defines ``NAME``, ``HELP``, ``ORDER``, ``configure(parser)`` and
``run(args) -> int``.  Messages go through ``logging``, shown on stderr by
:mod:`engine.cli.logs` (``-v``/``-q`` on every subcommand).  User mistakes
(:class:`tiles.errors.UserError`) print one line naming the file and the
problem and exit with status 2, never a traceback.
"""
from __future__ import annotations

import argparse
import importlib
import logging
import pkgutil
import sys
from collections.abc import Sequence

import engine  # noqa: F401  (registers configuration defaults)
from engine.cli.logs import PROG, add_verbosity_options, console_logging, verbosity
from engine.config import validate_settings
from tiles.errors import UserError
from tiles.tasks import TaskFailures

logger = logging.getLogger(__name__)


def _commands():
    mods = []
    for info in pkgutil.iter_modules(__path__):
        if info.name.startswith("_"):
            continue  # __main__ runs the command line when imported
        mod = importlib.import_module(f"{__name__}.{info.name}")
        if hasattr(mod, "NAME") and hasattr(mod, "run"):
            mods.append(mod)
    return sorted(mods, key=lambda m: (getattr(m, "ORDER", 100), m.NAME))


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog=PROG,
        description="Parse the point cloud of a whole building into spaces (rooms, hallways) and the "
                    "structural and furniture elements inside them (Armeni et al., CVPR 2016), on dask.",
        epilog="Run 'buildingparser COMMAND --help' for the options of a command. Settings go through "
               "dask.config under 'buildingparser' (e.g. DASK_BUILDINGPARSER__TILES__SIZE=20).",
    )
    parser.add_argument("--version", action="version", version=_version())
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for mod in _commands():
        p = sub.add_parser(mod.NAME, help=mod.HELP, description=getattr(mod, "DESCRIPTION", mod.HELP),
                           formatter_class=argparse.RawDescriptionHelpFormatter)
        mod.configure(p)
        add_verbosity_options(p)
        p.set_defaults(_run=mod.run)
    return parser


def _version() -> str:
    try:
        from importlib.metadata import version

        return f"{PROG} {version('buildingparser')}"
    except Exception:  # noqa: BLE001
        return PROG


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line (``argv`` without the program name; default ``sys.argv[1:]``); returns the exit code."""
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "_run", None):
        parser.print_help()
        return 2
    for stream in (sys.stdout, sys.stderr):  # a path need not be UTF-8: print its odd bytes escaped, never fail
        reconfigure = getattr(stream, "reconfigure", None)
        if reconfigure is not None:
            reconfigure(errors="backslashreplace")
    with console_logging(verbosity(args)):
        try:
            validate_settings()  # every buildingparser.* setting, before any work or cluster starts
            return int(args._run(args) or 0)
        except UserError as exc:
            logger.error("%s", exc.line())
            return 2
        except TaskFailures as exc:
            logger.error("%s", exc)
            return 1
        except KeyboardInterrupt:
            logger.error("interrupted")
            return 130


if __name__ == "__main__":
    sys.exit(main())
