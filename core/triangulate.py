"""Polygons to triangles: the fan, unless it folds; then ear clipping.

A polygon ``v0 v1 ... vk-1`` is first the fan from its first vertex
(``v0 vi vi+1``, as OBJ and SMF files are usually read). The fan folds when
one of its triangles faces against the polygon's normal (Newell's normal):
a concave polygon seen from a vertex that does not see all of it. Such a
polygon is ear-clipped in its best-fit plane instead (Meisters, "Polygons
have ears", Amer. Math. Monthly 82(6), 1975: every simple polygon of more
than 3 vertices has two ears; Eberly, "Triangulation by Ear Clipping",
Geometric Tools, 2002)::

    5-----4                 the fan from 0 folds (0 2 3 faces down);
    |     |                 ear clipping cuts ears, convex corners whose
    |  2--3                 triangle holds no other vertex, the best-shaped
    |  |                    first: 0 1 2, 5 0 2, 2 3 4, 2 4 5
    0--1

    while the polygon has more than 3 corners:      (all polygons of one size
        clip its best-scored corner                  at once, a block at a time)
        re-score the corner's two neighbours
    the last 3 corners are the last triangle

A polygon with no ear (self-intersecting, or of no area) still loses its
best-shaped convex corner, or any: it always gives ``k - 2`` triangles.
"""

import numpy as np

#: polygons times corners times vertices :func:`_ear_scores` tests at once (its memory)
_EAR_BLOCK = 1 << 20
#: an area below this fraction of a polygon's squared size is flat (rounding: a rotated
#: polygon's collinear vertices are a few 1e-16 off their line)
_FLAT = 1e-10


