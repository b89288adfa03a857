"""Generated training buildings: ``train --styles`` reaches the generator and the model's provenance."""
from __future__ import annotations

import pytest

from engine.training.synthetic import generate_buildings
from engine.training.workflow import prepare_training
from tiles.errors import UserError


def test_generated_training_buildings_have_the_styles_asked_for(tmp_path):
    (classic,), _ = generate_buildings(str(tmp_path / "c"), 41, 1, 60.0, density=60)
    (varied,), names = generate_buildings(str(tmp_path / "v"), 41, 1, 60.0, density=60, styles="varied")
    assert names == ["synthetic seed 41"]
    assert "styles" not in classic.meta.sources[0].info
    assert varied.meta.sources[0].info["styles"] == "varied"
    # the same plan, other scan characters: the varied building's points are not the classic one's
    assert classic.meta.sources[0].info["seed"] == varied.meta.sources[0].info["seed"] == 41
    assert classic.meta.point_count != varied.meta.point_count


def test_training_styles_are_checked_before_any_work(tmp_path):
    plan = prepare_training([], str(tmp_path / "m"), synthetic=2, styles="varied")
    assert plan.styles == "varied" and plan.synthetic == 2
    assert prepare_training([], str(tmp_path / "m"), synthetic=2).styles == "classic"
    with pytest.raises(UserError, match="--styles must be classic or a comma-separated combination of varied, subsampled, windows"):
        prepare_training([], str(tmp_path / "m"), synthetic=2, styles="baroque")
