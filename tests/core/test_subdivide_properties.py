"""Property tests of core.subdivide on random cages as simplify and an artist
leave them: open patches with holes, flipped diagonals, random creases
(chains ending at borders, corners of 3+ creases, darts), folded and
degenerate positions, far from the origin or at any scale."""

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings, strategies as st

from core.errors import InvalidMeshError
from core.subdivide import subdivide, subdivision_operator
from core.topology import edge_map, euler_characteristic
from tests.core.test_subdivide import reference
from tests.mesh_factory import boundary_edges


def _patch(nx, ny, flips, drops):
    """An (nx, ny) grid of quads, each split along one diagonal or the other
    (``flips``), less the faces ``drops`` (holes, notches)."""
    x, y = np.meshgrid(np.arange(nx + 1.0), np.arange(ny + 1.0))
    V = np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], 1)
    j, i = np.divmod(np.arange(nx * ny), nx)
    a = j * (nx + 1) + i
    b, c, d = a + 1, a + nx + 2, a + nx + 1
    f = np.asarray(flips[:nx * ny] + [False] * (nx * ny - len(flips)))[:, None]
    F = np.where(f, np.stack([a, b, d, b, c, d], 1), np.stack([a, b, c, a, c, d], 1)).reshape(-1, 3)
    keep = np.ones(len(F), bool)
    keep[[k % len(F) for k in drops]] = False
    return V, F[keep]


@st.composite
def cages(draw):
    nx, ny = draw(st.integers(1, 5)), draw(st.integers(1, 5))
    flips = draw(st.lists(st.booleans(), max_size=25))
    drops = draw(st.lists(st.integers(0, 49), max_size=6))
    V, F = _patch(nx, ny, flips, drops)
    assume(len(F) > 0)
    try:
        subdivision_operator(F, len(V))
    except InvalidMeshError:          # dropping faces made a bow-tie vertex
        assume(False)
    seed = draw(st.integers(0, 2 ** 32 - 1))
    rng = np.random.default_rng(seed)
    V = V + rng.normal(0, draw(st.sampled_from([0.0, 0.2, 0.6])), V.shape)   # 0.6 folds faces
    V[:, 2] = rng.normal(0, 0.5, len(V))
    if draw(st.booleans()):                                   # an edit: points moved together
        k = rng.integers(len(V), size=2)
        V[k[0]] = V[k[1]]
    E = edge_map(F, len(V)).E
    C = E[rng.random(len(E)) < draw(st.sampled_from([0.0, 0.15, 0.5]))]
    return V, F, C


def _sharp_vertices(F, n, C):
    on = np.zeros(n, bool)
    on[boundary_edges(F, n).ravel()] = True
    on[np.asarray(C, np.int64).ravel()] = True
    return on


def _border_loops(F, n):
    """Connected pieces of the border edges (loops on a manifold mesh)."""
    B = boundary_edges(F, n)
    if not len(B):
        return 0
    label = np.arange(n)
    for _ in range(n):      # label propagation: a test helper, small meshes
        low = np.minimum(label[B[:, 0]], label[B[:, 1]])
        new = label.copy()
        np.minimum.at(new, B[:, 0], low)
        np.minimum.at(new, B[:, 1], low)
        if np.array_equal(new, label):
            break
        label = new
    return np.unique(label[np.unique(B)]).size


SETTINGS = settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.filter_too_much,
                                                                           HealthCheck.too_slow])


@SETTINGS
@given(cages(), st.integers(0, 3), st.sampled_from(["butterfly", "loop"]))
def test_random_cages_equal_the_reference(cage, levels, scheme):
    V, F, C = cage
    Vf, Ff = subdivide(V, F, levels=levels, scheme=scheme, creases=C)
    Vr, Fr = reference(V, F, levels, scheme, C)
    assert np.array_equal(Ff, Fr)
    np.testing.assert_allclose(Vf, Vr, rtol=0, atol=1e-12 * (1 + np.abs(V).max()))


@SETTINGS
@given(cages(), st.integers(0, 4), st.sampled_from(["butterfly", "loop"]))
def test_counts_topology_interpolation_and_untouched_inputs(cage, levels, scheme):
    V, F, C = cage
    for a in (V, F, C):
        a.setflags(write=False)
    copies = [a.copy() for a in (V, F, C)]
    Vf, Ff = subdivide(V, F, levels=levels, scheme=scheme, creases=C)
    for a, b in zip((V, F, C), copies):
        assert np.array_equal(a, b) and not a.flags.writeable
    assert Ff.shape == (len(F) * 4 ** levels, 3) and np.isfinite(Vf).all()
    assert Vf.flags.writeable and Ff.flags.writeable
    used = np.unique(F).size
    assert euler_characteristic(Ff, len(Vf)) - (len(Vf) - np.unique(Ff).size) == \
        euler_characteristic(F, len(V)) - (len(V) - used)
    assert _border_loops(Ff, len(Vf)) == _border_loops(F, len(V))
    if scheme == "butterfly":
        assert np.array_equal(Vf[:len(V)], V)


