"""core/detail_search.py: fine vertices with no bound dense vertex get their
exact closest point on the dense surface, from an index of only the faces
that can come that near (none is left out: far points, unbound patches
of every size, no bound vertex anywhere)."""

import numpy as np
import pytest

from core.detail_search import dense_points_near
from core.mesh import bbox_diagonal
from core.spatial import TriangleIndex, closest_points
from core.subdivide import subdivide
from tests.mesh_factory import icosphere, load_shared, torus


def _case(V_dense, F_dense, unbound, seed=0, lift=0.02):
    """A fine mesh near the dense one (an icosphere scaled onto its bounding
    box, vertices lifted off it), and ``nearest``: each fine vertex's nearest
    dense vertex on a face, -1 for the ``unbound`` share of them (a patch around one
    vertex, grown by distance)."""
    rng = np.random.default_rng(seed)
    lo, hi = V_dense.min(axis=0), V_dense.max(axis=0)
    Vs, Fs = icosphere(3)
    P = 0.5 * (lo + hi) + 0.5 * (hi - lo) * Vs
    P = P + lift * bbox_diagonal(V_dense) * rng.standard_normal(P.shape)
    used = np.unique(F_dense)                  # (a scan's unused vertices are never bound)
    d2 = ((P[:, None, :] - V_dense[None, used, :]) ** 2).sum(axis=2)
    nearest = used[np.argmin(d2, axis=1)]
    centre = P[rng.integers(P.shape[0])]
    far = np.argsort(((P - centre) ** 2).sum(axis=1), kind="stable")
    nearest[far[:int(unbound * P.shape[0])]] = -1
    return Fs, nearest, P


@pytest.mark.parametrize("unbound,offset", [(0.01, 0.0), (0.2, 0.0), (0.7, 0.0), (1.0, 0.0),
                                            (0.2, 1e4)], ids=["1%", "20%", "70%", "all", "far from 0"])
def test_unbound_fine_vertices_get_their_exact_closest_point(unbound, offset):
    Vd, Fd = torus(60, 30, bump=0.02)
    Vd = Vd + offset                          # (the cells' rounding margin scales with this)
    Ff, nearest, P = _case(Vd, Fd, unbound)
    q = dense_points_near(Vd, Fd, Ff, nearest, P)
    missing = nearest < 0
    exact = closest_points(Vd, Fd, P[missing])
    got = np.linalg.norm(q[missing] - P[missing], axis=1)
    np.testing.assert_allclose(got, exact.distance, rtol=0, atol=1e-12 * bbox_diagonal(Vd))
    np.testing.assert_allclose(q[missing], exact.point, rtol=0, atol=1e-12 * bbox_diagonal(Vd))
    # the others lie on the dense surface too
    assert closest_points(Vd, Fd, q).distance.max() <= 1e-12 * bbox_diagonal(Vd)


def test_far_fine_vertices_and_a_real_scan():
    """A real mesh; some unbound fine vertices far off it (the distance bound
    then covers most of the scan) and the rest close to it."""
    Vd, Fd = load_shared("stanford-bunny.obj")
    Ff, nearest, P = _case(Vd, Fd, 0.3, seed=2, lift=0.002)
    P[np.flatnonzero(nearest < 0)[:5]] += 0.3 * bbox_diagonal(Vd)
    q = dense_points_near(Vd, Fd, Ff, nearest, P)
    missing = nearest < 0
    exact = closest_points(Vd, Fd, P[missing])
    np.testing.assert_allclose(np.linalg.norm(q[missing] - P[missing], axis=1), exact.distance,
                               rtol=0, atol=1e-12 * bbox_diagonal(Vd))


def test_an_unbound_patch_the_fine_edges_do_not_reach_uses_the_whole_scan():
    """Two fine components, one wholly unbound: no distance bound reaches it
    over the fine edges, and the whole scan's index answers it (exactly)."""
    Vd, Fd = subdivide(*icosphere(2), levels=1).V, subdivide(*icosphere(2), levels=1).F
    Vs, Fs = icosphere(1)
    P = np.vstack([1.05 * Vs, 0.3 * Vs + [0.5, 0.0, 0.0]])
    Ff = np.vstack([Fs, Fs + Vs.shape[0]])
    nearest = np.full(P.shape[0], -1)
    nearest[:Vs.shape[0]] = np.argmin(((P[:Vs.shape[0], None] - Vd[None]) ** 2).sum(axis=2), axis=1)
    q = dense_points_near(Vd, Fd, Ff, nearest, P)
    exact = closest_points(Vd, Fd, P[Vs.shape[0]:])
    np.testing.assert_allclose(q[Vs.shape[0]:], exact.point, rtol=0, atol=1e-12)


def test_the_exact_detail_index_grows_its_cells_for_few_queries_and_stays_exact():
    from core.detail_search import detail_cell_factor, exact_detail_index
    from core.spatial import CELL_FACTOR
    assert detail_cell_factor(1000, 1000) == detail_cell_factor(2000, 1000) == CELL_FACTOR
    growth = [detail_cell_factor(f, 1000) for f in (4000, 32000, 320000)]
    assert growth == sorted(growth) and growth[0] > CELL_FACTOR
    assert growth[1] == pytest.approx(2 * CELL_FACTOR)               # (16x the faces: twice)
    assert detail_cell_factor(10, 0) >= CELL_FACTOR                  # (no query: no error)
    Vd, Fd = torus(200, 100, bump=0.02)                              # 40k faces
    rng = np.random.default_rng(3)
    P = Vd[rng.integers(Vd.shape[0], size=500)] + 0.01 * rng.standard_normal((500, 3))
    index = exact_detail_index(Vd, Fd, P.shape[0])                   # cells 2.8x the default
    assert index.tables.cell_size > 2 * TriangleIndex(Vd, Fd).tables.cell_size
    assert index.closest(P).distance.tolist() == closest_points(Vd, Fd, P).distance.tolist()
