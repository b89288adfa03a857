"""Colours and per-space scan character: materials, palettes, brightness, density factor, noise.

Colours are 8-bit RGB.  Each surface gets a base colour from its material's
palette (per building, per space or per element), the scan adds per-point
jitter, the space's brightness (some rooms are much darker) and a gentle
fall-off with distance from the nearest scan position.
"""
from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from engine.synth.building import Space

WALLS = [(205, 200, 190), (190, 185, 170), (215, 212, 205), (180, 175, 160), (200, 195, 180), (175, 180, 182),
         (196, 184, 160), (170, 185, 175), (220, 210, 190)]
CARPETS = [(95, 95, 100), (70, 75, 90), (110, 100, 85), (120, 60, 55), (85, 95, 80), (60, 60, 62)]
HARD_FLOORS = [(185, 180, 170), (160, 150, 135), (150, 110, 70), (200, 195, 185), (120, 115, 110)]
CEILINGS = [(225, 225, 220), (210, 210, 205), (235, 232, 225), (200, 198, 190)]
DOORS = [(140, 95, 60), (165, 120, 80), (200, 200, 195), (110, 115, 125), (80, 60, 50), (60, 90, 130)]
FRAMES = [(180, 180, 180), (230, 230, 230), (90, 90, 95), (150, 110, 70)]
TABLES = [(160, 120, 80), (210, 205, 195), (120, 90, 60), (190, 190, 190), (80, 80, 85), (230, 228, 220)]
CHAIRS = [(40, 40, 45), (30, 50, 110), (120, 30, 30), (60, 60, 65), (90, 110, 60), (150, 150, 150)]
SOFAS = [(60, 80, 120), (120, 60, 50), (70, 70, 70), (150, 130, 100), (40, 90, 80), (170, 50, 60)]
BOOKCASES = [(150, 110, 70), (190, 190, 185), (100, 75, 50), (130, 135, 140), (215, 210, 200)]
BOARDS = [(238, 238, 235), (232, 235, 236), (180, 140, 90), (40, 60, 50)]
METAL = (70, 70, 75)
GLASS = (170, 192, 210)
LIGHT = (245, 245, 240)


def pick(rng: np.random.Generator, palette: list[tuple[int, int, int]]) -> tuple[float, float, float]:
    """One colour of a palette, slightly varied."""
    c = np.asarray(palette[int(rng.integers(len(palette)))], float)
    return tuple(float(v) for v in np.clip(c * rng.uniform(0.92, 1.08) + rng.normal(0, 4, 3), 0, 255))


def vivid(rng: np.random.Generator) -> tuple[float, float, float]:
    """A random saturated colour (books, boxes, clutter)."""
    import colorsys

    r, g, b = colorsys.hsv_to_rgb(rng.random(), rng.uniform(0.3, 0.9), rng.uniform(0.3, 0.95))
    return (255 * r, 255 * g, 255 * b)


def building_style(rng: np.random.Generator) -> dict:
    """Choices shared by the whole building: windows, structure, lights, frames."""
    return {
        "window_width": float(rng.uniform(0.9, 2.2)),
        "window_gap": float(rng.uniform(0.6, 2.0)),
        "window_height": float(rng.uniform(1.2, 1.8)),
        "sill": float(rng.uniform(0.75, 1.0)),
        "window_frame": pick(rng, FRAMES),
        "pilasters": bool(rng.random() < 0.5),
        "pilaster": (float(rng.uniform(0.3, 0.5)), float(rng.uniform(0.15, 0.3))),
        "beams": bool(rng.random() < 0.6),
        "grid": float(rng.uniform(4.5, 7.0)),
        "light_step": float(rng.uniform(2.2, 3.2)),
        "light_size": (0.6, 1.2) if rng.random() < 0.6 else (0.6, 0.6),
        "wall": pick(rng, WALLS),
        "ceiling": pick(rng, CEILINGS),
        "door": pick(rng, DOORS),
        "door_frame": pick(rng, FRAMES),
    }


def space_colours(rng: np.random.Generator, space: Space, style: dict) -> None:
    """Per-space colours and scan character (density factor x0.5-x2, noise 2-6 mm, brightness)."""
    wall = style["wall"] if rng.random() < 0.7 else pick(rng, WALLS)
    if space.type in ("WC", "storage") or rng.random() < 0.25:
        floor, fj = pick(rng, HARD_FLOORS), 6.0
    else:
        floor, fj = pick(rng, CARPETS), 12.0
    space.colours = {
        "wall": wall, "floor": floor, "floor_jitter": fj,
        "ceiling": style["ceiling"] if rng.random() < 0.8 else pick(rng, CEILINGS),
        "door": style["door"] if rng.random() < 0.7 else pick(rng, DOORS),
        "door_frame": style["door_frame"], "column": wall, "beam": style["ceiling"],
    }
    space.density = float(math.exp(rng.uniform(math.log(0.5), math.log(2.0))))
    space.noise = float(rng.uniform(0.002, 0.006))
    space.brightness = float(rng.uniform(0.45, 0.7) if rng.random() < 0.15 else rng.uniform(0.8, 1.05))
    if "variety" in style:
        vary_scan(space, style["variety"])
    if "subsample" in style:
        subsample_scan(space, style["subsample"])


#: The key of a room's scan-character stream in a varied building (its boards use keys 0, 1, ...).
SCAN_KEY = 1_000_000


def vary_scan(space: Space, variety: int) -> None:
    """A room of a ``styles="varied"`` building, after its classic draws (which stay as they are): saturated
    walls (a third of the rooms), a dark room (one in six), scan noise 1-10 mm with a real scanner's tails
    (clipped at 5 sigma, not 3: a surface of 10^6 points spans about +- 4.9 sigma) and a density factor four
    times as wide (x0.25-x4 in all), from the room's own variety stream."""
    r = np.random.default_rng([variety, int(space.id), SCAN_KEY])
    if r.random() < 1 / 3:
        space.colours["wall"] = space.colours["column"] = vivid(r)
    if r.random() < 1 / 6:
        space.brightness = float(r.uniform(0.25, 0.45))
    space.noise = float(math.exp(r.uniform(math.log(0.001), math.log(0.010))))
    space.noise_clip = 5.0
    space.density *= float(math.exp(r.uniform(math.log(0.5), math.log(2.0))))


def subsample_scan(space: Space, stream: int) -> None:
    """A room of a ``styles="subsampled"`` building, after its classic draws (which stay as they are): its scan
    keeps one point per cell of a world-aligned voxel grid 1-5 cm wide, as clouds often arrive (CloudCompare's
    spatial subsampling, PDAL's voxel filters), from the room's own stream."""
    r = np.random.default_rng([stream, int(space.id), SCAN_KEY])
    space.voxel = float(r.uniform(0.01, 0.05))


def shade(rng: np.random.Generator, base: np.ndarray, jitter: np.ndarray, brightness: float,
          distance: np.ndarray) -> np.ndarray:
    """8-bit colours of points: base ``(n, 3)`` darkened by brightness and distance, plus jitter."""
    light = (brightness * (1.0 - 0.25 * np.minimum(distance / 10.0, 1.0))).astype(np.float32)
    rgb = base.astype(np.float32) * light[:, None]
    rgb += rng.standard_normal(base.shape, dtype=np.float32) * jitter.astype(np.float32)[:, None]
    return np.clip(np.rint(rgb), 0, 255).astype(np.uint16)
