"""The final relocation of a simplified cage (``core._relocate``): the
backward pull and the border ties, each against the same set-up without it."""

import numpy as np

from core._relocate import relocate, segment_triangles
from tests.mesh_factory import boundary_edges, regular_grid


def _square(n=9, z=0.0):
    V, F = regular_grid(n, n)
    V = V.copy()
    V[:, 2] = z
    return V, F


def test_backward_pull_brings_in_cage_parts_no_input_point_sees():
    # the cage floats 0.2 above the input square; the only forward samples sit
    # in one corner, so the forward term alone cannot move the far side
    Vc, Fc = _square(9, z=0.2)
    Vi, Fi = _square(17)
    P = Vi[(Vi[:, 0] < 0.2) & (Vi[:, 1] < 0.2)]
    movable = np.ones(Vc.shape[0], dtype=bool)
    far = (Vc[:, 0] > 0.6) & (Vc[:, 1] > 0.6)
    alone = relocate(Vc, Fc, P, movable, iters=4)
    pulled = relocate(Vc, Fc, P, movable, iters=4, surface=(Vi, Fi), back=0.3)
    assert alone[far, 2].min() > 0.15
    assert np.abs(pulled[:, 2]).max() < 0.02
    assert np.abs(pulled[:, :2] - Vc[:, :2]).max() < 1e-3  # straight down, to the closest points


def test_border_ties_pull_an_overhanging_border_back_onto_the_input_border():
    # the cage's right column sticks out 0.05 beyond the input square's border,
    # in the plane: every input point projects onto the cage with no residual
    Vc, Fc = _square(9)
    right = Vc[:, 0] > 1 - 1e-9
    Vc[right, 0] += 0.05
    Vi, Fi = _square(17)
    movable = np.ones(Vc.shape[0], dtype=bool)
    Eb_c, Eb_i = boundary_edges(Fc, Vc.shape[0]), boundary_edges(Fi, Vi.shape[0])
    C = Vi[np.unique(Eb_i)]
    seg = (Vi, segment_triangles(Eb_i))
    alone = relocate(Vc, Fc, Vi, movable, iters=4)
    tied = relocate(Vc, Fc, Vi, movable, iters=4, border=(C, Eb_c, seg, 1.0))
    assert (alone[right, 0] - 1).min() > 0.04
    assert np.abs(tied[right, 0] - 1).max() < 0.02  # from 0.05; the corners turn, so not to 0
    assert np.abs(tied[:, 2]).max() < 1e-12  # nothing leaves the plane


def test_locked_vertices_never_move():
    Vc, Fc = _square(9, z=0.2)
    Vi, Fi = _square(17)
    movable = np.ones(Vc.shape[0], dtype=bool)
    movable[::3] = False
    out = relocate(Vc, Fc, Vi, movable, iters=3, surface=(Vi, Fi), back=0.3)
    np.testing.assert_array_equal(out[~movable], Vc[~movable])
    assert np.abs(out[movable, 2]).max() < 0.2  # the others did move down


def compactness(V):
    """4 sqrt(3) area / sum of squared edges of the triangle V (3,3)."""
    area = 0.5 * np.linalg.norm(np.cross(V[1] - V[0], V[2] - V[0]))
    return 4 * np.sqrt(3) * area / sum(np.sum((V[i] - V[i - 1]) ** 2) for i in range(3))


def test_a_move_that_would_make_a_sliver_is_undone():
    # the input is a needle along the cage triangle's base: the backward pull
    # drags the free apex down onto it
    V = np.array([[0, 0, 0], [1, 0, 0], [0.5, 0.5, 0]], dtype=float)
    F = np.array([[0, 1, 2]], dtype=np.int64)
    Vi = np.array([[0, 0, 0], [1, 0, 0], [0.5, 0.002, 0]], dtype=float)
    surface = (Vi, F)
    movable = np.array([False, False, True])
    free = relocate(V, F, Vi, movable, iters=4, surface=surface, back=5.0)
    kept = relocate(V, F, Vi, movable, iters=4, surface=surface, back=5.0, min_compact=0.02)
    assert compactness(free) < 0.01                # unguarded: the face becomes a needle
    assert compactness(kept) >= 0.02               # guarded: the step that would is undone
    assert kept[2, 1] < 0.1                        # ... the ones before it stay


