"""Incremental deform: ``deform(b, V, moved=ids, out=D)`` recomputes only the
dense vertices the moved cage vertices influence, and equals a full deform.

Properties: incremental == full (hypothesis, random moved sets, both
schemes, chains of updates), the recomputed rows lie inside
``Binding.affected``, rows outside it are never written, duplicates are
fine, an empty ``moved`` writes nothing, and bad ``moved`` / ``out`` raise
named errors.
"""

import dataclasses

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from core.binding import bind, deform
from core.errors import InvalidArgumentError
from core.mesh import bbox_diagonal, vertex_normals
from core.simplify import simplify
from tests.mesh_factory import drawn_edit, noisy_sphere, sphere_binding, torus


@pytest.fixture(scope="module", params=["butterfly", "loop"])
def case(request):
    return sphere_binding(request.param)


@pytest.fixture(scope="module")
def torus_case():
    Vd, Fd = torus(96, 48, bump=0.01)
    cage = simplify(Vd, Fd, target_faces=200)
    return Vd, cage.V, bind(Vd, Fd, cage.V, cage.F, levels=2)


def _tol(Vd):
    return 1e-12 * bbox_diagonal(Vd)


@settings(max_examples=25, deadline=None)
@given(data=st.data())
def test_incremental_equals_full_for_random_moved_sets(case, data):
    Vd, Vc, b = case
    ids, Ve = drawn_edit(data, Vc)
    D = deform(b, Vc)
    got = deform(b, Ve, moved=ids, out=D)
    assert got is D
    assert np.abs(D - deform(b, Ve)).max() <= _tol(Vd)


def test_chain_of_updates_tracks_the_full_deform(torus_case):
    # and the fine normals each update recomputes (from the faces around them, summed as
    # the full deform sums them) are the full normals of the same fine positions, bit for
    # bit (the positions themselves may differ from a full deform's by rounding)
    from core import binding as binding_module
    Vd, Vc, b = torus_case
    rng = np.random.default_rng(3)
    D = deform(b, Vc)
    Ve = Vc.copy()
    for _ in range(6):
        ids = rng.choice(Vc.shape[0], rng.integers(1, 8), replace=False)
        Ve[ids] += 0.02 * rng.standard_normal((ids.shape[0], 3))
        deform(b, Ve, moved=ids, out=D)
        g = b._cache["geometry"]
        fresh = ~g.stale
        assert fresh.sum() > 0.9 * fresh.size
        full = binding_module._vertex_normals_t(g.levels[-1], b.operator.F_fine)
        assert np.array_equal(g.normals[:, fresh], full[:, fresh])
        assert np.abs(D - deform(b, Ve)).max() <= _tol(Vd)


def test_only_affected_rows_are_written(torus_case):
    Vd, Vc, b = torus_case
    ids = np.array([4, 17])
    allowed = b.affected(ids)
    # the rows outside the affected ones are not written (bit for bit as before;
    # nothing turns over here, so the fold repair writes nothing either)
    D = deform(b, Vc)
    before = D.copy()
    Ve = Vc.copy()
    Ve[ids] += 0.03
    deform(b, Ve, moved=ids, out=D)
    assert np.array_equal(D[~allowed], before[~allowed])
    assert b.repaired(D).shape == (0,)
    full = deform(b, Ve)
    assert np.abs(D[allowed] - full[allowed]).max() <= _tol(Vd)
    assert allowed.sum() < 0.5 * Vd.shape[0]


def test_duplicates_and_dtypes_of_moved(case):
    Vd, Vc, b = case
    D = deform(b, Vc)
    Ve = Vc.copy()
    Ve[[2, 9]] -= 0.04
    deform(b, Ve, moved=np.array([9, 2, 2, 9, 9], dtype=np.int32), out=D)
    assert np.abs(D - deform(b, Ve)).max() <= _tol(Vd)
    D2 = deform(b, Vc)
    deform(b, Ve, moved=[2, 9], out=D2)
    assert np.array_equal(D, D2)


