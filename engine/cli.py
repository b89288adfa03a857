"""The ``buildingparser`` command line: one subcommand per step of the pipeline.

Subcommands live in :mod:`engine.commands`, one module each, discovered at start:
a module defines ``NAME``, ``HELP``, ``ORDER``, ``configure(parser)`` and
``run(args) -> int``.  User mistakes (:class:`tiles.errors.UserError`) print one
line naming the file and the problem and exit with status 2, never a traceback.
"""
from __future__ import annotations

import argparse
import importlib
import json
import pkgutil
import sys
import warnings
from collections.abc import Sequence

import engine  # noqa: F401  (registers configuration defaults)
import engine.commands
from tiles.errors import UserError
from tiles.tasks import TaskFailures

PROG = "buildingparser"


def _commands():
    mods = []
    for info in pkgutil.iter_modules(engine.commands.__path__):
        mod = importlib.import_module(f"engine.commands.{info.name}")
        if hasattr(mod, "NAME") and hasattr(mod, "run"):
            mods.append(mod)
    return sorted(mods, key=lambda m: (getattr(m, "ORDER", 100), m.NAME))


def add_cluster_options(parser: argparse.ArgumentParser) -> None:
    """Options of every command that runs work on dask."""
    g = parser.add_argument_group("cluster")
    g.add_argument("--scheduler", metavar="ADDRESS",
                   help="existing dask scheduler (tcp://host:8786, tls://...); default: DASK_SCHEDULER_ADDRESS "
                        "or buildingparser.scheduler, else an embedded LocalCluster")
    g.add_argument("--workers", type=int, metavar="N", help="workers of the embedded LocalCluster (default: one per core)")
    g.add_argument("--memory-limit", metavar="SIZE", help="memory per worker of the embedded LocalCluster (e.g. 4GiB)")


def add_storage_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--storage-options", metavar="JSON", type=_json_dict, default=None,
                        help='fsspec options for URLs, e.g. \'{"endpoint_url": "http://127.0.0.1:9000"}\'')


def _json_dict(text: str) -> dict:
    try:
        value = json.loads(text)
    except json.JSONDecodeError as exc:
        raise argparse.ArgumentTypeError(f"not JSON: {exc}") from None
    if not isinstance(value, dict):
        raise argparse.ArgumentTypeError("must be a JSON object")
    return value


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
