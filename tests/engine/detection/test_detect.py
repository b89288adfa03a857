"""Detection end to end on generated buildings: train a small model, detect, label points, elements.json."""
from __future__ import annotations

import json

import numpy as np
import pytest

from engine.cli import main
from engine.detection.detect import detect
from engine.detection.model import Model, default_model_path
from engine.detection.settings import DetectionSettings
from engine.detection.surfaces import refine_extent, surface_shift
from engine.metrics.boxes import box_iou_3d, boxes_array
from engine.metrics.detection import evaluate_detections
from engine.outputs.labels import label_points, read_elements_json, write_elements_json
from engine.synth import generate
from tiles.classes import CLASS_CODES
from tiles.store import open_store

STRUCTURE = ("ceiling", "floor", "wall")


@pytest.fixture(scope="module")
def buildings(tmp_path_factory):
    """Two small generated buildings (different seeds, rotated): one to train on, one to test on."""
    root = tmp_path_factory.mktemp("det")
    out = {}
    for name, seed, yaw in (("train", 11, 20.0), ("test", 12, 63.0)):
        generate(str(root / f"{name}.zarr"), seed=seed, rooms=3, density=1200, yaw=yaw)
        out[name] = open_store(str(root / f"{name}.zarr"))
    return root, out


@pytest.fixture(scope="module")
def trained(buildings, client):
    """A structural-only model trained with the command line (one mining round)."""
    root, stores = buildings
    model = root / "model"
    rc = main(["train", stores["train"].url, "--model", str(model), "--classes", ",".join(STRUCTURE),
               "--rounds", "1", "--scheduler", client.scheduler.address])
    assert rc == 0
    return Model.load(model)


def test_surface_shift_moves_a_thin_box_onto_the_surface_beside_it():
    rng = np.random.default_rng(0)
    vox, bin_ = 0.1, 0.005
    # a ceiling at z = 3.03 (voxel 30) over beam sides spread evenly through voxels 26-30
    ceiling = 3.03 + rng.normal(0, 0.003, 5000)
    beams = rng.uniform(2.6, 3.03, 2000)
    values = np.concatenate([ceiling, beams])
    sel = lambda a, b: values[(values >= a * vox) & (values < b * vox)]  # noqa: E731
    # the best window was the beams' layer, voxel 29; NMS grew it by one voxel each way
    assert surface_shift(sel(28, 31), 29, 30, 28, 31, vox, bin_) == 1
    assert surface_shift(sel(29, 32), 30, 31, 29, 32, vox, bin_) == 0  # already on it
    assert surface_shift(sel(26, 29), 27, 28, 26, 29, vox, bin_) == 0  # no surface in reach: stays
    assert surface_shift(sel(29, 32), 31, 32, 29, 32, vox, bin_) == -1  # from above
    assert surface_shift(sel(27, 31), 28, 30, 27, 31, vox, bin_) == 1  # a box two voxels thick: the smallest move
    assert surface_shift(np.zeros(0), 3, 4, 2, 5, vox, bin_) == 0


def test_refine_extent_is_the_noise_band_of_the_surface():
    rng = np.random.default_rng(1)
    sigma = 0.004
    wall = 1.234 + rng.normal(0, sigma, 20000)
    # a board's edge and a few stray points touching the wall widen the dense run, not the band
    stray = np.concatenate([rng.uniform(1.25, 1.27, 600), rng.uniform(1.2, 1.3, 100)])
    lo, hi = refine_extent(np.concatenate([wall, stray]), 1.2, 1.3, 0.005)
    assert abs((lo + hi) / 2 - 1.234) < 0.002
    assert 5 * sigma < hi - lo < 7 * sigma  # +- 3 sigma: the band holding the surface's points
    # a noise-free plane still gets a box (one bin), and no points leave the box as it was
    lo, hi = refine_extent(np.full(50, 1.234), 1.2, 1.3, 0.005)
    assert lo < 1.234 < hi and 0.002 < hi - lo <= 0.005
    assert refine_extent(np.zeros(0), 1.2, 1.3, 0.005) == (1.2, 1.3)


def test_one_per_space_and_refine_classes_settings():
    assert DetectionSettings.from_config().one_per_space == ("ceiling", "floor")
    assert DetectionSettings.from_config().refine_classes == ("ceiling", "floor", "wall")
    with pytest.raises(ValueError, match="refine-classes"):
        DetectionSettings(refine_classes="walls")
    assert DetectionSettings(one_per_space="wall, floor").one_per_space == ("wall", "floor")
    assert DetectionSettings(one_per_space=()).to_json()["one_per_space"] == []
    with pytest.raises(ValueError, match="one-per-space"):
        DetectionSettings(one_per_space=("stairs",))


