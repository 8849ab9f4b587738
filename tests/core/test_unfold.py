"""The fold repair (core.unfold, run by core.deform).

Stages on built inputs (a flat grid with a vertex pushed over its
neighbours: repaired to no face turned over, only the region written,
the raw rows kept), the cage rotations (exact for a rigid motion, a proper
rotation always), and through deform: a rough torus whose butterfly
surface folds under a large one-ring lift has fewer faces turned over
with the repair and only the reported rows change; a half-turn of the cage
(every face turned by more than 90 degrees from rest, none folded)
repairs nothing; incremental == full through folds; a real scan's edits
that fold dense faces mostly fold none with it; the relaxation, weighted by
the inverse rest edge lengths, leaves no face turned over where the uniform
mean did (a rough sphere's pushes; the rocker-arm's thin triangles).
"""

import dataclasses

import numpy as np
import pytest

from core.binding import bind, deform
from core.fit import fit_cage
from core.mesh import NORMALS_BLOCK, bbox_diagonal, face_normals, turned_faces, vertex_normals
from core.simplify import simplify
from core import unfold
from core.unfold import (FLAT_AT_REST, CageRings, FaceBatch, FaceStars, FineFaceGroups, away_rows,
                         nearest_rotations, repair, rest_normals, ring_rotations, turned_over,
                         TURNED_DEG)
from tests.mesh_factory import load_shared, regular_grid, torus


def _turned(V0, V1, F):
    return turned_faces(V0, V1, F).size


def _identity(vertices, vectors):
    return vectors.copy()


def _rest_normals(V, F):
    return np.ascontiguousarray(face_normals(V, F, normalize=False).T)


def _rough_torus_at(levels):
    """A rough torus (noise 1% of its size), its 200-face cage, bound with butterfly at
    ``levels``, a cage vertex's normal and its one-ring: (Vd, Fd, cage, b, normal, ring)."""
    Vd, Fd = torus(96, 48, bump=0.01)
    Vd = Vd + 0.01 * np.random.default_rng(0).standard_normal(Vd.shape)
    cage = simplify(Vd, Fd, target_faces=200)
    b = bind(Vd, Fd, cage.V, cage.F, levels=levels, scheme="butterfly")
    normal = vertex_normals(cage.V, cage.F)[50]
    return Vd, Fd, cage, b, normal, np.unique(cage.F[(cage.F == 50).any(axis=1)])


# ------------------------------------------------------------------ stages
def test_turned_faces_are_the_faces_an_edit_folds_over():
    # a hexagon fan: its centre pushed out past rim vertex 1 folds exactly the two
    # faces on rim vertex 1's edges; a motion turning every normal by less than 90
    # degrees (here 0.5 rad, scaled, moved) folds none, mirroring a flat fan folds all
    angles = np.radians(60.0 * np.arange(6))
    V = np.vstack([[0.0, 0.0, 0.0], np.stack([np.cos(angles), np.sin(angles),
                                              np.zeros(6)], axis=1)])
    F = np.array([[0, 1 + k, 1 + (k + 1) % 6] for k in range(6)])
    pushed = V.copy()
    pushed[0] = 1.5 * V[1]
    assert turned_faces(V, pushed, F).tolist() == [0, 5]
    c, s = np.cos(0.5), np.sin(0.5)
    R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]) @ \
        np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])
    Vt, Ft = torus(24, 12)
    assert turned_faces(Vt, 2.0 * Vt @ R.T + [3.0, -1.0, 2.0], Ft).size == 0
    assert turned_faces(V, V * [-1.0, 1.0, 1.0], F).tolist() == list(range(6))  # (flat)
    # a face degenerate at rest has no normal to turn from: never counted
    flat = V.copy()
    flat[0] = V[1]                     # faces 0 and 5 have two corners at one place
    assert turned_faces(flat, flat * [-1.0, 1.0, 1.0], F).tolist() == [1, 2, 3, 4]
    assert turned_faces(V, pushed, F.tolist()).dtype == np.int64   # lists are taken


