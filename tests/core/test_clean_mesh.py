"""core.clean: every defect class of real scans in, a clean manifold out, maps back.

Built meshes for each defect (soups, bow-ties, non-manifold edges, fins and
double-sided sheets, debris, collapsed clusters, huge and tiny coordinates),
hypothesis properties over random defects injected into spheres and tori, and
the whole chain (simplify -> fit_cage -> bind -> deform) on the shared meshes
and messy variants of them.
"""

import time

import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

import core
from core.clean import (BUDGET_DEBRIS_SHARE, DEBRIS_MAX_FACE_SHARE, DEBRIS_MAX_FACES, OPEN_SHARE,
                        WELD_DISTANCE, WIDER_WELDS, CleanReport, bulk_box, clean_mesh)
from core.errors import InvalidArgumentError, InvalidMeshError
from core.topology import manifold_report, topology_summary
from tests.mesh_factory import (cyclic_rows, duplicated, icosphere, klein_bottle, load_shared,
                                mobius_strip, needle_cone, pinched, random_winding, regular_grid,
                                shared_mesh_names, torus, unwelded, with_debris, with_far_speck,
                                with_fins, with_pinholes, with_sheets)


def assert_manifold(V, F):
    rep = manifold_report(F, V.shape[0])
    assert rep.is_oriented_manifold, rep
    assert np.array_equal(np.unique(F), np.arange(V.shape[0]))     # no unreferenced vertex


def summary(F, n):
    s = topology_summary(F, n)
    return s.euler, s.components, s.boundary_loops


def assert_maps(r, V, F, weld=1e-5):
    """Every clean vertex sits on its input vertex; every clean face is an input face
    (as a set of positions); every used input vertex maps to a clean vertex there
    (within ``weld`` of the diagonal: welds move a vertex by about their distance)."""
    tol = weld * core.bbox_diagonal(V)
    np.testing.assert_array_equal(r.V, V[r.clean_to_input])
    np.testing.assert_allclose(np.sort(V[F[r.face_to_input]], axis=1),
                               np.sort(r.V[r.F], axis=1), rtol=0, atol=tol)
    hit = r.input_to_clean >= 0
    np.testing.assert_allclose(r.V[r.input_to_clean[hit]], V[hit], rtol=0, atol=tol)


# ---------------------------------------------------------------- defect classes
def test_a_clean_mesh_comes_back_unchanged():
    V, F = torus(20, 10)
    r = clean_mesh(V, F)
    assert np.array_equal(r.V, V) and np.array_equal(r.F, F) and not r.report
    assert r.report.summary() == ""
    np.testing.assert_array_equal(r.twin, core._clean.twin_table(F, V.shape[0]))


@pytest.mark.parametrize("jitter", [0.0, 1e-7])
def test_soups_weld_back_to_the_mesh(jitter):
    V, F = icosphere(3)
    S, FS = unwelded(V, F, jitter)
    r = clean_mesh(S, FS)
    assert r.report.n_welded_vertices == FS.size - V.shape[0]
    assert r.F.shape == F.shape and summary(r.F, r.V.shape[0]) == (2, 1, 0)
    assert_manifold(r.V, r.F)
    assert_maps(r, S, FS)
    assert r.report.summary() == f"welded {FS.size - V.shape[0]:,} vertices"


def test_weld_distance_is_relative_to_the_diagonal_and_zero_welds_exact_duplicates_only():
    V, F = icosphere(2)
    S, FS = unwelded(V, F, 1e-4)
    assert clean_mesh(S, FS, weld_distance=1e-6).report.n_welded_vertices == 0   # a soup still
    assert clean_mesh(S, FS, weld_distance=1e-2).F.shape == F.shape
    assert clean_mesh(S * 1e4, FS, weld_distance=1e-2).F.shape == F.shape
    E, FE = unwelded(V, F, 0.0)
    assert clean_mesh(E, FE, weld_distance=0.0).report.n_welded_vertices == FE.size - V.shape[0]


@pytest.mark.parametrize("jitter, used", [(1e-6, 1e-5), (1e-5, 1e-4), (3e-5, 1e-4)])
def test_the_automatic_weld_widens_for_a_soup_whose_copies_drifted_apart(jitter, used):
    V, F = icosphere(3)
    S, FS = unwelded(V, F, jitter, seed=1)
    plain = clean_mesh(S, FS, weld_distance=1e-6)
    assert np.count_nonzero(plain.twin == core._clean.BOUNDARY) > OPEN_SHARE * plain.twin.size
    r = clean_mesh(S, FS)
    assert r.report.weld_distance == used
    assert r.F.shape == F.shape and summary(r.F, r.V.shape[0]) == (2, 1, 0)
    assert_manifold(r.V, r.F)
    assert_maps(r, S, FS, weld=8 * used)         # (pairs up to 4 weld distances per axis)
    assert r.report.summary() == (f"welded {FS.size - V.shape[0]:,} vertices (within {used:g} "
                                  f"of the size: the input came in pieces)")
    assert r.report.weld_widened
    # the same weld asked for: said as asked, not as a finding about the input
    asked = clean_mesh(S, FS, weld_distance=used)
    assert np.array_equal(asked.F, r.F) and not asked.report.weld_widened
    assert asked.report.summary() == f"welded {FS.size - V.shape[0]:,} vertices (within {used:g} of the size)"


