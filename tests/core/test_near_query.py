"""Tests of core/near_query.py: NearQuery returns the exact closest point,
bit for bit the brute-force minimum over every triangle (ties to the lowest
face index), whatever the block size, point order or thread."""

from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

import core.near_query as near_query
import core.spatial as spatial
from core.errors import InvalidArgumentError, InvalidMeshError
from core.near_query import NearQuery, search_for
from core.spatial import closest_pairs, triangle_rows
from core.subdivide import subdivision_operator
from tests.mesh_factory import (cad_cylinder, cube, icosphere, load_shared, regular_grid,
                                shared_mesh_names, torus)


def _brute(V, F, P, faces=None):
    """Per point: the smallest squared distance the kernel gives over every
    triangle (or over ``faces``), the lowest face index among equal ones,
    and that face's (v, w)."""
    faces = np.arange(F.shape[0]) if faces is None else np.sort(faces)
    D = triangle_rows(V[F[faces, 0]], V[F[faces, 1]], V[F[faces, 2]])
    q, m = P.shape[0], faces.shape[0]
    qq = np.repeat(np.arange(q), m)
    tt = np.tile(np.arange(m), q)
    v, w, d2 = closest_pairs(np.ascontiguousarray(P.T), qq, D, tt)   # (the kernel, in blocks)
    d2 = d2.reshape(q, m)
    first = np.argmin(d2, axis=1)                 # the first (lowest face) among equal minima
    k = np.arange(q) * m + first
    return faces[first], v[k], w[k], d2[np.arange(q), first]


def _assert_exact(V, F, P, r, faces=None):
    face, v, w, d2 = _brute(V, F, P, faces)
    assert r.face.dtype == np.int64 and r.face.shape == (P.shape[0],)
    np.testing.assert_array_equal(r.face, face)
    np.testing.assert_array_equal(r.bary[:, 1], np.clip(v, 0, 1))
    np.testing.assert_array_equal(r.bary[:, 2], np.clip(w, 0, 1))
    np.testing.assert_array_equal(r.distance, np.sqrt(d2))


