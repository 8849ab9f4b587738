"""A gravel scan: a bumpy sphere in a ring of pebbles, its cage at the
topology floor (every pebble and the sphere a tetrahedron, as ``simplify``
leaves them). The fine surface is small blobs inside the pebbles, so most
dense samples lie many grid cells from it: the closest-point searches'
far path (``TriangleIndex``'s BVH, by groups of queries) and the fit's reach
(cells sized to the samples' distance) answer them. The answers are exact,
and the same as the plain path's (one query at a time, default cells)."""

import numpy as np
import pytest

import core.fit as fit
import core.spatial as spatial
from core import fit_cage
from core.metrics import sample_surface
from core.near_query import NearQuery
from core.spatial import TriangleIndex, closest_pairs, triangle_rows
from core.subdivide import subdivision_operator
from tests.mesh_factory import icosphere

#: a regular tetrahedron, its faces consistently oriented
_TET_V = np.array([[1.0, 1.0, 1.0], [1.0, -1.0, -1.0], [-1.0, 1.0, -1.0], [-1.0, -1.0, 1.0]])
_TET_F = np.array([[0, 1, 2], [0, 3, 1], [0, 2, 3], [1, 3, 2]])


def gravel(k=150, seed=3):
    """(V, F) of a bumpy sphere and ``k`` pebbles (flattened icospheres of
    0.2-5% of the sphere's diagonal, in a ring 0.6-1.5 diagonals around
    it), and (Vc, Fc), a cage of one tetrahedron inside each."""
    rng = np.random.default_rng(seed)
    V, F = icosphere(3)
    V = V * (1 + 0.05 * np.sin(5 * V[:, [0]]) * np.sin(4 * V[:, [1]]))
    d = float(np.linalg.norm(V.max(axis=0) - V.min(axis=0)))
    P, Q = icosphere(1)
    size = np.exp(rng.uniform(np.log(0.002), np.log(0.05), k)) * d
    angle, radius = rng.uniform(0, 2 * np.pi, k), rng.uniform(0.6, 1.5, k) * d
    centre = np.c_[radius * np.cos(angle), radius * np.sin(angle), rng.normal(0, 0.05 * d, k)]
    squash = rng.uniform(0.5, 1.0, (k, 1, 3))
    pebbles = P[None] * size[:, None, None] * squash + centre[:, None]
    Vd = np.vstack([V, pebbles.reshape(-1, 3)])
    Fd = np.vstack([F, (Q[None] + V.shape[0] + P.shape[0] * np.arange(k)[:, None, None]).reshape(-1, 3)])
    tet = _TET_V / np.sqrt(3.0)
    Vc = np.vstack([0.8 * tet, (0.3 * tet[None] * size[:, None, None] + centre[:, None]).reshape(-1, 3)])
    Fc = (_TET_F[None] + 4 * np.arange(k + 1)[:, None, None]).reshape(-1, 3)
    return Vd, Fd, Vc, Fc


@pytest.fixture(scope="module")
def scene():
    """The gravel, its cage's fine surface (Loop, two levels) and the dense
    samples a fit of it asks about (twice the fine vertices)."""
    Vd, Fd, Vc, Fc = gravel()
    op = subdivision_operator(Fc, Vc.shape[0], levels=2, scheme="loop")
    Vf = op.apply(Vc)
    samples = sample_surface(Vd, Fd, 2 * op.n_fine, seed=0).points
    return Vd, Fd, Vc, Fc, Vf, op.F_fine, np.asarray(samples, dtype=np.float64)


def _kernel(V, F, P, faces):
    """The exact kernel's (v, w, d2) of each point of ``P`` on its face of ``faces``."""
    D = triangle_rows(V[F[faces, 0]], V[F[faces, 1]], V[F[faces, 2]])
    n = P.shape[0]
    return closest_pairs(np.ascontiguousarray(P.T), np.arange(n), D, np.arange(n))


def _brute_d2(V, F, P):
    """Each point's smallest squared distance the kernel gives over every triangle."""
    D = triangle_rows(V[F[:, 0]], V[F[:, 1]], V[F[:, 2]])
    q, m = P.shape[0], F.shape[0]
    _, _, d2 = closest_pairs(np.ascontiguousarray(P.T), np.repeat(np.arange(q), m), D,
                             np.tile(np.arange(m), q))
    return d2.reshape(q, m).min(axis=1)


def _assert_exact(V, F, P, r, d2_min):
    """``r`` names, for every point, a face at the smallest distance ``d2_min``
    (bit for bit; any of exactly equidistant faces) and the kernel's closest
    point on it."""
    v, w, d2 = _kernel(V, F, P, r.face)
    np.testing.assert_array_equal(d2, d2_min)
    np.testing.assert_array_equal(r.distance, np.sqrt(d2_min))
    np.testing.assert_array_equal(r.bary[:, 1], np.clip(v, 0, 1))
    np.testing.assert_array_equal(r.bary[:, 2], np.clip(w, 0, 1))


def _one_by_one(monkeypatch):
    """The BVH's groups made groups of one (cubes far smaller than any
    gap between the queries): the search of one query at a time."""
    monkeypatch.setattr(spatial, "_PROBE_CELLS", 2.0 ** -40)
    monkeypatch.setattr(spatial, "_GROUP_SHARE", 2.0 ** -40)
    monkeypatch.setattr(spatial, "_GROUP_LEVELS", 40)


