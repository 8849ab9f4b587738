"""Tests of core/metrics.py: surface sampling and the Metro surface distance."""

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

import core
from core.errors import InvalidArgumentError, InvalidMeshError
from core import metrics
from core.metrics import DistanceFrom, SurfaceDistance, sample_surface, surface_distance
from core.near_query import NearQuery, search_for
from core.spatial import TriangleIndex
from tests.mesh_factory import cube, icosphere, load_shared, regular_grid, torus


# --- sampling ------------------------------------------------------------------------------------

def test_samples_lie_on_their_faces_and_are_seeded():
    V, F = torus(16, 8)
    s = sample_surface(V, F, 5000, seed=3)
    assert s.points.shape == (5000, 3) and s.face.dtype == np.int64 and s.bary.shape == (5000, 3)
    assert (s.bary >= 0).all() and (s.bary <= 1).all()
    np.testing.assert_allclose(s.bary.sum(axis=1), 1.0, atol=1e-15)
    np.testing.assert_allclose(np.einsum("ij,ijk->ik", s.bary, V[F[s.face]]), s.points, atol=1e-15)
    again = sample_surface(V, F, 5000, seed=3)
    assert (again.points == s.points).all()
    assert not (sample_surface(V, F, 5000, seed=4).points == s.points).all()
    d = TriangleIndex(V, F).closest(s.points).distance
    assert d.max() <= 1e-15 * 10


def test_samples_are_area_weighted():
    """Two triangles, areas 1 : 9: the share of samples follows the areas."""
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 2, 0], [10, 0, 0], [13, 0, 0], [10, 6, 0.0]])
    F = np.array([[0, 1, 2], [3, 4, 5]])
    s = sample_surface(V, F, 200_000, seed=0)
    share = np.mean(s.face == 0)
    assert abs(share - 0.1) < 4 * np.sqrt(0.1 * 0.9 / 200_000)


def test_samples_are_uniform_inside_a_triangle():
    """sqrt trick: the fraction of samples in the sub-triangle near A, scaled by 1/2
    (area 1/4), is 1/4; and the centroid of the samples is the triangle's centroid."""
    V = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]])
    s = sample_surface(V, [[0, 1, 2]], 400_000, seed=1)
    n = s.points.shape[0]
    corner = np.mean(s.points.sum(axis=1) <= 0.5)
    assert abs(corner - 0.25) < 4 * np.sqrt(0.25 * 0.75 / n)
    np.testing.assert_allclose(s.points.mean(axis=0), [1 / 3, 1 / 3, 0], atol=4 / np.sqrt(18 * n))


def test_sampling_zero_area_mesh_and_bad_input():
    V = np.array([[0.0, 0, 0], [1, 0, 0], [2, 0, 0]])
    s = sample_surface(V, [[0, 1, 2], [0, 0, 0]], 100)
    assert np.isfinite(s.points).all() and (s.points[:, 1:] == 0).all()
    with pytest.raises(InvalidArgumentError, match="sample_surface: n_samples must be an integer"):
        sample_surface(V, [[0, 1, 2]], -1)
    with pytest.raises(InvalidArgumentError, match="n_samples must be an integer"):
        sample_surface(V, [[0, 1, 2]], 2.5)
    with pytest.raises(InvalidMeshError, match="sample_surface: the mesh has no faces"):
        sample_surface(V, np.zeros((0, 3), dtype=np.int64), 10)
    assert sample_surface(V, [[0, 1, 2]], 0).points.shape == (0, 3)


# --- the whole-mesh measures of core.mesh ---------------------------------------------------------

MEASURES = {**{name: getattr(core, name) for name in ("face_areas", "face_normals",
                                                      "vertex_normals", "enclosed_volume")},
            "turned_faces": lambda V, F: core.turned_faces(V, V, F)}


