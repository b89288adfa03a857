"""Features of a 3D window (paper Table 1) from summed voxel moments.

A window is a box of whole voxels ``[lo, hi)`` of a space's :class:`~engine.detection.moments.VoxelGrid`
(canonical frame, see :mod:`engine.detection.canonical`), cut into ``K x K x K``
sub-boxes; sub-box ``j`` along an axis of ``W`` voxels spans voxels
``[lo + (j W) // K, lo + ((j + 1) W) // K)`` (:func:`sub_bounds`).  Its feature
vector (:class:`FeatureLayout`) is::

    global   position          P, min corner in the unit cube                      (3)
             position_code     tent code of the window centre, 5 tents per axis    (15)
             size              S, size in the unit cube                            (3)
             size_code         tent code of S, 5 tents per axis                    (15)
             metric_code       tent code of log2 of the size in metres, 6 per axis (18)
             boundary_code     tent code of the distance in metres from the window
                               to the nearer end of the space, 5 per axis          (15)
    local, per sub-box l (x-major order), zero where l holds no points:
             occupancy         B_l, 1 if l holds at least ``min_points`` points    (1)
             ratio             d_l, points of l / points of the window, times K^3  (1)
             color             mean r, g, b of l in [0, 1]                         (3)
             normal            |n_x|, |n_y|, |n_z| of the smallest eigenvector     (3)
             curvature         lambda_min / sum(lambda) of the covariance of l     (1)
    context (layouts with ``context``), the slabs of space beside the window's six faces:
             context_fill      per slab n_s / (n_s + n_window): along x and y the
                               smaller and the larger of the two sides, along z
                               below and above                                     (6)
             context_color     per axis, the window's mean luminance minus its two
                               slabs' (3) and its absolute value (3); the window's
                               mean r, g, b minus all six slabs' (3)               (9)

Colours are normalised per space before the moments are summed
(:func:`normalise_colours`, the layout's ``colour`` mode): the generated
buildings, like real scans, hold dark rooms and long hallways whose surfaces
come out at half the brightness of the others, and a detector trained on raw
colours misses their ceilings (their learned "light grey above" is not there).
``"space-median"`` scales each space's colours so that the median luminance of
its points is :data:`COLOUR_TARGET`: a per-space exposure (a multiplicative
factor) cancels exactly, while the contrast between surfaces stays.  Measured
on generated buildings (2 quick training buildings, 1 mining round, test seeds
2000-2001): mAP 25.2 against 20.5 with raw colours (ceiling 28 against 22,
floor 83 against 79, window 37 against 5).  Models written before this mode
existed read back as ``"none"`` (raw colours).

The context block is our addition too (like a deformable-part model's context,
or the "shell" of a 3D window): a window's own features see only its inside,
so a board (a pale rectangle 2 cm proud of a wall) and the wall patch beside it
looked alike, and so did a door and the wall it interrupts.  The slabs are
:data:`CONTEXT_MARGIN` metres thick (at least one voxel), clipped to the grid,
and span the window's extent along the other two axes; their sums are box
sums of the integral volume like everything else.  Horizontal sides enter as
min/max because a board hangs on either wall.  Layouts written before it have
no such block (``FeatureLayout.context`` False).

The tent codes are our addition: a linear SVM can only score a raw position
or size monotonically (a wall sits at either end of an axis, a chair has a
typical size), so each is also given as a piecewise-linear "soft one-hot"
code (:func:`tent_code`).  The metric code carries the window's size in metres,
which the unit cube discards and which tells a chair from a table whatever the
room's size.  The boundary code carries, per axis, how far the window stands
from the space's nearer end in metres (0 against a wall or the floor): in a
long room the unit-cube position code cannot tell a board on the end wall from
a table a metre in front of it.  Models written before it existed have no such
block (``FeatureLayout.boundary`` False).  Normals enter as absolute components: their sign is arbitrary.
The ratio is scaled by ``K^3`` so that it is about 1 for an even spread.

All sums come from the integral volume of the space (:mod:`engine.detection.moments`): a
window's features cost a few hundred look-ups, independent of its points.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from engine.detection import moments as mom

#: Tent centres of the position and unit-size codes (unit cube).
UNIT_TENTS = (0.0, 0.25, 0.5, 0.75, 1.0)
#: Tent centres of the metric size code, in metres (log2-spaced coding).
METRIC_TENTS = (0.05, 0.15, 0.4, 1.0, 2.5, 6.0)
#: Tent centres of the distance to the space's nearer end, in metres.
BOUNDARY_TENTS = (0.0, 0.1, 0.3, 1.0, 3.0)
GLOBAL_BLOCKS = (("position", 3), ("position_code", 3 * len(UNIT_TENTS)), ("size", 3),
                 ("size_code", 3 * len(UNIT_TENTS)), ("metric_code", 3 * len(METRIC_TENTS)),
                 ("boundary_code", 3 * len(BOUNDARY_TENTS)))
LOCAL_BLOCKS = (("occupancy", 1), ("ratio", 1), ("color", 3), ("normal", 3), ("curvature", 1))
LOCAL_SIZE = sum(n for _, n in LOCAL_BLOCKS)
#: The context block (layouts with ``context``), after the local blocks.
CONTEXT_BLOCKS = (("context_fill", 6), ("context_color", 9))
CONTEXT_SIZE = sum(n for _, n in CONTEXT_BLOCKS)
#: Thickness in metres of the slabs beside a window's faces that the context block reads.
CONTEXT_MARGIN = 0.3
#: Moment channels the context block reads: the count and the r, g, b sums.
CONTEXT_CHANNELS = (0, 10, 11, 12)
#: Colour normalisations of a layout: raw colours, or scaled per space to a median luminance.
COLOUR_MODES = ("none", "space-median")
#: The median luminance of a space's points after ``"space-median"`` normalisation.
COLOUR_TARGET = 0.5

#: Feature groups removed by the ablations of paper section 5.3 (Table 3).
ABLATIONS: dict[str, tuple[str, ...]] = {
    "full": (),
    "no_local": ("ratio", "normal", "curvature"),
    "no_global": ("position", "position_code", "boundary_code"),
    "no_color": ("color", "context_color"),
}


def normalise_colours(rgb: np.ndarray | None, mode: str = "space-median") -> np.ndarray | None:
    """A space's colours ``(n, 3)`` in [0, 1] normalised as ``mode`` says (see :data:`COLOUR_MODES`).

    ``"space-median"`` multiplies all colours by ``COLOUR_TARGET / median(luminance)``
    (luminance = mean of r, g, b), so that the same surfaces in a space scanned at
    any exposure give the same features; values may exceed 1.  A space without
    colours, or whose median luminance is 0, is returned unchanged.
    """
    factor = colour_factor(rgb, mode)
    if rgb is None or factor == 1.0:
        return rgb
    return np.asarray(rgb, dtype=np.float64) * factor


def colour_factor(rgb: np.ndarray | None, mode: str = "space-median") -> float:
    """The factor :func:`normalise_colours` multiplies a space's colours by (1.0 when it leaves them)."""
    if mode not in COLOUR_MODES:
        raise ValueError(f"unknown colour normalisation {mode!r}; known: {COLOUR_MODES}")
    if rgb is None or mode == "none" or len(rgb) == 0:
        return 1.0
    med = float(np.median(np.asarray(rgb, dtype=np.float64).mean(axis=1)))
    return COLOUR_TARGET / med if med > 0 else 1.0