def test_empty_moved_changes_nothing(case):
    Vd, Vc, b = case
    D = deform(b, Vc)
    before = D.copy()
    for empty in ([], np.zeros(0, dtype=np.int64), np.zeros((0,), dtype=np.float64)):
        assert deform(b, Vc * 2.0, moved=empty, out=D) is D
        assert np.array_equal(D, before)


def test_full_deform_into_out(case):
    Vd, Vc, b = case
    D = np.full((b.n_dense, 3), np.nan)
    assert deform(b, Vc * 1.1, out=D) is D
    assert np.array_equal(D, deform(b, Vc * 1.1))


def test_inputs_are_not_modified(case):
    Vd, Vc, b = case
    Ve = Vc + 0.01
    Ve0 = Ve.copy()
    ids = np.array([1, 5])
    ids0 = ids.copy()
    deform(b, Ve, moved=ids, out=deform(b, Vc))
    assert np.array_equal(Ve, Ve0) and np.array_equal(ids, ids0)


@pytest.mark.parametrize("bad", [[-1], [0, 10**6], [3, -5, 2]])
def test_out_of_range_moved_raises_naming_the_index(case, bad):
    Vd, Vc, b = case
    D = deform(b, Vc)
    if bad == [0, 10**6]:
        bad = [0, Vc.shape[0]]
    first = next(i for i in bad if i < 0 or i >= Vc.shape[0])
    with pytest.raises(InvalidArgumentError, match=rf"moved index {first} is out of range "
                                                   rf"\[0, {Vc.shape[0]}\)"):
        deform(b, Vc, moved=bad, out=D)


def test_bad_moved_and_out_raise_named_errors(case):
    Vd, Vc, b = case
    D = deform(b, Vc)
    with pytest.raises(InvalidArgumentError, match="moved must be integer"):
        deform(b, Vc, moved=[0.5], out=D)
    with pytest.raises(InvalidArgumentError, match="moved needs out"):
        deform(b, Vc, moved=[0])
    n = b.n_dense
    for out in (np.zeros((n - 1, 3)), np.zeros((n, 3), np.float32), np.zeros((3, n)).T,
                D.tolist()):
        with pytest.raises(InvalidArgumentError, match=rf"out must be a writable C-contiguous "
                                                       rf"\({n}, 3\) float64"):
            deform(b, Vc, moved=[0], out=out)
    ro = D.copy()
    ro.flags.writeable = False
    with pytest.raises(InvalidArgumentError, match="out must be a writable"):
        deform(b, Vc, out=ro)


def test_influenced_lists_exactly_the_rows_the_update_writes(torus_case):
    Vd, Vc, b = torus_case
    # without the fold repair (which reads the rows around what it writes, and
    # would see the sentinel as turned-over faces)
    b = dataclasses.replace(b, F_dense=None, _cache=None)
    ids = [4, 17, 17]
    rows = b.influenced(ids)
    assert rows.dtype == np.int64 and np.array_equal(rows, np.unique(rows))
    assert b.affected(ids)[rows].all()
    D = np.full((b.n_dense, 3), 7.0)
    deform(b, Vc + 0.01, moved=ids, out=D)
    written = (D != 7.0).any(axis=1)
    assert np.array_equal(np.flatnonzero(written), rows)
    assert b.influenced([]).shape == (0,)
    with pytest.raises(InvalidArgumentError, match="Binding.influenced: moved index -2"):
        b.influenced([-2])


def test_influenced_unordered_is_the_same_set_and_a_copy(torus_case):
    Vd, Vc, b = torus_case
    ids = [4, 17, 30]
    loose = b.influenced(ids, ordered=False)
    assert loose.dtype == np.int64 and loose.size == np.unique(loose).size
    assert np.array_equal(np.sort(loose), b.influenced(ids))
    loose[:] = -1                     # the caller's array, not the binding's cache
    assert np.array_equal(np.sort(b.influenced(ids, ordered=False)), b.influenced(ids))
    assert b.influenced([], ordered=False).shape == (0,)