def test_the_per_triangle_normal_blocks_apply_the_same_operator_as_the_rows():
    # B^T B + diag(lam) from 3x3 blocks per triangle equals gathering the rows
    # and scattering them back, on a grid with rows on faces and on segments
    from core._relocate import block_matvec, normal_blocks
    from core.mesh import barycentric_gather, barycentric_scatter
    V, F = regular_grid(6, 5)
    T3 = segment_triangles(boundary_edges(F, V.shape[0]))
    G = np.concatenate([F, T3])
    rng = np.random.default_rng(7)
    group = rng.integers(0, G.shape[0], 500)
    b = rng.random((3, 500))
    b[2, group >= F.shape[0]] = 0.0                    # a point on a segment has two weights
    idx = G[group].T
    lam = rng.random(V.shape[0])
    X = rng.normal(size=(V.shape[0], 3))
    rows = barycentric_scatter(barycentric_gather(X, idx.T, b.T), idx.T, b.T, V.shape[0]) + lam[:, None] * X
    got = block_matvec(np.ascontiguousarray(G.T), normal_blocks(group, b, G.shape[0]), X, lam)
    assert np.abs(got - rows).max() <= 1e-12 * np.abs(rows).max()


def test_relocation_stops_once_an_update_moves_less_than_min_move():
    # the cage floats above the input square: every update moves it down, by less
    # each time; with min_move at a whole edge length the first update is the last
    Vc, Fc = _square(9, z=0.05)
    Vi, Fi = _square(17)
    movable = np.ones(Vc.shape[0], dtype=bool)
    kw = dict(surface=(Vi, Fi), back=0.3)
    once = relocate(Vc, Fc, Vi, movable, iters=1, **kw)
    four = relocate(Vc, Fc, Vi, movable, iters=4, **kw)
    assert np.abs(four[:, 2]).max() < np.abs(once[:, 2]).max() < 0.05     # each update moves
    assert np.array_equal(relocate(Vc, Fc, Vi, movable, iters=4, min_move=1.0, **kw), once)
    assert np.array_equal(relocate(Vc, Fc, Vi, movable, iters=4, min_move=1e-12, **kw), four)
    # on the plane nothing moves (beyond round-off): one update
    Vp = _square(9)[0]
    assert np.abs(relocate(Vp, Fc, Vi, movable, iters=4, min_move=1e-4, **kw) - Vp).max() < 1e-15


def test_searches_started_where_the_input_was_merged_give_the_exact_searches_result():
    # a noisy coarse sphere relocated towards a finer one, both ways: starting
    # every closest-point search at the cage vertex each input vertex is nearest
    # to (as the engine's merges give them) and walking changes nothing
    from tests.mesh_factory import icosphere
    rng = np.random.default_rng(5)
    Vc, Fc = icosphere(2)
    Vc = Vc * (1 + 0.04 * rng.standard_normal((Vc.shape[0], 1)))
    Vi, Fi = icosphere(4)
    Vi = (Vi * (1 + 0.02 * rng.standard_normal((Vi.shape[0], 1)))) @ np.linalg.qr(
        rng.standard_normal((3, 3)))[0]
    cage_of = np.argmin(((Vi[:, None, :] - Vc[None, :, :]) ** 2).sum(axis=2), axis=1)
    movable = np.ones(Vc.shape[0], dtype=bool)
    kw = dict(iters=4, surface=(Vi, Fi), back=0.3, min_compact=0.02)
    exact = relocate(Vc, Fc, Vi, movable, **kw)
    walked = relocate(Vc, Fc, Vi, movable, P_near=cage_of, cage_of=cage_of, **kw)
    assert np.abs(exact - Vc).max() > 1e-3                # it does move
    # the same closest points (a point on an edge between two faces may be
    # assigned to the other one: the same row, summed in another order)
    np.testing.assert_allclose(walked, exact, rtol=0, atol=1e-14)


def test_the_backward_start_is_the_nearest_input_vertex_merged_into_the_home_corners():
    # brute force: for each point, the input vertices merged into the corners of
    # its face that carry its largest barycentric weight, and the nearest of them
    from core._relocate import _BACK_BARY, _merged_nearest
    rng = np.random.default_rng(8)
    F = rng.integers(0, 20, (30, 3))
    Vc = rng.random((20, 3))
    Vin = rng.random((200, 3))
    cage_of = rng.integers(-1, 20, 200)
    cage_of[cage_of == 7] = -1                   # a cage vertex nothing went to
    k = _BACK_BARY.shape[0]
    X = np.einsum("pc,fcd->fpd", _BACK_BARY, Vc[F]).reshape(-1, 3)
    got = _merged_nearest(X, F, _BACK_BARY, 20, Vin, cage_of)
    for p in range(X.shape[0]):
        f, j = divmod(p, k)
        home = F[f][_BACK_BARY[j] == _BACK_BARY[j].max()]
        cand = np.flatnonzero(np.isin(cage_of, home))
        want = cand[np.argmin(((Vin[cand] - X[p]) ** 2).sum(axis=1))] if cand.size else -1
        assert got[p] == want
