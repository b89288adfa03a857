"""The stair of a stair tower (hardness ``stairs``): landings, two flights and the slabs around the well.

A stair tower stands at the west end of the main hallway on every floor; its
space of one floor reaches from that floor's level to the next floor's
(``Space.stairs["rise"]``), so the tower is a shaft through the slabs.  In the
space's own frame its footprint's bounding box is cut along x into the
*landing* at the near end (east, the door to the hallway or lobby), the
*flights* and the *half landing* at the far end; the flights run side by side:
flight 1 (south half) rises from the landing to the half landing, flight 2
(north half) from the half landing back to the next floor's landing.

* floor: the whole footprint on the ground floor; above, the slab of the floor
  around the well (landing, flight-1 half, half landing): the well over flight 2
  of the storey below is open;
* ceiling: the underside of the next floor's slab around the well (the top
  floor: a plain ceiling); the top floor's tower has no flight;
* the stair: one clutter instance (``kind: "stairs"``): solid steps of flight
  1, the half landing slab and the floating steps of flight 2;
* scan positions: on the landing and on the half landing.
"""
from __future__ import annotations

import numpy as np
import shapely
from shapely.geometry import Polygon, box
from shapely.geometry.polygon import orient

from engine.synth.building import Element, Space
from engine.synth.geometry import Box

LANDING = 1.2
RISER = 0.175
STEP_COLOUR = (160, 158, 152)


def _zones(space: Space) -> dict:
    lo, hi = space.footprint.min(0), space.footprint.max(0)
    return {"lo": lo, "hi": hi, "near": float(hi[0]), "far": float(lo[0]), "mid": float((lo[1] + hi[1]) / 2)}


def _xy(geom) -> np.ndarray:
    if geom.geom_type != "Polygon":
        geom = max(geom.geoms, key=lambda g: g.area)
    return np.asarray(orient(geom, 1.0).exterior.coords)[:-1]


def stair_slabs(space: Space) -> tuple[np.ndarray, np.ndarray, float]:
    """Floor polygon, ceiling polygon and ceiling height of one floor's space of a stair tower."""
    st, z = space.stairs, _zones(space)
    fp = Polygon(space.footprint)
    lo, hi, near, far, mid = z["lo"], z["hi"], z["near"], z["far"], z["mid"]
    around = shapely.union_all([box(near - LANDING, lo[1], near, hi[1]), box(far, lo[1], near, mid),
                                box(far, lo[1], far + LANDING, hi[1])]).intersection(fp)
    floor = space.footprint.copy() if not st["below"] else _xy(around)
    if st["top"]:
        return floor, space.footprint.copy(), space.z1
    return floor, _xy(around), space.z1 - 0.2


def stair_elements(space: Space) -> None:
    """The stair of a non-top floor's tower space (see the module docstring)."""
    st, z = space.stairs, _zones(space)
    if st["top"]:
        return
    lo, hi, near, far, mid = z["lo"], z["hi"], z["near"], z["far"], z["mid"]
    z0, rise = space.z0, float(st["rise"])
    n = max(6, int(round(rise / 2 / RISER)))
    r = rise / (2 * n)
    run = (near - LANDING) - (far + LANDING)
    td = run / n
    boxes = []
    y0, y1 = lo[1] + 0.02, mid - 0.05
    for k in range(1, n + 1):  # flight 1: solid steps
        xh = near - LANDING - (k - 1) * td
        top = z0 + k * r
        boxes.append(Box(np.array([xh - td / 2, (y0 + y1) / 2, (z0 + top) / 2]), np.array([td, y1 - y0, top - z0]),
                         0.0, STEP_COLOUR, jitter=5.0))
    half = z0 + rise / 2
    boxes.append(Box(np.array([far + LANDING / 2 + 0.01, (lo[1] + hi[1]) / 2, half - 0.1]),
                     np.array([LANDING - 0.02, hi[1] - lo[1] - 0.04, 0.2]), 0.0, STEP_COLOUR, jitter=5.0))
    y0, y1 = mid + 0.05, hi[1] - 0.02
    for k in range(1, n + 1):  # flight 2: floating steps
        xl = far + LANDING + (k - 1) * td
        top = half + k * r
        th = r + 0.12
        boxes.append(Box(np.array([xl + td / 2, (y0 + y1) / 2, top - th / 2]), np.array([td, y1 - y0, th]),
                         0.0, STEP_COLOUR, jitter=5.0))
    space.elements.append(Element(-1, "clutter", space.id, boxes, info={"kind": "stairs"}))


def stair_scanners(space: Space, rng: np.random.Generator) -> None:
    """Scan positions on the landing and (below the top floor) on the half landing."""
    st, z = space.stairs, _zones(space)
    cy = (z["lo"][1] + z["hi"][1]) / 2
    pts = [[z["near"] - LANDING / 2, cy, space.z0 + rng.uniform(1.35, 1.65)]]
    if not st["top"]:
        pts.append([z["far"] + LANDING / 2, cy, space.z0 + st["rise"] / 2 + rng.uniform(1.35, 1.65)])
    space.scanners = np.asarray(pts, float)