def _near_points(V, F, rng, n=600, spread=(0.0, 0.05, 0.3)):
    """Points on and around the surface: vertices, edge and face points, and
    those moved by a fraction ``spread`` of the mean edge length."""
    E = V[F[:, [1, 2, 0]]] - V[F]
    edge = float(np.linalg.norm(E, axis=2).mean())
    f = rng.integers(0, F.shape[0], n)
    b = rng.random((n, 3))
    b[: n // 4, 0] = 0                                  # on edges
    b /= b.sum(axis=1, keepdims=True)
    P = np.einsum("ij,ijk->ik", b, V[F[f]])
    P += rng.normal(size=P.shape) * edge * rng.choice(spread, size=(n, 1))
    return np.vstack([P, V[F[:40].ravel()]])


def _meshes():
    rng = np.random.default_rng(5)
    V, F = icosphere(3)
    yield "icosphere", V, F
    V, F = torus(40, 16)
    yield "bumpy torus", V + 0.004 * rng.normal(size=V.shape), F
    yield "open grid", *regular_grid(20, 14, z=lambda x, y: 0.2 * np.sin(4 * x) * y)
    yield "cube", *cube(4)                                   # flat faces: exact ties
    Vc, Fc = torus(12, 6)
    op = subdivision_operator(Fc, Vc.shape[0], levels=2, scheme="butterfly")
    yield "subdivided cage", op.apply(Vc), op.F_fine            # what bind queries
    Vs = rng.normal(size=(400, 3)) * rng.choice([0.01, 0.1, 1.0], size=(400, 1))
    yield "soup", Vs, rng.integers(0, 400, size=(150, 3))


@pytest.mark.parametrize("name,V,F", list(_meshes()), ids=[m[0] for m in _meshes()])
def test_equals_the_brute_force_minimum_bit_for_bit(name, V, F):
    P = _near_points(V, F, np.random.default_rng(1))
    _assert_exact(V, F, P, NearQuery(V, F).closest(P))


@pytest.mark.parametrize("name,V,F", list(_meshes())[:4], ids=[m[0] for m in _meshes()][:4])
def test_same_answer_for_any_block_size_order_and_thread(monkeypatch, name, V, F):
    P = _near_points(V, F, np.random.default_rng(2))
    query = NearQuery(V, F)
    ref = query.closest(P)
    for block in (7, 64):
        monkeypatch.setattr(near_query, "_BLOCK", block)
        r = query.closest(P)
        for a, b in zip(r, ref):
            np.testing.assert_array_equal(a, b)
    perm = np.random.default_rng(3).permutation(P.shape[0])
    r = query.closest(P[perm])
    for a, b in zip(r, ref):
        np.testing.assert_array_equal(a, b[perm])
    monkeypatch.setattr(near_query, "_BLOCK", 50)
    with ThreadPoolExecutor(4) as pool:
        parts = list(pool.map(lambda s: query.closest(P[s:s + 100]), range(0, P.shape[0], 100)))
    for k in range(4):
        np.testing.assert_array_equal(np.concatenate([p[k] for p in parts]), ref[k])


def _needled_sphere(rng):
    """A sphere crossed by 40 needles (a pinched scan's cage): past a needle's
    tip the edge-line bound stays near 0, so a point's smallest bound can be
    a needle far from it."""
    V, F = icosphere(3)
    a, b = rng.integers(0, V.shape[0], (2, 40))
    tip = V[a] + 1e-3 * rng.normal(size=(40, 3))
    Vn = np.vstack([V, tip])
    Fn = np.vstack([F, np.stack([a, b, V.shape[0] + np.arange(40)], axis=1)])
    return Vn, Fn, _near_points(Vn, F, rng, n=3000, spread=(0.0, 0.05))


def _spy(monkeypatch, names):
    """Count the calls of the module's functions ``names`` and the number of
    (point, triangle) pairs the exact kernel evaluates."""
    calls = dict.fromkeys(names, 0)
    calls["pairs"] = 0
    for name in names + ["_kernel"]:
        real = getattr(near_query, name)

        def spy(*args, _real=real, _name=name):
            if _name == "_kernel":
                calls["pairs"] += args[2].shape[0]
            else:
                calls[_name] += 1
            return _real(*args)
        monkeypatch.setattr(near_query, name, spy)
    return calls


def test_loose_probes_past_sliver_tips_take_the_index_bound(monkeypatch):
    # points whose probe was a needle far from them get their ball from the index's
    # exact distance: a few pairs a point (24 a point when the needle's distance was
    # the ball), and still the brute-force minimum, bit for bit
    Vn, Fn, P = _needled_sphere(np.random.default_rng(4))
    loose = []
    real = near_query._loose_probes
    monkeypatch.setattr(near_query, "_loose_probes",
                        lambda *a: loose.append(real(*a)) or loose[-1])
    calls = _spy(monkeypatch, [])
    _assert_exact(Vn, Fn, P, NearQuery(Vn, Fn).closest(P))
    assert sum(int(m.sum()) for m in loose) > P.shape[0] // 2
    assert calls["pairs"] < 10 * P.shape[0]


def test_crowded_points_and_split_blocks_answer_exactly(monkeypatch):
    # the crowded points try the nearest centroid next, and blocks with many pairs a
    # point are answered in halves (made to happen here by lowering the thresholds)
    Vn, Fn, P = _needled_sphere(np.random.default_rng(4))
    monkeypatch.setattr(near_query, "_CROWDED_BLOCK", 1)
    monkeypatch.setattr(near_query, "_MIN_BLOCK", 256)
    monkeypatch.setattr(near_query, "_CROWDED", 2)
    calls = _spy(monkeypatch, ["_block", "_crowded_next"])
    asked = []                          # the loose probes whose distance the index is asked for
    real = near_query._loose_reach

    def loose_reach(index, B, loose, known):
        rows = B.q[loose]
        asked.append(rows if known is None else rows[np.isnan(known[rows])])
        return real(index, B, loose, known)
    monkeypatch.setattr(near_query, "_loose_reach", loose_reach)
    _assert_exact(Vn, Fn, P, NearQuery(Vn, Fn).closest(P))
    assert calls["_block"] > 1 and calls["_crowded_next"] >= 1
    # a loose probe's exact distance is asked for once, not again in each half of its block
    rows = np.concatenate(asked)
    assert rows.size > 0 and np.unique(rows).size == rows.size


def test_needles_are_pruned_by_their_capsules(monkeypatch):
    """A CAD cylinder's sides (triangles 1,600 times longer than wide) and cap
    fans are thin: no plane, so their float32 tile bound is 0 wherever the
    point is. Their pairs' bounds are raised to the index's capsule bound
    (the distance to the longest edge less the height) before any is
    evaluated: 15,496 exact pairs here instead of 1,205,779 (every cell
    answered by the tiles), and the same distances."""
    monkeypatch.setattr(near_query, "_INDEX_CELL", 10**6)  # (every cell answered here, none by the index)
    monkeypatch.setattr(near_query, "_NEEDLES_PER_FACE", np.inf)   # (tiles, not the needles' index)
    V, F = cad_cylinder(400)
    rng = np.random.default_rng(13)
    P = V[rng.integers(0, V.shape[0], 1500)] + 0.02 * rng.standard_normal((1500, 3))
    P[:500, 2] = rng.uniform(0.0, 10.0, 500)          # beside the sides, anywhere along them
    _, _, _, d2 = _brute(V, F, P)
    counts = []
    for raise_them in (True, False):
        if not raise_them:
            monkeypatch.setattr(near_query, "_raise_for_needles", lambda *a: None)
        calls = _spy(monkeypatch, [])
        r = NearQuery(V, F).closest(P)
        # (the crowded cells' points are the index's: among equidistant faces, its pick)
        np.testing.assert_array_equal(r.distance, np.sqrt(d2))
        counts.append(calls["pairs"])
    assert counts[0] < 0.1 * counts[1]


def test_agrees_with_the_index_up_to_exact_ties():
    V, F = torus(60, 24)
    V = V + 0.003 * np.random.default_rng(4).normal(size=V.shape)
    P = _near_points(V, F, np.random.default_rng(5), n=3000)
    query = NearQuery(V, F)
    a = query.closest(P)
    b = query.index.closest(P)
    np.testing.assert_array_equal(a.distance, b.distance)
    same = a.face == b.face
    assert same.mean() > 0.95
    np.testing.assert_array_equal(a.bary[same], b.bary[same])
    np.testing.assert_array_equal(a.point[same], b.point[same])


@pytest.mark.parametrize("name,V,F", list(_meshes())[:5], ids=[m[0] for m in _meshes()][:5])
def test_a_reach_widens_the_cells_and_changes_no_answer(name, V, F):
    """With ``reach``, the cells are at least reach / _REACH_SHARE wide and
    the answers do not change: the brute-force minimum bit for bit near the
    surface; the same distances for points several cells of the plain grid
    away (some of which either grid leaves to the index: its face among
    exactly equidistant ones may differ)."""
    rng = np.random.default_rng(6)
    plain = NearQuery(V, F)
    h = plain.index.tables.cell_size
    P = _near_points(V, F, rng, n=300)
    centres = V[F[:200]].mean(axis=1)
    far = centres + rng.normal(size=centres.shape) * 3 * h
    for reach in (0.0, h, 4 * h):
        query = NearQuery(V, F, reach=reach)
        assert query.index.tables.cell_size >= max(reach / near_query._REACH_SHARE, h) * (1 - 1e-12)
        _assert_exact(V, F, P, query.closest(P))
        np.testing.assert_array_equal(query.closest(far).distance, plain.closest(far).distance)
        np.testing.assert_array_equal(query.closest(far).distance, np.sqrt(_brute(V, F, far)[3]))
    with pytest.raises(InvalidArgumentError, match="reach must be a finite number"):
        NearQuery(V, F, reach=-1.0)
    with pytest.raises(InvalidArgumentError, match="reach must be a finite number"):
        NearQuery(V, F, reach=np.inf)


def test_points_in_empty_cells_off_and_outside_the_grid():
    """Points in cells no triangle crosses (off a flat grid), beyond the
    grid's box, and far away (answered by the index): exact distances, and
    bit-exact results where no fallback is involved."""
    V, F = regular_grid(16, 16)
    rng = np.random.default_rng(6)
    xy = rng.random((400, 2))
    P = np.column_stack([xy, rng.choice([-1, 1], 400) * rng.choice([0.02, 0.08, 0.2], 400)])
    P[:50, :2] += rng.choice([-1.0, 1.0], (50, 2)) * 0.05        # beyond the border
    query = NearQuery(V, F)
    _assert_exact(V, F, P, query.closest(P))
    far = rng.normal(size=(60, 3)) * 100
    r = query.closest(far)
    np.testing.assert_allclose(r.distance, np.sqrt(_brute(V, F, far)[3]), rtol=1e-12)


def _degenerate_triangles(rng, k, slivers, segments, points):
    """Corners ``A, B, C`` (k,3) of random triangles: the first ``slivers``
    nearly flat (C close to the segment AB), up to ``segments`` zero-area
    segments (C = B), up to ``points`` single points (B = C = A)."""
    A = rng.normal(size=(k, 3))
    B = A + rng.normal(size=(k, 3)) * 0.3
    C = A + rng.normal(size=(k, 3)) * 0.3
    s = slivers
    C[:s] = A[:s] + (B[:s] - A[:s]) * rng.random((s, 1)) + 1e-8 * rng.normal(size=(s, 3))
    C[s:segments] = B[s:segments]
    B[segments:points] = C[segments:points] = A[segments:points]
    return A, B, C


def _soup(A, B, C, offset, scale):
    """The triangles ``(A, B, C)`` as an unshared mesh, scaled and moved."""
    k = A.shape[0]
    return np.concatenate([A, B, C]) * scale + offset, np.arange(3 * k).reshape(3, k).T


def test_degenerate_triangles_slivers_far_from_the_origin():
    """Slivers, segments and points; small triangles a long way from the
    origin (the float32 filters are relative to the grid and loosened)."""
    rng = np.random.default_rng(7)
    A, B, C = _degenerate_triangles(rng, 120, 30, 45, 55)
    for offset, scale in ((0.0, 1.0), (1e4, 1e-3)):
        V, F = _soup(A, B, C, offset, scale)
        P = V[rng.integers(0, V.shape[0], 500)] + rng.normal(size=(500, 3)) * 0.05 * scale
        query = NearQuery(V, F)
        _assert_exact(V, F, P, query.closest(P), faces=query.index.tables.face)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.integers(0, 2**32 - 1), st.integers(1, 60), st.sampled_from([1e-3, 1.0, 1e3]))