@pytest.mark.parametrize("name", ["icosphere", "stanford-bunny"])
@pytest.mark.parametrize("jitter, used", [(2e-6, 1e-5), (1e-5, 1e-4)])
def test_a_drifted_soup_wound_at_random_widens_its_weld_too(name, jitter, used):
    # half the faces wound the other way (photogrammetry, some scanner exports): the
    # copy check read the corner across each half-edge off by one and took the faces
    # wound against a neighbour for copies of it, so half the edges stayed "open" after
    # any weld and none was widened (the bunny stayed 69,452 one-face pieces)
    V, F = load_shared("stanford-bunny.obj") if name == "stanford-bunny" else icosphere(3)
    S, FS = random_winding(*unwelded(V, F, jitter, seed=1), share=0.5, seed=3)
    r = clean_mesh(S, FS)
    assert r.report.weld_widened and r.report.weld_distance == used
    assert r.F.shape == F.shape and r.report.n_welded_vertices == FS.size - np.unique(F).size
    assert summary(r.F, r.V.shape[0]) == summary(F, V.shape[0])
    assert_manifold(r.V, r.F)
    flipped = r.report.n_flipped_faces
    assert 0.4 * F.shape[0] < flipped < 0.6 * F.shape[0]   # one consistent orientation


@pytest.mark.parametrize("far", [10.0, 1e3, 1e6])
@pytest.mark.parametrize("jitter", [None, 1e-7], ids=["mesh", "jittered soup"])
def test_a_stray_face_far_off_is_debris_and_leaves_the_weld_alone(far, jitter):
    """One triangle far from the scan (a stray speck, or a scan placed far
    from the origin with a triangle left at 0): the weld's unit is the size
    of the mesh's bulk, not the box the speck stretches (1,000 diagonals away
    it welded away 965 of the bunny's faces, 10,000 away all of them). The
    speck goes as debris; the rest cleans as without it, and the cage is the
    same bit for bit."""
    V, F = load_shared("stanford-bunny.obj") if jitter is None else icosphere(3)
    if jitter is not None:
        V, F = unwelded(V, F, jitter)
    ref = clean_mesh(V, F)
    W, G = with_far_speck(V, F, far)
    r = clean_mesh(W, G)
    np.testing.assert_array_equal(r.V, ref.V)
    np.testing.assert_array_equal(r.F, ref.F)
    assert r.report.n_debris_faces == ref.report.n_debris_faces + 1
    assert r.report.n_welded_vertices == ref.report.n_welded_vertices
    cage, plain = core.simplify(W, G, target_faces=300), core.simplify(V, F, target_faces=300)
    np.testing.assert_array_equal(cage.V, plain.V)
    np.testing.assert_array_equal(cage.F, plain.F)


def test_a_scan_far_from_the_origin_with_a_triangle_left_at_it():
    V, F = icosphere(3)
    W, G = with_far_speck(*unwelded(V + 1e6, F, 1e-7), at=np.zeros(3))     # (a soup: STL)
    r = clean_mesh(W, G)
    assert r.F.shape[0] == F.shape[0] and summary(r.F, r.V.shape[0]) == (2, 1, 0)
    assert r.report.n_debris_faces == 1


@pytest.mark.parametrize("stretch", [1e4, 1e5, 1e6])
@pytest.mark.parametrize("make", [lambda: icosphere(3), lambda: torus(40, 20)], ids=["sphere", "torus"])
def test_a_clean_mesh_stretched_into_a_needle_stays_as_it_is(make, stretch):
    """Stretched along x its faces are far below the weld distance tall (of a
    size the stretch sets), but not below the mesh's own faces: they are not
    collapsed clusters (the sphere at 1e5 lost 768 of its 1,280 faces, the
    torus 398 and came out in 4 pieces)."""
    V, F = make()
    W = V * [stretch, 1.0, 1.0]
    r = clean_mesh(W, F)
    assert np.array_equal(r.V, W) and np.array_equal(r.F, F) and not r.report
    cage = core.simplify(W, F, target_faces=200)
    assert cage.F.shape[0] == 200 and cage.n_components == 1


@pytest.mark.parametrize("jitter", [0.0, 1e-9, 1e-7])
def test_a_cluster_collapsed_to_a_point_welds_even_when_it_is_most_of_the_mesh(jitter):
    """The collapsed-face rule's reference is the tallest face, not a typical
    one: 2,000 of a sphere's 2,562 vertices moved to one point (most of its
    faces collapsed) still weld into it."""
    V, F = icosphere(4)
    near = np.argsort(np.linalg.norm(V - V[0], axis=1))[:2000]
    W = V.copy()
    W[near] = V[0] + jitter * np.random.default_rng(0).standard_normal((near.size, 3))
    r = clean_mesh(W, F)
    assert r.report.n_welded_vertices == near.size - 1
    assert_manifold(r.V, r.F)


