"""Arguments of subdivide / subdivision_operator / SubdivisionOperator as
they arrive from an add-on, a script or a file: every bad one is refused by
a core error that names it, never a NumPy error from inside."""

import numpy as np
import pytest

from core.errors import InvalidArgumentError
from core.fit import fit_cage
from core.subdivide import subdivide, subdivision_operator
from tests.mesh_factory import icosphere, octahedron


@pytest.mark.parametrize("call", ["subdivide", "subdivision_operator", "fit_cage"])
def test_ragged_creases_are_named(call):
    """A crease list with a row of one vertex was NumPy's 'setting an array
    element with a sequence' ValueError."""
    V, F = octahedron()
    ragged = [[0, 2], [2]]
    with pytest.raises(InvalidArgumentError, match=rf"{call}: .*creases must be a \(k,2\) integer "
                                                   r"array of vertex pairs, got rows of different lengths"):
        if call == "subdivide":
            subdivide(V, F, creases=ragged)
        elif call == "subdivision_operator":
            subdivision_operator(F, 6, creases=ragged)
        else:
            Vd, Fd = icosphere(2)
            fit_cage(Vd, Fd, V, F, creases=ragged, iterations=1)


def test_a_crease_index_beyond_int64_is_shown_as_given():
    """An unsigned index past 2^63 was shown wrapped to a negative number
    ('pair 0 = [0, -9223372036854775803] is not an edge')."""
    V, F = octahedron()
    C = np.array([[0, 2 ** 63 + 5]], dtype=np.uint64)
    with pytest.raises(InvalidArgumentError, match=r"pair 0 = \[0, 9223372036854775813\] is not an edge"):
        subdivide(V, F, creases=C)


def test_empty_creases_of_any_kind_are_no_creases():
    V, F = octahedron()
    plain = subdivision_operator(F, 6, levels=2)
    for empty in ([], (), np.zeros((0, 2), np.int32), np.zeros(0), [[]]):
        op = subdivision_operator(F, 6, levels=2, creases=empty)
        assert op.fingerprint == plain.fingerprint and op.creases.shape == (0, 2)


def test_support_of_an_empty_selection_is_empty():
    """support([]) was refused: an empty list is float64 to NumPy."""
    V, F = octahedron()
    op = subdivision_operator(F, 6, levels=2)
    for empty in ([], np.zeros(0, np.int64), ()):
        got = op.support(empty)
        assert got.dtype == bool and got.shape == (op.n_fine,) and not got.any()


@pytest.mark.parametrize("levels", [1, 3])
def test_coordinates_near_the_float_limit_give_values_or_a_named_error_never_nan(levels):
    """Butterfly overshoots its cage (up to 12% on two triangles): finite
    coordinates near 1.7e308 came out as inf and NaN ('invalid value
    encountered in reduceat'). Values that fit are computed (exactly as at a
    smaller scale: by a power of two), values that do not are refused."""
    from core.errors import InvalidMeshError
    from core.subdivide import subdivision_operator
    V = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0.3]])
    F = np.array([[0, 1, 2], [2, 1, 3]])
    with pytest.raises(InvalidMeshError, match=r"subdivide: the subdivided positions would exceed "
                                               r"the largest float: .*reach 1\.7e\+308 .*scale them down"):
        subdivide(V * 1.7e308, F, levels=levels)
    op = subdivision_operator(F, 4, levels=levels)
    with pytest.raises(InvalidArgumentError, match=r"SubdivisionOperator.apply: the subdivided "
                                                   r"values would exceed the largest float"):
        op.apply(V * 1.7e308)
    s = 2.0 ** 1020                 # 1.1e307: butterfly's overshoot still fits
    got = subdivide(V * s, F, levels=levels).V
    assert np.isfinite(got).all() and np.array_equal(got, subdivide(V, F, levels=levels).V * s)
    assert np.array_equal(op.apply(V * s), op.apply(V) * s)
    loop = subdivide(V * 1.7e308, F, levels=levels, scheme="loop").V     # (convex: always fits)
    assert np.isfinite(loop).all()


def test_levels_beyond_any_mesh_are_refused_also_without_faces():
    """Without faces no level made a face, so any levels passed: 10,000 took
    3 s, 10**6 some five minutes, building one empty level after another.
    More levels than one triangle may take (14: 4**14 faces) are refused."""
    V = np.zeros((3, 3))
    empty = np.zeros((0, 3), dtype=np.int64)
    assert subdivide(V, empty, levels=14).V.shape == (3, 3)
    with pytest.raises(InvalidArgumentError, match=r"subdivide: levels=100000 is more than any mesh "
                                                   r"takes \(at most 14"):
        subdivide(V, empty, levels=10 ** 5)
    with pytest.raises(InvalidArgumentError, match=r"subdivision_operator: levels=15 is more"):
        subdivision_operator(empty, 3, levels=15)
    with pytest.raises(InvalidArgumentError, match=r"levels=15 would make 1\.07e\+09 faces of 1 "):
        subdivide(V, [[0, 1, 2]], levels=15)


@pytest.mark.parametrize("n", [2 ** 62, 2 ** 63, 10 ** 30])
def test_a_vertex_count_beyond_any_subdivision_is_named(n):
    """n_vertices past what any subdivision makes was NumPy's ValueError
    ('array is too big'), OverflowError ('Python int too large to convert
    to C long') or a MemoryError from inside."""
    with pytest.raises(InvalidArgumentError, match=rf"subdivision_operator: n_vertices={n} is more "
                                                   r"than a subdivision may hold \(at most 268,435,456\)"):
        subdivision_operator([[0, 1, 2]], n, levels=1)


def test_support_names_an_unsigned_id_past_int64_as_given():
    """An unsigned id past 2**63 was shown wrapped ('got -9223372036854775807')."""
    op = subdivision_operator([[0, 1, 2]], 3, levels=1)
    with pytest.raises(InvalidArgumentError, match=r"must be in \[0, 3\), got 9223372036854775809"):
        op.support(np.array([2 ** 63 + 1], dtype=np.uint64))
    assert op.support(np.array([1], dtype=np.uint64)).sum() == 4


def test_a_fan_beyond_the_butterflys_ring_stencils_is_named_and_loop_takes_it():
    """Each edge at a vertex of valence k reads its k ring vertices: a CAD cap
    fan of 10k triangles held 5.5 GB and 40k ran out of memory. Beyond
    MAX_RING_ENTRIES a level, named with the vertex; Loop takes the fan (its
    rows read at most four vertices), and a fan within the bound subdivides."""
    from core.errors import InvalidMeshError
    from core.subdivide import MAX_RING_ENTRIES
    from tests.mesh_factory import cad_cylinder
    V, F = cad_cylinder(n_around=5000)                # two cap fans of valence 5,000
    assert 2 * 5000 * 5001 > MAX_RING_ENTRIES
    with pytest.raises(InvalidMeshError, match=r"^subdivide: butterfly subdivision reads a "
                                               r"vertex's whole ring .* vertex 10000 has 5,000 "
                                               r"edges \(50,\d{3},\d{3} stencil entries a level"):
        subdivide(V, F, levels=1)
    assert subdivide(V, F, levels=1, scheme="loop").F.shape[0] == 4 * F.shape[0]
    V, F = cad_cylinder(n_around=1000)
    assert subdivide(V, F, levels=1).F.shape[0] == 4 * F.shape[0]
