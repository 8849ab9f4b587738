"""Tests of core.subdivide: modified butterfly and Loop as linear operators.

The reference implementation at the top is deliberately slow and plain (loops
and dictionaries, one rule per edge, straight from the module docstring); the
vectorised operator must agree with it.
"""

from collections import defaultdict

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from core import _refine
from core.errors import InvalidArgumentError, InvalidMeshError
from core.subdivide import SubdivisionOperator, subdivide, subdivision_operator
from core.mesh import face_normals
from core.topology import edge_faces as _edge_faces, edge_map, euler_characteristic, manifold_report
from tests.mesh_factory import (midpoint_split, cube, icosahedron, icosphere, load_shared, octahedron, regular_grid,
                                tetrahedron, torus)

# ---------------------------------------------------------------------------
# slow, obviously-correct reference: one subdivision level, rule by rule


def _butterfly_s(k):
    if k == 3:
        return [5 / 12, -1 / 12, -1 / 12]
    if k == 4:
        return [3 / 8, 0.0, -1 / 8, 0.0]
    return [(0.25 + np.cos(2 * np.pi * j / k) + 0.5 * np.cos(4 * np.pi * j / k)) / k for j in range(k)]


def reference_level(V, F, creases, scheme):
    """One level of subdivision, per edge and per vertex with Python loops."""
    V = np.asarray(V, dtype=float)
    n = len(V)
    F = [tuple(int(x) for x in f) for f in F]
    edges = sorted({(min(u, v), max(u, v)) for f in F for u, v in ((f[0], f[1]), (f[1], f[2]), (f[2], f[0]))})
    eid = {e: i for i, e in enumerate(edges)}
    opposite = {}  # directed (u, v) -> w for the face (u, v, w)
    for a, b, c in F:
        opposite[(a, b)], opposite[(b, c)], opposite[(c, a)] = c, a, b
    crease = {(min(u, v), max(u, v)) for u, v in creases}
    nbrs = defaultdict(set)
    for u, v in edges:
        nbrs[u].add(v)
        nbrs[v].add(u)

    def sharp(u, v):
        return (min(u, v), max(u, v)) in crease or not ((u, v) in opposite and (v, u) in opposite)

    n_sharp = defaultdict(int)
    for u, v in edges:
        if sharp(u, v):
            n_sharp[u] += 1
            n_sharp[v] += 1

    def ring(v, start):
        r, cur = [start], opposite[(v, start)]
        while cur != start:
            r.append(cur)
            cur = opposite[(v, cur)]
        return r

    def sharp_nbrs(v):
        return sorted(w for w in nbrs[v] if sharp(v, w))

    out = np.zeros((n + len(edges), V.shape[1]))
    # old vertices
    for v in range(n):
        if scheme == "butterfly":
            out[v] = V[v]
        else:
            k, s = len(nbrs[v]), n_sharp[v]
            if k == 0 or s == 1 or s >= 3:
                out[v] = V[v]
            elif s == 2:
                p, q = sharp_nbrs(v)
                out[v] = 0.75 * V[v] + 0.125 * (V[p] + V[q])
            else:
                beta = 3 / 16 if k == 3 else 3 / (8 * k)
                out[v] = (1 - k * beta) * V[v] + beta * sum(V[w] for w in nbrs[v])
    # new vertices
    for (a, b), k in eid.items():
        if scheme == "loop":
            if sharp(a, b):
                p = 0.5 * (V[a] + V[b])
            else:
                p = 0.375 * (V[a] + V[b]) + 0.125 * (V[opposite[(a, b)]] + V[opposite[(b, a)]])
        elif sharp(a, b):
            def outer(x, y):
                if n_sharp[x] == 2:
                    (z,) = [w for w in sharp_nbrs(x) if w != y]
                    return V[z]
                return 2 * V[x] - V[y]   # corner: reflected, never across it
            p = -outer(a, b) / 16 + 9 / 16 * V[a] + 9 / 16 * V[b] - outer(b, a) / 16
        else:
            ext = [x for x in (a, b) if n_sharp[x] == 0 and len(nbrs[x]) != 6]
            if ext:
                stencils = []
                for x in ext:
                    y = b if x == a else a
                    r = ring(x, y)
                    stencils.append(0.75 * V[x] + sum(w * V[z] for w, z in zip(_butterfly_s(len(r)), r)))
                p = sum(stencils) / len(stencils)
            else:
                c, d = opposite[(a, b)], opposite[(b, a)]

                def wing(x, y, apex):   # across edge (x, y) of a face whose third vertex is apex
                    if sharp(x, y):
                        return V[x] + V[y] - V[apex]
                    return V[opposite[(y, x)]]
                wings = wing(b, c, a) + wing(c, a, b) + wing(a, d, b) + wing(d, b, a)
                p = 0.5 * (V[a] + V[b]) + 0.125 * (V[c] + V[d]) - wings / 16
        out[n + k] = p
    F2 = []
    for a, b, c in F:
        ma = n + eid[(min(b, c), max(b, c))]
        mb = n + eid[(min(c, a), max(c, a))]
        mc = n + eid[(min(a, b), max(a, b))]
        F2 += [(a, mc, mb), (mc, b, ma), (mb, ma, c), (ma, mb, mc)]
    creases2 = []
    for u, v in crease:
        creases2 += [(u, n + eid[(u, v)]), (v, n + eid[(u, v)])]
    return out, np.array(F2, dtype=np.int64).reshape(-1, 3), creases2


