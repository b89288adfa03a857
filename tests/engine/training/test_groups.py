"""Per-class feature groups: the choice rule, the refit of the chosen classes, and training that validates them
on building-wise folds."""
from __future__ import annotations

import numpy as np
import pytest

from engine.detection.layout import ABLATIONS, FeatureLayout
from engine.training import groups
from engine.training.settings import TrainSettings
from engine.training.svm import refit_without
from engine.training.train import train_with_samples
from tests.engine.handmade import generated_stores
from tiles.classes import ELEMENT_CLASSES


def _ap(**per_variant):
    out = {}
    for v, (vals, n) in per_variant.items():
        out[v] = {c: vals.get(c) for c in ELEMENT_CLASSES}
        out[v]["n_gt"] = {c: n.get(c, 0) for c in ELEMENT_CLASSES}
    return out


def test_a_variant_replaces_the_full_svm_only_by_the_margin_and_with_enough_elements():
    n = {"door": 40, "chair": 40, "sofa": 3, "table": 40}
    ap = _ap(full=({"door": 0.10, "chair": 0.80, "sofa": 0.0, "table": None}, n),
             no_local=({"door": 0.30, "chair": 0.84, "sofa": 0.9, "table": 0.2}, n),
             no_color=({"door": 0.40, "chair": 0.70, "sofa": 0.9, "table": 0.1}, n))
    chosen = groups.choose_groups(ap)
    # doors: the best variant; chairs: +4 points is under the margin; sofas: too few elements
    assert chosen == {"door": "no_color", "table": "no_local"}
    # only the classes allowed to drop a group
    assert groups.choose_groups(ap, ["door", "chair"]) == {"door": "no_color"}


@pytest.fixture(scope="module")
def two_buildings(tmp_path_factory):
    return generated_stores(tmp_path_factory.mktemp("groups"), ((41, 10.0), (42, 35.0)), density=500)


def test_apply_groups_refits_only_the_chosen_classes(two_buildings):
    settings = TrainSettings.from_config(rounds=0, classes=(0, 1, 2))
    model, samples = train_with_samples(two_buildings[:1], settings=settings)
    out = groups.apply_groups(model, samples, {"wall": "no_local"}, settings)
    wall = ELEMENT_CLASSES.index("wall")
    ref = refit_without(model, samples, ABLATIONS["no_local"], settings)
    np.testing.assert_allclose(out.weights[wall], ref.weights[wall])
    off = ~FeatureLayout(model.layout.k, ABLATIONS["no_local"]).mask
    assert np.all(out.weights[wall, off] == 0) and np.any(model.weights[wall, off] != 0)
    np.testing.assert_array_equal(out.weights[:wall], model.weights[:wall])  # ceiling and floor unchanged
    atoms = [a for a, at in enumerate(model.dictionary.atoms_) if at.class_code == wall]
    assert np.all(out.atom_weights[atoms][:, off] == 0)
    assert out.layout == model.layout  # one layout: the dropped group is zero weights


def test_fold_models_take_the_chosen_classes_rows_as_apply_groups_refits_them(two_buildings):
    settings = TrainSettings.from_config(rounds=0, classes=(0, 1, 2))
    model, samples = train_with_samples(two_buildings[:1], settings=settings)
    ref = groups.apply_groups(model, samples, {"wall": "no_local"}, settings)
    models = [model, refit_without(model, samples, ABLATIONS["no_color"], settings),
              refit_without(model, samples, ABLATIONS["no_local"], settings)]
    out = groups.compose_chosen(models, ("full", "no_color", "no_local"), {"wall": "no_local"})
    np.testing.assert_allclose(out.weights, ref.weights)
    np.testing.assert_allclose(out.atom_weights, ref.atom_weights)
    np.testing.assert_allclose(out.bias, ref.bias)
    assert out.layout == model.layout


def test_training_validates_groups_on_building_folds(two_buildings):
    settings = TrainSettings.from_config(rounds=0, classes=(0, 1, 2), select_groups="no_local,no_color", rescore=True)
    model, _ = train_with_samples(two_buildings, settings=settings)
    # the re-ranking learnt from the fold detectors' detections of the buildings they did not see
    rr = model.rescorer.report
    assert rr["samples"] == "out of fold" and rr["classes"]["wall"]["detections"] > 0
    assert 0 < rr["classes"]["wall"]["elements"]
    rep = model.svm["groups"]
    assert rep["candidates"] == ["no_local", "no_color"]
    assert set(rep["validation_ap"]) == {"full", "no_local", "no_color"}
    # each building was a validation fold once: every ground-truth wall of both counted
    walls = sum(1 for s in two_buildings for e in s.doc("ground_truth")["elements"] if e["class"] == "wall")
    assert 0 < rep["validation_ap"]["full"]["n_gt"]["wall"] <= walls
    assert rep["validation_ap"]["full"]["wall"] is not None
    assert set(rep["chosen"]) <= {"ceiling", "floor", "wall"}
    with pytest.raises(ValueError):
        TrainSettings(select_groups="no_walls")
    # one building: nothing to validate on, the model keeps every group
    one, _ = train_with_samples(two_buildings[:1], settings=settings)
    assert one.svm["groups"]["chosen"] == {} and "skipped" in one.svm["groups"]
    assert one.rescorer.report["samples"] == "the final detectors' own"
