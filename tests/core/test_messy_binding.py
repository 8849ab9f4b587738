"""Bind, deform and refine on messy real-scan inputs and awkward cages.

What a scan brings (coincident corners, zero-area faces, meshes far from
the origin) must not cost the promises: no edit gives the original back,
a rigid motion of the cage moves everything rigidly, an incremental deform
equals the full one.
"""

import numpy as np
import pytest

from core.binding import bind, deform, frames, refine
from tests.mesh_factory import icosphere, noisy_sphere


def _rotation(seed, angle_deg=None):
    """A random rotation, or one by ``angle_deg`` about a random axis."""
    rng = np.random.default_rng(seed)
    if angle_deg is None:
        Q, _ = np.linalg.qr(rng.standard_normal((3, 3)))
        return Q * np.sign(np.linalg.det(Q))
    a = rng.standard_normal(3)
    a /= np.linalg.norm(a)
    K = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    t = np.radians(angle_deg)
    return np.eye(3) + np.sin(t) * K + (1 - np.cos(t)) * K @ K


@pytest.mark.parametrize("seed", range(4))
def test_frames_of_a_face_with_two_corners_at_one_point_turn_with_a_rotation(seed):
    # corners 0 and 1 one rounding step apart (a zero-area cage face subdivided): the
    # first edge is 1e-16 of noise whose direction a rotation changes at random; the
    # tangent must come from the second edge, which turns with the rotation
    p = np.array([0.3, -0.2, 0.7])
    Vf = np.array([p, np.nextafter(p, 2 * p), p + [0.01, 0.004, -0.002]])
    n = np.cross(Vf[2] - Vf[0], [0.0, 0.0, 1.0])
    Nf = np.tile(n / np.linalg.norm(n), (3, 1))
    corners, bary = np.array([[0, 1, 2]]), np.array([[0.2, 0.3, 0.5]])
    Q = _rotation(seed)
    t = np.array([1.0, -2.0, 0.5])
    fr = frames(Vf, Nf, corners, bary)
    fr2 = frames(Vf @ Q.T + t, Nf @ Q.T, corners, bary)
    for a, b in zip(fr[1:], fr2[1:]):
        assert np.abs(b - a @ Q.T).max() < 1e-12


def _diagonal(V):
    return float(np.linalg.norm(V.max(axis=0) - V.min(axis=0)))


@pytest.mark.parametrize("scheme", ["butterfly", "loop"])
@pytest.mark.parametrize("far", [1e5, 1e6])
def test_a_scan_far_from_the_origin_comes_back_unedited_to_1e12_of_its_size(scheme, far):
    # georeferenced scans sit 1e5-1e6 from the origin: the frames were built from
    # differences of coordinates rounded at 1e-11..1e-10, and the unedited cage gave
    # the scan back 4e-12 / 3e-11 of its size off
    Vd, Fd = noisy_sphere()
    Vc, Fc = icosphere(1)
    o = np.array([far, -0.7 * far, 0.3 * far])
    b = bind(Vd + o, Fd, 0.97 * Vc + o, Fc, levels=2, scheme=scheme)
    assert np.abs(deform(b, 0.97 * Vc + o) - (Vd + o)).max() <= 1e-12 * _diagonal(Vd)


def _ulps_off(A, B):
    return float(np.abs(A - B).max() / np.spacing(np.abs(B).max()))


@pytest.mark.parametrize("far", [0.0, 1e6])
def test_rigid_motions_of_a_real_scan_far_from_the_origin_are_exact_to_its_coordinates(far):
    # a scan at 1e6 (or a cage moved 1e3 of its size away): each frame's rounding at the
    # coordinates' size, times the offsets over a fine edge, moved the beetle's rotated
    # scan up to 150 rounding steps of its coordinates (2e-8 of its size) off the rotated
    # original; relative to a working origin it is a few, as the rotation's own rounding
    from tests.mesh_factory import load_shared
    from core.simplify import simplify
    V, F = load_shared("beetle.obj")
    V = V + far
    s = simplify(V, F, target_faces=120)
    b = bind(V, F, s.V, s.F, levels=3, scheme="butterfly", creases=s.feature_edges)
    D = deform(b, s.V)
    for seed, angle in ((0, 90.0), (1, 180.0), (2, 135.0)):
        Q = _rotation(seed, angle)
        t = np.array([1.0, -2.0, 0.5]) * (1e3 * _diagonal(V) if far == 0 else 1.0)
        Vc = s.V @ Q.T + t
        assert _ulps_off(deform(b, Vc), D @ Q.T + t) <= 8


