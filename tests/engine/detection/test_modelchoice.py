"""Which model a run uses: the colour-free one for a cloud without colour, one colour, or when the setting says so."""
from __future__ import annotations

import os

import dask
import laspy
import numpy as np
import pytest

from engine.config import validate_settings
from engine.detection import modelchoice
from engine.detection.model import default_model_path
from engine.detection.modelchoice import COLOUR_GROUPS, choose_model, colour_state
from tiles.builder import PartSummary, constant_colour
from tiles.ingest import ingest


def _las(path, n=3000, colours=None, seed=0):
    """A small LAS file: without colour (``colours`` None, point format 6) or with ``colours`` (n, 3) uint16."""
    rng = np.random.default_rng(seed)
    h = laspy.LasHeader(point_format=6 if colours is None else 7, version="1.4")
    h.scales = np.array([0.001] * 3)
    h.offsets = np.zeros(3)
    las = laspy.LasData(h)
    xyz = rng.uniform(0, 1, (n, 3)) * (12.0, 8.0, 3.0)
    las.x, las.y, las.z = xyz[:, 0], xyz[:, 1], xyz[:, 2]
    if colours is not None:
        las.red, las.green, las.blue = colours.T
    las.write(str(path))
    return str(path)


@pytest.fixture
def installed(tmp_path, monkeypatch):
    """A stand-in for the shipped colour-free model's files (the choice only needs them to exist)."""
    stem = str(tmp_path / "models" / "nocolour")
    os.makedirs(os.path.dirname(stem))
    for ext in (".npz", ".json"):
        open(stem + ext, "w").close()
    monkeypatch.setattr(modelchoice, "colour_free_model_path", lambda: stem)
    return stem


@pytest.fixture(scope="module")
def stores(tmp_path_factory):
    """Stores of one cloud without colour, with one colour on every point, and with varied colour (several parts
    each, so that the constancy is put together from the parts)."""
    root = tmp_path_factory.mktemp("colour")
    n = 3000
    varied = np.random.default_rng(1).integers(0, 65535, (n, 3)).astype(np.uint16)
    constant = np.tile(np.array([[30000, 30000, 30000]], dtype=np.uint16), (n, 1))
    one_part_differs = constant.copy()
    one_part_differs[-1] = (30000, 30001, 30000)  # the last part has another (constant) colour
    out = {}
    for name, colours in (("none", None), ("constant", constant), ("varied", varied), ("last", one_part_differs)):
        src = _las(root / f"{name}.las", n, colours)
        out[name] = ingest([src], str(root / f"{name}.zarr"), tile_size=5.0, part_points=1000)
    return out


def test_the_store_records_whether_the_colour_is_constant(stores):
    assert stores["none"].meta.color_constant is None and colour_state(stores["none"].meta) == "none"
    assert stores["constant"].meta.color_constant is True and colour_state(stores["constant"].meta) == "constant"
    assert stores["varied"].meta.color_constant is False and colour_state(stores["varied"].meta) == "varied"
    assert stores["last"].meta.color_constant is False  # each part constant, not the same colour


def test_constant_colour_of_parts():
    def part(i, constant, rgb=(1, 2, 3)):
        return PartSummary(i, 10, color_constant=constant, constants=dict(zip(("red", "green", "blue"), rgb)))

    assert constant_colour([]) is None
    assert constant_colour([part(0, True), part(1, True)]) is True
    assert constant_colour([part(0, True), part(1, False)]) is False
    assert constant_colour([part(0, True), part(1, True, (1, 2, 4))]) is False


def test_a_cloud_without_colour_or_with_one_colour_gets_the_colour_free_model(stores, installed):
    for name, why in (("none", "no colour"), ("constant", "the same colour")):
        c = choose_model(stores[name].meta, None, "auto")
        assert c.path == installed and c.colour_free and c.name == "nocolour" and why in c.reason
        assert c.to_json() == {"name": "nocolour", "colour_free": True, "reason": c.reason}


def test_a_coloured_cloud_gets_the_default_model(stores, installed):
    for name in ("varied", "last"):
        c = choose_model(stores[name].meta, None, "auto")
        assert c.path is None and not c.colour_free and c.name == "default" and "has colour" in c.reason


def test_a_model_given_by_the_user_wins(stores, installed, tmp_path):
    for name in ("none", "constant", "varied"):
        for mode in ("auto", "always", "never"):
            c = choose_model(stores[name].meta, str(tmp_path / "mine.npz"), mode)
            assert c.path == str(tmp_path / "mine") and c.name == "mine" and not c.colour_free
            assert "--model" in c.reason


def test_the_setting_always_and_never(stores, installed):
    for name in ("none", "constant", "varied"):
        assert choose_model(stores[name].meta, None, "always").path == installed
        assert choose_model(stores[name].meta, None, "never").path is None
    with dask.config.set({"buildingparser.detection.colour-free-model": "never"}):
        assert choose_model(stores["none"].meta).path is None
    with dask.config.set({"buildingparser.detection.colour-free-model": "always"}):
        assert choose_model(stores["varied"].meta).path == installed
    assert choose_model(stores["none"].meta).path == installed  # the shipped setting: auto


