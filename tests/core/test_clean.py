"""The half-edge twin table, face keys and fan counting (``core._clean``).

Every fast path is checked against a plain reference: the argsort twin
table and the corner union-find fan count the simplifier used before."""

import numpy as np
import pytest

from core._clean import (BOUNDARY, NON_MANIFOLD, _MAX_WALK, coincident_pairs, half_edge_ends, non_manifold_vertices,
                         spatial_order, twin_table)
from core.clean import clean_mesh
from core.topology import connected_labels
from tests.mesh_factory import icosphere, load_shared, regular_grid, shared_mesh_names, torus


# --- references (the union-find versions) -----------------------------------------------

def ref_twin_table(F, n):
    U, W = half_edge_ends(F)
    key = np.minimum(U, W) * np.int64(max(n, 1)) + np.maximum(U, W)
    order = np.argsort(key, kind="stable")
    ks = key[order]
    twin = np.full(ks.size, BOUNDARY, dtype=np.int64)
    if ks.size == 0:
        return twin
    start = np.flatnonzero(np.concatenate([[True], ks[1:] != ks[:-1]]))
    count = np.diff(np.concatenate([start, [ks.size]]))
    pair = start[count == 2]
    twin[order[pair]] = order[pair + 1]
    twin[order[pair + 1]] = order[pair]
    twin[order[np.repeat(count > 2, count)]] = NON_MANIFOLD
    return twin


def ref_non_manifold_vertices(F, n, twin):
    U, W = half_edge_ends(F)
    bad = np.zeros(n, dtype=bool)
    nm = twin == NON_MANIFOLD
    bad[U[nm]] = True
    bad[W[nm]] = True
    h = np.flatnonzero(twin > np.arange(twin.size))
    t = twin[h]
    f_h, f_t = h - h % 3, t - t % 3
    Fr = F.ravel()

    def corner(base, v):
        return base + np.where(Fr[base] == v, 0, np.where(Fr[base + 1] == v, 1, 2))

    pairs = np.concatenate([np.stack([corner(f_h, U[h]), corner(f_t, U[h])], axis=1),
                            np.stack([corner(f_h, W[h]), corner(f_t, W[h])], axis=1)])
    labels = connected_labels(Fr.size, pairs)
    fans = np.bincount(Fr[labels == np.arange(Fr.size)], minlength=n)
    return bad | (fans > 1)


def check_against_reference(F, n):
    """Fast twin table and fan mask equal the references; returns the mask."""
    twin = twin_table(F, n)
    np.testing.assert_array_equal(twin, ref_twin_table(F, n))
    bad = non_manifold_vertices(F, n, twin)
    np.testing.assert_array_equal(bad, ref_non_manifold_vertices(F, n, twin))
    np.testing.assert_array_equal(bad, non_manifold_vertices(F, n, twin, ends=half_edge_ends(F)))
    return bad


# --- built meshes --------------------------------------------------------------------------

def cone(k, apex=0, first=1, flip=False):
    """Closed cone: apex, a ring of k vertices and a base centre; 2k faces."""
    ring = first + np.arange(k)
    centre = first + k
    nxt = np.roll(ring, -1)
    side = np.stack([np.full(k, apex), ring, nxt], axis=1)
    base = np.stack([np.full(k, centre), nxt, ring], axis=1)
    F = np.concatenate([side, base])
    return F[:, ::-1] if flip else F


def open_fan(k, apex=0, first=1):
    """k triangles around apex, not closed (a boundary vertex with one fan)."""
    ring = first + np.arange(k + 1)
    return np.stack([np.full(k, apex), ring[:-1], ring[1:]], axis=1)


def test_bow_tie_of_two_closed_cones_freezes_only_the_apex():
    F = np.concatenate([cone(5), cone(7, first=7)])
    n = 15
    bad = check_against_reference(F, n)
    assert np.flatnonzero(bad).tolist() == [0]
    assert (twin_table(F, n) >= 0).all()            # every edge is a manifold interior edge


def test_two_fans_on_a_boundary_vertex():
    F = np.concatenate([open_fan(3), open_fan(4, first=5)])
    assert np.flatnonzero(check_against_reference(F, 10)).tolist() == [0]


def test_open_fan_plus_closed_cone_and_single_fans():
    # a path and a cycle at vertex 0 (only the walk can tell)
    F = np.concatenate([open_fan(3), cone(4, first=5)])
    assert np.flatnonzero(check_against_reference(F, 10)).tolist() == [0]
    # one open fan, one closed cone, an inconsistently oriented cone: all manifold
    assert not check_against_reference(open_fan(6), 8).any()
    assert not check_against_reference(cone(6), 8).any()
    Fi = cone(6).copy()
    Fi[::2] = Fi[::2, ::-1]
    assert not check_against_reference(Fi, 8).any()
    # two cones, one of them flipped
    F2 = np.concatenate([cone(6), cone(6, first=8, flip=True)])
    assert np.flatnonzero(check_against_reference(F2, 15)).tolist() == [0]


