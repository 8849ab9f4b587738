"""simplify(..., max_dihedral_deg=): no collapse bends two adjacent faces
beyond the bound (away from the input's creases), and the stop says so."""

import numpy as np
import pytest

from core.errors import InvalidArgumentError
from core.simplify import simplify
from core.topology import manifold_report, topology_summary
from tests.mesh_factory import bend_angles_deg, cube, icosphere, torus


@pytest.mark.parametrize("shape, limit", [("sphere", 20.0), ("sphere", 35.0), ("torus", 30.0)])
def test_no_collapse_bends_faces_beyond_the_bound(shape, limit):
    V, F = icosphere(4) if shape == "sphere" else torus(40, 20, bump=0.2)
    free = simplify(V, F, target_faces=40)
    assert free.stopped_because == "target"
    assert bend_angles_deg(free.V, free.F).max() > limit      # the bound is what stops it below
    assert bend_angles_deg(V, F).max() < limit                  # (the input is within it)
    r = simplify(V, F, target_faces=40, max_dihedral_deg=limit)
    assert r.stopped_because == "max_dihedral"
    assert r.F.shape[0] > 40
    assert bend_angles_deg(r.V, r.F, r.feature_edges).max() <= limit + 1e-9
    rep = manifold_report(r.F, r.V.shape[0])
    assert rep.is_oriented_manifold
    assert topology_summary(r.F, r.V.shape[0]).euler == topology_summary(F, V.shape[0]).euler
    assert "dihedral" in r.message and f"{r.F.shape[0]:,} faces" in r.message


def test_a_looser_bound_goes_further():
    V, F = icosphere(4)
    counts = [simplify(V, F, target_faces=40, max_dihedral_deg=a).F.shape[0] for a in (15.0, 25.0, 40.0)]
    assert counts[0] > counts[1] > counts[2]


def test_creases_of_the_input_are_exempt():
    # a cube's edges bend by 90 degrees: they are creases, so a 10 degree bound
    # still lets the flat sides collapse down to the 12-face cube
    V, F = cube(8)
    r = simplify(V, F, target_faces=12, max_dihedral_deg=10.0)
    assert r.F.shape[0] == 12 and r.stopped_because == "target"
    assert bend_angles_deg(r.V, r.F, r.feature_edges).max() <= 10.0 + 1e-9


def test_a_bound_the_target_never_reaches_changes_nothing():
    V, F = icosphere(4)
    a = simplify(V, F, target_faces=2000)
    b = simplify(V, F, target_faces=2000, max_dihedral_deg=60.0)
    assert b.stopped_because == "target" and b.F.shape[0] == a.F.shape[0]
    assert bend_angles_deg(b.V, b.F).max() <= 60.0


@pytest.mark.parametrize("bad", [0.0, -5.0, 180.0, 200.0, float("nan")])
def test_bad_bounds_are_refused(bad):
    V, F = icosphere(2)
    with pytest.raises(InvalidArgumentError, match="max_dihedral_deg"):
        simplify(V, F, target_faces=20, max_dihedral_deg=bad)


def test_a_symmetric_cage_takes_the_bound_too():
    from core.mirror import mirror_partners
    V, F = icosphere(4)
    r = simplify(V, F, target_faces=40, max_dihedral_deg=25.0, symmetry="X")
    assert r.stopped_because == "max_dihedral" and r.F.shape[0] > 40
    assert (mirror_partners(r.V, "X") >= 0).all()
    # away from the mirror plane every bend is within the bound
    C = r.V[r.F].mean(axis=1)
    off = np.abs(C[:, 0]) > 0.2
    assert bend_angles_deg(r.V, r.F[off]).max() <= 25.0 + 1e-9
