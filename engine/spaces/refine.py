"""Refining the large spaces of a parse in their own frame (issue 8: hard buildings).

The building's slicing (:mod:`engine.spaces.slicing`) searches its histograms in ONE
frame, the building's.  Two things defeat it on real buildings:

* a **wing at an angle**: its walls are slanted in the building's frame and
  smear over many bins, so no peak-gap-peak divider is found there and the
  whole wing (several rooms and its hallway) stays one cell;
* a **large cell never cut**: its walls' voids were filled in the histogram of
  the box it was searched in by the rooms beside it (or by a wing's smear).

After merging, every space of at least ``min_area`` m² is parsed again on its
own points only (one task per space: memory is bounded by the largest
space): its dominant orientation is estimated with the building's estimator
(:mod:`engine.spaces.alignment`; a yaw within ``snap_deg`` of the building's is
snapped to it), then the same recursive slicing and merging run in that
frame, on histograms that hold nothing but the space.  When that splits the
space, its pieces replace it: the result is per point, so nothing else has to
follow.  The sub-frame shares the building frame's origin; only the yaw
differs (``Cell.yaw`` / ``Face.yaw`` in ``meta/spaces``).

The refinement reuses the store-based passes unchanged through
:class:`MemoryStore`, a one-tile store holding the space's raw scaled
integers (so a point falls in exactly the same bins here and when the labels
are written).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy import ndimage

from engine.spaces.alignment import (
    AlignmentSettings,
    Frame,
    block_sum,
    coarse_yaw,
    density_image,
    orientation_field,
    parabolic_peak,
    refine_angles,
    refine_sample,
    tile_evidence,
)
from engine.spaces.histograms import BoxIndex, Grid
from engine.spaces.slicing import Box, FoundDivider

# -- a tile store in memory ------------------------------------------------------------------------------

@dataclass
class MemoryTile:
    """The tile record the passes use: name, point count, world bounds."""

    name: str
    count: int
    bounds: list[float]


@dataclass
class MemoryMeta:
    """The store metadata the passes use (the real store's scale, offset and origin)."""

    scale: tuple[float, float, float]
    offset: tuple[float, float, float]
    origin: tuple[float, float, float]
    point_count: int
    bounds: list[float]


class MemoryStore:
    """A one-tile, read-only store of raw scaled-integer coordinates (``x``, ``y``, ``z``).

    It keeps the bins of its points in the last grid asked for (:meth:`cached_bins`):
    the refinement of a space makes one histogram pass over the same points per
    slicing level and one for its faces, all in the same frame, and computing the
    bins was about half of each pass (the medium bench_run building: 6 passes over
    5.3 M points).  On a cluster each piece of a :class:`PieceStore` keeps its own.
    """

    def __init__(self, raw: dict[str, np.ndarray], scale, offset, origin) -> None:
        self.raw = {k: np.asarray(raw[k]) for k in ("x", "y", "z")}
        self._bins: tuple[bytes, tuple[np.ndarray, np.ndarray, np.ndarray]] | None = None
        n = len(self.raw["x"])
        sc, of = np.asarray(scale, float), np.asarray(offset, float)
        if n:
            lo = [float(self.raw[a].min() * sc[i] + of[i]) for i, a in enumerate("xyz")]
            hi = [float(self.raw[a].max() * sc[i] + of[i]) for i, a in enumerate("xyz")]
        else:
            lo = hi = [0.0, 0.0, 0.0]
        bounds = lo + hi
        self.meta = MemoryMeta(tuple(sc), tuple(of), tuple(float(v) for v in origin), n, bounds)
        self.tiles = [MemoryTile("memory", n, bounds)]

    def read(self, tile: Any, columns) -> dict[str, np.ndarray]:
        return {c: self.raw[c] for c in columns}

    def cached_bins(self, grid: Grid, tile: Any = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``grid.raw_bins`` of the points, computed once per grid (read-only arrays; the grid's affine map
        is the key, so another frame or bin width computes them again and replaces them)."""
        affine = grid.raw_affine(self.meta)
        key = affine.tobytes()
        if self._bins is None or self._bins[0] != key:
            bins = grid.raw_bins(self.raw, affine)
            for b in bins:
                b.flags.writeable = False
            self._bins = (key, bins)
        return self._bins[1]

    def drop_bins(self) -> None:
        """Forget the kept bins (memory)."""
        self._bins = None

    def xy_local(self) -> np.ndarray:
        """Horizontal coordinates relative to the origin (float64 ``(n, 2)``)."""
        m = self.meta
        return np.stack([self.raw[a] * m.scale[i] + (m.offset[i] - m.origin[i]) for i, a in enumerate("xy")],
                        axis=1)


class PieceStore:
    """A :class:`MemoryStore` whose tiles are pieces of its points held by the workers, one piece per worker
    thread, so that the refinement's histogram passes run as one task per piece on the cluster.

    Each piece (a contiguous slice of the points, a :class:`MemoryStore` that
    keeps its own bins) is sent once to one worker; a pass's task for a piece
    takes the piece's future as its input (:meth:`task_input`), so dask runs it
    where the piece is.  The store itself pickles to its metadata and tile
    names; the whole store (tile ``"memory"``) stays with the task that made it.
    A pass sums integer counts over tiles, so its result does not depend on how
    the points are split.
    """

    def __init__(self, mem: MemoryStore, client, slots: list[str]) -> None:
        n = mem.meta.point_count
        cuts = np.linspace(0, n, len(slots) + 1).astype(np.int64)
        m = mem.meta
        self._mem: MemoryStore | None = mem
        self._futures = []
        self.tiles = []
        for i, (a0, a1, addr) in enumerate(zip(cuts[:-1], cuts[1:], slots)):
            piece = MemoryStore({a: mem.raw[a][a0:a1] for a in "xyz"}, m.scale, m.offset, m.origin)
            self._futures.append(client.scatter(piece, workers=[addr], hash=False))
            self.tiles.append(MemoryTile(f"piece-{i}", piece.meta.point_count, piece.meta.bounds))
        self.meta = m

    def __getstate__(self) -> dict[str, Any]:
        return {"meta": self.meta, "tiles": self.tiles}

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        self._mem, self._futures = None, []

    def task_input(self, tile: str):
        """What a pass's task gets for ``tile``: the future of its piece (dask resolves it on the worker)."""
        return self._futures[int(str(tile).rsplit("-", 1)[1])]

    def _piece(self, tile: Any) -> MemoryStore:
        if isinstance(tile, MemoryStore):
            return tile
        if tile == "memory" and self._mem is not None:
            return self._mem
        raise KeyError(f"{tile!r}: a piece is read through its task input")

    def read(self, tile: Any, columns) -> dict[str, np.ndarray]:
        return self._piece(tile).read(tile, columns)

    def cached_bins(self, grid: Grid, tile: Any = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return self._piece(tile).cached_bins(grid, tile)


def _in_task() -> bool:
    """Whether this code runs in a dask worker's task."""
    try:
        from distributed import get_worker

        get_worker()
    except ValueError:
        return False
    return True


# -- the space's own frame(s) --------------------------------------------------------------------------------

def _snap(deg: float, building_yaw: float, snap_deg: float) -> float:
    """The direction ``deg + k * 90°`` closest to the building's yaw (radians); the building's within ``snap_deg``."""
    b = math.degrees(building_yaw)
    diff = ((deg - b + 45.0) % 90.0) - 45.0
    return building_yaw if abs(diff) <= snap_deg else math.radians(b + diff)


def space_yaw(xy: np.ndarray, params: AlignmentSettings, building_yaw: float, snap_deg: float,
              evidence: dict[str, Any] | None = None) -> float:
    """The dominant wall orientation of some points (radians), the building's yaw when within ``snap_deg``.

    The same estimator as the building's (:func:`engine.spaces.alignment.estimate_alignment`) on one
    "tile": orientation histogram modulo 90 degrees, then refinement by projection sharpness.
    The result is the one of the four directions ``yaw + k * 90°`` closest to ``building_yaw``.
    ``evidence``: :func:`engine.spaces.alignment.tile_evidence` of these very points when already computed.
    """
    ev = evidence if evidence is not None else tile_evidence(np.asarray(xy, dtype=np.float64), params)
    if not np.any(ev["histogram"] > 0):
        return building_yaw
    coarse = coarse_yaw(ev["histogram"], params.angle_bin)
    sharp = refine_sample(ev, coarse, params)["sharpness"]
    deg = parabolic_peak(refine_angles(coarse, params), sharp) if np.any(sharp > 0) else coarse
    return _snap(deg, building_yaw, snap_deg)


def _circular_offset(a: np.ndarray, b: float) -> np.ndarray:
    """``a - b`` modulo 90 degrees, in [-45, 45)."""
    return ((np.asarray(a, dtype=np.float64) - b + 45.0) % 90.0) - 45.0


def two_orientations(hist: np.ndarray, angle_bin: float, separation: float, half_width: float,
                     min_second: float) -> list[float]:
    """The dominant orientation of a histogram modulo 90 (degrees) and a second one when it is strong.

    The second is the peak of the circularly smoothed histogram at least
    ``separation`` degrees from the first; it counts when the weight within
    ``half_width`` degrees of it is at least ``min_second`` times the first's.
    """
    h = np.asarray(hist, dtype=np.float64)
    if not np.any(h > 0):
        return []
    centres = (np.arange(len(h)) + 0.5) * angle_bin
    first = coarse_yaw(h, angle_bin)
    sm = ndimage.gaussian_filter1d(h, 1.0 / angle_bin, mode="wrap")
    far = np.abs(_circular_offset(centres, first)) >= separation
    if not far.any():
        return [first]
    second = float(centres[np.flatnonzero(far)[int(np.argmax(sm[far]))]])
    m1 = h[np.abs(_circular_offset(centres, first)) <= half_width].sum()
    m2 = h[np.abs(_circular_offset(centres, second)) <= half_width].sum()
    if m2 < min_second * m1:
        return [first]
    sub = np.abs(_circular_offset(centres, second)) <= half_width  # the second's own circular mean
    z = np.sum(h[sub] * np.exp(1j * np.radians(4 * _circular_offset(centres[sub], second))))
    return [first, float((second + math.degrees(np.angle(z)) / 4.0) % 90.0)]


@dataclass
class Regions:
    """Which of two frames each part of a space belongs to: a label raster of ``block`` metre squares."""

    labels: np.ndarray  # (rows: y, cols: x) int8, 0 or 1
    lo: np.ndarray  # store-local x, y of the raster's corner
    block: float

    def of(self, xy: np.ndarray) -> np.ndarray:
        """Label of store-local points (clipped to the raster)."""
        ix = np.clip(np.floor((xy[:, 0] - self.lo[0]) / self.block).astype(np.int64), 0, self.labels.shape[1] - 1)
        iy = np.clip(np.floor((xy[:, 1] - self.lo[1]) / self.block).astype(np.int64), 0, self.labels.shape[0] - 1)
        return self.labels[iy, ix]


def frame_regions(xy: np.ndarray, params: AlignmentSettings, orientations: list[float], tolerance: float,
                  block: float, smooth: float) -> Regions:
    """Split a space into the parts whose walls follow each of two orientations (degrees modulo 90).

    Every pixel of the density image votes with its coherent wall strength
    (:func:`engine.spaces.alignment.orientation_field`) for the orientation within
    ``tolerance`` degrees of its own; the votes are summed over ``block``
    metre squares and smoothed (Gaussian, ``smooth`` metres); a square takes
    the orientation with more votes, a square without votes that of the
    nearest square with some.
    """
    img, lo = density_image(xy, params.pixel)
    ang, weight = orientation_field(img, params)
    k = max(1, int(round(block / params.pixel)))
    votes = []
    for o in orientations:
        near = np.abs(_circular_offset(ang, o)) <= tolerance
        votes.append(ndimage.gaussian_filter(block_sum(np.where(near, weight, 0.0), k), smooth / (k * params.pixel),
                                             mode="constant"))
    v = np.stack(votes)
    lab = np.argmax(v, axis=0).astype(np.int8)
    none = v.max(axis=0) <= 1e-9 * max(float(v.max()), 1e-300)
    if none.any() and not none.all():
        _, (iy, ix) = ndimage.distance_transform_edt(none, return_indices=True)
        lab = lab[iy, ix]
    return Regions(lab, np.asarray(lo, dtype=np.float64), k * params.pixel)


# -- one space's refinement ---------------------------------------------------------------------------------

@dataclass
class Part:
    """The cells of one frame of a refined space (bins of its grid), their space and their faces."""

    yaw: float
    cells: list[Box] = field(default_factory=list)
    labels: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    edges: list[Any] = field(default_factory=list)
    dividers: list[FoundDivider] = field(default_factory=list)

    @property
    def n_spaces(self) -> int:
        return int(self.labels.max()) + 1 if len(self.labels) and self.labels.max() >= 0 else 0

    def index(self, floor_bins: tuple[int, int]) -> BoxIndex:
        """Locates points in the part's cells (its storey as storey 0)."""
        rows = np.array([[0, c.u0, c.u1, c.v0, c.v1] for c in self.cells], dtype=np.int64).reshape(-1, 5)
        return BoxIndex.build(np.array([floor_bins], dtype=np.int64), rows)


@dataclass
class Refinement:
    """A space parsed again: one part per frame (two for a space with a wing at an angle), and the
    regions that route its points to the parts (None: one part)."""

    space: int
    floor: int
    parts: list[Part] = field(default_factory=list)
    regions: Regions | None = None
    points: int = 0

    @property
    def n_spaces(self) -> int:
        return sum(pt.n_spaces for pt in self.parts)

    def part_of(self, xy_local: np.ndarray) -> np.ndarray:
        """Part of each store-local point."""
        if self.regions is None:
            return np.zeros(len(xy_local), dtype=np.int64)
        return self.regions.of(xy_local).astype(np.int64)


def gather_tile(job: tuple[str, np.ndarray], store, index: BoxIndex, grid: Grid) -> dict[str, np.ndarray]:
    """The raw ``x``, ``y``, ``z`` of one tile's points located in ``cells`` (``job``: tile, cell ids in the
    building's parse); a task of its own when spaces are refined on a cluster (:func:`refine_spaces`)."""
    tile, cells = job
    member = np.zeros(len(index.boxes) + 1, dtype=bool)
    member[np.asarray(cells, dtype=np.int64)] = True
    raw = store.read(tile, ("x", "y", "z"))
    box = index.locate(*grid.raw_bins(raw, grid.raw_affine(store.meta)))
    sel = member[box]  # box -1 -> the last entry (False)
    return {a: raw[a][sel] for a in "xyz"}


def _joined(pieces: list[dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
    """Per-tile pieces of a space's points, concatenated in tile order."""
    return {a: (np.concatenate([p[a] for p in pieces]) if pieces else np.zeros(0, np.int32)) for a in "xyz"}


def gather_space(store, tiles: list[str], index: BoxIndex, grid: Grid, cells: np.ndarray) -> dict[str, np.ndarray]:
    """The raw ``x``, ``y``, ``z`` of the points located in ``cells`` (ids in the building's parse)."""
    return _joined([gather_tile((t, cells), store, index, grid) for t in tiles])


def _parse_part(mem: MemoryStore, yaw: float, grid: Grid, params, floor: int, floors: np.ndarray,
                band_z: np.ndarray, pieces_points: int = 0) -> Part:
    """Recursive slicing and merging of a memory store's points in the frame ``yaw``.

    In a dask task on a cluster with more than one thread, the histogram passes
    of a space of at least ``pieces_points`` points (> 0) run as tasks over
    pieces of its points (:class:`PieceStore`): the refinement of one large
    space no longer keeps the other workers idle.
    """
    if pieces_points <= 0 or mem.meta.point_count < pieces_points or not _in_task():
        return _parse_part_with(mem, mem, yaw, grid, params, floor, floors, band_z, None)
    from distributed import worker_client

    with worker_client() as client:
        workers = client.scheduler_info()["workers"]
        slots = [a for a in sorted(workers) for _ in range(max(1, int(workers[a].get("nthreads", 1))))]
        if len(slots) < 2:
            return _parse_part_with(mem, mem, yaw, grid, params, floor, floors, band_z, None)
        return _parse_part_with(mem, PieceStore(mem, client, slots), yaw, grid, params, floor, floors, band_z,
                                client)


def _parse_part_with(mem: MemoryStore, passes, yaw: float, grid: Grid, params, floor: int, floors: np.ndarray,
                     band_z: np.ndarray, client) -> Part:
    """:func:`_parse_part` with the histogram passes over ``passes`` (``mem`` or its :class:`PieceStore`)."""
    from engine.spaces.ceilings import ceiling_dividers, ceiling_occupancy, step_lines
    from engine.spaces.merging import merge, neighbour_edges, ridge_faces, test_edges
    from engine.spaces.ridges import Occupancy, space_ridges
    from engine.spaces.slicing import slice_storeys

    out = Part(yaw)
    if mem.meta.point_count == 0:
        return out
    sub = Grid.for_store(mem, Frame(yaw, tuple(grid.frame.origin)), grid.bin_width, grid.z_bin)
    fl = np.asarray(floors, dtype=np.int64)[floor:floor + 1]
    bz = np.asarray(band_z, dtype=np.int64)[floor:floor + 1]
    bu, bv, bzs = sub.tile_bins(mem, "memory")
    start = [Box(0, int(bu.min()), int(bu.max()) + 1, int(bv.min()), int(bv.max()) + 1)]
    # walls seen as one dense surface (no void): ridge lines over the space's upper band (engine.spaces.ridges)
    ridges = space_ridges(bu, bv, bzs, int(bz[0]), grid.z_bin, params.ridges, grid.bin_width)
    # a ceiling that changes height is a wall too (engine.spaces.ceilings): its step lines cut and divide like ridges
    ceiling = ceiling_occupancy(bu, bv, bzs, int(bz[0]), params.ceilings, grid.bin_width, grid.z_bin)
    ridges = ridges + step_lines(ceiling, params.ceilings, params.ridges, grid.bin_width, grid.z_bin, ridges,
                                 points=(bu, bv, bzs), floor_z=int(bz[0]) - int(round(params.upper_band / grid.z_bin)))
    occ = (Occupancy.build(bu, bv, bzs, int(bz[0]), params.ridges.bins(params.ridges.occupancy_pixel, grid.bin_width))
           if ridges else None)
    if passes is not mem:  # the passes read the pieces: this task's copy of the bins is no longer needed
        del bu, bv, bzs
        mem.drop_bins()
    cells, dividers, _ = slice_storeys(passes, sub, [tuple(fl[0])], start, params.slicing_walls, bz, client=client,
                                       max_levels=params.max_levels, ridges=ridges, ridge_params=params.ridges)
    edges = neighbour_edges(cells, params.walls.bins(params.min_face))
    test_edges(passes, sub, fl, cells, edges, params.walls, params.merge_window, bz, client=client)
    # a side with a ceiling in the storey and a side without one (a stair shaft) are not one room
    edges = ceiling_dividers(edges, ceiling, params.ceilings, grid.bin_width)
    if ridges:
        edges = ridge_faces(edges, ridges, params.ridges, grid.bin_width, occ)
    comps = merge(cells, edges, grid.bin_width, params.rules)
    for c in cells:
        c.floor = floor
    for e in edges:
        e.floor = floor
    for d in dividers:
        d.floor, d.yaw = floor, (None if yaw == grid.frame.yaw else yaw)
    out.cells, out.labels, out.edges, out.dividers = cells, comps.labels, edges, dividers
    return out


def refine_space(item: dict[str, Any], store, index: BoxIndex, grid: Grid, params, floors: np.ndarray,
                 band_z: np.ndarray) -> Refinement:
    """Parse one space again on its own points, in its own frame(s) (one task).

    ``item``: ``space``, ``floor``, ``cells`` (its cell ids in the building's
    parse) and ``tiles`` (the tiles holding it); with ``pieces`` (the
    :func:`gather_tile` results of its tiles, in order) the points are not read again;
    ``pieces_points``: see :func:`_parse_part`.  ``params`` is the stage's
    :class:`engine.spaces.parse.SpaceSettings`.  When the space's walls follow two
    orientations (``refine_min_second``), it is split into the regions of each
    (:func:`frame_regions`) and each region is parsed in its own frame.
    """
    f = int(item["floor"])
    pieces = int(item.get("pieces_points") or 0)
    if "pieces" in item:  # gathered by one task per tile (refine_spaces)
        raw = _joined(item["pieces"])
    else:
        raw = gather_space(store, item["tiles"], index, grid, item["cells"])
    m = store.meta
    origin = tuple(grid.frame.origin)
    mem = MemoryStore(raw, m.scale, m.offset, origin)
    out = Refinement(int(item["space"]), f, points=len(raw["x"]))
    if out.points < 100:
        return out
    al = params.alignment
    xy = mem.xy_local()
    ev = tile_evidence(xy, al)
    found = two_orientations(ev["histogram"], al.angle_bin, params.refine_separation_deg, 2.0,
                             params.refine_min_second)
    if len(found) == 2:
        out.regions = frame_regions(xy, al, found, 2.0, params.refine_block, params.refine_smooth)
        region = out.regions.of(xy)
        if np.all(region == region[0]):
            out.regions = None
    if out.regions is None:
        yaw = space_yaw(xy, al, grid.frame.yaw, params.refine_snap_deg, evidence=ev)
        out.parts = [_parse_part(mem, yaw, grid, params, f, floors, band_z, pieces)]
        return out
    for k in range(2):
        sel = region == k
        sub = MemoryStore({a: raw[a][sel] for a in "xyz"}, m.scale, m.offset, origin)
        yaw = space_yaw(sub.xy_local(), al, grid.frame.yaw, params.refine_snap_deg)
        out.parts.append(_parse_part(sub, yaw, grid, params, f, floors, band_z, pieces))
    return out


def refine_spaces(items: list[dict[str, Any]], store, index: BoxIndex, grid: Grid, params, floors: np.ndarray,
                  band_z: np.ndarray, client=None) -> list[Refinement]:
    """:func:`refine_space` of every item (results in item order), largest space first, its points gathered
    by one task per tile.

    A space's refinement is one long task (its points in memory, recursive
    slicing in its own frame), and the space stage waits for the last one:
    with one large space, one worker parsed it while the others idled.  Three
    things shorten that wait without changing a result: the spaces start
    largest (most bins) first; the points of a space are read and located in
    its tiles by tasks of their own, spread over the workers (a quarter of the
    task's time on the medium ``bench_run`` building: 5.3 M points in 3 tiles);
    and the histogram passes of a space of at least
    ``buildingparser.spaces.refine-pieces-points`` points run as tasks over
    pieces of its points, one per worker thread (:class:`PieceStore`; most of
    the rest of the task).  Without a client: one after another here.
    """
    from engine import config
    from engine.spaces.histograms import share
    from tiles.tasks import run_tasks

    keys = [it["space"] for it in items]
    if client is None or not items:
        return run_tasks(refine_space, items, client=client, label="spaces: refining large spaces", keys=keys,
                         extra_args=(store, index, grid, params, floors, band_z))
    boxes = np.asarray(index.boxes, dtype=np.int64).reshape(-1, 5)
    bins = (boxes[:, 2] - boxes[:, 1]) * (boxes[:, 4] - boxes[:, 3])
    order = sorted(range(len(items)), key=lambda i: (-int(bins[np.asarray(items[i]["cells"], np.int64)].sum()), i))
    shared = share(client, index)
    retries = config.setting("retries")
    pieces_points = config.setting("spaces.refine-pieces-points") or 0
    jobs = [dict(items[i], pieces_points=pieces_points) for i in order]

    def with_pieces(job: dict[str, Any]) -> dict[str, Any]:
        """The job with its tiles' gather tasks as futures: the refinement task waits for them and receives
        their data."""
        pieces = client.map(gather_tile, [(t, job["cells"]) for t in job["tiles"]], store=store, index=shared,
                            grid=grid, pure=False, retries=retries)
        return dict(job, pieces=pieces)

    # One refinement per worker thread at a time, its gathers submitted with it: a refinement whose passes
    # run as tasks over pieces gives up its thread while it waits (worker_client), and with every job
    # submitted at once the next refinements and their gathers would start in that thread, holding the
    # points of many large spaces in memory together.
    threads = sum(int(w.get("nthreads", 1)) for w in client.scheduler_info()["workers"].values())
    done = run_tasks(refine_space, jobs, client=client, label="spaces: refining large spaces",
                     keys=[keys[i] for i in order], extra_args=(store, shared, grid, params, floors, band_z),
                     window=max(1, threads), prepare=with_pieces)
    out: list[Any] = [None] * len(items)
    for i, r in zip(order, done):
        out[i] = r
    return out


def relabel(cell: np.ndarray, raw: dict[str, np.ndarray], meta, refined: list[tuple[Refinement, list]],
            owner: np.ndarray) -> np.ndarray:
    """New cell ids of a tile's points: points of a refined space are located in its refinement's cells.

    ``owner[cell + 1]`` is the refinement index of a building cell (-1: not refined);
    ``refined[k]`` = (refinement, [(grid, index, first new cell id) per part]).  Points of a
    refined space outside every one of its new cells get -1.
    """
    out = cell.copy()
    who = owner[cell + 1]
    for k in np.unique(who[who >= 0]).tolist():
        ref, parts = refined[k]
        sel = np.flatnonzero(who == k)
        part = {a: raw[a][sel] for a in "xyz"}
        if ref.regions is not None:
            xy = np.stack([part[a] * meta.scale[i] + (meta.offset[i] - meta.origin[i]) for i, a in enumerate("xy")],
                          axis=1)
            which = ref.part_of(xy)
        else:
            which = np.zeros(len(sel), dtype=np.int64)
        new = np.full(len(sel), -1, dtype=np.int64)
        for j, (g, idx, first) in enumerate(parts):
            mine = np.flatnonzero(which == j)
            if not len(mine):
                continue
            sub = idx.locate(*g.raw_bins({a: part[a][mine] for a in "xyz"}, g.raw_affine(meta)))
            new[mine] = np.where(sub >= 0, sub + first, -1)
        out[sel] = new
    return out


def clipped_footprint(rects: list[list[float]], frame: Frame, clip_rects: list[list[float]], clip_frame: Frame
                      ) -> tuple[dict[str, Any], float]:
    """GeoJSON (world) and area of the union of ``rects`` (in ``frame``) within the union of ``clip_rects``.

    A refined space's cells are boxes of its own frame that may reach beyond the
    space: its footprint is their union clipped to the space it came from.
    """
    import shapely
    from shapely import affinity
    from shapely.geometry import box, mapping

    def world(rs: list[list[float]], fr: Frame):
        c, s = fr.cos_sin
        g = shapely.union_all([box(*r) for r in rs])
        return affinity.affine_transform(g, [c, -s, s, c, fr.origin[0], fr.origin[1]])

    if not rects or not clip_rects:
        return {"type": "Polygon", "coordinates": []}, 0.0
    geom = shapely.set_precision(world(rects, frame).intersection(world(clip_rects, clip_frame)), 1e-4)
    return mapping(geom), float(geom.area)


def face_side_space(refinement: Refinement, point_world: np.ndarray, origin, bin_width: float) -> int:
    """The new space (numbered within the refinement) at a world point: the cell holding it in its part,
    else the nearest cell with a space of any part."""
    best, best_d, base = -1, np.inf, 0
    pw = np.asarray(point_world, dtype=np.float64)[None, :2]
    want = int(refinement.part_of(pw - np.asarray(origin[:2]))[0]) if refinement.regions is not None else 0
    for j, part in enumerate(refinement.parts):
        a = Frame(part.yaw, tuple(origin)).to_aligned(pw)[0] / bin_width
        rows = np.array([[c.u0, c.u1, c.v0, c.v1] for c in part.cells], dtype=np.float64).reshape(-1, 4)
        lab = np.asarray(part.labels)
        ok = lab >= 0
        if ok.any():
            du = np.maximum(np.maximum(rows[:, 0] - a[0], a[0] - rows[:, 1]), 0.0)
            dv = np.maximum(np.maximum(rows[:, 2] - a[1], a[1] - rows[:, 3]), 0.0)
            d = np.where(ok, np.hypot(du, dv), np.inf) + (0.0 if j == want else 1e6)
            i = int(np.argmin(d))
            if d[i] < best_d:
                best, best_d = base + int(lab[i]), float(d[i])
        base += part.n_spaces
    return best
