"""core.mesh.barycentric_gather / barycentric_scatter: the one barycentric
operator the fit and the relocation use."""

import numpy as np

from core.mesh import barycentric_gather, barycentric_scatter


def random_rows(rng, s=500, n=80):
    corners = rng.integers(0, n, size=(s, 3))
    bary = rng.random((s, 3))
    bary /= bary.sum(axis=1, keepdims=True)
    return corners, bary, n


def test_gather_and_scatter_are_adjoint():
    rng = np.random.default_rng(0)
    corners, bary, n = random_rows(rng)
    X = rng.standard_normal((n, 3))
    R = rng.standard_normal((corners.shape[0], 3))
    lhs = np.sum(barycentric_gather(X, corners, bary) * R)
    rhs = np.sum(X * barycentric_scatter(R, corners, bary, n))
    assert abs(lhs - rhs) <= 1e-12 * max(abs(lhs), 1.0)


def test_unit_weights_pick_the_corner_and_transposed_arrays_give_the_same():
    rng = np.random.default_rng(1)
    corners, _, n = random_rows(rng)
    X = rng.standard_normal((n, 3))
    one = np.zeros(corners.shape, dtype=np.float64)
    one[:, 1] = 1.0
    assert np.array_equal(barycentric_gather(X, corners, one), X[corners[:, 1]])
    corners, bary, n = random_rows(rng)
    a = barycentric_gather(X, corners, bary)
    b = barycentric_gather(X, np.ascontiguousarray(corners.T).T, np.ascontiguousarray(bary.T).T)
    assert np.array_equal(a, b)
    # scatter of ones counts each vertex's total weight
    w = barycentric_scatter(np.ones((corners.shape[0], 1)), corners, bary, n)[:, 0]
    expect = np.bincount(corners.ravel(), weights=bary.ravel(), minlength=n)
    np.testing.assert_allclose(w, expect, rtol=1e-12, atol=1e-12)
    assert abs(w.sum() - corners.shape[0]) < 1e-9