def tent_code(x: np.ndarray, centres) -> np.ndarray:
    """Piecewise-linear code ``(..., len(centres))`` of ``x``: weights of the two nearest centres, summing to 1."""
    c = np.asarray(centres, dtype=np.float64)
    x = np.clip(np.asarray(x, dtype=np.float64), c[0], c[-1])
    k = np.clip(np.searchsorted(c, x, side="right") - 1, 0, len(c) - 2)
    t = (x - c[k]) / (c[k + 1] - c[k])
    out = np.zeros(x.shape + (len(c),))
    np.put_along_axis(out, k[..., None], (1.0 - t)[..., None], axis=-1)
    np.put_along_axis(out, (k + 1)[..., None], t[..., None], axis=-1)
    return out


@dataclass
class FeatureLayout:
    """Where each feature group sits in the vector, and which groups a model uses.

    Parameters
    ----------
    k
        Sub-boxes per axis of a window (K).
    disabled
        Feature groups (names of ``GLOBAL_BLOCKS`` / ``LOCAL_BLOCKS``) that are zeroed (ablations).
    min_points
        Points a sub-box needs to count as occupied.
    colour
        Colour normalisation of each space before its moments (:data:`COLOUR_MODES`).
    boundary
        Whether the global block ends with ``boundary_code`` (models written before it: False).
    context
        Whether the vector ends with the context block (models written before it: False).
    """

    k: int = 4
    disabled: tuple[str, ...] = ()
    min_points: int = 1
    colour: str = "space-median"
    boundary: bool = True
    context: bool = True
    spans: dict[str, list[tuple[int, int]]] = field(init=False, repr=False)

    def __post_init__(self) -> None:
        if int(self.k) < 1:
            raise ValueError(f"K must be at least 1, got {self.k}")
        self.k = int(self.k)
        if self.colour not in COLOUR_MODES:
            raise ValueError(f"unknown colour normalisation {self.colour!r}; known: {COLOUR_MODES}")
        known = {n for n, _ in GLOBAL_BLOCKS} | {n for n, _ in LOCAL_BLOCKS} | {n for n, _ in CONTEXT_BLOCKS}
        bad = set(self.disabled) - known
        if bad:
            raise ValueError(f"unknown feature groups {sorted(bad)}; known: {sorted(known)}")
        self.disabled = tuple(self.disabled)
        spans: dict[str, list[tuple[int, int]]] = {}
        i = 0
        for name, n in self.global_blocks:
            spans[name] = [(i, i + n)]
            i += n
        self.n_global = i
        for name, _ in LOCAL_BLOCKS:
            spans[name] = []
        for _ in range(self.k ** 3):
            for name, n in LOCAL_BLOCKS:
                spans[name].append((i, i + n))
                i += n
        self.local_end = i
        for name, n in self.context_blocks:
            spans[name] = [(i, i + n)]
            i += n
        self.size = i
        self.spans = spans

    @property
    def global_blocks(self) -> tuple[tuple[str, int], ...]:
        """The global block's groups in order (without ``boundary_code`` in older layouts)."""
        return GLOBAL_BLOCKS if self.boundary else tuple(b for b in GLOBAL_BLOCKS if b[0] != "boundary_code")

    @property
    def context_blocks(self) -> tuple[tuple[str, int], ...]:
        """The context block's groups (none in older layouts)."""
        return CONTEXT_BLOCKS if self.context else ()

    def without(self, groups) -> FeatureLayout:
        """This layout with ``groups`` disabled as well (same columns)."""
        return dataclasses.replace(self, disabled=tuple(dict.fromkeys(self.disabled + tuple(groups))))

    @property
    def mask(self) -> np.ndarray:
        """Bool ``(size,)``: the columns the model uses."""
        m = np.ones(self.size, dtype=bool)
        for name in self.disabled:
            for a, b in self.spans.get(name, []):
                m[a:b] = False
        return m

    def to_json(self) -> dict[str, Any]:
        return {"k": self.k, "disabled": list(self.disabled), "min_points": self.min_points, "colour": self.colour,
                "boundary": self.boundary, "context": self.context, "size": self.size,
                "global_blocks": [list(b) for b in self.global_blocks], "local_blocks": [list(b) for b in LOCAL_BLOCKS],
                "context_blocks": [list(b) for b in self.context_blocks], "context_margin": CONTEXT_MARGIN,
                "unit_tents": list(UNIT_TENTS), "metric_tents": list(METRIC_TENTS),
                "boundary_tents": list(BOUNDARY_TENTS),
                "order": "global blocks, then for each sub-box (x-major: index = (i*K + j)*K + k) its local blocks, "
                         "then the context blocks"}

    @classmethod
    def from_json(cls, d: dict[str, Any]) -> FeatureLayout:
        # models written before colour normalisation existed used raw colours
        # and before the boundary code (the context block) existed had no such block
        lay = cls(int(d["k"]), tuple(d.get("disabled", ())), int(d.get("min_points", 1)),
                  str(d.get("colour", "none")), bool(d.get("boundary", False)), bool(d.get("context", False)))
        if "size" in d and int(d["size"]) != lay.size:
            raise ValueError(f"feature layout of size {d['size']}, this version builds {lay.size}")
        return lay


