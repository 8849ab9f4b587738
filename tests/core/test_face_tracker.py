"""Closest faces by walking (``core._face_tracker``): the same closest points
as the exact :class:`TriangleIndex` when started near the answer, and again
after the mesh or the points move."""

import numpy as np

from core._face_tracker import FaceTracker, faces_across
from core.spatial import TriangleIndex
from tests.mesh_factory import cad_cylinder, fillet_cap, icosphere, regular_grid, torus


def _nearest_vertex(V, Q):
    """Brute-force nearest vertex of ``V`` to each query (the relocation's
    guess is as good: the vertex the query's input vertex was merged into)."""
    return np.argmin(((Q[:, None, :] - V[None, :, :]) ** 2).sum(axis=2), axis=1)


def _assert_same_as_index(got, V, F, Q):
    exact = TriangleIndex(V, F).closest(Q)
    d = np.linalg.norm(got.point - Q, axis=1)
    # the same distances (a tie between two faces may pick the other one)
    np.testing.assert_allclose(d, exact.distance, rtol=1e-12, atol=1e-15)
    same = got.face == exact.face
    assert same.mean() > 0.99
    np.testing.assert_array_equal(got.bary[same], exact.bary[same])
    np.testing.assert_array_equal(got.point[same], exact.point[same])
    A, B, C = (V[F[got.face, k]] for k in range(3))
    np.testing.assert_allclose(got.bary[:, :1] * A + got.bary[:, 1:2] * B + got.bary[:, 2:] * C,
                               got.point, atol=1e-14)


def test_faces_across_link_the_two_faces_of_every_edge_and_mark_borders():
    for V, F in (torus(12, 8), regular_grid(5, 4)):
        X = faces_across(F, V.shape[0])
        for f in range(F.shape[0]):
            for c in range(3):
                edge = {F[f, (c + 1) % 3], F[f, (c + 2) % 3]}
                others = [g for g in range(F.shape[0]) if g != f and edge <= set(F[g])]
                assert X[f, c] == (others[0] if others else -1)


def test_walks_from_a_vertex_near_each_point_find_the_exact_closest_points():
    # a coarse noisy sphere and points around it, in and out, each started at
    # its nearest coarse vertex
    rng = np.random.default_rng(3)
    V, F = icosphere(2)
    V = V * (1 + 0.05 * rng.standard_normal((V.shape[0], 1)))
    Q = icosphere(4)[0] * (1 + 0.08 * rng.standard_normal((2562, 1)))
    Q = Q @ np.linalg.qr(rng.standard_normal((3, 3)))[0]   # off the coarse vertices: no ties
    near = _nearest_vertex(V, Q)
    tracker = FaceTracker(F, V.shape[0], steps=8)
    tracker.place(V)
    _assert_same_as_index(tracker.closest(Q, near), V, F, Q)
    # started one edge off (a neighbour of the nearest vertex), they walk there
    E = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
    neighbour = np.zeros(V.shape[0], dtype=np.int64)
    neighbour[E[:, 0]] = E[:, 1]
    tracker = FaceTracker(F, V.shape[0], steps=8)
    tracker.place(V)
    _assert_same_as_index(tracker.closest(Q, neighbour[near]), V, F, Q)


def test_later_calls_follow_the_moving_mesh_and_the_moving_points():
    rng = np.random.default_rng(4)
    V, F = torus(24, 12, bump=0.03, bump_waves=(7, 3))
    Q = torus(96, 48)[0] + 0.01 * rng.standard_normal((96 * 48, 3))
    tracker = FaceTracker(F, V.shape[0], steps=8)
    tracker.place(V)
    tracker.closest(Q, _nearest_vertex(V, Q))
    for _ in range(3):
        V = V + 0.01 * rng.standard_normal(V.shape)     # the mesh moves
        tracker.place(V)
        _assert_same_as_index(tracker.closest(Q), V, F, Q)
        Q = Q + 0.01 * rng.standard_normal(Q.shape)     # the points move
        _assert_same_as_index(tracker.closest(Q), V, F, Q)


def test_queries_with_no_guess_are_searched_exactly():
    V, F = icosphere(2)
    Q = np.array([[0.0, 0.0, 2.0], [0.3, -0.2, 0.1], [5.0, 1.0, -1.0]])
    tracker = FaceTracker(F, V.shape[0], steps=0)      # no walking at all
    tracker.place(V)
    _assert_same_as_index(tracker.closest(Q, np.array([-1, -1, -1])), V, F, Q)
    tracker = FaceTracker(F, V.shape[0], steps=0)
    tracker.place(V)
    _assert_same_as_index(tracker.closest(Q), V, F, Q)