def reference(V, F, levels, scheme, creases=()):
    creases = [tuple(c) for c in creases]
    for _ in range(levels):
        V, F, creases = reference_level(V, F, creases, scheme)
    return V, F


# ---------------------------------------------------------------------------
# small meshes built here


def fan_disk(k=5):
    """An open disk: one interior vertex of valence k, k boundary vertices."""
    ang = np.arange(k) * 2 * np.pi / k
    V = np.vstack([[0, 0, 0], np.stack([np.cos(ang), np.sin(ang), np.zeros(k)], 1)])
    F = np.array([[0, 1 + i, 1 + (i + 1) % k] for i in range(k)], dtype=np.int64)
    return V, F


def mixed_valence_patch():
    """Open planar patch: regular grid with one vertex removed in the middle
    and its hole re-triangulated, giving interior vertices of valence 5, 7 and
    extraordinary vertices next to the boundary."""
    V, F = regular_grid(6, 6, size=6.0)
    rng = np.random.default_rng(3)
    V[:, :2] += rng.uniform(-0.15, 0.15, (V.shape[0], 2)) * ((V[:, 0] > 0) & (V[:, 0] < 6)
                                                            & (V[:, 1] > 0) & (V[:, 1] < 6))[:, None]
    # flip a few interior diagonals: edge (v00, v11) -> (v10, v01) in quads (i, j)
    F = F.copy()
    nq = 36
    for i, j in ((2, 2), (3, 1), (1, 4), (0, 0)):
        q = j * 6 + i
        v00, v10, v11, v01 = j * 7 + i, j * 7 + i + 1, j * 7 + i + 8, j * 7 + i + 7
        F[q] = [v00, v10, v01]
        F[q + nq] = [v10, v11, v01]
    return V, F


def bipyramid(k=10):
    """Closed: two apexes of valence k (rows longer than 8 entries), a ring of valence 4."""
    ang = np.arange(k) * 2 * np.pi / k
    V = np.vstack([np.stack([np.cos(ang), np.sin(ang), 0.1 * np.cos(3 * ang)], 1), [[0, 0, 1.2], [0, 0, -0.8]]])
    top = [[i, (i + 1) % k, k] for i in range(k)]
    bottom = [[(i + 1) % k, i, k + 1] for i in range(k)]
    return V, np.array(top + bottom, dtype=np.int64)


def cube_creases(V, F):
    """Edges of the triangulated cube that lie on the 12 cube edges."""
    E = edge_map(F, len(V)).E
    mid = 0.5 * (V[E[:, 0]] + V[E[:, 1]])
    on = (np.isclose(np.abs(mid), 0.5).sum(axis=1) >= 2)
    return E[on]


MESHES = {
    "tetrahedron": tetrahedron,
    "octahedron": octahedron,
    "icosahedron": icosahedron,
    "icosphere1": lambda: icosphere(1),
    "torus": lambda: torus(8, 6),
    "grid": lambda: regular_grid(5, 4),
    "fan5": lambda: fan_disk(5),
    "fan3": lambda: fan_disk(3),
    "patch": mixed_valence_patch,
    "cube": lambda: cube(2),
    "bipyramid": bipyramid,
    "fan9": lambda: fan_disk(9),
}


def _random_positions(V, seed=0):
    rng = np.random.default_rng(seed)
    return V + 0.05 * rng.standard_normal(V.shape)


# ---------------------------------------------------------------------------
# counts, numbering, sums


@pytest.mark.parametrize("scheme", ["butterfly", "loop"])
@pytest.mark.parametrize("name", ["tetrahedron", "icosphere1", "torus", "grid", "patch", "cube"])
def test_exact_counts_per_level(name, scheme):
    V, F = MESHES[name]()
    n, m = len(V), len(F)
    for levels in range(4):
        op = subdivision_operator(F, n, levels=levels, scheme=scheme)
        n_exp, F_exp = n, F
        for _ in range(levels):
            e = edge_map(F_exp, n_exp).E.shape[0]
            F_exp = _refine.split_faces(F_exp, n_exp, edge_map(F_exp, n_exp).face_edge)
            n_exp += e
        assert op.n_fine == n_exp
        assert op.F_fine.shape == (m * 4 ** levels, 3)
        assert np.array_equal(op.F_fine, F_exp)
        assert np.array_equal(op.fine_to_coarse_face, np.repeat(np.arange(m), 4 ** levels))
        assert euler_characteristic(op.F_fine, op.n_fine) == euler_characteristic(F, n)
        assert manifold_report(op.F_fine, op.n_fine).is_oriented_manifold