def test_property_random_soups(seed, m, scale):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(3, 3 * m + 3))
    V = rng.normal(size=(n, 3)) * scale
    if rng.random() < 0.3:                            # a coarse lattice: ties, degeneracies
        V = np.round(V / scale * 2) * scale / 2
    F = rng.integers(0, n, size=(m, 3))
    P = np.vstack([V[F[:5].ravel()], rng.normal(size=(80, 3)) * scale * rng.choice([0.3, 1, 3])])
    query = NearQuery(V, F)
    r = query.closest(P)
    face, v, w, d2 = _brute(V, F, P, faces=query.index.tables.face)
    np.testing.assert_array_equal(r.distance, np.sqrt(d2))      # the exact minimum
    near = np.isin(np.arange(P.shape[0]), _fallback_rows(query, P), invert=True)
    np.testing.assert_array_equal(r.face[near], face[near])     # ties: the lowest face


def _fallback_rows(query, P):
    """Rows NearQuery hands to its index (``TriangleIndex.grid_closest``: their
    ties follow its rule)."""
    rows = []
    original = query.index.grid_closest

    def spy(Q, **kw):
        rows.append(Q)
        return original(Q, **kw)
    query.index.grid_closest = spy
    try:
        query.closest(P)
    finally:
        query.index.grid_closest = original
    if not rows:
        return np.zeros(0, dtype=np.int64)
    Q = np.concatenate(rows)
    return np.flatnonzero((P[:, None, :] == Q[None, :, :]).all(axis=2).any(axis=1))


