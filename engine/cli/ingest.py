"""``buildingparser ingest SRC... STORE``: read point clouds into a new tile store."""
from __future__ import annotations

import argparse
import sys

NAME = "ingest"
HELP = "read LAS/LAZ, S3DIS folders, text or E57 point clouds into a tile store"
ORDER = 10
DESCRIPTION = """\
Read one or more point clouds into a new tile store (a Zarr folder or URL).

Inputs (local paths or fsspec URLs such as s3://bucket/scan.laz):
  .las .laz           every point and dimension (bit fields, gps_time, colour, NIR,
                      extra bytes); scale, offset, CRS and VLRs are kept for export
  S3DIS folder        an Area_N folder, a folder of areas or one room: annotation
                      files become ground truth (gt_space, gt_class, gt_instance)
  .txt .xyz .pts .csv .asc
                      one point per line: x y z or x y z r g b (space or comma)
  .e57                every scan with its pose applied (needs pye57)
  .ply                the vertices, binary or ASCII, every property kept (colour as
                      LAS colour, a 16-bit intensity as LAS intensity, the rest as
                      extra dimensions); a mesh's faces are not points
  .pcd                PCL's ascii, binary and binary_compressed; packed rgb as
                      colour, every other field as an extra dimension

Several inputs go into one store in the order given; see 'tiles.ingest' for how
different point formats and scales are combined.  Points read = points stored,
always; the command prints the count and the rate.

examples:
  buildingparser ingest building.laz building.zarr
  buildingparser ingest Stanford3dDataset_v1.2/Area_1 area1.zarr --tile-size 20
  buildingparser ingest s3://bucket/scan.laz s3://bucket/scan.zarr --scheduler tls://head:8786
  buildingparser ingest campus.copc.laz hall.zarr --bounds 512300 5402100 512420 5402180
"""


def configure(parser: argparse.ArgumentParser) -> None:
    from engine.cli.options import add_cluster_options, add_storage_options

    parser.add_argument("sources", nargs="+", metavar="SRC", help="input files or S3DIS folders")
    parser.add_argument("store", metavar="STORE", help="the tile store to create (path or URL)")
    parser.add_argument("--overwrite", action="store_true", help="replace STORE if it exists")
    parser.add_argument("--tile-size", type=float, metavar="M",
                        help="tile edge in metres (default: buildingparser.tiles.size, 10)")
    parser.add_argument("--part-points", type=int, metavar="N",
                        help="points read by one task (default: buildingparser.ingest.part-points)")
    parser.add_argument("--bounds", type=float, nargs=4, metavar=("XMIN", "YMIN", "XMAX", "YMAX"),
                        help="only the points inside this box (the inputs' x, y, inclusive): a COPC file is read "
                             "by bounds, only the octree nodes the box meets")
    parser.add_argument("--skip-bad-lines", action="store_true",
                        help="skip (and count) text lines that cannot be read instead of stopping")
    add_storage_options(parser)
    add_cluster_options(parser)


def run(args: argparse.Namespace) -> int:
    import dask

    from engine.pipeline.cluster import check_reachable, cluster_client
    from tiles.ingest import ingest, precheck
    from tiles.ingest.bounds import Bounds

    Bounds.parse(args.bounds)  # bad bounds are refused before the cluster starts
    precheck(args.sources, args.store, overwrite=args.overwrite, storage_options=args.storage_options)
    settings = {"buildingparser.ingest.bad-lines": "skip"} if args.skip_bad_lines else {}
    with dask.config.set(settings), cluster_client(args.scheduler, n_workers=args.workers,
                                                   memory_limit=args.memory_limit) as client:
        check_reachable(client, *args.sources, args.store)
        store = ingest(args.sources, args.store, client=client, overwrite=args.overwrite,
                       tile_size=args.tile_size, part_points=args.part_points,
                       storage_options=args.storage_options, bounds=args.bounds)
    rep = store.ingest_report
    print(f"ingested {rep['points']:,} points from {rep['sources']} source(s) into {store.url}: "
          f"{rep['tiles']} tiles, {rep['seconds']:.1f} s, {rep['points_per_second']:,.0f} points/s")
    if "outside" in rep:
        print(f"left out: {rep['outside']:,} points outside the bounds {' '.join(f'{v:g}' for v in rep['bounds'])}")
    sys.stdout.flush()
    return 0