def sub_bounds(width: np.ndarray, k: int) -> np.ndarray:
    """Sub-box edges ``(..., k + 1)`` (voxel offsets from the window's corner) of windows ``width`` voxels wide."""
    w = np.asarray(width, dtype=np.int64)
    return (np.arange(k + 1) * w[..., None]) // k


def global_features(position: np.ndarray, size: np.ndarray, metric_size: np.ndarray,
                    extent: np.ndarray | None = None) -> np.ndarray:
    """The global block ``(..., n_global)`` from unit-cube P, S and the size in metres (all ``(..., 3)``).

    With the space's ``extent`` (metres, ``(3,)``) the block ends with the boundary code
    (layouts with ``boundary``); without it, it stops after the metric size code.
    """
    position = np.asarray(position, dtype=np.float64)
    size = np.asarray(size, dtype=np.float64)
    centre = position + size / 2.0
    lead = position.shape[:-1]
    parts = [position, tent_code(centre, UNIT_TENTS).reshape(*lead, -1), size,
             tent_code(size, UNIT_TENTS).reshape(*lead, -1),
             tent_code(np.log2(np.maximum(metric_size, 1e-6)), np.log2(METRIC_TENTS)).reshape(*lead, -1)]
    if extent is not None:
        parts.append(tent_code(boundary_distance(position, size, extent), BOUNDARY_TENTS).reshape(*lead, -1))
    return np.concatenate(parts, axis=-1)


