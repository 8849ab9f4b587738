"""core.symmetry: mirror-symmetric cages (simplify(..., symmetry=...)) and the
symmetric fit (fit_cage(..., symmetry=...))."""

import numpy as np
import pytest

from core import (InvalidArgumentError, bind, bbox_diagonal, deform, euler_characteristic,
                  fit_cage, manifold_report, simplify, surface_distance)
from core.clean import clean_mesh
from core.mirror import AXES, mirror, mirror_partners, symmetrize
from core.symmetry import simplify_symmetric
from core.simplify import ASYMMETRY_NOTE
from tests.mesh_factory import cube, icosphere, load_shared, regular_grid, torus


# ---------------------------------------------------------------- meshes
def bumpy_sphere(k=4):
    """A sphere with bumps that are even in x, y and z (symmetric about every plane)."""
    V, F = icosphere(k)
    r = 1.0 + 0.06 * np.cos(5 * V[:, 0]) * np.cos(4 * V[:, 1]) + 0.04 * np.cos(6 * V[:, 2])
    return V * r[:, None], F


def open_sheet():
    """A wavy open grid centred on x = 0, even in x: its border crosses the X plane."""
    V, F = regular_grid(24, 16, z=lambda x, y: 0.08 * np.cos(9 * (x - 0.5)) * np.sin(7 * y))
    return V - [0.5, 0.5, 0.0], F


def jittered(V, F, axis="X", amount=0.004, seed=0):
    """A nearly symmetric scan: the negative side moved about a little."""
    k = AXES[axis]
    rng = np.random.default_rng(seed)
    W = V.copy()
    neg = W[:, k] < -1e-9
    W[neg] += amount * bbox_diagonal(V) * rng.standard_normal((int(neg.sum()), 3))
    W[neg, (k + 1) % 3] *= 1.01
    return W, F


def centred(V, axis):
    k = AXES[axis]
    V = V.copy()
    V[:, k] -= 0.5 * (V[:, k].min() + V[:, k].max())
    return V


