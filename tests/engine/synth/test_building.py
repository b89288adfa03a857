"""The building model: one local-to-world frame, parts that cover every space, bounds and origin."""
from __future__ import annotations

import math

import numpy as np
import pytest

from engine.synth import Frame, plan_building


def test_frame_is_a_rotation_then_a_shift():
    f = Frame(math.radians(90), (10.0, 20.0, 3.0))
    np.testing.assert_allclose(f.xyz(np.array([[1.0, 0.0, 0.5], [0.0, 2.0, 0.0]])),
                               [[10.0, 21.0, 3.5], [8.0, 20.0, 3.0]], atol=1e-12)
    assert f.angle(math.radians(100)) == pytest.approx(math.radians(-170))
    assert Frame(math.pi, (0, 0, 0)).angle(0.0) == pytest.approx(math.pi)  # (-pi, pi]


def test_parts_cover_each_space_once(building):
    by_space = {}
    for p in building.parts:
        by_space.setdefault(p.space, []).append(p)
    assert sorted(by_space) == [s.id for s in building.spaces]
    assert [p.part_id for p in building.parts] == list(range(len(building.parts)))
    for ps in by_space.values():
        assert [p.piece for p in ps] == list(range(ps[0].pieces))
        assert ps[0].lo == -math.inf and ps[-1].hi == math.inf
        assert all(a.hi == b.lo for a, b in zip(ps, ps[1:]))  # slabs touch, no gap, no overlap


def test_pieces_respect_the_part_budget():
    b = plan_building(2, area_m2=300, density=2000, part_points=200_000)
    assert max(p.estimate for p in b.parts) <= 200_000
    assert max(p.pieces for p in b.parts) > 1


def test_bounds_and_origin_enclose_the_building():
    b = plan_building(1, area_m2=200, density=100, yaw=45.0, offset=(500000.0, 4100000.0, 30.0))
    lo, hi = b.world_bounds()[:3], b.world_bounds()[3:]
    origin = np.asarray(b.origin())
    assert np.all(origin <= lo) and np.all(origin == np.round(origin))
    assert np.all(hi - origin < 1000)  # int32 steps of 0.1 mm reach 214 km
    doc = b.ground_truth()
    for s in doc["spaces"]:
        fp = np.asarray(s["footprint"])
        assert np.all(fp >= lo[:2] - 1e-6) and np.all(fp <= hi[:2] + 1e-6)