def boundary_distance(position: np.ndarray, size: np.ndarray, extent: np.ndarray) -> np.ndarray:
    """Metres from a window (unit-cube ``position`` and ``size``) to the space's nearer end, per axis."""
    ext = np.asarray(extent, dtype=np.float64)
    return np.maximum(np.minimum(position, 1.0 - position - size) * ext, 0.0)


def global_scores(positions: tuple[np.ndarray, np.ndarray, np.ndarray], shape: np.ndarray, grid_shape,
                  voxel: np.ndarray, weights: np.ndarray,
                  boundary: bool = False) -> tuple[list[np.ndarray], np.ndarray]:
    """The global block's share of linear scores of one window shape at a grid of positions, separably.

    Parameters
    ----------
    positions
        Window starts (voxels) along x, y and z.
    shape
        The window's size in voxels ``(3,)``.
    grid_shape, voxel
        The space's grid: voxels per axis and voxel size (metres) per axis.
    weights
        ``(m, n_global)`` weights of the global block.
    boundary
        Whether the block ends with the boundary code (the layout's ``boundary``).

    Returns
    -------
    ``terms`` (per axis ``(m, n_a)``) and ``const`` ``(m,)``: for the window at
    ``(px[i], py[j], pz[k])``, ``global_features(...) @ weights[j]`` equals
    ``terms[0][j, i] + terms[1][j, j'] + terms[2][j, k] + const[j]`` up to the
    order of the sums.  Every global feature depends on one axis's position
    (P and its code) or on none (the size codes), so the block costs a few
    numbers per position along each axis instead of a vector per window.
    """
    n = np.asarray(grid_shape)
    shape = np.asarray(shape)
    size = shape / n
    weights = np.asarray(weights, dtype=np.float64)
    nt, nb = len(UNIT_TENTS), len(BOUNDARY_TENTS)
    cut = 3 + 3 * nt  # then S, its code and the metric code: the same for every position
    end = cut + 3 + 3 * nt + 3 * len(METRIC_TENTS)  # then the boundary code, per axis again
    extent = n * np.asarray(voxel, dtype=np.float64)
    terms = []
    for a in range(3):
        p = np.asarray(positions[a]) / n[a]
        code = tent_code(p + size[a] / 2.0, UNIT_TENTS)  # (n_a, 5): the position code's columns of axis a
        t = weights[:, a, None] * p[None] + weights[:, 3 + a * nt:3 + (a + 1) * nt] @ code.T
        if boundary:
            d = boundary_distance(p, size[a], extent[a])
            t = t + weights[:, end + a * nb:end + (a + 1) * nb] @ tent_code(d, BOUNDARY_TENTS).T
        terms.append(t)
    const = weights[:, cut:end] @ global_features(np.zeros(3), size, shape * np.asarray(voxel))[cut:end]
    return terms, const