def test_non_manifold_edge_freezes_its_two_ends_only():
    F = np.array([[0, 1, 2], [1, 0, 3], [0, 1, 4], [2, 1, 5]])
    twin = twin_table(F, 6)
    assert (twin == NON_MANIFOLD).sum() == 3
    assert np.flatnonzero(check_against_reference(F, 6)).tolist() == [0, 1]


def test_high_valence_fans_finish_with_the_union_find():
    k = 3 * _MAX_WALK
    one = cone(k)
    assert not check_against_reference(one, k + 2).any()
    two = np.concatenate([cone(k), cone(k, first=k + 2)])
    assert np.flatnonzero(check_against_reference(two, 2 * k + 3)).tolist() == [0]
    path_and_cycle = np.concatenate([open_fan(k), cone(k, first=k + 2)])
    assert np.flatnonzero(check_against_reference(path_and_cycle, 2 * k + 3)).tolist() == [0]


@pytest.mark.parametrize("make", [lambda: icosphere(3), lambda: torus(), lambda: regular_grid(9, 7)])
def test_closed_and_open_manifolds_have_no_frozen_vertex(make):
    V, F = make()
    assert not check_against_reference(F, V.shape[0]).any()


def test_random_holes_match_the_union_find():
    """Deleting random faces of a sphere makes boundary and bow-tie vertices."""
    V, F = icosphere(3)
    rng = np.random.default_rng(7)
    total = 0
    for _ in range(20):
        keep = rng.random(F.shape[0]) < rng.uniform(0.3, 0.9)
        total += int(check_against_reference(F[keep], V.shape[0]).sum())
    assert total > 0  # the cases were exercised


@pytest.mark.parametrize("name", shared_mesh_names())
def test_shared_meshes_match_the_references(name):
    V, F = load_shared(name)
    c = clean_mesh(V, F)
    check_against_reference(c.F, c.V.shape[0])


# --- twin table ------------------------------------------------------------------------------

def test_twin_table_pairs_boundary_and_non_manifold():
    F = np.array([[0, 1, 2], [2, 1, 3]])             # h0 = (1, 2) and h5 = (2, 1) are twins
    assert twin_table(F, 4).tolist() == [5, -1, -1, -1, -1, 0]
    Fn = np.array([[0, 1, 2], [1, 0, 3], [0, 1, 4]])  # edge (0, 1) used three times
    assert twin_table(Fn, 5).tolist() == [-1, -1, -2, -1, -1, -2, -1, -1, -2]
    assert twin_table(np.zeros((0, 3), dtype=np.int64), 0).size == 0


def test_twin_table_without_room_to_pack_uses_the_argsort():
    V, F = torus()
    n = V.shape[0]
    big = 2 ** 31                                   # n^2 * 2^bits no longer fits in int64
    np.testing.assert_array_equal(twin_table(F, big), ref_twin_table(F, big))
    np.testing.assert_array_equal(twin_table(F, big), twin_table(F, n))


# --- face keys -------------------------------------------------------------------------------

def test_face_keys_beyond_the_packed_key_range(monkeypatch):
    # above ~2.1M vertices (lo n + mid) n + hi overflows an int64; the keys fall back
    # to ranks of the sorted rows: both paths group the same faces
    import importlib
    clean = importlib.import_module("core._clean")
    V, F = icosphere(2)
    F = np.concatenate([F, F[[3, 7]][:, [1, 2, 0]], F[[5]][:, ::-1]])   # 3 repeated sets, any order
    packed = clean.face_keys(F, V.shape[0])
    monkeypatch.setattr(clean, "_KEY_MAX_N", 0)
    ranked = clean.face_keys(F, V.shape[0])
    for keys in (packed, ranked):
        assert np.unique(keys).size == F.shape[0] - 3
        assert keys[-3] == keys[3] and keys[-2] == keys[7] and keys[-1] == keys[5]
    monkeypatch.undo()
    big = 3_000_000
    Fb = np.array([[0, 1, big], [big, 0, 1], [1, 2, big], [0, 2, big - 1]], dtype=np.int64)
    keys = clean.face_keys(Fb, big + 1)
    assert keys[0] == keys[1] and len(set(keys.tolist())) == 3


