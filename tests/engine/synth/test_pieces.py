"""Pieces in their own frame: tables stand on the floor with their top at the given height, backs towards +y."""
from __future__ import annotations

import numpy as np
import pytest

from engine.synth.pieces import board, bookcase, chair, clutter, sofa, table


def _bounds(parts):
    lo = np.array([[cx - sx / 2, cy - sy / 2, cz - sz / 2] for cx, cy, cz, sx, sy, sz, _ in parts])
    hi = np.array([[cx + sx / 2, cy + sy / 2, cz + sz / 2] for cx, cy, cz, sx, sy, sz, _ in parts])
    return lo.min(0), hi.max(0)


@pytest.mark.parametrize("seed", range(6))
def test_a_table_stands_on_the_floor_within_its_size(seed):
    parts = table(np.random.default_rng(seed), 1.4, 0.7, 0.75, (1, 2, 3))
    lo, hi = _bounds(parts)
    assert lo[2] == pytest.approx(0.0) and hi[2] == pytest.approx(0.75)
    assert np.all(lo[:2] >= [-0.7 - 1e-9, -0.35 - 1e-9]) and np.all(hi[:2] <= [0.7 + 1e-9, 0.35 + 1e-9])
    assert parts[0][5] == pytest.approx(0.03)  # the top first: recipes read it as the table's top


@pytest.mark.parametrize("seed", range(6))
def test_chair_and_sofa_backs_are_towards_plus_y(seed):
    rng = np.random.default_rng(seed)
    back = chair(rng, (0, 0, 0))[1]
    assert back[1] > 0 and back[2] > 0.42
    s = sofa(rng, 2.0, (0, 0, 0))
    assert s[2][1] > 0 and _bounds(s)[0][2] == pytest.approx(0.0)


@pytest.mark.parametrize("seed", range(6))
def test_bookcase_and_books_stay_inside_the_case(seed):
    lo, hi = _bounds(bookcase(np.random.default_rng(seed), 1.0, 0.4, 2.0, (0, 0, 0)))
    assert np.allclose(lo, [-0.5, -0.2, 0.0]) and np.allclose(hi, [0.5, 0.2, 2.0])


def test_board_hangs_from_its_bottom():
    parts = board(np.random.default_rng(0), 1.5, 1.0, 0.9, (0, 0, 0))
    assert parts[0][2] - parts[0][5] / 2 == pytest.approx(0.9)


def test_clutter_stands_at_its_height_and_unknown_kinds_are_refused():
    for kind in ("monitor", "laptop", "papers", "bin", "box", "plant", "printer", "cooler", "toilet"):
        parts, (w, d) = clutter(np.random.default_rng(1), kind, 0.75)
        assert _bounds(parts)[0][2] == pytest.approx(0.75) and w > 0 and d > 0
    with pytest.raises(ValueError):
        clutter(np.random.default_rng(1), "piano")
