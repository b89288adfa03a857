"""The window dictionary: Affinity Propagation on hand-made boxes and occupancy patterns."""
from __future__ import annotations

import numpy as np
import pytest

from engine.detection.dictionary import WindowDictionary, occupancy_agreement, size_iou
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


def test_relative_only_where_the_members_clearly_follow_the_room():
    rng = np.random.default_rng(5)
    n = 12
    rooms = rng.uniform([5, 3, 2.8], [9, 18, 3.2], (n, 3))
    # boards 0.1 m deep, 1.1 m high, a little wider in wider rooms (as generated conference rooms have)
    metric = np.stack([rooms[:, 0] * 0.25 * rng.uniform(0.75, 1.25, n), np.full(n, 0.1),
                       rng.uniform(1.05, 1.15, n)], axis=1)
    cv = lambda s: s.std() / s.mean()  # noqa: E731
    assert 0.5 * cv(metric[:, 0]) < cv(metric[:, 0] / rooms[:, 0]) < cv(metric[:, 0])
    occ = np.ones((n, K, K, K), bool)
    d = WindowDictionary(k=K, min_gap=1.0).fit(np.full(n, CLASS_CODES["board"]), metric / rooms, metric, occ)
    [atom] = d.atoms_
    assert not atom.relative.any()  # the old rule (cv in the unit cube <= cv in metres) made x relative
    legacy = WindowDictionary(k=K, min_gap=1.0, relative_ratio=None).fit(
        np.full(n, CLASS_CODES["board"]), metric / rooms, metric, occ)
    assert legacy.atoms_[0].relative[0]
    # one wall and one chair: the wall spans its room's length and height, the chair keeps metres
    d = WindowDictionary(k=K).fit(np.array([CLASS_CODES["wall"], CLASS_CODES["chair"]]),
                                  np.array([[0.97, 0.01, 1.0], [0.1, 0.12, 0.3]]),
                                  np.array([[6.0, 0.03, 3.0], [0.5, 0.6, 0.9]]), np.ones((2, K, K, K), bool))
    assert d.atoms_of(CLASS_CODES["wall"])[0].relative.tolist() == [True, False, True]
    assert not d.atoms_of(CLASS_CODES["chair"])[0].relative.any()
    # a model written before the parameter existed reads back with the rule it was fitted with
    back = WindowDictionary.from_arrays(d.to_arrays(), {k: v for k, v in d.params().items() if k != "relative_ratio"})
    assert back.relative_ratio is None and WindowDictionary.from_arrays(d.to_arrays(), d.params()).relative_ratio == 0.5
