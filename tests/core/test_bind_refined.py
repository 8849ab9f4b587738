"""``bind_refined``: a binding's detail at other levels, found from the
binding (each dense vertex's face taken down the levels) instead of binding
every dense vertex again.

Properties: with the exact detail search the refine is :func:`bind`'s at
those levels (to rounding); with the local one nearly every fine vertex gets
the same point, every point lies on the dense surface and about as close as
bind's; each dense vertex's finer face holds it parametrically; messy (an
unwelded scan) and coarser levels work; bad arguments raise named errors.
"""

import dataclasses

import numpy as np
import pytest

from core._refine import CHILD_BARY
from core.binding import bind, bind_refined, deform, refine
from core.errors import CancelledError, InvalidArgumentError, InvalidMeshError
from core.mesh import bbox_diagonal
from core.simplify import simplify
from core.spatial import TriangleIndex
from core.subdivide import parametric_faces, subdivision_operator
from tests.mesh_factory import icosahedron, noisy_sphere, torus, unwelded


@pytest.fixture(scope="module")
def torus_scan():
    Vd, Fd = torus(160, 80, bump=0.01, bump_waves=(10, 5))
    return Vd, Fd, simplify(Vd, Fd, target_faces=240)


def _rest_of(b):
    """The dense mesh as the binding ``b`` binds it."""
    return deform(b, b.V_cage_rest)


@pytest.mark.parametrize("scheme", ["loop", "butterfly"])
@pytest.mark.parametrize("levels", [0, 1, 3])
def test_exact_detail_is_binds_at_those_levels(scheme, levels):
    Vd, Fd = noisy_sphere(3)
    cage = simplify(Vd, Fd, target_faces=80)
    b = bind(Vd, Fd, cage.V, cage.F, levels=2, scheme=scheme)
    got = bind_refined(b, _rest_of(b), levels)
    want = bind(Vd, Fd, cage.V, cage.F, levels=levels, scheme=scheme)
    assert (got.levels, got.scheme, got.fingerprint, got.n_dense) == \
        (levels, scheme, want.fingerprint, 0)
    assert got.F_dense is None and np.array_equal(got.V_cage_rest, cage.V)
    assert deform(got, cage.V).shape == (0, 3)
    Ve = cage.V.copy()
    Ve[[2, 5]] += 0.05
    assert np.abs(refine(got, Ve).V - refine(want, Ve).V).max() <= 1e-12 * bbox_diagonal(Vd)


@pytest.mark.parametrize("scheme", ["loop", "butterfly"])
def test_local_detail_is_on_the_dense_surface_and_nearly_always_binds(torus_scan, scheme):
    Vd, Fd, cage = torus_scan
    diag = bbox_diagonal(Vd)
    b = bind(Vd, Fd, cage.V, cage.F, levels=2, scheme=scheme, detail_search="local")
    got = refine(bind_refined(b, _rest_of(b), 4, detail_search="local"), cage.V).V
    want = refine(bind(Vd, Fd, cage.V, cage.F, levels=4, scheme=scheme,
                       detail_search="local"), cage.V).V
    same = np.abs(got - want).max(axis=1) <= 1e-12 * diag
    assert same.mean() >= 0.995
    index = TriangleIndex(Vd, Fd)
    assert index.closest(got).distance.max() <= 1e-9 * diag       # on the dense surface
    # each point about as near its fine vertex as the closest point of the dense surface
    P = subdivision_operator(cage.F, cage.V.shape[0], levels=4, scheme=scheme).apply(cage.V)
    closest = index.closest(P).distance
    excess = np.linalg.norm(got - P, axis=1) - closest
    assert np.mean(excess <= 1e-9 * diag) >= 0.995 and excess.max() <= 0.01 * diag