def test_small_model_detects_walls_floor_and_ceiling(buildings, trained, client):
    _, stores = buildings
    store = stores["test"]
    props = detect(store, model=trained, client=client, space_array="gt_space")
    assert props and {p.class_name for p in props} <= set(STRUCTURE)
    # one floor and one ceiling per space (one-per-space), several walls
    per_space = [(p.space_id, p.class_name) for p in props]
    assert all(per_space.count((s, c)) == 1 for s, c in set(per_space) if c in ("floor", "ceiling"))
    assert max(per_space.count(k) for k in set(per_space)) > 1
    gt = [e for e in store.doc("ground_truth")["elements"] if e["class"] in STRUCTURE and e.get("points", 1) >= 500]
    found = {}
    for e in gt:
        mine = [p for p in props if p.class_code == e["class_code"]]
        d = np.array([[*p.center, *p.world_size, p.yaw] for p in mine]).reshape(-1, 7)
        found.setdefault(e["class"], []).append(float(box_iou_3d(boxes_array([e]), d).max(initial=0.0)))
    assert all(iou > 0.5 for iou in found["floor"]), found["floor"]
    assert all(iou > 0.5 for iou in found["ceiling"]), found["ceiling"]
    assert np.mean(np.array(found["wall"]) > 0.5) >= 0.8, found["wall"]
    ev = evaluate_detections(props, store.doc("ground_truth")["elements"], client=client)
    assert ev.ap["floor"] > 0.5 and ev.ap["ceiling"] > 0.5 and ev.ap["wall"] > 0.5


def test_largest_spaces_are_submitted_first_with_the_same_proposals(buildings, trained, client, monkeypatch):
    """Tasks start in submission order: the spaces with most points go first (no long task left for the end of
    the stage), and the proposals, their order and element ids are those of submitting by space id."""
    import engine.detection.detect as det

    _, stores = buildings
    store = stores["test"]
    sent = []
    real = det.run_tasks

    def spy(fn, items, **kw):
        sent.append([ref for ref, _ in items])
        return real(fn, items, **kw)

    monkeypatch.setattr(det, "run_tasks", spy)
    props = detect(store, model=trained, client=client, space_array="gt_space")
    counts = [r.count for r in sent[0]]
    assert len(counts) > 2 and counts == sorted(counts, reverse=True) and sent[0] != sorted(sent[0], key=lambda r: r.space_id)
    monkeypatch.setattr(det, "by_size", lambda refs: refs)  # id order, as before
    before = detect(store, model=trained, client=client, space_array="gt_space")
    assert [(p.element_id, p.space_id, p.class_code, p.score, tuple(p.center), tuple(p.world_size)) for p in props] \
        == [(p.element_id, p.space_id, p.class_code, p.score, tuple(p.center), tuple(p.world_size)) for p in before]


def test_training_again_on_the_same_data_writes_the_same_model(buildings, client, tmp_path):
    from engine.training.settings import TrainSettings
    from engine.training.train import train

    _, stores = buildings
    settings = TrainSettings.from_config(classes=(0,), rounds=0)
    docs = []
    for i in range(2):
        model = train([stores["train"]], client=client, settings=settings, names=["synthetic seed 11"],
                      provenance={"synthetic": {"buildings": 1, "first_seed": 11}})
        _, js = model.save(tmp_path / f"m{i}")
        docs.append(json.loads(open(js).read()))
    # stable descriptions, not the stores' (temporary) paths; no timestamps or durations
    assert docs[0]["provenance"]["buildings"] == ["synthetic seed 11"]
    assert not {"seconds", "trained_at"} & set(docs[0]["provenance"])
    assert docs[0] == docs[1]
    a, b = (Model.load(tmp_path / f"m{i}").arrays() for i in range(2))
    assert all(np.array_equal(a[k], b[k]) for k in a)


