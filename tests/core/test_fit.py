"""Tests of core.cg (conjugate gradients) and core.fit (fit_cage)."""

import numpy as np
import pytest

from core.fit import fit_cage
from core.cg import conjugate_gradient
from core.errors import InvalidArgumentError, InvalidMeshError
from core.mesh import bbox_diagonal, enclosed_volume
from core.spatial import closest_points
from core.subdivide import subdivision_operator
from tests.mesh_factory import icosphere, load_shared, torus


# ------------------------------------------------------------------ conjugate gradients
def _spd(n, seed, cond=100.0):
    rng = np.random.default_rng(seed)
    Q, _ = np.linalg.qr(rng.standard_normal((n, n)))
    return Q @ np.diag(np.geomspace(1.0, cond, n)) @ Q.T


def test_cg_solves_several_right_hand_sides():
    M = _spd(40, 0)
    B = np.random.default_rng(1).standard_normal((40, 3))
    r = conjugate_gradient(lambda X: M @ X, B, rtol=1e-12, max_iterations=200)
    assert r.converged and r.X.shape == (40, 3) and r.residual.shape == (3,)
    assert np.allclose(r.X, np.linalg.solve(M, B), rtol=1e-9, atol=1e-10)
    assert r.iterations <= 80  # exact arithmetic would need <= 40


def test_cg_vector_warm_start_and_preconditioner():
    M = _spd(30, 2, cond=1e4)
    b = np.random.default_rng(3).standard_normal(30)
    x = np.linalg.solve(M, b)
    r = conjugate_gradient(lambda v: M @ v, b, X0=x, rtol=1e-10)
    assert r.iterations == 0 and r.X.shape == (30,)
    d = np.diag(M)
    r = conjugate_gradient(lambda v: M @ v, b, rtol=1e-10, max_iterations=500,
                           preconditioner=lambda v: v / d)
    assert r.converged and np.allclose(r.X, x, rtol=1e-7, atol=1e-9)


def test_cg_zero_rhs_and_iteration_cap():
    M = _spd(10, 4)
    r = conjugate_gradient(lambda v: M @ v, np.zeros((10, 2)))
    assert r.iterations == 0 and np.array_equal(r.X, np.zeros((10, 2))) and r.converged
    r = conjugate_gradient(lambda v: M @ v, np.ones(10), max_iterations=2, rtol=1e-14)
    assert r.iterations == 2 and not r.converged


def test_cg_bad_arguments():
    with pytest.raises(InvalidArgumentError, match="rtol"):
        conjugate_gradient(lambda v: v, np.ones(3), rtol=0)
    with pytest.raises(InvalidArgumentError, match="X0"):
        conjugate_gradient(lambda v: v, np.ones(3), X0=np.ones(4))
    with pytest.raises(InvalidArgumentError, match="max_iterations"):
        conjugate_gradient(lambda v: v, np.ones(3), max_iterations=-1)


# ------------------------------------------------------------------ fit on built meshes
@pytest.fixture(scope="module")
def sphere_case():
    Vd, Fd = icosphere(4)           # the dense "scan": the unit sphere
    Vc, Fc = icosphere(1)           # a cage with vertices on the sphere, faces inside it
    return Vd, Fd, Vc, Fc


def _fine_distance(Vd, Fd, Vc, Fc, levels=2):
    op = subdivision_operator(Fc, Vc.shape[0], levels=levels)
    Vf = op.apply(Vc)
    return (closest_points(Vd, Fd, Vf).distance.mean(),
            enclosed_volume(Vf, op.F_fine))


