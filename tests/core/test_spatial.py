"""Tests of core/spatial.py: the point-triangle kernel and the exact nearest-triangle index."""

import warnings

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st, HealthCheck

import core.spatial as spatial
from core.errors import InvalidArgumentError, InvalidMeshError
from core.spatial import (KERNEL_BLOCK, ClosestPoints, TriangleIndex, closest_on_triangles,
                          closest_pairs, closest_points, point_triangle_closest, triangle_rows)
from tests.mesh_factory import (cad_cylinder, cube, fillet_cap, icosphere, load_shared, needle_cone,
                                midpoint_split, regular_grid, torus)


# --- references written independently of the module ---------------------------------------------

def _ref_segment(P, X, Y):
    e = Y - X
    ee = np.einsum("ij,ij->i", e, e)
    t = np.where(ee > 0, np.einsum("ij,ij->i", P - X, e) / np.where(ee > 0, ee, 1), 0.0)
    t = np.clip(t, 0, 1)
    return np.linalg.norm(P - (X + t[:, None] * e), axis=1)


def _ref_distance(P, A, B, C):
    """Distance by enumeration: the three edges and, if inside, the plane projection
    (solved with lstsq, a different route from the module's formulas)."""
    d = np.minimum(np.minimum(_ref_segment(P, A, B), _ref_segment(P, B, C)), _ref_segment(P, C, A))
    for k in range(P.shape[0]):
        M = np.stack([B[k] - A[k], C[k] - A[k]], axis=1)
        if np.linalg.matrix_rank(M, tol=1e-12 * max(np.abs(M).max(), 1e-300)) < 2:
            continue
        (v, w), *_ = np.linalg.lstsq(M, P[k] - A[k], rcond=None)
        if v >= 0 and w >= 0 and v + w <= 1:
            d[k] = min(d[k], np.linalg.norm(P[k] - (A[k] + M @ [v, w])))
    return d


def _brute(V, F, P):
    """Nearest distance over all triangles, with the module's own pair kernel."""
    q, m = P.shape[0], F.shape[0]
    qq = np.repeat(np.arange(q), m)
    tt = np.tile(np.arange(m), q)
    r = point_triangle_closest(P[qq], V[F[tt, 0]], V[F[tt, 1]], V[F[tt, 2]])
    return r.distance.reshape(q, m).min(axis=1)


def _check_result(V, F, P, r, rtol=1e-12):
    """Exact distance, consistent point / bary / distance."""
    assert isinstance(r, ClosestPoints)
    assert r.face.dtype == np.int64 and r.face.shape == (P.shape[0],)
    scale = max(float(np.abs(V).max()), 1.0)
    ref = _brute(V, F, P)
    np.testing.assert_allclose(r.distance, ref, rtol=rtol, atol=1e-14 * scale)
    assert (r.bary >= 0).all() and (r.bary <= 1).all()
    np.testing.assert_allclose(r.bary.sum(axis=1), 1.0, atol=1e-12)
    rec = np.einsum("ij,ijk->ik", r.bary, V[F[r.face]])
    np.testing.assert_allclose(rec, r.point, atol=1e-12 * scale)
    np.testing.assert_allclose(np.linalg.norm(P - r.point, axis=1), r.distance,
                               rtol=1e-12, atol=1e-14 * scale)


