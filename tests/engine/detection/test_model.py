"""The model file: documented arrays in .npz plus JSON, read back without pickle, CRF slot unchanged."""
from __future__ import annotations

import json

import numpy as np
import pytest

from engine.detection.dictionary import WindowDictionary
from engine.detection.layout import FeatureLayout
from engine.detection.model import Model, load_model
from tiles.errors import UserError


def _model():
    rng = np.random.default_rng(0)
    k = 2
    d = WindowDictionary(k=k).fit(np.array([0, 0, 2, 8]), rng.uniform(0.1, 1, (4, 3)), rng.uniform(0.1, 5, (4, 3)),
                                  rng.uniform(size=(4, k, k, k)) > 0.5)
    lay = FeatureLayout(k=k, disabled=("color",))
    w = rng.normal(size=(12, lay.size)) * lay.mask
    trained = np.zeros(12, bool)
    trained[[0, 2, 8]] = True
    return Model(lay, d, w, rng.normal(size=12), trained, voxel=0.08, max_cells=123456, stride=0.2,
                 provenance={"buildings": ["a", "b"]}, cv={"mean_ap": 0.5},
                 crf={"format": "crf", "w0": 1.5, "grid": 2},
                 crf_arrays={"crf_edge": rng.normal(size=(78, 19)), "crf_k": np.arange(12)})


def test_model_round_trips_without_pickle(tmp_path):
    m = _model()
    npz, js = m.save(tmp_path / "sub" / "m.npz")
    assert npz.endswith("m.npz") and js.endswith("m.json")
    with np.load(npz, allow_pickle=False) as z:  # plain arrays only
        assert set(z.files) >= {"weights", "bias", "trained", "atom_class", "atom_occupancy", "crf_edge", "crf_k"}
    doc = json.loads(open(js).read())
    assert doc["format"] == "buildingparser-detector" and "weights" in doc["arrays"]
    back = load_model(tmp_path / "sub" / "m")
    for name, arr in m.arrays().items():
        assert np.array_equal(back.arrays()[name], arr), name
        assert back.arrays()[name].dtype == arr.dtype, name
    assert back.params() == json.loads(json.dumps(m.params()))
    assert back.crf == m.crf and set(back.crf_arrays) == {"crf_edge", "crf_k"}
    assert back.layout.disabled == ("color",) and back.voxel == 0.08 and back.max_cells == 123456


def test_bad_model_files_are_user_errors(tmp_path):
    with pytest.raises(UserError, match="no such model"):
        Model.load(tmp_path / "missing")
    m = _model()
    m.save(tmp_path / "m")
    (tmp_path / "m.json").write_text('{"format": "something else"}')
    with pytest.raises(UserError, match="not a buildingparser detection model"):
        Model.load(tmp_path / "m")
    m.save(tmp_path / "p")
    np.savez(tmp_path / "p.npz", weights=np.array([object()], dtype=object))  # needs pickle: refused
    with pytest.raises(UserError):
        Model.load(tmp_path / "p")


def test_model_validates_shapes():
    m = _model()
    with pytest.raises(ValueError):
        Model(m.layout, m.dictionary, m.weights[:, :5], m.bias, m.trained)
    with pytest.raises(ValueError):
        Model(m.layout, m.dictionary, m.weights, m.bias, m.trained, crf_arrays={"edge": np.zeros(3)})


