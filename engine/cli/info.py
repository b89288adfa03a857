"""``buildingparser info PATH``: what a tile store, a point cloud file or an S3DIS folder holds."""
from __future__ import annotations

import argparse
import json

NAME = "info"
HELP = "show what a tile store or a point cloud file holds (points, bounds, dimensions, results)"
ORDER = 95
DESCRIPTION = """\
Show what a tile store holds: point count, bounds, tiles, the per-point
dimensions by kind (coordinate, las, extra, ground_truth, result), which results
and ground truth exist, and the sources it was made from.  Given a point cloud
file instead (.las/.laz, .ply, .pcd, .e57, text) or an S3DIS folder: its format,
point count, bounds (LAS), grid, CRS and the dimensions ingest would store,
from the header alone.  --json prints the same as one JSON document (for
scripts).

examples:
  buildingparser info building.zarr
  buildingparser info s3://bucket/area1.zarr --json
  buildingparser info scan.laz
"""


def configure(parser: argparse.ArgumentParser) -> None:
    from engine.cli.options import add_storage_options

    parser.add_argument("store", metavar="PATH", help="a tile store, a point cloud file or an S3DIS folder (path or URL)")
    parser.add_argument("--json", action="store_true", help="print JSON instead of text")
    add_storage_options(parser)


def run(args: argparse.Namespace) -> int:
    from tiles import paths
    from tiles.info import file_info, format_file_info, format_info, store_info
    from tiles.store import open_store

    path = paths.normalize(args.store)
    if path.rstrip("/").endswith(".zarr") or paths.exists(paths.join(path, "zarr.json"), args.storage_options):
        info = store_info(open_store(args.store, args.storage_options))
        print(json.dumps(info, indent=2) if args.json else format_info(info))
    else:
        info = file_info(args.store, args.storage_options)
        print(json.dumps(info, indent=2, default=str) if args.json else format_file_info(info))
    return 0