def test_face_stars_list_the_faces_around_vertices():
    V, F = regular_grid(4, 4)
    stars = FaceStars.of(F, V.shape[0])
    for v in range(V.shape[0]):
        assert np.array_equal(stars.around([v]), np.flatnonzero((F == v).any(axis=1)))
    assert np.array_equal(stars.around([0, 5]),
                          np.flatnonzero(np.isin(F, [0, 5]).any(axis=1)))


def test_repair_puts_a_pushed_vertex_back_and_writes_only_its_region():
    V, F = regular_grid(8, 8)
    X = V.copy()
    centre = 4 * 9 + 4                     # an inner vertex, pushed past its right neighbour
    X[centre, 0] += 1.6 / 8
    FT = np.ascontiguousarray(F.T)
    rest = _rest_normals(V, F)
    stars = FaceStars.of(F, V.shape[0])
    away = away_rows(X, FT, None, rest)
    folded = turned_over(X, FT, away, rest, _identity)
    assert folded.size > 0 and np.isin(centre, F[folded]).all()
    Y = X.copy()
    rep = repair(Y, V, F, FT, stars, folded, rest, _identity, away)
    assert np.array_equal(rep.away, away)
    assert _turned(V, Y, F) == 0
    changed = np.flatnonzero((Y != X).any(axis=1))
    assert np.isin(changed, rep.rows).all() and np.array_equal(rep.rows, np.unique(rep.rows))
    assert np.array_equal(rep.raw, X[rep.rows])
    # the region: the folded faces' vertices and their one-ring, at most two rounds' worth
    assert rep.rows.shape[0] <= 25 and np.isin(centre, rep.rows)
    # identity rotation, flat rest: the fixed point is the rest grid, nearly reached
    assert np.abs(Y - V).max() < np.abs(X - V).max()


def test_turned_over_means_away_from_rest_and_far_from_the_cage_rotation():
    # one triangle, its normal turned by 100 degrees about x; the cage's rotation there
    # turns rest normals by 0, 20 and 50 degrees: turned over while the normal is more
    # than TURNED_DEG from the rotated rest normal (80, 50 degrees), away from rest in all
    V = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]])
    F = np.array([[0, 1, 2]])
    FT = np.ascontiguousarray(F.T)
    rest = _rest_normals(V, F)

    def about_x(deg):
        t = np.radians(deg)
        return np.array([[1, 0, 0], [0, np.cos(t), -np.sin(t)], [0, np.sin(t), np.cos(t)]])

    X = V @ about_x(100).T
    away = away_rows(X, FT, None, rest)
    assert away.tolist() == [0]
    for deg in (0, 20, 50):
        expected = [0] if 100 - deg > TURNED_DEG else []
        turn = (lambda d: lambda vertices, vectors: vectors @ about_x(d).T)(deg)
        assert turned_over(X, FT, away, rest, turn).tolist() == expected, deg
    assert 100 - 50 < TURNED_DEG < 100 - 20


def test_nothing_to_repair_changes_nothing():
    V, F = regular_grid(5, 5)
    X = V + 0.01
    FT = np.ascontiguousarray(F.T)
    rest = _rest_normals(V, F)
    away = away_rows(X, FT, np.arange(F.shape[0]), rest)
    assert away.size == 0
    rep = repair(X, V, F, FT, None, turned_over(X, FT, away, rest, _identity), rest, _identity,
                 away)
    assert rep.rows.size == 0 and rep.raw.shape == (0, 3)
    assert np.array_equal(X, V + 0.01)


