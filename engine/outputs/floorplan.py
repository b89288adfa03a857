"""The floor plan image: a top view of the spaces, one panel per storey, dividers drawn.

Each tile rasterises its points (world x, y) into the building's pixel grid
and keeps, per occupied pixel, its most frequent space and that count; the
driver keeps, per pixel, the label of the largest count over tiles.  The pixel
is at least ``floorplan.min-pixel`` metres and large enough that the longer
side of the plan stays under ``floorplan.max-pixels`` pixels, so the raster of
a 1 km building is a few million pixels.
"""
from __future__ import annotations

import math
import os
from typing import TYPE_CHECKING, Any

import numpy as np

from engine import config
from engine.spaces.alignment import Frame
from engine.spaces.document import SpaceParse
from tiles.store import TileStore
from tiles.tasks import run_tasks

if TYPE_CHECKING:
    from distributed import Client


def plan_pixel(extent: float, min_pixel: float | None = None, max_pixels: int | None = None) -> float:
    """Pixel size (m) for a plan whose longer side is ``extent`` metres."""
    min_pixel = float(min_pixel or config.setting("spaces.floorplan.min-pixel"))
    max_pixels = int(max_pixels or config.setting("spaces.floorplan.max-pixels"))
    return max(min_pixel, extent / max_pixels)


def _tile_raster(tile: str, store, lo: tuple[float, float], pixel: float, shape: tuple[int, int],
                 cell_floor: np.ndarray, n_spaces: int) -> dict[str, np.ndarray]:
    """Per occupied (floor, pixel) of one tile: the most frequent space (-1: unassigned) and its count."""
    xyz = store.xyz(tile, local=False)
    cols = store.read(tile, ["cell_id", "space_id"])
    cell = cols["cell_id"].astype(np.int64)
    keep = cell >= 0
    if not keep.any():
        return {"key": np.zeros(0, np.int64), "label": np.zeros(0, np.int64), "count": np.zeros(0, np.int64)}
    floor = cell_floor[cell[keep]]
    ix = np.clip(((xyz[keep, 0] - lo[0]) / pixel).astype(np.int64), 0, shape[1] - 1)
    iy = np.clip(((xyz[keep, 1] - lo[1]) / pixel).astype(np.int64), 0, shape[0] - 1)
    pix = (floor * shape[0] + iy) * shape[1] + ix
    lab = cols["space_id"][keep].astype(np.int64) + 1
    keys, counts = np.unique(pix * (n_spaces + 1) + lab, return_counts=True)
    p, lab = keys // (n_spaces + 1), keys % (n_spaces + 1) - 1
    order = np.lexsort((-counts, p))
    p, lab, counts = p[order], lab[order], counts[order]
    first = np.r_[True, p[1:] != p[:-1]]
    return {"key": p[first], "label": lab[first], "count": counts[first]}


def floorplan_raster(store: TileStore, parse: SpaceParse, *, client: Client | None = None,
                     pixel: float | None = None
                     ) -> tuple[np.ndarray, tuple[float, float], float]:
    """Label raster ``(floors, rows, cols)`` (-2 empty, -1 unassigned, else space id), its corner and pixel."""
    b = store.meta.bounds
    lo = (float(b[0]), float(b[1]))
    pixel = pixel or plan_pixel(max(b[3] - b[0], b[4] - b[1]))
    shape = (int(math.ceil((b[4] - b[1]) / pixel)) + 1, int(math.ceil((b[3] - b[0]) / pixel)) + 1)
    n_floors = max(1, len(parse.floors))
    cell_floor = np.array([c.floor for c in parse.cells], dtype=np.int64)
    tiles = [t.name for t in store.tiles]
    parts = run_tasks(_tile_raster, tiles, client=client, label="floor plan raster", keys=tiles,
                      extra_args=(store, lo, pixel, shape, cell_floor, len(parse.spaces)))
    key = np.concatenate([r["key"] for r in parts])
    lab = np.concatenate([r["label"] for r in parts])
    cnt = np.concatenate([r["count"] for r in parts])
    order = np.lexsort((-cnt, key))
    key, lab = key[order], lab[order]
    first = np.r_[True, key[1:] != key[:-1]] if len(key) else np.zeros(0, bool)
    raster = np.full(n_floors * shape[0] * shape[1], -2, dtype=np.int64)
    raster[key[first]] = lab[first]
    return raster.reshape(n_floors, shape[0], shape[1]), lo, pixel


