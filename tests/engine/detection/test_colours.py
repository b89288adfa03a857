"""Colour normalisation per space: a space's exposure cancels, the contrast between its surfaces stays."""
from __future__ import annotations

import numpy as np
import pytest

from engine.detection.canonical import CanonicalFrame
from engine.detection.colours import COLOUR_TARGET, normalise_colours
from engine.detection.features import window_features
from engine.detection.layout import FeatureLayout
from engine.detection.volume import SpaceVolume


def test_colour_normalisation_cancels_a_space_exposure_and_keeps_contrast():
    rng = np.random.default_rng(4)
    n = 6000
    # a light ceiling over a dark floor, the same space scanned at full and at half exposure
    xyz = np.c_[rng.uniform(0, 2, n), rng.uniform(0, 2, n), np.where(np.arange(n) < 4000, 1.95, 0.05)]
    rgb = np.where((np.arange(n) < 4000)[:, None], [0.9, 0.9, 0.85], [0.3, 0.2, 0.2])
    rgb = rgb + rng.normal(0, 0.01, (n, 3))
    lo, hi = np.array([[0, 0, 0]]), np.array([[20, 20, 20]])
    lay = FeatureLayout(k=2)
    assert lay.colour == "space-median"

    def colour_block(scale, mode):
        frame = CanonicalFrame(0.0, [0.0, 0.0, 0.0], (2.0, 2.0, 2.0))
        vol = SpaceVolume.build(xyz, rgb * scale, frame, 0.1, 10**7, mode)
        feats = window_features(vol.iv, vol.grid, lo, hi, lay)[0]
        return feats[lay.n_global:lay.local_end].reshape(lay.k, lay.k, lay.k, -1)[..., 2:5]  # the local block's colours

    full, half = colour_block(1.0, "space-median"), colour_block(0.5, "space-median")
    assert np.allclose(full, half)  # the exposure cancels
    # the median luminance (the ceiling's, 4000 of 6000 points) becomes the target; the floor stays darker
    assert full[:, :, 1].mean() == pytest.approx(COLOUR_TARGET, rel=0.02)
    assert full[:, :, 0].mean() < 0.5 * full[:, :, 1].mean()
    raw_full, raw_half = colour_block(1.0, "none"), colour_block(0.5, "none")
    assert np.allclose(raw_half, 0.5 * raw_full) and not np.allclose(raw_full, raw_half, atol=0.1)
    assert normalise_colours(None) is None
    with pytest.raises(ValueError, match="colour"):
        FeatureLayout(k=2, colour="gamma")