def test_faces_pointing_away_are_the_same_found_in_parts_on_the_threads():
    # from _AWAY_THREADS_MIN faces on the test runs in a part per worker: the same faces,
    # in the same (ascending) order, as one test over all of them
    V, F = regular_grid(120, 120)
    X = V.copy()
    X[:, 2] += 0.3 * np.sin(7 * V[:, 0]) * np.cos(5 * V[:, 1])
    X[::7, 0] += 0.02               # some faces turned over
    FT = np.ascontiguousarray(F.T)
    rest = _rest_normals(V, F)
    faces = np.arange(0, F.shape[0], 2)
    assert faces.size >= unfold._AWAY_THREADS_MIN
    expected = faces[np.einsum("ij,ji->i", face_normals(X, F[faces], normalize=False),
                               rest[:, faces]) < 0]
    assert 0 < expected.size < faces.size
    assert np.array_equal(away_rows(X, FT, faces, rest), expected)
    assert away_rows(X, FT, faces[:0], rest).size == 0
    # every face (None: the blocks are slices, not gathers), against the same test
    every = np.flatnonzero(np.einsum("ij,ji->i", face_normals(X, F, normalize=False), rest) < 0)
    assert np.array_equal(away_rows(X, FT, None, rest), every) and every.size > expected.size
    # the same faces gathered once as they are tested (a FaceBatch, kept over a drag), in
    # any order, some twice: the same faces found then and from the batch
    again = np.concatenate([faces[::-1], faces[:500]])
    away, batch = FaceBatch.tested(X, FT, again, rest)
    assert np.array_equal(away, expected) and np.array_equal(batch.away(X), expected)
    corners, normals = (np.concatenate([batch.blocks[s][i] for s in sorted(batch.blocks)], axis=1)
                        for i in (0, 1))
    assert np.array_equal(corners, FT[:, again]) and np.array_equal(normals, rest[:, again])
    assert corners.nbytes + normals.nbytes + batch.columns.nbytes == FaceBatch.size(FT, again, rest)
    away, none = FaceBatch.tested(X, FT, again, rest, keep=False)
    assert np.array_equal(away, expected) and none is None
    # columns standing for faces (here each face twice, as under two fine faces' groups)
    twice = np.repeat(faces, 2)
    columns = np.arange(twice.size)[::-1]
    assert np.array_equal(FaceBatch.tested(X, FT[:, twice], columns, rest[:, twice], twice)[0],
                          expected)
    assert FaceBatch.tested(X, FT, faces[:0], rest)[1].away(X).size == 0


def test_cage_rings_give_the_vertex_normals_at_a_few_vertices():
    for V, F in (torus(12, 6), regular_grid(5, 4)):
        V = V + 0.05 * np.random.default_rng(1).standard_normal(V.shape)
        rings = CageRings.of(F, V.shape[0])
        some = np.array([0, 3, V.shape[0] - 1, 7])
        assert np.abs(rings.normals(V, some) - vertex_normals(V, F)[some]).max() < 1e-14


def test_ring_rotations_are_exact_for_a_rigid_motion_and_always_rotations():
    V, F = torus(12, 6)
    rings = CageRings.of(F, V.shape[0])
    th = 2.0
    R = np.array([[np.cos(th), 0, np.sin(th)], [0, 1, 0], [-np.sin(th), 0, np.cos(th)]])
    got = ring_rotations(V, V @ R.T + 3.0, rings, np.arange(V.shape[0]))
    assert np.abs(got - R).max() < 1e-12
    # any deformation (here: a random one) still gives proper rotations
    rng = np.random.default_rng(0)
    got = ring_rotations(V, V + 0.3 * rng.standard_normal(V.shape), rings, np.arange(V.shape[0]))
    assert np.abs(got @ got.transpose(0, 2, 1) - np.eye(3)).max() < 1e-12
    assert np.allclose(np.linalg.det(got), 1.0)


def test_nearest_rotation_of_a_reflection_is_a_rotation():
    M = np.diag([1.0, 1.0, -1.0])[None]
    R = nearest_rotations(M)
    assert np.isclose(np.linalg.det(R[0]), 1.0)
    assert np.abs(R[0] @ R[0].T - np.eye(3)).max() < 1e-12


