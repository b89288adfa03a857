"""Synthetic buildings with exact ground truth, at any scale (``buildingparser synth``).

The two halves are public so that tests and benchmarks can build small
buildings in-process: :func:`plan_building` (the plan: spaces, walls with
openings, elements made of primitives) and :func:`scan_part` /
:func:`scan_building` (the per-point columns of one part / of all parts).
:func:`generate` does both and writes a tile store, a LAS/LAZ file or the raw
S3DIS layout, one dask task per part.
"""
from engine.synth.api import generate
from engine.synth.building import Building, Element, Frame, Opening, PartSpec, Space, Wall
from engine.synth.plan import plan_building
from engine.synth.scan import scan_building, scan_part

__all__ = ["generate", "plan_building", "scan_part", "scan_building", "Building", "Element", "Frame", "Opening",
           "PartSpec", "Space", "Wall"]
