"""``buildingparser synth OUT``: generate a synthetic building scan with exact ground truth."""
from __future__ import annotations

import argparse
import sys

NAME = "synth"
HELP = "generate a synthetic building scan with exact ground truth (store, LAS/LAZ or S3DIS layout)"
ORDER = 5
DESCRIPTION = """\
Generate the coloured point cloud of a synthetic building, with exact ground truth
per point (space, class, element instance) and per element (class, space, box).

Each floor is a plan of rooms, hallways, a lobby, L-shaped rooms and an open-plan
space split by a partial wall; walls 0.1-0.35 m thick with doors (open or closed
leaves) joining every space, windows on exterior walls, columns, beams, and the
furniture and clutter of each room type (office, conferenceRoom, hallway, lobby,
storage, WC, openspace).  Floors stack with a slab and a ceiling void between them.
Only what a scanner inside each space sees gets points: wall faces but never the
inside of a wall, no floor under a bookcase, no wall behind it.

Density: points per m^2 of scanned surface, before each space's own factor
(x0.5 to x2).  The default (buildingparser.synth.density, 8000) gives about
35 000 points per m^2 of floor, as S3DIS (215 M points over 6 020 m^2).

Formats (--format, default: laz if OUT ends in .las/.laz, else store):
  store   a tile store with gt_space, gt_class, gt_instance and meta/ground_truth
  laz     one LAS 1.4 point format 7 file (.las or .laz) with gt_* extra bytes,
          and gt.json (the ground-truth document) beside it
  s3dis   OUT/Area_1/<space>/<space>.txt and Annotations/<class>_<i>.txt, as the
          raw S3DIS dataset, and OUT/gt.json

examples:
  buildingparser synth demo.zarr --rooms 12 --png demo.png
  buildingparser synth big.zarr --area-m2 6000 --seed 3
  buildingparser synth tower.laz --area-m2 2400 --floors 3 --yaw 30 --offset 500000 4100000 30
  buildingparser synth s3dis_like --format s3dis --area-m2 900 --density 2000
  buildingparser synth hard.zarr --area-m2 900 --floors 2 --hard
  buildingparser synth glassy.zarr --area-m2 600 --hard glass,registration=0.5
  buildingparser synth b1100.zarr --seed 1100 --area-m2 250 --training-yaw   # as make model's
"""


def configure(parser: argparse.ArgumentParser) -> None:
    from engine.cli.options import STYLES_HELP, add_cluster_options, add_storage_options, styles

    parser.add_argument("out", metavar="OUT", help="tile store (path or URL), .las/.laz file, or S3DIS folder")
    parser.add_argument("--seed", type=int, default=0, metavar="N", help="random seed: same seed, same building "
                                                                         "and points (default 0)")
    size = parser.add_mutually_exclusive_group()
    size.add_argument("--area-m2", type=float, metavar="A",
                      help="gross floor area of the whole building in m^2, all floors "
                           "(default: buildingparser.synth.area-m2, 300)")
    size.add_argument("--rooms", type=int, metavar="R",
                      help="number of spaces of the whole building, hallways included (met exactly when room "
                           "sizes allow); the area follows from it")
    parser.add_argument("--floors", type=int, default=1, metavar="F", help="storeys (default 1)")
    parser.add_argument("--density", type=float, metavar="D",
                        help="points per m^2 of scanned surface before each space's x0.5-x2 factor "
                             "(default: buildingparser.synth.density, 8000: S3DIS-like)")
    turn = parser.add_mutually_exclusive_group()
    turn.add_argument("--yaw", type=float, default=0.0, metavar="DEG",
                      help="rotate the whole building by DEG degrees about the vertical (default 0)")
    turn.add_argument("--training-yaw", action="store_true",
                      help="the yaw that `train --synthetic` gives the building of this seed "
                           "(engine.training.train.synthetic_yaw): the same building as train generates")
    parser.add_argument("--offset", type=float, nargs=3, default=(0.0, 0.0, 0.0), metavar=("X", "Y", "Z"),
                        help="world position of the building's local origin, e.g. 500000 4100000 30 (default 0 0 0)")
    parser.add_argument("--format", choices=("store", "laz", "s3dis"),
                        help="output format (default: laz if OUT ends in .las/.laz, else store)")
    parser.add_argument("--png", metavar="FILE", help="also draw the plan (spaces by ground truth, element boxes) "
                                                      "to this PNG")
    parser.add_argument("--overwrite", action="store_true", help="replace OUT (and gt.json) if it exists")
    parser.add_argument("--hard", nargs="?", const="all", default=None, metavar="LIST",
                        help="add the difficulties of real scans: all of them (--hard), or some "
                             "(--hard registration,glass; name=level for a level 0-2); see "
                             "engine.synth.hard.hardness: registration, glass, unscanned, hidden_walls, wing, oblique, "
                             "bottlenecks, open_plan, walls, clutter, stairs, artefacts")
    parser.add_argument("--styles", type=styles, default="classic", metavar="STYLES", help=STYLES_HELP)
    parser.add_argument("--part-points", type=int, metavar="N",
                        help="largest estimated point count of one task; bigger spaces are cut into pieces "
                             "(default: buildingparser.synth.part-points)")
    add_storage_options(parser)
    add_cluster_options(parser)


def run(args: argparse.Namespace) -> int:
    from engine.pipeline.cluster import cluster_client
    from engine.synth import generate
    from engine.synth.plan import check_parameters
    from engine.synth.writers import precheck

    fmt = args.format or ("laz" if args.out.lower().endswith((".las", ".laz")) else "store")
    if args.training_yaw:
        from engine.training.synthetic import synthetic_yaw

        args.yaw = synthetic_yaw(args.seed)
    check_parameters(area_m2=args.area_m2, rooms=args.rooms, floors=args.floors, density=args.density, yaw=args.yaw,
                     offset=args.offset, hardness=args.hard)
    precheck(args.out, fmt, overwrite=args.overwrite, storage_options=args.storage_options)
    with cluster_client(args.scheduler, n_workers=args.workers, memory_limit=args.memory_limit) as client:
        r = generate(args.out, seed=args.seed, area_m2=args.area_m2, rooms=args.rooms, floors=args.floors,
                     density=args.density, yaw=args.yaw, offset=tuple(args.offset), format=fmt, png=args.png,
                     client=client, overwrite=args.overwrite, part_points=args.part_points,
                     storage_options=args.storage_options, hardness=args.hard, styles=args.styles)
    print(f"generated {r['points']:,} points of {r['spaces']} spaces and {r['elements']:,} elements "
          f"({r['floor_area_m2']:,.0f} m2 of floor) into {r['out']} ({r['format']}): "
          f"{r['seconds']:.1f} s, {r['points_per_second']:,.0f} points/s")
    if args.png:
        print(f"plan drawn to {args.png}")
    sys.stdout.flush()
    return 0