def local_features(sums: np.ndarray, n_window: np.ndarray, k: int, min_points: int = 1) -> np.ndarray:
    """Local features ``(..., 9)`` of sub-boxes from their moment sums ``(..., 13)``.

    ``n_window`` (broadcastable to ``sums[..., 0]``) is the point count of each
    sub-box's window, for the ratio.  Sub-boxes with fewer than ``min_points``
    points get all zeros; normal and curvature need 3 points.
    """
    lead = sums.shape[:-1]
    sums = sums.reshape(-1, sums.shape[-1])
    n = sums[:, 0]
    occ = n >= max(min_points, 1)
    safe = np.where(n > 0, n, 1.0)
    out = np.zeros((len(sums), LOCAL_SIZE))
    out[:, 0] = occ
    out[:, 1] = np.where(occ, n / np.broadcast_to(np.maximum(n_window, 1.0), lead).reshape(-1) * k ** 3, 0.0)
    out[:, 2:5] = np.where(occ[:, None], sums[:, 10:13] / safe[:, None], 0.0)
    geo = occ & (n >= 3)
    if geo.all():
        lam, total, vec = mom.smallest_eigen_columns(*mom.covariance_columns(sums))
    elif geo.any():  # eigen-analysis only where there is a surface to analyse
        lam, total, vec = mom.smallest_eigen_columns(*mom.covariance_columns(sums[geo]))
    if geo.any():
        ok = total > 0
        out[geo, 5:8] = np.where(ok[:, None], np.abs(vec), 0.0)
        out[geo, 8] = np.where(ok, lam / np.where(ok, total, 1.0), 0.0)
    return out.reshape(*lead, LOCAL_SIZE)


def context_margin(voxel: np.ndarray) -> np.ndarray:
    """Slab thickness in voxels ``(3,)`` per axis: :data:`CONTEXT_MARGIN` metres, at least one voxel."""
    return np.maximum(1, np.round(CONTEXT_MARGIN / np.asarray(voxel, dtype=np.float64))).astype(np.int64)


def slab_interval(iv: np.ndarray, side: int, margin: int, n: int) -> np.ndarray:
    """The intervals ``(m, 2)`` of the slabs before (``side`` -1) or after (+1) intervals ``iv`` ``(m, 2)``."""
    iv = np.asarray(iv, dtype=np.int64)
    if side < 0:
        return np.stack([np.maximum(iv[:, 0] - margin, 0), iv[:, 0]], axis=1)
    return np.stack([iv[:, 1], np.minimum(iv[:, 1] + margin, n)], axis=1)