def test_does_not_modify_inputs_and_checks_them():
    V, F = icosphere(2)
    P = _near_points(V, F, np.random.default_rng(8), n=50)
    V0, F0, P0 = V.copy(), F.copy(), P.copy()
    query = NearQuery(V, F)
    query.closest(P)
    assert (V == V0).all() and (F == F0).all() and (P == P0).all()
    with pytest.raises(InvalidArgumentError, match=r"NearQuery.closest: P must be \(q,3\)"):
        query.closest(np.zeros((4, 2)))
    with pytest.raises(InvalidArgumentError, match="NaN or infinite"):
        query.closest([[0.0, np.nan, 0.0]])
    r = query.closest(np.zeros((0, 3)))
    assert r.face.shape == (0,) and r.point.shape == (0, 3) and r.distance.shape == (0,)
    with pytest.raises(InvalidMeshError):
        NearQuery(V, np.zeros((0, 3), dtype=np.int64))


def test_the_float32_bound_never_exceeds_the_kernels_distance():
    """Every (point, reference) bound the tiles compute, slivers, segments and
    points included, near and off the origin, is at most the kernel's squared
    distance of that pair (what it is compared with)."""
    rng = np.random.default_rng(9)
    A, B, C = _degenerate_triangles(rng, 80, 20, 30, 36)
    for offset, scale in ((0.0, 1.0), (-3e3, 1e-2)):
        V, F = _soup(A, B, C, offset, scale)
        query = NearQuery(V, F)
        T = query._t
        P = np.concatenate([V + rng.normal(size=V.shape) * 0.05 * scale, V])
        block, _ = near_query._start_block(T, P, np.arange(P.shape[0]),
                                           np.clip(np.floor((P - T.lo) / T.h), 0, T.dims - 1)
                                           .astype(np.int64))
        cells = np.flatnonzero(T.count)
        point = np.repeat(np.arange(block.q.shape[0]), cells.shape[0])
        cell = np.tile(cells, block.q.shape[0])
        checked = 0
        tiles = near_query._tiles(T, block.A, point, cell)
        for tile in tiles.sets:
            span = slice(tile.first, tile.first + tile.lb.shape[0])
            valid = tiles.valid[span]
            rows = point[tiles.rows[span]][valid]
            lb = tile.lb[valid]                               # (r, W)
            tri = np.repeat(tile.tri, valid.sum(axis=1), axis=0)
            owner = np.repeat(rows, tri.shape[1])
            _, _, d2 = near_query._kernel(T, block.X, owner, tri.ravel())
            real = np.isfinite(lb.ravel())               # the table's padding is infinite
            assert (lb.ravel()[real] <= d2[real]).all()
            checked += int(real.sum())
        assert checked >= point.shape[0] * 3              # every (point, reference) pair


