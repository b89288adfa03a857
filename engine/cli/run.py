"""``buildingparser run INPUT --out DIR``: the whole pipeline, from a point cloud to spaces, elements and a report."""
from __future__ import annotations

import argparse
import logging

from engine.cli.options import add_cluster_options, add_storage_options

logger = logging.getLogger(__name__)

NAME = "run"
HELP = "parse a building end to end: spaces, elements, points.laz, report.html"
ORDER = 10
DESCRIPTION = """\
Parse a building's point cloud end to end (Armeni et al., CVPR 2016):
ingest into a tile store -> spaces (void-based dividers, merged over-segments)
-> per-space canonical frames and sliding-window detection -> CRF -> space
update from the detected walls -> per-point labels -> outputs and metrics.

Writes into DIR: points.laz (every input point, input order, all input
dimensions plus classification = 64 + class code, element_class, space_id,
element_id), points.copc.laz (the same points as a COPC octree for web
viewers and QGIS), spaces.geojson and spaces.gpkg (in the input's CRS),
floorplan.png, elements.json, metrics.json (ARI and AP when the input has
ground truth), report.html, buildingparser.log (every message of the run,
with timestamps), and store.zarr (the tile store) unless INPUT is a store
already. A rerun skips the stages whose inputs and settings have not
changed (--force redoes them).

examples:
  buildingparser run scan.laz --out results/
  buildingparser run s3://bucket/area.laz --out s3://bucket/results --scheduler tcp://cluster:8786
  buildingparser run Area_1/ --out area1/ --workers 2 --memory-limit 8GiB
  buildingparser run s3://bucket/campus.copc.laz --out hall/ --bounds 512300 5402100 512420 5402180
"""


def configure(p: argparse.ArgumentParser) -> None:
    p.add_argument("input", metavar="INPUT",
                   help="point cloud (.las/.laz, .ply, .pcd, .txt/.xyz/.pts, .e57, an S3DIS Area folder) or a tile store")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder (created if missing)")
    p.add_argument("--model", metavar="MODEL",
                   help="detection model (MODEL.npz + MODEL.json); default: the shipped model, or the shipped "
                        "colour-free one for a cloud without colour (...detection.colour-free-model)")
    p.add_argument("--store", metavar="STORE", help="where to build the tile store (default DIR/store.zarr)")
    p.add_argument("--tile-size", type=float, metavar="M", help="tile edge in metres for a new store")
    p.add_argument("--bounds", type=float, nargs=4, metavar=("XMIN", "YMIN", "XMAX", "YMAX"),
                   help="only the points inside this box (the input's x, y; a COPC file is read by bounds)")
    p.add_argument("--force", action="store_true", help="redo every stage even when its earlier result is current")
    p.add_argument("--no-crf", action="store_true", help="keep every detection proposal (skip the CRF)")
    p.add_argument("--no-update", action="store_true", help="do not update the spaces from detected walls")
    p.add_argument("--no-points", action="store_true", help="do not write points.laz (nor points.copc.laz)")
    p.add_argument("--no-copc", action="store_true",
                   help="do not write points.copc.laz, the COPC octree for web viewers (buildingparser.outputs.copc)")
    p.add_argument("--no-ifc", action="store_true", help="do not write building.ifc (buildingparser.outputs.ifc)")
    p.add_argument("--no-viewer", action="store_true",
                   help="do not write viewer.html, the 3D view (buildingparser.outputs.viewer)")
    add_storage_options(p)
    add_cluster_options(p)


def run(args: argparse.Namespace) -> int:
    import contextlib

    import dask

    from engine.cli.logs import run_log
    from engine.pipeline.cluster import cluster_client, scheduler_address
    from engine.pipeline.clusterstart import ClusterStart

    # the cluster starts in a thread while the run imports the engine, checks the input, claims DIR and loads
    # the model; the run waits for it before its first distributed work.  A user error on the way leaves
    # nothing: the cluster is closed (once up) and DIR not made.
    with ClusterStart(lambda: cluster_client(args.scheduler, n_workers=args.workers,
                                             memory_limit=args.memory_limit)) as starting:
        from engine.pipeline.context import check_run_inputs
        from engine.pipeline.outfolder import claim_output_folder
        from engine.pipeline.results import summary_lines
        from engine.pipeline.run import RunSettings
        from engine.pipeline.run import run as run_pipeline

        options = RunSettings(model=args.model, store=args.store, force=args.force, crf=not args.no_crf,
                              update=not args.no_update, export_points=not args.no_points,
                              tile_size=args.tile_size, storage_options=args.storage_options, bounds=args.bounds)
        check_run_inputs(args.input, options)  # a missing input is refused before DIR is made
        if scheduler_address(args.scheduler):  # an existing cluster: only connecting, which may fail (one line)
            starting.client()  # ... before DIR is made
        # the output folder next: unwritable, taken by another run or holding the user's files -> one line, no work
        with claim_output_folder(args.out, force=args.force), run_log(args.out, args.storage_options):
            logger.debug("run %s --out %s: %s", args.input, args.out, options)
            off = {f"buildingparser.outputs.{k}": False for k, no in (("ifc", args.no_ifc),
                                                                       ("viewer", args.no_viewer),
                                                                       ("copc", args.no_copc)) if no}
            with dask.config.set(off) if off else contextlib.nullcontext():
                metrics = run_pipeline(args.input, args.out, client=starting, options=options)
                lines = summary_lines(metrics, args.out)
    print("\n".join(lines))
    return 0