def test_fit_moves_an_inscribed_cage_onto_the_sphere(sphere_case):
    Vd, Fd, Vc, Fc = sphere_case
    r = fit_cage(Vd, Fd, Vc, Fc, levels=2, iterations=6)
    assert r.V.shape == Vc.shape and r.V.dtype == np.float64
    # (it stops once a step would not bring it closer: converged after 3 here)
    assert 2 <= r.cg_iterations.shape[0] == r.mean_distance.shape[0] - 1 <= 6
    assert r.diagonal == pytest.approx(bbox_diagonal(Vd))
    d0, vol0 = _fine_distance(Vd, Fd, Vc, Fc)
    d1, vol1 = _fine_distance(Vd, Fd, r.V, Fc)
    vol = enclosed_volume(Vd, Fd)
    assert d1 * 1.5 <= d0
    assert abs(vol1 - vol) < 0.5 * abs(vol0 - vol)
    assert r.mean_distance[-1] < 0.7 * r.mean_distance[0]
    # the cage moved outward everywhere, and stays a round cage
    radius = np.linalg.norm(r.V, axis=1)
    assert (radius > 1.0).all() and radius.std() < 0.02 * radius.mean()


def test_the_dense_index_cells_change_no_fit(monkeypatch):
    """The dense surface's index has cells of at least a median fine edge
    (_DENSE_CELL_EDGES): the answers are exact either way, so the fit is the
    one the default cells give (to rounding: a closest point on a shared
    edge may come from either face)."""
    import core.fit as fit_module
    from core.spatial import TriangleIndex
    Vd, Fd = torus(96, 48, bump=0.01, bump_waves=(12, 6))
    Vc, Fc = torus(12, 6)
    cells = []

    def recording(V, F, **kw):
        index = TriangleIndex(V, F, **kw)
        cells.append(index.tables.cell_size)
        return index
    monkeypatch.setattr(fit_module, "TriangleIndex", recording)
    wide = fit_cage(Vd, Fd, Vc, Fc, levels=2, iterations=3)
    monkeypatch.setattr(fit_module, "TriangleIndex", lambda V, F, **kw: recording(V, F))
    plain = fit_cage(Vd, Fd, Vc, Fc, levels=2, iterations=3)
    n = len(cells) // 2                       # the dense index first, then one per iteration
    assert cells[0] > cells[n]
    op = subdivision_operator(Fc, Vc.shape[0], levels=2)
    Vf = op.apply(Vc)
    edge = np.median(np.linalg.norm(Vf[op.F_fine] - Vf[op.F_fine[:, [1, 2, 0]]], axis=2))
    assert cells[0] >= fit_module._DENSE_CELL_EDGES * edge * (1 - 1e-12)
    np.testing.assert_allclose(wide.V, plain.V, rtol=0, atol=1e-12 * wide.diagonal)
    np.testing.assert_allclose(wide.mean_distance, plain.mean_distance, rtol=1e-12)


@pytest.mark.parametrize("shape, faces, scheme", [("cube", 100, "loop"),
                                                   ("cylinder", 800, "butterfly")])
def test_a_fit_at_its_fixed_point_stops_with_the_result_of_every_iteration(monkeypatch, shape,
                                                                          faces, scheme):
    """Once a solve gives the cage back bit for bit and its correspondences
    were matched with the reach they give the next match, every later
    iteration repeats that one: the fit stops there, with the cage and the
    records (distances and CG iterations, one per iteration asked for) of
    the whole loop, bit for bit, in fewer matches (a CAD cylinder's fit
    converges in a few steps; a cube's cage is already on the cube)."""
    import core.fit as fit_module
    from core.simplify import simplify
    from tests.mesh_factory import cad_cylinder, cube
    V, F = cube(8) if shape == "cube" else cad_cylinder(1000, height=1.0)
    cage = simplify(V, F, target_faces=faces)
    calls = []
    match = fit_module._match

    def counted(*args, **kwargs):
        calls.append(1)
        return match(*args, **kwargs)
    monkeypatch.setattr(fit_module, "_match", counted)

    def fit():
        calls.clear()
        return fit_cage(V, F, cage.V, cage.F, levels=2, scheme=scheme, iterations=8,
                        creases=cage.feature_edges)
    short = fit()
    n_short = len(calls)
    monkeypatch.setattr(fit_module, "_fixed_point", lambda *args: False)
    whole = fit()
    assert len(calls) == 9 and n_short <= 6
    assert short.cg_iterations.shape == (8,) and short.cg_iterations[-1] == 0
    for a, b in zip(short, whole):
        np.testing.assert_array_equal(a, b)