@pytest.mark.parametrize("levels", [0, 1, 3])
@pytest.mark.parametrize("scheme", ["butterfly", "loop"])
def test_incremental_equals_full_at_other_levels(levels, scheme):
    Vd, Fd = noisy_sphere(3, amp=0.02)
    cage = simplify(Vd, Fd, target_faces=80)
    b = bind(Vd, Fd, cage.V, cage.F, levels=levels, scheme=scheme)
    rng = np.random.default_rng(levels)
    D = deform(b, cage.V)
    Ve = cage.V.copy()
    for _ in range(3):
        ids = rng.choice(cage.V.shape[0], 4, replace=False)
        Ve[ids] += 0.05 * rng.standard_normal((4, 3))
        deform(b, Ve, moved=ids, out=D)
        assert np.abs(D - deform(b, Ve)).max() <= _tol(Vd)


def test_binding_stays_picklable_after_an_incremental_deform(case):
    import pickle
    Vd, Vc, b = case
    D = deform(b, Vc)
    deform(b, Vc + 0.01, moved=[0, 1], out=D)
    b2 = pickle.loads(pickle.dumps(b))
    assert np.array_equal(deform(b2, Vc + 0.01), deform(b, Vc + 0.01))


def test_long_chain_without_a_full_deform_between(torus_case):
    """The kept fine geometry is updated in place (stale normals recomputed
    when first read): a chain of overlapping updates, each checked against a
    full deform on a copy of the binding (which keeps its own geometry)."""
    import pickle
    Vd, Vc, b = torus_case
    ref = pickle.loads(pickle.dumps(b))
    rng = np.random.default_rng(11)
    D = deform(b, Vc)
    Ve = Vc.copy()
    centres = rng.choice(Vc.shape[0], 3, replace=False)
    for step in range(12):
        # around one of three places in turn, so changed-but-unread normals get read later
        near = np.argsort(np.linalg.norm(Vc - Vc[centres[step % 3]], axis=1))[:rng.integers(1, 6)]
        Ve[near] += 0.02 * rng.standard_normal((near.shape[0], 3))
        deform(b, Ve, moved=near, out=D)
        assert np.abs(D - deform(ref, Ve)).max() <= _tol(Vd)


def test_incremental_after_a_deform_of_another_cage(torus_case):
    """``out`` from one cage, the kept geometry from another: the geometry is
    recomputed and the result still equals the full deform."""
    Vd, Vc, b = torus_case
    rng = np.random.default_rng(5)
    V1 = Vc + 0.01 * rng.standard_normal(Vc.shape)
    V2 = Vc + 0.01 * rng.standard_normal(Vc.shape)
    D = deform(b, V2)
    deform(b, V1)                         # keeps V1's geometry
    V3 = V2.copy()
    V3[[3, 8]] += 0.03
    deform(b, V3, moved=[3, 8], out=D)
    assert np.abs(D - deform(b, V3)).max() <= _tol(Vd)


@pytest.mark.parametrize("scheme", ["butterfly", "loop"])
def test_chain_on_a_fine_mesh_denser_than_the_dense_one(scheme):
    """Most fine faces have no dense vertex bound to them: the normals no row
    reads are not kept up to date, the ones rows read are."""
    import pickle
    Vd, Fd = noisy_sphere(3, amp=0.02)
    cage = simplify(Vd, Fd, target_faces=80)
    b = bind(Vd, Fd, cage.V, cage.F, levels=3, scheme=scheme)
    assert b.operator.F_fine.shape[0] > 3 * Vd.shape[0]
    ref = pickle.loads(pickle.dumps(b))
    rng = np.random.default_rng(2)
    D = deform(b, cage.V)
    Ve = cage.V.copy()
    for step in range(10):
        ids = rng.choice(cage.V.shape[0], rng.integers(1, 4), replace=False)
        Ve[ids] += 0.03 * rng.standard_normal((ids.shape[0], 3))
        deform(b, Ve, moved=ids, out=D)
        assert np.abs(D - deform(ref, Ve)).max() <= _tol(Vd)