def test_incremental_deform_of_a_real_scan_far_from_the_origin_equals_the_full_one():
    # at 1e6 each level's rows, summed in another order, differed by rounding steps of
    # 1e6, which the frames multiplied: 1.9e-8 of the beetle's size between the two
    from tests.mesh_factory import load_shared
    from core.simplify import simplify
    V, F = load_shared("beetle.obj")
    V = V + 1e6
    s = simplify(V, F, target_faces=120)
    b = bind(V, F, s.V, s.F, levels=3, scheme="butterfly", creases=s.feature_edges)
    rng = np.random.default_rng(0)
    Ve = s.V.copy()
    D = deform(b, Ve)
    for _ in range(5):
        ids = rng.integers(0, Ve.shape[0], 3)
        Ve[ids] += 0.02 * _diagonal(V) * rng.standard_normal((3, 3))
        deform(b, Ve, moved=ids, out=D)
        assert _ulps_off(D, deform(b, Ve)) <= 2


def test_ring_linear_maps_are_the_cage_motion_near_each_vertex():
    from core.unfold import CageRings, ring_linear_maps
    from tests.mesh_factory import torus
    V, F = torus(12, 6)
    rings = CageRings.of(F, V.shape[0])
    every = np.arange(V.shape[0])
    Q = _rotation(3, 120.0)
    assert np.abs(ring_linear_maps(V, V @ Q.T + 5.0, rings, every) - Q).max() < 1e-12
    assert np.abs(ring_linear_maps(V, 0.5 * V, rings, every) - 0.5 * np.eye(3)).max() < 1e-12
    # a squash: closer to it than the ring's rotation is (the normal term blends in)
    S = np.diag([1.0, 1.0, 0.2])
    A = ring_linear_maps(V, V @ S, rings, every)
    assert (np.abs(A - S).max(axis=(1, 2)) < np.abs(np.eye(3) - S).max()).all()
    # any edit, however wild (rings collapsed, turned inside out), gives maps that keep
    # the orientation: the fallback, the ring's rotation times its stretch
    rng = np.random.default_rng(0)
    for W in (V + 0.5 * rng.standard_normal(V.shape), V * [1.0, 1.0, 0.0], -V):
        A = ring_linear_maps(V, W, rings, every)
        assert np.isfinite(A).all() and (np.linalg.det(A) > 0).all()


@pytest.mark.parametrize("factor", [0.5, 0.75])
@pytest.mark.parametrize("levels", [1, 2])
def test_a_cage_scaled_down_folds_no_face_of_the_scan(factor, levels):
    # the detail keeps its size when the cage shrinks, so thin parts (the cow's legs and
    # ears) turned faces over; the fold repair relaxed them to their rest shape at full
    # size between neighbours at half size, and 141-149 faces stayed turned over (the
    # cage itself folds nowhere); the rest shape is now scaled as the cage is there
    from tests.mesh_factory import load_shared
    from core.mesh import turned_faces
    from core.simplify import simplify
    V, F = load_shared("cow.obj")
    s = simplify(V, F, target_faces=200)
    b = bind(V, F, s.V, s.F, levels=levels, scheme="butterfly")
    c = 0.5 * (s.V.min(axis=0) + s.V.max(axis=0))
    Ve = c + factor * (s.V - c)
    assert turned_faces(s.V, Ve, s.F).size == 0
    D = deform(b, Ve)
    assert turned_faces(V, D, F).size == 0