@pytest.mark.parametrize("name", list(MEASURES))
def test_measures_check_their_mesh(name):
    V, F = icosphere(1)
    n = V.shape[0]
    measure = MEASURES[name]
    F_neg, F_out, V_nan = F.copy(), F.copy(), V.copy()
    F_neg[3, 1], F_out[5, 2], V_nan[7, 0] = -1, n, np.nan
    with pytest.raises(InvalidMeshError, match=rf"^{name}: 1 faces index vertices outside "
                                               rf"\[0, {n}\), e\.g\. face 3 = \[.*-1"):
        measure(V, F_neg)                                   # not vertex n-1 in silence
    with pytest.raises(InvalidMeshError, match=rf"^{name}: .*e\.g\. face 5 = \[.*{n}\]"):
        measure(V, F_out)
    with pytest.raises(InvalidMeshError, match=rf"^{name}: 1 vertices have NaN .*vertex 7"):
        measure(V_nan, F)
    with pytest.raises(InvalidMeshError, match=rf"^{name}: F must be \(m,3\) integers, "
                                               rf"got \(80, 2\)"):
        measure(V, F[:, :2])
    # lists and float32 are read as float64 (the results too), like everywhere in core
    ref = measure(V, F)
    np.testing.assert_array_equal(measure(V.tolist(), F.tolist()), ref)
    out32 = measure(V.astype(np.float32), F.astype(np.int32))
    assert np.asarray(out32).dtype == np.asarray(ref).dtype
    if name != "turned_faces":
        assert np.asarray(out32).dtype == np.float64


def test_turned_faces_checks_the_shape_of_the_new_positions():
    V, F = icosphere(1)
    with pytest.raises(InvalidMeshError, match=r"turned_faces: V_new must have the shape of V_rest"):
        core.turned_faces(V, V[:-1], F)
    with pytest.raises(InvalidMeshError, match=r"turned_faces: V_new must be \(n,3\) floats"):
        core.turned_faces(V, V[:, :2], F)


# --- surface distance ----------------------------------------------------------------------------

def test_distance_to_itself_is_zero():
    V, F = torus(20, 10)
    d = surface_distance(V, F, V, F, samples=5000)
    assert isinstance(d, SurfaceDistance)
    diag = np.linalg.norm(V.max(0) - V.min(0))
    assert d.hausdorff <= 1e-14 * diag and d.mean <= 1e-14 * diag
    assert d.diagonal == pytest.approx(diag, rel=1e-15)
    assert d.hausdorff_pct <= 1e-12 and d.n_samples == 5000


def test_sphere_vs_scaled_sphere_matches_radius_difference():
    V, F = icosphere(4)                    # 5,120 faces, inscribed in the unit sphere
    d = surface_distance(V, F, 1.1 * V, F, samples=5_000)
    # the polyhedra deviate from the spheres by at most the sagitta of their edges
    edge = np.linalg.norm(V[F[:, 0]] - V[F[:, 1]], axis=1).max()
    sag = 1.1 * (1 - np.cos(edge / 2))
    assert abs(d.hausdorff - 0.1) <= sag
    assert abs(d.mean - 0.1) <= sag and abs(d.rms - 0.1) <= sag
    assert abs(d.a_to_b_mean - 0.1) <= sag and abs(d.b_to_a_mean - 0.1) <= sag
    diag = np.linalg.norm(V.max(0) - V.min(0))
    assert d.diagonal == pytest.approx(diag, rel=1e-15)
    assert d.hausdorff_pct == pytest.approx(100 * d.hausdorff / diag, rel=1e-12)


def test_translated_cube_gives_the_translation_length():
    V, F = cube(2)
    t = 0.1
    d = surface_distance(V, F, V + [t, 0, 0], F, samples=4000)
    # every point of A's -x side is exactly t from B's -x side; nothing is farther
    assert d.hausdorff == pytest.approx(t, rel=1e-12)
    assert d.a_to_b_max == pytest.approx(t, rel=1e-12)
    assert d.b_to_a_max == pytest.approx(t, rel=1e-12)
    assert d.mean < t and d.mean > 0


