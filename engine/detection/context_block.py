"""The context block of a window's features (our addition): the slabs of space beside its six faces.

The slabs are :data:`CONTEXT_MARGIN` metres thick (at least one voxel), clipped to the grid, and span the
window's extent along the other two axes; their sums are box sums of the integral volume like everything else.
Design notes: ``docs/design/detection.md``.
"""
from __future__ import annotations

import numpy as np

from engine.detection import moments as mom

#: The context block (layouts with ``context``), after the local blocks.
CONTEXT_BLOCKS = (("context_fill", 6), ("context_color", 9))
CONTEXT_SIZE = sum(n for _, n in CONTEXT_BLOCKS)
#: Thickness in metres of the slabs beside a window's faces that the context block reads.
CONTEXT_MARGIN = 0.3
#: Moment channels the context block reads: the count and the r, g, b sums.
CONTEXT_CHANNELS = (0, 10, 11, 12)


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


def context_sums(iv: np.ndarray, grid: mom.VoxelGrid, lo: np.ndarray, hi: np.ndarray,
                 channels: tuple[int, ...] | None = CONTEXT_CHANNELS) -> tuple[np.ndarray, np.ndarray]:
    """Sums ``(n, 4)`` of windows ``[lo, hi)`` and ``(n, 6, 4)`` of their slabs (x-, x+, y-, y+, z-, z+).

    ``iv`` holds all moment channels (``channels`` picks :data:`CONTEXT_CHANNELS`), or only those (``channels``
    None: :attr:`engine.detection.volume.SpaceVolume.context_iv`).
    """
    shape = np.asarray(grid.shape)
    g = context_margin(grid.voxel)
    pick = (lambda s: s) if channels is None else (lambda s: s[..., list(channels)])  # noqa: E731
    window = pick(mom.box_sums(iv, lo, hi))
    slabs = []
    for a in range(3):
        for side in (-1, 1):
            slo, shi = lo.copy(), hi.copy()
            cut = slab_interval(np.stack([lo[:, a], hi[:, a]], axis=1), side, int(g[a]), int(shape[a]))
            slo[:, a], shi[:, a] = cut[:, 0], cut[:, 1]
            slabs.append(pick(mom.box_sums(iv, slo, shi)))
    return window, np.stack(slabs, axis=-2)


def window_context(iv: np.ndarray, grid: mom.VoxelGrid, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """The context block ``(n, 15)`` of windows ``[lo, hi)`` (voxel indices ``(n, 3)``); ``iv`` all channels."""
    return context_features(*context_sums(iv, grid, lo, hi))


def context_bounds(civ: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Lower and upper bounds ``(15,)`` of each context feature of any window of a space.

    ``civ`` is the space's integral volume of :data:`CONTEXT_CHANNELS`.  Windows and slabs are
    unions of voxels, so a mean colour (or luminance) lies between the least and the greatest of
    the occupied voxels' means: the shares are in [0, 1], a luminance contrast within the
    voxels' luminance span ``s`` (``[-s, s]``, its magnitude ``[0, s]``), a channel's contrast within
    that channel's span.
    """
    sums = np.diff(np.diff(np.diff(civ, axis=0), axis=1), axis=2).reshape(-1, civ.shape[-1])
    sums = sums[sums[:, 0] > 0.5]
    if len(sums):
        means = sums[:, 1:] / sums[:, :1]
        lum = means.mean(axis=1)
        channel = means.max(axis=0) - means.min(axis=0)
        lum_span = float(lum.max() - lum.min())
    else:
        channel, lum_span = np.zeros(3), 0.0
    pad = lambda v: v * (1.0 + 1e-9) + 1e-9  # noqa: E731  (the integral volume's rounding)
    channel, lum_span = pad(channel), pad(lum_span)
    lo = np.concatenate([np.zeros(6), np.full(3, -lum_span), np.zeros(3), -channel])
    hi = np.concatenate([np.ones(6), np.full(6, lum_span), channel])
    return lo, hi