def test_labels_and_elements_json(buildings, trained, client, tmp_path):
    _, stores = buildings
    store = stores["test"]
    props = detect(store, model=trained, client=client, space_array="gt_space",
                   settings=DetectionSettings.from_config(max_per_class=8))
    labelled = label_points(store, props, client=client)
    store.refresh()
    assert store.meta.dimension("classification").kind == "result"
    cls = np.concatenate([store.read(t, ["classification"])["classification"] for t in store.tiles])
    gtc = np.concatenate([store.read(t, ["gt_class"])["gt_class"] for t in store.tiles])
    eid = np.concatenate([store.read(t, ["element_id"])["element_id"] for t in store.tiles])
    assert cls.dtype == np.uint8 and eid.dtype == np.int32 and labelled == int((cls != 12).sum())
    assert set(np.unique(cls)) <= {CLASS_CODES[c] for c in STRUCTURE} | {12}
    assert np.all((eid == -1) == (cls == 12)) and eid.max() < len(props)
    for c in ("floor", "ceiling"):  # most floor / ceiling points are labelled so
        assert np.mean(cls[gtc == CLASS_CODES[c]] == CLASS_CODES[c]) > 0.8
    path = write_elements_json(props, tmp_path / "out" / "elements.json")
    recs = read_elements_json(path)
    assert len(recs) == len(props)
    r = recs[0]
    assert set(r) >= {"element_id", "class", "class_code", "score", "space_id", "center", "size", "yaw", "voxels"}
    p = next(q for q in props if q.element_id == r["element_id"])
    assert np.allclose(r["center"], p.center) and np.allclose(r["size"], p.world_size)
    # world coordinates: the box centre lies inside the building's bounds
    b = store.meta.bounds
    assert b[0] - 0.1 <= r["center"][0] <= b[3] + 0.1 and b[1] - 0.1 <= r["center"][1] <= b[4] + 0.1


def test_detect_command(buildings, trained, client, tmp_path, capsys):
    root, stores = buildings
    out = tmp_path / "e.json"
    rc = main(["detect", stores["test"].url, "--model", str(root / "model"), "--out", str(out),
               "--space-array", "gt_space", "--evaluate", "--scheduler", client.scheduler.address])
    assert rc == 0
    text = capsys.readouterr().out
    assert "detections" in text and "mAP" in text
    assert json.loads(out.read_text())
    # no space_id yet in this store: a clear one-line error
    assert main(["detect", stores["test"].url, "--model", str(root / "model"), "--out", str(out),
                 "--scheduler", client.scheduler.address]) == 2


def test_default_model_loads():
    m = Model.load(default_model_path())
    assert m.trained.sum() >= 10 and len(m.dictionary.atoms_) >= 12


def test_a_spaces_one_ceiling_is_its_highest_window_and_its_floor_its_lowest():
    """``surface-choice``: a table-top plane or a beam's underside that outscores the ceiling is not the ceiling."""
    from engine.detection.surfaces import surface_order

    keep = np.array([4, 0, 2, 3])  # best first: a plane at 0.9 m, the ceiling, a window at mid-height, the floor
    lo = np.zeros((5, 3), dtype=np.int64)
    hi = np.ones((5, 3), dtype=np.int64)
    lo[4, 2], hi[4, 2] = 9, 10  # middle 0.95 m in a 3 m (30 voxel) space
    lo[0, 2], hi[0, 2] = 29, 30
    lo[2, 2], hi[2, 2] = 14, 16  # middle exactly half-way: in both halves
    lo[3, 2], hi[3, 2] = 0, 1
    assert surface_order(keep, lo, hi, 30, upper=True)[0] == 0
    assert surface_order(keep, lo, hi, 30, upper=False)[0] == 3
    assert surface_order(keep, lo, hi, 30, True, "halves").tolist() == [0, 2]
    assert surface_order(keep, lo, hi, 30, False, "halves").tolist() == [4, 2, 3]
    assert surface_order(np.array([4]), lo, hi, 30, True, "halves").tolist() == [4]  # nothing above: what there is
    assert surface_order(keep, lo, hi, 30, True, "score").tolist() == keep.tolist()
    ties = np.array([2, 1])  # same height: the better score first
    lo[1], hi[1] = lo[2], hi[2]
    assert surface_order(ties, lo, hi, 30, upper=True).tolist() == [2, 1]
    with pytest.raises(ValueError, match="surface-choice"):
        DetectionSettings(surface_choice="highest")


def test_ceilings_of_rooms_with_beams_are_found_at_the_ceiling(tmp_path):
    """``surface-choice: extreme`` (the default): each space's ceiling is at its ground-truth height (within 5 cm),
    not at the beams' undersides.

    (With the shipped model of session 10, ``score`` -- the best window, searched beside it only -- put one of
    these ceilings at the beams; the model trained with 250 m2 buildings too finds them with either rule, so
    the rules' difference is tested on hand-made windows in the test above, not on this building.)"""

    from engine.detection.model import load_model
    from engine.detection.space import detect_space
    from engine.spaces.points import index_spaces, load_space
    from tiles.store import open_store

    generate(str(tmp_path / "b.zarr"), seed=43, rooms=3, density=800, yaw=20.0)
    store = open_store(str(tmp_path / "b.zarr"))
    gt = store.doc("ground_truth")["elements"]
    assert sum(e["class"] == "beam" for e in gt) >= 3  # the building this test needs
    origin = np.asarray(store.meta.origin)
    settings = DetectionSettings.from_config()
    assert settings.surface_choice == "extreme"
    model = load_model(None)
    errors = []
    for ref in index_spaces(store, "gt_space"):
        want = [e for e in gt if int(e["space"]) == ref.space_id and e["class"] == "ceiling"]
        props = detect_space(load_space(store, ref, "gt_space"), model, settings, origin)
        got = [p for p in props if p.class_code == 0]  # ceiling
        assert len(got) == 1 and len(want) == 1
        errors.append(abs(got[0].center[2] - want[0]["center"][2]))
    assert max(errors) < 0.05, errors


