"""Artists' and adversarial edits thrown at ``deform`` / ``refine`` (a campaign on
2026-12-05 evening): each test is a bug that campaign found, with its repro."""

import numpy as np
import pytest

from core.binding import bind, deform
from core.errors import InvalidArgumentError, InvalidMeshError, TopologyMismatchError
from core.mesh import bbox_diagonal
from core.simplify import simplify
from tests.mesh_factory import grid, icosphere


@pytest.fixture(scope="module")
def grid_loop():
    V, F = grid(12, 12)
    cage = simplify(V, F, target_faces=80)
    return V, cage, bind(V, F, cage.V, cage.F, levels=1, scheme="loop")


def test_a_cage_vertex_put_on_its_neighbour_deforms_the_same_incrementally(grid_loop):
    # A cage vertex moved exactly onto a neighbour (snapping, merge by distance not yet
    # applied) folds its fine faces flat: a fine vertex whose every face has no area had
    # a normal made of rounding noise, so the incremental deform (the same positions to
    # 1e-16) drew another direction than the full one: a dense vertex bound there
    # 0.029 of the diagonal apart on this grid (suzanne's cage: 1e-3). Such a normal is
    # none now, in both (the frame falls back as on any flat face).
    V, cage, b = grid_loop
    tol = 1e-12 * bbox_diagonal(V)
    E = np.concatenate([cage.F[:, [0, 1]], cage.F[:, [1, 2]], cage.F[:, [2, 0]]])
    for a, c in E:
        Ve = cage.V.copy()
        Ve[a] = cage.V[c]
        full = deform(b, Ve)
        D = deform(b, cage.V)
        deform(b, Ve, moved=[a], out=D)
        assert np.abs(D - full).max() <= tol, (a, c)
        assert np.isfinite(full).all()


def test_a_binding_keeps_its_arrays_from_the_caller_and_from_deform(grid_loop):
    # Binding.from_arrays kept the caller's float64 arrays (np.asarray): a buffer
    # reused after loading (here the rest cage zeroed) moved the binding's rest, and its
    # deforms 0.4 of the size off; and deform(b, V, out=b.offset) (C-contiguous after
    # from_arrays) wrote the dense positions over the binding's own offsets.
    V, cage, b = grid_loop
    Ve = cage.V.copy()
    Ve[[3, 9]] += [0.0, 0.0, 0.2]
    want = deform(b, Ve)
    arrays = b.to_arrays()
    b2 = type(b).from_arrays(arrays)
    for key in ("bary", "offset", "fine_detail", "V_cage_rest"):
        arrays[key][...] = 0.0
    assert np.array_equal(deform(b2, Ve), want)
    for key in ("bary", "offset"):
        with pytest.raises(InvalidArgumentError, match="read-only"):
            deform(b2, Ve, out=getattr(b2, key))
    assert np.array_equal(deform(b2, Ve), want)
    assert np.array_equal(type(b).from_arrays(b2.to_arrays()).offset, b.offset)
    # to_arrays still hands out writable copies
    assert all(a.flags.writeable for a in b2.to_arrays().values() if isinstance(a, np.ndarray))


@pytest.fixture(scope="module")
def sphere_loop():
    V, F = icosphere(3)
    V = V * (1.0 + 0.02 * np.sin(7 * V[:, :1]) * np.cos(5 * V[:, 1:2]))
    cage = simplify(V, F, target_faces=120)
    return V, cage, bind(V, F, cage.V, cage.F, levels=2, scheme="loop")


def test_one_vertex_dragged_a_million_sizes_away_leaves_the_rest(sphere_loop):
    # (41009d6's normal floor was taken from the edited cage's size: one vertex dragged
    # 1e6 away made it 1.0, every real normal of a unit cage fell under it, and every
    # row moved, 1.5e5 units on the cow; the floor is the rest cage's now)
    V, cage, b = sphere_loop
    D0 = deform(b, cage.V)
    for v in (0, 7, 20):
        Ve = cage.V.copy()
        Ve[v] += 1e6
        D = deform(b, Ve)
        keep = ~b.affected([v])
        keep[b.repaired(D)] = False
        assert keep.sum() > 0.2 * keep.size
        assert np.array_equal(D[keep], D0[keep])
        inc = deform(b, cage.V)
        deform(b, Ve, moved=[v], out=inc)
        assert np.abs(inc - D).max() <= 1e-12 * bbox_diagonal(D)