def test_rows_rebuilt_in_many_blocks(torus_case, monkeypatch):
    """Blocks of whole fine faces (tiny blocks here), inline or on the worker
    threads: same result as one block."""
    import core.binding as binding_module
    Vd, Vc, b = torus_case
    Ve = Vc.copy()
    ids = np.array([2, 30, 31])
    Ve[ids] += 0.02
    one = deform(b, Vc)
    deform(b, Ve, moved=ids, out=one)
    monkeypatch.setattr(binding_module, "_ROW_BLOCK", 5)
    many = deform(b, Vc)
    deform(b, Ve, moved=ids, out=many)
    assert np.array_equal(one, many)
    assert np.abs(many - deform(b, Ve)).max() <= _tol(Vd)
    # the blocks on the worker threads (from _THREADED_ROWS rows): the same bits
    monkeypatch.setattr(binding_module, "_THREADED_ROWS", 1)
    threaded = deform(b, Vc)
    deform(b, Ve, moved=ids, out=threaded)
    assert np.array_equal(one, threaded)


@pytest.mark.parametrize("span", [10, 1000, 10**6])
def test_distinct_is_unique_on_both_paths_and_leaves_the_scratch_clean(span):
    from core import binding
    rng = np.random.default_rng(span)
    scratch = {"stamp": np.empty(10**6 + 10, dtype=np.int64),
               "seen": np.zeros(10**6 + 10, dtype=bool)}
    for dtype in (np.int64, np.int32):
        values = (rng.integers(0, span, 5000) + 7).astype(dtype)
        got = binding._distinct(values, scratch)
        assert got.dtype == np.int64 and np.array_equal(got, np.unique(values))
        assert not scratch["seen"].any()
    assert binding._distinct(np.zeros(0, dtype=np.int32), scratch).dtype == np.int64


@pytest.mark.parametrize("scheme,levels", [("butterfly", 2), ("loop", 2), ("loop", 3)])
def test_a_drag_and_the_moves_after_it_are_the_full_deform_bit_for_bit(scheme, levels):
    """The same cage vertices moved again and again (a drag), with moves of
    other vertices in between and after it, each step equal to a full deform
    on a copy of the binding bit for bit (a drag's fine positions had come
    from a linear map of the moved vertices, 1e-16 of the diagonal off, which
    the updates after the drag kept in 1,084 rows of a campaign's case); 200
    small moves leave no drift."""
    import pickle
    Vd, Fd = noisy_sphere(3, amp=0.02)
    cage = simplify(Vd, Fd, target_faces=80)
    b = bind(Vd, Fd, cage.V, cage.F, levels=levels, scheme=scheme)
    ref = pickle.loads(pickle.dumps(b))
    rng = np.random.default_rng(levels)
    D = deform(b, cage.V)
    Ve = cage.V.copy()
    drag, single = np.array([5, 9]), np.array([12])
    other = np.array([30, 31])
    for ids in [drag] * 4 + [other] + [single] * 5 + [drag] * 3 + [other, drag, other]:
        Ve[ids] += 0.03 * rng.standard_normal((ids.shape[0], 3))
        deform(b, Ve, moved=ids, out=D)
        assert np.array_equal(D, deform(ref, Ve))
    for _ in range(200):
        Ve[drag] += 1e-3 * rng.standard_normal((drag.shape[0], 3))
        deform(b, Ve, moved=drag, out=D)
    assert np.array_equal(D, deform(ref, Ve))


