"""Incremental refine: ``refine(b, V, moved=ids, out=R)`` recomputes only the
fine vertices the moved cage vertices move (``Binding.refined_rows``), and
equals a full refine.

Properties: incremental == full bit for bit (hypothesis, random moved sets,
both schemes, levels 0-3, chains of updates), a drag (the same vertices moved
again and again) within 1e-12 of the diagonal and without drift, the rows
outside ``refined_rows`` never written and unchanged by the edit, a
mirrored cage or a fresh ``out`` refined whole, deform and refine sharing
the kept subdivided cage, and bad ``moved`` / ``out`` raising named errors.
"""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from core.binding import bind, deform, refine
from core.errors import InvalidArgumentError
from core.mesh import bbox_diagonal
from core.simplify import simplify
from tests.mesh_factory import drawn_edit, sphere_binding, torus


@pytest.fixture(scope="module", params=["butterfly", "loop"])
def case(request):
    return sphere_binding(request.param)


@pytest.fixture(scope="module")
def torus_case():
    Vd, Fd = torus(96, 48, bump=0.01)
    cage = simplify(Vd, Fd, target_faces=200)
    return Vd, Fd, cage, bind(Vd, Fd, cage.V, cage.F, levels=2, scheme="loop")


@settings(max_examples=25, deadline=None)
@given(data=st.data())
def test_incremental_equals_full_for_random_moved_sets(case, data):
    Vd, Vc, b = case
    ids, Ve = drawn_edit(data, Vc)
    R = refine(b, Vc).V
    got = refine(b, Ve, moved=ids, out=R)
    assert got.V is R
    assert np.array_equal(R, refine(b, Ve).V)          # the same operations, column by column


@pytest.mark.parametrize("levels", [0, 1, 3])
@pytest.mark.parametrize("scheme", ["butterfly", "loop"])
def test_a_chain_of_updates_at_other_levels_is_the_full_refine(levels, scheme):
    Vd, Fd = torus(64, 32, bump=0.01)
    cage = simplify(Vd, Fd, target_faces=150)
    b = bind(Vd, Fd, cage.V, cage.F, levels=levels, scheme=scheme)
    rng = np.random.default_rng(levels)
    Ve = cage.V.copy()
    R = refine(b, Ve).V
    for _ in range(5):            # different vertices each time (no drag): bit for bit
        ids = rng.choice(Ve.shape[0], rng.integers(1, 6), replace=False)
        Ve[ids] += 0.02 * rng.standard_normal((ids.shape[0], 3))
        refine(b, Ve, moved=ids, out=R)
    assert np.array_equal(R, refine(b, Ve).V)


def test_refined_rows_are_the_rows_that_change_and_the_only_ones_written(torus_case):
    Vd, _, cage, b = torus_case
    ids = np.array([4, 17])
    rows = b.refined_rows(ids)
    assert np.array_equal(rows, np.unique(rows)) and rows.dtype == np.int64
    n_fine = b.operator.n_fine
    assert 0 < rows.shape[0] < 0.5 * n_fine
    R = refine(b, cage.V).V
    before = R.copy()
    Ve = cage.V.copy()
    Ve[ids] += 0.03
    refine(b, Ve, moved=ids, out=R)
    outside = np.setdiff1d(np.arange(n_fine), rows)
    assert np.array_equal(R[outside], before[outside])
    # and the full refine of the edit leaves them as they were too: the rows are every
    # vertex the edit can move
    assert np.array_equal(refine(b, Ve).V[outside], before[outside])
    # (a vertex listed moves: each of them reads a moved position or normal)
    assert (R[rows] != before[rows]).any(axis=1).mean() > 0.95


def test_a_drag_and_a_move_after_it_are_the_full_refine_bit_for_bit(torus_case):
    Vd, _, cage, b = torus_case
    R = refine(b, cage.V).V
    Ve = cage.V.copy()
    ids = np.array([5, 6, 30])
    for step in range(40):                   # the same vertices again and again: a drag
        Ve[ids] += 0.002 * np.array([1.0, -0.5, 0.25])
        refine(b, Ve, moved=ids, out=R)
    assert np.array_equal(R, refine(b, Ve).V)
    Ve[70] += 0.01                           # and another vertex after it
    refine(b, Ve, moved=[70], out=R)
    assert np.array_equal(R, refine(b, Ve).V)


def test_deform_and_refine_share_the_kept_subdivided_cage(torus_case):
    # an incremental deform after a refine of another cage (and the other way round)
    # still equals the full one: each finds the kept cage differs elsewhere than at moved
    Vd, _, cage, b = torus_case
    tol = 1e-12 * bbox_diagonal(Vd)
    V1 = cage.V.copy()
    V1[[1, 2]] += 0.02
    R = refine(b, V1).V
    D = deform(b, V1)
    V2 = V1.copy()
    V2[[40, 41]] -= 0.03
    refine(b, V2 + 0.0, moved=[40, 41], out=R)
    deform(b, V2, moved=[40, 41], out=D)
    assert np.array_equal(R, refine(b, V2).V)
    assert np.abs(D - deform(b, V2)).max() <= tol
    V3 = V2.copy()
    V3[[7]] += 0.01
    deform(b, V3, moved=[7], out=D)                # the kept cage is now V3 ...
    refine(b, V3, moved=[7], out=R)                # ... which refine takes as it is
    assert np.array_equal(R, refine(b, V3).V)


