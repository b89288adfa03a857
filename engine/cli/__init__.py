"""The ``buildingparser`` command line: one subcommand per step of the pipeline.

Subcommands live in this package, one module each, discovered at start:
a module defines ``NAME``, ``HELP``, ``ORDER``, ``configure(parser)`` and
``run(args) -> int``.  User mistakes (:class:`tiles.errors.UserError`) print one
line naming the file and the problem and exit with status 2, never a traceback.
"""
from __future__ import annotations

import argparse
import importlib
import pkgutil
import sys
import warnings
from collections.abc import Sequence

import engine  # noqa: F401  (registers configuration defaults)
from tiles.errors import UserError
from tiles.tasks import TaskFailures

PROG = "buildingparser"


def _commands():
    mods = []
    for info in pkgutil.iter_modules(__path__):
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
        p.set_defaults(_run=mod.run)
    return parser


def _version() -> str:
    try:
        from importlib.metadata import version

        return f"{PROG} {version('buildingparser')}"
    except Exception:  # noqa: BLE001
        return PROG


def _one_line_warnings(message, category, filename, lineno, file=None, line=None):
    print(f"{PROG}: warning: {message}", file=sys.stderr)


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "_run", None):
        parser.print_help()
        return 2
    warnings.showwarning = _one_line_warnings
    try:
        return int(args._run(args) or 0)
    except UserError as exc:
        print(f"{PROG}: error: {exc.line()}", file=sys.stderr)
        return 2
    except TaskFailures as exc:
        print(f"{PROG}: error: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print(f"{PROG}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