def _spy_groups(monkeypatch):
    """Record the group sizes of every BVH grouping, and the queries the BVH answers."""
    seen = {"sizes": [], "bvh": 0}
    groups, bvh = TriangleIndex._query_groups, TriangleIndex._bvh_query

    def spy_groups(self, PT, q, size):
        out = groups(self, PT, q, size)
        seen["sizes"].append(out[1])
        return out

    def spy_bvh(self, PT, far, best, crowded=0):
        seen["bvh"] += far.size
        return bvh(self, PT, far, best, crowded)
    monkeypatch.setattr(TriangleIndex, "_query_groups", spy_groups)
    monkeypatch.setattr(TriangleIndex, "_bvh_query", spy_bvh)
    return seen


def test_the_cage_is_at_the_floor_and_the_samples_are_far(scene):
    """The scene is what it claims: a closed, consistently oriented cage of
    tetrahedra (its fine surface blobs), and dense samples mostly many of
    the fine surface's cells away from it."""
    Vd, Fd, Vc, Fc, Vf, Ff, P = scene
    assert Fc.shape[0] == 4 * (Vc.shape[0] // 4)
    q = NearQuery(Vf, Ff)
    r = q.closest(P)
    assert np.median(r.distance) > 1.5 * q.index.tables.cell_size


def test_far_samples_get_the_exact_closest_points(monkeypatch, scene):
    """Every kind of search over the fine surface (the fit's NearQuery with
    and without a reach, the plain index) names for every sample a face at
    the brute-force minimum, bit for bit, and the kernel's point on it; the
    BVH answered most of them, by groups of more than one."""
    Vd, Fd, Vc, Fc, Vf, Ff, P = scene
    rng = np.random.default_rng(0)
    pick = rng.choice(P.shape[0], 150, replace=False)
    d2_min = _brute_d2(Vf, Ff, P[pick])
    seen = _spy_groups(monkeypatch)
    r = NearQuery(Vf, Ff).closest(P)
    assert seen["bvh"] > 0.3 * P.shape[0]
    assert max(int(s.max()) for s in seen["sizes"]) >= 10
    reach = float(np.median(r.distance))
    for result in (r, NearQuery(Vf, Ff, reach=reach).closest(P), TriangleIndex(Vf, Ff).closest(P)):
        picked = type(r)(*(a[pick] for a in result))
        _assert_exact(Vf, Ff, P[pick], picked, d2_min)


def test_groups_answer_as_one_query_at_a_time(monkeypatch, scene):
    """The BVH's grouped search gives every query what its search one at a
    time gives, bit for bit: the distance, and the face (among exactly
    equidistant ones the lowest, in either search), the point and its
    barycentric coordinates; most samples went to the BVH (cells of a
    sixth of the default), by groups."""
    Vd, Fd, Vc, Fc, Vf, Ff, P = scene
    seen = _spy_groups(monkeypatch)
    grouped = TriangleIndex(Vf, Ff, cell_factor=spatial.CELL_FACTOR / 6).closest(P)
    assert seen["bvh"] > 0.5 * P.shape[0] and max(int(s.max()) for s in seen["sizes"]) >= 10
    _one_by_one(monkeypatch)
    alone = TriangleIndex(Vf, Ff, cell_factor=spatial.CELL_FACTOR / 6).closest(P)
    for got, want in zip(grouped, alone):
        np.testing.assert_array_equal(got, want)


def test_queries_outside_and_far_from_the_grid_by_groups(scene):
    """Queries a hundred diagonals away, in clusters and alone, through the
    grouped BVH: the brute-force minimum, bit for bit."""
    Vd, Fd, Vc, Fc, Vf, Ff, P = scene
    rng = np.random.default_rng(1)
    d = float(np.linalg.norm(Vf.max(axis=0) - Vf.min(axis=0)))
    centres = rng.normal(size=(6, 3)) * 100 * d
    Q = np.vstack([np.repeat(centres, 20, axis=0) + rng.normal(size=(120, 3)) * d,
                   rng.normal(size=(30, 3)) * 100 * d])
    _assert_exact(Vf, Ff, Q, TriangleIndex(Vf, Ff).closest(Q), _brute_d2(Vf, Ff, Q))


def test_the_fit_equals_the_plain_paths(monkeypatch, scene):
    """The fit of the gravel's cage (its searches by groups, with the last
    match's reach) equals, bit for bit, the fit whose searches take one
    query at a time (the hierarchy's ties go to the lowest face either
    way); and the fit with the default cells but for exact ties (the
    samples near the fine surface: the lowest face; those the index
    answers by its grid: its own rule), within a few ulps."""
    Vd, Fd, Vc, Fc, Vf, Ff, P = scene
    kwargs = dict(levels=2, scheme="loop", iterations=3)
    quick = fit_cage(Vd, Fd, Vc, Fc, **kwargs)
    assert quick.mean_distance[-1] < 0.5 * quick.mean_distance[0]
    _one_by_one(monkeypatch)
    alone = fit_cage(Vd, Fd, Vc, Fc, **kwargs)
    for got, want in zip(quick, alone):
        np.testing.assert_array_equal(got, want)
    monkeypatch.setattr(fit._Matches, "reach", property(lambda self: None))
    plain = fit_cage(Vd, Fd, Vc, Fc, **kwargs)
    np.testing.assert_allclose(quick.V, plain.V, rtol=0, atol=1e-12)
    np.testing.assert_allclose(quick.mean_distance, plain.mean_distance, rtol=1e-12)
    np.testing.assert_array_equal(quick.cg_iterations, plain.cg_iterations)