@pytest.mark.parametrize("mess", ["unwelded", "far speck"])
def test_the_local_detail_search_looks_on_the_cleaned_scan(mess):
    # the local search (detail_search="auto" above 100k faces) looked on the scan as it
    # came: an unwelded scan's vertex had a fan of one triangle (70% of the fine vertices
    # refined off the scan's closest point), and a far speck bound near the cage was the
    # nearest bound vertex of some fine vertices (refined 1.7e3 diagonals away)
    from tests.mesh_factory import unwelded, with_far_speck
    Vd, Fd = noisy_sphere()
    Vd, Fd = unwelded(Vd, Fd) if mess == "unwelded" else with_far_speck(Vd, Fd)
    Vc, Fc = icosphere(1)
    Vc = 0.97 * Vc
    exact = refine(bind(Vd, Fd, Vc, Fc, levels=3, detail_search="exact"), Vc).V
    local = refine(bind(Vd, Fd, Vc, Fc, levels=3, detail_search="local"), Vc).V
    off = np.linalg.norm(local - exact, axis=1)
    assert off.max() < 0.05 * _diagonal(Vc)
    assert np.count_nonzero(off > 1e-9) <= 0.01 * off.shape[0]


def _unwelded_torus_case():
    """A rough torus as an unwelded scan (every triangle on vertices of its own), its
    200-face cage and a cage lift that makes the fold repair work: (Vd, Fd, key, cage,
    b, ids, lift), ``key[i]`` the welded vertex unwelded vertex ``i`` sits on."""
    from core.simplify import simplify
    from core.mesh import vertex_normals
    from tests.mesh_factory import torus, unwelded
    V, F = torus(96, 48, bump=0.01)
    V = V + 0.01 * np.random.default_rng(0).standard_normal(V.shape)
    Vd, Fd = unwelded(V, F)
    cage = simplify(Vd, Fd, target_faces=200)
    b = bind(Vd, Fd, cage.V, cage.F, levels=2, scheme="butterfly")
    ids = np.unique(cage.F[(cage.F == 50).any(axis=1)])
    lift = 0.08 * _diagonal(V) * vertex_normals(cage.V, cage.F)[50]
    return Vd, Fd, F.ravel(), cage, b, ids, lift


def _crack(D, key):
    """The largest distance between copies of one scan vertex."""
    hi = np.full((key.max() + 1, 3), -np.inf)
    lo = np.full((key.max() + 1, 3), np.inf)
    np.maximum.at(hi, key, D)
    np.minimum.at(lo, key, D)
    return float(np.abs(hi - lo).max())


def test_the_fold_repair_keeps_an_unwelded_scan_closed():
    # every triangle of an STL scan has vertices of its own: the repair relaxed the
    # triangles one by one (no neighbours across them) and opened cracks of 1-45% of the
    # size; now it relaxes the welded scan and every copy follows its vertex
    Vd, Fd, key, cage, b, ids, lift = _unwelded_torus_case()
    Ve = cage.V.copy()
    Ve[ids] += lift
    D = deform(b, Ve)
    assert b.repaired(D).size > 0
    assert _crack(D, key) == 0.0
    # and through incremental deforms, equal to the full ones
    rng = np.random.default_rng(5)
    cur = cage.V.copy()
    D = deform(b, cur)
    for _ in range(4):
        some = rng.choice(ids, rng.integers(1, ids.size + 1), replace=False)
        cur[some] = cage.V[some] + rng.uniform(0.5, 1.0) * lift
        deform(b, cur, moved=some, out=D)
        full = deform(b, cur)
        assert np.abs(D - full).max() <= 1e-12 * _diagonal(Vd)
        assert np.array_equal(b.repaired(D), b.repaired(full))
        assert _crack(D, key) == 0.0


@pytest.mark.parametrize("step", ["bind", "fit_cage"])
def test_bad_meshes_are_refused_naming_the_argument(step):
    # bind and fit_cage take two meshes: "V must be (n,3) floats", "the mesh has no
    # faces" and "subdivision_operator: 3 non-manifold edges" named neither which mesh
    # nor the function the user called
    from core import InvalidArgumentError, InvalidMeshError, fit_cage
    call = bind if step == "bind" else fit_cage
    Vd, Fd = noisy_sphere(2)
    Vc, Fc = icosphere(1)
    cases = [
        ((Vd[:, :2], Fd, Vc, Fc), InvalidMeshError, f"{step}: V_dense must be"),
        ((Vd, Fd.astype(float), Vc, Fc), InvalidMeshError, f"{step}: F_dense must be"),
        ((Vd, Fd, Vc.astype(complex), Fc), InvalidMeshError, f"{step}: V_cage must be"),
        ((Vd, Fd, Vc, Fc[:0]), InvalidMeshError, f"{step}: F_cage has no faces"),
        ((Vd, Fd + 1000, Vc, Fc), InvalidMeshError, f"{step}: 320 faces of F_dense index"),
        ((Vd, Fd, np.where(np.arange(42)[:, None] == 3, np.nan, Vc), Fc), InvalidMeshError,
         f"{step}: 1 vertices of V_cage have NaN"),
        ((Vd, Fd, Vc, np.vstack([Fc, Fc[:1]])), InvalidMeshError,
         rf"{step}: the cage \(F_cage\): 3 non-manifold edges"),
        ((Vd, Fd, Vc, np.vstack([Fc[:1, ::-1], Fc[1:]])), InvalidMeshError,
         rf"{step}: the cage \(F_cage\): faces are not consistently oriented"),
    ]
    for args, error, match in cases:
        with pytest.raises(error, match=match):
            call(*args, levels=1)
    with pytest.raises(InvalidArgumentError, match=rf"{step}: the cage \(F_cage\): creases must"):
        call(Vd, Fd, Vc, Fc, levels=1, creases=[[0, 41]])