def test_the_bulk_box_leaves_out_far_specks_but_not_the_mesh():
    V, F = load_shared("stanford-bunny.obj")
    used = V[np.unique(F)]
    bulk = bulk_box(used)
    box_lo, box_hi = used.min(axis=0), used.max(axis=0)
    # the bulk is nearly the whole box (2% of the vertices left out along each axis) ...
    assert np.all(bulk[0] >= box_lo) and np.all(bulk[1] <= box_hi)
    assert np.linalg.norm(bulk[1] - bulk[0]) > 0.9 * np.linalg.norm(box_hi - box_lo)
    # ... and the same with specks far off
    specks = np.random.default_rng(0).random((used.shape[0] // 200, 3)) * 1e6
    far = bulk_box(np.vstack([used, specks]))
    assert np.linalg.norm(far[1] - far[0]) < 1.1 * np.linalg.norm(bulk[1] - bulk[0])
    # a flat mesh keeps its flat axis; points all at one place but a few: the whole box
    flat = bulk_box(np.c_[np.random.default_rng(1).random((500, 2)), np.zeros(500)])
    assert flat[0][2] == flat[1][2] == 0.0 and np.all(flat[1][:2] > flat[0][:2])
    P = np.zeros((1000, 3))
    P[-3:] = np.eye(3)
    np.testing.assert_array_equal(np.array(bulk_box(P)), np.array([np.zeros(3), np.ones(3)]))


def test_the_automatic_weld_leaves_real_borders_and_far_drift_alone():
    # a scan's own holes do not close at a wider weld: the same as the default's weld
    for V, F in (regular_grid(12, 12), load_shared("beetle.obj")):
        fixed, auto = clean_mesh(V, F, weld_distance=WELD_DISTANCE), clean_mesh(V, F)
        assert auto.report.weld_distance == WELD_DISTANCE and not auto.report.summary().count("pieces")
        assert np.array_equal(auto.F, fixed.F) and np.array_equal(auto.V, fixed.V)
    # drift beyond the widest step: nothing welds (a soup, which simplify names as such)
    V, F = icosphere(2)
    S, FS = unwelded(V, F, 30 * WIDER_WELDS[-1], seed=1)
    r = clean_mesh(S, FS)
    assert r.report.weld_distance == WELD_DISTANCE and r.F.shape == FS.shape


def test_bowties_are_split_one_vertex_per_fan():
    V, F = icosphere(3)
    Vp, Fp = pinched(V, F, k=3)
    assert manifold_report(Fp, Vp.shape[0]).non_manifold_vertices.shape[0] == 3
    r = clean_mesh(Vp, Fp)
    assert r.report.n_split_vertices == 3 and r.report.n_added_vertices == 3
    assert r.report.n_unreferenced_vertices == 3
    assert r.F.shape == Fp.shape and r.V.shape[0] == V.shape[0]
    assert_manifold(r.V, r.F)
    assert summary(r.F, r.V.shape[0]) == (2, 1, 0)
    assert_maps(r, Vp, Fp)


def test_a_fin_is_cut_into_its_own_sheet():
    V, F = icosphere(2)
    Vf, Ff = with_fins(V, F, k=4)
    r = clean_mesh(Vf, Ff, min_component_area=0)
    assert r.report.n_non_manifold_edges == 4
    assert_manifold(r.V, r.F)
    # the sphere is whole (its two faces paired on each edge), each fin a lone triangle
    assert summary(r.F, r.V.shape[0]) == (2 + 4, 5, 4)
    assert r.F.shape[0] == Ff.shape[0]
    # as debris (small against the sphere) they go
    d = clean_mesh(Vf, Ff, min_component_area=0.01)
    assert d.report.n_debris_components == 4 and summary(d.F, d.V.shape[0]) == (2, 1, 0)


def test_double_sided_sheets_go_both_sides_or_keep_the_side_that_mends():
    V, F = icosphere(2)
    # reversed copies of patches of the sphere: one side of each is the sphere itself
    Vs, Fs = with_sheets(V, F, k=5)
    r = clean_mesh(Vs, Fs)
    assert r.report.n_duplicate_faces == Fs.shape[0] - F.shape[0]
    assert r.report.n_double_sided_sheets == 0
    assert r.F.shape == F.shape and summary(r.F, r.V.shape[0]) == (2, 1, 0)
    assert_manifold(r.V, r.F)
    # the case: a pair folded over the surface (two of its edges are the sphere's)
    a, b, c = F[0]
    d = [v for v in F[np.any(F == b, axis=1) & np.any(F == c, axis=1)].ravel() if v not in (a, b, c)][0]
    Fx = np.concatenate([F, [[a, b, d], [a, d, b]]])
    r = clean_mesh(V, Fx)
    assert r.report.n_double_sided_sheets == 1 and r.F.shape == F.shape
    assert summary(r.F, r.V.shape[0]) == (2, 1, 0)
    assert_manifold(r.V, r.F)


def test_a_mesh_that_is_only_a_double_sided_sheet_keeps_one_side():
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0.0]])
    F = np.array([[0, 1, 2], [1, 3, 2], [0, 2, 1], [1, 2, 3]])
    r = clean_mesh(V, F)
    assert r.F.shape[0] == 2 and r.report.n_duplicate_faces == 2
    assert_manifold(r.V, r.F)


def test_a_double_sided_part_beside_a_speck_keeps_one_side_not_the_speck():
    """A flat disc modelled double-sided (a cone of height 0: its side lies
    on its base), a few of its vertices pinched, and a speck far off: the
    pinched sheets' sides no longer mend each other, and removing both left
    the speck as the whole cage (6,001 faces -> 1). Sheets holding more area
    than everything else are the model: one side stays, the speck goes."""
    Vp, Fp = pinched(*needle_cone(500, height=0.0), k=3, seed=1)
    Vs, Fs = with_far_speck(Vp, Fp, far=1e3)
    r = clean_mesh(Vs, Fs)
    assert r.report.n_double_sided_sheets == 0 and r.report.n_debris_components == 1
    assert r.F.shape[0] == Fp.shape[0] // 2
    area = core.face_areas(r.V, r.F).sum()
    assert abs(area - core.face_areas(Vp, Fp).sum() / 2) < 1e-9 * area
    assert_manifold(r.V, r.F)
    c = core.simplify(Vs, Fs, target_faces=100)
    assert c.F.shape[0] == 100 and np.ptp(c.V[:, :2], axis=0).min() > 1.9
    # a double-sided pair folded onto a closed surface still goes (its area is the lesser)
    V, F = icosphere(2)
    a, b, c = F[0]
    beside = F[np.any(F == b, axis=1) & np.any(F == c, axis=1)].ravel()
    d = [v for v in beside if v not in (a, b, c)][0]
    r = clean_mesh(V, np.concatenate([F, [[a, b, d], [a, d, b]]]))
    assert r.report.n_double_sided_sheets == 1 and r.F.shape == F.shape