def test_a_dense_mesh_of_needles_is_matched_on_cells_a_third_as_wide(monkeypatch):
    """A CAD cylinder (caps fans of needles, sides strips): its index with
    the fit's cells (a fine edge wide) is a grid of needles, hundreds in a
    cell; the fit matches on cells of NEEDLE_CELL_FACTOR extents instead.
    The answers are exact either way: the same fit to rounding."""
    import core.fit as fit_module
    from core.near_query import NEEDLE_CELL_FACTOR, needle_grid
    from core.simplify import simplify
    from core.spatial import TriangleIndex
    from tests.mesh_factory import cad_cylinder
    V, F = cad_cylinder(1000, height=1.0)
    cage = simplify(V, F, target_faces=400)
    built = []

    def recording(V, F, **kw):
        index = TriangleIndex(V, F, **kw)
        built.append((kw, index))
        return index
    monkeypatch.setattr(fit_module, "TriangleIndex", recording)
    fine = fit_cage(V, F, cage.V, cage.F, levels=2, iterations=3, creases=cage.feature_edges)
    (first, wide), (second, narrow) = built
    assert needle_grid(wide.tables) and "min_cell" in first
    assert second == {"cell_factor": NEEDLE_CELL_FACTOR}
    assert narrow.tables.cell_size < 0.5 * wide.tables.cell_size
    monkeypatch.setattr(fit_module, "needle_grid", lambda tables: False)
    plain = fit_cage(V, F, cage.V, cage.F, levels=2, iterations=3, creases=cage.feature_edges)
    assert len(built) == 3
    np.testing.assert_allclose(fine.V, plain.V, rtol=0, atol=1e-12 * fine.diagonal)
    np.testing.assert_allclose(fine.mean_distance, plain.mean_distance, rtol=1e-12)
    Vb, Fb = torus(48, 24, bump=0.01)                 # (a smooth mesh: no needles)
    assert not needle_grid(TriangleIndex(Vb, Fb).tables)


def test_fit_recovers_a_cage_whose_subdivision_is_the_dense_mesh():
    Vc, Fc = torus(10, 6)
    op = subdivision_operator(Fc, Vc.shape[0], levels=2)
    Vd, Fd = op.apply(Vc), op.F_fine
    rng = np.random.default_rng(0)
    start = Vc + 0.01 * rng.standard_normal(Vc.shape)
    r = fit_cage(Vd, Fd, start, Fc, levels=2, iterations=10, smoothness=0.0)
    # the surface is recovered (the cage may slide along it: only the
    # surface is determined by the data)
    assert r.mean_distance[-1] < 0.1 * r.mean_distance[0]
    assert r.mean_distance[-1] < 1e-4 * bbox_diagonal(Vd)


def test_fit_is_equivariant_under_similarity(sphere_case):
    # (a noisy sphere and a randomly turned cage: on symmetric inputs the
    # closest points have exact ties, which rounding may break either way)
    Vd, Fd, Vc, Fc = sphere_case
    rng = np.random.default_rng(7)
    Vd = Vd * (1 + 0.01 * rng.standard_normal((Vd.shape[0], 1)))
    Q, _ = np.linalg.qr(rng.standard_normal((3, 3)))
    Vc = 0.95 * Vc @ Q.T
    r = fit_cage(Vd, Fd, Vc, Fc, levels=1, iterations=2)
    s, t = 250.0, np.array([10.0, -3.0, 7.0])
    r2 = fit_cage(s * Vd + t, Fd, s * Vc + t, Fc, levels=1, iterations=2)
    assert np.abs(r2.V - (s * r.V + t)).max() <= 1e-6 * s
    assert np.allclose(r2.mean_distance, s * r.mean_distance, rtol=1e-6)


def test_fit_with_zero_iterations_returns_the_input(sphere_case):
    Vd, Fd, Vc, Fc = sphere_case
    r = fit_cage(Vd, Fd, Vc, Fc, levels=1, iterations=0)
    assert np.array_equal(r.V, Vc) and r.mean_distance.shape == (1,)
    assert r.cg_iterations.shape == (0,)