def test_numbering_new_vertex_on_edge_k():
    V, F = icosphere(1)
    n = len(V)
    em = edge_map(F, n)
    op = subdivision_operator(F, n, levels=1, scheme="loop")
    face, bary = op.fine_vertex_parent()
    # new vertex n + k sits halfway along E[k] of the parent face
    for k in (0, 7, em.E.shape[0] - 1):
        b = bary[n + k]
        P = b @ V[F[face[n + k]]]
        assert np.allclose(P, 0.5 * (V[em.E[k, 0]] + V[em.E[k, 1]]))
    # old vertices sit at a corner of their face
    assert np.array_equal(F[face[:n], np.argmax(bary[:n], axis=1)], np.arange(n))
    assert np.all(bary[:n].max(axis=1) == 1.0)
    # child i < 3 of face f keeps corner i
    for i in range(3):
        assert np.array_equal(op.F_fine[i::4, i], F[:, i])


@pytest.mark.parametrize("name", ["icosphere1", "patch", "cube"])
def test_fine_vertex_parent_matches_iterated_midpoint_split(name):
    V, F = MESHES[name]()
    op = subdivision_operator(F, len(V), levels=3, scheme="loop")
    face, bary = op.fine_vertex_parent()
    assert np.all(bary >= 0) and np.allclose(bary.sum(axis=1), 1.0)
    param = np.einsum("ij,ijk->ik", bary, V[F[face]])
    Vm, Fm = V, F
    for _ in range(3):
        Vm, Fm = midpoint_split(Vm, Fm)   # the test factory's own split, same vertex numbering
    np.testing.assert_allclose(param, Vm, rtol=0, atol=1e-14)
    # each fine face's corners lie in (or on the border of) its parent coarse face
    T = V[F[op.fine_to_coarse_face]]                   # (m 4^L, 3, 3)
    e1, e2 = T[:, 1] - T[:, 0], T[:, 2] - T[:, 0]
    G = np.stack([np.stack([(e1 * e1).sum(1), (e1 * e2).sum(1)], 1),
                  np.stack([(e1 * e2).sum(1), (e2 * e2).sum(1)], 1)], 1)
    for j in range(3):
        d = param[op.F_fine[:, j]] - T[:, 0]
        uv = np.linalg.solve(G, np.stack([(d * e1).sum(1), (d * e2).sum(1)], 1)[..., None])[..., 0]
        b = np.column_stack([1 - uv.sum(1), uv])
        assert b.min() > -1e-12
        np.testing.assert_allclose(np.einsum("ij,ijk->ik", b, T), param[op.F_fine[:, j]], atol=1e-12)


@pytest.mark.parametrize("scheme", ["butterfly", "loop"])
@pytest.mark.parametrize("name", list(MESHES))
def test_every_stencil_row_sums_to_one(name, scheme):
    V, F = MESHES[name]()
    creases = cube_creases(V, F) if name == "cube" else None
    op = subdivision_operator(F, len(V), levels=2, scheme=scheme, creases=creases)
    for S in op.stencils:
        sums = np.add.reduceat(S.weights, S.indptr[:-1])
        assert np.all(np.diff(S.indptr) >= 1)
        np.testing.assert_allclose(sums, 1.0, rtol=0, atol=1e-14)
        assert np.all(S.weights != 0)
    rows, cols, w = op.triplets()
    assert np.all(np.diff(rows) >= 0)
    np.testing.assert_allclose(np.bincount(rows, w, op.n_fine), 1.0, rtol=0, atol=1e-13)


@pytest.mark.parametrize("name", list(MESHES))
def test_butterfly_keeps_old_vertices_bit_for_bit(name):
    V, F = MESHES[name]()
    V = _random_positions(V, 1)
    Vf, _ = subdivide(V, F, levels=3, scheme="butterfly")
    assert np.array_equal(Vf[:len(V)], V)


# ---------------------------------------------------------------------------
# the operator equals the rules, composes, and has an exact adjoint


@pytest.mark.parametrize("scheme", ["butterfly", "loop"])
@pytest.mark.parametrize("name", list(MESHES))
def test_operator_equals_rule_by_rule_reference(name, scheme):
    V, F = MESHES[name]()
    V = _random_positions(V, 2)
    creases = cube_creases(*MESHES[name]()) if name == "cube" else []
    for levels in (1, 2):
        Vf, Ff = subdivide(V, F, levels=levels, scheme=scheme, creases=creases if len(creases) else None)
        Vr, Fr = reference(V, F, levels, scheme, creases)
        assert np.array_equal(Ff, Fr)
        np.testing.assert_allclose(Vf, Vr, rtol=0, atol=1e-12)


def test_operator_with_creases_on_a_smooth_surface_equals_reference():
    V, F = icosphere(1)
    E = edge_map(F, len(V)).E
    # a crease path through the sphere: a few edges, endpoints become corners,
    # plus a vertex where three creases meet
    creases = E[[0, 1, 2, 10, 11, 40]]
    for scheme in ("butterfly", "loop"):
        Vf, _ = subdivide(V, F, levels=2, scheme=scheme, creases=creases)
        Vr, _ = reference(V, F, 2, scheme, creases)
        np.testing.assert_allclose(Vf, Vr, rtol=0, atol=1e-12)


