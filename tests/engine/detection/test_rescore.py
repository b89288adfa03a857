"""Learned re-ranking of final detections: features of hand-made boxes, a validated fit that is used only when it
ranks better than the detector, the model file, and detection and training using it."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from engine.detection import rescore as rs
from engine.metrics.precision import average_precision


def test_space_features_read_the_nearer_end_wherever_the_box_stands():
    extent = np.array([6.0, 4.0, 3.0])
    lo = np.array([[0.1, 1.0, 0.0], [5.4, 1.0, 2.0]])  # 0.1 m from x's low end; 0.1 m from its high end
    hi = np.array([[0.6, 2.0, 1.0], [5.9, 2.0, 3.0]])
    f = rs.space_features(lo, hi, extent)
    assert f.shape == (2, 11)
    np.testing.assert_allclose(f[:, :3], np.log([[0.5, 1.0, 1.0]] * 2))
    np.testing.assert_allclose(f[:, 3], np.log(0.15))  # the same near-end distance on either side
    np.testing.assert_allclose(f[:, 4], np.log(1.05))
    np.testing.assert_allclose(f[:, 5:7], [[0.0, 1 / 3], [2 / 3, 1.0]])  # bottom and top in the space's height
    np.testing.assert_allclose(f[:, 10], 0.5 / 24.0)


def test_rescore_features_hold_the_score_and_see_where_points_stop():
    extent = np.array([5.0, 5.0, 3.0])
    rng = np.random.default_rng(0)
    wall = rng.uniform([0.0, 2.0, 0.0], [5.0, 2.05, 3.0], (4000, 3))  # a wall running on past the box

    def points_in(lo, hi):
        return wall[np.all((wall >= lo) & (wall <= hi), axis=1)]

    lo, hi = np.array([[1.0, 1.9, 0.0], [1.0, 1.9, 0.0]]), np.array([[1.5, 2.2, 2.0], [5.0, 2.2, 3.0]])
    f = rs.rescore_features(np.array([1.5, -0.5]), lo, hi, points_in, extent)
    assert f.shape == (2, rs.N_FEATURES)
    np.testing.assert_array_equal(f[:, 0], [1.5, -0.5])
    # the wider horizontal role (x here): the piece of wall has points on both sides beyond the box, the
    # whole wall's box none: their shares inside the box differ
    wide = 1 + 1 * rs.BOX_FEATURES
    share = wide + rs.BOX_FEATURES - 2
    assert f[0, share] < 0.5 < f[1, share]
    # a space without detections (training must not stop at it)
    none = rs.rescore_features(np.zeros(0), np.zeros((0, 3)), np.zeros((0, 3)), points_in, extent)
    assert none.shape == (0, rs.N_FEATURES)


def _samples(n_buildings: int, per: int, informative: bool, seed: int = 0) -> tuple[dict, np.ndarray]:
    """Detections of class 6 whose score is noise; feature 5 tells true from false when ``informative``."""
    rng = np.random.default_rng(seed)
    n = n_buildings * per
    tp = rng.random(n) < 0.3
    feats = rng.normal(size=(n, rs.N_FEATURES))
    feats[:, 0] = rng.normal(size=n)
    if informative:
        feats[:, 5] += 2.5 * tp
    n_gt = np.zeros(12, int)
    n_gt[6] = int(tp.sum()) + 5  # a few elements no detection found
    return {"cls": np.full(n, 6), "feats": feats, "tp": tp, "building": np.repeat(np.arange(n_buildings), per)}, n_gt


def test_fit_is_used_where_validation_ranks_better_and_ranks_new_detections_better():
    samples, n_gt = _samples(6, 60, informative=True)
    fit = rs.fit_rescorer(samples, n_gt)
    rep = fit.report["classes"]["door"]
    assert fit.enabled[6] and rep["enabled"] and rep[f"ap_c{rep['c']:g}"] >= rep["ap_detector"] + rs.MARGIN
    assert not fit.enabled[:6].any() and not fit.enabled[7:].any()
    new, n_new = _samples(3, 60, informative=True, seed=1)
    before = average_precision(new["feats"][:, 0], new["tp"], int(n_new[6]))
    after = average_precision(fit.decision(new["cls"], new["feats"]), new["tp"], int(n_new[6]))
    assert after > before + 0.2


def test_fit_stays_off_on_noise_and_with_too_few_buildings():
    noise = rs.fit_rescorer(*_samples(6, 60, informative=False))
    assert not noise.enabled.any() and np.all(noise.coef == 0)
    few = rs.fit_rescorer(*_samples(2, 60, informative=True))
    assert not few.enabled[6] and "too few" in few.report["classes"]["door"]["why"]


def test_apply_rescores_only_enabled_classes():
    coef = np.zeros((12, rs.N_FEATURES))
    coef[6, 0] = -2.0  # doors: the score turned around
    enabled = np.zeros(12, bool)
    enabled[6] = True
    fit = rs.Rescorer(np.zeros((12, rs.N_FEATURES)), np.ones((12, rs.N_FEATURES)), coef, np.full(12, 0.5), enabled)
    lo, hi = np.array([[1.0, 1.0, 0.0], [2.0, 2.0, 0.0]]), np.array([[2.0, 1.2, 2.0], [3.0, 3.0, 0.8]])
    out = fit.apply(np.array([1.0, 1.0]), np.array([6, 7]), lo, hi, lambda a, b: np.zeros((0, 3)),
                    np.array([5.0, 5.0, 3.0]))
    np.testing.assert_allclose(out, [-1.5, 1.0])
    with pytest.raises(ValueError):
        rs.Rescorer(coef[:, :3], coef[:, :3], coef[:, :3], np.zeros(12), enabled)


def test_clip_holds_a_feature_that_training_barely_saw_varying():
    # a feature nearly constant in training (scale 1e-4) read on an unfamiliar building: 0.1 away is 1,000 sigmas
    f = rs.N_FEATURES
    scale, coef = np.ones((12, f)), np.zeros((12, f))
    scale[:, 1] = 1e-4
    coef[4, :2] = [1.0, 0.5]
    fit = rs.Rescorer(np.zeros((12, f)), scale, coef, np.zeros(12), np.ones(12, bool))
    feats = np.zeros((2, f))
    feats[:, :2] = [[0.5, 0.1], [0.5, 0.0]]
    np.testing.assert_allclose(fit.decision(np.array([4, 4]), feats), [500.5, 0.5])
    np.testing.assert_allclose(fit.decision(np.array([4, 4]), feats, clip=10.0), [5.5, 0.5])  # 0.5 + 0.5 * 10
    np.testing.assert_allclose(fit.decision(np.array([4, 4]), feats * 0.0001, clip=10.0),
                               fit.decision(np.array([4, 4]), feats * 0.0001))  # within the clip: unchanged


def test_model_with_rescorer_round_trips_and_older_models_have_none(tmp_path):
    from engine.detection.model import load_model
    from tests.engine.detection.test_model import _model

    m = _model()
    rng = np.random.default_rng(3)
    enabled = np.zeros(12, bool)
    enabled[[4, 6]] = True
    fit = rs.Rescorer(rng.normal(size=(12, rs.N_FEATURES)), rng.uniform(0.5, 2, (12, rs.N_FEATURES)),
                      rng.normal(size=(12, rs.N_FEATURES)), rng.normal(size=12), enabled,
                      {"classes": {"door": {"enabled": True}}})
    dataclasses.replace(m, rescorer=fit).save(tmp_path / "v4")
    back = load_model(tmp_path / "v4")
    assert back.params()["version"] == 4 and back.params()["rescore"]["classes"]["door"]["enabled"]
    for k, v in fit.to_arrays().items():
        np.testing.assert_array_equal(back.rescorer.to_arrays()[k], v)
    m.save(tmp_path / "v1")
    assert load_model(tmp_path / "v1").rescorer is None and "rescore_coef" not in m.params()["arrays"]
