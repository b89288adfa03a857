"""``buildingparser export STORE OUT.laz``: write a tile store back to LAS 1.4 or LAZ."""
from __future__ import annotations

import argparse

NAME = "export"
HELP = "write a tile store as LAS 1.4 / LAZ (or COPC), with results and ground truth"
ORDER = 90
DESCRIPTION = """\
Write a tile store as a LAS 1.4 (.las) or LAZ (.laz) file, in the input's point
order, with every input dimension and the results the store holds:

  classification      64 + the class code (64 ceiling ... 76 clutter: LAS 1.4's
                      user-definable range), named by a Classification Lookup
                      VLR; the source's own classification is kept as the
                      extra-bytes dimension source_classification; a legacy
                      point format (0-5) is raised to its LAS 1.4 twin (6-10)
  element_class       the class code 0-12 (S3DIS order), extra-bytes uint8
  space_id, element_id
                      extra-bytes int32 dimensions (-1: none)
  gt_space, gt_class, gt_instance
                      ground truth, as extra-bytes dimensions

The point format is the source's (7 for text, S3DIS and E57 sources), with its
scale, offset, CRS and VLRs.  8-bit colours of non-LAS sources are written as
16-bit v*257 (exactly reversible: v = c // 257).

An OUT ending in .copc.laz is written as COPC (copc.io): the same points and
dimensions arranged in an octree for web viewers and QGIS, point format 6, 7
or 8 (buildingparser.copc.node-points, buildingparser.copc.group-points).

examples:
  buildingparser export building.zarr building-parsed.laz
  buildingparser export s3://bucket/area1.zarr s3://bucket/area1.laz
  buildingparser export building.zarr building.copc.laz
"""


def configure(parser: argparse.ArgumentParser) -> None:
    from engine.cli.options import add_cluster_options, add_storage_options

    parser.add_argument("store", metavar="STORE", help="the tile store (path or URL)")
    parser.add_argument("out", metavar="OUT", help="output .las, .laz or .copc.laz (path or URL)")
    parser.add_argument("--overwrite", action="store_true", help="replace OUT if it exists")
    parser.add_argument("--point-format", type=int, metavar="ID", choices=range(11),
                        help="LAS point format to write (default: the source's, 7 without a LAS source)")
    add_storage_options(parser)
    add_cluster_options(parser)


def run(args: argparse.Namespace) -> int:
    from engine.pipeline.cluster import check_reachable, cluster_client
    from tiles import copc
    from tiles.export import export, precheck
    from tiles.store import open_store

    store = open_store(args.store, args.storage_options)
    as_copc = copc.is_copc_name(args.out)
    (copc.precheck if as_copc else precheck)(args.out, overwrite=args.overwrite, storage_options=args.storage_options)
    write = copc.write_copc if as_copc else export
    with cluster_client(args.scheduler, n_workers=args.workers, memory_limit=args.memory_limit) as client:
        check_reachable(client, args.store)
        rep = write(store, args.out, client=client, overwrite=args.overwrite, point_format=args.point_format,
                    storage_options=args.storage_options)
    if as_copc:
        what = f"COPC, point format {rep['point_format']}, {rep['nodes']:,} octree nodes in {rep['levels']} levels"
    else:
        extra = f", extra bytes: {', '.join(rep['extra_dimensions'])}" if rep["extra_dimensions"] else ""
        what = f"point format {rep['point_format']}{extra}"
    print(f"exported {rep['points']:,} points to {rep['path']} ({what}): "
          f"{rep['seconds']:.1f} s, {rep['points_per_second']:,.0f} points/s")
    return 0