@pytest.mark.parametrize("scheme", ["butterfly", "loop"])
def test_operator_composes_over_levels(scheme):
    V, F = mixed_valence_patch()
    V = _random_positions(V, 4)
    op2 = subdivision_operator(F, len(V), levels=2, scheme=scheme)
    op1 = subdivision_operator(F, len(V), levels=1, scheme=scheme)
    op1b = subdivision_operator(op1.F_fine, op1.n_fine, levels=1, scheme=scheme)
    assert np.array_equal(op1b.F_fine, op2.F_fine)
    np.testing.assert_allclose(op2.apply(V), op1b.apply(op1.apply(V)), rtol=0, atol=1e-13)
    # triplets compose the levels into one matrix
    rows, cols, w = op2.triplets()
    direct = np.stack([np.bincount(rows, w * V[cols, d], op2.n_fine) for d in range(3)], 1)
    np.testing.assert_allclose(direct, op2.apply(V), rtol=0, atol=1e-13)
    assert np.all(np.diff(rows * op2.n_coarse + cols) > 0)   # sorted, no repeated pair


@pytest.mark.parametrize("scheme", ["butterfly", "loop"])
@pytest.mark.parametrize("name", ["bipyramid", "fan9", "patch", "cube"])
def test_apply_plan_equals_the_csr_arrays(name, scheme):
    V, F = MESHES[name]()
    op = subdivision_operator(F, len(V), levels=2, scheme=scheme)
    X = _random_positions(V, 9)
    for S in op.stencils:
        assert S.plan is not None
        csr = S._replace(plan=None).apply(X)
        np.testing.assert_allclose(S.apply(X), csr, rtol=0, atol=1e-14)
        X = csr
    # the long rows (valence > 7) really went through the overflow path
    if name == "fan9" or (name, scheme) == ("bipyramid", "loop"):
        assert op.stencils[0].plan.long_rows.shape[0] > 0


@pytest.mark.parametrize("scheme", ["butterfly", "loop"])
def test_a_large_level_applied_in_threaded_chunks_equals_its_rows_bit_for_bit(scheme):
    """A level of more than 65,536 rows is applied in chunks of its blocks on
    the worker threads; every row is the one ``rows_t`` gives for it (each
    block's rows gathered and summed at once), so neither the cuts nor the
    threads change a bit, and repeated applies agree."""
    V, F = icosphere(4)
    op = subdivision_operator(F, len(V), levels=3, scheme=scheme)
    S = op.stencils[-1]
    assert S.n_out > 65536 and any(not b.copy and b.stop - b.start > 32768 for b in S.plan.blocks)
    Xt = np.ascontiguousarray(np.random.default_rng(3).standard_normal((3, S.n_in)))
    whole = S.apply_t(Xt)
    assert np.array_equal(whole, S.rows_t(Xt, np.arange(S.n_out)))
    assert np.array_equal(whole, S.apply_t(Xt))
    every_other = np.arange(0, S.n_out, 2)
    assert np.array_equal(whole[:, every_other], S.rows_t(Xt, every_other))


@pytest.mark.parametrize("scheme", ["butterfly", "loop"])
@pytest.mark.parametrize("name", ["fan9", "patch", "cube", "torus"])
def test_apply_writes_the_last_level_into_the_result_bit_for_bit(name, scheme):
    """apply() evaluates the last level straight into the (n_fine, k) result;
    it equals the level-by-level Stencil.apply chain exactly, for any k and 1-D."""
    V, F = MESHES[name]()
    for levels in (1, 2, 3):
        op = subdivision_operator(F, len(V), levels=levels, scheme=scheme)
        X = np.random.default_rng(levels).standard_normal((len(V), 5))
        chain = X
        for S in op.stencils:
            chain = S.apply(chain)
        out = op.apply(X)
        assert out.shape == (op.n_fine, 5) and out.flags.c_contiguous
        assert np.array_equal(out, chain)
        one = op.apply(X[:, 2])
        assert one.shape == (op.n_fine,) and one.flags.c_contiguous
        assert np.array_equal(one, chain[:, 2])
    op0 = subdivision_operator(F, len(V), levels=0, scheme=scheme)
    assert np.array_equal(op0.apply(X), X) and not np.shares_memory(op0.apply(X), X)


def test_refined_topology_equals_topology_from_scratch():
    for name in ("torus", "patch", "cube", "fan3"):
        V, F = MESHES[name]()
        T = _refine.topology(F, len(V), np.zeros(0, dtype=np.int64), "test", True)
        for _ in range(2):
            T2 = _refine.refine_topology(T)
            R = _refine.topology(T2.F, T2.n, np.zeros(0, dtype=np.int64), "test", True)
            for field in ("F", "E", "face_edge", "faces", "corners", "opp", "valence", "n_sharp"):
                assert np.array_equal(getattr(T2, field), getattr(R, field)), (name, field)
            T = T2


@pytest.mark.parametrize("scheme", ["butterfly", "loop"])
def test_apply_transpose_is_the_adjoint(scheme):
    V, F = mixed_valence_patch()
    op = subdivision_operator(F, len(V), levels=2, scheme=scheme)
    rng = np.random.default_rng(5)
    x = rng.standard_normal((op.n_coarse, 4))
    y = rng.standard_normal((op.n_fine, 4))
    lhs = np.sum(op.apply(x) * y)
    rhs = np.sum(x * op.apply_transpose(y))
    assert abs(lhs - rhs) <= 1e-12 * (abs(lhs) + 1)
    # 1-D values and the transpose as an explicit matrix from the triplets
    rows, cols, w = op.triplets()
    AT_y = np.bincount(cols, w * y[rows, 0], op.n_coarse)
    np.testing.assert_allclose(op.apply_transpose(y[:, 0]), AT_y, rtol=0, atol=1e-12)
    assert op.apply(x[:, 0]).shape == (op.n_fine,)