@SETTINGS
@given(cages(), st.integers(1, 3), st.sampled_from(["butterfly", "loop"]),
       st.sampled_from([1e-4, 1e4, 3.7, 2.0 ** -20]), st.sampled_from([0.0, 1e5, -3e4]))
def test_translation_scale_and_affine_covariance(cage, levels, scheme, scale, shift):
    V, F, C = cage
    Vf = subdivide(V, F, levels=levels, scheme=scheme, creases=C).V
    t = np.array([shift, -0.5 * shift, 0.25 * shift])
    Vm = scale * V + t
    got = subdivide(Vm, F, levels=levels, scheme=scheme, creases=C).V
    # rounding: a few ulps of the coordinates (the cage's, moved) per level
    tol = 1e-12 * max(np.abs(Vm).max(), scale * np.abs(V).max())
    np.testing.assert_allclose(got, scale * Vf + t, rtol=0, atol=tol)
    if shift == 0 and np.log2(scale) == int(np.log2(scale)):
        assert np.array_equal(got, scale * Vf)        # a power of two scales exactly
    A = np.array([[1.0, 0.3, -0.2], [0.1, 2.0, 0.5], [-0.4, 0.2, 0.7]])
    got = subdivide(V @ A.T + t, F, levels=levels, scheme=scheme, creases=C).V
    np.testing.assert_allclose(got, Vf @ A.T + t, rtol=0, atol=1e-12 * np.abs(V @ A.T + t).max() * 4)


@SETTINGS
@given(cages(), st.integers(1, 3), st.sampled_from(["butterfly", "loop"]))
def test_borders_and_creases_depend_only_on_their_own_vertices(cage, levels, scheme):
    """The refined border and crease curves (the fine vertices on sharp
    coarse edges, and the sharp coarse vertices) read no vertex off them:
    moving every other cage vertex leaves them bit for bit."""
    V, F, C = cage
    n = len(V)
    on = _sharp_vertices(F, n, C)
    assume(on.any() and not on.all())
    op = subdivision_operator(F, n, levels=levels, scheme=scheme, creases=C)
    face, bary = op.fine_vertex_parent()
    sharp = edge_map(F, n)
    keys = set(map(tuple, np.sort(np.vstack([boundary_edges(F, n), np.reshape(C, (-1, 2))]), 1).tolist()))
    corners = F[np.maximum(face, 0)]
    zero = (bary == 0) & (face >= 0)[:, None]
    on_curve = np.zeros(op.n_fine, bool)
    for g in np.flatnonzero(zero.sum(1) >= 1):      # (a test: a loop over fine vertices is fine)
        rest = corners[g][~zero[g]]
        if rest.size == 1:
            on_curve[g] = on[rest[0]]
        elif rest.size == 2:
            on_curve[g] = tuple(sorted(rest.tolist())) in keys
    assert sharp.E.shape[0] > 0
    assert not (op.support(~on) & on_curve).any()
    rng = np.random.default_rng(0)
    moved = V.copy()
    moved[~on] += rng.normal(0, 1, ((~on).sum(), 3))
    assert np.array_equal(op.apply(moved)[on_curve], op.apply(V)[on_curve])


@pytest.mark.parametrize("scheme", ["butterfly", "loop"])
def test_a_mirror_symmetric_cage_refines_mirror_symmetric(scheme):
    """A cage that is its own mirror image about X = 0 (faces mirrored and
    turned back over, creases mirrored) refines into a mirror-symmetric mesh:
    each fine vertex has its mirror image among the fine vertices."""
    rng = np.random.default_rng(4)
    V, F = _patch(4, 3, [bool(b) for b in rng.integers(0, 2, 12)], [23])   # a notch
    V[:, 2] = rng.normal(0, 0.3, len(V))
    V[:, 1] += rng.normal(0, 0.1, len(V))
    n = len(V)
    plane = np.flatnonzero(V[:, 0] == 0)           # the left column, welded to its mirror
    partner = np.arange(n, 2 * n)
    partner[plane] = plane
    Vm = V * [-1, 1, 1]
    Vs = np.vstack([V, Vm])
    Fs = np.vstack([F, partner[F][:, ::-1]])
    used = np.unique(Fs)
    C = np.array([[0, 1], [1, 6], [6, 7], [7, 8], [7, 12]])      # a chain and a 3-crease corner
    Cs = np.vstack([C, partner[C]])
    Vf, _ = subdivide(Vs, Fs, levels=3, scheme=scheme, creases=Cs)
    fine_used = np.unique(subdivision_operator(Fs, 2 * n, levels=3, creases=Cs).F_fine)
    P = Vf[fine_used]
    Q = P * [-1, 1, 1]
    order_p = np.lexsort(np.round(P, 9).T)
    order_q = np.lexsort(np.round(Q, 9).T)
    np.testing.assert_allclose(P[order_p], Q[order_q], rtol=0, atol=1e-12)
    assert used.size < 2 * n