# ---------------------------------------------------------------- checks
def assert_symmetric(V, F, axis):
    """Every vertex has an exact mirror partner, plane vertices have coordinate
    exactly 0.0, and every face has its mirror face (reversed orientation)."""
    k = AXES[axis]
    p = mirror_partners(V, axis, tolerance=1e-6)
    assert np.array_equal(mirror(V, k)[p], V) or np.abs(mirror(V, k)[p] - V).max() <= 1e-6 * bbox_diagonal(V)
    assert np.array_equal(mirror(V, k)[p], V)                        # exactly, in fact
    on = p == np.arange(V.shape[0])
    assert np.all(V[on, k] == 0.0)
    n = np.int64(V.shape[0])

    def directed(F):
        h = F[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
        return np.sort(h[:, 0] * n + h[:, 1])

    # the mirror of face (a, b, c) is (p[a], p[c], p[b]): same directed edges as the faces
    assert np.array_equal(directed(F), directed(p[F][:, [0, 2, 1]]))
    return p


def assert_clean(r, V_in, F_in):
    rep = manifold_report(r.F, r.V.shape[0])
    assert rep.is_oriented_manifold, rep
    assert np.array_equal(np.unique(r.F), np.arange(r.V.shape[0]))
    used = np.flatnonzero(clean_mesh(V_in, F_in).input_to_clean >= 0)   # what cleaning keeps
    assert r.vertex_map.shape == (V_in.shape[0],)
    assert np.all((r.vertex_map[used] >= 0) & (r.vertex_map[used] < r.V.shape[0]))
    assert r.face_map.shape == (r.F.shape[0],)
    assert np.all((r.face_map >= 0) & (r.face_map < F_in.shape[0]))


def hausdorff(V, F, r):
    return surface_distance(V, F, r.V, r.F).hausdorff


# ---------------------------------------------------------------- the cage
@pytest.mark.parametrize("axis", ["X", "Y", "Z"])
def test_bumpy_sphere_cage_is_symmetric_manifold_with_the_same_euler(axis):
    V, F = bumpy_sphere()
    r0 = simplify(V, F, target_faces=400)
    r = simplify(V, F, target_faces=400, symmetry=axis)
    assert_symmetric(r.V, r.F, axis)
    assert_clean(r, V, F)
    assert euler_characteristic(r.F) == euler_characteristic(r0.F) == 2
    assert 0.95 * 400 <= r.F.shape[0] <= 400 and r.stopped_because == "target"
    assert r.n_components == 1 and r.n_boundary_loops == 0


@pytest.mark.parametrize("target", [4, 5])
@pytest.mark.parametrize("axis", ["X", "Y", "Z"])
def test_a_target_below_the_smallest_symmetric_cage_stops_there_and_says_so(axis, target):
    """Half of 4 or 5 faces is a half cage of one or two triangles on the
    seam, which the mirroring drops: it gave an empty cage (and an
    IndexError). Now the half keeps enough to mirror: the smallest
    symmetric cage, a clean manifold, stopped at its floor."""
    V, F = bumpy_sphere(3)
    r = simplify(V, F, target_faces=target, symmetry=axis)
    assert_symmetric(r.V, r.F, axis)
    assert_clean(r, V, F)
    assert euler_characteristic(r.F) == 2 and target < r.F.shape[0] <= 16
    assert r.stopped_because == "topology_floor"
    assert r.message.startswith(f"stopped at {r.F.shape[0]} faces of {target} asked")


@pytest.mark.parametrize("axis", ["X", "Z"])
def test_a_small_target_is_met_within_a_few_faces_not_undershot(axis):
    """The mirrored cage jumps by more than twice the half's faces (its seam):
    spot to 36 faces in X gave 30 (half targets 18 and 16 made 40 and 30
    faces) and said "target". A cage ``UNDER_SLACK`` or more under (and
    ``UNDER_SHARE`` of the target) asks the half for a few more faces, and
    the closest cage within the target wins: 36 here (a half of 17)."""
    from core.simplify import UNDER_SHARE, UNDER_SLACK
    V, F = load_shared("spot.obj")[:2]
    V = V - 0.5 * (V.min(axis=0) + V.max(axis=0))
    for target in (8, 12, 16, 20, 24, 30, 36, 40, 50, 64, 100):
        r = simplify(V, F, target_faces=target, symmetry=axis)
        assert_symmetric(r.V, r.F, axis)
        assert r.stopped_because == "target" and r.F.shape[0] <= target
        assert target - r.F.shape[0] < max(UNDER_SLACK, UNDER_SHARE * target), target
        if (axis, target) == ("X", 36):
            assert r.F.shape[0] == 36
        assert r.message.split("; ")[0] == f"{F.shape[0]:,} → {r.F.shape[0]:,} faces"
    if axis == "X":        # 34 asked: 30 or 36 (none between), and the message says so
        r = simplify(V, F, target_faces=34, symmetry=axis)
        assert r.F.shape[0] == 30 and r.stopped_because == "target"
        assert r.message.split("; ")[0] == (f"{F.shape[0]:,} → 30 faces (of 34 asked: a mirrored "
                                            f"cage comes in steps of its seam's faces)")


def test_a_lock_whose_mirror_image_lands_on_the_seam_is_held_beside_it():
    """Locks on the cow's negative side near its plane (Z): one whose mirror
    image's nearest half vertex is on the seam (which is never locked) had
    been dropped, its vertex moved 8.6% of the diagonal and its cage vertex
    not marked; it is held by the nearest corner off the seam, as far from
    it as the cow's two sides are apart (1.9%) and a face."""
    V, F = load_shared("cow.obj")[:2]
    d = bbox_diagonal(V)
    near = np.flatnonzero((V[:, 2] < 0) & (V[:, 2] > -0.15 * d))
    locked = np.zeros(V.shape[0], dtype=bool)
    locked[np.random.default_rng(1).choice(near, 30, replace=False)] = True
    r = simplify(V, F, target_faces=300, symmetry="Z", locked=locked)
    assert_symmetric(r.V, r.F, "Z")
    idx = np.flatnonzero(locked)
    assert r.locked[r.vertex_map[idx]].all()
    assert np.linalg.norm(r.V[r.vertex_map[idx]] - V[idx], axis=1).max() < 0.03 * d


def test_the_half_targets_tried_skip_the_ones_made_already():
    """The mirrored count does not grow with the half's target (suzanne's
    half asked for 19, 18, 17 and 20 faces: 40, 40, 32 and 38 mirrored): a
    next try already made steps past it instead of ending the search, so 38
    asked comes back at 38, not 32 with a note that no closer cage exists;
    the cow in Z, 60 asked: 58, not 56."""
    for name, axis, centre, target, expected in (("suzanne.obj", "X", 0, 38, 38),
                                                 ("cow.obj", "Z", None, 60, 58)):
        V, F = load_shared(name)[:2]
        if centre is not None:
            V = V.copy()
            V[:, centre] -= 0.5 * (V[:, centre].min() + V[:, centre].max())
        r = simplify(V, F, target_faces=target, symmetry=axis)
        assert_symmetric(r.V, r.F, axis)
        assert r.F.shape[0] == expected and "asked" not in r.message.split("; ")[0]


@pytest.mark.parametrize("axis", ["X", "Z"])
def test_torus_keeps_genus_and_symmetry(axis):
    V, F = torus(48, 24, bump=0.02)
    r = simplify(V, F, target_faces=300, symmetry=axis)
    assert_symmetric(r.V, r.F, axis)
    assert_clean(r, V, F)
    assert euler_characteristic(r.F) == euler_characteristic(simplify(V, F, target_faces=300).F) == 0
    assert 285 <= r.F.shape[0] <= 300


def test_border_crossing_the_plane():
    V, F = open_sheet()
    r0 = simplify(V, F, target_faces=150)
    r = simplify(V, F, target_faces=150, symmetry="X")
    assert_symmetric(r.V, r.F, "X")
    assert_clean(r, V, F)
    assert r.n_boundary_loops == r0.n_boundary_loops == 1
    assert euler_characteristic(r.F) == euler_characteristic(r0.F) == 1
    assert 140 <= r.F.shape[0] <= 150


def test_seam_never_pinches_when_the_plane_cuts_a_wavy_sheet_many_times():
    # the sheet crosses z = 0 along several curves: seams that end on the border,
    # and collapses that join two seam vertices by an inside edge (split before mirroring)
    V, F = regular_grid(20, 20, z=lambda x, y: 0.1 * np.sin(6 * x) * np.cos(5 * y))
    V = V - [0.5, 0.5, 0.0]
    for target in (50, 400):
        r = simplify(V, F, target_faces=target, symmetry="Z")
        assert_symmetric(r.V, r.F, "Z")
        assert manifold_report(r.F, r.V.shape[0]).is_oriented_manifold


def test_a_component_that_barely_crosses_the_plane_keeps_the_target():
    # its positive side is a thin cap whose border is all seam: collapses join seam vertices
    # by inside edges, which are flipped or split before mirroring, and the half then asked
    # for fewer faces, so the target still holds
    B, Fb = icosphere(3)
    S, Fs = icosphere(3, radius=0.3)
    V = np.vstack([B, S + [-0.27, 3.0, 0.0]])
    F = np.vstack([Fb, Fs + B.shape[0]])
    r = simplify(V, F, target_faces=300, symmetry="X")
    assert_symmetric(r.V, r.F, "X")
    assert_clean(r, V, F)
    assert 285 <= r.F.shape[0] <= 300 and r.n_components == 2


def test_several_components_on_both_sides():
    S, Fs = icosphere(3, radius=0.4)
    V = np.vstack([S + [0.6, 0.0, 0.0], S - [0.6, 0.0, 0.0], bumpy_sphere(3)[0] * 0.3])
    F = np.vstack([Fs, Fs + S.shape[0], bumpy_sphere(3)[1] + 2 * S.shape[0]])
    r = simplify(V, F, target_faces=300, symmetry="X")
    assert_symmetric(r.V, r.F, "X")
    assert_clean(r, V, F)
    assert r.n_components == 3
    # the spheres on the negative side map to the mirrored cage sphere
    neg = V[:, 0] < -0.3
    assert np.all(r.V[r.vertex_map[neg], 0] < 0)


def test_nearly_symmetric_scan_still_gives_a_symmetric_cage():
    V, F = jittered(*bumpy_sphere())
    r = simplify(V, F, target_faces=400, symmetry="X")
    assert_symmetric(r.V, r.F, "X")
    assert_clean(r, V, F)
    assert euler_characteristic(r.F) == 2



def test_an_input_off_its_mirror_plane_is_named_in_the_message():
    # a box [-0.3, 0.7] x [-0.5, 0.5]^2: its positive side reaches 0.4 beyond the mirrored
    # negative one (the end caps at 0.7 and 0.3). Scans seldom sit on their mirror plane:
    # the bunny made symmetric in X came back 35.8% off with nothing said
    V, F = cube(4)
    r = simplify(V + [0.2, 0.0, 0.0], F, target_faces=200, symmetry="X")
    assert_symmetric(r.V, r.F, "X")
    assert r.asymmetry == pytest.approx(0.4 / np.sqrt(3.0), rel=1e-9)
    assert r.asymmetry_note in r.message and "differ by up to 23.1% of its size" in r.message
    for V, F in (bumpy_sphere(), jittered(*bumpy_sphere())):      # symmetric, nearly so
        r = simplify(V, F, target_faces=200, symmetry="X")
        assert r.asymmetry < ASYMMETRY_NOTE and r.asymmetry_note == ""
        assert "mirror-symmetric" not in r.message
    assert simplify(V, F, target_faces=200).asymmetry is None      # no symmetry asked


def test_a_cow_is_named_asymmetric_in_x_not_in_z():
    V, F = load_shared("cow.obj")
    rx, rz = (simplify(V, F, target_faces=400, symmetry=axis) for axis in ("X", "Z"))
    assert rx.asymmetry > 0.15 and "not mirror-symmetric" in rx.message
    assert rz.asymmetry < 0.02 and rz.asymmetry_note == ""

def error_ratios(cases):
    """(Hausdorff, mean) distance of the symmetric cage over the plain one, per case."""
    out = []
    for V, F, axis, target in cases:
        r0 = simplify(V, F, target_faces=target)
        r = simplify(V, F, target_faces=target, symmetry=axis)
        assert_symmetric(r.V, r.F, axis)
        d0, d1 = surface_distance(V, F, r0.V, r0.F), surface_distance(V, F, r.V, r.F)
        out.append((d1.hausdorff / d0.hausdorff, d1.mean / d0.mean))
    return np.array(out)


def assert_within_a_quarter(ratios):
    # the mean distance case by case; the Hausdorff distance (one worst point, which
    # moves with every change of the engine) over the cases, and never far over
    assert np.all(ratios[:, 1] <= 1.25), ratios
    assert np.exp(np.log(ratios[:, 0]).mean()) <= 1.25 and np.all(ratios[:, 0] <= 1.5), ratios


def test_error_within_a_quarter_of_the_plain_cage():
    V, F = bumpy_sphere()
    assert_within_a_quarter(error_ratios([(V, F, "X", t) for t in (200, 400, 600)]))


def test_shared_meshes_error_within_a_quarter_of_the_plain_cage():
    cases = []
    for name, axis, targets in (("suzanne.obj", "X", (150, 300)), ("spot.obj", "X", (300, 600, 1200))):
        V, F = load_shared(name)
        cases += [(centred(V, axis), F, axis, t) for t in targets]
    assert_within_a_quarter(error_ratios(cases))


def test_shared_meshes_cages_are_symmetric_manifolds_with_the_plain_euler():
    for name, axis, target in (("suzanne.obj", "X", 300), ("spot.obj", "X", 400),
                               ("cow.obj", "Z", 600)):
        V, F = load_shared(name)
        V = centred(V, axis)
        r = simplify(V, F, target_faces=target, symmetry=axis)
        assert_symmetric(r.V, r.F, axis)
        assert_clean(r, V, F)
        assert euler_characteristic(r.F) == euler_characteristic(simplify(V, F, target_faces=target).F)


def test_ratio_and_max_error():
    V, F = bumpy_sphere()
    r = simplify(V, F, ratio=0.05, symmetry="Y")
    assert_symmetric(r.V, r.F, "Y")
    assert r.target == round(0.05 * F.shape[0]) and 0.95 * r.target <= r.F.shape[0] <= r.target
    bound = 0.01 * bbox_diagonal(V)
    r = simplify(V, F, max_error=bound, symmetry="X")
    assert_symmetric(r.V, r.F, "X")
    assert r.hausdorff is not None and r.hausdorff <= bound
    assert hausdorff(V, F, r) <= bound and r.F.shape[0] < F.shape[0] / 4
    assert r.bound == bound and not r.bound_note
    assert set(r.seconds) >= {"clean", "symmetry", "total"}     # (was None with symmetry)
    assert r.seconds["total"] >= sum(v for k, v in r.seconds.items() if k != "total") - 1e-9


@pytest.mark.parametrize("share", [0.33, 0.45])
def test_a_bound_so_large_the_half_mirrors_to_nothing_takes_a_lower_share(share):
    """At a third of its size or more, the bound took an icosphere's half to
    lone triangles on the seam, which the mirroring drops, and the empty cage
    was measured: 'surface_distance (mesh b): the mesh has no faces' (the
    add-on's Max error of 40% with Symmetry). A lower share is taken while
    the mirrored cage is empty: a closed symmetric cage within the bound."""
    V, F = icosphere(4)
    bound = share * bbox_diagonal(V)
    r = simplify(V, F, max_error=bound, symmetry="X")
    assert r.F.shape[0] >= 4 and r.n_components == 1 and r.n_boundary_loops == 0
    assert_symmetric(r.V, r.F, "X")
    assert 0 < r.hausdorff <= bound and hausdorff(V, F, r) <= bound


def test_a_bound_the_symmetric_cage_misses_is_said(monkeypatch):
    """An icosphere with one-face holes on its positive side only: every vertex
    has its mirror image (the vertex asymmetry is 0), the faces differ; with a
    tight ``max_error`` the symmetric cage (the positive side mirrored: holed on
    both) lies 12x the bound off the input, and was said to be stopped by the
    bound, no note."""
    V, F = icosphere(3)
    centres = V[F].mean(axis=1)
    F = np.delete(F, np.flatnonzero(centres[:, 0] > 0.3)[::40], axis=0)
    bound = 1e-3 * bbox_diagonal(V)
    plain = simplify(V, F, max_error=bound)
    assert plain.hausdorff <= bound and not plain.bound_note
    from core import symmetry
    runs = []
    monkeypatch.setattr(symmetry, "simplify",
                        lambda *a, **k: runs.append(k["max_error"]) or simplify(*a, **k))
    r = simplify(V, F, max_error=bound, symmetry="X")
    assert r.asymmetry < 1e-12 and r.hausdorff > 5 * bound
    # the first half's cage said no lower share of the bound could meet it: one run, not
    # one per share (300 spheres scattered on both sides: 10.4 -> 4.0 s)
    assert runs == [symmetry.MAX_ERROR_SHARES[0] * bound]
    assert r.bound_note.startswith(f"it lies {r.hausdorff / bound:.1f}x the error bound off the "
                                   f"input") and "turn symmetry off" in r.bound_note
    assert r.bound_note in r.message


def test_a_bound_of_zero():
    """``max_error=0``: a mirrored cage of a symmetric icosphere lies a rounding
    step off it (2.2e-16), which is within the bound (its note had divided by
    the bound); the holed one is far off, and said to be, without a ratio."""
    V, F = icosphere(3)
    r = simplify(V, F, max_error=0.0, symmetry="X")
    assert_symmetric(r.V, r.F, "X")
    assert r.bound == 0.0 and 0.0 <= r.hausdorff <= 1e-12 * bbox_diagonal(V)
    assert r.bound_note == "" and "bound" in r.message
    centres = V[F].mean(axis=1)
    F = np.delete(F, np.flatnonzero(centres[:, 0] > 0.3)[::40], axis=0)
    r = simplify(V, F, max_error=0.0, symmetry="X")
    assert r.hausdorff > 1e-3 * bbox_diagonal(V)
    assert r.bound_note.startswith("it lies beyond the error bound off the input (Hausdorff "
                                   f"distance {r.hausdorff:.4g} against the 0 asked)")
    assert r.bound_note in r.message


def test_cancel_returns_the_cleaned_input_and_inputs_are_not_modified():
    V, F = bumpy_sphere(3)
    V0, F0 = V.copy(), F.copy()
    r = simplify(V, F, target_faces=100, symmetry="X", progress=lambda f: False)
    assert r.stopped_because == "cancelled"
    assert np.array_equal(r.V, V) and np.array_equal(r.F, F)
    assert np.array_equal(r.vertex_map, np.arange(V.shape[0]))
    seen = []
    simplify(V, F, target_faces=100, symmetry="X", progress=lambda f: seen.append(f) or True)
    assert seen and all(0.0 <= f <= 1.0 for f in seen)
    assert np.array_equal(V, V0) and np.array_equal(F, F0)


def test_weights_and_locks_are_read_on_both_sides():
    V, F = bumpy_sphere(3)
    lock = np.zeros(V.shape[0], dtype=bool)
    i = int(np.argmax(V[:, 0] + 0.5 * V[:, 1]))            # far on the positive side
    lock[i] = True
    r = simplify(V, F, target_faces=100, symmetry="X", locked=lock,
                 vertex_weights=np.where(V[:, 0] < 0, 5.0, 1.0))
    assert_symmetric(r.V, r.F, "X")
    assert np.array_equal(r.V[r.vertex_map[i]], V[i])      # a locked vertex is not moved


def test_one_sided_mesh_and_bad_axis_are_clear_errors():
    V, F = icosphere(2)
    with pytest.raises(InvalidArgumentError, match=r"symmetry 'X'.*X = 0 plane.*positive side"):
        simplify(V + [2.0, 0.0, 0.0], F, target_faces=50, symmetry="X")
    with pytest.raises(InvalidArgumentError, match="negative side"):
        simplify(V - [0.0, 0.0, 1.5], F, target_faces=50, symmetry="Z")
    with pytest.raises(InvalidArgumentError, match=r"^simplify: symmetry must be 'X', 'Y' or 'Z' "
                                                   r"\(or 0, 1, 2\), got 'W'"):
        simplify_symmetric(V, F, axis="W", target_faces=50)
    with pytest.raises(InvalidArgumentError, match="give at least one of"):
        simplify(V, F, symmetry="X")
    # nothing to mirror: no faces at all (NumPy's bare ValueError before)
    with pytest.raises(InvalidArgumentError, match="needs a mesh with faces to mirror"):
        simplify(V, np.zeros((0, 3), dtype=np.int64), target_faces=10, symmetry="X")


def test_mirror_partners():
    V = np.array([[1.0, 2, 3], [-1.0, 2, 3], [0.0, 5, 1], [2.0, 0, 0], [-2.0, 0, 0]])
    assert mirror_partners(V, "X").tolist() == [1, 0, 2, 4, 3]
    # coincident vertices pair up in order; a near partner is found within the tolerance
    W = np.vstack([V, V[:3], [[0.3, 1, 1], [-0.3 - 1e-9, 1, 1]]])
    assert mirror_partners(W, "X").tolist() == [1, 0, 2, 4, 3, 6, 5, 7, 9, 8]
    with pytest.raises(InvalidArgumentError, match="not mirror-symmetric about the Y plane"):
        mirror_partners(V, "Y", where="fit_cage")
    assert mirror_partners(V, 0).tolist() == [1, 0, 2, 4, 3]     # the axis as symmetrize takes it
    with pytest.raises(InvalidArgumentError, match="^mirror_partners: axis must be 'X', 'Y' or 'Z'"):
        mirror_partners(V, "x")


@pytest.mark.parametrize("axis", ["X", 0])
def test_symmetrize_takes_the_axis_as_mirror_partners_does_and_checks_the_partners(axis):
    V = np.array([[1.0, 2, 3], [-1.2, 2, 3], [0.1, 5, 1], [2.0, 0, 0], [-2.0, 0, 0]])
    p = mirror_partners(V, "X", tolerance=0.1)
    S = symmetrize(V, p, axis)
    np.testing.assert_array_equal(S[p] * [-1, 1, 1], S)
    assert S[2, 0] == 0.0 and S[0, 0] == 1.1
    bad = p.copy()
    bad[3] = -1                   # no "no partner" value: not vertex n-1 in silence
    with pytest.raises(InvalidArgumentError, match=r"^symmetrize: partner must hold vertex indices "
                                                   r"in \[0, 5\), got 1 outside, e\.g\. partner\[3\] = -1"):
        symmetrize(V, bad, axis)
    bad[3] = 5
    with pytest.raises(InvalidArgumentError, match=r"partner\[3\] = 5"):
        symmetrize(V, bad, axis)
    with pytest.raises(InvalidArgumentError, match=r"^symmetrize: partner must be \(5,\) vertex indices"):
        symmetrize(V, p[:4], axis)
    for wrong in ("W", 3, -1, True, None):
        with pytest.raises(InvalidArgumentError, match=r"^symmetrize: axis must be 'X', 'Y' or 'Z' "
                                                       r"\(or 0, 1, 2\)"):
            symmetrize(V, p, wrong)


# ---------------------------------------------------------------- fit and bind
def test_fit_keeps_the_cage_symmetric_and_bind_deform_is_exact_on_an_asymmetric_scan():
    V, F = jittered(*bumpy_sphere(), amount=0.006)
    r = simplify(V, F, target_faces=200, symmetry="X")
    fit = fit_cage(V, F, r.V, r.F, levels=2, scheme="loop", iterations=3, symmetry="X")
    assert_symmetric(fit.V, r.F, "X")
    assert fit.mean_distance[-1] < fit.mean_distance[0]
    plain = fit_cage(V, F, r.V, r.F, levels=2, scheme="loop", iterations=3)
    assert fit.mean_distance[-1] <= 1.25 * plain.mean_distance[-1]
    b = bind(V, F, fit.V, r.F, levels=2, scheme="loop")
    assert np.abs(deform(b, fit.V) - V).max() <= 1e-12 * bbox_diagonal(V)


def test_fit_with_symmetry_needs_a_symmetric_cage():
    V, F = bumpy_sphere(3)
    with pytest.raises(InvalidArgumentError, match="fit_cage: the vertices are not mirror-symmetric"):
        fit_cage(V, F, V + [0.1, 0.0, 0.0], F, levels=1, iterations=1, symmetry="X")


def test_a_symmetric_cage_s_feature_edges_are_its_edges_and_the_fit_takes_them():
    # (a fuzzed mesh of the batch CLI, 2026-12-05: the mirror's weld at the seam joined the
    # ends of two of the half's feature edges that are no edges of the whole cage, and
    # fit_cage refused them as creases)
    import os
    from core import fit_cage, read_obj
    from core.topology import edge_map
    V, F = read_obj(os.path.join(os.path.dirname(__file__), "data", "symmetry_seam_creases.obj"))
    r = simplify(V, F, target_faces=200, symmetry='X')
    E = edge_map(r.F, r.V.shape[0]).E
    edges = set(map(tuple, np.sort(E, axis=1).tolist()))
    assert len(r.feature_edges) > 40
    assert all(tuple(e) in edges for e in r.feature_edges.tolist())
    fit = fit_cage(V, F, r.V, r.F, levels=2, creases=r.feature_edges)
    assert np.isfinite(fit.V).all()