@pytest.mark.parametrize("case", ["torus", "grid", "thin", "nonmanifold", "empty"])
def test_spatial_order_is_the_same_mesh_with_its_own_twin_table(case):
    if case == "torus":
        V, F = torus(30, 15)
    elif case == "grid":
        V, F = regular_grid(12, 9)
    elif case == "thin":  # one axis 1e-304 thick (found by hypothesis: no overflow warning)
        V, F = regular_grid(12, 9)
        V = V.copy()
        V[:, 2] = 1e-304 * np.random.default_rng(0).random(V.shape[0])
    elif case == "nonmanifold":  # a fin on a grid: three faces on one edge
        V, F = regular_grid(6, 6)
        V = np.concatenate([V, [[0.5, 0.5, 1.0]]])
        F = np.concatenate([F, [[F[0, 0], F[0, 1], V.shape[0] - 1]]])
    else:
        V, F = np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64)
    twin = twin_table(F, V.shape[0])
    V2, F2, twin2, U2, W2, order, forder = spatial_order(V, F, twin)
    assert np.array_equal(np.sort(order), np.arange(V.shape[0]))
    assert np.array_equal(np.sort(forder), np.arange(F.shape[0]))
    assert np.array_equal(V2, V[order])
    assert np.array_equal(order[F2], F[forder])            # same faces, same corners
    assert np.array_equal(twin2, twin_table(F2, V.shape[0]))
    U, W = half_edge_ends(F2)
    assert np.array_equal(U2, U) and np.array_equal(W2, W)
    if F.shape[0]:
        # faces in the order of their smallest (new) vertex, ties by old index
        first = F2.min(axis=1)
        assert np.all(np.diff(first) >= 0)
        assert np.array_equal(forder, np.lexsort((np.arange(F.shape[0]), first[np.argsort(forder)])))
    # without the ends: the same mesh, no (3m,) end arrays
    lean = spatial_order(V, F, twin, ends=False)
    assert lean[3] is None and lean[4] is None
    for a, b in zip(lean[:3] + lean[5:], (V2, F2, twin2, order, forder)):
        assert np.array_equal(a, b)


@pytest.mark.parametrize("step", [1, 7, 1 << 20])
def test_edge_representatives_are_one_half_edge_per_edge_in_any_slicing(step):
    from core._clean import BOUNDARY, edge_representatives, half_edge_ends, twin_table
    from core.topology import edge_keys
    from tests.mesh_factory import regular_grid
    V, F = regular_grid(9, 7)                      # borders and interior edges
    twin = twin_table(F, V.shape[0])
    h = np.arange(twin.size)
    for boundary in (True, False):
        rep = edge_representatives(twin, boundary, step)
        want = np.flatnonzero((twin > h) | ((twin == BOUNDARY) & boundary))
        assert np.array_equal(rep, want)
    U, W = half_edge_ends(F, edge_representatives(twin, True, step))
    keys = edge_keys(U, W, V.shape[0])
    assert np.unique(keys).size == keys.size == np.unique(edge_keys(*half_edge_ends(F), V.shape[0])).size


# --- sorted keys, components, interior edges ------------------------------------------------

@pytest.mark.parametrize("size, bound", [(1, 10), (3000, 2 ** 40),           # packed
                                         (7, 2 ** 62), (3000, 2 ** 55), (40000, 2 ** 50),  # ranges
                                         (40000, 2 ** 62)])                 # too many: argsort
def test_sort_keys_is_the_stable_argsort_packed_or_split_into_key_ranges(size, bound):
    from core._groups import sort_keys
    rng = np.random.default_rng(size)
    key = rng.integers(0, bound, size, dtype=np.int64)
    key[::3] = key[0]                                  # long runs of one key: ties by index
    key[1::7] = bound - 1
    order, ks = sort_keys(key.copy(), bound)
    ref = np.argsort(key, kind="stable")
    np.testing.assert_array_equal(order, ref)
    np.testing.assert_array_equal(ks, key[ref])


def test_twin_table_split_into_key_ranges_equals_the_reference():
    # 2^28 vertices: n^2 with the half-edge index no longer packs into one int64
    V, F = torus(20, 10)
    F = np.concatenate([F, F[:3]])                     # a few non-manifold edges too
    big = 2 ** 28
    np.testing.assert_array_equal(twin_table(F, big), ref_twin_table(F, big))
    np.testing.assert_array_equal(twin_table(F, big), twin_table(F, V.shape[0]))


def ref_connected_labels(n, pairs):
    """Smallest node of each component, by a plain union-find."""
    parent = list(range(n))

    def find(x):
        while parent[x] != x:
            parent[x] = parent[parent[x]]
            x = parent[x]
        return x

    for a, b in np.asarray(pairs).reshape(-1, 2).tolist():
        ra, rb = find(a), find(b)
        if ra != rb:
            parent[max(ra, rb)] = min(ra, rb)
    return np.array([find(x) for x in range(n)], dtype=np.int64)