def test_a_models_box_regression_moves_its_classes_detections(buildings, trained):
    """Detection applies the model's learned box regression (engine.detection.boxfit) to the classes it is enabled for,
    after the rules, and ``box-fit: false`` turns it off."""
    import dataclasses

    from engine.detection import boxfit as bf
    from engine.detection.space import detect_space
    from engine.spaces.points import index_spaces, load_space

    _, stores = buildings
    store = stores["test"]
    ref = max(index_spaces(store, "gt_space"), key=lambda r: r.count)
    pts = load_space(store, ref, "gt_space")
    coef = np.zeros((12, 3, 2, bf.N_FEATURES + 1))
    coef[CLASS_CODES["wall"], 2, :, -1] = [0.1, -0.1]  # walls: bottom up and top down by a tenth of their height
    enabled = np.zeros(12, bool)
    enabled[CLASS_CODES["wall"]] = True
    moved = dataclasses.replace(trained, boxfit=bf.BoxFit(coef, enabled))
    plain = detect_space(pts, trained, DetectionSettings.from_config())
    fitted = detect_space(pts, moved, DetectionSettings.from_config())
    off = detect_space(pts, moved, DetectionSettings.from_config(box_fit=False))
    assert [p.class_code for p in plain] == [p.class_code for p in fitted] and len(plain) > 3
    walls = 0
    for a, b, c in zip(plain, fitted, off):
        np.testing.assert_allclose(c.world_size, a.world_size)
        if a.class_name == "wall":
            walls += 1
            assert b.world_size[2] == pytest.approx(0.8 * a.world_size[2]) and b.center[2] == pytest.approx(a.center[2])
        else:
            np.testing.assert_allclose(b.world_size, a.world_size)
    assert walls >= 2


def test_a_models_rescorer_replaces_its_classes_scores(buildings, trained):
    """Detection gives the classes the model's learned re-ranking (engine.detection.rescore) is enabled for its log-odds
    as their score, from the features of their final boxes; other classes and ``rescore: false`` keep the
    detector's score, and the boxes do not move."""
    import dataclasses

    from engine.detection import rescore as rs
    from engine.detection.space import detect_space
    from engine.spaces.points import index_spaces, load_space

    _, stores = buildings
    store = stores["test"]
    ref = max(index_spaces(store, "gt_space"), key=lambda r: r.count)
    pts = load_space(store, ref, "gt_space")
    wall = CLASS_CODES["wall"]
    coef = np.zeros((12, rs.N_FEATURES))
    coef[wall, 0] = -1.0  # walls: the detector's score turned around
    coef[wall, rs.N_FEATURES - 3] = 0.5  # ... plus half the log of the space's height (the same for every wall)
    enabled = np.zeros(12, bool)
    enabled[wall] = True
    rescored = dataclasses.replace(trained, rescorer=rs.Rescorer(np.zeros((12, rs.N_FEATURES)),
                                                                 np.ones((12, rs.N_FEATURES)), coef, np.full(12, 2.0),
                                                                 enabled))
    plain = detect_space(pts, trained, DetectionSettings.from_config())
    new = detect_space(pts, rescored, DetectionSettings.from_config())
    off = detect_space(pts, rescored, DetectionSettings.from_config(rescore=False))
    assert [p.class_code for p in plain] == [p.class_code for p in new] and len(plain) > 3
    walls = [(a, b) for a, b in zip(plain, new) if a.class_code == wall]
    assert len(walls) >= 2
    shift = {round(b.score + a.score - 2.0, 9) for a, b in walls}
    assert len(shift) == 1 and shift != {0.0}  # one space: the same height term for every wall
    for a, b, c in zip(plain, new, off):
        np.testing.assert_allclose(b.world_size, a.world_size)
        assert c.score == a.score
        if a.class_code != wall:
            assert b.score == a.score
