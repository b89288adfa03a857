"""Training: the samples it returns refit its own SVMs exactly; ablations drop their feature columns."""
from __future__ import annotations

import numpy as np
import pytest

from engine.detection.layout import ABLATIONS, FeatureLayout
from engine.synth import generate
from engine.training.settings import TrainSettings
from engine.training.svm import refit_without
from engine.training.train import train, train_with_samples
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
    """``make model`` must reproduce the shipped model: its dictionary rule, mining and window weights are the
    settings' defaults."""
    import dask

    from engine.detection.model import load_model

    _, settings, model, _ = trained
    shipped = load_model(None).svm["settings"]
    assert (settings.relative_ratio, settings.mining) == (shipped["relative_ratio"], shipped["mining"]) \
        == (0.5, "hardest")
    assert (settings.atom_weights, settings.atom_scale) == (shipped["atom_weights"], shipped["atom_scale"]) \
        == (True, 0.5)
    assert load_model(None).atom_weights is not None
    # per-class feature groups validated on folds, and the learned box regression: the shipped model has both
    assert (settings.select_groups, settings.box_fit, settings.group_classes) == (
        shipped["select_groups"], shipped["box_fit"], shipped["group_classes"])
    # the walls the space update needs keep all their groups
    assert "wall" not in settings.group_classes.split(",") and "wall" not in load_model(None).svm["groups"]["chosen"]
    assert settings.select_groups and settings.box_fit
    # the context block: configured, and in the shipped model's layout
    assert settings.context and shipped["context"] and load_model(None).layout.context and model.layout.context
    assert load_model(None).boxfit is not None and load_model(None).svm["groups"]["chosen"]
    # the learned re-ranking: configured, and in the shipped model, learnt out of fold and used for some classes
    rescorer = load_model(None).rescorer
    assert settings.rescore and shipped["rescore"] and rescorer is not None and rescorer.enabled.any()
    assert rescorer.report["samples"] == "out of fold"
    assert model.dictionary.relative_ratio == 0.5 and model.svm["settings"]["mining"] == "hardest"
    with dask.config.set({"buildingparser.detection.train.relative-ratio": None,
                          "buildingparser.detection.train.mining": "random"}):
        assert (TrainSettings.from_config().relative_ratio, TrainSettings.from_config().mining) == (None, "random")


def test_training_detects_without_the_planar_fit_and_the_kept_sets_cut(trained):
    """The planar fit moves boxes after their scores and re-ranking: the box regression and the re-ranking learn on
    the boxes they are applied to, so training's own detection passes leave it out, whatever the settings say; and
    they learn on the scores before the kept set's cut (``cut``, applied after the re-ranking)."""
    from engine.detection.settings import DetectionSettings

    assert DetectionSettings.from_config().planar_classes == ("board",)
    assert DetectionSettings.from_config().cut == {"window": -1.0}
    assert trained[2].detection["planar_classes"] == [] and trained[2].detection["cut"] == {}


def test_hardest_mining_takes_the_highest_scoring_fresh_violators(trained):
    """``mining: hardest``: a space's hard negatives are its top-scoring violators, none mined before."""
    import dataclasses

    from engine.detection.settings import DetectionSettings
    from engine.training.jobs import instances_task, training_jobs
    from engine.training.samples import samples_task

    store, settings, model, _ = trained
    det = DetectionSettings.from_config()
    det = dataclasses.replace(det, max_stride=max(det.max_stride, settings.max_stride))
    jobs = training_jobs([store])
    job = max(jobs, key=lambda j: j.ref.count)
    job = dataclasses.replace(job, frame=instances_task(job, settings)["frame"])
    n = 15
    out = {}
    for mining in ("random", "hardest"):
        s = dataclasses.replace(settings, mining=mining, hard_negatives=n)
        out[mining] = samples_task(job, model, s, 1, det, (0, 1, 2))
    for c in (0, 1, 2):
        score = {}
        for m in out:  # each negative scored with its window's weights (the class's plus the window's own)
            w, b = model.window_weights(out[m][c]["keys"] >> 48)
            score[m] = np.sort(np.einsum("nd,nd->n", out[m][c]["neg"].astype(np.float64), w) + b)[::-1]
        assert len(score["hardest"]) == len(score["random"]) > 0
        # the top n of the violators beat any n of them, rank by rank (float32 features: a small tolerance)
        assert np.all(score["hardest"] >= score["random"] - 1e-3)
    assert np.any(score["hardest"] > score["random"] + 1e-3)
    # a violator already in the training set is passed over for the next one down
    c = 2
    mined = dataclasses.replace(job, mined={c: out["hardest"][c]["keys"][:5]})
    again = samples_task(mined, model, dataclasses.replace(settings, mining="hardest", hard_negatives=n), 1, det,
                         (c,))[c]["keys"]
    assert not np.isin(out["hardest"][c]["keys"][:5], again).any() and len(again) == n
    with pytest.raises(ValueError):
        TrainSettings(mining="best")


def test_training_with_windows_own_weights_scores_with_them(trained):
    """``atom-weights``: the model holds each window's part, refits reproduce it, detection uses it."""
    import dataclasses

    from engine.detection.settings import DetectionSettings
    from engine.detection.sliding import score_windows, window_shape
    from engine.detection.space import detect_space, prepare_space, space_frame
    from engine.spaces.points import index_spaces, load_space

    store, settings, _, _ = trained
    s = dataclasses.replace(settings, atom_weights=True, rescore=False)  # version 2: window weights alone
    model, samples = train_with_samples([store], settings=s)
    assert model.atom_weights is not None and model.params()["version"] == 2
    used = [a for a, at in enumerate(model.dictionary.atoms_) if model.trained[at.class_code]]
    assert np.any(model.atom_weights[used] != 0)
    same = refit_without(model, samples, ())
    np.testing.assert_array_equal(same.atom_weights, model.atom_weights)
    np.testing.assert_array_equal(same.atom_bias, model.atom_bias)
    # a detection's score is its window's score with the class's and the window's own weights
    ref = max(index_spaces(store, "gt_space"), key=lambda r: r.count)
    pts = load_space(store, ref, "gt_space")
    det = DetectionSettings.from_config()
    det = dataclasses.replace(det, local_search=False, refine=False)
    props = detect_space(pts, model, det)
    assert props
    vol = prepare_space(pts, model, space_frame(pts))
    p = props[0]
    a = p.extra["atom"]
    w, b = model.window_weights([a])
    shape = window_shape(model.dictionary.atoms_[a].size_in(vol.grid.extent), vol.grid)
    ws = score_windows(vol, shape, w[0], float(b[0]), model.layout, det.stride, det.min_window_points, det.max_stride)
    assert np.isclose(ws.scores.max(), max(q.score for q in props if q.extra["atom"] == a), atol=1e-6)