def _random_queries(V, rng, n=400):
    lo, hi = V.min(axis=0), V.max(axis=0)
    diag = np.linalg.norm(hi - lo)
    near = lo + rng.random((n, 3)) * (hi - lo)
    far = (lo + hi) / 2 + rng.normal(size=(n // 4, 3)) * 50 * diag
    return np.vstack([near, far])


# --- the pair kernel -----------------------------------------------------------------------------

def test_kernel_every_voronoi_region():
    A, B, C = np.array([0.0, 0, 0]), np.array([2.0, 0, 0]), np.array([0.0, 2, 0])
    cases = [  # point, expected closest point
        ([0.5, 0.5, 3.0], [0.5, 0.5, 0.0]),      # face
        ([-1.0, -1.0, 1.0], [0.0, 0.0, 0.0]),    # vertex A
        ([3.0, -1.0, 0.0], [2.0, 0.0, 0.0]),     # vertex B
        ([-1.0, 3.0, -2.0], [0.0, 2.0, 0.0]),    # vertex C
        ([1.0, -5.0, 0.0], [1.0, 0.0, 0.0]),     # edge AB
        ([-4.0, 1.5, 1.0], [0.0, 1.5, 0.0]),     # edge AC
        ([2.0, 2.0, 0.0], [1.0, 1.0, 0.0]),      # edge BC
    ]
    P = np.array([c[0] for c in cases])
    expect = np.array([c[1] for c in cases])
    k = len(cases)
    r = point_triangle_closest(P, np.tile(A, (k, 1)), np.tile(B, (k, 1)), np.tile(C, (k, 1)))
    np.testing.assert_allclose(r.point, expect, atol=1e-15)
    np.testing.assert_allclose(r.distance, np.linalg.norm(P - expect, axis=1), rtol=1e-15)
    np.testing.assert_allclose(r.bary @ np.stack([A, B, C]), expect, atol=1e-15)


def test_kernel_matches_independent_reference_on_random_triangles():
    rng = np.random.default_rng(7)
    k = 3000
    A, B, C = rng.normal(size=(3, k, 3))
    P = rng.normal(size=(k, 3)) * rng.choice([0.1, 1.0, 10.0, 1e4], size=(k, 1))
    r = point_triangle_closest(P, A, B, C)
    np.testing.assert_allclose(r.distance, _ref_distance(P, A, B, C), rtol=1e-10, atol=1e-13)
    assert (r.bary >= 0).all() and (r.bary <= 1).all()
    np.testing.assert_allclose(r.bary.sum(axis=1), 1.0, atol=1e-14)
    rec = r.bary[:, :1] * A + r.bary[:, 1:2] * B + r.bary[:, 2:] * C
    np.testing.assert_allclose(rec, r.point, atol=1e-12)


def test_kernel_ericson_and_robust_paths_agree():
    """The region classification and the robust (edges + projection) path are two exact
    methods; on well-shaped triangles they must give the same distances."""
    rng = np.random.default_rng(3)
    k = 20000
    A, B, C = rng.normal(size=(3, k, 3))
    P = rng.normal(size=(k, 3)) * 3
    D = spatial.triangle_rows(A, B, C)
    v, w, d2 = spatial.closest_on_triangles(P[:, 0].copy(), P[:, 1].copy(), P[:, 2].copy(), D)
    ap = P - A
    n = D[12:15].T
    h = np.einsum("ij,ij->i", ap, n)
    ap_in = ap - h[:, None] * n
    rv, rw, rd = spatial._robust_kernel(ap_in[:, 0], ap_in[:, 1], ap_in[:, 2], D)
    ok = D[15] == 0
    assert ok.mean() > 0.99
    np.testing.assert_allclose(np.sqrt(d2[ok]), np.sqrt(rd[ok] + h[ok] ** 2), rtol=1e-12)


@pytest.mark.parametrize("shape", ["point", "segment", "repeated_vertex", "needle", "flat_sliver"])
def test_kernel_degenerate_triangles(shape):
    rng = np.random.default_rng(11)
    k = 500
    X = rng.normal(size=(k, 3))
    Y = rng.normal(size=(k, 3))
    if shape == "point":
        A, B, C = X, X.copy(), X.copy()
    elif shape == "segment":       # three collinear points, the middle one inside
        A, B, C = X, Y, 0.3 * X + 0.7 * Y
    elif shape == "repeated_vertex":
        A, B, C = X, Y, Y.copy()
    elif shape == "needle":        # one tiny angle
        A, B, C = X, Y, Y + 1e-9 * rng.normal(size=(k, 3))
    else:                          # a long flat sliver: third vertex 1e-7 off the segment
        A, B, C = X, Y, 0.5 * (X + Y) + 1e-7 * rng.normal(size=(k, 3))
    P = rng.normal(size=(k, 3)) * 2
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        r = point_triangle_closest(P, A, B, C)
    assert np.isfinite(r.distance).all() and np.isfinite(r.bary).all()
    # slivers have an ill-conditioned plane: exact up to ~1e-8 of their size
    atol = 1e-8 if shape in ("needle", "flat_sliver") else 1e-12
    np.testing.assert_allclose(r.distance, _ref_distance(P, A, B, C), rtol=1e-12, atol=atol)
    np.testing.assert_allclose(r.bary.sum(axis=1), 1.0, atol=1e-12)
    rec = r.bary[:, :1] * A + r.bary[:, 1:2] * B + r.bary[:, 2:] * C
    np.testing.assert_allclose(rec, r.point, atol=1e-12)


def test_closest_pairs_in_blocks_is_the_kernel_on_every_pair():
    # more pairs than a block (the last block short), repeated points and triangles,
    # slivers among them: the same bits as one call of the kernel on all of them
    rng = np.random.default_rng(3)
    A, B, C = (rng.normal(size=(50, 3)) for _ in range(3))
    C[:5] = A[:5] + 1e-9 * (B[:5] - A[:5])                  # slivers (robust path)
    D = triangle_rows(A, B, C)
    PT = rng.normal(size=(3, 400))
    k = 3 * KERNEL_BLOCK + 17
    q, t = rng.integers(0, 400, k), rng.integers(0, 50, k)
    got = closest_pairs(PT, q, D, t)
    want = closest_on_triangles(PT[0, q], PT[1, q], PT[2, q], D[:, t])
    for g, w in zip(got, want):
        assert np.array_equal(g, w)
    small = closest_pairs(PT, q[:10], D, t[:10])
    assert all(np.array_equal(g, w[:10]) for g, w in zip(small, want))


def test_kernel_bad_input():
    z = np.zeros((2, 3))
    with pytest.raises(InvalidArgumentError, match=r"point_triangle_closest: P must be \(k,3\)"):
        point_triangle_closest(np.zeros((2, 2)), z, z, z)
    with pytest.raises(InvalidArgumentError, match="same number of rows"):
        point_triangle_closest(np.zeros((3, 3)), z, z, z)
    bad = z.copy()
    bad[1, 2] = np.nan
    with pytest.raises(InvalidArgumentError, match=r"1 rows of B have NaN or infinite values, e.g. row 1 = \[0.0, 0.0, nan\]"):
        point_triangle_closest(z, z, bad, z)


# --- the index -----------------------------------------------------------------------------------

def _meshes():
    rng = np.random.default_rng(5)
    V, F = icosphere(2)
    yield "icosphere", V, F
    V, F = torus(24, 12)
    yield "torus", V + 0.01 * rng.normal(size=V.shape), F
    yield "grid", *regular_grid(12, 9, z=lambda x, y: 0.2 * np.sin(4 * x) * y)
    yield "cube", *cube(3)
    # a random triangle soup with very different sizes
    Vs = rng.normal(size=(300, 3)) * rng.choice([0.01, 0.1, 1.0], size=(300, 1))
    yield "soup", Vs, rng.integers(0, 300, size=(100, 3))


@pytest.mark.parametrize("name,V,F", list(_meshes()), ids=[m[0] for m in _meshes()])
def test_index_matches_brute_force(name, V, F):
    rng = np.random.default_rng(1)
    P = _random_queries(V, rng)
    edge_pts = 0.37 * V[F[:50, 0]] + 0.63 * V[F[:50, 1]]
    P = np.vstack([P, V[F[:60].ravel()], edge_pts])
    r = TriangleIndex(V, F).closest(P)
    _check_result(V, F, P, r)
    # points on vertices and edges of the mesh are at distance zero
    on = r.distance[-(180 + edge_pts.shape[0]):]
    scale = float(np.abs(V).max())
    assert (on <= 1e-15 * scale).all()


@pytest.mark.parametrize("name,V,F", list(_meshes())[:3], ids=[m[0] for m in _meshes()][:3])
def test_index_bvh_path_matches_brute_force(monkeypatch, name, V, F):
    """Every query that leaves its cell goes through the BVH (no scan-all shortcut)."""
    monkeypatch.setattr(spatial, "_MAX_PHASE2_CELLS", 1)
    monkeypatch.setattr(spatial, "_BRUTE_PAIRS", 0)
    P = _random_queries(V, np.random.default_rng(6), 300)
    _check_result(V, F, P, TriangleIndex(V, F).closest(P))


@pytest.mark.parametrize("brute_pairs", [0, spatial._BRUTE_PAIRS], ids=["bvh", "scan-all"])
def test_index_far_queries_and_equidistant_centre(monkeypatch, brute_pairs):
    monkeypatch.setattr(spatial, "_BRUTE_PAIRS", brute_pairs)
    V, F = icosphere(3)
    rng = np.random.default_rng(2)
    dirs = rng.normal(size=(200, 3))
    dirs /= np.linalg.norm(dirs, axis=1)[:, None]
    P = np.vstack([dirs * 1e3, dirs * 7.0, np.zeros((1, 3))])   # the centre: every face ties
    r = TriangleIndex(V, F).closest(P)
    _check_result(V, F, P, r)


def test_index_small_chunks_and_frontier_splits(monkeypatch):
    """Force every chunking / splitting / fallback path with tiny limits."""
    monkeypatch.setattr(spatial, "_PAIR_CHUNK", 64)
    monkeypatch.setattr(spatial, "_QUERY_CHUNK", 32)
    monkeypatch.setattr(spatial, "_FRONTIER_CAP", 16)
    monkeypatch.setattr(spatial, "_MAX_PHASE2_CELLS", 2)
    monkeypatch.setattr(spatial, "_BRUTE_PAIRS", 0)
    V, F = torus(20, 10)
    rng = np.random.default_rng(4)
    P = _random_queries(V, rng, 300)
    _check_result(V, F, P, TriangleIndex(V, F).closest(P))


def test_index_degenerate_meshes():
    rng = np.random.default_rng(8)
    # every triangle degenerate (points and segments), plus one normal triangle
    V = rng.normal(size=(30, 3))
    F = np.array([[0, 0, 0], [1, 2, 2], [3, 4, 5], [6, 6, 7]] + [[8, 9, 10]], dtype=np.int64)
    V[5] = 0.5 * (V[3] + V[4])                       # collinear
    P = _random_queries(V, rng, 200)
    _check_result(V, F, P, TriangleIndex(V, F).closest(P))
    # all the vertices at one point
    V1 = np.zeros((3, 3)) + 2.0
    r = TriangleIndex(V1, [[0, 1, 2]]).closest([[2.0, 2.0, 3.0]])
    assert r.distance[0] == 1.0 and r.point.tolist() == [[2.0, 2.0, 2.0]]


def test_index_single_triangle_and_duplicates():
    V = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]])
    F = np.array([[0, 1, 2], [0, 1, 2], [2, 1, 0]])
    P = np.random.default_rng(0).normal(size=(100, 3))
    _check_result(V, F, P, TriangleIndex(V, F).closest(P))


