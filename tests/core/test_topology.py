"""core.topology: the public edge map, manifold report, Euler characteristic
and summary check ``F`` and ``n_vertices`` and name what is wrong."""

import numpy as np
import pytest

from core.errors import InvalidArgumentError, InvalidMeshError
from core.topology import edge_map, euler_characteristic, manifold_report, topology_summary
from tests.mesh_factory import icosphere, regular_grid, torus

PUBLIC = {f.__name__: f for f in (edge_map, manifold_report, euler_characteristic,
                                  topology_summary)}


def test_invariants_of_known_meshes():
    for (V, F), euler, loops in ((icosphere(2), 2, 0), (torus(12, 6), 0, 0),
                                 (regular_grid(5, 4), 1, 1)):
        n = V.shape[0]
        s = topology_summary(F, n)
        assert (s.euler, s.components, s.boundary_loops) == (euler, 1, loops)
        assert euler_characteristic(F) == euler_characteristic(F.tolist(), n) == euler
        assert manifold_report(F, n).is_oriented_manifold
        em = edge_map(F, n)
        assert em.E.shape[0] == n + F.shape[0] - euler


@pytest.mark.parametrize("name", list(PUBLIC))
def test_bad_faces_and_counts_raise_named_errors(name):
    fn = PUBLIC[name]
    V, F = icosphere(1)
    n = V.shape[0]
    F_neg, F_out = F.copy(), F.copy()
    F_neg[2, 1], F_out[2, 1] = -1, n
    with pytest.raises(InvalidMeshError, match=rf"^{name}: F must be \(m,3\) integers, got \(80, 4\)"):
        fn(np.c_[F, F[:, 0]], n)
    with pytest.raises(InvalidMeshError, match=rf"^{name}: F must be \(m,3\) integers, .*float64"):
        fn(F.astype(float), n)
    with pytest.raises(InvalidMeshError, match=rf"^{name}: 1 faces index vertices outside "
                                               rf"\[0, {n}\), e\.g\. face 2 = \[0, -1, 14\]"):
        fn(F_neg, n)
    with pytest.raises(InvalidMeshError, match=rf"^{name}: .*e\.g\. face 2 = \[0, {n}, 14\]"):
        fn(F_out, n)
    for bad in (-1, 2.5, True, "42"):
        with pytest.raises(InvalidArgumentError, match=rf"^{name}: n_vertices must be an integer >= 0"):
            fn(F, bad)
    fn([], n)                                   # no faces: fine, whatever the form


def test_euler_characteristic_without_a_vertex_count():
    _, F = icosphere(1)
    assert euler_characteristic(F + 10**15) == 2           # only the used vertices count
    F_neg = F.copy()
    F_neg[4, 0] = -3
    with pytest.raises(InvalidMeshError, match=r"^euler_characteristic: 1 faces have negative "
                                               r"indices, e\.g\. face 4 = \[-3,"):
        euler_characteristic(F_neg)