def test_inconsistent_orientation_is_fixed_by_the_majority():
    V, F = icosphere(2)
    Fx = F.copy()
    flip = np.arange(0, F.shape[0], 7)
    Fx[flip] = Fx[flip][:, ::-1]
    r = clean_mesh(V, Fx)
    assert r.report.n_flipped_faces == flip.size
    np.testing.assert_array_equal(np.sort(r.F, axis=1), np.sort(F, axis=1))
    assert core.enclosed_volume(r.V, r.F) > 0
    assert_manifold(r.V, r.F)


def same_oriented_faces(F_a, F_b):
    """Whether two face lists hold the same oriented faces (any order)."""
    key = lambda F: np.sort(cyclic_rows(F).view([("a", F.dtype), ("b", F.dtype), ("c", F.dtype)]),
                            axis=0)
    return np.array_equal(key(np.ascontiguousarray(F_a)), key(np.ascontiguousarray(F_b)))


@pytest.mark.parametrize("name", ["cow.obj", "spot.obj", "stanford-bunny.obj"])
@pytest.mark.parametrize("share", [0.5, 0.6])
@pytest.mark.parametrize("seed", [0, 2])
def test_random_winding_comes_back_outward_not_by_a_coin_toss(name, share, seed):
    # half or more of the faces reversed at random: the majority used to win, and the
    # cow, spot and the bunny came back inside-out for seeds 0 and 2 (all six at 0.6)
    V, F = load_shared(name)
    r = clean_mesh(*random_winding(V, F, share, seed))
    assert_manifold(r.V, r.F)
    assert core.enclosed_volume(r.V, r.F) > 0
    assert same_oriented_faces(r.clean_to_input[r.F], F)       # every face as the scan had it
    assert r.report.n_flipped_faces == np.count_nonzero(~np.all(
        cyclic_rows(random_winding(V, F, share, seed)[1]) == cyclic_rows(F), axis=1))


def test_random_winding_of_a_torus_and_a_sphere_with_pinholes_comes_back_outward():
    for V, F in (torus(48, 24), with_pinholes(*icosphere(4), share=0.01)):
        r = clean_mesh(*random_winding(V, F, 0.55, seed=3))
        assert same_oriented_faces(r.clean_to_input[r.F], F)
        assert core.enclosed_volume(r.V, r.F) > 0


@pytest.mark.parametrize("scale, offset", [(1e150, 0.0), (1e-150, 0.0), (1.0, 1e9)])
def test_random_winding_comes_back_outward_at_any_scale(scale, offset):
    # the cones' volumes are taken in units of the component's size: at 1e150 they
    # overflowed and the majority decided (inside-out for seeds 0 and 2)
    V, F = icosphere(3)
    for seed in range(3):
        r = clean_mesh(*random_winding(V * scale + offset, F, 0.5, seed))
        assert same_oriented_faces(r.clean_to_input[r.F], F)


def test_orientation_without_a_tie_or_an_inside_keeps_the_majority():
    V, F = icosphere(3)
    inside_out = F[:, ::-1]
    r = clean_mesh(V, inside_out)                       # consistent: left as it came
    assert r.report.n_flipped_faces == 0 and np.array_equal(r.F, inside_out)
    bowl = inside_out[V[inside_out].mean(axis=1)[:, 2] < 0]      # an open bowl, normals in
    Vb, Fb = random_winding(V, bowl, 0.2, seed=1)
    r = clean_mesh(Vb, Fb)
    assert same_oriented_faces(r.clean_to_input[r.F], bowl)     # the majority: still in
    sheet = regular_grid(20, 20)                         # flat: no inside, a tie keeps the majority
    r = clean_mesh(*random_winding(*sheet, 0.5, seed=4))
    assert manifold_report(r.F, r.V.shape[0]).is_oriented_manifold
    assert r.report.n_flipped_faces <= sheet[1].shape[0] // 2


@pytest.mark.parametrize("scramble", [False, True])
def test_a_moebius_strip_is_cut_open_across_into_an_oriented_disk(scramble):
    V, F = mobius_strip(120, 12)
    if scramble:                                 # and its faces' orientations at random
        F = F.copy()
        flip = np.random.default_rng(3).random(F.shape[0]) < 0.5
        F[flip] = F[flip][:, ::-1]
    r = clean_mesh(V, F)
    rep = r.report
    assert rep.n_non_orientable_components == 1 and rep.n_seam_edges >= 11
    # a seam from border to border: its k edges and k + 1 vertices, each vertex once per side
    assert rep.n_flipped_faces == 0 and r.V.shape[0] == V.shape[0] + rep.n_seam_edges + 1
    assert_manifold(r.V, r.F)
    assert summary(r.F, r.V.shape[0]) == (1, 1, 1)              # a disk
    assert_maps(r, V, F, weld=0.0)
    assert "cut 1 one-sided (non-orientable) components open along" in rep.summary()
    # cleaned again, the seam's coincident copies weld and it is cut open the same way
    again = clean_mesh(r.V, r.F)
    assert again.report.n_welded_vertices == rep.n_seam_edges + 1
    assert again.report.n_seam_edges == rep.n_seam_edges and again.V.shape == r.V.shape
    assert summary(again.F, again.V.shape[0]) == (1, 1, 1)


def test_a_klein_bottle_is_cut_open_into_one_oriented_piece_and_a_sphere_beside_it_is_untouched():
    V, F = klein_bottle(80, 40)
    Vs, Fs = icosphere(3)
    Vs = Vs * 0.5 + [0.0, 0.0, 5.0]
    Va, Fa = np.vstack([Vs, V]), np.vstack([Fs, F + Vs.shape[0]])
    r = clean_mesh(Va, Fa)
    assert r.report.n_non_orientable_components == 1
    assert_manifold(r.V, r.F)
    # the bottle (closed, Euler 0) cut along closed seams: Euler 0 still, one piece with borders
    euler, components, loops = summary(r.F, r.V.shape[0])
    assert (euler, components) == (2 + 0, 2) and loops >= 1
    assert r.V.shape[0] - Va.shape[0] == r.report.n_seam_edges
    sphere = r.face_to_input < Fs.shape[0]
    np.testing.assert_array_equal(r.V[r.F[sphere]], Va[Fa[r.face_to_input[sphere]]])
    assert_maps(r, Va, Fa, weld=0.0)