def test_window_weights_add_each_windows_own_part_and_round_trip(tmp_path):
    """A version-2 model: a window scores with its class's weights plus its own; saved and read back."""
    import dataclasses

    m = _model()
    n_atoms, d = len(m.dictionary.atoms_), m.layout.size
    rng = np.random.default_rng(1)
    aw, ab = rng.normal(size=(n_atoms, d)), rng.normal(size=n_atoms)
    own = dataclasses.replace(m, atom_weights=aw, atom_bias=ab)
    atoms = np.arange(n_atoms)
    codes = [a.class_code for a in m.dictionary.atoms_]
    w, b = own.window_weights(atoms)
    np.testing.assert_array_equal(w, m.weights[codes] + aw)
    np.testing.assert_array_equal(b, m.bias[codes] + ab)
    w1, b1 = m.window_weights(atoms)  # a model without them: the class's weights alone
    np.testing.assert_array_equal(w1, m.weights[codes])
    np.testing.assert_array_equal(b1, m.bias[codes])
    assert m.params()["version"] == 1 and "atom_weights" not in m.params()["arrays"]
    own.save(tmp_path / "v2")
    back = load_model(tmp_path / "v2")
    assert back.params()["version"] == 2
    np.testing.assert_array_equal(back.atom_weights, aw)
    np.testing.assert_array_equal(back.atom_bias, ab)
    with pytest.raises(ValueError):
        dataclasses.replace(m, atom_weights=aw[:, :3], atom_bias=ab)
    with pytest.raises(ValueError):
        dataclasses.replace(m, atom_weights=aw, atom_bias=None)


@pytest.mark.parametrize("field, value, message", [
    ("voxel", -1, "model field voxel = -1: must be a finite number of metres > 0"),
    ("voxel", float("nan"), "model field voxel = NaN: must be a finite number"),
    ("voxel", "0.1", 'model field voxel = "0.1": must be a finite number'),
    ("max_cells", 0, "model field max_cells = 0: must be an integer >= 1"),
    ("max_cells", 1.5, "model field max_cells = 1.5: must be an integer"),
    ("stride", 2, r"model field stride = 2: must be a fraction in \(0, 1\]"),
    ("layout", [1, 2], "model field layout = \\[1, 2\\]: must be an object"),
    ("version", True, "model field version = true: must be an integer"),
    ("svm", "x", "model field svm must be an object or null"),
])
def test_wrong_types_and_ranges_in_the_json_are_one_line(tmp_path, field, value, message):
    _model().save(tmp_path / "m")
    doc = json.loads((tmp_path / "m.json").read_text())
    doc[field] = value
    (tmp_path / "m.json").write_text(json.dumps(doc))
    with pytest.raises(UserError, match=message) as e:
        Model.load(tmp_path / "m")
    assert "\n" not in e.value.line() and e.value.path.endswith("m.json")


def test_a_missing_field_and_bad_arrays_are_one_line(tmp_path):
    m = _model()
    m.save(tmp_path / "m")
    doc = json.loads((tmp_path / "m.json").read_text())
    del doc["layout"]
    (tmp_path / "m.json").write_text(json.dumps(doc))
    with pytest.raises(UserError, match="model description lacks 'layout'"):
        Model.load(tmp_path / "m")
    arrays = m.arrays()
    for name, bad, message in (("weights", np.full_like(arrays["weights"], np.nan), "weights must hold finite numbers"),
                               ("weights", arrays["weights"][:, :3], r"incomplete or inconsistent model .*shape"),
                               ("bias", np.array(["a"] * 12), "bias must hold finite numbers")):
        m.save(tmp_path / "b")
        np.savez(tmp_path / "b.npz", **{**arrays, name: bad})
        with pytest.raises(UserError, match=message) as e:
            Model.load(tmp_path / "b")
        assert "Traceback" not in e.value.line()


def test_broken_crf_weights_in_a_model_are_refused_on_load(tmp_path):
    from engine.crf.model import CLASS_PAIRS, CRFWeights, edge_feature_size

    m = _model()
    CRFWeights(0.5, np.zeros(12), np.zeros((len(CLASS_PAIRS), edge_feature_size(2))), 2, np.ones(12, int)).store_in(m)
    m.save(tmp_path / "m")
    assert CRFWeights.from_model(Model.load(tmp_path / "m")) is not None
    np.savez(tmp_path / "m.npz", **{**m.arrays(), "crf_edge": np.zeros((3, 3))})
    with pytest.raises(UserError, match=r"its CRF weights are not valid \(edge weights of shape \(3, 3\)"):
        Model.load(tmp_path / "m")
