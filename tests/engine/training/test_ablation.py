"""Several models of one dictionary detected in one pass give each model's own proposals."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from engine.detection.detect import detect
from engine.detection.layout import ABLATIONS
from engine.detection.settings import DetectionSettings
from engine.training.ablation import check_compatible, detect_many
from engine.training.settings import TrainSettings
from engine.training.svm import refit_without
from engine.training.train import train_with_samples
from tests.engine.handmade import generated_stores


@pytest.fixture(scope="module")
def setup(tmp_path_factory):
    stores = generated_stores(tmp_path_factory.mktemp("abl"), ((21, 15.0), (22, 50.0)))
    settings = TrainSettings.from_config(rounds=1, classes=(0, 1, 2, 8))  # ceiling, floor, wall, chair
    model, samples = train_with_samples(stores[:1], settings=settings)
    return stores, model, samples


def test_detect_many_equals_each_model_alone(setup):
    stores, model, samples = setup
    models = [model] + [refit_without(model, samples, ABLATIONS[v]) for v in ("no_local", "no_color")]
    check_compatible(models)
    many = detect_many(stores[1], models)
    assert sum(len(p) for p in many) > 0
    for m, got in zip(models, many):
        # training detects each space in its own frame (its buildings are exact), not in its group's orientation
        alone = detect(stores[1], model=m, space_array="gt_space",
                       settings=DetectionSettings.from_config(orientation_tolerance=0.0))
        assert len(got) == len(alone)
        for a, b in zip(got, alone):
            assert (a.space_id, a.class_code, a.element_id) == (b.space_id, b.class_code, b.element_id)
            np.testing.assert_allclose(a.center, b.center, atol=1e-9)
            np.testing.assert_allclose(a.world_size, b.world_size, atol=1e-9)
            assert a.score == pytest.approx(b.score, abs=1e-6)
    # the ablated models' own detections differ from the full model's (their weights do)
    assert any(len(a) != len(b) or any(abs(p.score - q.score) > 1e-3 for p, q in zip(a, b))
               for a, b in zip(many[1:], many[:1] * 2))


def test_models_of_different_dictionaries_are_refused(setup):
    _, model, _ = setup
    other = dataclasses.replace(model, voxel=model.voxel * 2)
    with pytest.raises(ValueError, match="same dictionary"):
        check_compatible([model, other])
