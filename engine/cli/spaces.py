"""``buildingparser spaces STORE``: parse a tile store into spaces (paper section 3)."""
from __future__ import annotations

import argparse
import logging

logger = logging.getLogger(__name__)

NAME = "spaces"
HELP = "parse a tile store into spaces (rooms, hallways): cell_id and space_id per point"
ORDER = 30
DESCRIPTION = """\
Parse the building of a tile store into disjoint spaces with void-based
peak-gap-peak dividers (Armeni et al. 2016, section 3): align the building's
axes, cut it at storey slabs and walls into over-segmented cells, merge cells
with no divider across their shared face.  Writes cell_id and space_id per
point into the store and the document meta/spaces (frame, storeys, cells,
dividers, spaces with footprints and shared faces); prints the number of
spaces, and the Adjusted Rand Index of spaces and cells when the store has
ground truth (gt_space).  Settings: buildingparser.spaces.* (engine/spaces/spaces.yaml).

examples:
  buildingparser spaces building.zarr --png floorplan.png --geojson spaces.geojson --gpkg spaces.gpkg
  buildingparser spaces s3://bucket/area1.zarr --scheduler tcp://10.0.0.5:8786
"""


def configure(parser: argparse.ArgumentParser) -> None:
    from engine.cli.options import add_cluster_options, add_storage_options

    parser.add_argument("store", metavar="STORE", help="the tile store (path or URL)")
    parser.add_argument("--png", metavar="FILE", help="also draw the floor plan to FILE (PNG)")
    parser.add_argument("--geojson", metavar="FILE", help="also write the spaces' footprints to FILE (GeoJSON)")
    parser.add_argument("--gpkg", metavar="FILE", help="also write the spaces' footprints to FILE (GeoPackage)")
    parser.add_argument("--yaw", type=float, metavar="DEGREES",
                        help="use this yaw of the building's first axis instead of estimating it")
    add_cluster_options(parser)
    add_storage_options(parser)


def run(args: argparse.Namespace) -> int:
    from engine.metrics.ari import distributed_ari
    from engine.outputs.floorplan import draw_floorplan
    from engine.outputs.geojson import spaces_feature_collection, write_spaces_geojson, write_spaces_gpkg
    from engine.pipeline.cluster import check_reachable, cluster_client
    from engine.spaces.parse import parse_spaces
    from engine.spaces.settings import SpaceSettings
    from tiles.crs import parse_crs
    from tiles.store import open_store

    store = open_store(args.store, args.storage_options)
    params = SpaceSettings.from_config(**({"yaw": args.yaw} if args.yaw is not None else {}))
    with cluster_client(args.scheduler, n_workers=args.workers, memory_limit=args.memory_limit) as client:
        check_reachable(client, store.url)
        parse = parse_spaces(store, client=client, params=params)
        print(f"{len(parse.spaces)} spaces in {len(parse.floors)} storey(s) from {len(parse.cells)} cells "
              f"(yaw {parse.frame.to_json()['yaw_deg']:.2f} deg, {parse.stats['seconds']['total']:.1f} s)")
        if "gt_space" in store.refresh().meta.names():
            final = distributed_ari(store, "gt_space", "space_id", client=client)
            over = distributed_ari(store, "gt_space", "cell_id", client=client)
            print(f"ARI final {final:.4f}, over-segmented {over:.4f}")
        if args.geojson:
            logger.info("spaces: %s", write_spaces_geojson(parse, args.geojson, parse_crs(store.meta.crs)))
        if args.gpkg:
            crs = parse_crs(store.meta.crs)
            logger.info("spaces: %s", write_spaces_gpkg(spaces_feature_collection(parse, crs), args.gpkg, crs))
        if args.png:
            logger.info("floor plan: %s", draw_floorplan(store, parse, args.png, client=client))
    return 0
