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


def _assert_tiles(X, T, share=1e-6):
    """The triangles ``T`` (k-2,3) of the planar polygon ``X`` (k,3) cover it
    exactly once: each faces the polygon's way (Newell's normal; with an area
    above ``share`` of the polygon's), their areas add up to the polygon's,
    and each polygon edge is a triangle edge once (the others come in
    opposite pairs, the diagonals)."""
    k = len(X)
    n = np.cross(X[T[:, 1]] - X[T[:, 0]], X[T[:, 2]] - X[T[:, 0]])
    D = X - X[0]
    N = np.cross(D, np.roll(D, -1, axis=0)).sum(axis=0)
    assert T.shape == (k - 2, 3) and (n @ N > share * (N @ N)).all()
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


# --- large polygons (clipped in rounds: core.triangulate._clip_in_rounds) ---


def comb(teeth):
    """A comb of ``teeth`` teeth 1 wide and 4 long on a bar (CONCAVE["comb"]
    has 5)."""
    teeth = [p for i in range(teeth - 1, -1, -1)
             for p in [(2 * i + 2, 1), (2 * i + 1, 1), (2 * i + 1, 5), (2 * i, 5)]]
    return np.array([(0, 0), (2 * len(teeth) // 4 - 1, 0)] + teeth, dtype=np.float64)


def star(k, inner=0.4):
    """A star of ``k // 2`` spikes (CONCAVE["star"] has 5)."""
    t = np.arange(k) * 2 * np.pi / k
    return np.c_[np.cos(t), np.sin(t)] * np.where(np.arange(k) % 2, inner, 1.0)[:, None]


def spiral(k, turns=4):
    """A strip wound ``turns`` times: its outer side convex, its inner side
    reflex (an ear clipper that cuts one ear at a time from each end needs
    about ``k / 4`` rounds)."""
    t = np.linspace(0.5, turns * 2 * np.pi, k // 2)
    side = np.c_[np.cos(t), np.sin(t)]
    return np.concatenate([(3.5 + t)[:, None] * side, ((1 + t)[:, None] * side)[::-1]])


def coastline(k, seed=0):
    """A rough closed curve: random angles, a radius of 1/f noise."""
    rng = np.random.default_rng(seed)
    t = np.sort(rng.uniform(0, 2 * np.pi, k))
    f = np.fft.rfft(rng.normal(size=k)) / np.maximum(np.arange(k // 2 + 1), 1) ** 0.8
    f[0] = 0
    r = np.fft.irfft(f, k)
    return (1 + 0.35 * r / np.abs(r).max())[:, None] * np.c_[np.cos(t), np.sin(t)]


def notch(k):
    """A 10 x 10 square with a half disc bitten out of one side, its arc of
    ``k - 4`` vertices all reflex (fanned from the square's corners)."""
    a = np.linspace(-np.pi / 2, -3 * np.pi / 2, k - 4)
    return np.concatenate([[(0, 0), (10, 0)], np.c_[10 + 3 * np.cos(a), 5 + 3 * np.sin(a)],
                           [(10, 10), (0, 10)]])


def skyline(columns, seed=0):
    """An orthogonal outline (a CAD face's lettering, a bar chart): columns
    of random widths and heights on a base, a third of its edges split by
    a midpoint (collinear vertices)."""
    rng = np.random.default_rng(seed)
    x = np.r_[0, np.cumsum(rng.integers(1, 4, size=columns))].astype(np.float64)
    h = rng.integers(1, 20, size=columns) + np.arange(columns) % 2 / 2   # (no equal neighbours)
    top = np.c_[np.c_[x[1:], x[:-1]][::-1].ravel(), np.repeat(h[::-1], 2)]   # (right to left)
    P = np.concatenate([[(x[-1], 0.0)], top, [(0.0, 0.0)]])
    split = rng.uniform(size=len(P)) < 1 / 3
    mid = (P + np.roll(P, -1, axis=0)) / 2
    return np.insert(P, np.flatnonzero(split) + 1, mid[split], axis=0)


LARGE = {"comb": comb(750), "star": star(3000), "spiral": spiral(3000),
         "coastline": coastline(3000), "notch": notch(3000), "skyline": skyline(900)}


def _count_work(monkeypatch):
    """Counts the rounds of clipping and the (corner, triangle) pairs tested."""
    import core.triangulate as tri
    work = {"rounds": 0, "pairs": 0}
    round_of_clips, inside = tri._round_of_clips, tri._inside

    def counted_round(*args):
        work["rounds"] += 1
        return round_of_clips(*args)

    def counted_inside(P, tol, pid, T, X):
        work["pairs"] += X.size
        return inside(P, tol, pid, T, X)

    monkeypatch.setattr(tri, "_round_of_clips", counted_round)
    monkeypatch.setattr(tri, "_inside", counted_inside)
    return work


def _assert_no_corner_inside(P, T):
    """No vertex of the 2D polygon ``P`` (k,2) lies in a triangle of ``T``
    (k-2,3) (strictly; a vertex on a triangle's edge breaks the edge pairs
    of :func:`_assert_tiles`)."""
    o = lambda a, b, c: ((b[..., 0] - a[..., 0]) * (c[..., 1] - a[..., 1])
                         - (b[..., 1] - a[..., 1]) * (c[..., 0] - a[..., 0]))
    w = np.sign(o(P[T[0, 0]], P[T[0, 1]], P[T[0, 2]]))
    for s in range(0, len(T), 256):
        A, B, C = (P[T[s:s + 256, i], None] for i in range(3))
        inside = (w * o(A, B, P) > 0) & (w * o(B, C, P) > 0) & (w * o(C, A, P) > 0)
        assert not inside.any()


@pytest.mark.parametrize("name", sorted(LARGE))
def test_large_concave_polygons_are_tiled_in_few_rounds(name, monkeypatch):
    """Large concave outlines (thousands of vertices: a comb, a star, a
    spiral strip, a coastline, a square with a dense bite, an orthogonal
    outline with collinear vertices), both windings, rotated into 3D: k - 2
    triangles that tile the polygon, each facing its way, holding no other
    vertex; in a few rounds of O(k) work (the ear clipper of small polygons
    needs k - 3 rounds of O(k))."""
    P = LARGE[name]
    k = len(P)
    for loop in (np.roll(np.arange(k), -7), np.roll(np.arange(k)[::-1], -3)):
        X = in_3d(P[loop], seed=len(loop) % 7)
        work = _count_work(monkeypatch)
        T = triangulate_polygons(X, fan(k), np.array([k]))
        assert T.dtype == np.int64 and not np.array_equal(T, fan(k))
        _assert_tiles(X, T, share=0)
        _assert_no_corner_inside(P[loop], T)
        assert work["rounds"] <= 40 and work["pairs"] <= 64 * k, work


def test_a_dense_smooth_outline_is_tiled():
    """16,000 vertices on a smooth concave outline: each corner's triangle
    is below the flat tolerance of the polygon's size (convex only by
    rounding's measure), and still the polygon is tiled, no triangle of
    zero area."""
    t = np.linspace(0, 2 * np.pi, 16000, endpoint=False)
    P = np.c_[(1 + 0.3 * np.cos(2 * t)) * np.cos(t),
              (1 + 0.3 * np.cos(2 * t)) * 0.6 * np.sin(t) + 0.5 * np.cos(t) ** 2]
    X = in_3d(np.roll(P, -4000, axis=0))
    T = triangulate_polygons(X, fan(len(P)), np.array([len(P)]))
    _assert_tiles(X, T, share=0)


def test_a_thin_strip_winding_at_every_vertex_is_tiled(monkeypatch):
    """A strip narrower than its zigzag, a bend at every vertex: only its two
    ends are ears, so rounds stall (a few ears each) and the rest is clipped
    one ear at a time; still tiled."""
    x = np.arange(400) * 0.1
    y = np.where(np.arange(400) % 2, 1.0, 0.0)
    P = np.r_[np.c_[x, y], np.c_[x, y + 0.3][::-1]]
    k = len(P)
    X = in_3d(np.roll(P, -100, axis=0))
    work = _count_work(monkeypatch)
    T = triangulate_polygons(X, fan(k), np.array([k]))
    _assert_tiles(X, T, share=0)
    _assert_no_corner_inside(np.roll(P, -100, axis=0), T)
    assert work["rounds"] == 3


@pytest.mark.parametrize("kind", ["random", "doubled", "collinear"])
def test_large_polygons_without_a_clean_triangulation_give_k_minus_2_triangles(kind, monkeypatch):
    """A large self-intersecting polygon (random vertices), a large comb
    with every vertex repeated (touching itself everywhere) and a zigzag
    along a line and back, with one vertex off it: k - 2 triangles of 3
    distinct vertices each, in a few rounds."""
    rng = np.random.default_rng(7)
    zigzag = np.arange(3000.0)[:, None] % 7 * [1, 1]
    P = {"random": rng.uniform(size=(3000, 2)), "doubled": np.repeat(comb(300), 2, axis=0),
         "collinear": np.r_[[(3.0, 9.0)], zigzag]}[kind]            # (the fan from (3, 9) folds)
    k = len(P)
    work = _count_work(monkeypatch)
    T = triangulate_polygons(in_3d(P), fan(k), np.array([k]))
    assert T.shape == (k - 2, 3) and T.dtype == np.int64 and not np.array_equal(T, fan(k))
    assert T.min() >= 0 and T.max() < k and (np.diff(np.sort(T, axis=1)) > 0).all()
    assert work["rounds"] <= 100 and work["pairs"] <= 64 * k, work


def test_large_polygons_in_one_call_get_what_each_gets_alone():
    """Large polygons of several sizes, mixed with small ones and triangles,
    in one call: each polygon's rows are what it gets alone."""
    shapes = [LARGE["comb"], np.array(CONCAVE["L"]), LARGE["spiral"][::2], np.zeros((0, 2)),
              star(101 * 2), np.array(CONCAVE["arrow"]), coastline(500, seed=3)]
    loops, X, n = [], [], 0
    for j, P in enumerate(shapes):
        P = P if len(P) else np.array([(0, 0), (1, 0), (0, 1.0)])
        X.append(in_3d(P, seed=j))
        loops.append(np.roll(np.arange(n, n + len(P)), -(j + 1)))
        n += len(P)
    X = np.concatenate(X)
    F, sizes = fans(loops)
    T = triangulate_polygons(X, F, sizes)
    first = np.cumsum(sizes - 2) - (sizes - 2)
    for loop, at in zip(loops, first):
        alone = triangulate_polygons(X, *fans([loop]))
        assert np.array_equal(T[at:at + len(loop) - 2], alone)
        at_in_loop = (alone - loop.min() + np.argmin(loop)) % len(loop)   # (loop: a rotated range)
        _assert_tiles(X[loop], at_in_loop, share=0)


def test_random_star_shaped_polygons_of_sizes_around_the_switch_are_tiled():
    """Random star-shaped polygons of 60 to 70 and of 200 vertices (either
    side of the switch from one ear a round to rounds of many), one call."""
    rng = np.random.default_rng(5)
    loops, X, n = [], [], 0
    for k in list(range(60, 71)) * 3 + [200] * 5:
        angle = (np.arange(k) + rng.uniform(0, 1, size=k)) * 2 * np.pi / k
        P = rng.uniform(0.2, 1.0, size=k)[:, None] * np.c_[np.cos(angle), np.sin(angle)]
        X.append(in_3d(P, seed=k))
        loops.append(np.arange(n, n + k))
        n += k
    X = np.concatenate(X)
    F, sizes = fans(loops)
    T = triangulate_polygons(X, F, sizes)
    first = np.cumsum(sizes - 2) - (sizes - 2)
    for loop, at in zip(loops, first):
        _assert_tiles(X[loop], T[at:at + len(loop) - 2] - loop[0], share=0)
    assert not np.array_equal(T, F)
