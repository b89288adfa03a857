"""Detection in one space: the one ceiling under beams, and the model's box regression and re-ranking applied."""
from __future__ import annotations

import numpy as np
import pytest

from engine.detection.settings import DetectionSettings
from engine.synth import generate
from tiles.classes import CLASS_CODES


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
    from engine.detection import rescore as rs
    from engine.detection.space import detect_space

    wall = CLASS_CODES["wall"]
    row = np.zeros(rs.N_FEATURES)
    row[0] = -1.0  # walls: the detector's score turned around
    row[rs.N_FEATURES - 3] = 0.5  # ... plus half the log of the space's height (the same for every wall)
    pts, rescored = _largest_space_and_wall_rescorer(buildings, trained, row, 2.0)
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


def test_a_classes_cut_lowers_its_scores_by_it_and_no_other(buildings, trained):
    """``cut``: a class's final scores are lowered by its cut (a cut of -1 raises them by 1), so that a detection
    scored above the cut is kept downstream (score > 0); the other classes' scores and every box stay."""
    from engine.detection.space import detect_space
    from engine.spaces.points import index_spaces, load_space

    _, stores = buildings
    store = stores["test"]
    ref = max(index_spaces(store, "gt_space"), key=lambda r: r.count)
    pts = load_space(store, ref, "gt_space")
    plain = detect_space(pts, trained, DetectionSettings.from_config(cut={}))
    cut = detect_space(pts, trained, DetectionSettings.from_config(cut={"wall": -1.0, "floor": 0.5}))
    assert [p.class_code for p in plain] == [p.class_code for p in cut] and len(plain) > 3
    assert {p.class_code for p in plain} >= {CLASS_CODES["wall"], CLASS_CODES["floor"], CLASS_CODES["ceiling"]}
    want = {CLASS_CODES["wall"]: 1.0, CLASS_CODES["floor"]: -0.5}
    for a, b in zip(plain, cut):
        assert b.score == pytest.approx(a.score + want.get(a.class_code, 0.0))
        np.testing.assert_allclose(b.world_size, a.world_size)


def test_feature_points_subsamples_the_point_statistics_of_the_re_ranking(buildings, trained):
    """``feature-points`` caps the points the re-ranking's statistics read around a box: far above any box's points
    it changes nothing, a small cap changes the statistics (and so the scores) but never the boxes."""
    from engine.detection import rescore as rs
    from engine.detection.boxfit import N_FEATURES as BOX_FEATURES
    from engine.detection.space import detect_space

    wall = CLASS_CODES["wall"]
    row = np.zeros(rs.N_FEATURES)
    row[1:1 + 3 * BOX_FEATURES] = 1.0  # walls: the sum of their point statistics
    pts, model = _largest_space_and_wall_rescorer(buildings, trained, row, 0.0)
    every = detect_space(pts, model, DetectionSettings.from_config(feature_points=0))
    capped_high = detect_space(pts, model, DetectionSettings.from_config(feature_points=len(pts.xyz)))
    capped_low = detect_space(pts, model, DetectionSettings.from_config(feature_points=300))
    assert [p.score for p in every] == [p.score for p in capped_high]
    walls = [(a, b) for a, b in zip(every, capped_low) if a.class_code == wall]
    assert len(walls) >= 2 and any(abs(a.score - b.score) > 1e-6 for a, b in walls)
    for a, b in zip(every, capped_low):
        np.testing.assert_allclose(b.world_size, a.world_size)
        np.testing.assert_allclose(b.center, a.center)


def _largest_space_and_wall_rescorer(buildings, trained, coef_row, bias: float):
    """The test building's largest ground-truth space, and ``trained`` with a re-ranking for walls alone
    (features unscaled, coefficients ``coef_row``, intercept ``bias``)."""
    import dataclasses

    from engine.detection import rescore as rs
    from engine.spaces.points import index_spaces, load_space

    _, stores = buildings
    store = stores["test"]
    ref = max(index_spaces(store, "gt_space"), key=lambda r: r.count)
    coef = np.zeros((12, rs.N_FEATURES))
    coef[CLASS_CODES["wall"]] = coef_row
    enabled = np.zeros(12, bool)
    enabled[CLASS_CODES["wall"]] = True
    rescorer = rs.Rescorer(np.zeros((12, rs.N_FEATURES)), np.ones((12, rs.N_FEATURES)), coef, np.full(12, bias),
                           enabled)
    return load_space(store, ref, "gt_space"), dataclasses.replace(trained, rescorer=rescorer)


