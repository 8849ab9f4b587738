"""Property tests of core.fit.fit_cage on cages as artists leave them: open
patches, a single triangle, creases, weights at the ends of their ranges."""

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from core.fit import fit_cage
from core.subdivide import subdivide


def _fan(k):
    """An open planar fan of k triangles around the origin (radius 1)."""
    ang = np.arange(k) * 2 * np.pi / k
    V = np.vstack([[0.0, 0, 0], np.stack([np.cos(ang), np.sin(ang), np.zeros(k)], 1)])
    F = np.array([[0, 1 + i, 1 + (i + 1) % k] for i in range(k)], dtype=np.int64)
    return V, F


def _noisy_patch(V, F, seed, noise=0.003, shift=0.2):
    """A dense scan of the cage's Loop surface (noise: a share of its size)
    and the cage moved off it (shift: a share of its size)."""
    rng = np.random.default_rng(seed)
    size = np.linalg.norm(V.max(0) - V.min(0))
    DV, DF = subdivide(V, F, levels=3, scheme="loop")
    DV = DV + noise * size * rng.standard_normal(DV.shape)
    return DV, DF, V + shift * size * rng.standard_normal(V.shape)


@pytest.mark.parametrize("k, seed, levels, smoothness, point_to_point", [
    (1, 1, 0, 1.0, 0.0),        # a single triangle: 1 -> 7.4x the start's mean distance
    (1, 5, 1, 0.05, 0.0),       # 1 -> 2.5x
    (12, 0, 0, 1.0, 0.0),       # 1 -> 3.6x
    (12, 4, 0, 100.0, 0.1),     # 1 -> 1.018x (default point_to_point)
    (12, 2, 0, 100.0, 0.1),     # 1 -> 1.008x
])
def test_fit_never_ends_farther_than_it_started(k, seed, levels, smoothness, point_to_point):
    """Each step of the fit is kept only if it does not increase the mean
    distance (its own measure): the record never rises, and the cage it
    returns is the one its last entry measured."""
    V, F = _fan(k) if k > 1 else (np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]]), np.array([[0, 1, 2]]))
    DV, DF, start = _noisy_patch(V, F, seed)
    kw = dict(levels=levels, smoothness=smoothness, point_to_point=point_to_point)
    r = fit_cage(DV, DF, start, F, iterations=7, **kw)
    md = r.mean_distance
    assert np.isfinite(r.V).all() and np.isfinite(md).all()
    assert np.all(np.diff(md) <= 0), md / md[0]
    assert r.cg_iterations.shape[0] == md.shape[0] - 1
    again = fit_cage(DV, DF, r.V, F, iterations=0, **kw)
    assert again.mean_distance[0] == pytest.approx(md[-1], rel=1e-12)


def test_a_cage_far_larger_than_the_scan_keeps_a_fine_dense_index(monkeypatch):
    """The dense index's cells are a mean fine edge wide, but at most an
    eighth of the scan's diagonal: a cage 30x the scan's size made the scan
    one cell (every closest-point query then read all of its triangles: a
    500-face cage on the 69k-face bunny took 37 s instead of 3.5 s); the
    fit is the same either way (the answers are exact)."""
    import core.fit as fit_module
    from core.spatial import TriangleIndex
    from tests.mesh_factory import torus
    Vd, Fd = torus(48, 24, bump=0.01, bump_waves=(12, 6))
    Vc, Fc = torus(12, 6)
    cells = []

    def recording(V, F, **kw):
        cells.append(kw.get("min_cell"))
        return TriangleIndex(V, F, **kw)
    monkeypatch.setattr(fit_module, "TriangleIndex", recording)
    diag = np.linalg.norm(Vd.max(0) - Vd.min(0))
    big = fit_cage(Vd, Fd, 30 * Vc, Fc, levels=1, iterations=1)
    assert cells[0] <= diag / 8 * (1 + 1e-12)
    monkeypatch.setattr(fit_module, "TriangleIndex", lambda V, F, **kw: TriangleIndex(V, F))
    plain = fit_cage(Vd, Fd, 30 * Vc, Fc, levels=1, iterations=1)
    np.testing.assert_allclose(big.V, plain.V, rtol=0, atol=1e-9 * diag)


def test_a_fit_that_keeps_no_step_returns_the_cage_bit_for_bit():
    """iterations=0 ('returns the input'), or a first step that would not
    bring the cage closer, gives back the cage as given: it came back
    through the working origin (minus the dense mesh's centre, plus it
    again), one ulp off where that centre rounds (0.1 off the origin)."""
    from tests.mesh_factory import icosphere
    Vd, Fd = icosphere(3)
    Vc, Fc = icosphere(1)
    t = np.array([0.1, -0.1 / 3, 0.1 / 7])
    start = 0.9 * Vc + t + np.random.default_rng(0).normal(0, 1e-3, Vc.shape)
    r = fit_cage(Vd + t, Fd, start, Fc, levels=1, iterations=0)
    assert np.array_equal(r.V, start)
    fitted = fit_cage(Vd + t, Fd, start, Fc, levels=1, iterations=6).V
    again = fit_cage(Vd + t, Fd, fitted, Fc, levels=1, iterations=6)
    assert again.cg_iterations.shape == (0,) and np.array_equal(again.V, fitted)