def test_strong_smoothness_keeps_the_cage_shape(sphere_case):
    # the smoothness term acts on the cage's displacement: a huge weight only
    # allows displacements with zero Laplacian (a translation), so the shape stays
    Vd, Fd, Vc, Fc = sphere_case
    Vc = 0.9 * Vc
    r = fit_cage(Vd, Fd, Vc, Fc, levels=1, iterations=2, smoothness=1e8, laplacian="cotangent")
    d = r.V - Vc
    assert np.abs(d - d.mean(axis=0)).max() < 1e-3


def test_fit_does_not_modify_inputs(sphere_case):
    Vd, Fd, Vc, Fc = (a.copy() for a in sphere_case)
    fit_cage(Vd, Fd, Vc, Fc, levels=1, iterations=1)
    for a, b in zip((Vd, Fd, Vc, Fc), sphere_case):
        assert np.array_equal(a, b)


def test_fit_bad_arguments(sphere_case):
    Vd, Fd, Vc, Fc = sphere_case
    with pytest.raises(InvalidArgumentError, match="fit_cage: smoothness"):
        fit_cage(Vd, Fd, Vc, Fc, smoothness=-1)
    with pytest.raises(InvalidArgumentError, match="fit_cage: iterations"):
        fit_cage(Vd, Fd, Vc, Fc, iterations=-2)
    with pytest.raises(InvalidArgumentError, match="laplacian"):
        fit_cage(Vd, Fd, Vc, Fc, laplacian="harmonic")
    with pytest.raises(InvalidMeshError, match="fit_cage: F_dense must be"):
        fit_cage(Vd, Fd.astype(float), Vc, Fc)


# ------------------------------------------------------------------ real meshes
def _qem_cage(V, F, faces):
    from core.simplify import simplify
    r = simplify(V, F, target_faces=faces)
    creases = getattr(r, "feature_edges", None)
    return r.V, r.F, creases


@pytest.mark.slow
def test_fit_undoes_qem_shrinkage_on_the_bunny():
    from core.metrics import surface_distance
    Vd, Fd = load_shared("stanford-bunny.obj")
    Vc, Fc, creases = _qem_cage(Vd, Fd, 2000)
    r = fit_cage(Vd, Fd, Vc, Fc, levels=2, scheme="butterfly", creases=creases)
    op = subdivision_operator(Fc, Vc.shape[0], levels=2, scheme="butterfly", creases=creases)
    before = surface_distance(Vd, Fd, op.apply(Vc), op.F_fine)
    after = surface_distance(Vd, Fd, op.apply(r.V), op.F_fine)
    assert after.mean * 1.5 <= before.mean


@pytest.mark.slow
@pytest.mark.parametrize("name", ["homer.obj", "rocker-arm.obj", "spot.obj"])
def test_fit_restores_the_enclosed_volume(name):
    Vd, Fd = load_shared(name)
    Vc, Fc, creases = _qem_cage(Vd, Fd, 2000)
    r = fit_cage(Vd, Fd, Vc, Fc, levels=2, scheme="butterfly", creases=creases)
    op = subdivision_operator(Fc, Vc.shape[0], levels=2, scheme="butterfly", creases=creases)
    vol = enclosed_volume(Vd, Fd)
    assert abs(enclosed_volume(op.apply(r.V), op.F_fine) - vol) <= 0.002 * abs(vol)


def test_progress_reports_and_cancels():
    from tests.mesh_factory import icosphere as _ico
    V, F = _ico(3)
    Vc, Fc = _ico(1)
    seen = []
    r = fit_cage(V, F, Vc * 0.9, Fc, levels=2, iterations=4, progress=lambda f: seen.append(f))
    assert seen == [0.2, 0.4, 0.6, 0.8] and not r.cancelled
    r = fit_cage(V, F, Vc * 0.9, Fc, levels=2, iterations=4, progress=lambda f: f < 0.3)
    assert r.cancelled and r.cg_iterations.shape[0] == 2


