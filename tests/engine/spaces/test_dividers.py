"""The peak-gap-peak filter bank, max-pooling, NMS and threshold on hand-made 1-D density signals."""
from __future__ import annotations

import numpy as np
import pytest

from engine.spaces.dividers import (
    DividerSettings,
    bank_responses,
    detect_dividers,
    empty_runs,
    max_pool,
    non_maximum_suppression,
    occupied_extent,
    vertical_params,
)

BW = 0.01


def room_signal(walls, *, length=21.0, slice_width=5.0, density=300.0, height=2.8, seed=0, faces=True):
    """Expected counts of a 1-D histogram across rooms: floor + ceiling everywhere, walls as void + two faces.

    ``walls``: (centre, thickness) in metres.  Poisson-sampled, so the signal is noisy like a scan.
    """
    x = (np.arange(int(round(length / BW))) + 0.5) * BW
    lam = np.full(len(x), 2 * density * slice_width * BW)
    for centre, t in walls:
        lam[np.abs(x - centre) < t / 2] = 0.0
        if faces:
            for face in (centre - t / 2 - BW / 2, centre + t / 2 + BW / 2):
                lam[int(face / BW)] += density * slice_width * height
    return np.random.default_rng(seed).poisson(lam).astype(float), x


def test_two_peaks_with_a_gap_give_one_divider_at_the_gap_centre():
    h, _ = room_signal([(7.3, 0.2)])
    found = detect_dividers(h)
    assert len(found) == 1
    d = found[0]
    assert abs(d.position - 7.3) <= BW
    assert 0.1 <= d.width <= 0.26
    assert d.contrast > 0.9 and d.void_ratio < 0.1
    assert abs(d.cut * BW - 7.3) <= BW


def test_a_lone_strong_peak_is_not_a_divider():
    h, x = room_signal([])
    h[int(6.0 / BW)] += 20 * h.mean() * 5  # a bookcase face: a strong peak without a void
    h[int(12.0 / BW):int(12.0 / BW) + 3] += 10 * h.mean()  # a table side, a bit wider
    assert detect_dividers(h) == []


def test_an_aisle_between_two_tall_faces_is_not_a_divider():
    # two bookcases facing each other across 0.3 m: peaks with a gap, but the floor and the ceiling
    # run through the gap at the room's level, so the void test refuses it
    h, _ = room_signal([])
    level = h.mean()
    h[int(5.0 / BW)] += 60 * level
    h[int(5.32 / BW)] += 60 * level
    assert detect_dividers(h) == []


@pytest.mark.parametrize("factor", [0.2, 100.0])
def test_density_scaled_gives_the_same_dividers(factor):
    walls = [(4.0, 0.12), (9.5, 0.2), (15.0, 0.3)]
    base, _ = room_signal(walls, density=300.0)
    scaled, _ = room_signal(walls, density=300.0 * factor, seed=1)
    a = [round(d.position, 2) for d in detect_dividers(base)]
    b = [round(d.position, 2) for d in detect_dividers(scaled)]
    assert len(a) == len(walls)
    assert a == pytest.approx(b, abs=BW)


def test_several_walls_of_different_thickness_are_all_found():
    walls = [(2.5, 0.08), (5.0, 0.12), (8.0, 0.2), (11.5, 0.3), (15.5, 0.45), (18.5, 0.7)]
    h, _ = room_signal(walls)
    found = detect_dividers(h)
    assert [round(d.position, 1) for d in found] == pytest.approx([w[0] for w in walls], abs=0.05)
    widths = [d.width for d in found]
    assert widths == sorted(widths)  # the best stop width follows the void's thickness


def test_a_wall_cut_by_a_door_is_found_in_the_upper_band():
    # door jambs and threshold fill the gap over all heights; above the door the wall is solid
    h_full, _ = room_signal([(6.0, 0.2)])
    h_up, _ = room_signal([(6.0, 0.2)], density=300.0 * 0.6 / 2.8, seed=3)  # band: 0.6 m of wall + ceiling
    gap = slice(int(5.9 / BW) + 1, int(6.1 / BW))
    level = np.median(h_full)
    h_full[gap] += 0.6 * level  # jambs and threshold: 60 % of the room level
    with_band = detect_dividers(h_full, upper=h_up)
    assert len(with_band) == 1 and abs(with_band[0].position - 6.0) <= BW
    # the same gap filled up to the ceiling (an open passage) is no divider
    h_up[gap] = np.median(h_up)
    assert detect_dividers(h_full, upper=h_up) == []


