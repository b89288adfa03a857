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


def test_the_training_rules_of_the_shipped_model_are_the_configured_ones(trained):
    """``make model`` must reproduce the shipped model: its dictionary rule and mining are the settings' defaults."""
    import dask

    from engine.model import load_model

    _, settings, model, _ = trained
    shipped = load_model(None).svm["settings"]
    assert (settings.relative_ratio, settings.mining) == (shipped["relative_ratio"], shipped["mining"]) == (0.5, "hardest")
    assert model.dictionary.relative_ratio == 0.5 and model.svm["settings"]["mining"] == "hardest"
    with dask.config.set({"buildingparser.detection.train.relative-ratio": None,
                          "buildingparser.detection.train.mining": "random"}):
        assert (TrainSettings.from_config().relative_ratio, TrainSettings.from_config().mining) == (None, "random")


def test_hardest_mining_takes_the_highest_scoring_fresh_violators(trained):
    """``mining: hardest``: a space's hard negatives are its top-scoring violators, none mined before."""
    import dataclasses

    from engine.detection import DetectionSettings
    from engine.training import _instances_task, _samples_task, training_jobs

    store, settings, model, _ = trained
    det = DetectionSettings.from_config()
    det = dataclasses.replace(det, max_stride=max(det.max_stride, settings.max_stride))
    jobs = training_jobs([store])
    job = max(jobs, key=lambda j: j.ref.count)
    job = dataclasses.replace(job, frame=_instances_task(job, settings)["frame"])
    n = 15
    out = {}
    for mining in ("random", "hardest"):
        s = dataclasses.replace(settings, mining=mining, hard_negatives=n)
        out[mining] = _samples_task(job, model, s, 1, det, (0, 1, 2))
    for c in (0, 1, 2):
        score = {m: np.sort(out[m][c]["neg"].astype(np.float64) @ model.weights[c] + model.bias[c])[::-1]
                 for m in out}
        assert len(score["hardest"]) == len(score["random"]) > 0
        # the top n of the violators beat any n of them, rank by rank (float32 features: a small tolerance)
        assert np.all(score["hardest"] >= score["random"] - 1e-3)
    assert np.any(score["hardest"] > score["random"] + 1e-3)
    # a violator already in the training set is passed over for the next one down
    c = 2
    mined = dataclasses.replace(job, mined={c: out["hardest"][c]["keys"][:5]})
    again = _samples_task(mined, model, dataclasses.replace(settings, mining="hardest", hard_negatives=n), 1, det,
                          (c,))[c]["keys"]
    assert not np.isin(out["hardest"][c]["keys"][:5], again).any() and len(again) == n
    with pytest.raises(ValueError):
        TrainSettings(mining="best")