def test_every_space_gets_its_ceiling_and_floor_whatever_their_score(buildings, trained):
    """``one-per-space-always`` (the default): a space whose ceiling and floor windows all score below
    ``score-threshold`` still gets its best window of each (its other classes stay below it); without it, none."""
    from engine.detection.space import detect_space
    from engine.spaces.points import index_spaces, load_space

    _, stores = buildings
    store = stores["test"]
    ref = max(index_spaces(store, "gt_space"), key=lambda r: r.count)
    pts = load_space(store, ref, "gt_space")
    usual = detect_space(pts, trained, DetectionSettings.from_config())
    # no window of this model scores that high (and no wall at the space's sides: tests/engine/detection/test_sides.py)
    strict = DetectionSettings.from_config(score_threshold=50.0, side_classes="")
    assert strict.one_per_space_always
    props = detect_space(pts, trained, strict)
    assert sorted(p.class_code for p in props) == [CLASS_CODES["ceiling"], CLASS_CODES["floor"]]
    assert all(p.score < 50.0 for p in props)
    for c in ("ceiling", "floor"):  # the same window as when it passes the threshold
        a = next(p for p in usual if p.class_code == CLASS_CODES[c])
        b = next(p for p in props if p.class_code == CLASS_CODES[c])
        np.testing.assert_allclose(b.center, a.center, atol=1e-6)
    assert detect_space(pts, trained, DetectionSettings.from_config(score_threshold=50.0, side_classes="",
                                                                     one_per_space_always=False)) == []


def test_a_beam_whose_top_is_in_the_lower_half_of_its_space_is_dropped():
    """``hanging-classes`` (default: beams): a beam hangs from the ceiling; one lying on the floor is not one."""
    from engine.detection.space import fallen

    hanging = DetectionSettings.from_config().hanging_classes
    assert hanging == ("beam",)
    beam, table = CLASS_CODES["beam"], CLASS_CODES["table"]
    hi = np.array([[1.0, 1.0, 0.34], [1.0, 1.0, 2.95], [1.0, 1.0, 0.75], [1.0, 1.0, 1.49]])
    got = fallen(np.array([beam, beam, table, beam]), hi, 3.0, hanging)
    assert got.tolist() == [True, False, False, True]
    assert not fallen(np.array([beam]), hi[:1], 3.0, ()).any()


def test_footprint_classes_move_only_their_detections_horizontal_sides(buildings):
    """``footprint-classes`` (engine/detection/footprint.py) runs after the scores: with the shipped model, it moves
    the horizontal sides of chairs to their points and changes no score, no height and no other class's box."""
    from engine.detection.model import load_model
    from engine.detection.space import detect_space
    from engine.spaces.points import index_spaces, load_space

    _, stores = buildings
    store = stores["test"]
    shipped = load_model()
    moved = 0
    for ref in index_spaces(store, "gt_space"):
        pts = load_space(store, ref, "gt_space")
        plain = detect_space(pts, shipped, DetectionSettings.from_config(footprint_classes=""))
        fitted = detect_space(pts, shipped, DetectionSettings.from_config(footprint_classes="chair"))
        assert [(p.class_code, p.score) for p in plain] == [(p.class_code, p.score) for p in fitted]
        for a, b in zip(plain, fitted):
            assert b.world_size[2] == pytest.approx(a.world_size[2])
            if a.class_code != CLASS_CODES["chair"]:
                np.testing.assert_allclose(b.world_size, a.world_size)
                np.testing.assert_allclose(b.center, a.center)
            else:
                moved += not np.allclose(b.world_size, a.world_size)
    assert moved > 0


