"""``buildingparser edit RUN_FOLDER --merge A B`` / ``--split A --line X0 Y0 X1 Y1``: space manipulation."""
from __future__ import annotations

import argparse
import logging

NAME = "edit"
HELP = "merge spaces (removing the wall between them) or split a space by a line, in a finished run"
ORDER = 35
DESCRIPTION = """\
Edit the spaces of a finished run (paper Sec. 1, space manipulation) and write
the edited run into another folder: spaces.geojson, elements.json, a new
points.laz (every point in its order, space_id updated; the points of removed
walls, doors and windows dropped), the statistics, floorplan.png/.svg,
metrics.json (with an "edit" record; the run's scores kept under edit.before)
and report.html.  The run folder itself is not touched unless --in-place.

--merge A B ...   the spaces (of one storey, touching) become one, with the
                  smallest id; the walls on their shared boundary, and the doors
                  and windows in them, are removed; one floor and one ceiling
                  per height
--split A --line X0 Y0 X1 Y1
                  cut space A by the line through the two points (world
                  coordinates): the part left of the line keeps A, the other
                  gets a new id

examples:
  buildingparser edit results/ --merge 3 7 --out results-merged/
  buildingparser edit results/ --split 4 --line 10.0 2.5 10.0 9.0
"""
logger = logging.getLogger(__name__)


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("run_folder", metavar="RUN_FOLDER", help="the output folder of a finished run")
    what = parser.add_mutually_exclusive_group(required=True)
    what.add_argument("--merge", type=int, nargs="+", metavar="ID", help="spaces to merge (two or more)")
    what.add_argument("--split", type=int, metavar="ID", help="the space to split (with --line)")
    parser.add_argument("--line", type=float, nargs=4, metavar=("X0", "Y0", "X1", "Y1"),
                        help="the cutting line of --split, two points in world coordinates")
    parser.add_argument("--out", metavar="FOLDER",
                        help="where the edited run goes (default: RUN_FOLDER-edit, a new folder)")
    parser.add_argument("--in-place", action="store_true", help="allow --out to be RUN_FOLDER itself")


def run(args: argparse.Namespace) -> int:
    import os

    from engine.outputs.edit import edit_run

    out = args.out or os.path.normpath(args.run_folder) + "-edit"
    record = edit_run(args.run_folder, out, merge=args.merge, split=args.split, line=args.line,
                      in_place=args.in_place)
    if "merge" in record:
        logger.info("merged spaces %s into %d; removed %d elements (%s points)", record["merge"], record["space"],
                    len(record["removed_elements"]), f"{record['points_removed']:,}")
    else:
        logger.info("split space %d: new space %d", record["split"], record["new_space"])
    logger.info("edited run: %s", out)
    return 0
