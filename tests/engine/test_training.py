"""Training: the samples it returns refit its own SVMs exactly; ablations drop their feature columns."""
from __future__ import annotations

import numpy as np
import pytest

from engine.features import ABLATIONS, FeatureLayout
from engine.synth import generate
from engine.training import TrainSettings, refit_without, train, train_with_samples
from tiles.store import open_store


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    root = tmp_path_factory.mktemp("train")
    generate(str(root / "b.zarr"), seed=31, rooms=2, density=600, yaw=25.0)
    store = open_store(str(root / "b.zarr"))
    settings = TrainSettings.from_config(rounds=1, classes=(0, 1, 2))
    model, samples = train_with_samples([store], settings=settings)
    return store, settings, model, samples


def test_refit_on_the_samples_reproduces_the_model(trained):
    store, settings, model, samples = trained
    same = refit_without(model, samples, ())
    assert np.array_equal(same.trained, model.trained) and model.trained[:3].all()
    np.testing.assert_array_equal(same.weights, model.weights)
    np.testing.assert_array_equal(same.bias, model.bias)
    # train() is train_with_samples()'s model
    np.testing.assert_array_equal(train([store], settings=settings).weights, model.weights)


@pytest.mark.parametrize("variant", ["no_local", "no_global", "no_color"])
def test_ablation_refit_leaves_out_its_columns(trained, variant):
    _, _, model, samples = trained
    abl = refit_without(model, samples, ABLATIONS[variant])
    off = ~FeatureLayout(model.layout.k, ABLATIONS[variant]).mask
    assert abl.layout.disabled == ABLATIONS[variant]
    assert np.all(abl.weights[:, off] == 0) and np.any(model.weights[:3][:, off] != 0)
    assert not np.allclose(abl.weights[:3], model.weights[:3])
    assert abl.svm["ablation"]["disabled"] == list(ABLATIONS[variant])
    assert abl.dictionary is model.dictionary


def test_the_dictionary_rule_of_the_shipped_model_is_the_default(trained):
    """``make model`` must reproduce the shipped model: training keeps its dictionary rule unless configured."""
    import dask

    _, settings, model, _ = trained
    assert settings.relative_ratio is None and model.dictionary.relative_ratio is None
    with dask.config.set({"buildingparser.detection.train.relative-ratio": 0.5}):
        assert TrainSettings.from_config().relative_ratio == 0.5
