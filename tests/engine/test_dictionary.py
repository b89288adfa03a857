"""The window dictionary: Affinity Propagation on hand-made boxes and occupancy patterns."""
from __future__ import annotations

import numpy as np
import pytest

from engine.dictionary import WindowDictionary, occupancy_agreement, size_iou
from tiles.classes import CLASS_CODES

K = 2


def _pattern(cells):
    occ = np.zeros((K, K, K), dtype=bool)
    for c in cells:
        occ[c] = True
    return occ


def _instances():
    rng = np.random.default_rng(0)
    cls, unit, metric, occ = [], [], [], []
    chair, table = _pattern([(0, 0, 0), (0, 0, 1), (1, 0, 0)]), _pattern([(0, 0, 1), (1, 0, 1), (0, 1, 1), (1, 1, 1)])
    for _ in range(12):  # chairs: 0.5 x 0.5 x 0.9 m in rooms of 4 to 12 m
        room = rng.uniform([4, 4, 2.8], [12, 12, 3.2])
        m = np.array([0.5, 0.5, 0.9]) * rng.uniform(0.95, 1.05, 3)
        cls.append(CLASS_CODES["chair"]), metric.append(m), unit.append(m / room), occ.append(chair)
    for _ in range(9):  # tables: 1.6 x 0.8 x 0.75 m, one with a different pattern
        room = rng.uniform([4, 4, 2.8], [12, 12, 3.2])
        m = np.array([1.6, 0.8, 0.75]) * rng.uniform(0.95, 1.05, 3)
        cls.append(CLASS_CODES["chair"]), metric.append(m), unit.append(m / room), occ.append(table)
    for i in range(10):  # walls along x: the room's length, 2.4 cm thick, the room's height
        room = rng.uniform([4, 4, 2.8], [12, 12, 3.2])
        m = np.array([room[0], 0.024, room[2]])
        p = np.ones((K, K, K), bool)
        if i == 0:
            p[0, 0, 0] = False  # the mode keeps the majority pattern
        cls.append(CLASS_CODES["wall"]), metric.append(m), unit.append(m / room), occ.append(p)
    return np.array(cls), np.array(unit), np.array(metric), np.array(occ)


def test_affinity_propagation_on_hand_made_boxes():
    cls, unit, metric, occ = _instances()
    d = WindowDictionary(k=K, random_state=0).fit(cls, unit, metric, occ)
    chairs = d.atoms_of(CLASS_CODES["chair"])
    walls = d.atoms_of(CLASS_CODES["wall"])
    assert len(chairs) == 2 and len(walls) == 1
    small, big = sorted(chairs, key=lambda a: a.metric_size[0])
    assert (small.members, big.members) == (12, 9)
    assert np.allclose(small.metric_size, metric[:12].mean(0))
    assert np.allclose(big.metric_size, metric[12:21].mean(0))
    assert not small.relative.any()  # furniture keeps its size in metres
    assert small.occupancy.sum() == 3 and big.occupancy[:, :, 1].all() and not big.occupancy[:, :, 0].any()
    wall = walls[0]
    assert wall.relative.tolist() == [True, False, True]  # as long and high as the room, thickness in metres
    assert wall.occupancy.all()
    extent = np.array([8.0, 5.0, 3.0])
    assert np.allclose(wall.size_in(extent), [8.0 * wall.unit_size[0], wall.metric_size[1], 3.0 * wall.unit_size[2]])
    assert d.atoms_of(CLASS_CODES["sofa"]) == []


def test_dictionary_is_deterministic_and_round_trips():
    cls, unit, metric, occ = _instances()
    a = WindowDictionary(k=K, random_state=3).fit(cls, unit, metric, occ)
    b = WindowDictionary(k=K, random_state=3).fit(cls, unit, metric, occ)
    for k_, v in a.to_arrays().items():
        assert np.array_equal(v, b.to_arrays()[k_])
    c = WindowDictionary.from_arrays(a.to_arrays(), a.params())
    for k_, v in a.to_arrays().items():
        assert np.array_equal(v, c.to_arrays()[k_])


def test_similarity_pieces():
    unit = np.array([[0.5, 0.1, 1.0], [0.25, 0.1, 1.0]])
    metric = np.array([[4.0, 0.5, 3.0], [4.0, 0.25, 3.0]])
    # x agrees in metres, y in the unit cube: the per-axis best frame makes the boxes identical
    assert np.allclose(size_iou(unit, metric), 1.0)
    assert size_iou(np.array([[1, 1, 1], [0.5, 1, 1.0]]), np.array([[1, 1, 1], [0.5, 1, 1.0]]))[0, 1] == pytest.approx(0.5)
    occ = np.array([np.ones((2, 2, 2), bool), np.zeros((2, 2, 2), bool)])
    assert np.allclose(occupancy_agreement(occ), [[1, 0], [0, 1]])


def test_parameters_are_validated():
    cls, unit, metric, occ = _instances()
    with pytest.raises(ValueError):
        WindowDictionary(k=K, damping=0.2).fit(cls, unit, metric, occ)
    with pytest.raises(ValueError):
        WindowDictionary(k=3).fit(cls, unit, metric, occ)
