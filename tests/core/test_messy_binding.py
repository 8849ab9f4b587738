"""Bind, deform and refine on messy real-scan inputs and awkward cages.

What a scan brings (coincident corners, zero-area faces, meshes far from
the origin) must not cost the promises: no edit gives the original back,
a rigid motion of the cage moves everything rigidly, an incremental deform
equals the full one.
"""

import numpy as np
import pytest

from core.binding import bind, deform, frames, refine
from tests.mesh_factory import icosphere


def _rotation(seed, angle_deg=None):
    rng = np.random.default_rng(seed)
    Q, _ = np.linalg.qr(rng.standard_normal((3, 3)))
    if np.linalg.det(Q) < 0:
        Q[:, 0] *= -1
    return Q


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