def test_a_beam_is_not_a_divider():
    # a beam: two side faces high up, its bottom face and the floor below fill the gap at all heights
    h, _ = room_signal([])
    level = np.median(h)
    h[int(8.0 / BW)] += 15 * level
    h[int(8.3 / BW)] += 15 * level
    h[int(8.0 / BW) + 1:int(8.3 / BW)] += 0.5 * level  # beam bottom
    assert detect_dividers(h) == []


def test_bank_responses_equal_the_convolution_with_the_filter():
    rng = np.random.default_rng(5)
    h = rng.poisson(20, 300).astype(float)
    bank = np.array([[5, 3], [8, 2]])
    br = bank_responses(h, bank)
    for k, (d, c) in enumerate(bank):
        kernel_margin = np.r_[np.ones(c) / c, np.zeros(d), np.ones(c) / c]
        # correlation with the filter's three parts over its support [i - c, i + d + c)
        left = np.convolve(h, np.r_[np.ones(c), np.zeros(c + d)][::-1] / c, mode="valid")
        right = np.convolve(h, np.r_[np.zeros(c + d), np.ones(c)][::-1] / c, mode="valid")
        gap = np.convolve(h, np.r_[np.zeros(c), np.ones(d), np.zeros(c)][::-1] / d, mode="valid")
        # response at gap start i (filter support starts at i - c) on the half-bin grid j = 2 i + d
        i = np.arange(c, len(h) - d - c + 1)
        j = 2 * i + d
        np.testing.assert_allclose(br.left[k, j], left[i - c], atol=1e-9)
        np.testing.assert_allclose(br.right[k, j], right[i - c], atol=1e-9)
        np.testing.assert_allclose(br.gap[k, j], gap[i - c], atol=1e-9)
        np.testing.assert_allclose(br.response[k, j], np.minimum(left, right)[i - c] - gap[i - c], atol=1e-9)
        assert kernel_margin.sum() == pytest.approx(2.0)  # the paper's 1/(2c) normalisation, both margins
    pooled, best = max_pool(br)
    assert np.all(pooled >= br.response.max(axis=0) - 1e-12) and best.shape == pooled.shape


def test_filter_bank_spans_the_documented_widths():
    p = DividerSettings()
    bank = p.bank()
    assert bank[:, 0].min() * BW == pytest.approx(0.03) and bank[:, 0].max() * BW == pytest.approx(0.8)
    assert sorted(set(bank[:, 1] * BW)) == pytest.approx([0.02, 0.04, 0.08, 0.16, 0.32])
    v = vertical_params()
    assert v.bank()[:, 0].max() * v.bin_width == pytest.approx(2.0)


def test_non_maximum_suppression_keeps_the_best_within_the_radius():
    s = np.array([0, 1, 5, 4, 0, 0, 3, 0, 0, 0, 0, 2, 2, 0], dtype=float)
    assert non_maximum_suppression(s, 2).tolist() == [2, 6, 11]
    assert non_maximum_suppression(s, 4).tolist() == [2, 11]
    valid = np.ones(len(s), bool)
    valid[2] = False
    assert non_maximum_suppression(s, 2, valid).tolist() == [3, 6, 11]
    assert non_maximum_suppression(np.full(5, -np.inf), 1).tolist() == []


def test_empty_runs_and_extent():
    h = np.array([0, 0, 0, 5, 1, 0, 0, 2, 0, 0, 0, 0])
    assert empty_runs(h, 2) == [(0, 3), (5, 7), (8, 12)]
    assert empty_runs(h, 3) == [(0, 3), (8, 12)]
    assert occupied_extent(h) == (3, 8)
    assert occupied_extent(np.zeros(4)) is None