def test_symmetry_and_scaling():
    V, F = icosphere(3)
    rng = np.random.default_rng(0)
    W = V * (1 + 0.05 * rng.random((V.shape[0], 1)))
    ab = surface_distance(V, F, W, F, samples=3000, seed=5)
    ba = surface_distance(W, F, V, F, samples=3000, seed=5)
    assert ab.hausdorff == ba.hausdorff and ab.mean == ba.mean and ab.rms == ba.rms
    assert ab.a_to_b_max == ba.b_to_a_max and ab.a_to_b_mean == ba.b_to_a_mean
    assert ab.hausdorff >= max(ab.a_to_b_max, ab.b_to_a_max) and ab.rms >= ab.mean
    big = surface_distance(1e3 * V, F, 1e3 * W, F, samples=3000, seed=5)
    assert big.hausdorff == pytest.approx(1e3 * ab.hausdorff, rel=1e-9)
    assert big.mean_pct == pytest.approx(ab.mean_pct, rel=1e-9)


def test_one_sided_distances_of_a_patch_on_a_surface():
    """A patch lying on a larger plane: patch -> plane is 0, plane -> patch is not."""
    Vb, Fb = regular_grid(10, 10, size=2.0)
    Va, Fa = regular_grid(4, 4, size=1.0)
    d = surface_distance(Va, Fa, Vb, Fb, samples=2000)
    assert d.a_to_b_max <= 1e-15 and d.a_to_b_mean <= 1e-15
    assert d.b_to_a_max == pytest.approx(np.sqrt(2.0), rel=1e-12)   # corner (2,2) to (1,1)
    assert d.hausdorff == d.b_to_a_max


def test_default_sample_count_and_bad_input():
    V, F = icosphere(1)
    assert surface_distance(V, F, V, F).n_samples == 10_000
    with pytest.raises(InvalidArgumentError, match="surface_distance: samples must be an integer"):
        surface_distance(V, F, V, F, samples=-5)
    with pytest.raises(InvalidMeshError,
                       match=r"surface_distance \(mesh b\): the mesh has no faces"):
        surface_distance(V, F, V, np.zeros((0, 3), dtype=np.int64))
    with pytest.raises(InvalidMeshError, match=r"surface_distance \(mesh a\)"):
        surface_distance(V + np.nan, F, V, F)
    d = surface_distance(V, F, 2 * V, F, samples=0)          # vertices only
    assert d.hausdorff == pytest.approx(1.0, rel=1e-12)


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 2**32 - 1))
def test_property_bounds_and_triangle_inequality(seed):
    """0 <= mean <= rms <= hausdorff; a rigid translation by t gives hausdorff <= |t|."""
    rng = np.random.default_rng(seed)
    V, F = torus(10, 6)
    W = V + rng.normal(size=V.shape) * 0.02
    t = rng.normal(size=3) * 0.1
    d = surface_distance(V, F, W, F, samples=500, seed=seed)
    assert 0 <= d.a_to_b_mean <= d.a_to_b_rms <= d.a_to_b_max + 1e-15
    assert 0 <= d.mean <= d.rms <= d.hausdorff + 1e-15
    moved = surface_distance(W, F, W + t, F, samples=500, seed=seed)
    assert moved.hausdorff <= np.linalg.norm(t) * (1 + 1e-12)


def test_both_searches_give_the_same_distances_and_each_is_used_where_it_is_faster():
    # a bumpy torus against a coarse copy: the near-surface search and the plain index
    # give the same one-sided distances, bit for bit; the near search is taken where
    # the queries are at least as many as the faces
    rng = np.random.default_rng(2)
    V, F = torus(60, 30, bump=0.1)
    V = V + 0.002 * rng.standard_normal(V.shape)
    Vc, Fc = torus(12, 6)
    for (Vt, Ft), (Vq, Fq) in (((V, F), (Vc, Fc)), ((Vc, Fc), (V, F))):
        samples = sample_surface(Vq, Fq, 20000, seed=1).points
        near = metrics._one_side(NearQuery(Vt, Ft), samples, Vq)
        plain = metrics._one_side(TriangleIndex(Vt, Ft), samples, Vq)
        assert near == plain
    m = F.shape[0]
    assert isinstance(search_for(V, F, 10), TriangleIndex)
    assert isinstance(search_for(V, F, m - 1), TriangleIndex)
    assert isinstance(search_for(V, F, m), NearQuery)


