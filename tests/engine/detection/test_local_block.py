"""The local block of a window's features from sub-box moment sums."""
from __future__ import annotations

import numpy as np
import pytest

from engine.detection.local_block import local_features


def test_curvature_of_a_corner_and_normals_from_moments_match_eigh():
    rng = np.random.default_rng(2)
    sums = np.zeros((50, 13))
    for i in range(50):
        p = rng.normal(size=(30, 3)) * rng.uniform(0.01, 1, 3)
        sums[i, 0] = 30
        sums[i, 1:4] = p.sum(0)
        for k, (a, b) in enumerate(((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))):
            sums[i, 4 + k] = (p[:, a] * p[:, b]).sum()
        w, v = np.linalg.eigh(np.cov(p.T, bias=True))
        f = local_features(sums[i:i + 1], np.array([30.0]), 1)[0]
        assert f[8] == pytest.approx(w[0] / w.sum(), rel=1e-6)
        assert np.allclose(f[5:8], np.abs(v[:, 0]), atol=1e-6)