@pytest.mark.parametrize("copies", [100, 1000])
def test_index_of_a_mesh_with_many_copies_of_a_face_answers_as_without_them(copies):
    """More than _MAX_SAME_CODE copies of a face in one Morton cell are indexed
    once (the build used to size its tables for every face and fail: a scan
    with duplicated faces reached it through closest_points / surface_distance)."""
    V, F = icosphere(3)
    F2 = np.vstack([F, np.repeat(F[:1], copies, axis=0), np.repeat(F[5:6, ::-1], copies, axis=0)])
    assert copies > spatial._MAX_SAME_CODE
    P = np.random.default_rng(2).normal(size=(500, 3))
    index = TriangleIndex(V, F2)
    assert index.n_faces == F.shape[0]              # (a reversed copy is the same geometry)
    got, ref = index.closest(P), TriangleIndex(V, F).closest(P)
    np.testing.assert_array_equal(got.distance, ref.distance)
    np.testing.assert_array_equal(got.point, ref.point)
    np.testing.assert_array_equal(np.sort(V[F2[got.face]], axis=1), np.sort(V[F[ref.face]], axis=1))
    _check_result(V, F2, P, got)


@pytest.mark.parametrize("k", [60, 300])
def test_a_cluster_of_needles_does_not_set_the_cells_and_answers_exactly(k):
    """A degenerate cluster: the ``k`` vertices nearest one vertex moved to
    random points of a segment across the sphere, their faces needles along
    it. The cells stay those of the mesh's own triangles (the needles made
    them 4x wider, every query near them scanning hundreds), each needle is
    referenced only in the cells along its line, and the answers are exact."""
    W, F, a, b, needle = _collapsed_onto_a_segment(k)
    rng = np.random.default_rng(0)
    rng.random(k)
    index, others = TriangleIndex(W, F), TriangleIndex(W, np.delete(F, needle, axis=0))
    assert index._h <= 1.25 * others._h
    refs = np.bincount(index._order[index._cell_tri], minlength=F.shape[0])
    cells_along = np.ceil(np.abs(b - a).max() / index._h) + 1
    assert refs[needle].max() <= 27 * cells_along          # a tube of cells, not the box
    P = np.vstack([_random_queries(W, rng, 300), a + rng.random((100, 1)) * (b - a) + 1e-3])
    _check_result(W, F, P, index.closest(P))


def _collapsed_onto_a_segment(k, seed=0):
    """An icosphere whose ``k`` vertices nearest one vertex were moved to
    random points of a segment across it (a region a scanner collapsed onto
    a line): (W, F, the segment's ends, the needle faces)."""
    V, F = icosphere(4)
    rng = np.random.default_rng(seed)
    near = np.argsort(np.linalg.norm(V - V[0], axis=1))[:k]
    a, b = np.array([-0.9, -0.3, 0.1]), np.array([0.8, 0.4, -0.2])
    W = V.copy()
    W[near] = a + rng.random(k)[:, None] * (b - a)
    return W, F, a, b, np.flatnonzero(np.isin(F, near).all(axis=1))