@pytest.mark.parametrize("scheme", ["butterfly", "loop"])
def test_a_one_sided_scan_goes_through_the_chain(scheme):
    V, F = mobius_strip(240, 24, bump=0.01)
    r = core.simplify(V, F, target_faces=400)
    assert r.stopped_because == "target" and abs(r.F.shape[0] - 400) <= 20, r.message
    assert "one-sided" in r.message
    assert manifold_report(r.F, r.V.shape[0]).is_oriented_manifold
    assert topology_summary(r.F, r.V.shape[0]).euler == 1
    fit = core.fit_cage(V, F, r.V, r.F, levels=1, scheme=scheme)
    b = core.bind(V, F, fit.V, r.F, levels=1, scheme=scheme)
    d = core.bbox_diagonal(V)
    assert np.abs(core.deform(b, fit.V) - V).max() <= 1e-12 * d
    Ve = fit.V.copy()
    Ve[r.F[0]] += 0.01 * d
    D = core.deform(b, Ve)
    assert np.isfinite(D).all() and 0 < np.abs(D - V).max() <= 0.05 * d


def test_debris_is_dropped_by_area_and_by_face_budget():
    V, F = icosphere(3)
    Vd, Fd = with_debris(V, F, k=3000)
    r = clean_mesh(Vd, Fd)
    assert r.report.n_debris_components == 3000 and r.report.n_debris_faces == 12000
    assert r.F.shape == F.shape and summary(r.F, r.V.shape[0]) == (2, 1, 0)
    assert np.all(r.input_to_clean[V.shape[0]:] == -1)
    # ten equal shells: each gets a tenth of a 10-face budget, none is debris; with 9
    # faces each is too small, but together they are the mesh, not specks: all kept
    T, FT = icosphere(0)
    Vm = np.concatenate([T + [3.0 * k, 0, 0] for k in range(10)])
    Fm = np.concatenate([FT + 12 * k for k in range(10)])
    assert clean_mesh(Vm, Fm, face_budget=10).report.n_debris_components == 0
    assert clean_mesh(Vm, Fm, face_budget=9).report.n_debris_components == 0
    # one large shell and nine small ones holding under BUDGET_DEBRIS_SHARE of the area
    scale = np.sqrt(0.9 * BUDGET_DEBRIS_SHARE / 9)
    Vs = np.concatenate([T * (1.0 if k == 0 else scale) + [3.0 * k, 0, 0] for k in range(10)])
    assert clean_mesh(Vs, Fm, face_budget=20).report.n_debris_components == 9
    # a protected vertex keeps its component
    prot = np.zeros(Vs.shape[0], dtype=bool)
    prot[-1] = True
    assert clean_mesh(Vs, Fm, face_budget=20, protected=prot).report.n_debris_components == 8


def test_collapsed_clusters_answer_quickly():
    rng = np.random.default_rng(0)
    pts = rng.normal(size=(5, 3))
    V = pts[rng.integers(0, 5, 30000)]
    F = rng.integers(0, 30000, (20000, 3))
    t = time.perf_counter()
    r = clean_mesh(V, F)
    assert time.perf_counter() - t < 10
    assert_manifold(r.V, r.F)
    # every face left is one of the ten triangles of the five points
    assert r.F.shape[0] <= 10 and np.unique(r.V, axis=0).shape[0] <= 5
    # a sphere whose vertices sit on a few points simplifies in seconds, to a manifold
    Vs, Fs = icosphere(5)
    t = time.perf_counter()
    s = core.simplify(pts[rng.integers(0, 5, Vs.shape[0])], Fs, target_faces=100)
    assert time.perf_counter() - t < 60
    assert manifold_report(s.F, s.V.shape[0]).is_manifold


def test_everything_degenerate_is_a_clear_error():
    V = np.zeros((30, 3))
    F = np.arange(30).reshape(-1, 3)
    assert clean_mesh(V, F).F.shape == (0, 3)
    with pytest.raises(InvalidMeshError, match="nothing is left after cleaning the 10 faces"):
        core.simplify(V, F, target_faces=4)


@pytest.mark.parametrize("scale", [1e-200, 1e200])
def test_huge_and_tiny_coordinates_clean_and_simplify_like_unit_ones(scale):
    V, F = icosphere(3)
    S, FS = unwelded(V, F, 1e-7)
    ref = clean_mesh(S, FS)
    r = clean_mesh(S * scale, FS)
    np.testing.assert_array_equal(r.F, ref.F)
    a, b = core.simplify(S, FS, target_faces=200), core.simplify(S * scale, FS, target_faces=200)
    assert np.array_equal(a.F, b.F) and np.all(np.isfinite(b.V)) and np.isfinite(b.max_error)
    np.testing.assert_allclose(b.V / scale, a.V, rtol=1e-9, atol=1e-12)


def test_inputs_are_not_modified():
    V, F = pinched(*icosphere(2))
    V0, F0 = V.copy(), F.copy()
    r = clean_mesh(V, F)
    assert np.array_equal(V, V0) and np.array_equal(F, F0)
    assert not np.shares_memory(r.V, V) and not np.shares_memory(r.F, F)