def test_an_unsigned_moved_index_beyond_int64_is_named_as_given():
    Vd, Fd = noisy_sphere(2)
    Vc, Fc = icosphere(1)
    b = bind(Vd, Fd, Vc, Fc, levels=1)
    D = deform(b, Vc)
    from core import InvalidArgumentError
    with pytest.raises(InvalidArgumentError, match="moved index 9223372036854775813 is out of"):
        deform(b, Vc, moved=np.array([2**63 + 5], dtype=np.uint64), out=D)


def test_an_edit_of_a_scan_far_from_the_origin_changes_no_row_it_does_not_reach():
    # the working origin followed the edited cage's box: a vertex pulled past the box
    # moved it, and every row of a scan 1e5-1e6 from the origin changed in its last bit,
    # also those the edit does not reach (Binding.affected); it stays the rest cage's
    Vd, Fd = noisy_sphere()
    Vc, Fc = icosphere(1)
    Vc = 0.97 * Vc
    for far in (1e5 + 0.3, 1e6 + 0.7):
        o = np.array([far, -far / 3, 0.0])
        b = bind(Vd + o, Fd, Vc + o, Fc, levels=2)
        D0 = deform(b, Vc + o)
        for i in (0, 5, 17):
            for amount in (0.05, 0.3, 1.0):
                Ve = Vc + o
                Ve[i] += amount * Vc[i] / np.linalg.norm(Vc[i])
                away = ~b.affected([i])
                assert np.array_equal(deform(b, Ve)[away], D0[away])


def test_bind_of_a_single_dense_point_leaves_it_as_it_was():
    # a block of one row: its transpose was a contiguous view of V_dense, and the
    # offsets were computed in place in the caller's array
    Vc, Fc = icosphere(1)
    Vd = np.array([[0.1, 0.2, 0.3]])
    b = bind(Vd, np.zeros((0, 3), np.int64), Vc, Fc, levels=1)
    assert Vd.tolist() == [[0.1, 0.2, 0.3]]
    assert np.abs(deform(b, Vc) - Vd).max() < 1e-15


@pytest.mark.parametrize("shape", [(3, 1), (3, 3)])
def test_the_operator_at_level_zero_returns_new_arrays(shape):
    # for one column (or one vertex) both transposes were views: apply and its adjoint
    # returned the caller's array itself, and writing the result wrote the input
    from core.subdivide import subdivision_operator
    op = subdivision_operator([[0, 1, 2]], 3, levels=0)
    X = np.arange(float(np.prod(shape))).reshape(shape)
    for Y in (op.apply(X), op.apply_transpose(X)):
        assert np.array_equal(Y, X) and not np.shares_memory(X, Y)


