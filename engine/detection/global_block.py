"""The global block of a window's features (paper Table 1): its position and size, and their tent codes.

P and S in the unit cube, each also as a piecewise-linear "soft one-hot" code (:func:`tent_code`), the size in
metres (log2 code) and, in layouts with ``boundary``, the distance to the space's nearer end.
:func:`global_scores` gives the block's share of linear scores separably, axis by axis.
Design notes: ``docs/design/detection.md``.
"""
from __future__ import annotations

import numpy as np

#: Tent centres of the position and unit-size codes (unit cube).
UNIT_TENTS = (0.0, 0.25, 0.5, 0.75, 1.0)
#: Tent centres of the metric size code, in metres (log2-spaced coding).
METRIC_TENTS = (0.05, 0.15, 0.4, 1.0, 2.5, 6.0)
#: Tent centres of the distance to the space's nearer end, in metres.
BOUNDARY_TENTS = (0.0, 0.1, 0.3, 1.0, 3.0)
GLOBAL_BLOCKS = (("position", 3), ("position_code", 3 * len(UNIT_TENTS)), ("size", 3),
                 ("size_code", 3 * len(UNIT_TENTS)), ("metric_code", 3 * len(METRIC_TENTS)),
                 ("boundary_code", 3 * len(BOUNDARY_TENTS)))


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