@pytest.mark.parametrize("key, value, match", [
    ("offset", lambda a: np.where(np.arange(a.size).reshape(a.shape) == 4, np.nan, a),
     "offset has NaN or infinite values"),
    ("bary", lambda a: np.where(np.arange(a.size).reshape(a.shape) == 0, np.inf, a),
     "bary has NaN or infinite values"),
    ("fine_detail", lambda a: a * np.nan, "fine_detail has NaN"),
    ("V_cage_rest", lambda a: a * np.nan, "V_cage_rest has NaN"),
    ("offset", lambda a: a * 1e300, "offset reaches"),
    ("offset", lambda a: a.ravel()[:-1], "offset must have 3 columns"),
    ("F_dense", lambda a: a[:, :2], "F_dense must have 3 columns"),
    ("creases", lambda a: np.array([0, 1, 2]), "creases must have 2 columns"),
    ("fine_face", lambda a: a + 0.5, "fine_face must be integer indices, got float64"),
    ("fine_face", lambda a: a > 0, "fine_face must be integer indices, got bool"),
    ("F_cage", lambda a: a.astype(float), "F_cage must be integer indices"),
    ("bary", lambda a: a.astype(complex), "bary must be real numbers, got complex128"),
    ("V_cage_rest", lambda a: "abc", "V_cage_rest must be real numbers"),
])
def test_from_arrays_names_broken_arrays(sphere_loop, key, value, match):
    # each was taken (a NaN offset deformed to NaN, a float index truncated, a 1e300
    # offset overflowed in the fold repair) or NumPy's ValueError / TypeError /
    # ComplexWarning; None creases are none
    V, cage, b = sphere_loop
    arrays = b.to_arrays()
    arrays[key] = value(arrays[key])
    with pytest.raises((InvalidArgumentError, InvalidMeshError), match=match):
        type(b).from_arrays(arrays)
    arrays = b.to_arrays()
    arrays["creases"] = None
    assert np.array_equal(deform(type(b).from_arrays(arrays), cage.V), deform(b, cage.V))


def test_dataclasses_replace_gives_a_binding_of_its_own_arrays(sphere_loop):
    # dataclasses.replace hands the cache and the operator over: replace(b, offset=0)
    # deformed with the old offsets, replace(b, levels=1) kept the level-2 operator
    # (its fingerprint unchanged, so nothing noticed)
    import dataclasses
    V, cage, b = sphere_loop
    flat = dataclasses.replace(b, offset=np.zeros_like(b.offset))
    D = deform(flat, cage.V)
    assert np.abs(D - deform(b, cage.V)).max() > 1e-3
    assert np.array_equal(D, deform(type(b).from_arrays(flat.to_arrays()), cage.V))
    with pytest.raises(TopologyMismatchError):
        dataclasses.replace(b, levels=1)
    same = dataclasses.replace(b)
    assert same._operator is b._operator and np.array_equal(deform(same, cage.V), deform(b, cage.V))


def test_a_cage_held_in_the_output_buffer():
    # deform(b, buf[:n], out=buf): the rows overwrote the cage before the fold repair
    # read it (which cage vertices moved, their rotations), and a deform that repairs
    # came out 0.1 of the size off (a rough torus); the cage is copied first now
    from tests.mesh_factory import torus
    from core.mesh import vertex_normals
    Vd, Fd = torus(96, 48, bump=0.01)
    Vd = Vd + 0.01 * np.random.default_rng(0).standard_normal(Vd.shape)
    cage = simplify(Vd, Fd, target_faces=200)
    b = bind(Vd, Fd, cage.V, cage.F, levels=2, scheme="butterfly")
    ring = np.unique(cage.F[(cage.F == 50).any(axis=1)])
    Ve = cage.V.copy()
    Ve[ring] += 0.05 * bbox_diagonal(Vd) * vertex_normals(cage.V, cage.F)[50]
    want = deform(b, Ve)
    assert b.repaired(want).size > 0
    n = Ve.shape[0]
    buf = np.zeros((b.n_dense, 3))
    buf[:n] = Ve
    assert np.array_equal(deform(b, buf[:n], out=buf), want)