def _two_boxes(room, ext, rng, cls, lo_m, hi_m):
    """``detect(settings)``: detect_in_volume over the points of ``room`` (2 mm of noise added) on two injected
    ``cls`` windows of one atom, boxes ``lo_m``-``hi_m`` (metres), both scored 5."""
    from engine.detection.canonical import CanonicalFrame
    from engine.detection.model import load_model
    from engine.detection.space import detect_in_volume, prepare_indexed
    from engine.spaces.points import SpacePoints

    xyz = np.concatenate(room) + rng.normal(0, 0.002, (len(room) * 60000, 3))
    xyz[:, 0] = np.clip(xyz[:, 0], 0.0, ext[0])
    pts = SpacePoints(0, xyz, np.full((len(xyz), 3), 0.6))
    model = load_model(None)
    vol, index = prepare_indexed(pts, model, CanonicalFrame(0.0, [0, 0, -0.001], ext + [0, 0, 0.002]))
    code = CLASS_CODES[cls]
    atom = next(i for i, a in enumerate(model.dictionary.atoms_) if a.class_code == code)
    lo = np.round(np.asarray(lo_m) / vol.grid.voxel).astype(np.int64)
    hi = np.round(np.asarray(hi_m) / vol.grid.voxel).astype(np.int64)
    found = {atom: (lo, hi, np.array([5.0, 5.0]), np.array([atom, atom]), np.zeros(2, bool))}
    return lambda settings: detect_in_volume(vol, model, settings, index, [code], found)


def _room(rng, ext, x0):
    """The points of a room ``ext`` metres: floor, ceiling and four walls, 60,000 points each, its first wall at
    x = ``x0`` (the third array)."""
    room = [rng.uniform([0, 0, 0], [ext[0], ext[1], 0], (60000, 3)),
            rng.uniform([0, 0, ext[2]], ext, (60000, 3))]
    for axis, at in ((0, x0), (0, ext[0]), (1, 0.0), (1, ext[1])):
        w = rng.uniform(0, 1, (60000, 3)) * ext
        w[:, axis] = at
        room.append(w)
    return room


def test_a_board_box_on_a_bare_wall_is_not_kept_by_detection():
    """``face-classes``: of two board windows on one wall, the one over a board standing 2 cm out of it is kept and
    the one over bare wall is dropped (engine.detection.faces.fit_faces's ``bare``); with ``face-classes`` empty
    both stay."""
    rng = np.random.default_rng(11)
    ext = np.array([5.0, 8.0, 3.0])
    room = _room(rng, ext, 0.0)
    wall = room[2]  # x = 0: a board 2 cm proud over y 2.0-4.6, z 0.9-2.05; bare wall over y 5.3-7.7
    wall[:, 0] += np.where((wall[:, 1] > 2.0) & (wall[:, 1] < 4.6) & (wall[:, 2] > 0.9) & (wall[:, 2] < 2.05), 0.02, 0)
    board = CLASS_CODES["board"]
    detect = _two_boxes(room, ext, rng, "board", [[0.0, 2.2, 1.0], [0.0, 5.6, 1.0]], [[0.1, 4.4, 2.0], [0.1, 7.4, 2.0]])

    def centres_y(settings):
        det = detect(settings)
        return sorted(((det.lo_m + det.hi_m) / 2)[det.class_code == board, 1].round(1))

    kept = centres_y(DetectionSettings.from_config())
    assert len(kept) == 1 and 2.0 < kept[0] < 4.6
    both = centres_y(DetectionSettings.from_config(face_classes=()))
    assert len(both) == 2 and 5.3 < both[1] < 7.7


def test_a_window_over_an_opening_with_a_sill_gets_the_opening_bonus():
    """``opening-bonus``: of two window boxes on one wall, the one over an opening (face points missing, glass
    15 cm deeper, a sill 0.9 m up) scores ``opening-bonus`` more than without it; the one over solid wall the
    same."""
    rng = np.random.default_rng(12)
    ext = np.array([5.0, 8.0, 3.0])
    room = _room(rng, ext, 0.2)
    wall = room[2]  # x = 0.2: a window opening over y 2.0-3.5, z 0.9-2.1, its glass at x = 0.05
    hole = (wall[:, 1] > 2.0) & (wall[:, 1] < 3.5) & (wall[:, 2] > 0.9) & (wall[:, 2] < 2.1)
    wall[hole, 0] = 0.05
    window = CLASS_CODES["window"]
    detect = _two_boxes(room, ext, rng, "window", [[0.0, 1.8, 0.8], [0.0, 5.6, 0.8]], [[0.3, 3.7, 2.2], [0.3, 7.4, 2.2]])

    def scores(bonus):
        det = detect(DetectionSettings.from_config(opening_bonus=bonus))
        mine = det.class_code == window
        order = np.argsort(((det.lo_m + det.hi_m) / 2)[mine, 1])
        return det.score[mine][order]

    with_bonus, without = scores(2.0), scores(0.0)
    assert len(with_bonus) == 2 == len(without)
    assert with_bonus[0] - without[0] == pytest.approx(2.0) and with_bonus[1] == pytest.approx(without[1])
