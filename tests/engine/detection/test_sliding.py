"""Sliding-window scores: every position equals the window's feature vector times the weights."""
from __future__ import annotations

import numpy as np
import pytest

import engine.detection.sliding as sliding
from engine.detection.canonical import CanonicalFrame
from engine.detection.features import window_features
from engine.detection.layout import FeatureLayout
from engine.detection.sliding import _slot_sums, axis_positions, non_maximum_suppression, score_windows, score_windows_many
from engine.detection.volume import SpaceVolume


def _room(rng, n=40000, extent=(3.0, 2.4, 2.2)):
    """Points on a room's floor, two walls and a table top, plus sparse clutter: most sub-boxes are air."""
    e = np.asarray(extent)
    q = n // 4
    u = lambda lo, hi, m=q: rng.uniform(lo, hi, m)  # noqa: E731
    g = lambda mu, m=q: rng.normal(mu, 0.005, m)  # noqa: E731
    parts = [np.column_stack([u(0, e[0]), u(0, e[1]), g(0.02)]),  # floor
             np.column_stack([g(0.03), u(0, e[1]), u(0, e[2])]),  # wall x = 0
             np.column_stack([u(0, e[0]), g(e[1] - 0.04), u(0, e[2])]),  # wall y = max
             np.column_stack([u(1.0, 1.8, q // 2), u(0.6, 1.2, q // 2), g(0.75, q // 2)]),  # table top
             rng.uniform(0, e, (200, 3))]
    xyz = np.clip(np.concatenate(parts), 0, e)
    rgb = rng.uniform(0, 1, (len(xyz), 3))
    frame = CanonicalFrame(0.3, [0.0, 0.0, 0.0], extent)
    return SpaceVolume.build(frame.from_metric(xyz), rgb, frame, 0.1, 10**7, "space-median")


@pytest.mark.parametrize("k, min_points, shape", [(4, 1, (7, 5, 9)), (4, 4, (11, 3, 6)), (3, 2, (30, 24, 1)),
                                                  (4, 1, (1, 24, 22)), (2, 1, (5, 5, 5)), (4, 1, (1, 1, 1))])
def test_every_position_scores_its_feature_vector(monkeypatch, k, min_points, shape):
    monkeypatch.setattr(sliding, "SUBBOX_BATCH", 700)  # several batches of x positions
    rng = np.random.default_rng(k * 100 + min_points)
    vol = _room(rng)
    lay = FeatureLayout(k=k, min_points=min_points)
    w = rng.normal(size=lay.size)
    ws = score_windows(vol, np.array(shape), w, -0.3, lay, stride=0.25, min_points=10, max_stride=0.2)
    gi = np.stack(np.meshgrid(ws.px, ws.py, ws.pz, indexing="ij"), axis=-1).reshape(-1, 3)
    ref = window_features(vol.iv, vol.grid, gi, gi + ws.shape, lay) @ w - 0.3
    got = ws.scores.ravel()
    few = ws.counts.ravel() < 10
    assert (~few).sum() > 5 and (few.any() or np.prod(shape) > 500)  # small windows meet the air
    assert np.all(np.isneginf(got[few]))  # windows with too few points are not scored
    # the same moment sums as window_features (its eight-corner look-ups): only the order of the
    # final sums differs.  Sums taken another way differ by rounding that a nearly degenerate
    # covariance magnifies (1e-9 here, 3e-2 on generated buildings)
    assert np.allclose(got[~few], ref[~few], rtol=0, atol=1e-10)


def test_masked_groups_are_ignored():
    rng = np.random.default_rng(7)
    vol = _room(rng)
    lay = FeatureLayout(k=4, disabled=("color", "position"))
    w = rng.normal(size=lay.size)
    a = score_windows(vol, np.array([6, 6, 6]), w, 0.0, lay, stride=0.25, max_stride=0.2)
    w2 = np.where(lay.mask, w, 1e6)
    b = score_windows(vol, np.array([6, 6, 6]), w2, 0.0, lay, stride=0.25, max_stride=0.2)
    assert np.array_equal(a.scores, b.scores)


@pytest.mark.parametrize("seed, fill, batch", [(0, 1.0, 1 << 20), (1, 0.3, 1 << 20), (2, 0.1, 7), (3, 0.0, 5)])
def test_slot_sums_equal_the_sum_over_slots(monkeypatch, seed, fill, batch):
    # random intervals: one interval in several slots of one position and of several positions,
    # intervals no position uses, a sparse table; small term batches split the entries
    monkeypatch.setattr(sliding, "TERM_BATCH", batch)
    rng = np.random.default_rng(seed)
    k, m, nf = 3, 2, 5
    nu = [12, 9, 4]
    npos = [5, 6, 7]
    feats = rng.normal(size=(*nu, nf)) * (rng.random(nu) < fill)[..., None]
    index = tuple(rng.integers(0, nu[a], (npos[a], k)) for a in range(3))
    w2 = rng.normal(size=(k, k, k, nf, m))
    want = np.zeros((*npos, m))
    for a in range(k):
        for b in range(k):
            for c in range(k):
                want += feats[np.ix_(index[0][:, a], index[1][:, b], index[2][:, c])] @ w2[a, b, c]
    where = np.nonzero(np.any(feats != 0, axis=-1))
    got = _slot_sums(tuple(nu), where, feats[where], index, w2, k)
    assert got.shape == (m, *npos)
    assert np.abs(want).max() > 1 or fill == 0
    assert np.allclose(np.moveaxis(got, 0, -1), want, rtol=0, atol=1e-12)


def test_many_models_share_the_features_and_score_each_as_alone(monkeypatch):
    monkeypatch.setattr(sliding, "SUBBOX_BATCH", 900)
    rng = np.random.default_rng(11)
    vol = _room(rng)
    lay = FeatureLayout(k=4, min_points=2)
    w = rng.normal(size=(3, lay.size))
    b = np.array([0.5, -1.0, 2.0])
    many = score_windows_many(vol, np.array([8, 4, 7]), w, b, lay, stride=0.25, min_points=10, max_stride=0.2)
    assert len(many) == 3
    for j in range(3):
        one = score_windows(vol, np.array([8, 4, 7]), w[j], b[j], lay, stride=0.25, min_points=10, max_stride=0.2)
        assert np.array_equal(np.isneginf(many[j].scores), np.isneginf(one.scores))
        ok = np.isfinite(one.scores)
        assert ok.sum() > 10
        assert np.allclose(many[j].scores[ok], one.scores[ok], rtol=0, atol=1e-12)
        assert np.array_equal(many[j].counts, one.counts) and np.array_equal(many[j].px, one.px)
    assert not np.allclose(many[0].scores[ok], many[1].scores[ok])


def test_positions_reach_both_faces():
    p = axis_positions(23, 5, 0.25)
    assert p[0] == 0 and p[-1] == 18 and np.all(np.diff(p) >= 1)
    assert axis_positions(10, 10, 0.25).tolist() == [0]
    assert axis_positions(10, 12, 0.25).tolist() == [0]


def test_nms_keeps_best_of_overlapping_boxes():
    lo = np.array([[0, 0, 0], [1, 0, 0], [10, 0, 0], [0, 0, 0]])
    hi = lo + [10, 2, 2]
    hi[3] = [2, 2, 2]
    keep = non_maximum_suppression(lo, hi, np.array([0.5, 0.9, 0.7, 0.1]), 0.3, 10)
    assert keep.tolist() == [1, 2, 3]


def test_a_floor_scores_the_context_only_where_a_window_may_pass_it(monkeypatch):
    """With ``floor``, the scores above it are those without it; every other position is at most the floor,
    and the context block of many of them was never computed (their score is -inf)."""
    monkeypatch.setattr(sliding, "SUBBOX_BATCH", 800)
    rng = np.random.default_rng(5)
    vol = _room(rng)
    lay = FeatureLayout(k=4, min_points=2)
    assert lay.context
    w = rng.normal(size=(3, lay.size))
    b = np.array([0.0, 0.5, -0.5])
    shape = np.array([6, 5, 8])
    full = score_windows_many(vol, shape, w, b, lay, stride=0.25, min_points=10, max_stride=0.2)
    finite = np.concatenate([f.scores[np.isfinite(f.scores)] for f in full])
    floor = float(np.quantile(finite, 0.8))
    cut = score_windows_many(vol, shape, w, b, lay, stride=0.25, min_points=10, max_stride=0.2, floor=floor)
    skipped = 0
    for f, c in zip(full, cut):
        above = f.scores > floor
        assert above.sum() > 5
        assert np.allclose(c.scores[above], f.scores[above], rtol=0, atol=1e-9)
        assert np.all(c.scores[~above] <= floor)
        skipped += int((np.isneginf(c.scores) & np.isfinite(f.scores)).sum())
        assert np.array_equal(c.counts, f.counts)
    assert skipped > 0
    # the context block matters here: without it the scores above the floor are others
    w0 = w.copy()
    w0[:, lay.local_end:] = 0.0
    bare = score_windows_many(vol, shape, w0, b, lay, stride=0.25, min_points=10, max_stride=0.2)
    ok = full[0].scores > floor
    assert not np.allclose(bare[0].scores[ok], full[0].scores[ok], atol=1e-3)
