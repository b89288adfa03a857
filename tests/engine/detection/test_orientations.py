"""The building's orientations (engine/detection/orientations.py)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from engine.detection.orientations import reference_yaws, wrap_quarter

DEG = math.pi / 180


def test_frames_group_by_their_yaw_modulo_90_degrees_and_take_the_median():
    main = [29.1, 29.3, 28.8, 29.0, 119.2]  # one a quarter turn off: the same orientation
    wing = [-8.9, -9.2, -8.7]
    ref = np.degrees(reference_yaws(np.radians(main + wing + [6.0]), DEG))
    assert ref[:5] == pytest.approx([29.1] * 5)
    assert ref[5:8] == pytest.approx([-8.9] * 3)
    assert ref[8] == pytest.approx(6.0)  # alone: its own


def test_a_group_across_the_quarter_circles_seam_and_a_chain_too_long_for_the_tolerance():
    ref = np.degrees(reference_yaws(np.radians([44.8, -44.9, 44.9]), DEG))
    assert wrap_quarter(np.radians(ref - 44.9)) == pytest.approx(np.zeros(3), abs=1e-9)
    # a chain 0.8 degrees a link: one group, but its ends are farther than 1 degree from its median
    ref = np.degrees(reference_yaws(np.radians([0.0, 0.8, 1.6, 2.4, 3.2]), DEG))
    assert ref == pytest.approx([0.0, 1.6, 1.6, 1.6, 3.2])


def test_tolerance_zero_keeps_every_space_in_its_own_yaw():
    assert reference_yaws(np.radians([0.3, 0.0]), 0.0) == pytest.approx(np.radians([0.3, 0.0]))


def test_a_space_without_a_yaw_of_its_own_takes_no_part():
    ref = np.degrees(reference_yaws(np.radians([0.2, np.nan, -0.2, 0.3]), DEG))
    assert np.isnan(ref[1]) and ref[[0, 2, 3]] == pytest.approx([0.2] * 3)