def context_features(window: np.ndarray, slabs: np.ndarray) -> np.ndarray:
    """The context block ``(..., 15)`` from sums ``(..., 4)`` of the window and ``(..., 6, 4)`` of its slabs.

    Sums are of :data:`CONTEXT_CHANNELS` (count, r, g, b); the slabs in the
    order x-, x+, y-, y+, z-, z+.  Contrasts are zero where either side holds no points.
    """
    n_w = window[..., 0]
    n_s = slabs[..., 0]
    fill = n_s / np.maximum(n_s + n_w[..., None], 1.0)
    lead = n_w.shape
    out = np.empty(lead + (CONTEXT_SIZE,))
    out[..., 0] = np.minimum(fill[..., 0], fill[..., 1])
    out[..., 1] = np.maximum(fill[..., 0], fill[..., 1])
    out[..., 2] = np.minimum(fill[..., 2], fill[..., 3])
    out[..., 3] = np.maximum(fill[..., 2], fill[..., 3])
    out[..., 4:6] = fill[..., 4:6]
    has_w = n_w > 0
    mean_w = window[..., 1:4] / np.maximum(n_w, 1.0)[..., None]
    lum_w = mean_w.mean(axis=-1)
    for a in range(3):
        pair = slabs[..., 2 * a, :] + slabs[..., 2 * a + 1, :]
        n_p = pair[..., 0]
        d = np.where(has_w & (n_p > 0), lum_w - pair[..., 1:4].mean(axis=-1) / np.maximum(n_p, 1.0), 0.0)
        out[..., 6 + a] = d
        out[..., 9 + a] = np.abs(d)
    every = slabs.sum(axis=-2)
    n_e = every[..., 0]
    ok = (has_w & (n_e > 0))[..., None]
    out[..., 12:15] = np.where(ok, mean_w - every[..., 1:4] / np.maximum(n_e, 1.0)[..., None], 0.0)
    return out


