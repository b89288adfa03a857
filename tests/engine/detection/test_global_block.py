"""The global block of a window's features: tent codes, the separable global scores, the boundary code."""
from __future__ import annotations

import numpy as np
import pytest

from engine.detection import moments as mom
from engine.detection.global_block import global_features, global_scores, tent_code
from engine.detection.layout import FeatureLayout


def test_tent_code():
    c = tent_code(np.array([0.0, 0.1, 0.5, 1.2, -3]), (0, 0.25, 0.5, 0.75, 1))
    assert np.allclose(c.sum(1), 1)
    assert np.allclose(c[1], [0.6, 0.4, 0, 0, 0])
    assert np.allclose(c[2], [0, 0, 1, 0, 0]) and np.allclose(c[3], [0, 0, 0, 0, 1]) and np.allclose(c[4], [1, 0, 0, 0, 0])


@pytest.mark.parametrize("shape", [(7, 5, 9), (12, 24, 8), (1, 1, 1)])
def test_global_scores_are_the_global_block_times_the_weights(shape):
    rng = np.random.default_rng(sum(shape))
    grid = mom.VoxelGrid.covering([3.0, 2.4, 2.2], 0.1, 10**6)
    n = np.asarray(grid.shape)
    shape = np.minimum(shape, n)
    pos = [np.unique(np.append(np.arange(0, n[a] - shape[a] + 1, 2), n[a] - shape[a])) for a in range(3)]
    lo = np.stack(np.meshgrid(*pos, indexing="ij"), axis=-1).reshape(-1, 3)
    size = np.broadcast_to(shape, lo.shape)
    i, j, k = np.unravel_index(np.arange(len(lo)), [len(p) for p in pos])
    for boundary in (True, False):  # the current layout, and one written before the boundary code
        lay = FeatureLayout(k=2, boundary=boundary)
        w = rng.normal(size=(3, lay.n_global))
        terms, const = global_scores(pos, shape, grid.shape, grid.voxel, w, boundary)
        want = global_features(lo / n, size / n, size * grid.voxel, n * grid.voxel if boundary else None) @ w.T
        got = terms[0][:, i] + terms[1][:, j] + terms[2][:, k] + const[:, None]
        assert np.allclose(got.T, want, rtol=0, atol=1e-12)
        assert np.ptp(want[:, 0]) > 0.1  # the positions matter


def test_boundary_code_is_the_metric_distance_to_the_nearer_end():
    """A window against an end of a long space is at distance 0 along that axis whatever the room's size."""
    from engine.detection.global_block import BOUNDARY_TENTS, boundary_distance

    ext = np.array([20.0, 4.0, 3.0])
    pos = np.array([0.0, 0.25, 0.5])
    size = np.array([0.1, 0.5, 0.5])
    np.testing.assert_allclose(boundary_distance(pos, size, ext), [0.0, 1.0, 0.0])
    g = global_features(pos, size, size * ext, ext)
    code = g[-3 * len(BOUNDARY_TENTS):].reshape(3, -1)
    np.testing.assert_allclose(code, [[1, 0, 0, 0, 0], [0, 0, 0, 1, 0], [1, 0, 0, 0, 0]])
    old = FeatureLayout.from_json({k: v for k, v in FeatureLayout().to_json().items() if k not in ("boundary", "size")})
    assert not old.boundary and old.size == FeatureLayout().size - 15 and "boundary_code" not in old.spans
    assert FeatureLayout.from_json(FeatureLayout().to_json()).boundary
