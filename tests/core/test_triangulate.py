"""core.triangulate: polygons to triangles (the fan, ear-clipped where it folds)."""

import numpy as np
import pytest

from core.triangulate import triangulate_polygons


def fan(k):
    """(k-2,3) the fan of a k-gon from its first vertex."""
    return np.stack([np.zeros(k - 2, dtype=np.int64), np.arange(1, k - 1), np.arange(2, k)], axis=1)


def fans(loops):
    """``(F, sizes)``: the fans of the polygons ``loops`` (vertex index
    lists), one after another, and their sizes (the input of
    :func:`triangulate_polygons`)."""
    F = np.concatenate([np.asarray(loop, dtype=np.int64)[fan(len(loop))] for loop in loops])
    return F, np.array([len(loop) for loop in loops], dtype=np.int64)


def in_3d(P, seed=5):
    """The 2D points ``P`` (k,2) rotated into 3D and moved away from the origin."""
    Q = np.linalg.qr(np.random.default_rng(seed).normal(size=(3, 3)))[0]
    return np.c_[P, np.zeros(len(P))] @ Q.T + [30.0, -20.0, 70.0]


def every_loop(k):
    """The 2k loops of a k-gon: from every first vertex, both windings."""
    return [np.roll(np.arange(k)[::w], -s) for w in (1, -1) for s in range(k)]


def _assert_tiles(X, T):
    """The triangles ``T`` (k-2,3) of the planar polygon ``X`` (k,3) cover it
    exactly once: each faces the polygon's way (Newell's normal), their areas
    add up to the polygon's, and each polygon edge is a triangle edge once
    (the others come in opposite pairs, the diagonals)."""
    k = len(X)
    n = np.cross(X[T[:, 1]] - X[T[:, 0]], X[T[:, 2]] - X[T[:, 0]])
    D = X - X[0]
    N = np.cross(D, np.roll(D, -1, axis=0)).sum(axis=0)
    assert T.shape == (k - 2, 3) and (n @ N > 1e-6 * (N @ N)).all()
    assert np.isclose(np.linalg.norm(n, axis=1).sum(), np.linalg.norm(N), rtol=1e-12)
    edges = {(int(a), int(b)) for t in T for a, b in zip(t, np.roll(t, -1))}
    assert len(edges) == 3 * (k - 2)                             # (no edge twice the same way)
    assert all((i, (i + 1) % k) in edges for i in range(k))
    assert all((b, a) in edges for a, b in edges if (b - a) % k not in (1, k - 1))


_t = np.arange(10) * np.pi / 5
#: concave polygons (2D), whose fan folds from some first vertices
CONCAVE = {
    "L": [(0, 0), (2, 0), (2, 1), (1, 1), (1, 2), (0, 2)],
    "arrow": [(0, 0), (2, 1), (0, 2), (0.5, 1)],
    "star": (np.c_[np.cos(_t), np.sin(_t)]
             * np.where(np.arange(10) % 2, 0.4, 1.0)[:, None]).tolist(),
    "comb": [(0, 0), (9, 0)] + [p for i in range(4, -1, -1) for p in
                                [(2 * i + 2, 1), (2 * i + 1, 1), (2 * i + 1, 5), (2 * i, 5)]],
}


@pytest.mark.parametrize("name", sorted(CONCAVE))
def test_concave_polygons_are_tiled_from_every_first_vertex_and_both_windings(name):
    """A concave polygon was fanned from its first vertex into overlapping,
    flipped triangles; it is ear-clipped, from every first vertex and both
    windings, in 3D (all 2k loops in one call)."""
    X = in_3d(np.array(CONCAVE[name], dtype=np.float64))
    k = len(X)
    loops = every_loop(k)
    F, sizes = fans(loops)
    T = triangulate_polygons(X, F, sizes)
    assert T.dtype == np.int64 and T.shape == F.shape
    folded = 0
    for j, loop in enumerate(loops):
        local = np.argsort(loop)[T[j * (k - 2):(j + 1) * (k - 2)]]     # (positions in this loop)
        _assert_tiles(X[loop], local)
        folded += not np.array_equal(local, fan(k))
    assert folded > 0


