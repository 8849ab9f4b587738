"""Arguments of the public functions that a fuzz of the API found taken without a
word, or failing deep inside with NumPy's own errors: each is now refused with
the library's error, naming the function, the argument and what it takes."""

import numpy as np
import pytest

import core
from core import InvalidArgumentError, InvalidMeshError
from core.mesh import stops
from tests.mesh_factory import icosphere


@pytest.fixture(scope="module")
def sphere():
    return icosphere(2)


@pytest.fixture(scope="module")
def cage(sphere):
    V, F = sphere
    r = core.simplify(V, F, target_faces=40)
    return r.V, r.F


@pytest.mark.parametrize("kwargs, match", [
    (dict(iterations=float("nan")), r"fit_cage: iterations must be an integer in \[0, 10000\]"),
    (dict(iterations=10**12), r"iterations must be an integer in \[0, 10000\], got 1000000000000"),
    (dict(iterations=None), "iterations must be an integer"),
    (dict(smoothness=float("inf")), r"smoothness must be a number >= 0, got inf"),
    (dict(smoothness="3"), r"smoothness must be a number >= 0, got '3'"),
    (dict(point_to_point=None), "point_to_point must be a number >= 0, got None"),
    (dict(samples=float("nan")), "samples must be an integer"),
    (dict(samples="3000"), "samples must be an integer"),
    (dict(samples=10**12), "samples must be an integer"),
    (dict(seed="3"), "seed must be an integer >= 0, got '3'"),
    (dict(seed=-1), "seed must be an integer >= 0, got -1"),
    (dict(cg_rtol=float("inf")), r"cg_rtol must be a number in \(0, 1\), got inf"),
    (dict(cg_rtol=-1), r"fit_cage: cg_rtol must be a number in \(0, 1\)"),
    (dict(cg_max_iterations=float("nan")), "cg_max_iterations must be an integer"),
    (dict(progress=5), "fit_cage: progress must be callable or None, got int"),
    (dict(levels=40), r"fit_cage: levels=40 would make .* faces of 40"),
    (dict(scheme="catmull"), "fit_cage: scheme must be one of"),
])
def test_fit_cage_refuses_settings_of_the_wrong_kind_before_any_work(sphere, cage, kwargs, match):
    V, F = sphere
    with pytest.raises(InvalidArgumentError, match=match):
        core.fit_cage(V, F, *cage, **kwargs)


@pytest.mark.parametrize("call, match", [
    (lambda V, F, C: core.subdivide(V, F, levels=40), r"subdivide: levels=40 would make"),
    (lambda V, F, C: core.subdivision_operator(F, len(V), levels=10**12), "levels=1000000000000"),
    (lambda V, F, C: core.bind(V, F, *C, levels=40), r"bind: levels=40 would make"),
    (lambda V, F, C: core.bind(V, F, *C, scheme=None), "bind: scheme must be one of"),
    (lambda V, F, C: core.sample_surface(V, F, 10**10), r"n_samples must be an integer in"),
    (lambda V, F, C: core.sample_surface(V, F, 10, seed=2.5), "seed must be an integer"),
    (lambda V, F, C: core.surface_distance(V, F, V, F, samples=10**12), "samples must be"),
    (lambda V, F, C: core.surface_distance(V, F, V, F, seed=1j), "seed must be an integer"),
    (lambda V, F, C: core.manifold_report(F, 10**12), r"n_vertices must be at most"),
    (lambda V, F, C: core.edge_map(F, 10**30), r"n_vertices must be at most"),
    (lambda V, F, C: core.TriangleIndex(V, F, cell_factor=1e-300), "cell_factor must be a number"),
    (lambda V, F, C: core.TriangleIndex(V, F, cell_factor=True), "cell_factor must be a number"),
    (lambda V, F, C: core.TriangleIndex(V, F, min_cell="1"), r"min_cell \(or None\) must be"),
])
def test_the_other_functions_refuse_them_too(sphere, cage, call, match):
    V, F = sphere
    with pytest.raises(InvalidArgumentError, match=match):
        call(V, F, cage)