@pytest.mark.parametrize("seed", range(6))
def test_connected_labels_are_each_components_smallest_node(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 3000))
    k = int(rng.integers(0, 2 * n))
    pairs = rng.integers(0, n, (k, 2))
    if seed % 2:                                        # long chains in both index orders
        chain = rng.permutation(n)
        pairs = np.concatenate([pairs, np.stack([chain[:-1], chain[1:]], axis=1)])
    labels = connected_labels(n, pairs)
    assert labels.dtype == np.int64
    np.testing.assert_array_equal(labels, ref_connected_labels(n, pairs))


@pytest.mark.parametrize("centre", ["largest", "smallest", "middle"])
def test_a_star_joins_in_two_rounds_whatever_its_centre(centre, monkeypatch):
    """Pairs sharing their larger root hooked it below whichever pair was
    written last, so a star centred on its largest node (40k coincident
    copies of a triangle, welded) joined one leaf a round: 4.8 s, quadratic.
    Now below the smallest: two rounds, the labels as a union-find gives."""
    import core.topology as topology
    n = 20_000
    hub = {"largest": n - 1, "smallest": 0, "middle": n // 2}[centre]
    leaves = np.random.default_rng(1).permutation(np.setdiff1d(np.arange(n), [hub]))
    pairs = np.stack([np.full(n - 1, hub), leaves], axis=1)
    rounds = []
    jump = topology._jump
    monkeypatch.setattr(topology, "_jump", lambda parent, nodes: (rounds.append(1),
                                                                  jump(parent, nodes)))
    labels = connected_labels(n, pairs)
    assert (labels == 0).all() and len(rounds) <= 2
    np.testing.assert_array_equal(connected_labels(n, pairs[::-1]), labels)


def test_connected_labels_of_a_path_and_of_no_pairs():
    n = 1000
    path = np.stack([np.arange(n - 1, 0, -1), np.arange(n - 2, -1, -1)], axis=1)
    assert (connected_labels(n, path) == 0).all()
    np.testing.assert_array_equal(connected_labels(5, np.zeros((0, 2), dtype=np.int64)), np.arange(5))


def test_interior_edges_are_the_representatives_and_their_twins():
    from core._clean import edge_representatives, interior_edges
    V, F = regular_grid(9, 7)
    twin = twin_table(F, V.shape[0])
    h, t = interior_edges(twin)
    np.testing.assert_array_equal(h, edge_representatives(twin, boundary=False))
    np.testing.assert_array_equal(t, twin[h])
    assert (h < t).all()


@pytest.mark.parametrize("make", [lambda: torus(12, 8), lambda: regular_grid(6, 6)])
def test_non_manifold_vertices_with_the_callers_corner_counts(make):
    from tests.mesh_factory import with_fins
    V, F = with_fins(*make())                           # non-manifold edges
    n = V.shape[0]
    twin = twin_table(F, n)
    corners = np.bincount(F.ravel(), minlength=n)
    np.testing.assert_array_equal(non_manifold_vertices(F, n, twin, corners=corners),
                                  ref_non_manifold_vertices(F, n, twin))


@pytest.mark.parametrize("far", [None, 1e6, -1e6], ids=["unit box", "far point", "far below"])
@pytest.mark.parametrize("distance", [0.0, 1e-6, 1e-3])
def test_coincident_pairs_group_exact_copies_and_near_points_as_brute_force(distance, far):
    """Exact copies (a soup as STL stores it: each point up to 6 times, -0.0 and
    0.0 alike) pair with one of them before the grids, which see one of each:
    the groups are those of every pair within ``distance`` per axis (and none
    beyond 4 ``distance``); also with a point far off (a grid too wide for
    packed keys) above or below the others."""
    rng = np.random.default_rng(3)
    base = rng.random((300, 3))
    base[:5, 0] = 0.0
    P = base[rng.integers(0, 300, 1500)]
    P[:5] = base[:5]
    P[5:10] = base[:5] * [-1.0, 1.0, 1.0]                  # -0.0: the same place as 0.0
    P[rng.random(1500) < 0.2] += rng.normal(scale=0.3 * distance, size=3) if distance else 0.0
    if far is not None:
        P[-1] = far
    pairs = coincident_pairs(P, distance)
    got = connected_labels(P.shape[0], pairs)
    D = np.abs(P[:, None, :] - P[None, :, :]).max(axis=2)
    near = np.argwhere(np.triu(D <= distance, 1))
    want = connected_labels(P.shape[0], near)
    # every pair within distance is joined ...
    assert (got[near[:, 0]] == got[near[:, 1]]).all()
    # ... and no pair farther than 4 distance per axis is a direct pair
    assert (D[pairs[:, 0], pairs[:, 1]] <= 4 * distance * (1 + 1e-9) + 1e-300).all()
    assert (got[:5] == got[5:10]).all()
    if distance == 0.0:
        np.testing.assert_array_equal(got, want)
