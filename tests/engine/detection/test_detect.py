"""Detection end to end on generated buildings: train a small model, detect, label points, elements.json."""
from __future__ import annotations

import json

import dask
import numpy as np

from engine.cli import main
from engine.detection.detect import detect
from engine.detection.model import Model, default_model_path
from engine.detection.settings import DetectionSettings
from engine.metrics.boxes import box_iou_3d, boxes_array
from engine.metrics.detection import evaluate_detections
from engine.outputs.labels import label_points, read_elements_json, write_elements_json
from tiles.classes import CLASS_CODES

STRUCTURE = ("ceiling", "floor", "wall")  # the classes of the ``trained`` model (conftest.py)


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

    def spy(fn, items, **kw):  # the spaces' own yaws, then their detection: both in this order
        sent.append([job[0] if isinstance(job, tuple) else job for job in items])
        return real(fn, items, **kw)

    monkeypatch.setattr(det, "run_tasks", spy)
    props = detect(store, model=trained, client=client, space_array="gt_space")
    counts = [r.count for r in sent[0]]
    assert len(counts) > 2 and counts == sorted(counts, reverse=True) and sent[0] != sorted(sent[0], key=lambda r: r.space_id)
    assert len(sent) == 2 and sent[1] == sent[0]
    monkeypatch.setattr(det, "by_size", lambda refs: refs)  # id order, as before
    before = detect(store, model=trained, client=client, space_array="gt_space")
    assert [(p.element_id, p.space_id, p.class_code, p.score, tuple(p.center), tuple(p.world_size)) for p in props] \
        == [(p.element_id, p.space_id, p.class_code, p.score, tuple(p.center), tuple(p.world_size)) for p in before]


def test_every_space_is_detected_in_its_groups_orientation(buildings, trained, client):
    """The spaces' own yaws differ by their estimates' errors; each space is detected in their median's frame
    (the building's walls are parallel), and in its own with orientation-tolerance 0."""
    from engine.detection.canonical import manhattan_yaw
    from engine.detection.orientations import wrap_quarter
    from engine.spaces.points import index_spaces, load_space

    _, stores = buildings
    store = stores["test"]
    refs = index_spaces(store, "gt_space")
    own = {r.space_id: float(manhattan_yaw(load_space(store, r, "gt_space").xyz)) for r in refs}
    assert np.ptp(list(own.values())) > 1e-6  # the estimates differ (by hundredths of a degree)

    def yaws(props):
        return {p.space_id: float(wrap_quarter(p.yaw)) for p in props}

    grouped = yaws(detect(store, model=trained, client=client, space_array="gt_space"))
    assert set(grouped) == set(own)
    assert np.allclose(list(grouped.values()), np.median(list(own.values())), atol=1e-12)
    alone = yaws(detect(store, model=trained, client=client, space_array="gt_space",
                        settings=DetectionSettings.from_config(orientation_tolerance=0.0)))
    assert all(abs(float(wrap_quarter(alone[k] - own[k]))) < 1e-12 for k in own)


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
    # the rule before 2026-12-05 (occupied cells only, by score alone) labels fewer of them so
    with dask.config.set({"buildingparser.detection.label-first": "", "buildingparser.detection.label-occupied": True}):
        label_points(store, props, client=client)
    store.refresh()
    old = np.concatenate([store.read(t, ["classification"])["classification"] for t in store.tiles])
    label_points(store, props, client=client)  # the default rule again, for the tests after this one
    store.refresh()
    assert not np.array_equal(old, cls)
    for c in ("floor", "ceiling"):
        assert np.mean(cls[gtc == CLASS_CODES[c]] == CLASS_CODES[c]) >= np.mean(old[gtc == CLASS_CODES[c]] == CLASS_CODES[c])
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