def test_needles_inside_others_are_not_indexed_and_answers_stay_exact():
    """Of needles along one line only those not inside another are indexed
    (the rest are within rounding of them): 300 vertices on a segment make
    about 560 needles, of which a few span the others; queries on the line
    meet those few, and every answer is exact."""
    W, F, a, b, needle = _collapsed_onto_a_segment(300)
    index = TriangleIndex(W, F)
    kept = np.zeros(F.shape[0], dtype=bool)
    kept[index._order] = True
    assert kept[np.setdiff1d(np.arange(F.shape[0]), needle)].all()
    assert needle.size > 500 and np.count_nonzero(kept[needle]) <= 20
    # every dropped needle lies inside a kept one
    seg = lambda f: np.sort(((W[F[f]] - a) @ (b - a)) / ((b - a) @ (b - a)), axis=1)[:, [0, 2]]
    inner, outer = seg(needle[~kept[needle]]), seg(needle[kept[needle]])
    inside = (outer[None, :, 0] <= inner[:, None, 0] + 1e-12) & (inner[:, None, 1] <= outer[None, :, 1] + 1e-12)
    assert inside.any(axis=1).all()
    rng = np.random.default_rng(5)
    P = np.vstack([_random_queries(W, rng, 300), a + rng.random((300, 1)) * (b - a)
                   + 1e-3 * rng.standard_normal((300, 3))])
    _check_result(W, F, P, index.closest(P))


def test_a_needle_with_no_height_is_found_in_every_cell_it_crosses():
    """One exactly flat needle across a sphere, its normal all rounding: the
    plane test that picks a triangle's cells must not trust that normal
    (it left the needle out of most cells along it, and queries next to the
    needle got a face 3x farther)."""
    W, F, a, b, needle = _collapsed_onto_a_segment(60)
    span = np.ptp(((W[F[needle]] - a) @ (b - a)), axis=1)
    F1 = np.delete(F, np.delete(needle, np.argmax(span)), axis=0)    # the longest needle only
    rng = np.random.default_rng(6)
    P = a + rng.random((400, 1)) * (b - a) + 1e-3 * rng.standard_normal((400, 3))
    _check_result(W, F1, P, TriangleIndex(W, F1).closest(P))


def test_index_far_from_origin_and_unit_invariance():
    V, F = torus(16, 8)
    rng = np.random.default_rng(9)
    P = _random_queries(V, rng, 200)
    base = TriangleIndex(V, F).closest(P).distance
    for scale, shift in ((1e-3, 0.0), (1e4, 0.0), (1.0, 1e6)):
        r = TriangleIndex(V * scale + shift, F).closest(P * scale + shift)
        np.testing.assert_allclose(r.distance, base * scale, rtol=1e-9,
                                   atol=1e-15 * (scale + shift))
    _check_result(V * 1e-3, F, P * 1e-3, TriangleIndex(V * 1e-3, F).closest(P * 1e-3))
    # the same cells at any scale, the CAD cylinder's (sized by its triangles' area) too: at
    # 1e-200 the areas had underflowed and the cells were a sixteenth of the size
    for Vm, Fm in ((V, F), cad_cylinder(400)):
        h = TriangleIndex(Vm, Fm)._h
        for scale in (1e-200, 1e-3, 1e4, 1e50):
            assert np.isclose(TriangleIndex(Vm * scale, Fm)._h, h * scale, rtol=1e-9)


def test_index_exact_on_sphere_analytic():
    V, F = icosphere(4)
    rng = np.random.default_rng(12)
    d = rng.normal(size=(2000, 3))
    d /= np.linalg.norm(d, axis=1)[:, None]
    P = d * rng.uniform(0.2, 3.0, size=(2000, 1))
    r = closest_points(V, F, P)
    # an inscribed polyhedron: distance within the sagitta of the analytic |1 - |p||
    sag = 1 - np.cos(0.5 * np.max(np.linalg.norm(V[F[:, 0]] - V[F[:, 1]], axis=1)))
    assert np.all(np.abs(r.distance - np.abs(1 - np.linalg.norm(P, axis=1))) <= 2 * sag)


def test_index_does_not_modify_inputs():
    V, F = icosphere(1)
    P = np.random.default_rng(0).normal(size=(50, 3))
    V0, F0, P0 = V.copy(), F.copy(), P.copy()
    index = TriangleIndex(V, F)
    index.closest(P)
    V[:] = 0.0                                # the index keeps its own copy
    assert (index.closest(P0).distance > 0).any()
    assert (F == F0).all() and (P == P0).all()
    V = V0


def test_index_empty_and_bad_input():
    with pytest.raises(InvalidMeshError, match="TriangleIndex: the mesh has no faces"):
        TriangleIndex(np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64))
    with pytest.raises(InvalidMeshError, match="TriangleIndex: the mesh has no faces"):
        TriangleIndex(np.eye(3), np.zeros((0, 3), dtype=np.int64))
    with pytest.raises(InvalidMeshError, match=r"F must be \(m,3\) integers"):
        TriangleIndex(np.eye(3), np.zeros((1, 3)))
    index = TriangleIndex(np.eye(3), [[0, 1, 2]])
    with pytest.raises(InvalidArgumentError, match=r"TriangleIndex.closest: P must be \(q,3\)"):
        index.closest(np.zeros((4, 2)))
    with pytest.raises(InvalidArgumentError, match="NaN or infinite"):
        index.closest([[0.0, np.inf, 0.0]])
    r = index.closest(np.zeros((0, 3)))
    assert r.face.shape == (0,) and r.point.shape == (0, 3) and r.bary.shape == (0, 3)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.integers(0, 2**32 - 1), st.integers(1, 40), st.sampled_from([1e-3, 1.0, 1e3]))