def triangulate_polygons(V, fans, sizes):
    """Triangles of polygons given by their fans: each fan kept, unless it
    folds (:func:`_folded_fans`); then the polygon is ear-clipped
    (:func:`_ear_clip`; the polygons of one size at once, a block at a time).

    Parameters
    ----------
    V : (n,3) float64, vertex positions.
    fans : (m,3) int64, the fans of the polygons, one after another: polygon
        ``j`` of ``sizes[j]`` vertices ``v0 v1 ... vk-1`` is the ``k - 2``
        rows ``v0 vi vi+1``, i = 1..k-2 (a triangle: its one row).
    sizes : (p,) int64, the vertices of each polygon (3 or more), in order;
        ``(sizes - 2).sum() == m``.

    Returns
    -------
    (m,3) int64, each polygon's ``k - 2`` triangles in its rows of ``fans``
    (a simple polygon's cover it once, each facing the polygon's way);
    ``fans`` itself (not copied) when no fan folds. ``fans`` is never
    modified.

    Examples
    --------
    >>> V = np.array([[1, 0, 0], [.25, .25, 0], [0, 1, 0], [0, 0, 0.]])   # (concave at 1)
    >>> triangulate_polygons(V, np.array([[0, 1, 2], [0, 2, 3]]), np.array([4]))
    array([[3, 0, 1],
           [1, 2, 3]])
    """
    first, k_of = _folded_fans(V, fans, sizes)
    if first.size == 0:
        return fans
    F = fans.copy()
    for k in np.unique(k_of):
        starts = first[k_of == k]
        step = max(1, _EAR_BLOCK // (k * k))
        for s in range(0, starts.size, step):
            at = starts[s:s + step, None] + np.arange(k - 2)
            loops = np.concatenate([F[at[:, :1], 0], F[at[:, :1], 1], F[at, 2]], axis=1)
            F[at] = np.take_along_axis(loops[:, None, :], _ear_clip(V[loops]), axis=2)
    return F


def _folded_fans(V, F, sizes):
    """``(first, k)``: the first rows in ``F`` of the polygons (the fans of
    :func:`triangulate_polygons`) whose fan folds, and their sizes. A fan
    folds when one of its triangles faces against the polygon (Newell's
    normal: the sum of the fan's triangle normals) by more than rounding; a
    fan that does not fold covers its polygon once (its triangles' winding
    numbers add up to the polygon's)."""
    poly = np.flatnonzero(sizes > 3)
    first = np.cumsum(sizes - 2) - (sizes - 2)              # each polygon's first row
    count = sizes[poly] - 2
    which = np.repeat(np.arange(poly.size), count)
    rows = (first[poly] - (np.cumsum(count) - count))[which] + np.arange(which.size)
    T = V[F[rows]]
    n = np.cross(T[:, 1] - T[:, 0], T[:, 2] - T[:, 0])
    N = np.stack([np.bincount(which, weights=n[:, c], minlength=poly.size) for c in range(3)], 1)
    against = np.einsum("ij,ij->i", n, N[which]) < -_FLAT * np.einsum("ij,ij->i", N, N)[which]
    folds = poly[np.bincount(which, weights=against, minlength=poly.size) > 0]
    return first[folds], sizes[folds]


def _ear_clip(X):
    """(q,k-2,3) triangles (positions 0..k-1 in each polygon) of q polygons of
    k vertices ``X`` (q,k,3), clipping one ear of each polygon at a time in
    its best-fit plane: the best-shaped ear (a convex corner whose triangle
    holds no other vertex); a polygon with none (self-intersecting) loses its
    best-shaped convex corner, or any. Each clip re-scores the two neighbours
    only (O(k^2) a polygon)."""
    q, k = X.shape[:2]
    P = _plane_coords(X)
    tol = _FLAT * (P ** 2).sum(axis=2).max(axis=1)
    loop = np.broadcast_to(np.arange(k), (q, k)).copy()
    score = _ear_scores(P, tol, loop, loop)
    r = np.arange(q)
    out = []
    for m in range(k, 3, -1):
        j = np.argmax(score, axis=1)
        out.append(np.stack([loop[r, j - 1], loop[r, j], loop[r, (j + 1) % m]], axis=1))
        keep = np.arange(m) != j[:, None]
        loop, score = loop[keep].reshape(q, m - 1), score[keep].reshape(q, m - 1)
        at = np.stack([(j - 1) % (m - 1), j % (m - 1)], axis=1)
        score[r[:, None], at] = _ear_scores(P, tol, loop, at)
    return np.stack(out + [loop], axis=1)


def _plane_coords(X):
    """(q,k,2) coordinates of polygons ``X`` (q,k,3) in their best-fit planes
    (Newell's normal N; axes u, w with u x w = N: a polygon winding
    counter-clockwise about N has a positive area)."""
    D = X - X[:, :1]
    N = np.cross(D, np.roll(D, -1, axis=1)).sum(axis=1)
    N /= np.maximum(np.linalg.norm(N, axis=1, keepdims=True), np.finfo(float).tiny)
    u = np.cross(N, np.eye(3)[np.argmin(np.abs(N), axis=1)])
    u /= np.maximum(np.linalg.norm(u, axis=1, keepdims=True), np.finfo(float).tiny)
    w = np.cross(N, u)
    return np.stack([np.einsum("qkc,qc->qk", D, u), np.einsum("qkc,qc->qk", D, w)], axis=2)


def _orient(A, B, C):
    """Twice the signed area of the 2D triangles ``A B C`` (..., 2) each."""
    return ((B[..., 0] - A[..., 0]) * (C[..., 1] - A[..., 1])
            - (B[..., 1] - A[..., 1]) * (C[..., 0] - A[..., 0]))


def _ear_scores(P, tol, loop, at):
    """(q,c) the score of clipping the corners at positions ``at`` (q,c) of
    the polygons ``loop`` (q,m) (vertex positions in ``P``, (q,k,2); areas
    within ``tol`` (q,) of 0 are flat): 2 plus the triangle's shape (in
    [-1, 1], 1 equilateral, negative reflex) for an ear (a convex corner
    whose closed triangle holds no other vertex), 1 plus it for another
    convex corner, 0 plus it for a flat or reflex one."""
    q, m = loop.shape
    c = at.shape[1]
    if q * c * m > _EAR_BLOCK and c > 1:                    # (a polygon of thousands of vertices)
        step = max(1, _EAR_BLOCK // (q * m))
        return np.concatenate([_ear_scores(P, tol, loop, at[:, s:s + step])
                               for s in range(0, c, step)], axis=1)
    r = np.arange(q)[:, None]
    A, B, C = (P[r, loop[r, (at + d) % m]] for d in (-1, 0, 1))
    area = _orient(A, B, C)
    sq = sum(((X - Y) ** 2).sum(axis=-1) for X, Y in ((A, B), (B, C), (C, A)))
    shape = np.where(sq > 0, 2 * np.sqrt(3) * area / np.where(sq > 0, sq, 1), 0)
    Q = P[r, loop][:, None]                                  # (q,1,m,2)
    A, B, C, t = A[:, :, None], B[:, :, None], C[:, :, None], -tol[:, None, None]
    inside = (_orient(A, B, Q) >= t) & (_orient(B, C, Q) >= t) & (_orient(C, A, Q) >= t)
    own = (np.arange(m) - at[:, :, None] + 1) % m < 3        # (the corner and its neighbours)
    convex = area > tol[:, None]
    ear = convex & ~(inside & ~own).any(axis=2)
    return np.where(ear, 2, convex.astype(float)) + shape