@pytest.mark.parametrize("kwargs, match", [
    (dict(weld_distance=-1.0), "weld_distance must be a number >= 0, got -1.0"),
    (dict(weld_distance=float("nan")), "weld_distance"),
    (dict(min_component_area=-0.1), "min_component_area must be"),
    (dict(weld_distance=2**64), None),                       # (a raw TypeError: none)
    (dict(min_component_area=np.complex128(1.0)), "min_component_area must be a number >= 0"),
    (dict(weld_distance=True), "weld_distance must be a number >= 0, got True"),
    (dict(face_budget=-1), r"^clean_mesh: face_budget must be an integer >= 0, got -1"),
    (dict(face_budget=2.5), r"^clean_mesh: face_budget must be an integer >= 0, got 2\.5"),
    (dict(protected=np.ones(3, dtype=bool)),
     r"^clean_mesh: protected must be \(42,\) booleans \(one per vertex\), got \(3,\) bool"),
    (dict(protected=np.ones(42)), r"^clean_mesh: protected must be \(42,\) booleans"),
])
def test_bad_tolerances_raise(kwargs, match):
    if match is None:                      # a huge tolerance is one (a closed mesh: no seam)
        r = clean_mesh(*icosphere(1), **kwargs)
        assert r.report.weld_distance == 2.0**64 and r.F.shape[0] == 80
        return
    with pytest.raises(InvalidArgumentError, match=match):
        clean_mesh(*icosphere(1), **kwargs)


def test_report_summary_reads_as_a_sentence():
    r = CleanReport(n_welded_vertices=4012, n_split_vertices=3, n_double_sided_sheets=2,
                    n_double_sided_faces=4)
    assert r.summary() == ("welded 4,012 vertices, split 3 bow-tie vertices, removed 2 "
                           "double-sided sheets (4 faces)")
    assert r.to_dict()["n_welded_vertices"] == 4012 and bool(r) and not CleanReport()


# ---------------------------------------------------------------- properties
def _inject(V, F, rng, kinds):
    """Random defects of the given kinds injected into a clean mesh."""
    for kind in kinds:
        seed = int(rng.integers(1 << 30))
        if kind == "soup":
            V, F = unwelded(V, F, float(rng.choice([0.0, 1e-8])), seed=seed)
        elif kind == "bowtie":
            V, F = pinched(V, F, k=int(rng.integers(1, 4)), seed=seed)
        elif kind == "fin":
            V, F = with_fins(V, F, k=int(rng.integers(1, 4)), seed=seed)
        elif kind == "sheet":
            V, F = with_sheets(V, F, k=int(rng.integers(1, 3)), seed=seed)
        elif kind == "debris":
            V, F = with_debris(V, F, k=int(rng.integers(1, 50)), seed=seed)
        elif kind == "flip":
            F = F.copy()
            f = rng.choice(F.shape[0], F.shape[0] // 10, replace=False)
            F[f] = F[f][:, ::-1]
    return V, F


@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 10_000), shape=st.sampled_from(["sphere", "torus"]),
       kinds=st.lists(st.sampled_from(["soup", "bowtie", "fin", "sheet", "debris", "flip"]),
                      min_size=1, max_size=3, unique=True),
       frac=st.floats(0.02, 0.5))
@example(seed=6747, shape="torus", kinds=["bowtie", "debris", "flip"], frac=0.0625)  # found once: 38 faces
@example(seed=535, shape="torus", kinds=["bowtie", "flip"], frac=0.0625)   # 38 faces (2026-12-03)
def test_random_defects_give_a_manifold_cage_and_an_exact_identity(seed, shape, kinds, frac):
    rng = np.random.default_rng(seed)
    V, F = icosphere(2) if shape == "sphere" else torus(16, 8)
    Vm, Fm = _inject(V, F, rng, kinds)
    c = clean_mesh(Vm, Fm)
    assert_manifold(c.V, c.F)
    assert_maps(c, Vm, Fm)
    target = max(30, int(frac * c.F.shape[0]))      # (a torus's floor is 14 faces)
    r = core.simplify(Vm, Fm, target_faces=target)
    assert manifold_report(r.F, r.V.shape[0]).is_oriented_manifold
    # the cage has no border loop the cleaned input did not have
    assert topology_summary(r.F, r.V.shape[0]).boundary_loops <= \
        topology_summary(c.F, c.V.shape[0]).boundary_loops
    # the target, or the floor; near the floor of these small shapes the no-fold and
    # no-sliver checks may stop a few faces short (a 256-face torus with three of its
    # far-apart vertex pairs pinched into one, asked for 30 faces: 32, and 38 for two
    # of the 10,000 seeds, the same before and after 2026-12-03's changes)
    assert r.F.shape[0] <= target or r.stopped_because == "topology_floor" or \
        (r.stopped_because == "no_valid_collapse" and r.F.shape[0] <= 1.1 * target + 8)
    # the dense mesh keeps its own topology: binding and identity on the input as it came
    b = core.bind(Vm, Fm, r.V, r.F, levels=1)
    d = core.bbox_diagonal(Vm)
    assert np.abs(core.deform(b, r.V) - Vm).max() <= 1e-9 * d


# ---------------------------------------------------------------- the whole chain, real meshes
MESSY = ["as is", "soup", "jittered soup", "bowties", "debris", "sheets", "pinholes",
         "copy in place", "holed copy in place", "speck far off"]


def _messy(V, F, how):
    if how == "soup":
        return unwelded(V, F)
    if how == "jittered soup":
        return unwelded(V, F, 1e-7)
    if how == "bowties":
        return pinched(V, F)
    if how == "debris":
        return with_debris(V, F)
    if how == "sheets":
        return with_sheets(V, F)
    if how == "pinholes":
        return with_pinholes(V, F)
    if how == "copy in place":
        return duplicated(V, F)
    if how == "holed copy in place":
        return duplicated(*with_pinholes(V, F))
    if how == "speck far off":
        return with_far_speck(V, F)
    return V, F


