"""The COPC octree: Morton codes, groups, and the node of each point against a plain reference."""
from __future__ import annotations

import numpy as np

from tiles.copc_octree import BITS, Cube, assign_levels, demorton, morton, pack, plan_groups


def _reference_levels(q, index, group_level, cap, cube):
    """The rule, level by level with sorts: sampled nodes keep the point nearest each sampling cell's centre."""
    n = len(q)
    level = np.full(n, -1)
    remaining = np.arange(n)
    for d in range(cube.depth + 1):
        if not len(remaining):
            break
        if d < group_level:
            sampled = np.ones(len(remaining), bool)
        elif d == cube.depth:
            sampled = np.zeros(len(remaining), bool)
        else:
            nodes, counts = np.unique(pack(q >> (BITS - d)), return_counts=True)
            sampled = counts[np.searchsorted(nodes, pack(q[remaining] >> (BITS - d)))] > cap
        level[remaining[~sampled]] = d
        rest = remaining[sampled]
        fine = BITS - d - cube.grid_bits
        cell = pack(q[rest] >> fine)
        off = 2 * (q[rest] & ((1 << fine) - 1)) + 1 - (1 << fine)
        order = np.lexsort((index[rest], (off * off).sum(1), cell))
        first = np.r_[True, cell[order][1:] != cell[order][:-1]] if len(rest) else np.zeros(0, bool)
        level[rest[order[first]]] = d
        remaining = rest[order[~first]]
    return level


def test_morton_codes_nest_and_invert():
    rng = np.random.default_rng(0)
    keys = rng.integers(0, 1 << 7, (500, 3))
    codes = morton(keys, 7)
    assert [demorton(int(c), 7) for c in codes[:50]] == [tuple(k) for k in keys[:50].tolist()]
    np.testing.assert_array_equal(codes >> 3, morton(keys >> 1, 6))  # a parent's code: the child's >> 3
    assert morton(np.array([[1, 0, 0], [0, 1, 0], [0, 0, 1]]), 1).tolist() == [1, 2, 4]  # COPC child order


def test_levels_follow_the_rule_with_clusters_and_duplicates():
    rng = np.random.default_rng(1)
    cube = Cube((0.0, 0.0, 0.0), 1.0, grid_bits=2)
    q = rng.integers(0, 1 << BITS, (4000, 3))
    q[:1500] = (1 << 20) + rng.integers(0, 1 << 12, (1500, 3))  # a dense cluster: deep levels
    q[1500:1600] = q[1500]  # duplicates: down to the deepest level
    index = rng.permutation(10_000)[:4000]
    got = assign_levels(q, index, 1, 50, cube)
    np.testing.assert_array_equal(got, _reference_levels(q, index, 1, 50, cube))
    assert got.max() == cube.depth and got.min() == 0


def test_groups_cover_every_point_once_within_their_budget():
    rng = np.random.default_rng(2)
    cube = Cube((0.0, 0.0, 0.0), 1.0, grid_bits=3)
    codes = np.sort(np.unique(rng.integers(0, 8 ** 3, 300)))
    counts = rng.integers(1, 40, len(codes))
    counts[5] = 500  # a level-3 cell over the budget: a group of its own at the deepest group level
    groups = plan_groups(codes, counts, cube, 100)
    assert sum(g.count for g in groups) == counts.sum()
    assert all(g.count <= 100 or g.level == 3 for g in groups)
    spans = sorted((g.lo, g.hi) for g in groups)
    assert all(a[1] <= b[0] for a, b in zip(spans, spans[1:]))  # disjoint Morton ranges


def test_levels_are_the_same_when_indices_span_too_far_for_one_key():
    """Distance and index share one int64 key when they fit; far-apart indices take the two-step choice."""
    rng = np.random.default_rng(3)
    cube = Cube((0.0, 0.0, 0.0), 1.0, grid_bits=2)
    q = rng.integers(0, 1 << BITS, (3000, 3))
    q[:1000] = (1 << 19) + rng.integers(0, 1 << 10, (1000, 3))
    index = rng.choice(1 << 20, 3000, replace=False).astype(np.int64)
    far = index * (1 << 40)  # the same order of indices, too far apart to share a key with a distance
    got = assign_levels(q, index, 1, 40, cube)
    np.testing.assert_array_equal(got, _reference_levels(q, index, 1, 40, cube))
    np.testing.assert_array_equal(assign_levels(q, far, 1, 40, cube), got)