def test_fine_face_groups_find_the_faces_around_the_rows(rough_torus):
    # the two ways an incremental deform tests the faces around its rows agree
    Vd, Fd, cage, b, normal, ring = rough_torus
    Ve = cage.V.copy()
    Ve[ring] += 0.08 * bbox_diagonal(Vd) * normal
    D = deform(dataclasses.replace(b, F_dense=None, _cache=None), Ve)
    FT = np.ascontiguousarray(Fd.T)
    rest = _rest_normals(Vd, Fd)
    groups = FineFaceGroups.of(Fd, b.fine_face, b.operator.F_fine.shape[0], rest)
    fine = np.unique(b.fine_face[b.influenced(ring)])
    rows = np.flatnonzero(np.isin(b.fine_face, fine))
    expected = away_rows(D, FT, FaceStars.of(Fd, Vd.shape[0]).around(rows), rest)
    assert expected.size > 0
    entries = groups.entries(fine)
    away = FaceBatch.tested(D, groups.corners, entries, groups.rest, groups.faces, keep=False)[0]
    assert np.array_equal(away, expected)
    # the entries are the faces around the rows, each once but for a face over three fine
    # faces, two of them asked for and not the one of its first corner
    around = FaceStars.of(Fd, Vd.shape[0]).around(rows)
    faces, count = np.unique(groups.faces[entries], return_counts=True)
    assert np.array_equal(faces, around)
    over = b.fine_face[Fd[faces]]
    asked = np.isin(over, fine)
    twice = (asked[:, 1:].sum(axis=1) == 2) & ~asked[:, 0] & (over[:, 1] != over[:, 2])
    assert np.array_equal(count, 1 + twice)
    assert not groups.seen.any()
    # every face appears under each of its distinct fine faces, owned by its first corner's
    assert groups.faces.shape[0] == sum(np.unique(b.fine_face[f]).size for f in Fd)
    assert groups.start[-1] == Fd.shape[0] == groups.shared_start[0]
    owned = np.repeat(np.arange(groups.start.shape[0] - 1), np.diff(groups.start))
    assert np.array_equal(b.fine_face[Fd[groups.faces[:Fd.shape[0]], 0]], owned)


def test_fine_face_groups_in_blocks_list_the_same_faces(rough_torus):
    # blocks of a cage face's fine faces (16 at two levels): a whole asked block's shared
    # entries owned in it are left out before the owner test, the faces listed the same
    # for whole blocks, part blocks and single fine faces
    Vd, Fd, cage, b, normal, ring = rough_torus
    rest = _rest_normals(Vd, Fd)
    m_fine = b.operator.F_fine.shape[0]
    plain = FineFaceGroups.of(Fd, b.fine_face, m_fine, rest)
    rng = np.random.default_rng(3)
    asked = [np.unique(b.fine_face[b.influenced(ring)]), np.arange(16, 48), np.array([5]),
             np.arange(m_fine), np.zeros(0, dtype=np.int64)]
    asked += [np.sort(rng.choice(m_fine, k, replace=False)) for k in (1, 30, 700)]
    for block in (16, 5, 1):
        groups = FineFaceGroups.of(Fd, b.fine_face, m_fine, rest, block=block)
        assert groups.owning.sum() == np.count_nonzero(np.diff(groups.start))
        for fine in asked:
            entries = groups.entries(fine)
            assert np.array_equal(np.sort(groups.faces[entries]),
                                  np.sort(plain.faces[plain.entries(fine)]))
            assert not groups.seen.any()


@pytest.mark.parametrize("levels", [1, 2])
def test_incremental_equals_full_through_repairs_at_both_test_paths(levels):
    # one level: the fine mesh is 4x coarser than the dense one, the faces are
    # found by fine face groups; two: around each row
    Vd, Fd, cage, b, normal, ring = _rough_torus_at(levels)
    rng = np.random.default_rng(7)
    cur = cage.V.copy()
    D = deform(b, cur)
    seen = 0
    for _ in range(6):
        ids = rng.choice(ring, rng.integers(1, ring.size + 1), replace=False)
        cur[ids] = cage.V[ids] + rng.random() * 0.1 * bbox_diagonal(Vd) * normal
        deform(b, cur, moved=ids, out=D)
        assert np.abs(D - deform(b, cur)).max() <= 1e-12 * bbox_diagonal(Vd)
        seen += b.repaired(D).size > 0
    assert seen > 0


