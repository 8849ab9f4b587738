"""The pipeline on kinds of scan mess earlier campaigns did not build
(overlapping scan passes, spikes, halos of specks, density contrasts,
georeferenced and float32 coordinates, thin shells, gravel, ...): each test a
bug such a campaign found, with the strongest property that was broken."""

import numpy as np

from core._touch_up import flip_flat_faces
from core.mesh import flat_faces
from core.topology import manifold_report


def test_flat_flips_of_one_round_never_make_the_same_edge_twice():
    """Two flat faces with the same corner ``c`` = 4 on two edges, (1, 2) and
    (1, 3), whose faces across share their far corner ``d`` = 0: each flip
    alone makes the new edge (4, 0), both in one round made it twice, an edge
    of four faces and a face on both sides of it (the 500-face cage of the cow
    in float32 at (5e6, 4e6, 300) m: 5 such pairs, 10 non-manifold vertices).
    One of them is flipped; the other face stays flat."""
    V = np.array([[0.0, -2.0, 0.72],    # d
                  [0.0, 0.0, 0.0],      # the line 1 - 4 - 3 - 2
                  [0.0, 0.0, 1.0],
                  [0.0, 0.0, 0.5],
                  [0.0, 0.0, 0.4]])
    F = np.array([[4, 2, 1], [1, 2, 0], [3, 4, 1], [1, 0, 3]])
    assert flat_faces(V, F).tolist() == [True, False, True, False]
    out, creases = flip_flat_faces(V, F, np.zeros((0, 2), dtype=np.int64))
    rep = manifold_report(out, V.shape[0])
    assert rep.is_oriented_manifold, rep
    assert flat_faces(V, out).sum() == 1
    assert sorted(map(sorted, out.tolist())) != sorted(map(sorted, F.tolist()))
