"""core.quadrics: plane quadrics, accumulation, batched optimal placement."""

import numpy as np
import pytest

from core.quadrics import (N_COEFFS, accumulate, edge_constraint_quadrics, face_quadrics, optimal_placement,
                           plane_quadrics, quadric_distance, quadric_error)
from tests.mesh_factory import cube, regular_grid


def random_planes(k, rng):
    n = rng.standard_normal((k, 3))
    n /= np.linalg.norm(n, axis=1)[:, None]
    return n, rng.standard_normal(k), rng.random(k) + 0.1


def test_plane_quadric_error_is_the_weighted_squared_distance():
    rng = np.random.default_rng(0)
    n, d, w = random_planes(50, rng)
    Q = plane_quadrics(n, d, w)
    assert Q.shape == (50, N_COEFFS)
    X = rng.standard_normal((50, 3))
    expected = w * (np.einsum("ij,ij->i", n, X) + d) ** 2
    np.testing.assert_allclose(quadric_error(Q, X), expected, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(Q[:, 10], w)
    # the distance form divides by the weight: back to |n.x + d|
    np.testing.assert_allclose(quadric_distance(Q, expected), np.abs(np.einsum("ij,ij->i", n, X) + d),
                               rtol=1e-12)


def test_accumulate_sums_quadrics_per_bin():
    rng = np.random.default_rng(1)
    Q = plane_quadrics(*random_planes(30, rng))
    idx = rng.integers(0, 7, size=30)
    out = accumulate(Q, idx, 7)
    ref = np.zeros((7, N_COEFFS))
    np.add.at(ref, idx, Q)
    np.testing.assert_allclose(out, ref, rtol=1e-12, atol=1e-14)
    # repeat=3: each item to three bins (faces to corners)
    F = rng.integers(0, 9, size=(30, 3))
    out3 = accumulate(Q, F.T.ravel(), 9, repeat=3)
    ref3 = np.zeros((9, N_COEFFS))
    for c in range(3):
        np.add.at(ref3, F[:, c], Q)
    np.testing.assert_allclose(out3, ref3, rtol=1e-12, atol=1e-14)


def test_face_quadrics_vanish_on_their_own_plane_and_weigh_by_area():
    V, F = regular_grid(4, 3, size=2.0)
    Q = face_quadrics(V, F)
    A = np.full(F.shape[0], 0.5 * (2.0 / 4) * (2.0 / 3))
    np.testing.assert_allclose(Q[:, 10], A)
    P = np.column_stack([np.random.default_rng(2).random((F.shape[0], 2)), np.zeros(F.shape[0])])
    np.testing.assert_allclose(quadric_error(Q, P), 0.0, atol=1e-15)
    P[:, 2] = 0.5
    np.testing.assert_allclose(quadric_error(Q, P), A * 0.25)
    # area_power 0: every plane weighs the mean area
    Q0, N = face_quadrics(V, F, area_power=0.0, return_normals=True)
    np.testing.assert_allclose(Q0[:, 10], A.mean())
    np.testing.assert_allclose(N, np.tile([0, 0, 1.0], (F.shape[0], 1)))


def test_edge_constraint_plane_contains_the_edge_and_the_normal():
    V = np.array([[0, 0, 0], [2, 0, 0], [0, 1, 0]], dtype=float)
    E = np.array([[0, 1]])
    Q = edge_constraint_quadrics(V, E, np.array([[0, 0, 1.0]]), np.array([3.0]))
    on_plane = np.array([[5.0, 0.0, 7.0]])         # anywhere in the x-z plane
    assert quadric_error(Q, on_plane)[0] == pytest.approx(0.0, abs=1e-15)
    assert quadric_error(Q, np.array([[1.0, 2.0, 0.0]]))[0] == pytest.approx(3.0 * 4.0)
    # a zero-length edge gives a zero quadric
    Z = edge_constraint_quadrics(V, np.array([[0, 0]]), np.array([[0, 0, 1.0]]), np.array([3.0]))
    assert not Z.any()


def test_optimal_placement_finds_the_corner_of_three_planes():
    rng = np.random.default_rng(3)
    k = 40
    corner = rng.standard_normal((k, 3))
    Q = np.zeros((k, N_COEFFS))
    for _ in range(3):
        n = rng.standard_normal((k, 3))
        n /= np.linalg.norm(n, axis=1)[:, None]
        Q += plane_quadrics(n, -np.einsum("ij,ij->i", n, corner), rng.random(k) + 0.5)
    P0 = corner + 0.3 * rng.standard_normal((k, 3))
    P1 = corner + 0.3 * rng.standard_normal((k, 3))
    X, err = optimal_placement(Q, P0, P1)
    ok = np.linalg.norm(X - corner, axis=1) < 1e-8
    # where the corner is not too far from the edge, it is found exactly
    near = np.linalg.norm(corner - 0.5 * (P0 + P1), axis=1) < 2.0 * np.linalg.norm(P1 - P0, axis=1)
    assert np.all(ok[near]) and near.sum() > k // 2
    np.testing.assert_allclose(err[near], 0.0, atol=1e-12)
    # never worse than either endpoint or the midpoint
    for P in (P0, P1, 0.5 * (P0 + P1)):
        assert np.all(err <= quadric_error(Q, P) + 1e-12)


def test_singular_quadrics_fall_back_to_the_best_point_of_the_edge():
    # one plane z = 0: any point of it is optimal; rank 1, so the 3x3 solve is refused
    Q = plane_quadrics(np.array([[0, 0, 1.0]] * 3), np.zeros(3), np.ones(3))
    P0 = np.array([[0, 0, 1.0], [0, 0, 2.0], [1, 1, 0.0]])
    P1 = np.array([[1, 0, -1.0], [1, 0, 3.0], [2, 1, 0.0]])
    X, err = optimal_placement(Q, P0, P1)
    # first edge crosses the plane at its midpoint; second stays above, best end z = 2
    np.testing.assert_allclose(X[0], [0.5, 0, 0], atol=1e-12)
    np.testing.assert_allclose(X[1], [0, 0, 2.0])
    np.testing.assert_allclose(err, [0.0, 4.0, 0.0], atol=1e-12)
    assert np.all(X[2, 2] == 0.0)


def test_placement_of_many_edges_is_each_edge_placed_alone():
    # a mix of well-posed (three planes), singular (one plane) and far-drifting
    # (nearly parallel planes) quadrics, more than two blocks of columns: the same
    # bits as one edge at a time, and never worse than either end
    import core.quadrics as quadrics
    rng = np.random.default_rng(7)
    k = 2 * quadrics._PLACE_BLOCK + 37
    Q = np.zeros((k, N_COEFFS))
    for j in range(3):
        n, d, w = random_planes(k, rng)
        if j:
            kind = rng.integers(0, 3, k)
            n[kind == 1] = [0.0, 0.0, 1.0]                                  # singular: one plane
            n[kind == 2] += 1e-9 * rng.standard_normal((int((kind == 2).sum()), 3))
        Q += plane_quadrics(n, d, w)
    P0 = rng.standard_normal((k, 3))
    P1 = P0 + 0.1 * rng.standard_normal((k, 3))
    X, err = optimal_placement(Q, P0, P1)
    alone = [optimal_placement(Q[i:i + 1], P0[i:i + 1], P1[i:i + 1]) for i in range(0, k, 97)]
    np.testing.assert_array_equal(X[::97], np.concatenate([x for x, _ in alone]))
    np.testing.assert_array_equal(err[::97], np.concatenate([e for _, e in alone]))
    for P in (P0, P1):
        assert np.all(err <= quadric_error(Q, P) + 1e-12)


def test_cube_corner_quadric_pins_the_corner():
    V, F = cube(2)
    Qf = face_quadrics(V, F)
    Q = accumulate(Qf, F.T.ravel(), V.shape[0], repeat=3)
    corner = int(np.flatnonzero(np.all(np.isclose(np.abs(V), 0.5), axis=1))[0])
    nb = int(F[np.any(F == corner, axis=1)][0][F[np.any(F == corner, axis=1)][0] != corner][0])
    X, err = optimal_placement((Q[corner] + Q[nb])[None], V[[corner]], V[[nb]])
    np.testing.assert_allclose(X[0], V[corner], atol=1e-12)
    assert err[0] == pytest.approx(0.0, abs=1e-14)


def test_scaling_the_mesh_scales_the_distance():
    rng = np.random.default_rng(4)
    V, F = regular_grid(3, 3, z=lambda x, y: 0.3 * x * y)
    X = rng.random((F.shape[0], 3))
    d1 = quadric_distance(face_quadrics(V, F), quadric_error(face_quadrics(V, F), X))
    s = 1234.5
    Qs = face_quadrics(V * s, F)
    ds = quadric_distance(Qs, quadric_error(Qs, X * s))
    np.testing.assert_allclose(ds, d1 * s, rtol=1e-9)


def test_vertex_face_quadrics_are_the_accumulated_face_quadrics_bit_for_bit():
    # the same operations in the same order as the (m,11) stack accumulated by bincount
    from core.quadrics import accumulate, face_quadrics, vertex_face_quadrics
    from core.mesh import face_normals
    from tests.mesh_factory import torus
    V, F = torus(30, 14, bump=0.05)
    F = np.concatenate([F, [[0, 1, 1]]])                  # a degenerate face: a zero quadric
    for p in (1.0, 0.5):
        QT, unit, N = vertex_face_quadrics(V, F, V.shape[0], p)
        ref = accumulate(face_quadrics(V, F, area_power=p), F.T.ravel(), V.shape[0], repeat=3)
        assert np.array_equal(QT.T, ref)
        assert np.array_equal(N, face_normals(V, F, normalize=False))
        assert np.array_equal(unit, face_quadrics(V, F, area_power=p, return_normals=True)[1])