@pytest.mark.parametrize("call", [
    lambda V, F, C: core.fit_cage(V, F, *C, levels=10, iterations=1),
    lambda V, F, C: core.bind(V, F, *C, levels=10),
    lambda V, F, C: core.bind_refined(core.bind(V, F, *C, levels=1), V, 10),
])
def test_fit_and_bind_refuse_more_fine_faces_than_memory_holds(sphere, cage, call):
    """A fit or a bind costs about 1 KB a fine face: at 9 levels a 100-face
    cage's fit ran for minutes and then out of memory inside NumPy (the
    subdivision's own cap, 268M faces, is for positions alone). The 40-face
    cage at 10 levels (42M fine faces) is refused, naming the levels it
    can take; at 9 (10.5M) it would be bound."""
    from core.subdivide import MAX_BOUND_FINE_FACES
    V, F = sphere
    assert cage[1].shape[0] * 4 ** 9 <= MAX_BOUND_FINE_FACES < cage[1].shape[0] * 4 ** 10
    with pytest.raises(InvalidArgumentError,
                       match=r"levels=10 would make 4\.19e\+07 faces of 40 .*levels=9 at most"):
        call(V, F, cage)


def test_a_huge_min_cell_is_one_cell_and_the_answers_stay_exact(sphere):
    V, F = sphere
    P = np.random.default_rng(0).normal(size=(50, 3))
    exact = core.TriangleIndex(V, F).closest(P).distance
    assert np.allclose(core.TriangleIndex(V, F, min_cell=1e300).closest(P).distance, exact,
                       rtol=0, atol=1e-12)


@pytest.mark.parametrize("V_bad, match", [
    (np.full((4, 3), np.nan), "bbox_diagonal: 4 vertices have NaN"),
    (np.ones((4, 2)), r"bbox_diagonal: V must be \(n,3\) floats"),
    (None, "bbox_diagonal: V must be"),
])
def test_bbox_diagonal_checks_its_vertices(V_bad, match):
    with pytest.raises(InvalidMeshError, match=match):
        core.bbox_diagonal(V_bad)


def test_coordinates_beyond_the_searches_reach_are_named(sphere):
    V, F = sphere
    for scale in (1e20, 1e55):           # within reach: exact, no warning
        with np.errstate(all="raise"):
            assert core.closest_points(V * scale, F, V[:3] * scale).distance.max() == 0.0
    with pytest.raises(InvalidMeshError, match="TriangleIndex: V reaches 1e.100 in its "
                                               "coordinates; its closest-point searches take "
                                               "coordinates up to 1e.60"):
        core.closest_points(V * 1e100, F, V[:3])
    with pytest.raises(InvalidMeshError, match=r"simplify \(symmetry\): V reaches 1e.300"):
        core.simplify(V * 1e300, F, target_faces=20, symmetry="X")


def test_an_edited_cage_of_the_wrong_kind_is_refused_by_deform(sphere, cage):
    V, F = sphere
    b = core.bind(V, F, *cage, levels=1)
    Vc = cage[0]
    for bad in (Vc.astype(complex), Vc.astype(str), Vc > 0):
        with pytest.raises(InvalidMeshError, match=r"deform: V_cage_edited must be \(n,3\) floats"):
            core.deform(b, bad)
    with pytest.raises(InvalidMeshError, match=r"deform: F must be \(m,3\) integers"):
        core.deform(b, Vc, F_cage=cage[1].astype(float) + 0.5)


def test_numpys_false_from_a_progress_callback_cancels(sphere, cage):
    V, F = sphere
    assert stops(False) and stops(np.False_) and not stops(None) and not stops(np.True_)
    r = core.simplify(V, F, target_faces=20, progress=lambda f: np.float64(f) < 0)
    assert r.stopped_because == "cancelled"
    fit = core.fit_cage(V, F, *cage, iterations=4, progress=lambda f: np.bool_(f < 0))
    assert fit.cancelled
    with pytest.raises(core.CancelledError):
        core.bind(V, F, *cage, progress=lambda f: np.bool_(False))


def test_writers_mirror_partners_and_affected_check_what_they_are_given(sphere, cage, tmp_path):
    V, F = sphere
    bad = V.copy()
    bad[3, 1] = np.nan
    with pytest.raises(InvalidMeshError, match=r"write_obj: 1 vertices have NaN or infinite "
                                               r"coordinates, 1 of them used by faces"):
        core.write_obj(tmp_path / "nan.obj", bad, F)          # (it was written, and not read back)
    assert not (tmp_path / "nan.obj").exists()
    with pytest.raises(InvalidMeshError, match=r"write_smf: V must be \(n,3\) floats"):
        core.write_smf(tmp_path / "c.smf", V.astype(complex), F)
    for bad_V in (V[:, :2], None, bad):
        with pytest.raises(InvalidMeshError, match="mirror_partners: (V must be|1 vertices have NaN)"):
            core.mirror_partners(bad_V, "X")
    for tol in (-1, float("nan"), "3", None):
        with pytest.raises(InvalidArgumentError, match=r"mirror_partners: tolerance must be a "
                                                       r"number in \(0, 1\]"):
            core.mirror_partners(V, "X", tolerance=tol)
    b = core.bind(V, F, *cage, levels=1)
    for ids, match in (([3.7], "moved must be integer cage vertex indices"),
                       (["3"], "moved must be integer"), ([10**6], "moved index 1000000 is out of range")):
        with pytest.raises(InvalidArgumentError, match=f"Binding.affected: {match}"):
            b.affected(ids)


