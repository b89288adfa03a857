"""``buildingparser info STORE``: what a tile store holds."""
from __future__ import annotations

import argparse
import json

NAME = "info"
HELP = "show a tile store's points, bounds, tiles, dimensions, results and ground truth"
ORDER = 95
DESCRIPTION = """\
Show what a tile store holds: point count, bounds, tiles, the per-point
dimensions by kind (coordinate, las, extra, ground_truth, result), which results
and ground truth exist, and the sources it was made from.  --json prints the
same as one JSON document (for scripts).

examples:
  buildingparser info building.zarr
  buildingparser info s3://bucket/area1.zarr --json
"""


def configure(parser: argparse.ArgumentParser) -> None:
    from engine.cli.options import add_storage_options

    parser.add_argument("store", metavar="STORE", help="the tile store (path or URL)")
    parser.add_argument("--json", action="store_true", help="print JSON instead of text")
    add_storage_options(parser)


def run(args: argparse.Namespace) -> int:
    from tiles.info import format_info, store_info
    from tiles.store import open_store

    info = store_info(open_store(args.store, args.storage_options))
    print(json.dumps(info, indent=2) if args.json else format_info(info))
    return 0