@pytest.mark.parametrize("step", ["fit_cage", "bind"])
def test_a_triangle_soup_cage_is_refused_naming_its_pieces(step):
    # spot as an unwelded soup jittered by 1% of its size: no weld joins it, so
    # simplify stops at its topology floor with every face its own piece; fitting that
    # "cage" took 10 s (162 s jittered by 30%) for nothing: refused, saying what to do
    from core.binding import bind
    from core.simplify import simplify
    from tests.mesh_factory import unwelded
    V, F = unwelded(*load_shared("spot.obj"), jitter=0.01)
    r = simplify(V, F, target_faces=1000)
    assert r.stopped_because == "topology_floor" and r.n_components == r.F.shape[0]
    run = {"fit_cage": fit_cage, "bind": bind}[step]
    with pytest.raises(InvalidMeshError, match=(
            rf"{step}: the cage is {r.F.shape[0]:,} separate pieces for its "
            rf"{r.F.shape[0]:,} faces, a triangle soup.*weld the source first")):
        run(V, F, r.V, r.F, levels=1)


def test_a_cage_in_pieces_from_a_source_that_is_not_a_soup_is_fitted_and_bound():
    # the beetle beside a copy of itself 1e-4 of its size off (an object exported twice,
    # moved): asked for 4 faces, its cage is 44 faces in 36 pieces at their floor, as a
    # soup's would be, but its source is 36 pieces of 2,291 faces: no soup note, and
    # fit_cage and bind take it
    from core.binding import bind
    from core.simplify import simplify
    from tests.mesh_factory import duplicated
    V, F = duplicated(*load_shared("beetle.obj"), offset=1e-4, seed=98)
    r = simplify(V, F, target_faces=4)
    assert r.n_components >= 32 and r.n_components > r.F.shape[0] / 2
    assert r.n_input_pieces is None and r.soup_note == "" and "weld it first" not in r.message
    fitted = fit_cage(V, F, r.V, r.F, levels=1)
    assert np.isfinite(fitted.V).all()
    assert bind(V, F, fitted.V, r.F, levels=1).n_dense == V.shape[0]


def test_a_cage_of_many_small_closed_pieces_is_not_a_soup():
    # 40 separate octahedra (a pebble field): 40 pieces for 320 faces is a cage
    from core.binding import bind, deform
    from tests.mesh_factory import octahedron
    Vo, Fo = octahedron()
    shift = np.repeat(3.0 * np.arange(40), 3).reshape(40, 3) * [1.0, 0.0, 0.0]
    V = np.concatenate([Vo + s for s in shift])
    F = np.concatenate([Fo + k * Vo.shape[0] for k in range(40)])
    fitted = fit_cage(V, F, V, F, levels=1, iterations=1)
    assert fitted.V.shape == V.shape and np.isfinite(fitted.V).all()
    b = bind(V, F, V, F, levels=1)
    np.testing.assert_allclose(deform(b, V), V, atol=1e-12 * bbox_diagonal(V))


@pytest.mark.parametrize("scheme", ["loop", "butterfly"])
def test_the_preconditioner_blocks_are_the_normal_matrix_block_row_sums(scheme):
    """The conjugate gradients' preconditioner: its 3x3 block of each cage
    vertex is its block row of the normal matrix summed (``A`` applied to
    every vertex moved by one along x, y, z; the Laplacian's rows sum to 0),
    and each inverse is of that block plus the Laplacian's diagonal, raised
    only where its Gershgorin bound fell below the floor (to it)."""
    import core.fit as fit_module
    Vd, Fd = torus(48, 24, bump=0.02, bump_waves=(8, 4))
    Vc, Fc = torus(8, 5)
    pb = fit_module._set_up(Vd, Fd, Vc * 0.97, Fc, levels=2, scheme=scheme, creases=None,
                            smoothness=0.05, point_to_point=0.1, laplacian="uniform",
                            samples=None, seed=0, symmetry=None, iterations=1)
    m = fit_module._match(pb, pb.X0)
    A, rhs, blocks = fit_module._normal_equations(pb, m)
    n = pb.X0.shape[0]
    for k in range(3):
        e = np.zeros((n, 3))
        e[:, k] = 1.0
        np.testing.assert_allclose(A(e.ravel()).reshape(n, 3), blocks[:, :, k],
                                   rtol=1e-9, atol=1e-12 * np.abs(blocks).max())
    np.testing.assert_allclose(blocks, blocks.transpose(0, 2, 1), atol=1e-15)
    rows, cols, w = pb.laplacian
    diagonal = pb.lam * fit_module._lt_l_diagonal(rows, cols, w, n)
    inv = fit_module._inverse_blocks(blocks, diagonal)
    full = blocks + diagonal[:, None, None] * np.eye(3)
    floor = 1e-3 * np.einsum("nii->n", full).max() / 3
    d = np.einsum("nii->ni", full)
    low = (d - (np.abs(full).sum(axis=2) - np.abs(d))).min(axis=1)    # Gershgorin
    raised = np.linalg.inv(inv) - full                  # t I, t = floor - that bound where below
    t = np.maximum(floor - low, 0.0)
    np.testing.assert_allclose(raised, t[:, None, None] * np.eye(3), atol=1e-9 * np.abs(full).max())
    assert (np.linalg.eigvalsh(full + t[:, None, None] * np.eye(3))[:, 0] >= floor * (1 - 1e-9)).all()
    assert (t == 0).sum() >= 0.5 * n
    # a singular block (no data, no Laplacian) is raised to the floor, not inverted as is
    flat = np.zeros((2, 3, 3))
    flat[0] = np.diag([1.0, 1.0, 0.0])
    inv = fit_module._inverse_blocks(flat, np.zeros(2))
    assert np.isfinite(inv).all() and (np.linalg.eigvalsh(inv) > 0).all()