@pytest.mark.parametrize("levels", [1, 2])
def test_a_drag_through_repairs_equals_full_at_both_test_paths(levels):
    # the same cage vertices moved again and again (the faces or group entries around
    # the rows are kept between the moves), the lift growing until faces fold and are
    # repaired, then shrinking back: each step equals a full deform of the same cage
    Vd, Fd, cage, b, normal, ring = _rough_torus_at(levels)
    cur = cage.V.copy()
    D = deform(b, cur)
    b.influenced([])
    repaired = []
    for lift in (0.02, 0.05, 0.08, 0.1, 0.05, 0.0):
        cur[ring] = cage.V[ring] + lift * bbox_diagonal(Vd) * normal
        deform(b, cur, moved=ring, out=D)
        assert np.array_equal(D, deform(b, cur))
        repaired.append(b.repaired(D).size)
    assert max(repaired) > 0 and repaired[-1] == 0
    assert np.abs(D - Vd).max() <= 1e-12 * bbox_diagonal(Vd)     # back at rest: the scan


@pytest.mark.parametrize("levels", [1, 2])
def test_the_faces_kept_between_tests_change_nothing(levels, monkeypatch):
    # a drag through repairs with the faces around its rows kept between the moves (a
    # FaceBatch), and its rows' gathers, and with none kept (over _KEPT_BATCH_BYTES): the
    # same bits, both paths
    import core.binding as binding_module
    Vd, Fd, cage, b, normal, ring = _rough_torus_at(levels)
    results = []
    for kept in (binding_module._KEPT_BATCH_BYTES, 0):
        monkeypatch.setattr(binding_module, "_KEPT_BATCH_BYTES", kept)
        fresh = dataclasses.replace(b, _cache=None)      # (nothing kept from before)
        cur = cage.V.copy()
        D = deform(fresh, cur)
        steps = []
        for lift in (0.05, 0.1, 0.08):
            cur[ring] = cage.V[ring] + lift * bbox_diagonal(Vd) * normal
            deform(fresh, cur, moved=ring, out=D)
            steps.append((D.copy(), fresh.repaired(D)))
        assert (fresh._cache["repair"]["around"]["batch"] is not None) == bool(kept)
        assert bool(fresh._cache["incremental"]["kept_rows"]) == bool(kept)
        results.append(steps)
    assert any(rows.size for _, rows in results[0])
    for (D0, r0), (D1, r1) in zip(*results):
        assert np.array_equal(D0, D1) and np.array_equal(r0, r1)


# ------------------------------------------------------------------ through deform
@pytest.fixture(scope="module")
def rough_torus():
    """A rough torus (noise 1% of its size) whose butterfly surface folds
    dense faces when a one-ring of its 200-face cage is lifted by 6-8% of
    the diagonal."""
    return _rough_torus_at(2)


@pytest.mark.parametrize("pct", [6, 8])
def test_deform_repairs_folds_and_reports_the_rows(rough_torus, pct):
    Vd, Fd, cage, b, normal, ring = rough_torus
    Ve = cage.V.copy()
    Ve[ring] += pct / 100 * bbox_diagonal(Vd) * normal
    plain = deform(dataclasses.replace(b, F_dense=None, _cache=None), Ve)
    D = deform(b, Ve)
    before, after = _turned(Vd, plain, Fd), _turned(Vd, D, Fd)
    assert before > 0 and after < before
    rows = b.repaired(D)
    assert rows.size > 0 and b.repaired(plain).size == 0
    changed = np.flatnonzero((D != plain).any(axis=1))
    assert np.isin(changed, rows).all()
    # the repair is local: inside what the lifted cage vertices move
    assert b.affected(ring)[rows].all()


def test_a_half_turn_repairs_nothing_and_stays_exact(rough_torus):
    Vd, Fd, cage, b, normal, ring = rough_torus
    R = np.diag([-1.0, -1.0, 1.0]) @ np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]])
    D = deform(b, cage.V @ R.T + 1.0)
    assert _turned(Vd, D, Fd) > 0.5 * Fd.shape[0]    # turned, yet not folded
    assert b.repaired(D).size == 0
    assert np.abs(D - (Vd @ R.T + 1.0)).max() <= 1e-12 * bbox_diagonal(Vd)


