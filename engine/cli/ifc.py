"""``buildingparser ifc OUT_FOLDER``: write ``building.ifc`` for a finished (or edited) run."""
from __future__ import annotations

import argparse
import logging

NAME = "ifc"
HELP = "write building.ifc (IFC4: storeys, spaces, detected elements) for a finished run's folder"
ORDER = 36
DESCRIPTION = """\
Write the run folder's building model, building.ifc (IFC4), from its
spaces.geojson and elements.json: one storey per storey of the parse, an
IfcSpace per space (its footprint extruded from floor to ceiling, with area and
volume), and the detected elements as IfcWall, IfcSlab (floors), IfcCovering
(ceilings), IfcBeam, IfcColumn, IfcDoor, IfcWindow and IfcFurniture, each in its
storey and referenced by its space; the input's CRS as the map conversion when
known.  'run' writes it already (unless --no-ifc); use this for an edited run.

examples:
  buildingparser ifc results/
  buildingparser ifc merged/ --validate
"""
logger = logging.getLogger(__name__)


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("folder", metavar="OUT_FOLDER", help="a finished run's output folder")
    parser.add_argument("--validate", action="store_true",
                        help="check the written file against the IFC4 schema (ifcopenshell.validate) and report")


def run(args: argparse.Namespace) -> int:
    from engine.outputs.ifc import write_ifc

    path = write_ifc(args.folder)
    logger.info("building.ifc: %s", path)
    if args.validate:
        import ifcopenshell
        import ifcopenshell.validate

        log = ifcopenshell.validate.json_logger()
        ifcopenshell.validate.validate(ifcopenshell.open(path), log, express_rules=True)
        for s in log.statements[:20]:
            logger.error("%s", s.get("message", s))
        logger.info("schema validation: %d issue(s)", len(log.statements))
        return 1 if log.statements else 0
    return 0
