"""The SVM primitives: each window's own block of the design, and what each window's own weights can separate."""
from __future__ import annotations

import numpy as np

from engine.training.svm import _atom_design, fit_svm


def test_atom_design_puts_each_row_in_its_windows_block():
    x = np.arange(12, dtype=np.float64).reshape(4, 3) + 1
    atom = np.array([7, -1, 3, 7])
    ids = np.array([3, 7])
    dense = _atom_design(x, atom, ids, 2.0).toarray()
    assert dense.shape == (4, 3 + 2 * 4)
    np.testing.assert_array_equal(dense[:, :3], x)
    np.testing.assert_array_equal(dense[0, 3:], [0, 0, 0, 0, *(2 * x[0]), 2])  # atom 7: second block
    np.testing.assert_array_equal(dense[1, 3:], 0)  # no window: shared part only
    np.testing.assert_array_equal(dense[2, 3:], [*(2 * x[2]), 2, 0, 0, 0, 0])


def test_windows_own_weights_separate_what_shared_weights_cannot():
    """Two windows of one class whose positives lie on opposite sides of a feature: one shared linear SVM
    cannot rank both, the class's SVM with each window's own part does."""
    rng = np.random.default_rng(0)
    n = 200
    f = rng.uniform(0.2, 1.0, n)
    x = np.column_stack([np.concatenate([f, -f, -f, f]), rng.normal(size=(4 * n, 2))])
    # atom 0: positives f > 0, negatives f < 0; atom 5: the other way round
    pos = np.concatenate([x[:n], x[n:2 * n]])
    neg = np.concatenate([x[2 * n:3 * n], x[3 * n:]])
    pos_atom = np.repeat([0, 5], n)
    neg_atom = np.repeat([0, 5], n)
    mask = np.ones(3, dtype=bool)
    shared = fit_svm(pos, neg, mask, 1.0, 0)
    s_pos, s_neg = pos @ shared.weights + shared.bias, neg @ shared.weights + shared.bias
    assert np.mean(s_pos > 0) + np.mean(s_neg < 0) < 1.3  # about chance
    fit = fit_svm(pos, neg, mask, 1.0, 0, (pos_atom, neg_atom))
    assert set(fit.atom_weights) == {0, 5}

    def score(v, a):
        return v @ (fit.weights + fit.atom_weights[a]) + fit.bias + fit.atom_bias[a]

    assert np.all(score(pos[:n], 0) > 0) and np.all(score(neg[:n], 0) < 0)
    assert np.all(score(pos[n:], 5) > 0) and np.all(score(neg[n:], 5) < 0)
