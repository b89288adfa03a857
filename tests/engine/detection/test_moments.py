"""Voxel moments: the flat voxel index and order, and the closed-form smallest eigenpair against LAPACK."""
from __future__ import annotations

import numpy as np
import pytest

import engine.detection.moments as mom


def _sym(rng, lam: np.ndarray) -> np.ndarray:
    """Symmetric matrices ``(n, 3, 3)`` with eigenvalues ``lam`` ``(n, 3)`` in random orthonormal frames."""
    q = np.linalg.qr(rng.normal(size=(len(lam), 3, 3)))[0]
    a = np.einsum("nij,nj,nkj->nik", q, lam, q)
    return (a + np.swapaxes(a, 1, 2)) / 2.0  # exactly symmetric, as covariances from moments are


def _check_against_eigh(cov: np.ndarray, vec_tol: float = 1e-9) -> None:
    lam, total, vec = mom.smallest_eigen(cov)
    w, v = np.linalg.eigh(cov)
    w = np.maximum(w, 0.0)
    scale = np.maximum(w[:, 2], 1e-300)
    assert np.all(np.abs(lam - w[:, 0]) <= 1e-12 * scale)
    assert np.all(np.abs(total - w.sum(axis=1)) <= 1e-12 * scale)
    assert np.allclose(np.linalg.norm(vec, axis=1), 1.0, atol=1e-12)
    # the same vector up to its sign (features take absolute values)
    assert np.all(np.abs(np.abs(vec) - np.abs(v[:, :, 0])) <= vec_tol)
    # and an eigenvector of the smallest eigenvalue
    res = np.einsum("nij,nj->ni", cov, vec) - lam[:, None] * vec
    assert np.all(np.linalg.norm(res, axis=1) <= 1e-9 * scale)


@pytest.mark.parametrize("kind", ["random", "planar", "disc", "near-gap", "tiny-scale"])
def test_closed_form_smallest_eigen_equals_eigh(kind):
    rng = np.random.default_rng(["random", "planar", "disc", "near-gap", "tiny-scale"].index(kind))
    n = 4000
    lam = rng.uniform(0, 1, (n, 3)) ** 2
    if kind == "planar":  # a surface: one eigenvalue zero or at scan-noise level
        lam[:, 0] = np.where(rng.random(n) < 0.5, 0.0, rng.uniform(0, 1e-6, n))
    elif kind == "disc":  # a square patch: the two largest equal, the smallest well apart
        lam[:, 1] = lam[:, 2] * (1 + rng.uniform(0, 1e-9, n))
        lam[:, 0] = lam[:, 2] * rng.uniform(0, 0.5, n)
    elif kind == "near-gap":  # the two smallest 1e-3 .. 1e-2 of the largest apart: still well determined
        lam[:, 2] = 1.0
        lam[:, 1] = lam[:, 0] + rng.uniform(1e-3, 1e-2, n)
    elif kind == "tiny-scale":  # sub-boxes of a few millimetres
        lam *= 1e-8
    cov = _sym(rng, lam)
    _check_against_eigh(cov, vec_tol=1e-9 if kind != "near-gap" else 1e-7)


def test_closed_form_is_used_where_the_eigenvector_is_determined(monkeypatch):
    rng = np.random.default_rng(5)
    cov = _sym(rng, rng.uniform(0.1, 1, (500, 3)))
    asked = []
    real = np.linalg.eigh

    def spy(a):
        asked.append(len(a))
        return real(a)

    monkeypatch.setattr(mom.np.linalg, "eigh", spy)
    mom.smallest_eigen(cov)
    assert sum(asked) == 0


def test_undetermined_eigenvectors_are_lapacks_choice():
    rng = np.random.default_rng(6)
    n = 300
    lam = np.zeros((n, 3))
    lam[:100] = [0.0, 0.0, 0.7]  # a line: the two smallest equal
    lam[100:200] = [0.3, 0.3, 0.3]  # a ball
    lam[200:] = np.array([0.2, 0.2 * (1 + 1e-7), 0.9])  # the two smallest nearly equal
    cov = _sym(rng, lam)
    cov[:10] = 0.0  # empty
    lam_c, total_c, vec_c = mom.smallest_eigen(cov)
    w, v = np.linalg.eigh(cov)
    w = np.maximum(w, 0.0)
    assert np.array_equal(lam_c, w[:, 0]) and np.array_equal(total_c, w.sum(axis=1))
    assert np.array_equal(vec_c, v[:, :, 0])


