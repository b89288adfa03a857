"""The local block of a window's features (paper Table 1): occupancy, ratio, colour, normal, curvature per sub-box.

A window is cut into ``K x K x K`` sub-boxes; sub-box ``j`` along an axis of ``W`` voxels spans voxels
``[lo + (j W) // K, lo + ((j + 1) W) // K)`` (:func:`sub_bounds`).  :func:`local_features` gives their features
from their moment sums.  Design notes: ``docs/design/detection.md``.
"""
from __future__ import annotations

import numpy as np

from engine.detection import moments as mom

LOCAL_BLOCKS = (("occupancy", 1), ("ratio", 1), ("color", 3), ("normal", 3), ("curvature", 1))
LOCAL_SIZE = sum(n for _, n in LOCAL_BLOCKS)


def sub_bounds(width: np.ndarray, k: int) -> np.ndarray:
    """Sub-box edges ``(..., k + 1)`` (voxel offsets from the window's corner) of windows ``width`` voxels wide."""
    w = np.asarray(width, dtype=np.int64)
    return (np.arange(k + 1) * w[..., None]) // k


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