def test_a_one_cell_grid_and_points_a_long_way_off():
    """One triangle (every grid side is the border): points at 1e6 of its size
    leave the float32 box and go to the index; the answer stays exact."""
    V = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0.2]])
    F = np.array([[0, 1, 2], [1, 3, 2]])
    rng = np.random.default_rng(10)
    P = np.vstack([rng.normal(size=(50, 3)) * s for s in (0.5, 10.0, 1e6)])
    query = NearQuery(V, F)
    r = query.closest(P)
    face, v, w, d2 = _brute(V, F, P)
    np.testing.assert_array_equal(r.distance, np.sqrt(d2))
    near = np.isin(np.arange(P.shape[0]), _fallback_rows(query, P), invert=True)
    assert near[:50].all() and not near[-50:].any()
    np.testing.assert_array_equal(r.face[near], face[near])


def _closest_counting_tiled(monkeypatch, query, P):
    """``query.closest(P)`` and how many of the points went through the tiles."""
    tiled = []
    real = near_query._block
    monkeypatch.setattr(near_query, "_block",
                        lambda T, P_, q, *a: (tiled.append(q.size), real(T, P_, q, *a))[1])
    return query.closest(P), sum(tiled)


def test_points_in_crowded_cells_are_answered_by_the_index(monkeypatch):
    """A CAD cylinder's caps are fans of needles that crowd the cells around
    their hubs (thousands of references: a bind to a cage of such faces took
    50 s and 8 GB for 24k points); the points there go to
    ``TriangleIndex.closest`` (its hierarchy), never through the tiles; the
    cells are sized by the triangles' area, not by the side triangles'
    height-long boxes (every cell had been crowded, and every point went to
    the hierarchy: 20,000 points near a 4,000-face cylinder 5.4 s and 2.6 GB),
    so the points beside the sides go through the tiles; the distances are
    the brute-force minimum, bit for bit (the faces too, but for exact ties)."""
    monkeypatch.setattr(near_query, "_NEEDLES_PER_FACE", np.inf)   # (tiles, not the needles' index)
    V, F = cad_cylinder(1200)
    P = _near_points(V, F, np.random.default_rng(8), n=400)
    query = NearQuery(V, F)
    T = query._t
    cell3 = np.clip(np.floor((P - T.lo) / T.h), 0, T.dims - 1).astype(np.int64)
    crowded = query.index.split_crowded(
        cell3[:, 0] + T.dims[0] * (cell3[:, 1] + T.dims[1] * cell3[:, 2]),
        limit=query._index_cell)[0]
    assert 0 < crowded.size < P.shape[0]
    r, tiled = _closest_counting_tiled(monkeypatch, query, P)
    assert tiled >= P.shape[0] - crowded.size       # (a crowded block is retried in halves)
    _, _, _, d2 = _brute(V, F, P)
    np.testing.assert_array_equal(r.distance, np.sqrt(d2))
    # each face given is a nearest one (an exact tie where it differs from the
    # lowest: beyond a vertical edge both its triangles give its closest point)
    D = triangle_rows(V[F[r.face, 0]], V[F[r.face, 1]], V[F[r.face, 2]])
    q = np.arange(P.shape[0])
    _, _, own = closest_pairs(np.ascontiguousarray(P.T), q, D, q)
    np.testing.assert_array_equal(own, d2)


