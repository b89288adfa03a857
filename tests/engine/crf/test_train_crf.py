"""``buildingparser train-crf``: CRF weights learnt from detections and written into the model."""
from __future__ import annotations

import json
import re

import numpy as np
import pytest

from engine.cli import main
from engine.crf.apply import apply_crf
from engine.crf.model import CRFWeights
from engine.crf.workflow import check_not_detector_data
from engine.detection.detect import detect
from engine.detection.model import Model
from engine.synth import generate
from tiles.errors import UserError
from tiles.store import open_store


@pytest.fixture(scope="module")
def small_model(tmp_path_factory, client):
    """A structural-only detector (one mining round) trained on one tiny building (seed 11)."""
    root = tmp_path_factory.mktemp("train_crf")
    generate(str(root / "train.zarr"), seed=11, rooms=3, density=1200, yaw=20.0)
    rc = main(["train", str(root / "train.zarr"), "--model", str(root / "model"),
               "--classes", "ceiling,floor,wall", "--rounds", "1", "--scheduler", client.scheduler.address])
    assert rc == 0
    return root


def test_train_crf_writes_weights_into_the_model(small_model, client, capsys):
    root = small_model
    before = Model.load(root / "model")
    assert CRFWeights.from_model(before) is None
    capsys.readouterr()
    rc = main(["train-crf", str(root / "model"), "--synthetic", "1", "--seed", "13", "--area", "60",
               "--density", "1200", "--keep-synthetic", str(root / "crf"), "--iterations", "15",
               "--scheduler", client.scheduler.address])
    assert rc == 0
    out = capsys.readouterr().out
    m = re.search(r"(\d+) spaces, (\d+) proposals \((\d+) true\), (\d+) S-SVM iterations.*training error "
                  r"([\d.]+) -> ([\d.]+)", out)
    assert m, out
    spaces, props, true, iters = (int(m.group(i)) for i in range(1, 5))
    after = Model.load(root / "model")
    w = CRFWeights.from_model(after)
    assert w is not None and w.grid == after.layout.k
    # learnt: not the untrained weights (keep every positive score)
    assert not np.allclose(w.vector(), CRFWeights.new(w.grid).vector())
    # the detectors are untouched
    old_arrays, new_arrays = before.arrays(), after.arrays()
    assert set(new_arrays) == set(old_arrays) | {"crf_bias", "crf_edge", "crf_k", "crf_decides"}
    for name, a in old_arrays.items():
        np.testing.assert_array_equal(new_arrays[name], a)
    assert after.provenance == before.provenance and after.layout == before.layout
    # the summary agrees with the recorded provenance of the weights
    t = after.crf["training"]
    assert t["data"] == ["synthetic seed 13"] and t["synthetic"]["first_seed"] == 13
    assert (t["spaces"], t["proposals"], t["positives"], t["iterations"]) == (spaces, props, true, iters)
    assert 0 < true < props and spaces >= 2 and 1 <= iters <= 15
    # one building: no folds to choose on, so crf.ssvm.miss-cost and every class decided
    assert t["validation"] == {"rule": t["validation"]["rule"], "buildings": 1, "folds": 0}
    assert t["miss_cost"] == 2.0 and w.decides.all() and "deciding ceiling, floor, wall" in out
    assert float(m.group(5)) == pytest.approx(t["errors"]["initial"], abs=1e-3)
    assert float(m.group(6)) == pytest.approx(t["errors"]["final"], abs=1e-3)
    json.loads((root / "model.json").read_text())  # still plain JSON, no temporary files left
    assert not list(root.glob("*train-crf-tmp*"))
    # the weights work: the CRF runs with them on the building they were learnt on
    store = open_store(str(root / "crf" / "synthetic-13.zarr"))
    proposals = detect(store, model=after, client=client, space_array="gt_space")
    assert len(proposals) == props
    kept, report = apply_crf(proposals, w, client=client)
    assert report["spaces"] == spaces and 0 < len(kept) <= props


def test_train_crf_refuses_the_detectors_training_data(small_model, client, capsys):
    root = small_model
    rc = main(["train-crf", str(root / "model"), str(root / "train.zarr"), "--scheduler", client.scheduler.address])
    assert rc == 2
    assert "trained on this store" in capsys.readouterr().err
    assert main(["train-crf", str(root / "model"), "--scheduler", client.scheduler.address]) == 2
    assert main(["train-crf", str(root / "nothing"), "--synthetic", "1"]) == 2


def test_detector_seeds_are_refused():
    prov = {"data": ["a.zarr", "s3://bucket/b.zarr"], "synthetic": {"buildings": 6, "first_seed": 1000}}
    check_not_detector_data(prov, ["c.zarr"], range(1006, 1010))
    check_not_detector_data(prov, [], range(990, 1000))
    with pytest.raises(UserError, match="seed 1005"):
        check_not_detector_data(prov, [], range(1005, 1007))
    with pytest.raises(UserError, match="1006 or higher"):
        check_not_detector_data(prov, [], range(995, 1001))
    with pytest.raises(UserError, match="trained on this store"):
        check_not_detector_data(prov, ["./a.zarr"], range(0))
    with pytest.raises(UserError, match="trained on this store"):
        check_not_detector_data(prov, ["s3://bucket/b.zarr/"], range(0))


def test_help_says_to_use_other_buildings(capsys):
    with pytest.raises(SystemExit):
        main(["train-crf", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "NOT trained on" in text and "--synthetic" in text and "--seed" in text and "--area" in text