def test_index_property_random_soups(seed, m, scale):
    rng = np.random.default_rng(seed)
    n = rng.integers(3, 3 * m + 3)
    V = rng.normal(size=(n, 3)) * scale
    if rng.random() < 0.3:                     # snap to a coarse lattice: ties, degeneracies
        V = np.round(V / scale * 2) * scale / 2
    F = rng.integers(0, n, size=(m, 3))
    P = np.vstack([rng.normal(size=(60, 3)) * scale * rng.choice([0.5, 2, 100]),
                   V[F[:5].ravel()]])
    _check_result(V, F, P, TriangleIndex(V, F).closest(P))


def test_index_real_mesh_bunny():
    V, F = load_shared("stanford-bunny.obj")
    rng = np.random.default_rng(0)
    used = np.unique(F)
    diag = np.linalg.norm(V[used].max(0) - V[used].min(0))
    P = V[used[rng.choice(used.size, 300, replace=False)]] + rng.normal(size=(300, 3)) * 0.01 * diag
    r = TriangleIndex(V, F).closest(P)
    # brute force on a few (all 69k triangles per query)
    ref = _brute(V, F, P[:12])
    np.testing.assert_allclose(r.distance[:12], ref, rtol=1e-12, atol=1e-15 * diag)
    assert (r.bary >= 0).all()
    np.testing.assert_allclose(np.einsum("ij,ijk->ik", r.bary, V[F[r.face]]), r.point,
                               atol=1e-12 * diag)


def test_bvh_bounds_contain_their_triangles(monkeypatch):
    """Internal invariant of the far-query path: every node's box and cylinder contain
    every vertex of the triangles below it (and the BVH is built lazily, once)."""
    monkeypatch.setattr(spatial, "_MAX_PHASE2_CELLS", 1)
    monkeypatch.setattr(spatial, "_BRUTE_PAIRS", 0)
    V, F = torus(30, 12)
    V = V + 0.02 * np.random.default_rng(0).normal(size=V.shape)
    index = TriangleIndex(V, F)
    assert index._bvh is None
    index.closest([[0.0, 0.0, 50.0]])                 # far: builds the BVH
    assert index._bvh is not None
    X = V[F[index._order]]                              # (m, 3, 3) in internal order
    for level in range(index._depth + 1):
        group = spatial._LEAF << (index._depth - level)
        box, slab = index._bvh[level], index._slab[level]
        for node in range(box.shape[1]):
            pts = X[node * group:(node + 1) * group].reshape(-1, 3)
            if pts.size == 0:
                continue
            assert (pts >= box[0:3, node]).all() and (pts <= box[3:6, node]).all()
            rel = pts - slab[0:3, node]
            h = rel @ slab[3:6, node]
            lat = np.sqrt(np.maximum(np.einsum("ij,ij->i", rel, rel) - h * h, 0))
            assert (np.abs(h) <= slab[7, node]).all() and (lat <= slab[6, node]).all()
            rod = index._rod.get(level)
            if rod is not None:                         # the lowest levels' rods too
                assert (_segment_distance(pts, rod[0:3, node], rod[3:6, node]) <= rod[6, node]).all()


def test_index_reuse_gives_identical_results():
    V, F = icosphere(3)
    P = np.random.default_rng(1).normal(size=(500, 3)) * 3
    index = TriangleIndex(V, F)
    a = index.closest(P)
    b = index.closest(P[::-1])
    assert (a.distance == b.distance[::-1]).all() and (a.face == b.face[::-1]).all()


def test_far_queries_from_many_threads_build_the_hierarchy_once_and_agree(monkeypatch):
    # the BVH is built lazily on the first far query; queries from worker threads
    # (as bind runs them) may arrive together: every thread gets the exact answer
    from concurrent.futures import ThreadPoolExecutor
    monkeypatch.setattr(spatial, "_BRUTE_PAIRS", 0)      # every far query takes the BVH
    V, F = icosphere(5)
    rng = np.random.default_rng(7)
    P = rng.standard_normal((4000, 3)) * 5.0          # far from the sphere: the BVH path
    expect = TriangleIndex(V, F).closest(P).distance
    for _ in range(5):
        index = TriangleIndex(V, F)
        with ThreadPoolExecutor(8) as pool:
            parts = list(pool.map(lambda s: index.closest(P[s:s + 500]).distance,
                                  range(0, P.shape[0], 500)))
        assert np.array_equal(np.concatenate(parts), expect)


def _lower_bound_cases(rng):
    """Triangles of every kind (regular, slivers, needles, segments, points) and
    points near them, on them and far away."""
    k = 200
    A = rng.normal(size=(k, 3)) * 10
    B = A + rng.normal(size=(k, 3))
    C = A + rng.normal(size=(k, 3))
    C[:40] = A[:40] + (B[:40] - A[:40]) * rng.random((40, 1)) + 1e-7 * rng.normal(size=(40, 3))
    C[40:60] = B[40:60]                                   # segments
    B[60:70] = C[60:70] = A[60:70]                        # points
    V = np.concatenate([A, B, C]) + 1e3                   # off the origin
    F = np.arange(3 * k).reshape(3, k).T
    P = np.concatenate([V + rng.normal(size=V.shape) * 0.01, V,
                        rng.normal(size=(300, 3)) * 30 + 1e3])
    return V, F, P