def test_operator_binding_arrays_and_symmetrize_refuse_what_they_cannot_mean(sphere, cage):
    V, F = sphere
    op = core.subdivision_operator(F, len(V), levels=1)
    for bad in (V.astype(str), V.astype(complex), V > 0):
        with pytest.raises(InvalidArgumentError, match=r"SubdivisionOperator.apply: expected "
                                                       r"\(162, k\) or \(162,\) real numbers"):
            op.apply(bad)
    with pytest.raises(InvalidArgumentError, match="SubdivisionOperator.apply_transpose"):
        op.apply_transpose([[1.0, 2.0], [3.0]])                  # ragged
    for ids in ([0.5], None):
        with pytest.raises(InvalidArgumentError, match="support: expected coarse vertex ids"):
            op.support(ids)
    arrays = core.bind(V, F, *cage, levels=1).to_arrays()
    for key, value in (("n_cage", "x"), ("levels", None), ("levels", 2.5)):
        with pytest.raises(InvalidArgumentError, match=f"Binding.from_arrays: {key} must be an "
                                                       f"integer >= 0"):
            core.Binding.from_arrays({**arrays, key: value})
    assert core.Binding.from_arrays(arrays).n_cage == len(cage[0])
    p = core.mirror_partners(V, "X")
    assert np.array_equal(core.symmetrize(V, p, "X"), V)       # (the sphere is symmetric)
    with pytest.raises(InvalidArgumentError, match="symmetrize: partner must pair the vertices"):
        core.symmetrize(V, np.roll(p, 1), "X")


def test_readers_refuse_what_is_no_obj_and_faces_name_huge_indices(sphere, tmp_path):
    V, F = sphere
    (tmp_path / "u.obj").write_text("v 1_0 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\n")
    with pytest.raises(InvalidMeshError, match=r"u.obj line 1: 'v 1_0 0 0' is not a number"):
        core.read_obj(tmp_path / "u.obj")                       # (it read 10.0)
    (tmp_path / "b.obj").write_bytes(bytes(range(256)) * 40)
    with pytest.raises(InvalidMeshError, match=r"has no 'v' or 'f' line .*not an OBJ file"):
        core.read_obj(tmp_path / "b.obj")                       # (it read an empty mesh)
    big = F.astype(np.uint64)
    big[2, 2] = np.iinfo(np.uint64).max
    with pytest.raises(InvalidMeshError, match=r"face 2 = \[.*, 18446744073709551615\] indexes "
                                               r"a vertex beyond any mesh"):
        core.euler_characteristic(big)                          # (it said -1)


@pytest.mark.parametrize("seed", [2**63 - 1, 2**63, 2**64, 2**70, np.uint64(2**64 - 1)])
def test_any_integer_seed_numpy_takes_is_taken(seed):
    # 2**63 - 1 was refused as "not an integer" (its float is 2**63), 2**64 and up
    # raised NumPy's TypeError from np.isfinite
    V, F = icosphere(1)
    a = core.sample_surface(V, F, 50, seed=seed)
    b = core.sample_surface(V, F, 50, seed=seed)
    assert np.array_equal(np.asarray(a[0] if isinstance(a, tuple) else a),
                          np.asarray(b[0] if isinstance(b, tuple) else b))
    for bad in (-1, 2.5, float("inf"), True, "3"):
        with pytest.raises(InvalidArgumentError, match="sample_surface: seed must be an integer >= 0"):
            core.sample_surface(V, F, 50, seed=bad)


def test_bind_names_a_ragged_crease_list():
    # a row of one vertex was NumPy's "setting an array element with a sequence"
    V, F = icosphere(2)
    Vc, Fc = icosphere(1)
    with pytest.raises(InvalidArgumentError, match=r"bind: creases must be a \(k,2\) integer array "
                                                   r"of vertex pairs, got rows of different lengths"):
        core.bind(V, F, Vc, Fc, creases=[[0, 1], [1]])
    with pytest.raises(InvalidArgumentError, match=r"bind: creases must be a \(k,2\) integer array"):
        core.bind(V, F, Vc, Fc, creases=[[0.0, 1.0]])