def test_incremental_equals_full_through_repairs(rough_torus):
    Vd, Fd, cage, b, normal, ring = rough_torus
    rng = np.random.default_rng(5)
    lift = 0.08 * bbox_diagonal(Vd) * normal
    cur = cage.V.copy()
    D = deform(b, cur)
    repaired = 0
    for _ in range(8):
        ids = rng.choice(ring, rng.integers(1, ring.size + 1), replace=False)
        cur[ids] = cage.V[ids] + rng.random() * lift
        before, previous = b.repaired(D), D.copy()
        deform(b, cur, moved=ids, out=D)
        after = b.repaired(D)
        # what the live update copies covers every row that changed
        copied = np.union1d(b.influenced(ids), np.union1d(before, after))
        assert np.isin(np.flatnonzero((D != previous).any(axis=1)), copied).all()
        full = deform(b, cur)
        assert np.abs(D - full).max() <= 1e-12 * bbox_diagonal(Vd)
        assert np.array_equal(after, b.repaired(full))
        repaired += after.size > 0 or before.size > 0
    assert repaired > 0


def test_scan_edits_that_fold_faces_mostly_fold_none():
    # the beetle, its cage fitted for Loop, the one-ring of each of its first 150
    # cage vertices lifted by 1% of the diagonal, the edits that leave the cage
    # itself unfolded: without the repair 21 of them fold 29 dense faces; with it
    # 16 of those fold none and 9 faces are left (2026-12-03)
    V, F = load_shared("beetle.obj")
    diag = bbox_diagonal(V)
    cage = simplify(V, F, target_faces=min(2000, F.shape[0] // 4))
    creases = cage.feature_edges if len(cage.feature_edges) else None
    Vc = fit_cage(V, F, cage.V, cage.F, levels=2, scheme="loop", creases=creases).V
    b = bind(V, F, Vc, cage.F, levels=2, scheme="loop", creases=creases)
    plain_binding = dataclasses.replace(b, F_dense=None, _cache=None)
    normals = vertex_normals(Vc, cage.F)
    plain, repaired = [], []
    for v in range(min(150, cage.V.shape[0])):
        ring = np.unique(cage.F[(cage.F == v).any(axis=1)])
        Ve = Vc.copy()
        Ve[ring] += 0.01 * diag * normals[v]
        if _turned(Vc, Ve, cage.F):
            continue
        p = _turned(V, deform(plain_binding, Ve), F)
        if p:
            plain.append(p)
            repaired.append(_turned(V, deform(b, Ve), F))
    assert len(plain) >= 10
    assert sum(repaired) <= 0.5 * sum(plain)
    assert sum(r == 0 for r in repaired) >= 0.6 * len(plain)


def test_the_relaxation_weighs_short_edges_and_leaves_no_face_turned_over():
    # a rough sphere, its 800-face cage, one-rings and a vertex pushed in by 3% of the
    # diagonal (no cage face turns over): the uniform mean the relaxation took left 2, 1
    # and 1 faces turned over on these three edits (a campaign's, 2026-12-06), turned by
    # the relaxation itself; weighted by the inverse rest edge lengths it leaves none
    from tests.mesh_factory import noisy_sphere
    Vd, Fd = noisy_sphere(5, amp=0.08)
    cage = simplify(Vd, Fd, target_faces=800)
    b = bind(Vd, Fd, cage.V, cage.F, levels=2, scheme="butterfly")
    plain_binding = dataclasses.replace(b, F_dense=None, _cache=None)
    diag, normals = bbox_diagonal(Vd), vertex_normals(cage.V, cage.F)
    for v, edit in ((117, "ring"), (15, "ring"), (221, "vertex")):
        ids = np.unique(cage.F[(cage.F == v).any(axis=1)]) if edit == "ring" else [v]
        Ve = cage.V.copy()
        Ve[ids] -= 0.03 * diag * normals[v]
        assert _turned(cage.V, Ve, cage.F) == 0
        assert _turned(Vd, deform(plain_binding, Ve), Fd) >= 5
        D = deform(b, Ve)
        assert _turned(Vd, D, Fd) == 0 and b.repaired(D).size > 0


def test_the_relaxation_weighs_short_edges_on_a_scan():
    # the rocker-arm (thin CAD-like triangles), a 400-face cage, one-rings pushed in by 3%:
    # faces turned by more than 90 degrees 29 / 29 / 29 / 40 without the repair; with it
    # and the uniform mean 15 / 12 / 14 / 6, all turned by the relaxation; weighted 3 / 2 /
    # 0 / 0
    V, F = load_shared("rocker-arm.obj")
    cage = simplify(V, F, target_faces=400)
    b = bind(V, F, cage.V, cage.F, levels=2, scheme="butterfly")
    diag, normals = bbox_diagonal(V), vertex_normals(cage.V, cage.F)
    left = []
    for v in (108, 55, 112, 90):
        ring = np.unique(cage.F[(cage.F == v).any(axis=1)])
        Ve = cage.V.copy()
        Ve[ring] -= 0.03 * diag * normals[v]
        left.append(_turned(V, deform(b, Ve), F))
    assert sum(left) <= 6 and max(left) <= 3


def test_faces_flat_at_rest_have_no_normal_to_turn():
    """Collinear corners: a zero rest normal, so no dot product can call the
    face turned over; a needle just above the bound keeps its normal."""
    PT = np.array([[0.0, 1.0, 0.5, 0.0, 1.0, 0.5],
                   [0.0, 0.0, 0.0, 0.0, 0.0, 2e-6],
                   [0.0, 0.0, 0.0, 1.0, 1.0, 1.0]])
    FT = np.array([[0, 3], [1, 4], [2, 5]])
    n = rest_normals(PT, FT)
    assert n.dtype == np.float32
    np.testing.assert_array_equal(n[:, 0], 0.0)
    assert FLAT_AT_REST < 2e-6 and np.abs(n[:, 1]).max() > 0
    np.testing.assert_allclose(n[:, 1], _rest_normals(PT.T, FT.T)[:, 1], rtol=1e-6)


def test_rest_normals_are_np_cross_in_float32_zero_exactly_where_flat_at_rest():
    # blocks on the worker threads (three blocks and a part), the corners gathered
    # once for the normals and the edge lengths: the normals of np.cross on rows,
    # rounded to float32, and zero exactly where the float32 normal is shorter than
    # FLAT_AT_REST times the longest edge squared
    rng = np.random.default_rng(8)
    n, m = 5000, 3 * NORMALS_BLOCK + 77
    V = rng.standard_normal((n, 3))
    F = rng.integers(0, n, (m, 3))
    F[:300, 2] = F[:300, 1]                                        # two corners at one place
    mid = np.arange(300, 900)
    V[F[mid, 2]] = 0.5 * (V[F[mid, 0]] + V[F[mid, 1]])             # collinear corners
    got = rest_normals(np.ascontiguousarray(V.T), np.ascontiguousarray(F.T))
    normal = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]).astype(np.float32)
    longest = np.max([((V[F[:, (k + 1) % 3]] - V[F[:, k]]) ** 2).sum(axis=1) for k in range(3)],
                     axis=0)
    n64 = normal.astype(np.float64)
    flat = (n64 * n64).sum(axis=1) <= FLAT_AT_REST ** 2 * longest * longest
    assert got.dtype == np.float32 and 300 <= flat.sum() < 1000
    np.testing.assert_array_equal(got.T[flat], 0.0)
    np.testing.assert_array_equal(got.T[~flat], normal[~flat])