def test_a_cage_of_slivers_is_answered_by_the_index(monkeypatch):
    """A CAD cylinder's coarse cage is itself 480 slivers and needles: in
    one grid cell (cells sized by their height-long boxes) a tile read all of
    them for every point and evaluated most exactly (the 500-face cage of a
    20k-face cylinder: 60k points in 5.4-6.0 s, 1.1-1.3 s through the
    index); cells sized by the triangles' area hold a few hundred at most
    (2.9-3.0 s either way, 2026-12-06), none crowded here: every point goes
    through the tiles, with the brute-force distances; a reach that widens
    the cells raises the limit with their area."""
    V, F = cad_cylinder(120)
    P = _near_points(V, F, np.random.default_rng(4), n=400)
    assert NearQuery(V, F)._t is None               # (a mesh of needles: the index answers all)
    monkeypatch.setattr(near_query, "_NEEDLES_PER_FACE", np.inf)   # the tiles, as they would
    query = NearQuery(V, F)
    assert np.diff(query.index.tables.cell_start).max() < F.shape[0] // 2
    r, tiled = _closest_counting_tiled(monkeypatch, query, P)
    assert tiled >= P.shape[0]          # (no crowded cell: every point through the tiles)
    np.testing.assert_array_equal(r.distance, np.sqrt(_brute(V, F, P)[3]))
    wide = NearQuery(V, F, reach=5.0)
    growth = wide.index.cell_growth
    assert growth > 1.0 and wide._index_cell == near_query._INDEX_CELL * growth ** 2