def test_a_bad_setting_is_refused_up_front():
    with dask.config.set({"buildingparser.detection.colour-free-model": "sometimes"}):
        with pytest.raises(Exception, match="colour-free-model"):
            validate_settings()


def test_without_the_colour_free_model_files_the_default_is_used_and_said(stores, tmp_path, monkeypatch):
    monkeypatch.setattr(modelchoice, "colour_free_model_path", lambda: str(tmp_path / "missing"))
    c = choose_model(stores["none"].meta, None, "auto")
    assert c.path is None and c.name == "default" and "not installed" in c.reason


def test_the_shipped_colour_free_model_loads_and_reads_no_colour():
    from engine.detection.model import Model

    path = modelchoice.colour_free_model_path()
    assert os.path.dirname(path) == os.path.dirname(default_model_path())
    model = Model.load(path)  # validated on load
    default = Model.load(default_model_path())
    assert set(COLOUR_GROUPS) <= set(model.layout.disabled)
    assert model.provenance["ablation"] == "no_color"
    mask = model.layout.mask
    for group in COLOUR_GROUPS:
        for a, b in model.layout.spans[group]:
            assert not mask[a:b].any()
            assert not np.any(np.asarray(model.weights)[:, a:b])
    # the same buildings, seeds and layout otherwise as the default model, and two hard buildings (make model's
    # HARD_SEEDS: tests/engine/training/test_shipped_recipe.py)
    hard = [d for d in model.provenance["data"] if os.path.basename(d).startswith("h")]
    assert hard
    assert model.layout.size == default.layout.size
    assert [d for d in model.provenance["data"] if d not in hard] == default.provenance["data"]


def _detections(points, model, rgb):
    from engine.detection.space import detect_space
    from engine.spaces.points import SpacePoints

    props = detect_space(SpacePoints(points.space_id, points.xyz, rgb), model)
    return [p.element_record() for p in props]


def _colourings(points):
    """The space's own colours and two others of the same points: random, and one grey."""
    rng = np.random.default_rng(5)
    return [points.rgb, rng.uniform(0, 1, points.rgb.shape), np.full(points.rgb.shape, 0.5)]


@pytest.fixture(scope="module")
def no_colour_model(buildings, client):
    """A small model trained with ``train --no-colour`` (structure and doors, one mining round)."""
    from engine.cli import main
    from engine.detection.model import Model

    root, stores = buildings
    stem = root / "nocolour-test"
    assert main(["train", stores["train"].url, "--model", str(stem), "--classes", "ceiling,floor,wall,door",
                 "--rounds", "1", "--no-colour", "--scheduler", client.scheduler.address]) == 0
    return Model.load(stem)


@pytest.fixture(scope="module")
def test_space(buildings):
    from engine.spaces.points import index_spaces, load_space

    _, stores = buildings
    refs = index_spaces(stores["test"], "gt_space")
    return load_space(stores["test"], max(refs, key=lambda r: r.count), "gt_space")


def test_train_no_colour_disables_the_colour_groups(no_colour_model):
    assert set(COLOUR_GROUPS) <= set(no_colour_model.layout.disabled)
    assert no_colour_model.provenance["ablation"] == "no_color"


def test_no_colour_leaks_into_a_colour_free_models_detections(no_colour_model, test_space):
    """Detections (features, SVM scores, box regression, re-ranking) are the same whatever the points' colours;
    for the default model they are not (so the colourings differ where it matters)."""
    from engine.detection.model import Model

    first, *others = [_detections(test_space, no_colour_model, rgb) for rgb in _colourings(test_space)]
    assert first and all(o == first for o in others)
    default = Model.load(default_model_path())
    first, *others = [_detections(test_space, default, rgb) for rgb in _colourings(test_space)]
    assert any(o != first for o in others)
    shipped = Model.load(modelchoice.colour_free_model_path())
    first, *others = [_detections(test_space, shipped, rgb) for rgb in _colourings(test_space)]
    assert first and all(o == first for o in others)


def test_train_refuses_no_colour_with_another_ablation(tmp_path, capsys):
    from engine.cli import main

    assert main(["train", "--synthetic", "1", "--model", str(tmp_path / "m"), "--no-colour",
                 "--ablation", "no_local"]) == 2
    assert "--no-colour" in capsys.readouterr().err


def test_detect_chooses_the_model_like_run(buildings, no_colour_model, client, tmp_path, monkeypatch, capsys):
    """``detect`` takes the colour-free model when the setting (or the cloud) says so and names it on stderr."""
    from engine.cli import main

    _, stores = buildings
    stem = os.path.join(os.path.dirname(stores["test"].url.rstrip("/")), "nocolour-test")
    monkeypatch.setattr(modelchoice, "colour_free_model_path", lambda: stem)
    out = tmp_path / "e.json"
    with dask.config.set({"buildingparser.detection.colour-free-model": "always"}):
        assert main(["detect", stores["test"].url, "--out", str(out), "--space-array", "gt_space",
                     "--scheduler", client.scheduler.address]) == 0
    assert "model: nocolour-test (detection.colour-free-model is always)" in capsys.readouterr().err
    assert out.is_file()