# ------------------------------------------------------------------ simplify's cleaned input
def test_simplify_keeps_its_cleaned_input_and_a_fit_to_it_is_the_fit_that_cleans():
    # an unwelded, jittered-free icosphere: simplify's cleaning and the fit's own weld
    # the same seams, so fitting the kept surface without cleaning it again gives the
    # fit of the messy input bit for bit
    from core.clean import clean_mesh
    from core.simplify import simplify
    from tests.mesh_factory import unwelded
    V, F = unwelded(*icosphere(4))
    r = simplify(V, F, target_faces=200)
    own = clean_mesh(V, F)
    assert np.array_equal(r.cleaned.V, own.V) and np.array_equal(r.cleaned.F, own.F)
    assert r.cleaned.F.shape[0] == F.shape[0] and r.cleaned.V.shape[0] < V.shape[0]
    a = fit_cage(V, F, r.V, r.F, levels=1)
    b = fit_cage(*r.cleaned, r.V, r.F, levels=1, clean=False)
    assert np.array_equal(a.V, b.V) and np.array_equal(a.mean_distance, b.mean_distance)


def test_the_cleaned_input_is_without_the_debris_the_target_dropped_and_without_caps():
    # specks too small for one face of the target go (the fit then no longer reaches
    # for them); pinholes capped for the collapse are not part of the scan
    from core.clean import clean_mesh
    from core.simplify import simplify
    from tests.mesh_factory import with_debris, with_pinholes
    V0, F0 = icosphere(4)
    V, F = with_debris(*with_pinholes(V0, F0, share=0.02), k=40, size=2e-2)
    r = simplify(V, F, target_faces=40)
    own = clean_mesh(V, F)
    assert r.cleaning.n_debris_components == 40 > own.report.n_debris_components
    holes = F0.shape[0] - (F.shape[0] - 4 * 40)
    assert holes > 0 and r.cleaned.F.shape[0] == F0.shape[0] - holes < r.n_clean_faces
    from core.topology import manifold_report
    assert manifold_report(r.cleaned.F, r.cleaned.V.shape[0]).is_oriented_manifold
    fit = fit_cage(*r.cleaned, r.V, r.F, levels=1, clean=False)
    assert fit.mean_distance[-1] < fit.mean_distance[0]