@pytest.mark.parametrize("start", ["point", "tiny", "plane"])
def test_a_collapsed_cage_put_back_vertex_by_vertex_deforms_as_a_full_deform(sphere_loop, start):
    # The cage collapsed (to its centre, to a millionth, onto a plane) and its vertices
    # put back one at a time with incremental deforms: fine faces folded flat or tiny
    # next to full-size ones have normals made of rounding, and the incremental fine
    # positions (the stencil rows summed in another order than the apply plan's, 1e-16
    # apart) drew other normals than a full deform: up to 2.5% of the diagonal apart on
    # spot. Each moved row is now summed as the plan sums it, and the normal floor is the
    # rest cage's (it had followed the edited cage's size class): bit for bit.
    V, cage, b = sphere_loop
    Vc = cage.V
    Ve = {"point": np.zeros_like(Vc) + Vc.mean(axis=0), "tiny": Vc * 1e-6,
          "plane": Vc * [1.0, 1.0, 0.0]}[start]
    D = deform(b, Ve)
    for k, v in enumerate(np.random.default_rng(0).permutation(Vc.shape[0])):
        Ve[v] = Vc[v]
        deform(b, Ve, moved=[v], out=D)
        if k % 7 == 0:
            assert np.array_equal(D, deform(b, Ve)), k
    assert np.array_equal(D, deform(b, Vc))


@pytest.mark.parametrize("scheme", ["loop", "butterfly"])
def test_a_mirrored_cage_gives_the_mirrored_mesh_with_its_detail(scheme):
    """A cage mirrored as a whole (Edit Mode's Mirror of every vertex) keeps
    its faces' winding, so frames from it point inward: the detail came out
    inverted (bumps as dents, 4 bump heights off). Now the mirror of the mesh,
    full, incremental, back again and refined; a local edit of the mirrored
    cage deforms as it does unmirrored, mirrored."""
    from core.binding import refine
    from tests.mesh_factory import torus
    V, F = torus(60, 30, bump=0.02, bump_waves=(12, 6))
    cage = simplify(V, F, target_faces=300)
    b = bind(V, F, cage.V, cage.F, levels=2, scheme=scheme)
    M = np.diag([1.0, -1.0, 1.0])                       # (not the repair's own x -> -x)
    tol = 1e-12 * bbox_diagonal(V)
    D = deform(b, cage.V @ M)
    assert np.abs(D - V @ M).max() <= tol
    np.testing.assert_allclose(refine(b, cage.V @ M).V, refine(b, cage.V).V @ M, rtol=0, atol=tol)
    Ve = cage.V.copy()
    Ve[7] += 0.02 * bbox_diagonal(V) * np.array([0.3, -0.5, 0.8])
    plain = deform(b, Ve)
    D = deform(b, cage.V @ M)
    deform(b, Ve @ M, moved=[7], out=D)                 # an edit of the mirrored cage
    assert np.abs(D - plain @ M).max() <= tol
    assert np.abs(D - deform(b, Ve @ M)).max() <= tol
    back = D.copy()
    deform(b, Ve, moved=np.arange(cage.V.shape[0]), out=back)   # mirrored back, incrementally
    assert np.abs(back - plain).max() <= tol