def test_the_pair_filters_never_exceed_the_exact_distance():
    """The sphere, bounding-disk and edge-line bounds the index filters pairs
    with are below the kernel's own squared distance (what a pair is pruned
    against), on every (point, triangle) pair, slivers and degenerate ones included."""
    V, F, P = _lower_bound_cases(np.random.default_rng(3))
    index = TriangleIndex(V, F)
    m = index.n_faces
    q = np.repeat(np.arange(P.shape[0]), m)
    t = np.tile(np.arange(m), P.shape[0])
    PT = np.ascontiguousarray(P.T)
    _, _, d2 = index._eval(PT, q, t)
    S = index._ball[:, t]
    X = PT[:, q] - S[:3]
    dc2 = (X * X).sum(axis=0)
    ok = d2 * (1 + spatial.PRUNE_SLACK)
    sphere = np.maximum(np.sqrt(dc2) - S[3], 0.0) ** 2
    assert (sphere <= ok * (1 + 4 * spatial.PRUNE_SLACK)).all()
    assert (index._disk_bound(X, t, dc2, S[3]) <= ok).all()
    assert (index._prism_bound(X, t, dc2) <= ok).all()
    # and the edge-line bound is tight where it matters: a point above the middle
    # of a regular triangle is bounded by its height exactly
    regular = np.flatnonzero(index._order >= 70)           # internal ids of faces 70..
    above = (index._ball[:3, regular] + 0.5 * index._prism[0:3, regular])
    lb = index._prism_bound(above - index._ball[:3, regular], regular, np.full(regular.size, 0.25))
    np.testing.assert_allclose(lb, 0.25, rtol=1e-7)    # less the 1e-12-of-size allowance


@pytest.mark.parametrize("factor", [0.4, 1.5, 4.0])
def test_index_any_cell_factor_is_exact(factor):
    V, F = torus(24, 12)
    V = V + 0.01 * np.random.default_rng(11).normal(size=V.shape)
    P = _random_queries(V, np.random.default_rng(12), 300)
    _check_result(V, F, P, TriangleIndex(V, F, cell_factor=factor).closest(P))
    default = TriangleIndex(V, F).closest(P)
    same = TriangleIndex(V, F, cell_factor=1.5).closest(P)
    assert all(np.array_equal(a, b) for a, b in zip(default, same))
    with pytest.raises(InvalidArgumentError, match=r"cell_factor must be a number in \[0.0015, 1500\]"):
        TriangleIndex(V, F, cell_factor=0)
    wide = TriangleIndex(V, F, cell_factor=factor, min_cell=0.5)
    assert wide.tables.cell_size >= 0.5
    _check_result(V, F, P, wide.closest(P))
    for bad in (0, -1.0, np.inf, "1"):
        with pytest.raises(InvalidArgumentError, match=r"min_cell \(or None\) must be a number > 0"):
            TriangleIndex(V, F, min_cell=bad)


def test_long_thin_triangles_are_searched_through_the_hierarchy(monkeypatch):
    """A CAD cylinder (side triangles 1,600 times longer than wide, fans of
    needles): every grid cell holds hundreds of them, so queries go to the
    BVH, whose probe finds a tight first bound. Exact, and each query looks
    at a few hundred triangles (the grid made each look at its whole cell:
    3,000 here; 64k faces took 2 ms a query)."""
    V, F = cad_cylinder(1000)
    rng = np.random.default_rng(11)
    P = V[rng.integers(0, V.shape[0], 300)] + 0.01 * rng.standard_normal((300, 3))
    P[:100, 2] = rng.uniform(0.0, 10.0, 100)          # beside the sides, anywhere along them
    index = TriangleIndex(V, F)
    assert np.diff(index.tables.cell_start).max() > index.crowded_cell
    pairs = []
    scan = TriangleIndex._scan
    monkeypatch.setattr(TriangleIndex, "_scan",
                        lambda self, PT, q, *a, **k: (pairs.append(q.size), scan(self, PT, q, *a, **k))[1])
    _check_result(V, F, P, index.closest(P))
    assert sum(pairs) / P.shape[0] < 300


def _segment_distance(P, start, edge):
    """Distances of the points ``P`` (k,3) to the segment ``start + s edge``, s in [0, 1]."""
    s = np.clip((P - start) @ edge / max(float(edge @ edge), 1e-300), 0.0, 1.0)
    return np.linalg.norm(P - start - s[:, None] * edge, axis=1)


def _exact_pairs_per_query(monkeypatch, index, V, F, P):
    """The (point, triangle) pairs ``index`` evaluates exactly per point of
    ``P``, its answers checked against brute force."""
    pairs = []
    ev = TriangleIndex._eval
    monkeypatch.setattr(TriangleIndex, "_eval",
                        lambda self, PT, q, t: (pairs.append(q.size), ev(self, PT, q, t))[1])
    _check_result(V, F, P, index.closest(P))
    return sum(pairs) / P.shape[0]


def test_a_fan_of_needles_is_searched_by_its_needles_not_their_boxes(monkeypatch):
    """A filleted box's end cap (a fan of 1,000 needles from one corner, each
    one's box as wide as the cap; the fillet's 100-long strips): the BVH's
    lowest nodes are rods around their needles and each needle's distance is
    bounded by its distance to its longest edge, so a query near the cap
    evaluates a few of them exactly, not the whole fan: these queries 106
    pairs each, 848 before (the 300 by the cap 72, 1,017 before), and the
    answers stay exact. The rods hold every corner below them."""
    monkeypatch.setattr(spatial, "_BRUTE_PAIRS", 0)
    V, F = fillet_cap()
    rng = np.random.default_rng(12)
    P = np.c_[np.full(300, 100.0) + rng.normal(0, 1.0, 300), rng.uniform(1, 99, (300, 2))]
    P = np.vstack([P, V[rng.integers(0, V.shape[0], 100)] + rng.normal(0, 0.5, (100, 3))])
    index = TriangleIndex(V, F)
    assert index._capsule_at is not None and (index._capsule_at >= 0).sum() >= 2000
    assert _exact_pairs_per_query(monkeypatch, index, V, F, P) < 200
    for level, rod in index._rod.items():
        group = spatial._LEAF << (index._depth - level)
        X = V[F[index._order]]
        for node in range(0, rod.shape[1], 7):
            pts = X[node * group:(node + 1) * group].reshape(-1, 3)
            if pts.size:
                assert (_segment_distance(pts, rod[0:3, node], rod[3:6, node]) <= rod[6, node]).all()