def test_each_dense_vertex_lies_in_its_finer_face_parametrically():
    rng = np.random.default_rng(4)
    k, depth = 2000, 3
    face = rng.integers(0, 50, k)
    bary = rng.dirichlet(np.ones(3), k)
    g = parametric_faces(face, bary, depth)
    assert np.array_equal(g // 4 ** depth, face)
    corners = np.broadcast_to(np.eye(3), (k, 3, 3)).copy()  # the fine face's corners ...
    h = g.copy()
    for _ in range(depth):                                     # ... in the coarse face
        corners = np.einsum("kij,kjl->kil", corners, CHILD_BARY[h % 4])
        h //= 4
    weights = np.linalg.solve(np.transpose(corners, (0, 2, 1)), bary[:, :, None])[:, :, 0]
    assert weights.min() >= -1e-12                             # inside (or on its border)
    assert np.array_equal(parametric_faces(g, bary, -depth), face)  # and up again: the parent


def test_an_unwelded_scan_and_coarser_levels(torus_scan):
    Vd, Fd, cage = torus_scan
    Vu, Fu = unwelded(Vd, Fd)                  # an STL: every triangle its own corners
    diag = bbox_diagonal(Vd)
    b = bind(Vu, Fu, cage.V, cage.F, levels=3, detail_search="local")
    index = TriangleIndex(Vd, Fd)
    for levels in (1, 4):
        got = refine(bind_refined(b, _rest_of(b), levels, detail_search="local"), cage.V).V
        want = refine(bind(Vu, Fu, cage.V, cage.F, levels=levels, detail_search="local"),
                      cage.V).V
        assert np.mean(np.abs(got - want).max(axis=1) <= 1e-12 * diag) >= 0.995
        assert index.closest(got).distance.max() <= 1e-9 * diag


def test_a_point_cloud_and_an_empty_mesh_have_no_detail():
    Vc, Fc = icosahedron()
    P = np.random.default_rng(0).standard_normal((50, 3))
    for V in (P, np.zeros((0, 3))):
        b = bind(V, np.zeros((0, 3), np.int64), Vc, Fc, levels=1)
        with pytest.raises(CancelledError):          # (it had no point to cancel at)
            bind_refined(b, V, 3, progress=lambda f: False)
        got = bind_refined(b, V, 3)
        assert not got.fine_detail.any()
        assert np.abs(refine(got, Vc).V - got.operator.apply(Vc)).max() <= 1e-14


@pytest.mark.parametrize("levels", [0, 1])
def test_from_a_coarse_binding_the_dense_vertices_are_bound_again(torus_scan, levels):
    # (a 60-face cage's binding at 0 levels, taken to 3: bind's points for 94% of the fine
    # vertices; from fewer than two levels the seeds are bind's own)
    Vd, Fd, cage = torus_scan
    b = bind(Vd, Fd, cage.V, cage.F, levels=levels, detail_search="local")
    got = refine(bind_refined(b, Vd, 3, detail_search="local"), cage.V).V
    want = refine(bind(Vd, Fd, cage.V, cage.F, levels=3, detail_search="local"), cage.V).V
    assert np.array_equal(got, want)


def test_inputs_are_not_modified_and_a_cancel_stops_it(torus_scan):
    Vd, Fd, cage = torus_scan
    b = bind(Vd, Fd, cage.V, cage.F, levels=2, detail_search="local")
    V = _rest_of(b)
    keep = V.copy(), b.fine_face.copy(), b.bary.copy()
    fractions = []
    with pytest.raises(CancelledError):
        bind_refined(b, V, 3, detail_search="local",
                     progress=lambda f: fractions.append(f) or f < 0.2)
    assert 0.0 < fractions[-1] < 0.5
    bind_refined(b, V, 3, detail_search="local", progress=lambda f: True)
    assert all(np.array_equal(a, k) for a, k in zip((V, b.fine_face, b.bary), keep))


def test_bad_arguments_raise_named_errors():
    Vd, Fd = noisy_sphere(2)
    cage = simplify(Vd, Fd, target_faces=40)
    b = bind(Vd, Fd, cage.V, cage.F, levels=1)
    with pytest.raises(InvalidArgumentError, match="bind_refined: expected a Binding"):
        bind_refined("b", Vd, 2)
    with pytest.raises(InvalidArgumentError, match=r"no dense faces \(F_dense\)"):
        bind_refined(dataclasses.replace(b, F_dense=None), Vd, 2)
    with pytest.raises(InvalidArgumentError, match="no rest cage: give V_cage"):
        bind_refined(dataclasses.replace(b, V_cage_rest=None), Vd, 2)
    with pytest.raises(InvalidMeshError, match=rf"V_dense has 5 rows but the binding has "
                                               rf"{Vd.shape[0]} dense vertices"):
        bind_refined(b, Vd[:5], 2)
    bad = Vd.copy()
    bad[3, 1] = np.nan
    with pytest.raises(InvalidMeshError, match="V_dense"):
        bind_refined(b, bad, 2)
    with pytest.raises(InvalidMeshError, match="V_cage has 3 rows"):
        bind_refined(b, Vd, 2, V_cage=cage.V[:3])
    with pytest.raises(InvalidArgumentError, match="detail_search must be one of"):
        bind_refined(b, Vd, 2, detail_search="near")
    with pytest.raises(InvalidArgumentError, match="progress must be callable"):
        bind_refined(b, Vd, 2, progress=3)
    with pytest.raises(InvalidArgumentError, match="levels"):
        bind_refined(b, Vd, -1)
