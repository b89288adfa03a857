"""Scan character per space: density x0.5-x2, noise 2-6 mm, some rooms darker; shading clips to 8 bits."""
from __future__ import annotations

import numpy as np

from engine.synth import plan_building
from engine.synth.colours import shade


def test_space_character_ranges():
    b = plan_building(3, area_m2=2500, density=100)
    dens = np.array([s.density for s in b.spaces])
    noise = np.array([s.noise for s in b.spaces])
    bright = np.array([s.brightness for s in b.spaces])
    assert dens.min() >= 0.5 and dens.max() <= 2.0 and dens.max() / dens.min() > 2.5
    assert noise.min() >= 0.002 and noise.max() <= 0.006
    assert (bright < 0.7).any() and (bright > 0.8).mean() > 0.6  # a few dark rooms among lit ones
    walls = {s.colours["wall"] for s in b.spaces}
    assert len(walls) > 2


def test_shade_darkens_with_brightness_and_distance():
    rng = np.random.default_rng(0)
    base = np.full((1000, 3), 200.0)
    near = shade(rng, base, np.zeros(1000), 1.0, np.zeros(1000))
    far_dark = shade(rng, base, np.zeros(1000), 0.5, np.full(1000, 20.0))
    assert np.all(near == 200) and np.all(far_dark == 75)
    noisy = shade(rng, np.full((20000, 3), 128.0), np.full(20000, 30.0), 1.0, np.zeros(20000))
    assert noisy.dtype == np.uint16 and abs(noisy.std() - 30) < 1 and abs(noisy.mean() - 128) < 1
    bright = shade(rng, np.full((20000, 3), 250.0), np.full(20000, 30.0), 1.0, np.zeros(20000))
    assert bright.max() == 255 and (bright == 255).mean() > 0.3  # clipped, never wrapped