def test_queries_in_crowded_cells_probe_from_their_own_small_groups():
    """Points a hair inside the flat base of a cone of 4,000 needles, those
    in crowded cells: a probe from the centre of a cube of 8 cells
    led each member to the needles at the centre's angle (median bound
    0.146 for true distances of 1e-4) and the descent then kept every leaf
    within it; probed in groups of half a cell, 0.015, and the answers are
    the brute-force ones (a 20k-face cone's simplify to 200 faces: 17.5 ->
    4 s)."""
    V, F = needle_cone(4000)
    rng = np.random.default_rng(3)
    r, a = rng.uniform(0.1, 0.5, 300), rng.uniform(0, 2 * np.pi, 300)
    P = np.c_[r * np.cos(a), r * np.sin(a), np.full(300, 1e-4)]
    index = TriangleIndex(V, F)
    cell = np.clip(np.floor((P - index._lo) / index._h), 0, index._dims - 1).astype(np.int64)
    dims = index._dims
    crowded, _, _ = index.split_crowded(cell[:, 0] + dims[0] * (cell[:, 1] + dims[1] * cell[:, 2]))
    assert crowded.size > 100                  # (about half: the cells near the hub)
    _check_result(V, F, P, index.closest(P))
    PT, q = np.ascontiguousarray(P[crowded].T), np.arange(crowded.size)
    bound = []
    for first in (0, q.size):                 # none, all probed as crowded
        best = spatial.BestPairs(q.size)
        index._probe_groups(PT, q, best, crowded=first)
        bound.append(float(np.median(np.sqrt(best.d2))))
    assert bound[0] > 8 * bound[1] and bound[0] > 0.1


def test_queries_beside_a_fillets_strips_evaluate_a_few_of_them(monkeypatch):
    """Points on a filleted box near its fillet, a row of 2,500 strips 100
    long (what a fit of its cage asks: the fine vertices, on the box's big
    faces and across the fillet): every strip passes the bound the probe of
    the nearest centroid gives, and a probe beam of 4 boxes missed the big
    face a point lies on (112 of 464 of a fit's points started 49 units
    off), so these points evaluated 3,070 pairs each (a fit of the 10k-face
    fillet's cage took 16 s CPU). Such a probe (beyond 4x the box distance of
    the leaves it reached and 1% of the diagonal) is made again with a beam of
    16, and past 8 pairs a query the pair of smallest bound goes first: 11
    pairs a query, the same answers."""
    monkeypatch.setattr(spatial, "_BRUTE_PAIRS", 0)
    V, F = fillet_cap(2500)
    rng = np.random.default_rng(5)
    a = rng.uniform(0, np.pi / 2, 200)
    on_fillet = np.c_[rng.uniform(10, 90, 200), 95 + 5 * np.cos(a), 95 + 5 * np.sin(a)]
    on_faces = np.c_[rng.uniform(10, 90, 200), np.full(200, 100.0), rng.uniform(90, 95, 200)]
    P = np.vstack([on_fillet, on_faces]) + rng.normal(0, 1e-4, (400, 3))
    index = TriangleIndex(V, F)
    assert _exact_pairs_per_query(monkeypatch, index, V, F, P) < 30


@pytest.mark.parametrize("name,V,F", list(_meshes())[:3], ids=[m[0] for m in _meshes()][:3])
def test_crowded_cells_path_matches_brute_force(monkeypatch, name, V, F):
    """Every query counted as in a crowded cell: the BVH with its probe alone is exact."""
    monkeypatch.setattr(spatial, "CROWDED_CELL", -1)
    P = _random_queries(V, np.random.default_rng(7), 300)
    _check_result(V, F, P, TriangleIndex(V, F).closest(P))


def _slab_cells_by_box(nrm, off, reach, c0, nr, lo, h):
    """Every cell of each box, kept when its centre is within ``reach`` of the plane."""
    out = []
    for t in range(nrm.shape[0]):
        g = np.stack(np.meshgrid(*[np.arange(c0[t, a], c0[t, a] + nr[t, a]) for a in range(3)],
                                 indexing="ij"), axis=-1).reshape(-1, 3)
        x = lo + h * (g + 0.5)
        keep = np.abs(x @ nrm[t] - off[t]) <= reach[t]
        out += [(t, *c) for c in g[keep]]
    return sorted(out)


def test_slab_cells_are_the_box_cells_the_plane_crosses():
    """The column enumeration gives exactly the cells of the box whose centre
    is within reach of the plane (the test it replaced, cell by cell over the
    whole box), for tilted, axis-aligned and normal-less triangles."""
    rng = np.random.default_rng(12)
    k = 40
    nrm = rng.normal(size=(k, 3))
    nrm[:5] = [[0, 0, 1.0]] * 5                      # axis-aligned
    nrm[5:8] = 0.0                                   # no normal: the whole box
    nrm[8:12, 0] = 0.0                               # along an axis
    c0 = rng.integers(0, 5, size=(k, 3))
    nr = rng.integers(1, 9, size=(k, 3))
    lo, h = np.array([-1.0, 0.5, 2.0]), 0.7
    centre = lo + h * (c0 + nr / 2.0)
    off = np.einsum("ij,ij->i", nrm, centre + rng.normal(scale=h, size=(k, 3)))
    reach = 0.5 * h * np.abs(nrm).sum(axis=1) + 1e-9
    tri, cells = spatial._slab_cells(nrm, off, reach, c0, nr, lo, h)
    got = sorted((int(t), *map(int, c)) for t, c in zip(tri, cells))
    assert got == _slab_cells_by_box(nrm, off, reach, c0, nr, lo, h)


def test_the_grid_references_are_the_same_a_run_of_triangles_at_a_time(monkeypatch):
    """Blocks whose boxes hold many cells are cut into runs (_CANDIDATE_CELLS):
    the same tables, bit for bit (a scan spike's long faces, a cylinder)."""
    V, F = icosphere(3)
    V = V.copy()
    V[0] *= 300                                       # a spike: five faces across the grid
    Vc, Fc = cad_cylinder(300)
    for mesh in ((V, F), (Vc, Fc)):
        whole = TriangleIndex(*mesh).tables
        monkeypatch.setattr(spatial, "_CANDIDATE_CELLS", 64)
        runs = TriangleIndex(*mesh).tables
        monkeypatch.undo()
        assert np.array_equal(whole.cell_start, runs.cell_start)
        assert np.array_equal(whole.cell_tri, runs.cell_tri)