def test_a_mesh_of_needles_is_answered_by_an_index_of_the_default_cells():
    """A CAD cylinder as tall as it is wide, its caps fans of needles: its
    grid references each face 11 times and a cell 253 faces on average, and
    its needles pass the tiles' bounds: surface_distance of a 10k-face one
    and its 200-face cage took 1.52 s, 0.33 now. An index of the default
    cells answers every query, exactly; the shared meshes and built smooth
    ones (references 1.9-2.1 a face, 21-28 a cell) keep the tiles."""
    V, F = cad_cylinder(500, height=1.0)
    query = NearQuery(V, F)
    assert query._t is None
    assert query.index.tables.cell_size == spatial.TriangleIndex(V, F).tables.cell_size
    P = _near_points(V, F, np.random.default_rng(9), n=400)
    np.testing.assert_array_equal(query.closest(P).distance, np.sqrt(_brute(V, F, P)[3]))
    for V, F in (icosphere(3), torus(60, 24), cube(6), regular_grid(30, 30)):
        assert NearQuery(V, F)._t is not None
    for name in shared_mesh_names():
        assert NearQuery(*load_shared(name)[:2])._t is not None


def test_a_mesh_of_needles_to_answer_many_queries_gets_cells_a_third_as_wide():
    """Told it is to answer at least 3 queries a face (``search_for`` tells
    it), a mesh of needles' index takes cells of a third of the default
    extents: each query bounds about a third of the pairs. The distances
    are the same, exact; fewer queries keep the default cells; ``queries``
    is checked."""
    V, F = cad_cylinder(500, height=1.0)
    P = _near_points(V, F, np.random.default_rng(11), n=3 * F.shape[0])
    few = NearQuery(V, F, queries=3 * F.shape[0] - 1)
    many = NearQuery(V, F, queries=3 * F.shape[0])
    assert few._t is None and many._t is None
    assert few.index.tables.cell_size == spatial.TriangleIndex(V, F).tables.cell_size
    assert many.index.tables.cell_size == spatial.TriangleIndex(
        V, F, cell_factor=spatial.CELL_FACTOR / 3).tables.cell_size
    assert many.index.tables.cell_size < 0.5 * few.index.tables.cell_size
    assert search_for(V, F, P.shape[0]).index.tables.cell_size == many.index.tables.cell_size
    assert search_for(V, F, F.shape[0]).index.tables.cell_size == few.index.tables.cell_size
    exact = np.sqrt(_brute(V, F, P)[3])
    np.testing.assert_array_equal(many.closest(P).distance, exact)
    np.testing.assert_array_equal(few.closest(P).distance, exact)
    V, F = icosphere(3)                    # (no needles: the tiles, whatever the count)
    assert NearQuery(V, F, queries=10 ** 6)._t is not None
    for bad in (-1, 2.5, "many", float("nan")):
        with pytest.raises(InvalidArgumentError, match="queries"):
            NearQuery(V, F, queries=bad)


def test_a_far_outlier_does_not_make_the_bulk_one_window():
    # one triangle 1,000 diagonals off: the grid's box was mostly empty, its cells grew
    # to fit _MAX_CELLS, and the whole sphere landed in a few cells (the bunny with such
    # a speck took 24 GB in surface_distance, killed; a 5k-face sphere 1.8-3.6 s instead
    # of 0.2; then those cells were crowded, answered by the hierarchy). The speck is
    # kept out of the grid now (spatial._Outliers): the sphere's grid is its own. The
    # answers stay exact
    from tests.mesh_factory import with_far_speck
    V, F = with_far_speck(*icosphere(4))
    q = NearQuery(V, F)
    index = q.index
    assert index._outliers.face.tolist() == [F.shape[0] - 1]
    plain = NearQuery(*icosphere(4)).index
    assert np.array_equal(index.tables.dims, plain.tables.dims)
    assert np.diff(index.tables.cell_start).max() == np.diff(plain.tables.cell_start).max()
    rng = np.random.default_rng(3)
    P = _near_points(V[:-3], F[:-1], rng, n=300)
    # the exact distances (among exactly equidistant faces any one: the points' own
    # vertices and edges are shared)
    r, (_, _, _, d2) = q.closest(P), _brute(V, F, P)
    np.testing.assert_array_equal(r.distance, np.sqrt(d2))