def test_a_fan_that_does_not_fold_is_kept():
    """Convex polygons, and a concave one seen whole from its first vertex,
    keep their fan (the triangles they had), also with collinear vertices
    rotated into 3D (a few 1e-16 off their line)."""
    hexagon = np.c_[np.cos(np.arange(6)), np.sin(np.arange(6))]
    shapes = [hexagon, np.array(CONCAVE["L"], dtype=np.float64)[[3, 4, 5, 0, 1, 2]],
              np.array([(0, 0), (1, 0), (2, 0), (3, 0), (3, 1), (0, 1)], dtype=np.float64),
              np.array([(0, 0), (0, 0), (1, 0), (1, 1), (0, 1)], dtype=np.float64)]
    for P in shapes:
        k = len(P)
        F = fan(k)
        T = triangulate_polygons(in_3d(P), F, np.array([k]))
        assert T is F and np.array_equal(F, fan(k))          # (the fans themselves, untouched)


def test_triangles_and_polygons_of_several_sizes_in_one_call():
    """Triangles and polygons of several sizes, mixed: each polygon's rows
    are what it gets alone, the triangles' rows are kept, and the input is
    not modified."""
    L = np.array(CONCAVE["L"], dtype=np.float64)
    arrow = np.array(CONCAVE["arrow"], dtype=np.float64)
    X = np.concatenate([in_3d(L), in_3d(arrow, seed=2)])
    loops = [[0, 1, 2], [3, 4, 5, 0], [6, 7, 8, 9], [1, 2, 3, 4, 5, 0], [9, 6, 7], [2, 3, 4, 5, 0, 1]]
    F, sizes = fans(loops)
    before = F.copy()
    T = triangulate_polygons(X, F, sizes)
    assert np.array_equal(F, before) and T.shape == F.shape
    first = np.cumsum(sizes - 2) - (sizes - 2)
    for loop, at in zip(loops, first):
        alone = triangulate_polygons(X, *fans([loop]))
        assert np.array_equal(T[at:at + len(loop) - 2], alone)
    triangles = first[sizes == 3]
    assert triangles.size == 2 and np.array_equal(T[triangles], F[triangles])
    assert not np.array_equal(T, F)                          # (the L from 1 folds)


def test_random_star_shaped_polygons_are_tiled():
    """300 random star-shaped polygons of each size 4..16 (simple, mostly
    concave), rotated into 3D, triangulated in one call."""
    rng = np.random.default_rng(11)
    q = 300
    for k in range(4, 17):
        angle = (np.arange(k) + rng.uniform(0, 1, size=(q, k))) * 2 * np.pi / k   # (gaps < pi)
        radius = rng.uniform(0.2, 1.0, size=(q, k))
        P = np.stack([radius * np.cos(angle), radius * np.sin(angle)], axis=2)
        X = np.concatenate([in_3d(p, seed=j) for j, p in enumerate(P)])
        F = (np.arange(q)[:, None, None] * k + fan(k)).reshape(-1, 3)
        T = triangulate_polygons(X, F, np.full(q, k)).reshape(q, k - 2, 3)
        for j in range(q):
            _assert_tiles(X[j * k:(j + 1) * k], T[j] - j * k)
        assert (T != F.reshape(q, k - 2, 3)).any(axis=(1, 2)).sum() > 10     # (folded fans)


@pytest.mark.parametrize("P", [
    [(0, 0), (1, 1), (1, 0), (0, 1)],                                   # a bow tie
    [(np.cos(a), np.sin(a)) for a in np.arange(5) * 4 * np.pi / 5],     # a pentagram
    [(0, 0), (1, 0), (2, 0), (3, 0)],                                   # no area
    [(0, 0), (2, 0), (2, 2), (1, 1), (1, 1), (0, 2)],                   # a repeated corner
    [(0, 0), (2, 0), (1, 1), (2, 2), (0, 2), (1, 1)],                   # touching itself
])
def test_polygons_without_a_clean_triangulation_still_give_k_minus_2_triangles(P):
    P = np.array(P, dtype=np.float64)
    k = len(P)
    T = triangulate_polygons(in_3d(P), fan(k), np.array([k]))
    assert T.shape == (k - 2, 3) and T.dtype == np.int64
    assert set(T.ravel().tolist()) <= set(range(k)) and (np.diff(np.sort(T, axis=1)) > 0).all()


def test_the_docstring_example():
    V = np.array([[1, 0, 0], [.25, .25, 0], [0, 1, 0], [0, 0, 0.]])
    T = triangulate_polygons(V, np.array([[0, 1, 2], [0, 2, 3]]), np.array([4]))
    assert T.tolist() == [[3, 0, 1], [1, 2, 3]]