def test_distance_from_one_mesh_to_many_is_surface_distance_and_builds_its_search_once():
    # simplify(max_error=...) measures each step's cage against one input: DistanceFrom
    # keeps the input's search (one of each kind) and samples, and every result is
    # surface_distance's, bit for bit, whatever came before (sample counts, seeds, cages
    # with fewer and more faces than it: both kinds of search)
    V, F = torus(60, 30, bump=0.1)
    source = DistanceFrom(V, F)
    cages = [torus(k, k // 2) for k in (8, 12, 20, 90)]
    asks = [dict(), dict(samples=0), dict(samples=3000, seed=4), dict()]
    kept = None
    for round_ in range(2):
        for (Vc, Fc), ask in zip(cages, asks):
            assert source.to(Vc, Fc, **ask) == surface_distance(V, F, Vc, Fc, **ask)
        if kept is None:
            kept = dict(source._searches)
    assert set(kept) == {NearQuery, TriangleIndex}
    assert all(source._searches[kind] is search for kind, search in kept.items())
    with pytest.raises(InvalidMeshError, match="surface_distance \\(mesh b\\)"):
        source.to(V, F[:, :2])


def test_shared_faces_are_not_searched_and_the_distances_stay_surface_distance_s():
    """``DistanceFrom.to(shared=...)``: a copy of a bumpy torus with a patch
    moved and re-triangulated keeps most faces of the original; leaving their
    samples out (distance 0) gives surface_distance's maxima bit for bit and
    its means and RMS to rounding, and searches only the samples off them."""
    V, F = torus(60, 30, bump=0.1)
    rng = np.random.default_rng(2)
    W = V.copy()
    patch = np.flatnonzero(np.linalg.norm(V - V[17], axis=1) < 0.4)
    W[patch] += 0.02 * rng.standard_normal((patch.size, 3))
    G = F.copy()
    G[:40] = G[:40, [0, 2, 1]]                 # (another winding: still the same triangles)
    W = np.concatenate([W, [[5.0, 5.0, 5.0]]])  # (an unused vertex of its own)
    on_b = ~np.isin(G, patch).any(axis=1)
    on_a = on_b.copy()
    source = DistanceFrom(V, F)
    searched = []
    real = metrics.search_for
    try:
        metrics.search_for = lambda V_, F_, n: (searched.append(n), real(V_, F_, n))[1]
        for ask in (dict(), dict(samples=0), dict(samples=5000, seed=3)):
            whole = source.to(W, G, **ask)
            n_whole = searched[-1]
            part = source.to(W, G, shared=(on_a, on_b), **ask)
            n_part = searched[-1]
            assert whole == surface_distance(V, F, W, G, **ask)
            assert (part.hausdorff, part.a_to_b_max, part.b_to_a_max) == \
                (whole.hausdorff, whole.a_to_b_max, whole.b_to_a_max) and whole.hausdorff > 0.01
            for k in ("mean", "rms", "a_to_b_mean", "b_to_a_mean", "a_to_b_rms", "b_to_a_rms"):
                assert getattr(part, k) == pytest.approx(getattr(whole, k), rel=1e-12, abs=1e-15)
            assert n_part < 0.2 * n_whole
    finally:
        metrics.search_for = real
    nothing = np.zeros(F.shape[0], dtype=bool)
    assert source.to(W, G, shared=(nothing, nothing)) == source.to(W, G)
    # masks of 0/1 integers or lists are booleans (an int mask's ~ had indexed the last face);
    # anything else is refused, naming it
    zeros = np.zeros(F.shape[0], dtype=np.int64)
    assert source.to(W, G, shared=(zeros, list(zeros))) == source.to(W, G)
    for bad, what in (((nothing.astype(float), nothing), r"shared\[0\] must be \(%d,\) booleans "
                       r"\(one per face of mesh a\), got \(%d,\) float64" % (len(F), len(F))),
                      ((nothing, nothing[:-1]), r"shared\[1\] must be \(%d,\) booleans" % len(G)),
                      ((nothing,), r"shared must be a pair \(on_a, on_b\) of face masks"),
                      (nothing, r"shared must be a pair")):
        with pytest.raises(InvalidArgumentError, match=what):
            source.to(W, G, shared=bad)


def test_real_mesh_bunny_vs_perturbed_copy():
    V, F = load_shared("stanford-bunny.obj")
    used = np.unique(F)
    diag = np.linalg.norm(V[used].max(0) - V[used].min(0))
    rng = np.random.default_rng(0)
    eps = 1e-3 * diag
    W = V + rng.uniform(-1, 1, size=V.shape) * eps        # each coordinate moved by <= eps
    d = surface_distance(V, F, W, F, samples=50_000)
    assert d.hausdorff <= np.sqrt(3) * eps * (1 + 1e-9)  # no point moved farther than that
    assert 0.05 * eps < d.mean < eps
    assert d.hausdorff_pct == pytest.approx(100 * d.hausdorff / diag, rel=1e-12)
    # the unperturbed copy is at distance 0
    assert surface_distance(V, F, V, F, samples=20_000).hausdorff <= 1e-12 * diag


def test_enclosed_volume_scales_as_the_cube_of_the_size_and_names_what_floats_cannot_hold():
    # the coordinates are scaled by a power of two before the products: the same
    # bits at ordinary sizes, and beyond the floats inf (it was NaN: inf - inf)
    V, F = icosphere(3)
    v = core.enclosed_volume(V, F)
    assert v > 0 and core.enclosed_volume(V, F[:, ::-1]) == -v
    for s in (2.0 ** 40, 2.0 ** -40, 3.0):
        assert core.enclosed_volume(V * s, F) == pytest.approx(v * s ** 3, rel=1e-14)
    assert core.enclosed_volume(V * 1e150, F) == np.inf
    assert core.enclosed_volume(V * 1e150, F[:, ::-1]) == -np.inf
    assert core.enclosed_volume(V * 1e-150, F) == 0.0
    assert core.enclosed_volume(V, F[:0]) == 0.0


@pytest.mark.parametrize("s", [1e200, 1e-200, 2.0 ** 600, 2.0 ** -600])
def test_normals_and_areas_are_found_at_any_scale(s):
    # normals do not depend on the size: at 1e200 the cross products overflowed (inf - inf
    # gave NaN normals and NaN areas), at 1e-200 they underflowed (zero normals)
    V, F = icosphere(2)
    V = V + [0.3, -0.2, 0.1]                            # no coordinate a power of two
    for fn in (core.vertex_normals, core.face_normals):
        N, Ns = fn(V, F), fn(V * s, F)
        np.testing.assert_allclose(Ns, N, rtol=0, atol=1e-15)
        np.testing.assert_allclose(np.linalg.norm(Ns, axis=1), 1.0, rtol=0, atol=1e-15)
    A, As = core.face_areas(V, F), core.face_areas(V * s, F)
    if s > 1e150:                                         # beyond the floats: inf, never NaN
        assert np.isposinf(As).all()
        assert np.isposinf(core.face_normals(V * s, F, normalize=False)).any()
    else:
        np.testing.assert_allclose(As, A * s * s, rtol=1e-14)
    # a power of two leaves the same bits at ordinary sizes
    assert (core.face_areas(V * 2.0 ** 30, F) == A * 2.0 ** 60).all()
    assert (core.vertex_normals(V * 2.0 ** 30, F) == core.vertex_normals(V, F)).all()


def test_scale_of_meshes_without_faces_or_extent():
    V = np.zeros((3, 3))
    F = np.array([[0, 1, 2]])
    assert core.face_areas(V, F).tolist() == [0.0]
    assert core.vertex_normals(V, F).tolist() == [[0.0] * 3] * 3
    assert core.face_areas(V, F[:0]).shape == (0,)


@settings(max_examples=60, deadline=None)
@given(st.integers(1, 40), st.lists(st.tuples(st.integers(0, 39), st.integers(0, 39),
                                              st.integers(0, 39)), max_size=30))
def test_used_vertices_is_unique_of_the_faces(n, faces):
    from core.mesh import used_vertices
    F = np.array([f for f in faces if max(f) < n], dtype=np.int64).reshape(-1, 3)
    got = used_vertices(F, n)
    assert got.dtype == np.int64 and got.tolist() == np.unique(F).tolist()


def test_surface_diagonal_names_a_bad_face():
    V, F = cube(2)
    assert core.surface_diagonal(V, F) == pytest.approx(core.bbox_diagonal(V))
    far = np.vstack([V, [[50.0, 50.0, 50.0]]])                 # a loose vertex: not counted
    assert core.surface_diagonal(far, F) == core.surface_diagonal(V, F)
    for bad in (F - 1, F + V.shape[0]):
        with pytest.raises(InvalidMeshError, match="surface_diagonal: .*faces index vertices"):
            core.surface_diagonal(V, bad)


def test_the_reverse_side_takes_cells_for_its_distances_and_measures_the_same():
    # few samples on a large mesh: its index's cells are sized for the other side's mean
    # distance when that is a few of its edges (the cage's samples are then answered in
    # the grid, not in a hierarchy built for them), the default otherwise; the
    # distances are the same bits either way
    V, F = torus(400, 100, bump=0.01)                       # 80k faces
    for target, wider in ((500, True), (8000, False)):
        cage = core.simplify(V, F, target_faces=target)
        sized = DistanceFrom(V, F)
        plain = DistanceFrom(V, F)
        plain._searches[TriangleIndex] = TriangleIndex(V, F)
        got, want = sized.to(cage.V, cage.F, samples=5000), plain.to(cage.V, cage.F, samples=5000)
        assert tuple(got) == tuple(want)
        h, h0 = sized._searches[TriangleIndex]._h, plain._searches[TriangleIndex]._h
        assert (h > 1.2 * h0) if wider else (h == h0)


def test_both_sides_of_a_mesh_of_needles_say_how_many_queries_they_answer():
    """A CAD cylinder's caps are fans of needles: the search of either side
    answering at least 3 queries a face takes the needles' finer cells
    (``NearQuery(queries=...)``); the reverse side, kept by the
    DistanceFrom, had been made without its count. The same distances."""
    from core.near_query import NEEDLE_CELL_FACTOR
    from tests.mesh_factory import cad_cylinder
    V, F = cad_cylinder(500, height=1.0)
    cage = core.simplify(V, F, target_faces=200)
    source = DistanceFrom(V, F)
    got = source.to(cage.V, cage.F, samples=4 * F.shape[0])
    reverse = source._searches[NearQuery]
    assert reverse._t is None and reverse.index.tables.cell_size == TriangleIndex(
        V, F, cell_factor=NEEDLE_CELL_FACTOR).tables.cell_size
    plain = DistanceFrom(V, F)
    plain._searches[NearQuery] = NearQuery(V, F)
    assert tuple(got) == tuple(plain.to(cage.V, cage.F, samples=4 * F.shape[0]))


def test_shares_of_the_size_keep_two_significant_digits():
    """A CAD part's cage 8e-6 of its size off read "max deviation 0.00% of
    size": small shares keep two significant digits, larger ones two
    decimals (the add-on's and the batch CLI's reports)."""
    from core import percent
    assert [percent(x) for x in (0.0, 0.0065, 0.003, 3.5e-4, 8e-6, 1e-3, 0.12, 1.0)] == \
        ["0%", "0.65%", "0.30%", "0.035%", "0.00080%", "0.10%", "12.00%", "100.00%"]
    assert percent(-2.5e-5) == "-0.0025%" and percent(float("nan")) == "nan%"
    assert percent(1e-12) == "under 0.000001%"


def test_a_loose_vertex_far_away_is_not_measured_nor_refused():
    """A vertex in no face at 1e20 beside a sphere (a stray point of a scan):
    the units check read every vertex and refused the measure ('mesh a
    reaches 1e+20'), which failed the add-on's report of a simplify that had
    left the vertex out. Only the faces' vertices are measured and checked;
    a face's vertex that far is still refused."""
    from core import InvalidMeshError, simplify, surface_distance
    from tests.mesh_factory import icosphere
    V, F = icosphere(3)
    far = np.vstack([V, [[1e20, 0.0, 0.0]]])
    cage = simplify(far, F, target_faces=100)
    for a, b in (((far, F), (cage.V, cage.F)), ((cage.V, cage.F), (far, F))):
        d = surface_distance(*a, *b)
        assert d == surface_distance(*(x if x is not far else V for x in a),
                                     *(x if x is not far else V for x in b))
    with pytest.raises(InvalidMeshError, match="mesh a reaches 1e\\+20"):
        surface_distance(far, np.vstack([F, [[0, 1, V.shape[0]]]]), cage.V, cage.F)
