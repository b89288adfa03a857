"""The CRF's weights and settings: files, the model slot, bad inputs."""
from __future__ import annotations

import numpy as np
import pytest

from engine.crf.apply import select_elements
from engine.crf.model import CLASS_PAIRS, CRFSettings, CRFWeights
from tests.engine.crf.helpers import CHAIR, WALL, K, prop, random_weights


def test_weights_round_trip_through_files_and_the_model_slot(tmp_path):
    rng = np.random.default_rng(0)
    w = random_weights(rng, k=3)
    w.k[WALL] = 5
    npz, js = w.save(tmp_path / "crf.npz")
    assert npz.endswith("crf.npz") and js.endswith("crf.json")
    back = CRFWeights.load(tmp_path / "crf")
    np.testing.assert_array_equal(back.vector(), w.vector())
    assert back.grid == 3 and back.k[WALL] == 5 and back.decides.all()
    w.decides[CHAIR] = False
    w.save(tmp_path / "crf2")
    back = CRFWeights.load(tmp_path / "crf2")
    assert back.decides.tolist() == w.decides.tolist() and "chair" not in back.params()["decides"]
    # weights of version 1 (no crf_decides) load with every class decided
    arrays = {k: v for k, v in w.to_arrays().items() if k != "crf_decides"}
    old = CRFWeights.from_arrays(arrays, dict(w.params(), version=1))
    assert old.decides.all()

    class Slot:
        crf = None
        crf_arrays: dict = {}

    m = Slot()
    assert CRFWeights.from_model(m) is None
    w.store_in(m)
    assert all(k.startswith("crf_") for k in m.crf_arrays)
    np.testing.assert_array_equal(CRFWeights.from_model(m).vector(), w.vector())
    assert len(w.edge) == len(CLASS_PAIRS) == 78


def test_bad_inputs_are_refused():
    w = CRFWeights.new(K)
    with pytest.raises(ValueError, match="one space"):
        select_elements([prop(WALL, [0, 0, 0], [.1, .1, .1], 1, space=0),
                         prop(WALL, [0, 0, 0], [.1, .1, .1], 1, space=1)], w)
    with pytest.raises(ValueError, match="occupancy"):
        select_elements([prop(WALL, [0, 0, 0], [.1, .1, .1], 1, k=3), prop(WALL, [.5, 0, 0], [.1, .1, .1], 1, k=3)], w)
    with pytest.raises(ValueError, match="edge weights"):
        CRFWeights(1.0, np.zeros(12), np.zeros((78, 5)), 2, np.ones(12))
    with pytest.raises(ValueError):
        CRFSettings(linearization_level=3)
    with pytest.raises(ValueError, match="format"):
        CRFWeights.from_arrays(w.to_arrays(), {"format": "other"})
    assert select_elements([], w) == ([], {"space_id": None, "status": "EMPTY", "seconds": 0.0, "solver_seconds": 0.0,
                                           "nodes": 0, "edges": 0, "kept": 0, "objective": 0.0, "warning": None})