def test_a_mirrored_cage_and_a_fresh_binding_are_refined_whole(torus_case):
    Vd, Fd, cage, b = torus_case
    R = refine(b, cage.V).V
    Vm = cage.V * np.array([-1.0, 1.0, 1.0])
    refine(b, Vm, moved=[0], out=R)                # (every row changes: written whole)
    assert np.array_equal(R, refine(b, Vm).V)
    fresh = bind(Vd, Fd, cage.V, cage.F, levels=1)
    out = np.zeros((fresh.operator.n_fine, 3))     # never written by a refine of it
    refine(fresh, cage.V, moved=[3], out=out)
    assert np.array_equal(out, refine(fresh, cage.V).V)


def test_empty_moved_duplicates_and_the_faces_returned(case):
    Vd, Vc, b = case
    R = refine(b, Vc).V
    before = R.copy()
    Ve = Vc.copy()
    Ve[[2, 9]] -= 0.04
    got = refine(b, Ve, moved=[], out=R)
    assert np.array_equal(R, before)                   # nothing listed: nothing written
    assert not got.F.flags.writeable and np.array_equal(got.F, b.operator.F_fine)
    refine(b, Ve, moved=np.array([9, 2, 2, 9], dtype=np.int32), out=R)
    assert np.array_equal(R, refine(b, Ve).V)
    full = refine(b, Ve)
    assert full.F.flags.writeable and not np.shares_memory(full.F, b.operator.F_fine)


def test_inputs_are_not_modified(case):
    Vd, Vc, b = case
    R = refine(b, Vc).V
    Ve = Vc.copy()
    Ve[3] += 0.05
    ids = np.array([3, 3])
    keep_V, keep_ids = Ve.copy(), ids.copy()
    refine(b, Ve, moved=ids, out=R)
    assert np.array_equal(Ve, keep_V) and np.array_equal(ids, keep_ids)


def test_bad_moved_and_out_raise_named_errors(case):
    Vd, Vc, b = case
    n_fine = b.operator.n_fine
    R = refine(b, Vc).V
    with pytest.raises(InvalidArgumentError, match="moved needs out"):
        refine(b, Vc, moved=[1])
    with pytest.raises(InvalidArgumentError, match=r"moved index -1 is out of range"):
        refine(b, Vc, moved=[-1], out=R)
    with pytest.raises(InvalidArgumentError, match="moved must be integer"):
        refine(b, Vc, moved=[1.5], out=R)
    with pytest.raises(InvalidArgumentError, match=rf"refine: out must be .*\({n_fine}, 3\)"):
        refine(b, Vc, moved=[1], out=np.zeros((n_fine - 1, 3)))
    with pytest.raises(InvalidArgumentError, match="float64"):
        refine(b, Vc, out=np.zeros((n_fine, 3), dtype=np.float32))
    with pytest.raises(InvalidArgumentError, match="Binding.refined_rows: moved index 99999"):
        b.refined_rows([99999])
    assert b.refined_rows([]).shape == (0,)


@pytest.mark.parametrize("far", [1e3, 1e9])
def test_a_cage_moved_far_away_and_back_is_refined_and_deformed_as_a_full_one(torus_case, far):
    # the working origin changes with a cage moved far away (or back): every row's
    # rounding changes, so the update is a full one (it had kept the kept cage's origin:
    # 9e-8 of the diagonal off the full result at 1e9)
    from core.binding import Binding
    Vd, _, cage, b = torus_case
    fresh = Binding.from_arrays(b.to_arrays())
    every = np.arange(cage.V.shape[0])
    R, D = refine(b, cage.V).V, deform(b, cage.V)
    for V in (cage.V + far, cage.V.copy()):
        refine(b, V, moved=every, out=R)
        deform(b, V, moved=every, out=D)
        assert np.array_equal(R, refine(fresh, V).V)
        assert np.array_equal(D, deform(fresh, V))
    V = cage.V + far                 # the last full ones far away, then back incrementally
    refine(b, V, out=R)
    deform(b, V, out=D)
    refine(b, cage.V, moved=every, out=R)
    deform(b, cage.V, moved=every, out=D)
    assert np.array_equal(R, refine(fresh, cage.V).V)
    assert np.array_equal(D, deform(fresh, cage.V))


def test_rest_as_a_whole_takes_a_mirror_or_turn_of_the_whole_cage(torus_case):
    # (the add-on's turned-cage warning compares with it: a cage mirrored or turned as a
    # whole turns no face over; a vertex pushed through the cage still does)
    import dataclasses
    from core.mesh import turned_faces
    Vd, _, cage, b = torus_case
    assert turned_faces(cage.V, cage.V * [-1.0, 1.0, 1.0], cage.F).size > 100
    c, s = np.cos(3.0), np.sin(3.0)
    for V in (cage.V * [-1.0, 1.0, 1.0], cage.V @ np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])):
        assert turned_faces(b.rest_as_a_whole(V), V, cage.F).size == 0
    V = cage.V.copy()
    V[0] = -V[0]
    assert turned_faces(b.rest_as_a_whole(V), V, cage.F).size > 0
    assert dataclasses.replace(b, V_cage_rest=None).rest_as_a_whole(V) is None


def test_rest_as_a_whole_names_a_cage_it_cannot_take(torus_case):
    from core.errors import InvalidMeshError, TopologyMismatchError
    _, _, cage, b = torus_case
    with pytest.raises(TopologyMismatchError, match="rest_as_a_whole.*5 vertices"):
        b.rest_as_a_whole(cage.V[:5])
    bad = cage.V.copy()
    bad[3, 1] = np.nan
    for V in (cage.V[:, :2], "x", bad):
        with pytest.raises(InvalidMeshError, match="rest_as_a_whole"):
            b.rest_as_a_whole(V)
