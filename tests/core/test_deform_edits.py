"""Artists' and adversarial edits thrown at ``deform`` / ``refine`` (a campaign on
2026-12-05 evening): each test is a bug that campaign found, with its repro."""

import numpy as np
import pytest

from core.binding import bind, deform
from core.mesh import bbox_diagonal
from core.simplify import simplify
from tests.mesh_factory import grid


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