def test_support_matches_the_triplets():
    V, F = icosphere(1)
    op = subdivision_operator(F, len(V), levels=2)
    rows, cols, w = op.triplets()
    ids = np.array([0, 5, 17])
    expected = np.zeros(op.n_fine, dtype=bool)
    expected[rows[np.isin(cols, ids)]] = True
    assert np.array_equal(op.support(ids), expected)
    mask = np.zeros(op.n_coarse, dtype=bool)
    mask[ids] = True
    assert np.array_equal(op.support(mask), expected)
    assert 0 < expected.sum() < op.n_fine


# ---------------------------------------------------------------------------
# geometry: planar, polynomial reproduction, spheres, boundaries, creases


@pytest.mark.parametrize("scheme", ["butterfly", "loop"])
@pytest.mark.parametrize("name", ["grid", "patch", "fan5", "fan3"])
def test_planar_mesh_stays_planar(name, scheme):
    V, F = MESHES[name]()
    V = V.copy()
    V[:, 2] = 0.0
    R = np.linalg.qr(np.random.default_rng(6).standard_normal((3, 3)))[0]
    V = V @ R.T + np.array([0.3, -1.0, 2.0])
    normal = R[:, 2]
    Vf, _ = subdivide(V, F, levels=3, scheme=scheme)
    dist = (Vf - V[0]) @ normal
    assert np.abs(dist).max() < 1e-12 * np.abs(V).max()


def _cubic(x, y):
    return 0.3 * x ** 3 - 0.7 * x ** 2 * y + 1.1 * x * y ** 2 + 0.4 * y ** 3 - x * y + 0.2 * x - 0.5 * y + 0.1


@pytest.mark.parametrize("levels", [1, 2])
def test_butterfly_reproduces_cubic_height_field_on_regular_grid(levels):
    nx = 12
    V, F = regular_grid(nx, nx, size=float(nx), z=_cubic)
    op = subdivision_operator(F, len(V), levels=levels)
    Vf = op.apply(V)
    face, bary = op.fine_vertex_parent()
    param = np.einsum("ij,ijk->ik", bary, V[F[face]])[:, :2]
    # stay away from the boundary rules' influence (3 coarse rings)
    far = np.all((param > 3) & (param < nx - 3), axis=1)
    assert far.sum() > 50
    np.testing.assert_allclose(Vf[far, :2], param[far], rtol=0, atol=1e-12)
    np.testing.assert_allclose(Vf[far, 2], _cubic(param[far, 0], param[far, 1]), rtol=0, atol=1e-10)
    # level 1: every new vertex whose edge has both ends inside is exact
    if levels == 1:
        E = edge_map(F, len(V)).E
        inside = np.all((V[:, :2] > 0) & (V[:, :2] < nx), axis=1)
        sel = len(V) + np.flatnonzero(inside[E[:, 0]] & inside[E[:, 1]])
        np.testing.assert_allclose(Vf[sel, 2], _cubic(Vf[sel, 0], Vf[sel, 1]), rtol=0, atol=1e-10)
    # and it does not reproduce a quartic (the test has teeth)
    V4, _ = regular_grid(nx, nx, size=float(nx), z=lambda x, y: x ** 4)
    Vf4 = op.apply(V4)
    assert np.abs(Vf4[far, 2] - param[far, 0] ** 4).max() > 1e-3


@pytest.mark.parametrize("levels", [1, 2])
def test_loop_reproduces_linear_fields_on_regular_grid(levels):
    nx = 8
    V, F = regular_grid(nx, nx, size=float(nx), z=lambda x, y: 0.25 * x - 0.5 * y + 1.0)
    op = subdivision_operator(F, len(V), levels=levels, scheme="loop")
    Vf = op.apply(V)
    face, bary = op.fine_vertex_parent()
    param = np.einsum("ij,ijk->ik", bary, V[F[face]])
    # the four grid corners are curve vertices of the boundary and move inwards
    corners = np.array([[0, 0], [0, nx], [nx, 0], [nx, nx]], dtype=float)
    d = np.min(np.linalg.norm(param[:, None, :2] - corners[None], axis=2), axis=1)
    ok = d > (0.0 if levels == 1 else 1.01)   # level 2: their error spreads one ring
    np.testing.assert_allclose(Vf[ok], param[ok], rtol=0, atol=1e-12)
    assert not np.allclose(Vf[~ok], param[~ok])


def test_loop_cube_lies_between_two_spheres():
    V, F = cube(1)
    Vf, Ff = subdivide(V, F, levels=4, scheme="loop")
    r = np.linalg.norm(Vf, axis=1)
    # positive weights: inside the cube's circumsphere; smooth: well outside its insphere's half
    assert r.max() <= np.sqrt(3) / 2 + 1e-12
    assert r.min() >= 0.25
    assert r.max() - r.min() < 0.3
    assert Ff.shape[0] == 12 * 4 ** 4