def test_a_flat_cage_and_a_fold_through_are_not_mirrors():
    """Only a whole, well-conditioned mirror turns the detail back: a flat cage
    has no mirror that moves it, and an edit pushing part of a cage through
    the rest is an edit (the deform as before, not a flipped one)."""
    import core.binding as binding
    from tests.mesh_factory import torus
    V, F = grid(20, 20)
    cage = simplify(V, F, target_faces=50)                # flat: its mirror in z is itself
    bumpy = V + np.c_[np.zeros((V.shape[0], 2)), 0.01 * np.sin(7 * V[:, 0])]
    b = bind(bumpy, F, cage.V, cage.F, levels=1, scheme="loop")
    assert np.abs(cage.V[:, 2]).max() == 0.0
    assert binding._handedness(b, cage.V * [1.0, 1.0, -1.0]) == 1.0
    assert np.array_equal(deform(b, cage.V * [1.0, 1.0, -1.0]), deform(b, cage.V))
    Vt, Ft = torus(40, 20)
    ct = simplify(Vt, Ft, target_faces=200)
    bt = bind(Vt, Ft, ct.V, ct.F, levels=1, scheme="loop")
    pushed = ct.V.copy()
    top = np.argsort(-pushed[:, 2])[:8]
    pushed[top, 2] *= -3.0                              # 8 top vertices pushed through
    assert binding._handedness(bt, pushed) == 1.0
    assert binding._handedness(bt, ct.V * [-1.0, 1.0, 1.0]) == -1.0
    assert binding._handedness(bt, 2.5 * ct.V @ _rotation_z(0.7).T * [1, -1, 1] + 3.0) == -1.0


def _rotation_z(angle):
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _rotation(seed):
    """A random proper rotation (det +1), from ``seed``."""
    q, _ = np.linalg.qr(np.random.default_rng(seed).standard_normal((3, 3)))
    return q * np.sign(np.linalg.det(q))


@pytest.mark.parametrize("scheme", ["loop", "butterfly"])
def test_a_fin_of_the_cage_leaves_rigid_motions_exact(scheme):
    """A cage whose faces fold back onto each other (the rim of a lens 3e-4
    thick: a symmetric cage's seam, a thin flap) has fine vertex normals that
    are what is left of sums that cancel, which a rounding step of the rotated
    positions turns: rows 3e-11 of the diagonal off the rotated scan (1.4e-6
    on a symmetric cage of the jittered fandisk). Those vertices have no
    normal in the binding's frames: rigid motions within 1e-12 of the
    diagonal, the scan back, and the same frames for a binding restored from
    its arrays and for an incremental deform."""
    import core.binding as binding
    from core.binding import Binding
    from core.subdivide import subdivide
    from tests.mesh_factory import lens
    Vc, Fc = lens(12, 3e-4)
    Vd, Fd = lens(96, 4e-4, rings=24)
    Vd = Vd + 0.002 * np.sin(20 * Vd[:, :1]) * [0.0, 0.0, 1.0]
    b = bind(Vd, Fd, Vc, Fc, levels=2, scheme=scheme)
    fine = subdivide(Vc, Fc, levels=2, scheme=scheme).V
    rim = np.flatnonzero(np.abs(fine[:, 2]) < 1e-12)
    assert rim.shape[0] == 48                          # the rim, 12 x 4 fine vertices
    np.testing.assert_array_equal(np.flatnonzero(binding._rest_folds(b)), rim)
    diag = bbox_diagonal(Vd)
    assert np.abs(deform(b, Vc) - Vd).max() <= 1e-15 * diag
    for seed in range(6):
        Q, t = _rotation(seed), np.random.default_rng(seed).standard_normal(3)
        moved = deform(b, (Vc - 0.3) @ Q.T + t)
        assert np.abs(moved - ((Vd - 0.3) @ Q.T + t)).max() <= 1e-12 * diag, seed
    Ve = Vc.copy()
    Ve[[2, 5]] += [[0.05, 0.0, 0.01], [0.0, -0.03, 0.02]]   # two rim vertices
    restored = Binding.from_arrays(b.to_arrays())
    assert np.array_equal(deform(restored, Ve), deform(b, Ve))
    D = deform(b, Vc)
    deform(b, Ve, moved=[2, 5], out=D)
    assert np.array_equal(D, deform(restored, Ve))