def test_smallest_eigen_reads_the_lower_triangle_and_keeps_leading_shape():
    rng = np.random.default_rng(7)
    cov = _sym(rng, rng.uniform(0.1, 1, (24, 3))).reshape(2, 3, 4, 3, 3)
    skew = cov.copy()
    skew[..., 0, 1] += 5.0  # eigh reads only the lower triangle; so does the closed form
    a, b = mom.smallest_eigen(cov), mom.smallest_eigen(skew)
    assert a[0].shape == (2, 3, 4) and a[2].shape == (2, 3, 4, 3)
    for x, y in zip(a, b):
        assert np.array_equal(x, y)


def test_covariance_six_matches_the_matrix():
    rng = np.random.default_rng(8)
    m = rng.normal(size=(50, 13))
    m[:, 0] = rng.integers(0, 6, 50)
    six = mom.covariance_six(m)
    full = mom.covariance(m)
    assert np.array_equal(six, full[:, [0, 0, 0, 1, 1, 2], [0, 1, 2, 1, 2, 2]])
    assert np.all(six[m[:, 0] < 2] == 0)


def test_flat_index_is_the_raveled_voxel_index():
    rng = np.random.default_rng(9)
    grid = mom.VoxelGrid.covering([3.1, 2.0, 2.7], 0.1, 10**6)
    xyz = rng.uniform(-0.5, 3.5, (20000, 3))  # also outside the grid: clipped into its border voxels
    xyz[:100] = np.round(xyz[:100] / grid.voxel) * grid.voxel  # on voxel faces
    want = np.ravel_multi_index(tuple(grid.index(xyz).T), grid.shape)
    assert np.array_equal(grid.flat_index(xyz), want)


@pytest.mark.parametrize("n_cells", [1, 50, 1 << 16, (1 << 16) + 1, 3_000_000, 1 << 40])
def test_voxel_order_is_the_stable_argsort(n_cells):
    rng = np.random.default_rng(n_cells % 1000)
    flat = rng.integers(0, n_cells, 50000)
    flat[::7] = flat[0]  # many ties: the order among them must be kept
    assert np.array_equal(mom.voxel_order(flat, n_cells), np.argsort(flat, kind="stable"))


def test_voxel_moments_with_a_given_index_and_without_colours():
    rng = np.random.default_rng(10)
    grid = mom.VoxelGrid.covering([2.0, 1.0, 1.5], 0.1, 10**6)
    xyz = rng.uniform(0, [2.0, 1.0, 1.5], (5000, 3))
    rgb = rng.uniform(0, 1, (5000, 3))
    m = mom.voxel_moments(xyz, rgb, grid)
    assert np.array_equal(m, mom.voxel_moments(xyz, rgb, grid, flat=grid.flat_index(xyz)))
    bare = mom.voxel_moments(xyz, None, grid)
    assert np.array_equal(bare[..., :10], m[..., :10]) and np.all(bare[..., 10:] == 0)
    # one voxel by hand
    idx = grid.index(xyz)
    sel = np.all(idx == idx[0], axis=1)
    p = xyz[sel] - grid.center
    want = [sel.sum(), *p.sum(0), *(p[:, a] * p[:, b] for a, b in mom._PAIRS), *rgb[sel].sum(0)]
    want = [float(np.sum(w)) for w in want]
    assert np.allclose(m[tuple(idx[0])], want, rtol=1e-12, atol=1e-12)


def test_column_bounds_are_numpys_min_and_max():
    rng = np.random.default_rng(5)
    for pts in (rng.normal(size=(1001, 3)), rng.normal(size=(1, 3)), np.asfortranarray(rng.normal(size=(50, 2)))):
        lo, hi = mom.column_bounds(pts)
        np.testing.assert_array_equal(lo, pts.min(axis=0))
        np.testing.assert_array_equal(hi, pts.max(axis=0))