@pytest.mark.parametrize("source", ["icosphere", "homer.obj"])
def test_collinear_faces_repair_the_same_in_full_and_incremental_deforms(source):
    """A scan with 3% of its faces made collinear (a corner moved to the middle
    of its opposite edge), a 4-face cage, one cage vertex lifted by 1% of the
    diagonal: the incremental deform equals the full one (before, noise in the
    rest normals of those faces decided which folded: homer's two deforms
    repaired 2,011 and 2,054 rows and differed by 0.4% of the diagonal)."""
    if source == "icosphere":
        from tests.mesh_factory import icosphere
        V, F = icosphere(4)
        V = V * [1.0, 0.8, 0.6]
    else:
        V, F = load_shared(source)
    rng = np.random.default_rng(3)
    V = V.copy()
    pick = rng.choice(F.shape[0], F.shape[0] // 30, replace=False)
    a, b_, c = F[pick].T
    V[c] = 0.5 * (V[a] + V[b_])
    diag = bbox_diagonal(V)
    cage = simplify(V, F, target_faces=4)
    Vc = fit_cage(V, F, cage.V, cage.F, levels=1, scheme="loop").V
    b = bind(V, F, Vc, cage.F, levels=1, scheme="loop")
    D = deform(b, Vc)
    assert np.abs(D - V).max() <= 1e-12 * diag
    Ve = Vc.copy()
    Ve[0] += 0.01 * diag
    full = deform(b, Ve)
    for moved in (np.array([0]), np.arange(Vc.shape[0])):
        inc = D.copy()
        deform(b, Ve, moved=moved, out=inc)
        assert np.abs(inc - full).max() <= 1e-12 * diag
        assert np.array_equal(b.repaired(inc), b.repaired(full))


def test_the_repair_maps_need_no_lapack_solve(rough_torus, monkeypatch):
    # np.linalg.inv on a stack of 3x3 matrices is LAPACK's gesv once per matrix, whose
    # triangular solves OpenBLAS runs on its threads: on a loaded 2-core machine
    # 0.45-1.3 s for 1,000 matrices (0.3 ms on one thread), 190 ms of a 230 ms
    # incremental deform of the bunny with 1,000 cage vertices moved. The local linear
    # maps invert their 3x3 sums by the adjugate now: the same maps to rounding.
    Vd, Fd, cage, b, normal, ring = rough_torus
    Ve = cage.V.copy()
    Ve[ring] += 0.03 * bbox_diagonal(Vd) * normal
    vertices = np.arange(cage.V.shape[0])
    rings = unfold.CageRings.of(cage.F, cage.V.shape[0])
    A = np.random.default_rng(1).random((50, 3, 3)) + 2 * np.eye(3)
    want = np.linalg.inv(A)

    def refused(*args, **kwargs):
        raise AssertionError("np.linalg.inv called")
    monkeypatch.setattr(np.linalg, "inv", refused)
    assert np.abs(unfold._inverses(A) - want).max() <= 1e-14
    maps = unfold.ring_linear_maps(cage.V, Ve, rings, vertices)
    assert np.isfinite(maps).all()
    D = deform(b, Ve)
    assert b.repaired(D).size > 0
    # a uniform scale is that scale
    assert np.abs(unfold.ring_linear_maps(cage.V, 0.5 * cage.V, rings, vertices)
                  - 0.5 * np.eye(3)).max() <= 1e-14


@pytest.mark.parametrize("reference_dtype", [np.float32, np.float64])
def test_normal_dots_are_the_area_normals_dotted_bit_for_bit_in_blocks(reference_dtype):
    # normal_dots gathers the corners' coordinates one at a time from the flat
    # positions, DOTS_BLOCK faces at a time (here several blocks and a partial one): the
    # same bits as the area normals (np.cross's operations) dotted with the reference,
    # for corner indices int32 or int64 and positions contiguous or not
    from core.mesh import DOTS_BLOCK, area_normals_rows, normal_dots
    rng = np.random.default_rng(4)
    n = 5000
    V = rng.standard_normal((n, 3))
    F = rng.integers(0, n, (2 * DOTS_BLOCK + 321, 3))
    reference = rng.standard_normal((3, F.shape[0])).astype(reference_dtype)
    normals = area_normals_rows(V, F.T)
    expected = reference[0] * normals[:, 0]
    expected += reference[1] * normals[:, 1]
    expected += reference[2] * normals[:, 2]
    wide = np.zeros((n, 6))
    wide[:, 1:4] = V
    for X in (V, wide[:, 1:4]):
        for T in (np.ascontiguousarray(F.T), F.T.astype(np.int32)):
            got = normal_dots(X, T, reference)
            assert got.dtype == np.float64
            assert np.array_equal(got, expected)
    assert normal_dots(V, F[:0].T, reference[:, :0]).shape == (0,)
