"""Learned box regression: features of hand-made points, face offsets that round-trip, a fit that helps only
when the points tell where the element is, the model file and detection using it."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from engine.detection import boxfit as bf


def _plane(axis: int, at: float, lo: np.ndarray, hi: np.ndarray, n: int = 400, seed: int = 0) -> np.ndarray:
    """Points on the plane ``x[axis] == at`` spread over the box's extent on the other axes."""
    rng = np.random.default_rng(seed)
    p = rng.uniform(lo, hi, (n, 3))
    p[:, axis] = at
    return p


def test_axis_features_of_a_plane_and_mirrored():
    lo, hi = np.array([1.0, 2.0, 0.5]), np.array([1.1, 3.5, 1.5])
    pts = _plane(0, 1.13, lo, hi)  # a plane 3 cm past the box's high face along x (box 10 cm deep)
    f = bf.axis_features(pts, lo, hi, 0, mirror=False)
    q = f[:len(bf.QUANTILES)]
    np.testing.assert_allclose(q, 1.3, atol=1e-9)  # every quantile at the plane, in box sizes
    prof = f[len(bf.QUANTILES):len(bf.QUANTILES) + bf.BINS]
    assert prof.sum() == pytest.approx(1.0) and prof.max() == 1.0
    assert f[-2] == 0.0 and f[-1] == 0.0 and f[-3] == pytest.approx(np.log(0.1))  # none inside, not empty
    m = bf.axis_features(pts, lo, hi, 0, mirror=True)
    np.testing.assert_allclose(m[:len(bf.QUANTILES)], -0.3, atol=1e-9)  # read backwards
    np.testing.assert_array_equal(m[len(bf.QUANTILES):len(bf.QUANTILES) + bf.BINS], prof[::-1])
    # points outside the box on another axis do not count; nothing left -> the empty flag
    far = pts + np.array([0.0, 5.0, 0.0])
    assert bf.axis_features(far, lo, hi, 0, mirror=False)[-1] == 1.0


def _reference_axis_features(points, lo, hi, axis, mirror):
    """The features as first written: np.quantile, np.histogram and a mean on the unsorted values."""
    other = [a for a in range(3) if a != axis]
    s = max(hi[axis] - lo[axis], 1e-6)
    within = (points >= lo) & (points <= hi)
    u = (points[within[:, other[0]] & within[:, other[1]], axis] - lo[axis]) / s
    u = 1.0 - u if mirror else u
    u = u[(u >= -bf.GROW) & (u <= 1.0 + bf.GROW)]
    f = np.zeros(bf.N_FEATURES)
    f[-3] = np.log(s)
    if len(u) < 3:
        f[:len(bf.QUANTILES)], f[-1] = 0.5, 1.0
        return f
    f[:len(bf.QUANTILES)] = np.quantile(u, bf.QUANTILES)
    f[len(bf.QUANTILES):len(bf.QUANTILES) + bf.BINS] = np.histogram(u, bins=bf.BINS, range=(-bf.GROW, 1.0 + bf.GROW))[0] / len(u)
    f[-2] = np.mean((u >= 0) & (u <= 1))
    return f