@pytest.mark.parametrize("scheme", ["loop", "butterfly"])
def test_first_moves_are_the_full_deform_bit_for_bit_near_and_far_from_the_origin(scheme):
    """An incremental deform (not a drag) rewrites its rows with the full
    deform's operations: the same bits, with the edges' size taken once per
    fine face and the rows relative to a working origin away from zero (a
    scan 1e5 of its size off: the origin added back to the rows)."""
    import core.binding as binding_module
    Vd, Fd = noisy_sphere(3, amp=0.02)
    cage = simplify(Vd, Fd, target_faces=80)
    rng = np.random.default_rng(11)
    for shift in (0.0, 1e5):
        Vs, Cs = Vd + shift, cage.V + shift
        b = bind(Vs, Fd, Cs, cage.F, levels=2, scheme=scheme)
        assert binding_module._deform_origin(b, Cs).any() == bool(shift)
        D = deform(b, Cs)
        Ve = Cs.copy()
        for k in (1, 3, 5):
            ids = rng.choice(Cs.shape[0], k, replace=False)
            Ve[ids] += 0.03 * rng.standard_normal((k, 3))
            deform(b, Ve, moved=ids, out=D)
            assert np.array_equal(D, deform(b, Ve))
            deform(b, Ve, out=D)         # (a full deform between: no drag)


def test_a_drag_keeps_its_rows_gathers_and_gives_the_same_bits(torus_case, monkeypatch):
    """From a drag's second step its rows' barycentric coordinates and offsets
    are kept, block by block (many tiny blocks here, on the worker threads):
    the steps give the bits they give with nothing kept."""
    import core.binding as binding_module
    Vd, Vc, b = torus_case
    monkeypatch.setattr(binding_module, "_ROW_BLOCK", 7)
    monkeypatch.setattr(binding_module, "_THREADED_ROWS", 1)
    ids = np.array([3, 11, 12])
    results = []
    for kept in (binding_module._KEPT_BATCH_BYTES, 0):
        monkeypatch.setattr(binding_module, "_KEPT_BATCH_BYTES", kept)
        fresh = dataclasses.replace(b, _cache=None)
        D = deform(fresh, Vc)
        Ve = Vc.copy()
        steps = []
        for step in range(4):
            Ve[ids] += 0.01 * (step + 1)
            deform(fresh, Ve, moved=ids, out=D)
            steps.append(D.copy())
        assert len(fresh._cache["incremental"]["kept_rows"]) > 1 if kept else \
            not fresh._cache["incremental"]["kept_rows"]
        results.append(steps)
    for kept_step, plain_step in zip(*results):
        assert np.array_equal(kept_step, plain_step)


def test_a_cage_that_reads_as_mirrored_is_tested_for_folds_everywhere():
    """One cage vertex of the cow pushed 2 diagonals through it: the cage as
    a whole reads as mirrored (every row's detail turned), and a full deform
    had tested only the faces around that vertex's rows for folds: 363 faces
    away from rest elsewhere were left, where the incremental updates after
    it tested them (the drag back: 1,262 rows 5.5% of the diagonal apart).
    Both test every face now, the same bits."""
    from tests.mesh_factory import load_shared
    B = __import__("sys").modules["core.binding"]
    V, F = load_shared("cow.obj")[:2]
    d = bbox_diagonal(V)
    r = simplify(V, F, target_faces=60)
    b, fresh = (bind(V, F, r.V, r.F, levels=3, scheme="loop") for _ in range(2))
    v = 6
    C = r.V.copy()
    n = vertex_normals(r.V, r.F)[v]
    A = deform(b, C)
    C[v] -= 2.0 * d * n
    deform(b, C, moved=[v], out=A)
    assert B._handedness(b, C) == -1.0 and np.array_equal(A, deform(fresh, C))
    for _ in range(3):
        C[v] += 0.56 * d * n
        deform(b, C, moved=[v], out=A)
        assert np.array_equal(A, deform(fresh, C))