@pytest.mark.slow
@pytest.mark.parametrize("how", MESSY)
@pytest.mark.parametrize("name", shared_mesh_names())
def test_every_shared_mesh_and_messy_variant_goes_through_the_chain(name, how):
    V, F = load_shared(name)
    Vm, Fm = _messy(V, F, how)
    clean = clean_mesh(Vm, Fm)
    target = int(np.clip(clean.F.shape[0] // 10, 100, 1500))
    r = core.simplify(Vm, Fm, target_faces=target)
    assert manifold_report(r.F, r.V.shape[0]).is_oriented_manifold
    assert topology_summary(r.F, r.V.shape[0]).boundary_loops <= \
        topology_summary(clean.F, clean.V.shape[0]).boundary_loops
    assert abs(r.F.shape[0] - target) <= 0.05 * target or r.stopped_because == "topology_floor", \
        r.message
    creases = r.feature_edges if len(r.feature_edges) else None
    fit = core.fit_cage(Vm, Fm, r.V, r.F, levels=2, creases=creases, iterations=2)
    b = core.bind(Vm, Fm, fit.V, r.F, levels=2, creases=creases)
    assert b.n_dense == Vm.shape[0]          # the source's own vertices, bow-ties and all
    d = core.bbox_diagonal(Vm)
    assert np.abs(core.deform(b, fit.V) - Vm).max() <= 1e-9 * d


def test_a_scan_with_3000_specks_gets_the_cage_of_the_scan_alone():
    V, F = icosphere(5)
    rng = np.random.default_rng(5)
    V = V * (1 + 0.03 * np.sin(7 * V[:, :1]) * np.cos(5 * V[:, 1:2]) + 0.002 * rng.standard_normal((len(V), 1)))
    Vd, Fd = with_debris(V, F, k=3000)
    for keep_topology in (True, False):
        alone = core.simplify(V, F, target_faces=2000, preserve_topology=keep_topology)
        r = core.simplify(Vd, Fd, target_faces=2000, preserve_topology=keep_topology)
        assert abs(r.F.shape[0] - 2000) <= 100 and r.cleaning.n_debris_components == 3000
        assert "dropped 3,000 debris components (12,000 faces)" in r.message
        mean = core.surface_distance(V, F, r.V, r.F).mean
        assert mean <= 1.1 * core.surface_distance(V, F, alone.V, alone.F).mean
        # the specks still follow the edit: bound to the nearest cage surface
        b = core.bind(Vd, Fd, r.V, r.F, levels=1)
        assert b.n_dense == Vd.shape[0]


def test_refine_detail_comes_from_the_scan_not_from_its_debris():
    V, F = icosphere(4)
    Vd, Fd = with_debris(V, F, k=400, size=2e-3)
    r = core.simplify(Vd, Fd, target_faces=200)
    b = core.bind(Vd, Fd, r.V, r.F, levels=2)
    fine = core.refine(b, r.V)
    # every refined vertex sits on the sphere (the specks, up to 6% of the diagonal
    # away from it, pull none of them off)
    d = core.TriangleIndex(V, F).closest(fine.V).distance
    assert d.max() <= 1e-3 * core.bbox_diagonal(V)


def test_a_collinear_soup_is_a_clear_error():
    rng = np.random.default_rng(0)
    P = np.zeros((3000, 3))
    P[:, 0] = rng.random(3000)
    with pytest.raises(InvalidMeshError, match=r"have no area \(their corners are collinear\): no"):
        core.simplify(P, np.arange(3000).reshape(-1, 3), target_faces=100)


def test_a_tiny_mesh_far_off_is_told_to_move_to_the_origin():
    """A sphere 2.5e-7 across placed 1e6 from the origin keeps 3 significant
    digits of its shape in its coordinates: its faces' area is lost in the
    rounding, and the error says so rather than only 'collinear'."""
    V, F = icosphere(3)
    with pytest.raises(InvalidMeshError, match=r"have no area \(their corners are collinear, or lost "
                       r"in rounding: the mesh is 2.5e-07 across and 1e\+06 from the origin, so its "
                       r"coordinates keep only 3 significant digits of its shape: move it to the origin"):
        core.simplify(V * 2.5e-7 / core.bbox_diagonal(V) + 1e6, F, target_faces=100)
    # moved to the origin, the same shape has a cage
    assert core.simplify(V * 2.5e-7 / core.bbox_diagonal(V), F, target_faces=100).F.shape[0] == 100


def test_the_bulk_of_a_mesh_is_never_debris_of_a_stray_huge_face():
    """A sphere of 20,480 faces sharing a vertex with one stray triangle 1,000
    times its size (a scan's bad point): by area the sphere was debris of the
    triangle, and the cage was the triangle alone, said to be on target. A
    component with more than DEBRIS_MAX_FACES faces and DEBRIS_MAX_FACE_SHARE
    of them is kept; specks still go."""
    V, F = icosphere(5)
    n = V.shape[0]
    V = np.vstack([V, [[1000.0, 0, 0], [0, 1000.0, 0]]])
    F = np.vstack([F, [[0, n, n + 1]]])
    out = clean_mesh(V, F)
    assert out.F.shape[0] == F.shape[0] and out.report.n_debris_faces == 0
    assert out.report.n_split_vertices == 1                  # the shared vertex, one per fan
    res = core.simplify(V, F, target_faces=500)
    assert res.n_components == 2 and res.F.shape[0] <= 500
    assert (res.vertex_map[:n] >= 0).all()                   # every sphere vertex has a home
    assert DEBRIS_MAX_FACES < 20480 and DEBRIS_MAX_FACE_SHARE * F.shape[0] < 20480
    # specks on the sphere still go
    Vd, Fd = with_debris(*icosphere(4), k=50)
    assert clean_mesh(Vd, Fd).report.n_debris_components == 50


def t_junctions(V, F, faces, pieces=2, off=0.0):
    """Each face ``(a, b, c)`` of ``faces`` split into a fan from ``c`` over
    ``pieces`` parts of its edge ``a - b`` (the points moved ``off`` along
    ``c - a``), the neighbour across ``a - b`` left whole: T-junctions."""
    t = np.arange(1, pieces) / pieces
    a, b, c = V[F[faces, 0]], V[F[faces, 1]], V[F[faces, 2]]
    P = a[:, None] + t[None, :, None] * (b - a)[:, None] + off * (c - a)[:, None]
    ids = V.shape[0] + np.arange(faces.size * (pieces - 1)).reshape(faces.size, pieces - 1)
    chain = np.concatenate([F[faces, :1], ids, F[faces, 1:2]], axis=1)
    fan = np.stack([chain[:, :-1], chain[:, 1:], np.repeat(F[faces, 2:], pieces, axis=1)], axis=-1)
    keep = np.ones(F.shape[0], dtype=bool)
    keep[faces] = False
    return np.vstack([V, P.reshape(-1, 3)]), np.vstack([F[keep], fan.reshape(-1, 3)])


def test_t_junctions_are_zipped():
    """A face split at points of its edge, its neighbour left whole (a
    T-junction, as exports and scan merges leave them) is a hole of zero
    width: the neighbour is split across it, nothing moves, the sphere is
    closed again. Found by fuzzing: spot with 170 T-junctions kept 155 border
    loops, and simplify(max_error=2% of the size) stopped at 897 faces (180
    without them), saying the error bound stopped it."""
    from tests.mesh_factory import apart_faces
    V, F = icosphere(2)
    faces = apart_faces(F, 12, seed=0)
    assert faces.size == 12
    V2, F2 = t_junctions(V, F, faces, pieces=3)
    r = clean_mesh(V2, F2)
    assert_manifold(r.V, r.F)
    assert r.report.n_t_junctions == 12 and "zipped 12 T-junctions" in r.report.summary()
    top = topology_summary(r.F, r.V.shape[0])
    assert top.boundary_loops == 0 and top.euler == 2 and top.components == 1
    assert r.F.shape[0] == F2.shape[0] + 2 * 12                  # each neighbour in three parts
    np.testing.assert_array_equal(r.V, V2[r.clean_to_input])      # nothing moved
    np.testing.assert_allclose(core.face_areas(r.V, r.F).sum(), core.face_areas(V2, F2).sum(),
                               rtol=1e-12)
    res = core.simplify(V2, F2, max_error=0.02 * core.bbox_diagonal(V2))
    assert res.n_boundary_loops == 0 and res.cleaning.n_pinholes == 0


def test_only_zero_width_slits_are_zipped():
    """A T-vertex within the weld distance of the edge is on it; one a
    thousandth of the size off it leaves a real (thin) hole, kept open."""
    V, F = icosphere(2)
    faces = np.array([0])
    for off, zipped, loops in ((1e-9, 1, 0), (1e-3, 0, 1)):
        V2, F2 = t_junctions(V, F, faces, off=off)
        r = clean_mesh(V2, F2)
        assert r.report.n_t_junctions == zipped
        assert topology_summary(r.F, r.V.shape[0]).boundary_loops == loops


def test_t_junctions_on_two_faces_that_share_an_edge():
    """Two faces ``f = (u, v, w)`` and ``g = (v, u, y)`` both split across,
    ``f`` along ``v - w`` and ``g`` along ``u - y``: the third vertex of each
    is an end of the other's slit (it was left open, found by fuzzing: fandisk
    with T-junctions and slivers kept 20 such pairs)."""
    V, F = icosphere(1)
    owner = {(int(a), int(b)): f for f, row in enumerate(F) for a, b in zip(row, np.roll(row, -1))}
    u, v, w = F[0]
    g = owner[(v, u)]
    y = next(c for c in F[g] if c not in (u, v))
    across = np.array([owner[(w, v)], owner[(y, u)]])
    # each face across, rotated so its split edge comes first (a -> b, as the helper takes it)
    for f, (a, b) in zip(across, ((w, v), (y, u))):
        F[f] = np.roll(F[f], -int(np.flatnonzero(F[f] == a)[0]))
        assert F[f, 1] == b
    V2, F2 = t_junctions(V, F, across)
    r = clean_mesh(V2, F2)
    assert_manifold(r.V, r.F)
    assert r.report.n_t_junctions == 2
    assert topology_summary(r.F, r.V.shape[0]).boundary_loops == 0


def test_a_long_thin_strip_is_not_welded_into_nothing():
    # one zigzag polygon 0.5 high and 19,999 long (an OBJ face of 20,000 corners, fanned):
    # open along its whole length, so the automatic weld tried 1e-4 of its size (2 units)
    # and collapsed every face ('nothing is left after cleaning'); a wider weld that
    # collapses more than a tenth of the faces is not kept
    n = 20000
    t = np.arange(n)
    V = np.stack([t * 1.0, (t % 2) * 0.5, np.zeros(n)], axis=1)
    F = np.stack([t[:-2], t[1:-1], t[2:]], axis=1)          # a strip of n - 2 triangles
    F[1::2] = F[1::2][:, ::-1]                               # consistently wound
    r = core.clean_mesh(V, F)
    assert not r.report.weld_widened and r.report.n_welded_vertices == 0
    assert r.F.shape[0] == n - 2 and r.report.n_degenerate_faces == 0
    cage = core.simplify(V, F, target_faces=200)
    assert cage.F.shape[0] <= 200 and cage.stopped_because == "target"