@pytest.mark.parametrize("seed", range(6))
def test_axis_features_are_those_of_quantiles_and_a_histogram_of_the_values(seed):
    """Bit for bit, values on the profile's bin edges and on the box's faces included."""
    rng = np.random.default_rng(seed)
    lo, hi = np.array([1.0, 2.0, 0.0]), np.array([1.5, 3.0, 2.0])
    n = int(rng.integers(3, 5000))
    pts = rng.uniform([0.0, 1.5, -0.5], [2.5, 3.5, 2.5], (n, 3))
    # some points exactly on the bin edges and faces (in box units: lo + edge * size)
    on = rng.integers(0, n, n // 4)
    pts[on, 0] = lo[0] + rng.choice(bf.PROFILE_EDGES, len(on)) * 0.5
    pts = np.round(pts, 2) if seed % 2 else pts  # ties
    for axis in range(3):
        for mirror in (False, True):
            np.testing.assert_array_equal(bf.axis_features(pts, lo, hi, axis, mirror),
                                          _reference_axis_features(pts, lo, hi, axis, mirror))


@pytest.mark.parametrize("n", [1, 2, 3, 4, 7, 100, 4097])
def test_sorted_quantiles_are_numpys_bit_for_bit(n):
    rng = np.random.default_rng(n)
    q = np.concatenate([bf._Q, np.linspace(0.0, 1.0, 101), rng.uniform(0, 1, 50)])
    for u in (np.sort(rng.normal(size=n)), np.sort(np.round(rng.uniform(-1, 2, n), 1))):
        np.testing.assert_array_equal(bf.sorted_quantiles(u, q), np.quantile(u, q))


def test_roles_and_face_offsets_round_trip():
    rng = np.random.default_rng(3)
    extent = np.array([6.0, 4.0, 4.0])
    lo = rng.uniform(0.2, 2.0, (50, 3))
    hi = lo + rng.uniform(0.1, 1.5, (50, 3))
    gt_lo = lo + rng.uniform(-0.05, 0.05, (50, 3))
    gt_hi = hi + rng.uniform(-0.05, 0.05, (50, 3))
    roles = bf.axis_roles(lo, hi)
    size = hi - lo
    thin = np.take_along_axis(size, roles[:, :1], 1)[:, 0]
    wide = np.take_along_axis(size, roles[:, 1:2], 1)[:, 0]
    assert np.all(thin <= wide) and np.all(roles[:, 2] == 2)
    t = bf.face_targets(lo, hi, gt_lo, gt_hi, extent)
    nlo, nhi = bf.moved_boxes(lo, hi, t, extent)
    np.testing.assert_allclose(nlo, gt_lo, atol=1e-12)
    np.testing.assert_allclose(nhi, gt_hi, atol=1e-12)
    # a box past the middle is read backwards: a truth 2 cm nearer the space's end is a negative offset of
    # both faces, as for a box near the start whose truth is 2 cm nearer the start
    one_lo, one_hi = np.array([[5.0, 1.0, 1.0], [0.5, 1.0, 1.0]]), np.array([[5.1, 2.0, 2.0], [0.6, 2.0, 2.0]])
    shift = np.array([[0.02, 0, 0], [-0.02, 0, 0]])
    t1 = bf.face_targets(one_lo, one_hi, one_lo + shift, one_hi + shift, extent)
    np.testing.assert_allclose(t1[:, 0], -0.2)
    np.testing.assert_allclose(t1[:, 1:], 0.0, atol=1e-12)


def _samples(n_buildings: int, per: int, informative: bool, seed: int = 0) -> dict[str, np.ndarray]:
    """Boards: 10 cm deep windows whose depth is off by up to 5 cm from the truth; the points show the board's
    face (informative) or lie anywhere (not)."""
    rng = np.random.default_rng(seed)
    extent = np.array([8.0, 6.0, 3.0])
    rows = {k: [] for k in ("cls", "feats", "targets", "lo", "hi", "gt_lo", "gt_hi", "extent", "building")}
    for b in range(n_buildings):
        for _ in range(per):
            wall = rng.uniform(0.0, 0.3)  # the wall face at low x; the board is 2 cm off it, its box 10 cm deep
            gt_lo = np.array([wall, rng.uniform(1, 2), rng.uniform(0.8, 1.0)])
            gt_hi = gt_lo + [0.1, rng.uniform(1.2, 2.4), rng.uniform(0.9, 1.2)]
            off = rng.uniform(-0.05, 0.05)
            lo, hi = gt_lo + [off, 0, 0], gt_hi + [off, 0, 0]
            lo[0] = max(lo[0], 0.0)
            face = wall + 0.02 if informative else rng.uniform(0.0, 0.4)
            pts = np.vstack([_plane(0, face, gt_lo, gt_hi, 300, b), _plane(0, max(wall - 0.001, 0), gt_lo, gt_hi, 50, b)])
            if not informative:
                pts[:, 0] = rng.uniform(0, 0.5, len(pts))
            f, _ = bf.box_features(lambda a, c: pts, lo[None], hi[None], extent)
            rows["cls"].append(11), rows["feats"].append(f[0]), rows["building"].append(b)
            rows["targets"].append(bf.face_targets(lo[None], hi[None], gt_lo[None], gt_hi[None], extent)[0])
            for k, v in (("lo", lo), ("hi", hi), ("gt_lo", gt_lo), ("gt_hi", gt_hi), ("extent", extent)):
                rows[k].append(v)
    return {k: np.asarray(v) for k, v in rows.items()}


def test_fit_moves_boxes_onto_the_elements_when_the_points_tell():
    s = _samples(4, 12, informative=True)
    fit = bf.fit_boxfit(s, [11])
    rep = fit.report["classes"]["board"]
    depth = rep["roles"][0]  # the board's error is in depth: that role is used, validated by its wins
    assert fit.enabled[11] and depth["used"] and depth["wins_cv"] - depth["losses_cv"] >= 2 * np.sqrt(
        depth["wins_cv"] + depth["losses_cv"]) and not fit.enabled[:11].any()
    test = _samples(1, 30, informative=True, seed=9)
    before = bf.box_iou_rows(test["lo"], test["hi"], test["gt_lo"], test["gt_hi"])
    nlo, nhi = bf.moved_boxes(test["lo"], test["hi"], fit.predict(test["cls"], test["feats"]), test["extent"])
    after = bf.box_iou_rows(nlo, nhi, test["gt_lo"], test["gt_hi"])
    assert after.mean() > 0.9 > before.mean() and (after >= 0.5).sum() > (before >= 0.5).sum()


def test_fit_stays_off_when_the_points_say_nothing_or_samples_are_few():
    noise = bf.fit_boxfit(_samples(4, 12, informative=False), [11])
    assert not noise.enabled.any() and np.all(noise.coef == 0)
    few = bf.fit_boxfit(_samples(2, 12, informative=True), [11])
    assert not few.enabled[11] and "too few" in few.report["classes"]["board"]["why"]


def test_model_with_box_regression_round_trips_and_old_models_have_none(tmp_path):
    from engine.detection.model import load_model
    from tests.engine.detection.test_model import _model

    m = _model()
    rng = np.random.default_rng(2)
    enabled = np.zeros(12, bool)
    enabled[11] = True
    fit = bf.BoxFit(rng.normal(size=(12, 3, 2, bf.N_FEATURES + 1)), enabled, {"classes": {"board": {"enabled": True}}})
    dataclasses.replace(m, boxfit=fit).save(tmp_path / "v3")
    back = load_model(tmp_path / "v3")
    assert back.params()["version"] == 3 and back.params()["boxfit"]["classes"]["board"]["enabled"]
    np.testing.assert_array_equal(back.boxfit.coef, fit.coef)
    np.testing.assert_array_equal(back.boxfit.enabled, enabled)
    m.save(tmp_path / "v1")
    assert load_model(tmp_path / "v1").boxfit is None and "boxfit_coef" not in m.params()["arrays"]
    with pytest.raises(ValueError):
        bf.BoxFit(fit.coef[:, :2], enabled)


def test_apply_moves_only_enabled_classes():
    extent = np.array([5.0, 5.0, 3.0])
    lo = np.array([[1.0, 1.0, 1.0], [2.0, 2.0, 0.0]])
    hi = np.array([[1.1, 2.5, 2.0], [3.0, 3.0, 0.8]])
    coef = np.zeros((12, 3, 2, bf.N_FEATURES + 1))
    coef[11, 0, :, -1] = 0.5  # boards: both faces of the thin axis half a box size outwards... the first face in
    enabled = np.zeros(12, bool)
    enabled[11] = True
    fit = bf.BoxFit(coef, enabled)
    lo_m, hi_m = lo.copy(), hi.copy()
    fit.apply(lo_m, hi_m, np.array([11, 7]), lambda a, b: np.zeros((0, 3)), extent)
    np.testing.assert_allclose(lo_m[0], [1.05, 1.0, 1.0])
    np.testing.assert_allclose(hi_m[0], [1.15, 2.5, 2.0])
    np.testing.assert_array_equal(lo_m[1], lo[1])  # tables: not enabled
    np.testing.assert_array_equal(hi_m[1], hi[1])