@pytest.mark.parametrize("call, shown", [
    (lambda V, F: core.topology_summary(F, F), r"got an array of shape \(320, 3\) \(int64\)$"),
    (lambda V, F: core.simplify(V, F, target_faces=F), r"got an array of shape \(320, 3\)"),
    (lambda V, F: core.subdivide(V, F, levels=[1] * 500), r"got a list of 500 items$"),
    (lambda V, F: core.subdivide(V, F, scheme="b" * 500), r"got 'bbbb.* \.\.\.$"),
])
def test_a_message_shows_a_large_wrong_value_by_its_kind_and_shape(sphere, call, shown):
    """A face array given where a count goes had printed all of its rows into
    the message (a 24-face cage: 26 lines): now its kind and shape, and a long
    value's start."""
    V, F = sphere
    with pytest.raises(InvalidArgumentError, match=shown) as raised:
        call(V, F)
    assert len(str(raised.value)) < 200 and "\n" not in str(raised.value)


def _quiet(call):
    """``call()`` with every warning an error (NumPy's overflow warnings
    included)."""
    import warnings
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        return call()


@pytest.mark.parametrize("scale", [1e-200, 1e-160, 1e160, 1e200])
def test_turned_faces_and_samples_at_any_scale(scale):
    """Beyond 1e154 the area normals overflowed: a folded face went uncounted
    by turned_faces (inf - inf), every sample fell on one face; below 1e-160
    the areas were zero and the samples uniform per face. Now the same
    answers as at unit scale, without a warning."""
    V = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0.1, 0.1, 0]])
    F = np.array([[0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4]])
    mirrored = V * [-1, 1, 1]
    assert _quiet(lambda: core.turned_faces(V * scale, mirrored * scale, F)).tolist() == \
        [0, 1, 2, 3]
    assert _quiet(lambda: core.turned_faces(V * scale, V * scale, F)).size == 0
    at_one = core.sample_surface(V, F, 2000, seed=3)
    scaled = _quiet(lambda: core.sample_surface(V * scale, F, 2000, seed=3))
    assert np.array_equal(scaled.face, at_one.face) and np.array_equal(scaled.bary, at_one.bary)


def test_simplify_and_fit_without_overflow_warnings(sphere, cage):
    """A holed mesh at 1e200 (its border loops' lengths overflowed) and a
    fit_cage smoothness of 1e200 (the solver's sums): NumPy's overflow
    warnings, errors under -W error; the same results as before."""
    V, F = sphere
    holed = F[np.arange(F.shape[0]) % 37 != 0]
    at_one = core.simplify(V, holed, target_faces=60)
    far = _quiet(lambda: core.simplify(V * 1e200, holed, target_faces=60))
    assert np.array_equal(far.F, at_one.F) and np.allclose(far.V / 1e200, at_one.V, atol=1e-15)
    fitted = _quiet(lambda: core.fit_cage(V, F, *cage, levels=1, iterations=2, smoothness=1e200))
    assert np.abs(fitted.V - cage[0]).max() <= 1e-12


def test_closest_point_queries_and_flags_are_checked(sphere):
    """Query points of strings or complex numbers (NumPy's errors, or the
    imaginary part dropped), beyond the searches' reach (wrong face, infinite
    distance at 1e154), a crowded_cell that is no number, a normalize flag
    that is no flag, and NumPy's timedelta64 as a number: each named."""
    V, F = sphere
    index = core.TriangleIndex(V, F)
    P = np.array([[0.2, 0.1, 1.5]])
    for bad, shown in (("abc", r"\(\) <U3"), (P.astype(complex), r"\(1, 3\) complex128"),
                       ([["0.2", "0.1", "1.5"]], r"\(1, 3\) <U3")):
        with pytest.raises(InvalidArgumentError, match=rf"^TriangleIndex\.closest: P must be "
                                                        rf"\(q,3\) floats, got {shown}$"):
            index.closest(bad)
    with pytest.raises(InvalidArgumentError, match=r"P reaches 1.5e\+155 .* up to 1e\+60"):
        core.closest_points(V, F, P * 1e155)
    with pytest.raises(InvalidArgumentError, match=r"crowded_cell must be a number >= 0, got '5'"):
        index.closest(P, crowded_cell="5")
    assert index.closest(P, crowded_cell=0).face.tolist() == index.closest(P).face.tolist()
    with pytest.raises(InvalidArgumentError, match=r"normalize must be True or False, got 'no'"):
        core.face_normals(V, F, normalize="no")
    with pytest.raises(InvalidArgumentError, match=r"levels must be an integer >= 0, got "
                                                   r"(np|numpy)\.timedelta64\(1\)"):
        core.subdivide(V, F, levels=np.timedelta64(1))
    with pytest.raises(InvalidArgumentError, match=r"ratio must be a number in \(0, 1\]"):
        core.simplify(V, F, ratio=np.timedelta64(1))