def _needle_soup(n, seed):
    """``n`` separate needles (height 1e-4 of their length) in every direction,
    a fifth of them along an axis."""
    rng = np.random.default_rng(seed)
    A = rng.uniform(-1, 1, (n, 3))
    D = rng.normal(size=(n, 3))
    D[: n // 5, 1:] = 0.0
    D[n // 5: n // 5 + 3] = [[0, 1, 0], [0, 0, 1], [0, 0, -1]]
    D /= np.linalg.norm(D, axis=1)[:, None]
    L = rng.uniform(0.2, 1.5, n)[:, None]
    C = A + 0.5 * L * D + 1e-4 * L * np.cross(D, rng.normal(size=(n, 3)))
    return np.concatenate([A, A + L * D, C]), np.arange(3 * n).reshape(3, n).T.copy()


@pytest.mark.parametrize("mesh", ["cone", "soup", "far rotated cylinder"])
def test_a_needles_columns_hold_every_cell_the_box_would_give_it(monkeypatch, mesh):
    """A needle's columns are enumerated along its longest edge only
    (_line_columns), not over its whole box: the same grid, bit for bit, as
    the whole box's columns give, from far fewer candidates (the cells
    _near_needle keeps lie within its reach of the edge, and so do their
    columns' centres, seen along the column)."""
    if mesh == "cone":
        V, F = needle_cone(3000)
    elif mesh == "soup":
        V, F = _needle_soup(2000, 4)
    else:
        V, F = cad_cylinder(1500)
        Q, _ = np.linalg.qr(np.random.default_rng(2).normal(size=(3, 3)))
        V = V @ Q.T + 1e3
    seen = []
    slab = spatial._slab_cells

    def counted(*args):
        out = slab(*args)
        seen.append(out[0].size)
        return out

    monkeypatch.setattr(spatial, "_slab_cells", counted)
    lines = TriangleIndex(V, F).tables
    n_lines = sum(seen)
    seen.clear()
    monkeypatch.setattr(spatial, "_needle_reach", lambda needles, *a: spatial._NeedleReach(
        np.zeros_like(needles.is_needle), needles.P, needles.U, needles.height))
    boxes = TriangleIndex(V, F).tables
    assert np.array_equal(lines.cell_start, boxes.cell_start)
    assert np.array_equal(lines.cell_tri, boxes.cell_tri)
    assert n_lines < 0.8 * sum(seen)


def test_far_queries_spread_around_a_mesh_keep_their_memory_bounded():
    """5,000 points spread over twice the box of a 40k-face torus (nearly all on
    the far path: the BVH, searched by groups of nearby queries). A group's
    members are each scanned against every leaf the group reached: groups as
    wide as the points' distance held dozens, and took 975 MiB here (100k points
    near a 160k-face torus: 20 GiB). The answers are the one-by-one search's."""
    import tracemalloc
    V, F = torus(50, 25)
    for _ in range(2):
        V, F = midpoint_split(V, F)
    rng = np.random.default_rng(1)
    lo, hi = V.min(axis=0), V.max(axis=0)
    P = 0.5 * (lo + hi) + (rng.random((5000, 3)) - 0.5) * 2 * (hi - lo)
    index = TriangleIndex(V, F)
    index.closest(P[:100])                          # (the hierarchy built outside the count)
    tracemalloc.start()
    try:
        hit = index.closest(P)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 250 * 2**20
    some = rng.choice(P.shape[0], 40, replace=False)
    d2 = ((V[F].mean(axis=1)[None] - P[some, None]) ** 2).sum(axis=2)    # centroids lie on
    assert (hit.distance[some] <= np.sqrt(d2.min(axis=1)) + 1e-12).all()  # the mesh
    one = [TriangleIndex(V, F).closest(P[[i]]).distance[0] for i in some[:5]]   # (scans all)
    np.testing.assert_array_equal(hit.distance[some[:5]], one)


def test_points_inside_a_filleted_corner_go_to_the_hierarchy_and_scan_few_leaves(monkeypatch):
    # a CAD filleted box corner (end caps fans of needles, the fillet strips) and points a
    # few percent of its size inside it, where the Loop surface of its cage lies: the grid's
    # cells within their distance reference thousands of triangles (each needle crosses
    # many), so they go to the hierarchy, which scans their leaves nearest first in rounds;
    # exact against brute force, and a bound on the pairs scanned (16k a point in the grid,
    # about 1,150 in one round of the hierarchy's leaves, as measured on 2026-12-07)
    V, F = fillet_cap(400)
    rng = np.random.default_rng(11)
    P = np.vstack([rng.uniform(3.0, 40.0, (300, 3)),                  # inside, near the caps
                   [95.0, 90.0, 90.0] + rng.normal(scale=2.0, size=(100, 3))])  # the fillet
    pairs = []
    scan = spatial.TriangleIndex._scan

    def counting(self, PT, q, t, best, *args, **kw):
        pairs.append(q.size)
        return scan(self, PT, q, t, best, *args, **kw)
    monkeypatch.setattr(spatial.TriangleIndex, "_scan", counting)
    index = TriangleIndex(V, F, min_cell=8.0)
    r = index.closest(P)
    _check_result(V, F, P, r)
    assert sum(pairs) < 0.25 * P.shape[0] * F.shape[0]
    # the same answers with the grid scanning every reference (no routing by references)
    # and with a single round of leaves (every leaf within the first leaf's distance)
    monkeypatch.setattr(spatial, "_PHASE2_CROWDED", np.inf)
    monkeypatch.setattr(spatial, "_LEAF_ROUNDS", (1, np.inf))
    monkeypatch.setattr(spatial.TriangleIndex, "_scan", scan)
    again = TriangleIndex(V, F, min_cell=8.0).closest(P)
    assert np.array_equal(again.distance, r.distance)