@settings(max_examples=12, deadline=None)
@given(k=st.integers(3, 14), seed=st.integers(0, 2 ** 16), levels=st.integers(0, 2),
       scheme=st.sampled_from(["butterfly", "loop"]),
       smoothness=st.sampled_from([0.0, 0.05, 100.0]), point_to_point=st.sampled_from([0.0, 0.1, 10.0]),
       laplacian=st.sampled_from(["uniform", "cotangent"]), crease=st.booleans(),
       merge=st.booleans())
def test_random_open_cages_fit_finite_monotone_and_leave_their_inputs(k, seed, levels, scheme, smoothness,
                                                                      point_to_point, laplacian, crease,
                                                                      merge):
    """Open fans (a border vertex of valence 2 at each rim corner, an
    interior vertex of valence k), creased or not, with two vertices moved
    onto one point or not, over a noisy scan of their surface: the fit is
    finite, its record never rises, and its inputs are untouched (read-only)."""
    V, F = _fan(k)
    F = F[:-1]                                  # open the fan
    DV, DF, start = _noisy_patch(V, F, seed, shift=0.05)
    if merge:
        start[2] = start[3]
    C = np.array([[0, 1], [0, k // 2 + 1]]) if crease else None
    args = [DV, DF, start, F] + ([C] if crease else [])
    for a in args:
        a.setflags(write=False)
    copies = [a.copy() for a in args]
    r = fit_cage(DV, DF, start, F, levels=levels, scheme=scheme, creases=C, iterations=4,
                 smoothness=smoothness, point_to_point=point_to_point, laplacian=laplacian)
    assert np.isfinite(r.V).all() and np.isfinite(r.mean_distance).all()
    assert np.all(np.diff(r.mean_distance) <= 0)
    for a, b in zip(args, copies):
        assert np.array_equal(a, b) and not a.flags.writeable


@pytest.mark.parametrize("scale", [1e4, 1e7, 1e-4])
def test_a_flat_cage_face_fits_alike_at_any_scale_with_cotangent_weights(scale):
    """The cotangent of a flat face's angle was its dot product over
    max(|cross|, 1e-300): at 1e4 units (a 4x4 grid 4e4 wide with one flat
    face) it overflowed to inf ('overflow encountered in divide'), the
    Laplacian went NaN, and the fit silently stayed where it started
    (0.0117 -> 0.0117, against 0.0117 -> 0.0071 at 1 unit)."""
    import warnings
    x, y = np.meshgrid(np.arange(5.0), np.arange(5.0))
    V = np.stack([x.ravel(), y.ravel(), np.zeros(25)], 1)
    q = (np.arange(4)[:, None] * 5 + np.arange(4)).ravel()
    F = np.vstack([np.stack([q, q + 1, q + 6], 1), np.stack([q, q + 6, q + 5], 1)])
    DV, DF = subdivide(V, F, levels=3, scheme="loop")
    DV = DV + 0.01 * np.random.default_rng(0).standard_normal(DV.shape)
    start = V.copy()
    start[6] = [2.0, 0.0, 0.0]            # face (0, 1, 6) flat: its corners on one line
    kw = dict(levels=1, iterations=3, laplacian="cotangent")
    unit = fit_cage(DV, DF, start, F, **kw)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        far = fit_cage(DV * scale, DF, start * scale, F, **kw)
    np.testing.assert_allclose(far.mean_distance / scale, unit.mean_distance, rtol=1e-6)
    assert unit.mean_distance[-1] < 0.7 * unit.mean_distance[0]
    np.testing.assert_allclose(far.V / scale, unit.V, rtol=0, atol=1e-6)


@pytest.mark.parametrize("scheme", ["butterfly", "loop"])
@pytest.mark.parametrize("levels", [0, 2])
def test_a_fitted_cage_with_holes_and_creases_binds_back_to_its_scan(scheme, levels):
    """simplify -> fit_cage -> bind on a holed, creased scan (the cube's
    creases, three holes, a far origin): the fit never ends farther than it
    started, and the unedited fitted cage deforms and refines onto the scan
    to 1e-12 of its diagonal."""
    from core import TriangleIndex, bind, deform, refine, simplify
    from tests.mesh_factory import cube
    V, F = cube(12)
    V = V + 1e5
    keep = np.ones(len(F), bool)
    keep[[5, 300, 301, 700]] = False                   # holes (one of two faces: a notch)
    F = F[keep]
    cage = simplify(V, F, target_faces=120, feature_angle_deg=40)
    assert cage.n_boundary_loops >= 2 and len(cage.feature_edges) > 0
    fit = fit_cage(V, F, cage.V, cage.F, levels=levels, scheme=scheme, creases=cage.feature_edges,
                   iterations=4)
    assert np.all(np.diff(fit.mean_distance) <= 0) and np.isfinite(fit.V).all()
    b = bind(V, F, fit.V, cage.F, levels=levels, scheme=scheme, creases=cage.feature_edges)
    diag = np.linalg.norm(V.max(0) - V.min(0))
    assert np.abs(deform(b, fit.V) - V).max() <= 1e-12 * diag
    R = refine(b, fit.V)
    assert R.F.shape[0] == cage.F.shape[0] * 4 ** levels
    # (closest points of coordinates 1e5 off the origin carry their rounding: 1e-16 of 1e5)
    assert TriangleIndex(V, F).closest(R.V).distance.max() <= 1e-12 * diag + 1e-16 * 1e5 * 8
