"""``buildingparser demo``: generate a building with ground truth and run the whole pipeline on it."""
from __future__ import annotations

import argparse
import os

from engine.cli.options import add_cluster_options

NAME = "demo"
HELP = "generate a building with ground truth (or take INPUT) and run the whole pipeline on it"
ORDER = 1
DESCRIPTION = """\
Generate a small synthetic building with exact ground truth as a LAZ file
(OUT/input/building.laz and its gt.json), then run the whole pipeline on it
and print the number of spaces, the ARI, the mAP and per-class AP, and where
the results are (OUT/report.html first; OUT/buildingparser.log keeps every
message of the run). Give INPUT to run on your own file.
This is what 'make demo' runs.
"""


def configure(p: argparse.ArgumentParser) -> None:
    p.add_argument("input", nargs="?", metavar="INPUT", help="a point cloud to use instead of a generated building")
    p.add_argument("--out", default="demo-output", metavar="DIR", help="output folder (default: demo-output)")
    p.add_argument("--seed", type=int, default=7, help="seed of the generated building (default 7)")
    p.add_argument("--area-m2", type=float, default=250.0, metavar="A",
                   help="floor area of the generated building in m^2 (default 250)")
    p.add_argument("--force", action="store_true", help="regenerate and redo every stage")
    add_cluster_options(p)


def run(args: argparse.Namespace) -> int:
    from engine.cli.logs import run_log
    from engine.pipeline.cluster import cluster_client
    from engine.pipeline.outfolder import claim_output_folder
    from engine.pipeline.results import summary_lines
    from engine.pipeline.run import RunSettings
    from engine.pipeline.run import run as run_pipeline
    from engine.synth import generate

    out = os.path.abspath(args.out)
    with claim_output_folder(out, force=args.force), run_log(out), \
            cluster_client(args.scheduler, n_workers=args.workers, memory_limit=args.memory_limit) as client:
        source = args.input
        if source is None:
            source = os.path.join(out, "input", "building.laz")
            if args.force or not os.path.exists(source):
                info = generate(source, seed=args.seed, area_m2=args.area_m2, format="laz", client=client,
                                overwrite=True)
                print(f"generated: {info['points']:,} points, {info['spaces']} spaces -> {source}")
        metrics = run_pipeline(source, out, client=client, options=RunSettings(force=args.force))
    print("\n".join(summary_lines(metrics, out)))
    print(f"\nopen {os.path.join(out, 'report.html')} in a browser to see the results")
    return 0