def window_context(iv: np.ndarray, grid: mom.VoxelGrid, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """The context block ``(n, 15)`` of windows ``[lo, hi)`` (voxel indices ``(n, 3)``); ``iv`` all channels."""
    shape = np.asarray(grid.shape)
    g = context_margin(grid.voxel)
    ch = list(CONTEXT_CHANNELS)
    window = mom.box_sums(iv, lo, hi)[..., ch]
    slabs = []
    for a in range(3):
        for side in (-1, 1):
            slo, shi = lo.copy(), hi.copy()
            cut = slab_interval(np.stack([lo[:, a], hi[:, a]], axis=1), side, int(g[a]), int(shape[a]))
            slo[:, a], shi[:, a] = cut[:, 0], cut[:, 1]
            slabs.append(mom.box_sums(iv, slo, shi)[..., ch])
    return context_features(window, np.stack(slabs, axis=-2))


def window_features(iv: np.ndarray, grid: mom.VoxelGrid, lo: np.ndarray, hi: np.ndarray,
                    layout: FeatureLayout, chunk: int = 4096) -> np.ndarray:
    """Feature vectors ``(n, layout.size)`` of windows ``[lo, hi)`` (voxel indices ``(n, 3)``).

    Used for training samples; :mod:`engine.detection.sliding` computes the same scores for
    all positions of a window shape at once without materialising the vectors.
    """
    lo = np.asarray(lo, dtype=np.int64).reshape(-1, 3)
    hi = np.asarray(hi, dtype=np.int64).reshape(-1, 3)
    k = layout.k
    out = np.zeros((len(lo), layout.size), dtype=np.float64)
    shape = np.asarray(grid.shape)
    vox = grid.voxel
    for s in range(0, len(lo), chunk):
        l, h = lo[s:s + chunk], hi[s:s + chunk]
        w = h - l
        out[s:s + chunk, :layout.n_global] = global_features(l / shape, w / shape, w * vox,
                                                              shape * vox if layout.boundary else None)
        b = sub_bounds(w, k)  # (m, 3, k+1)
        starts = l[:, :, None] + b[:, :, :-1]
        stops = l[:, :, None] + b[:, :, 1:]
        # all K^3 sub-boxes, x-major
        ix, iy, iz = np.meshgrid(np.arange(k), np.arange(k), np.arange(k), indexing="ij")
        ix, iy, iz = ix.ravel(), iy.ravel(), iz.ravel()
        slo = np.stack([starts[:, 0, ix], starts[:, 1, iy], starts[:, 2, iz]], axis=-1)  # (m, K^3, 3)
        shi = np.stack([stops[:, 0, ix], stops[:, 1, iy], stops[:, 2, iz]], axis=-1)
        sums = mom.box_sums(iv, slo, shi)  # (m, K^3, 13)
        n_win = mom.box_sums(iv, l, h)[:, 0]
        loc = local_features(sums, n_win[:, None], k, layout.min_points)
        out[s:s + chunk, layout.n_global:layout.local_end] = loc.reshape(len(l), -1)
        if layout.context:
            out[s:s + chunk, layout.local_end:] = window_context(iv, grid, l, h)
    out[:, ~layout.mask] = 0.0
    return out


@dataclass
class SpaceVolume:
    """One space ready for windows: its canonical frame, voxel grid and integral volume of moments."""

    frame: Any  # engine.detection.canonical.CanonicalFrame
    grid: mom.VoxelGrid
    iv: np.ndarray
    n_points: int

    @property
    def count_iv(self) -> np.ndarray:
        """The integral volume of point counts alone ``(nx+1, ny+1, nz+1, 1)``, contiguous (made once)."""
        return self._channels_iv("_count_iv", (0,))

    @property
    def context_iv(self) -> np.ndarray:
        """The integral volume of :data:`CONTEXT_CHANNELS` alone ``(nx+1, ny+1, nz+1, 4)``, contiguous (made once)."""
        return self._channels_iv("_context_iv", CONTEXT_CHANNELS)

    def _channels_iv(self, key: str, channels: tuple[int, ...]) -> np.ndarray:
        """A contiguous copy of some channels of ``iv``, cached under ``key`` until ``iv`` is replaced."""
        cached = self.__dict__.get(key)
        if cached is None or cached[0] is not self.iv:
            cached = self.__dict__[key] = (self.iv, np.ascontiguousarray(self.iv[..., list(channels)]))
        return cached[1]

    @classmethod
    def build(cls, xyz: np.ndarray, rgb: np.ndarray | None, frame: Any, voxel: float,
              max_cells: int, colour: str = "none") -> SpaceVolume:
        """Accumulate the moments of a space's points (``xyz`` in the frame's coordinates, ``rgb`` in [0, 1]).

        ``colour`` normalises the colours first (:func:`normalise_colours`; a model's ``layout.colour``).
        """
        grid = mom.VoxelGrid.covering(frame.extent, voxel, max_cells)
        return cls.from_metric(frame.to_metric(xyz), rgb, frame, grid, colour)

    @classmethod
    def from_metric(cls, metric: np.ndarray, rgb: np.ndarray | None, frame: Any, grid: mom.VoxelGrid,
                    colour: str = "none", flat: np.ndarray | None = None) -> SpaceVolume:
        """:meth:`build` from points already in canonical metres (``frame.to_metric``) on a chosen grid.

        ``flat`` is their :meth:`engine.detection.moments.VoxelGrid.flat_index` when the caller has it.
        The colours are scaled by :func:`colour_factor` column by column as they are summed
        (the same values as :func:`normalise_colours`, without a normalised copy).
        """
        m = mom.voxel_moments(metric, rgb, grid, flat, rgb_scale=colour_factor(rgb, colour))
        return cls(frame, grid, mom.integral_volume(m), int(len(metric)))

    def voxel_box(self, position: np.ndarray, size: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Unit-cube boxes ``(n, 3)`` snapped to voxel boxes ``[lo, hi)`` inside the grid.

        Ends are rounded to the nearest voxel boundary; a box thinner than that
        along an axis becomes the one voxel holding its centre.
        """
        shape = np.asarray(self.grid.shape)
        p = np.asarray(position, dtype=np.float64) * shape
        q = (np.asarray(position, dtype=np.float64) + np.asarray(size, dtype=np.float64)) * shape
        lo = np.round(p).astype(np.int64)
        hi = np.round(q).astype(np.int64)
        thin = hi <= lo
        centre = np.floor((p + q) / 2.0).astype(np.int64)
        lo = np.where(thin, centre, lo)
        hi = np.where(thin, centre + 1, hi)
        lo = np.clip(lo, 0, shape - 1)
        hi = np.clip(hi, lo + 1, shape)
        return lo, hi
