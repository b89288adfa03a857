"""ARI from summed per-tile contingency tables equals scikit-learn's adjusted_rand_score."""
from __future__ import annotations

import numpy as np
import pytest
from sklearn.metrics import adjusted_rand_score

from engine.metrics.ari import (
    ari,
    ari_from_contingency,
    contingency_pairs,
    contingency_table,
    distributed_ari,
    sum_pairs,
)
from tiles.schema import Dimension


def _table(truth, pred):
    return contingency_table(*contingency_pairs(truth, pred))


@pytest.mark.parametrize("seed", range(5))
def test_ari_from_contingency_equals_sklearn_on_random_labelings(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(50, 3000))
    truth = rng.integers(0, int(rng.integers(1, 30)), n)
    pred = np.where(rng.random(n) < 0.7, truth * 3 + 1, rng.integers(0, 40, n))
    assert ari_from_contingency(_table(truth, pred)) == pytest.approx(adjusted_rand_score(truth, pred), abs=1e-12)
    dense = _table(truth, pred).toarray()
    assert ari_from_contingency(dense) == pytest.approx(adjusted_rand_score(truth, pred), abs=1e-12)


@pytest.mark.parametrize("truth,pred", [
    ([0, 0, 0, 0], [5, 5, 5, 5]),          # one cluster each
    ([0, 1, 2, 3], [0, 1, 2, 3]),          # all singletons, identical
    ([0, 1, 2, 3], [7, 7, 7, 7]),          # singletons vs one cluster
    ([0, 0, 0, 0], [0, 1, 2, 3]),          # one cluster vs singletons
    ([0, 0, 1, 1], [1, 1, 0, 0]),          # identical up to renaming
    ([0, 0, 1, 1], [0, 1, 0, 1]),          # discordant (negative)
    ([3], [9]),                            # one point
])
def test_degenerate_cases_match_sklearn(truth, pred):
    assert ari(np.array(truth), np.array(pred)) == adjusted_rand_score(truth, pred)


def test_empty_labelings_score_one_like_sklearn():
    assert ari(np.zeros(0, int), np.zeros(0, int)) == adjusted_rand_score([], []) == 1.0
    assert ari_from_contingency(np.zeros((0, 0))) == 1.0


def test_minus_one_rules():
    truth = np.array([0, 0, 1, 1, -1, -1])
    pred = np.array([0, 0, -1, -1, 0, 3])
    # truth -1 is left out; prediction -1 is one more cluster
    assert ari(truth, pred) == adjusted_rand_score([0, 0, 1, 1], [0, 0, -1, -1]) == 1.0
    assert ari(np.array([0, 0, 0, 1]), np.array([-1, -1, 0, 0])) == adjusted_rand_score([0, 0, 0, 1], [9, 9, 0, 0])


def test_summing_tables_equals_the_table_of_all_points():
    rng = np.random.default_rng(7)
    truth, pred = rng.integers(0, 6, 1000), rng.integers(0, 9, 1000)
    parts = [contingency_pairs(truth[a:b], pred[a:b]) for a, b in ((0, 100), (100, 650), (650, 1000))]
    pairs, counts = sum_pairs(parts)
    whole_pairs, whole_counts = contingency_pairs(truth, pred)
    np.testing.assert_array_equal(pairs, whole_pairs)
    np.testing.assert_array_equal(counts, whole_counts)


def test_distributed_ari_equals_sklearn_over_a_tile_store(tmp_path, client):
    from tests.engine.handmade import write_store

    rng = np.random.default_rng(3)
    n = 60_000
    xyz = rng.uniform([0, 0, 0], [35, 22, 3], (n, 3))
    truth = (xyz[:, 0] // 7).astype(np.int32) + 10 * (xyz[:, 1] // 11).astype(np.int32)
    truth[rng.random(n) < 0.02] = -1
    store = write_store(tmp_path / "s.zarr", xyz, truth)
    assert len(store.tiles) > 4
    # a prediction that is wrong in places, written per tile in the store's own point order
    store.add_dimensions([Dimension("space_id", "int32", "result")])
    all_truth, all_pred = [], []
    for t in store.tiles:
        g = store.read(t, ["gt_space"])["gt_space"]
        p = np.where(rng.random(len(g)) < 0.9, g // 2, rng.integers(-1, 5, len(g))).astype(np.int32)
        store.write_array(t, "space_id", p)
        all_truth.append(g)
        all_pred.append(p)
    g, p = np.concatenate(all_truth), np.concatenate(all_pred)
    keep = g >= 0
    expected = adjusted_rand_score(g[keep], p[keep])
    assert distributed_ari(store, client=client) == pytest.approx(expected, abs=1e-12)
    assert distributed_ari(store) == pytest.approx(expected, abs=1e-12)