@pytest.mark.parametrize("scheme", ["butterfly", "loop"])
def test_open_grid_boundary_refines_as_a_curve_only(scheme):
    nx = 6
    V, F = regular_grid(nx, nx, size=1.0)
    rng = np.random.default_rng(8)
    V[:, 2] = 0.1 * rng.standard_normal(len(V))
    boundary = np.zeros(len(V), dtype=bool)
    em = edge_map(F, len(V))
    boundary[em.E[em.edge_face_count == 1].ravel()] = True
    op = subdivision_operator(F, len(V), levels=2, scheme=scheme)
    fine_boundary = np.zeros(op.n_fine, dtype=bool)
    emf = edge_map(op.F_fine, op.n_fine)
    fine_boundary[emf.E[emf.edge_face_count == 1].ravel()] = True
    V2 = V.copy()
    V2[~boundary] += rng.standard_normal(((~boundary).sum(), 3))
    A, B = op.apply(V), op.apply(V2)
    assert np.array_equal(A[fine_boundary], B[fine_boundary])
    assert not np.allclose(A[~fine_boundary], B[~fine_boundary])
    # and along one side the rule is the 4-point (butterfly) / midpoint + (1,6,1) (Loop) of that side
    side = np.flatnonzero(V[:, 1] == 0)          # vertices (i, 0), i = 0..nx, in order
    e_side = [np.flatnonzero((em.E[:, 0] == side[i]) & (em.E[:, 1] == side[i + 1]))[0] for i in range(nx)]
    z = V[side, 2]
    A1 = subdivide(V, F, levels=1, scheme=scheme).V
    for i in range(1, nx - 1):
        new = A1[len(V) + e_side[i], 2]
        if scheme == "butterfly":
            expect = (-z[i - 1] + 9 * z[i] + 9 * z[i + 1] - z[i + 2]) / 16 if i + 2 <= nx else None
        else:
            expect = 0.5 * (z[i] + z[i + 1])
        if expect is not None:
            assert new == pytest.approx(expect, abs=1e-14)


def test_interior_edges_next_to_the_boundary_read_no_missing_neighbour():
    # a single triangle and a strip: every wing is missing, the result is still
    # an affine combination of existing vertices and reproduces the plane
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], dtype=float)
    F = np.array([[0, 1, 3], [0, 3, 2]])
    op = subdivision_operator(F, 4, levels=1)
    Vf = op.apply(V)
    new = Vf[4 + np.flatnonzero((edge_map(F, 4).E == [0, 3]).all(axis=1))[0]]
    np.testing.assert_allclose(new, [0.5, 0.5, 0.0], atol=1e-15)
    assert np.all(op.stencils[0].cols < 4)


@pytest.mark.parametrize("scheme", ["butterfly", "loop"])
@pytest.mark.parametrize("n", [1, 2])
def test_cube_with_crease_edges_keeps_them_straight_and_corners_fixed(scheme, n):
    V, F = cube(n)
    creases = cube_creases(V, F)
    assert creases.shape[0] == 12 * n
    op = subdivision_operator(F, len(V), levels=3, scheme=scheme, creases=creases)
    Vf = op.apply(V)
    corner = np.all(np.isclose(np.abs(V), 0.5), axis=1)
    assert corner.sum() == 8
    assert np.array_equal(Vf[np.flatnonzero(corner)], V[corner])
    face, bary = op.fine_vertex_parent()
    param = np.einsum("ij,ijk->ik", bary, V[F[face]])
    on_edge = np.isclose(np.abs(param), 0.5).sum(axis=1) >= 2
    assert on_edge.sum() == 12 * (n * 8 - 1) + 8
    # crease vertices stay on their straight cube edge, uniformly spaced
    np.testing.assert_allclose(Vf[on_edge], param[on_edge], rtol=0, atol=1e-14)
    # the flat sides stay flat: every vertex on the cube's surface
    np.testing.assert_allclose(np.abs(Vf).max(axis=1), 0.5, rtol=0, atol=1e-14)
    # without creases the cube rounds off
    Vs = subdivide(V, F, levels=3, scheme=scheme).V
    assert np.abs(np.abs(Vs).max(axis=1) - 0.5).max() > 0.01


# ---------------------------------------------------------------------------
# input validation


def test_non_manifold_edge_raises_naming_it():
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1]], dtype=float)
    F = np.array([[0, 1, 2], [1, 0, 3], [0, 1, 4]])
    with pytest.raises(InvalidMeshError, match=r"subdivide: 1 non-manifold edges .*\(0, 1\)"):
        subdivide(V, F)


def test_non_manifold_vertex_raises_naming_it():
    # two triangles touching at vertex 2 only (a bow tie), plus two closed cones at vertex 0
    V = np.zeros((5, 3))
    V[:, 0] = np.arange(5)
    F = np.array([[0, 1, 2], [2, 3, 4]])
    with pytest.raises(InvalidMeshError, match=r"non-manifold vertices .*vertex 2"):
        subdivision_operator(F, 5)
    Vt, Ft = tetrahedron()
    F2 = np.vstack([Ft, Ft + 4])
    F2[F2 == 4] = 0   # two closed tetrahedra sharing vertex 0: two closed fans
    with pytest.raises(InvalidMeshError, match=r"non-manifold vertices .*vertex 0"):
        subdivision_operator(F2, 8, scheme="loop")