def test_a_mesh_of_few_faces_is_searched_whole_whatever_the_guess():
    # 20 faces: every answer is exact even with no walking and every guess at
    # one vertex (a walk from there could not reach the far side), later calls
    # too
    import core._face_tracker as ft
    from core.spatial import point_triangle_closest
    rng = np.random.default_rng(5)
    V, F = icosphere(0)
    assert F.shape[0] <= ft._EVERY_FACE
    Q = 2.0 * rng.standard_normal((600, 3))
    tracker = FaceTracker(F, V.shape[0], steps=0)
    for call in range(2):
        tracker.place(V)
        got = tracker.closest(Q, np.zeros(600, dtype=np.int64) if call == 0 else None)
        every = point_triangle_closest(np.repeat(Q, F.shape[0], axis=0), *(np.tile(V[F[:, k]], (600, 1))
                                                                          for k in range(3)))
        d = every.distance.reshape(600, F.shape[0])
        np.testing.assert_allclose(d[np.arange(600), got.face], d.min(axis=1), rtol=1e-12, atol=1e-15)
        A, B, C = (V[F[got.face, k]] for k in range(3))
        np.testing.assert_allclose(got.bary[:, :1] * A + got.bary[:, 1:2] * B + got.bary[:, 2:] * C,
                                   got.point, atol=1e-14)
        np.testing.assert_allclose(np.linalg.norm(got.point - Q, axis=1), d.min(axis=1),
                                   rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose(TriangleIndex(V, F).closest(Q).distance, d.min(axis=1),
                                   rtol=1e-12, atol=1e-15)
        V = V + 0.05 * rng.standard_normal(V.shape)


def test_around_a_fans_hub_only_the_faces_near_each_point_are_tried_and_the_answers_are_the_same():
    # a CAD cone and a fillet-like cap: hubs of 2,000 and 1,500 needles (and a
    # few wide faces around the fillet's corner); points near the surface, each
    # started at the hub, then moved a little: the same distances as trying every face
    rng = np.random.default_rng(4)
    for V, F in (cad_cylinder(2000), fillet_cap(1500)):
        diag = np.linalg.norm(np.ptp(V, axis=0))
        Q = V[F[rng.integers(0, F.shape[0], 3000)]].mean(axis=1) + rng.normal(0, 0.01 * diag, (3000, 3))
        hub = np.argmax(np.bincount(F.ravel()))
        near = np.full(Q.shape[0], hub)
        fan = FaceTracker(F, V.shape[0], steps=8)
        fan.place(V)
        assert fan._fans is not None and fan._fans.start.size >= 2
        every = FaceTracker(F, V.shape[0], steps=8)
        every.place(V)
        every._fans = None                               # every face around every vertex
        for step in range(2):
            got, ref = fan.closest(Q, near), every.closest(Q, near)
            np.testing.assert_array_equal(np.linalg.norm(got.point - Q, axis=1),
                                          np.linalg.norm(ref.point - Q, axis=1))
            assert (got.face == ref.face).mean() > 0.99      # (ties may go to the other face)
            Q = Q + rng.normal(0, 0.002 * diag, Q.shape)
        # on the cylinder's cap (a fan all round) the windows hold few of the hub's faces
        h = fan._fans.hub_of[near]
        starts, counts = fan._fans.windows(h, Q, np.full(Q.shape[0], (0.01 * diag) ** 2))
        share = counts.reshape(-1, 3).sum(axis=1).mean() / np.bincount(F.ravel())[hub]
        assert share < (0.1 if F.shape[0] == 8000 else 1.0)


def test_a_walk_that_reaches_a_hub_tries_the_spokes_nearer_than_its_sector_s_only():
    # points just over a CAD cylinder's cap, each started at a rim vertex 1.2 radians
    # round: their balls reach the hub, whose spokes within the ball's radius were
    # all tried (791 faces a point; a relocation tried 167, 424 at most); bounded first
    # by the spoke whose sector holds the point, a few are, and the answers are the same
    rng = np.random.default_rng(6)
    V, F = cad_cylinder(2000)
    top = np.flatnonzero(np.isclose(V[:, 2], V[:, 2].max()))
    rim = top[np.argsort(np.bincount(F.ravel(), minlength=V.shape[0])[top])[:-1]]
    r, t = np.sqrt(rng.uniform(0.01, 0.8, 2000)), rng.uniform(0, 2 * np.pi, 2000)
    Q = np.c_[r * np.cos(t), r * np.sin(t), V[:, 2].max() + rng.uniform(1e-3, 1e-2, 2000)]
    angle = np.arctan2(V[rim, 1], V[rim, 0])
    near = rim[np.argmin(np.abs(np.angle(np.exp(1j * (angle[None, :] - t[:, None] - 1.2)))),
                         axis=1)]
    pairs = []
    fan = FaceTracker(F, V.shape[0], steps=8)
    fan.place(V)
    real = fan._pairs
    fan._pairs = lambda QT, q, f: pairs.append(q.size) or real(QT, q, f)
    every = FaceTracker(F, V.shape[0], steps=8)
    every.place(V)
    every._fans = None
    got, ref = fan.closest(Q, near), every.closest(Q, near)
    np.testing.assert_allclose(np.linalg.norm(got.point - Q, axis=1),
                               np.linalg.norm(ref.point - Q, axis=1), rtol=0, atol=1e-15)
    _assert_same_as_index(got, V, F, Q)
    assert sum(pairs) < 50 * Q.shape[0]              # (37.5; 791 before)
