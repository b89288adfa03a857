"""The detector's settings: defaults from ``buildingparser.detection.*``, validation, class lists."""
from __future__ import annotations

import pytest

from engine.detection.settings import REFINE_BANDS, DetectionSettings


def test_one_per_space_and_refine_classes_settings():
    assert DetectionSettings.from_config().one_per_space == ("ceiling", "floor")
    assert DetectionSettings.from_config().refine_classes == ("ceiling", "floor", "wall")
    with pytest.raises(ValueError, match="refine-classes"):
        DetectionSettings(refine_classes="walls")
    assert DetectionSettings(one_per_space="wall, floor").one_per_space == ("wall", "floor")
    assert DetectionSettings(one_per_space=()).to_json()["one_per_space"] == []
    with pytest.raises(ValueError, match="one-per-space"):
        DetectionSettings(one_per_space=("stairs",))
    with pytest.raises(ValueError, match="surface-choice"):
        DetectionSettings(surface_choice="highest")


def test_feature_points_setting():
    assert DetectionSettings.from_config().feature_points == 50_000
    assert DetectionSettings(feature_points=0).feature_points == 0  # every point
    with pytest.raises(ValueError, match="feature-points"):
        DetectionSettings(feature_points=-1)


def test_refine_band_setting():
    assert DetectionSettings.from_config().refine_band == "tightest"  # the tightest box of a surface's points
    assert REFINE_BANDS["tightest"] is None and REFINE_BANDS["noise"] == 3.0
    assert DetectionSettings(refine_band="noise").to_json()["refine_band"] == "noise"
    with pytest.raises(ValueError, match="refine-band"):
        DetectionSettings(refine_band="3")


def test_cut_setting():
    """``cut``: the kept set's cut per class (0 for the classes it does not name); unknown classes refused."""
    shipped = DetectionSettings.from_config()
    assert shipped.cut == {"window": -1.0}
    arr = shipped.cut_array()
    assert arr[5] == -1.0 and (arr[[0, 1, 2, 3, 4, 6, 7, 8, 9, 10, 11]] == 0).all()
    assert (DetectionSettings(cut={}).cut_array() == 0).all()
    with pytest.raises(ValueError, match="cut"):
        DetectionSettings(cut={"windows": -1.0})
