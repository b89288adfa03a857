"""Synthetic buildings with exact ground truth, at any scale (``buildingparser synth``).

The two halves are public so that tests and benchmarks can build small
buildings in-process: :func:`plan_building` (the plan: spaces, walls with
openings, elements made of primitives) and :func:`scan_part` /
:func:`scan_building` (the per-point columns of one part / of all parts).
:func:`generate` does both and writes a tile store, a LAS/LAZ file or the raw
S3DIS layout, one dask task per part.

Modules: :mod:`~engine.synth.plan` (the building, floor by floor) with
:mod:`~engine.synth.streams` (random streams), :mod:`~engine.synth.layout`
(cells of a floor), :mod:`~engine.synth.rooms` (room types and heights),
:mod:`~engine.synth.walls` (walls on grid lines), :mod:`~engine.synth.shapes`
(walls of polygons, local frames), :mod:`~engine.synth.openings` (where doors
and windows go), :mod:`~engine.synth.parts` (scan tasks);
:mod:`~engine.synth.structure` (floor, ceiling, columns, beams, lights) with
:mod:`~engine.synth.faces` (wall faces) and :mod:`~engine.synth.frames` (door
and window elements); :mod:`~engine.synth.furniture` (room recipes) with
:mod:`~engine.synth.pieces` and :mod:`~engine.synth.placer`;
:mod:`~engine.synth.scanners`, :mod:`~engine.synth.colours`,
:mod:`~engine.synth.geometry` (the primitives), :mod:`~engine.synth.scan`,
:mod:`~engine.synth.writers`, :mod:`~engine.synth.draw`, :mod:`~engine.synth.api`.

Where harder, real-scan conditions plug in (not built yet): walls are general
segments with a thickness and footprints come from shapely polygon algebra, so
diagonal or curved (polyline) walls only need a layout that emits them; a
per-space rigid perturbation before ``Frame.xyz`` in ``scan_job`` gives
registration offsets; a wall ``kind`` with glass-density faces gives glass
partitions; a space flag that makes ``scan_job`` return nothing gives unscanned
rooms; density/count knobs of ``furnish`` give heavy clutter and walls hidden by
furniture; clutter panels (as WC stalls) give cubicles; thickness ranges in
``walls.grid_walls`` give very thin or thick walls; outliers along the scanner rays
in ``scan_job`` give flying points; a ``stairs`` space with step boxes and a slab
opening gives stairs.
"""
from engine.synth.api import generate
from engine.synth.building import Building, Element, Frame, Opening, PartSpec, Space, Wall
from engine.synth.plan import plan_building
from engine.synth.scan import scan_building, scan_part

__all__ = ["generate", "plan_building", "scan_part", "scan_building", "Building", "Element", "Frame", "Opening",
           "PartSpec", "Space", "Wall"]