def test_a_fit_cleans_as_a_simplify_to_the_cages_face_count_cleans():
    # the specks too small for one face of the cage are debris for the fit too: the
    # default fit of the messy scan is the fit of simplify's cleaned input, bit for bit,
    # and not the fit of the scan cleaned without a face budget (its specks pull it)
    from core.clean import clean_mesh
    from core.simplify import simplify
    from tests.mesh_factory import with_debris
    V, F = with_debris(*icosphere(4), k=30, size=2e-2)
    r = simplify(V, F, target_faces=60)
    assert r.F.shape[0] == 60 and r.cleaning.n_debris_components == 30
    a = fit_cage(V, F, r.V, r.F, levels=1)
    b = fit_cage(*r.cleaned, r.V, r.F, levels=1, clean=False)
    assert np.array_equal(a.V, b.V) and np.array_equal(a.mean_distance, b.mean_distance)
    kept = clean_mesh(V, F)
    assert kept.report.n_debris_components < 30
    c = fit_cage(kept.V, kept.F, r.V, r.F, levels=1, clean=False)
    assert not np.array_equal(a.V, c.V)


def test_a_symmetric_simplify_keeps_its_cleaned_input_too():
    from core.clean import clean_mesh
    from core.simplify import simplify
    V, F = icosphere(3)
    r = simplify(V, F, target_faces=100, symmetry="X")
    own = clean_mesh(V, F)
    assert np.array_equal(r.cleaned.V, own.V) and np.array_equal(r.cleaned.F, own.F)


def test_clean_must_be_a_bool(sphere_case):
    Vd, Fd, Vc, Fc = sphere_case
    with pytest.raises(InvalidArgumentError, match="fit_cage: clean must be True or False"):
        fit_cage(Vd, Fd, Vc, Fc, clean="no")


# ------------------------------------------------------------------ Anderson acceleration
def test_the_anderson_step_finds_an_affine_maps_fixed_point_from_its_iterates():
    # for G(x) = A x + b on n unknowns, the residuals of n + 1 plain iterates span the
    # space: their combination is the fixed point, exactly up to rounding
    import core.fit as fit_module
    rng = np.random.default_rng(3)
    A = 0.4 * rng.standard_normal((3, 3))
    b = rng.standard_normal(3)
    acc = fit_module._Anderson(3)
    x = np.zeros(3)
    for _ in range(4):
        g = A @ x + b
        acc.cages.append(x.copy())
        acc.solves.append(g)
        x = g
    fixed = np.linalg.solve(np.eye(3) - A, b)
    np.testing.assert_allclose(acc._combined(), fixed, rtol=0, atol=1e-12)


def test_accelerated_steps_fit_closer_than_as_many_plain_ones(monkeypatch):
    # a bumpy sphere's QEM cage: the records never rise (a step farther is undone),
    # and eight or six accelerated steps end closer than eight plain ones
    import core.fit as fit_module
    from core.simplify import simplify
    Vd, Fd = icosphere(5)
    Vd = Vd * (1 + 0.05 * np.sin(7 * Vd[:, [0]]) * np.cos(5 * Vd[:, [1]]))
    cage = simplify(Vd, Fd, target_faces=300)
    fast = fit_cage(Vd, Fd, cage.V, cage.F, levels=2, iterations=8)
    six = fit_cage(Vd, Fd, cage.V, cage.F, levels=2)
    monkeypatch.setattr(fit_module, "ANDERSON_DEPTH", 0)
    plain = fit_cage(Vd, Fd, cage.V, cage.F, levels=2, iterations=8)
    assert fast.mean_distance.shape == plain.mean_distance.shape == (9,)
    for r in (fast, plain):
        assert (np.diff(r.mean_distance) <= 0).all()
    assert fast.mean_distance[-1] < plain.mean_distance[-1]
    assert six.mean_distance.shape == (7,) and six.mean_distance[-1] < plain.mean_distance[-1]


def test_a_solve_that_is_not_finite_is_taken_plain_not_combined(monkeypatch):
    # (the loop then undoes it: its distance is NaN) no least squares over NaN
    import core.fit as fit_module
    matched = []
    monkeypatch.setattr(fit_module, "_match", lambda pb, X, reach=None: matched.append(X) or X)

    class Last:
        mean, reach = 1.0, None
    acc = fit_module._Anderson(3)
    X = np.zeros((2, 3))
    acc.step(None, X, X + 1.0, Last())
    G = np.full((2, 3), np.nan)
    out, m = acc.step(None, X + 1.0, G, Last())
    assert out is G and len(matched) == 2 and matched[-1] is G