def test_a_large_welded_scan_is_searched_as_it_is(monkeypatch):
    # cleaning a welded 2M-face scan for the local search was 60% of its bind: a welded scan
    # above the cleaning limit (with a far speck, which the search keeps off) is not
    # cleaned, and its refine detail is the exact search's but for the few fine vertices
    # whose closest triangle lies beyond their nearest bound vertex's two-ring
    import core.binding as binding
    from core.detail_search import is_unwelded
    from tests.mesh_factory import unwelded, with_far_speck
    Vd, Fd = with_far_speck(*noisy_sphere())
    assert not is_unwelded(Fd, Vd.shape[0]) and is_unwelded(unwelded(Vd, Fd)[1], 3 * Fd.shape[0])
    Vc, Fc = icosphere(1)
    Vc = 0.97 * Vc
    exact = refine(bind(Vd, Fd, Vc, Fc, levels=3, detail_search="exact"), Vc).V
    monkeypatch.setattr(binding, "_CLEAN_LOCAL_FACES", Fd.shape[0] - 1)
    monkeypatch.setattr(binding, "detail_surface", lambda *a: pytest.fail("cleaned"))
    local = refine(bind(Vd, Fd, Vc, Fc, levels=3, detail_search="local"), Vc).V
    off = np.linalg.norm(local - exact, axis=1)
    assert off.max() < 0.05 * _diagonal(Vc)
    assert np.count_nonzero(off > 1e-9) <= 0.01 * off.shape[0]


def test_the_local_search_looks_on_the_cleaned_scan_up_to_its_limit(monkeypatch):
    # "auto" takes the local search above 100k faces: up to the cleaning limit it looks on
    # the cleaned scan, where specks of debris on the surface are not the nearest bound
    # vertices the detail is searched from, and it refines as the exact search does but
    # for the few fine vertices whose closest triangle lies beyond their two-ring
    import core.binding as binding
    from tests.mesh_factory import with_debris
    Vd, Fd = with_debris(*noisy_sphere())
    Vc, Fc = icosphere(1)
    Vc = 0.97 * Vc
    exact = refine(bind(Vd, Fd, Vc, Fc, levels=3, detail_search="exact"), Vc).V
    cleaned = []
    real = binding.detail_surface
    monkeypatch.setattr(binding, "detail_surface", lambda *a: cleaned.append(1) or real(*a))
    monkeypatch.setattr(binding, "_EXACT_DETAIL_FACES", Fd.shape[0] - 1)
    auto = refine(bind(Vd, Fd, Vc, Fc, levels=3), Vc).V
    assert cleaned
    off = np.linalg.norm(auto - exact, axis=1)
    assert off.max() < 0.05 * _diagonal(Vc)
    assert np.count_nonzero(off > 1e-9) <= 0.01 * off.shape[0]


def test_a_halo_of_specks_does_not_set_the_binds_reach(monkeypatch):
    # 4,000 specks 1e-5 of the size around a sphere are most of the scan's vertices and
    # faces: their median distance to the cage's surface set the query's cells (a share
    # of the object), and a bind at three levels took 3.8 s where it takes 0.07 s
    # without them. The typical distance is now weighted by face area: the sphere's
    import core.binding as binding
    from core import simplify
    V0, F0 = icosphere(4)
    rng = np.random.default_rng(30)
    k = 4000
    T = rng.uniform(-1.6, 1.6, (k, 1, 3)) + rng.normal(scale=3.5e-5, size=(k, 3, 3))
    V = np.vstack([V0, T.reshape(-1, 3)])
    F = np.vstack([F0, V0.shape[0] + np.arange(3 * k).reshape(-1, 3)])
    cage = simplify(V0, F0, target_faces=50)
    origin = binding._working_origin(cage.V)

    def typical(Vd, Fd):
        return binding._typical_distance(Vd, Fd, cage.V, cage.F, "loop", None, origin)

    plain, halo = typical(V0, F0), typical(V, F)
    assert 0 < plain < 0.2
    assert halo == pytest.approx(plain, rel=0.25)
    specks = typical(T.reshape(-1, 3), np.arange(3 * k).reshape(-1, 3))
    assert specks > 5 * plain             # what the unweighted median gave
    # a point cloud (no faces): the vertices' plain median
    assert typical(V0, np.zeros((0, 3), dtype=np.int64)) > 0
    # and the bind's answers do not depend on the reach: the same faces with it or without,
    # the same offsets to rounding (a speck far from the surface goes to the index either way)
    b3 = bind(V, F, cage.V, cage.F, levels=3, scheme="loop")
    monkeypatch.setattr(binding, "_REACH_LEVELS", 3)              # no reach at three levels
    without = bind(V, F, cage.V, cage.F, levels=3, scheme="loop")
    assert np.array_equal(b3.fine_face, without.fine_face)
    assert np.abs(b3.offset - without.offset).max() <= 1e-12
    assert np.abs(b3.bary - without.bary).max() <= 1e-12