def test_bad_orientation_degenerate_and_duplicate_faces_raise():
    V, F = octahedron()
    F2 = F.copy()
    F2[0] = F2[0, ::-1]
    with pytest.raises(InvalidMeshError, match="consistently oriented"):
        subdivide(V, F2)
    with pytest.raises(InvalidMeshError, match="degenerate"):
        subdivide(V, np.vstack([F, [[0, 0, 1]]]))
    with pytest.raises(InvalidMeshError, match="duplicate faces"):
        subdivide(V[:3], np.array([[0, 1, 2], [0, 2, 1]]))
    with pytest.raises(InvalidMeshError, match=r"F must be \(m,3\) integers"):
        subdivide(V, F.astype(float))


def test_bad_arguments_raise():
    V, F = octahedron()
    with pytest.raises(InvalidArgumentError, match="scheme"):
        subdivide(V, F, scheme="catmull-clark")
    with pytest.raises(InvalidArgumentError, match="levels"):
        subdivide(V, F, levels=-1)
    with pytest.raises(InvalidArgumentError, match="levels"):
        subdivision_operator(F, 6, levels=1.5)
    with pytest.raises(InvalidArgumentError, match=r"not an edge"):
        subdivide(V, F, creases=[[0, 1]])   # opposite poles
    with pytest.raises(InvalidArgumentError, match="creases"):
        subdivide(V, F, creases=[[0, 2, 4]])
    op = subdivision_operator(F, 6)
    with pytest.raises(InvalidArgumentError, match="apply"):
        op.apply(np.zeros((5, 3)))
    # NaN coarse values are named (they gave NaN fine positions, silently)
    bad = V.copy()
    bad[[2, 4], 1] = [np.nan, np.inf]
    with pytest.raises(InvalidArgumentError, match=r"apply: 2 coarse vertices have NaN or infinite "
                                                   r"values, e.g. row 2 = \[.*nan"):
        op.apply(bad)
    with pytest.raises(InvalidArgumentError, match="1 coarse vertices"):
        op.apply(np.where(np.arange(6) == 5, np.nan, 0.0))


def test_isolated_vertices_components_levels_zero_and_empty():
    V1, F1 = tetrahedron()
    V2, F2 = icosahedron()
    V = np.vstack([V1, [[9.0, 9, 9]], V2 + 3])
    F = np.vstack([F1, F2 + 5])
    for scheme in ("butterfly", "loop"):
        Vf, Ff = subdivide(V, F, levels=2, scheme=scheme)
        assert np.array_equal(Vf[4], V[4])             # isolated vertex kept, untouched
        Va, _ = subdivide(V1, F1, levels=2, scheme=scheme)
        Vb, _ = subdivide(V2, F2, levels=2, scheme=scheme)
        assert Vf.shape[0] == Va.shape[0] + Vb.shape[0] + 1
    op0 = subdivision_operator(F, len(V), levels=0)
    assert np.array_equal(op0.apply(V), V) and np.array_equal(op0.F_fine, F)
    r, c, w = op0.triplets()
    assert np.array_equal(r, c) and np.all(w == 1)
    Ve, Fe = subdivide(np.zeros((3, 3)), np.zeros((0, 3), dtype=np.int64), levels=2)
    assert Ve.shape == (3, 3) and Fe.shape == (0, 3)


def test_inputs_not_modified_and_result_types():
    V, F = icosphere(1)
    V0, F0 = V.copy(), F.copy()
    res = subdivide(V, F, levels=1, scheme="loop")
    assert np.array_equal(V, V0) and np.array_equal(F, F0)
    assert res.V.dtype == np.float64 and res.F.dtype == np.int64
    op = subdivision_operator(F, len(V), levels=2, scheme="loop")
    assert isinstance(op, SubdivisionOperator)
    assert (op.scheme, op.levels, op.n_coarse) == ("loop", 2, len(V))


def test_fingerprint_identifies_the_coarse_topology():
    V, F = cube(1)
    creases = cube_creases(V, F)
    base = subdivision_operator(F, len(V), levels=2).fingerprint
    assert base == subdivision_operator(F.copy(), len(V), levels=2).fingerprint
    others = {
        subdivision_operator(F, len(V), levels=1).fingerprint,
        subdivision_operator(F, len(V), levels=2, scheme="loop").fingerprint,
        subdivision_operator(F, len(V), levels=2, creases=creases).fingerprint,
        subdivision_operator(F, len(V) + 1, levels=2).fingerprint,
        subdivision_operator(F[:, [1, 2, 0]], len(V), levels=2).fingerprint,
    }
    assert base not in others and len(others) == 5
    # crease order and direction do not matter
    assert (subdivision_operator(F, len(V), creases=creases[::-1, ::-1]).fingerprint
            == subdivision_operator(F, len(V), creases=creases).fingerprint)


# ---------------------------------------------------------------------------
# property: affine invariance (every row sums to one)


@settings(max_examples=25, deadline=None)
@given(name=st.sampled_from(["icosphere1", "torus", "patch", "fan3", "cube"]),
       scheme=st.sampled_from(["butterfly", "loop"]),
       seed=st.integers(0, 2 ** 31 - 1),
       levels=st.integers(1, 2))