def _colours(n: int) -> np.ndarray:
    """A qualitative colour per space (deterministic), in RGBA."""
    import matplotlib

    base = np.vstack([matplotlib.colormaps["tab20"](np.arange(20)), matplotlib.colormaps["tab20b"](np.arange(20)),
                      matplotlib.colormaps["Set3"](np.arange(12))])
    return base[np.arange(n) % len(base)]


def draw_floorplan(store: TileStore, parse: SpaceParse, path: str | os.PathLike, client: Client | None = None, *,
                   draw_dividers: bool = True, dpi: int = 150) -> str:
    """Draw the floor plan (spaces coloured, dividers drawn, ids written) to a PNG; returns the path."""
    from matplotlib.figure import Figure  # no pyplot: the caller's backend (a notebook's) is left alone
    from shapely.geometry import shape as to_shape

    raster, lo, pixel = floorplan_raster(store, parse, client=client)
    n_floors = raster.shape[0]
    colours = _colours(max(len(parse.spaces), 1))
    rgba = np.ones(raster.shape + (4,))
    occupied = raster >= 0
    rgba[occupied] = colours[raster[occupied] % len(colours)]
    rgba[raster == -1] = (0.6, 0.6, 0.6, 1.0)
    h, w = raster.shape[1:]
    extent = (lo[0], lo[0] + w * pixel, lo[1], lo[1] + h * pixel)
    aspect = (extent[3] - extent[2]) / max(extent[1] - extent[0], 1e-9)
    width_in = 8.0
    fig = Figure(figsize=(width_in, max(2.5, width_in * aspect) * n_floors + 0.5))
    axes = fig.subplots(n_floors, 1, squeeze=False)
    frame = parse.frame
    for f in range(n_floors):
        ax = axes[f, 0]
        ax.imshow(rgba[f], origin="lower", extent=extent, interpolation="nearest")
        if draw_dividers:
            for d in parse.dividers:
                if d.axis == "z" or d.floor != f:
                    continue
                a = d.position
                ends = [[a, d.extent[0]], [a, d.extent[1]]] if d.axis == "u" else [[d.extent[0], a], [d.extent[1], a]]
                seg = (frame if d.yaw is None else Frame(d.yaw, frame.origin)).to_world(np.array(ends))
                ax.plot(seg[:, 0], seg[:, 1], color="black" if d.kind != "empty" else "0.5",
                        lw=0.6, ls="-" if d.kind != "empty" else ":")
        for s in parse.spaces:
            if s.floor != f or not s.footprint.get("coordinates"):
                continue
            pt = to_shape(s.footprint).representative_point()
            ax.text(pt.x, pt.y, str(s.id), fontsize=6, ha="center", va="center")
        z = parse.floors[f].z_range if f < len(parse.floors) else [0, 0]
        ax.set_title(f"storey {f} (z {z[0]:.2f} - {z[1]:.2f} m): "
                     f"{sum(s.floor == f for s in parse.spaces)} spaces", fontsize=9)
        ax.set_xlim(extent[0], extent[1])
        ax.set_ylim(extent[2], extent[3])
        ax.set_aspect("equal")
        ax.tick_params(labelsize=6)
    fig.tight_layout()
    path = os.fspath(path)
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    fig.savefig(path, dpi=dpi)
    return path


def floorplan_summary(raster: np.ndarray) -> dict[str, Any]:
    """Pixel counts of a raster: occupied, unassigned, empty."""
    return {"occupied": int((raster >= 0).sum()), "unassigned": int((raster == -1).sum()),
            "empty": int((raster == -2).sum())}