def test_affine_invariance(name, scheme, seed, levels):
    V, F = MESHES[name]()
    rng = np.random.default_rng(seed)
    V = V + 0.1 * rng.standard_normal(V.shape)
    A = rng.standard_normal((3, 3)) + 3 * np.eye(3)
    t = rng.uniform(-10, 10, 3)
    creases = cube_creases(*MESHES[name]()) if name == "cube" else None
    Vf, _ = subdivide(V, F, levels=levels, scheme=scheme, creases=creases)
    Vg, _ = subdivide(V @ A.T + t, F, levels=levels, scheme=scheme, creases=creases)
    scale = np.abs(V @ A.T + t).max()
    np.testing.assert_allclose(Vg, Vf @ A.T + t, rtol=0, atol=1e-12 * scale)


# ---------------------------------------------------------------------------
# real cages from ../shared/meshes (skipped when absent)


@pytest.mark.parametrize("name,levels", [("spot.obj", 2), ("fandisk.obj", 1), ("rocker-arm.obj", 1)])
@pytest.mark.parametrize("scheme", ["butterfly", "loop"])
def test_real_meshes(name, levels, scheme):
    V, F = load_shared(name)
    res = subdivide(V, F, levels=levels, scheme=scheme)
    e = edge_map(F, len(V)).E.shape[0]
    assert res.F.shape[0] == F.shape[0] * 4 ** levels
    if levels == 1:
        assert res.V.shape[0] == len(V) + e
    assert np.isfinite(res.V).all()
    assert manifold_report(res.F, res.V.shape[0]).is_oriented_manifold
    assert euler_characteristic(res.F, res.V.shape[0]) == euler_characteristic(F, len(V))
    if scheme == "butterfly":
        assert np.array_equal(res.V[:len(V)], V)
    # the refined surface stays near the cage: inside its box grown by 5% of the diagonal
    diag = np.linalg.norm(V.max(0) - V.min(0))
    assert np.all(res.V >= V.min(0) - 0.05 * diag) and np.all(res.V <= V.max(0) + 0.05 * diag)


def _dihedral_deg(V, F, pairs):
    """Dihedral angle (between face normals) at the given interior edges."""
    em = edge_map(F, len(V))
    faces, _ = _edge_faces(em)
    n = len(V)
    key = em.E[:, 0] * n + em.E[:, 1]
    p = np.sort(pairs, axis=1)
    k = np.searchsorted(key, p[:, 0] * n + p[:, 1])
    N = face_normals(V, F)
    return np.degrees(np.arccos(np.clip((N[faces[k, 0]] * N[faces[k, 1]]).sum(1), -1, 1)))


@pytest.mark.parametrize("scheme", ["butterfly", "loop"])
def test_fandisk_creases_stay_sharp(scheme):
    V, F = load_shared("fandisk.obj")
    em = edge_map(F, len(V))
    coarse = _dihedral_deg(V, F, em.E)
    creases = em.E[coarse > 45]
    # the creases' descendants after one level: (a, n+k), (b, n+k) per crease k
    n = len(V)
    k = np.searchsorted(em.E[:, 0] * n + em.E[:, 1], creases[:, 0] * n + creases[:, 1])
    pairs = np.concatenate([np.stack([creases[:, 0], n + k], 1), np.stack([creases[:, 1], n + k], 1)])
    sharp = _dihedral_deg(*subdivide(V, F, levels=1, scheme=scheme, creases=creases), pairs)
    smooth = _dihedral_deg(*subdivide(V, F, levels=1, scheme=scheme), pairs)
    assert np.median(sharp) > 0.95 * np.median(coarse[coarse > 45])
    assert np.percentile(sharp, 5) > 60
    assert np.median(smooth) < 0.85 * np.median(sharp)   # without the tags they round off


@pytest.mark.parametrize("name", ["beetle.obj", "cow.obj", "suzanne.obj"])
def test_real_non_manifold_meshes_raise_naming_what_manifold_report_finds(name):
    V, F = load_shared(name)
    rep = manifold_report(F, len(V))
    if rep.non_manifold_edges.shape[0]:
        a, b = rep.non_manifold_edges[0]
        match = rf"non-manifold edges .*\({a}, {b}\)"
    else:
        match = rf"non-manifold vertices .*vertex {rep.non_manifold_vertices[0]}\b"
    with pytest.raises(InvalidMeshError, match=match):
        subdivide(V, F, scheme="loop")


@settings(max_examples=15, deadline=None)
@given(name=st.sampled_from(["icosphere1", "torus", "patch", "fan5", "bipyramid", "octahedron"]),
       scheme=st.sampled_from(["butterfly", "loop"]),
       seed=st.integers(0, 2 ** 31 - 1))
def test_random_creases_equal_reference(name, scheme, seed):
    V, F = MESHES[name]()
    rng = np.random.default_rng(seed)
    E = edge_map(F, len(V)).E
    creases = E[rng.random(E.shape[0]) < rng.uniform(0.05, 0.5)]
    V = V + 0.05 * rng.standard_normal(V.shape)
    Vf, Ff = subdivide(V, F, levels=2, scheme=scheme, creases=creases if len(creases) else None)
    Vr, Fr = reference(V, F, 2, scheme, creases)
    assert np.array_equal(Ff, Fr)
    np.testing.assert_allclose(Vf, Vr, rtol=0, atol=1e-12)
