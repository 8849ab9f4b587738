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

A polygon of up to ``_SMALL`` vertices loses one ear at a time
(:func:`_ear_clip`: O(k^2), but all polygons of one size at once)::

    while the polygon has more than 3 corners:      (all polygons of one size
        clip its best-scored corner                  at once, a block at a time)
        re-score the corner's two neighbours
    the last 3 corners are the last triangle

A larger one (a CAD face's lettering or gear, a scan's cap) loses many in
each of a few rounds (:func:`_clip_in_rounds`, all such polygons at once)::

    while a polygon has more than 3 corners:
        ears: its convex corners whose triangle holds none of its flat or
              reflex corners (only those can lie in an ear: Eberly), these
              looked up in a grid
        clip every ear better shaped than its neighbouring ears (two
              clipped ears never touch, so their triangles never overlap)
        grow each into a fan from its apex while the next triangle is an ear
              in turn, up to the next clipped ear (one ear at a time, a
              reflex chain such as a spiral's inside or a dense arc seen
              from one corner would take a round a vertex)

    . . . . . . . . a       fan from a over the chain b c d e: its triangles
      (reflex)    / |       sorted by their angle about a, so a blocker is
      e--d--c--b-'  |       tested against one triangle (and its two
                    ...     neighbours), found by binary search

A polygon with no ear (self-intersecting, or of no area) still loses its
best-shaped convex corner, or any (the large ones: every such corner better
scored than its neighbours): it always gives ``k - 2`` triangles.
"""

import numpy as np

from ._groups import member_of, sorted_unique

#: polygons times corners times vertices :func:`_ear_scores` tests at once (its memory)
_EAR_BLOCK = 1 << 20
#: an area below this fraction of a polygon's squared size is flat (rounding: a rotated
#: polygon's collinear vertices are a few 1e-16 off their line)
_FLAT = 1e-10
#: a corner's area above this times its polygon's largest coordinate times its two edges'
#: lengths is more than rounding (a dense outline's corners are convex below _FLAT)
_ROUNDING = 1e-12
#: barycentric coordinates of the centroids of the upward triangles of a triangle cut in
#: 5 x 5 (where :meth:`_Blockers.holds` looks first)
_PROBES = np.array([(i + 1 / 3, j + 1 / 3, 4 - i - j + 1 / 3) for i in range(5)
                    for j in range(5 - i)]) / 5
#: steps of an ear's shape (in [-1, 1]) that :func:`_round_of_clips` tells apart (finer,
#: and a smooth arc's ears would be clipped one a round from its most curved corner)
_SHAPES = 16
#: polygons of more vertices than this are clipped in rounds (:func:`_clip_in_rounds`)
_SMALL = 64
#: a polygon of more than _SMALL corners left that loses fewer in each of 3 rounds in a row is
#: clipped one ear at a time from there (a round costs about as much as this many ears)
_STALL = 16
#: a cell of :class:`_Blockers` is this times the outline's length over its blockers wide
#: (so it holds about one blocker along the outline)
_PER_CELL = 1.0


def triangulate_polygons(V, fans, sizes):
    """Triangles of polygons given by their fans: each fan kept, unless it
    folds (:func:`_folded_fans`); then the polygon is ear-clipped: one ear
    at a time up to ``_SMALL`` vertices (:func:`_ear_clip`; the polygons of
    one size at once, a block at a time), in rounds of many above
    (:func:`_clip_in_rounds`; O(k log k)-like: about 10 to 20 rounds for
    20,000 vertices). Each polygon's triangles depend on that polygon alone.

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
    large = k_of > _SMALL
    if large.any():
        at = np.repeat(first[large] - (np.cumsum(k_of[large] - 2) - (k_of[large] - 2)),
                       k_of[large] - 2) + np.arange((k_of[large] - 2).sum())
        F[at] = _clip_in_rounds(V, _loops(F, first[large], k_of[large]), k_of[large])
    for k in sorted_unique(k_of[~large]):
        at = first[~large][k_of[~large] == k, None] + np.arange(k - 2)
        loops = np.concatenate([F[at[:, :1], 0], F[at[:, :1], 1], F[at, 2]], axis=1)
        F[at] = _clip_one_at_a_time(V, loops)
    return F


def _clip_one_at_a_time(V, loops):
    """(q,k-2,3) the triangles (vertex ids) of the q polygons ``loops``
    (q,k) of one size, ear-clipped one ear at a time (:func:`_ear_clip`), a
    block of polygons at a time (``_EAR_BLOCK``)."""
    q, k = loops.shape
    step = max(1, _EAR_BLOCK // (k * k))
    return np.concatenate([np.take_along_axis(block[:, None, :], _ear_clip(V[block]), axis=2)
                           for block in (loops[s:s + step] for s in range(0, q, step))])


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
    u, w = _plane_axes(np.cross(D, np.roll(D, -1, axis=1)).sum(axis=1))
    return np.stack([np.einsum("qkc,qc->qk", D, u), np.einsum("qkc,qc->qk", D, w)], axis=2)


def _plane_axes(N):
    """Axes ``(u, w)`` (each (q,3)) of the planes with (Newell) normals ``N``
    (q,3), ``u x w`` along ``N``: ``N`` normalised (in place), ``u`` across
    its smallest component."""
    N /= np.maximum(np.linalg.norm(N, axis=1, keepdims=True), np.finfo(float).tiny)
    u = np.cross(N, np.eye(3)[np.argmin(np.abs(N), axis=1)])
    u /= np.maximum(np.linalg.norm(u, axis=1, keepdims=True), np.finfo(float).tiny)
    return u, np.cross(N, u)


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


def _loops(F, first, k):
    """(sum(k),) the vertex loops ``v0 v1 ... vk-1`` of the polygons whose
    fans start at rows ``first`` (p,) of ``F``, of ``k`` (p,) vertices,
    one after another."""
    start = np.cumsum(k) - k
    pid = np.repeat(np.arange(k.size), k)
    local = np.arange(k.sum()) - start[pid]
    row = first[pid] + np.maximum(local - 2, 0)
    return F[row, np.minimum(local, 2)]


def _clip_in_rounds(V, L, k):
    """(sum(k - 2),3) triangles of the p polygons ``L`` (vertex loops, one
    after another, of ``k`` (p,) vertices each), clipped in rounds in their
    best-fit planes (:func:`_round_of_clips`); each polygon's triangles in
    its rows, in the order clipped (round, then corner). They depend on that
    polygon alone."""
    p, n = k.size, k.sum()
    pid = np.repeat(np.arange(p), k)
    start = np.cumsum(k) - k
    ids = np.arange(n)
    nxt = np.where(ids - start[pid] == k[pid] - 1, start[pid], ids + 1)
    P, tol = _ragged_plane_coords(V[L], pid, start, nxt, p)
    size = np.maximum.reduceat(np.abs(V[L]).max(axis=1), start)
    live = ids
    out, key = [], []
    slow = np.zeros(p, dtype=np.int64)                           # (rounds in a row that clip few)
    stalled = np.zeros(p, dtype=bool)
    for r in range(int(k.max())):
        left = np.bincount(pid[live], minlength=p)
        act = live[(left[pid[live]] > 3) & ~stalled[pid[live]]]
        if act.size == 0:
            break
        T, dead = _round_of_clips(P, tol, size, pid, start, act, left)
        out.append(T)
        key.append(r * n + T[:, 1])
        live = live[~member_of(live, dead)]
        clipped = np.bincount(pid[dead], minlength=p)
        slow = np.where((left > 3) & (clipped < _STALL) & (left - clipped > _SMALL), slow + 1, 0)
        stalled |= slow >= 3
    # the polygons stalled in rounds (a long thin strip winding at every vertex: an ear at
    # each end only): one ear at a time, as the small ones
    done = ~stalled[pid[live]]
    last = live[done].reshape(-1, 3)                             # (3 corners left, each polygon)
    out.append(last)
    key.append(int(k.max()) * n + last[:, 1])
    rest = live[~done]
    if rest.size:
        m = np.bincount(pid[rest], minlength=p)[pid[rest]]
        flat = np.c_[P, np.zeros(n)]                             # (in the plane: z = 0)
        for c in sorted_unique(m):
            loops = rest[m == c].reshape(-1, c)
            out.append(_clip_one_at_a_time(flat, loops).reshape(-1, 3))
            key.append(int(k.max()) * n + np.tile(np.arange(c - 2), loops.shape[0]))
    T, key = np.concatenate(out), np.concatenate(key)
    return L[T[np.lexsort((key, pid[T[:, 1]]))]]


def _ragged_plane_coords(X, pid, start, nxt, p):
    """``(P, tol)``: the coordinates (n,2) of the polygon corners ``X`` (n,3)
    in their polygons' best-fit planes (as :func:`_plane_coords`), and the
    flat-area tolerance (p,) of each polygon."""
    D = X - X[start[pid]]
    c = np.cross(D, D[nxt])
    u, w = _plane_axes(np.stack([np.bincount(pid, weights=c[:, i], minlength=p)
                                 for i in range(3)], axis=1))
    P = np.stack([np.einsum("nc,nc->n", D, u[pid]), np.einsum("nc,nc->n", D, w[pid])], axis=1)
    return P, _FLAT * np.maximum.reduceat((P ** 2).sum(axis=1), start)


def _round_of_clips(P, tol, size, pid, start, act, left):
    """``(T, dead)``: one round's triangles (t,3) (corner ids, tip in the
    middle) and clipped corners, of the polygons whose live corners are
    ``act`` (sorted: each polygon's in loop order; ``left`` (p,) of each).
    Every ear better scored than both neighbouring ears is clipped (one only
    in a quadrilateral), then grown into a fan from its apex, forwards or
    backwards, over the corners that are ears in turn, up to the next clipped
    ear. A polygon with no ear loses its convex corners (or, with none, its
    corners) better scored than both neighbours: it gives ``k - 2``
    triangles in a few rounds, however degenerate. Shapes are compared in
    ``_SHAPES`` steps, ties by a hash of the corner's place in its polygon
    (so a row of equals, or a smooth arc's, loses about a third)."""
    g = pid[act]
    new = np.r_[True, g[1:] != g[:-1]]
    first = np.flatnonzero(new)
    grp = np.cumsum(new) - 1
    pos = np.arange(act.size) - first[grp]
    cnt = left[g]
    at = lambda i, j: first[grp[i]] + (pos[i] + j) % cnt[i]      # (positions in act)
    idx = np.arange(act.size)
    a, b = at(idx, -1), at(idx, 1)
    A, B, C = P[act[a]], P[act], P[act[b]]
    area = _orient(A, B, C)
    sq = sum(((X - Y) ** 2).sum(axis=-1) for X, Y in ((A, B), (B, C), (C, A)))
    shape = np.where(sq > 0, 2 * np.sqrt(3) * area / np.where(sq > 0, sq, 1), 0)
    convex = area > tol[g]
    near = np.sqrt(((A - B) ** 2).sum(axis=1)) + np.sqrt(((C - B) ** 2).sum(axis=1))
    weak = (area > _ROUNDING * size[g] * near) & ~convex         # (convex, below tol: dense)
    length = np.bincount(g, weights=np.sqrt(((C - B) ** 2).sum(axis=1)), minlength=left.size)
    grid = _Blockers(P, pid, act[~convex], left.size, length)
    tri = np.stack([act[a], act, act[b]], 1)
    ear = convex.copy()
    ear[convex] = ~grid.holds(P, tol, pid, tri[convex])
    weak[weak] = ~grid.holds(P, np.zeros_like(tol), pid, tri[weak])   # (exactly: none inside)
    score = np.select([ear, weak, convex], [2, 1.5, 1], 0) + np.floor(shape * _SHAPES) / _SHAPES
    ear |= weak
    lid = act - start[g]
    rank = (lid * 2654435761) % (1 << 32)                       # (ties: a hash of the corner)

    def best(ok):                                               # (than the neighbours that are ok)
        beats = lambda j: ~ok[j] | (score > score[j]) | ((score == score[j]) & (rank > rank[j]))
        return np.flatnonzero(ok & beats(a) & beats(b) & ((cnt > 4) | beats(at(idx, 2))))

    pick = best(ear)
    has_ear = np.bincount(g, weights=ear, minlength=left.size) > 0
    has_convex = np.bincount(g, weights=convex, minlength=left.size) > 0
    rest = best(~has_ear[g] & (convex | ~has_convex[g]))
    fwd, bwd = _fans(P, tol, pid, act, pick, at, cnt, grp, pos, grid)
    T = [np.stack([act[a[rest]], act[rest], act[b[rest]]], 1),
         np.stack([act[a[pick]], act[pick], act[b[pick]]], 1)]
    dead = [act[rest], act[pick]]
    for sign, x in ((1, fwd), (-1, bwd)):                       # (the fans' other triangles)
        e = np.repeat(pick, x)
        j = np.arange(e.size) - np.repeat(np.cumsum(x) - x, x) + 1
        tip = act[at(e, sign * j)]
        T.append(np.stack([act[at(e, -sign)], tip, act[at(e, sign * (j + 1))]][::sign], 1))
        dead.append(tip)
    return np.concatenate(T), np.concatenate(dead)


def _fans(P, tol, pid, act, pick, at, cnt, grp, pos, grid):
    """``(fwd, bwd)`` (s,) each: how many corners past each picked ear
    (positions ``pick`` in ``act``) its fan clips forwards or backwards (one
    of them 0): the corners ``pick + j``, j = 1.., while the triangle
    (apex, corner, next) is an ear (:func:`_fan_lengths`), leaving at least
    one corner (three in all) between neighbouring fans."""
    s = pick.size
    if s == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    gp = grp[pick]
    new = np.r_[True, gp[1:] != gp[:-1]]
    gfirst = np.flatnonzero(new)
    gi = np.cumsum(new) - 1
    ns = np.diff(np.r_[gfirst, s])[gi]                               # (ears in the polygon)
    rank = np.arange(s) - gfirst[gi]
    after = gfirst[gi] + (rank + 1) % ns                             # (the next ear, in pick)
    c = cnt[pick]
    gap_f = np.where(ns == 1, c - 1, (pos[pick[after]] - pos[pick] - 1) % c)
    gap_b = gap_f[gfirst[gi] + (rank - 1) % ns]
    keep = -(-3 // ns)                                               # (corners left in a gap)
    room_f, room_b = np.maximum(gap_f - keep, 0), np.maximum(gap_b - keep, 0)
    fwd = _fan_lengths(P, tol, pid, act, pick, at, room_f, 1, grid)
    bwd = _fan_lengths(P, tol, pid, act, pick, at, room_b, -1, grid)
    use_f = fwd >= bwd
    fwd, bwd = np.where(use_f, fwd, 0), np.where(use_f, 0, bwd)
    over = fwd + bwd[after] - room_f                                 # (a gap's two fans)
    shrink = (over > 0) & (ns > 1)
    bwd[after[shrink]] = np.maximum(bwd[after[shrink]] - over[shrink], 0)
    return fwd, bwd


def _fan_lengths(P, tol, pid, act, pick, at, room, sign, grid):
    """(s,) how many triangles (apex, t_j, t_j+1), j = 1..room, each picked
    ear's fan adds (``sign`` 1: apex the ear's previous corner, t_j the
    j-th corner after the ear, t_0 the ear; -1: the other way round): while
    each faces the polygon's way, the fan turns less than a full turn about
    its apex, and no triangle holds a blocker (found by its angle about the
    apex: the triangles of a fan are sorted by it). Prefixes of 2, 4, 8...
    triangles are tested, so a fan costs about its own size."""
    x = np.zeros(pick.size, np.int64)
    go = np.flatnonzero(room > 0)
    if go.size == 0:
        return x
    # the turn of every candidate triangle about its apex (j = 0..room)
    m = room[go] + 1
    f = np.repeat(np.arange(go.size), m)
    off = np.cumsum(m) - m
    j = np.arange(f.size) - off[f]
    q = pick[go][f]
    apex = act[at(q, -sign)]
    t0, t1 = act[at(q, sign * j)], act[at(q, sign * (j + 1))]
    U, W = P[t0] - P[apex], P[t1] - P[apex]
    cross = U[:, 0] * W[:, 1] - U[:, 1] * W[:, 0]
    turn = sign * np.arctan2(cross, (U * W).sum(axis=1))
    theta = np.cumsum(turn)
    theta -= np.repeat(theta[off] - turn[off], m)                    # (0 at t_0, each fan)
    ok = (sign * cross > tol[pid[apex]]) & (theta < 2 * np.pi - 1e-9)
    ok[off] = True
    bad = np.where(ok, np.iinfo(np.int64).max, j)
    most = np.full(go.size, np.iinfo(np.int64).max)
    np.minimum.at(most, f, bad)
    most = np.minimum(most - 1, room[go])                  # (triangles 1..most face the right way)
    span = np.minimum(2, most)
    live = np.flatnonzero(most > 0)
    while live.size:
        lim = span[live]
        # the blockers near each fan (its box: apex and t_0 .. t_lim+1)
        rows = np.repeat(live, lim + 1)
        idx = (np.repeat(off[live], lim + 1) + np.arange(rows.size)
               - np.repeat(np.cumsum(lim + 1) - (lim + 1), lim + 1))
        pts = np.concatenate([P[apex[idx]], P[t0[idx]], P[t1[idx]]])
        which = np.tile(np.repeat(np.arange(live.size), lim + 1), 3)
        lo = np.full((live.size, 2), np.inf)
        hi = np.full((live.size, 2), -np.inf)
        np.minimum.at(lo, which, pts)
        np.maximum.at(hi, which, pts)
        fi, X = grid.near(pid[apex[off[live]]], lo, hi, tol)
        hit = np.full(live.size, np.iinfo(np.int64).max)
        if fi.size:
            L = live[fi]
            a0 = P[apex[off[L]]]
            V0 = P[t0[off[L]]] - a0
            Y = P[X] - a0
            phi = sign * np.arctan2(V0[:, 0] * Y[:, 1] - V0[:, 1] * Y[:, 0], (V0 * Y).sum(axis=1))
            phi = np.where(phi < 0, phi + 2 * np.pi, phi)
            key = 8.0 * np.searchsorted(live, rows) + theta[idx]
            w = np.searchsorted(key, 8.0 * fi + phi)                 # (wedge: after triangle w-1)
            start = np.searchsorted(rows, L)
            for d in (-1, 0, 1):
                jj = np.clip(w - start + d, 0, lim[fi])
                k = off[L] + jj
                tri = np.stack([apex[k], t0[k], t1[k]][::sign], 1)
                inside = _inside(P, tol, pid, tri, X)
                np.minimum.at(hit, fi[inside], jj[inside])
        done = (hit <= lim) | (lim >= most[live])
        x[go[live]] = np.where(hit <= lim, np.maximum(hit - 1, 0), lim)
        live = live[~done]
        span[live] = np.minimum(2 * span[live], most[live])
    return x


class _Blockers:
    """The corners ``blockers`` (p polygons' flat and reflex corners: only
    these can lie in an ear) in a grid per polygon, over their box: square
    cells ``_PER_CELL`` times the outline's ``length`` (p,) over its
    blockers wide (a few blockers a cell along the outline), but no more
    than 16 cells a blocker nor fewer than one; each cell's blockers one
    after another (``order``, from ``first``)."""

    def __init__(self, P, pid, blockers, p, length):
        self.corner = blockers
        bp = pid[blockers]
        Q = P[blockers]
        nb = np.bincount(bp, minlength=p)
        lo = np.full((p, 2), np.inf)
        hi = np.full((p, 2), -np.inf)
        np.minimum.at(lo, bp, Q)
        np.maximum.at(hi, bp, Q)
        ext = np.where(nb[:, None] > 0, hi - lo, 0)
        cells = np.maximum(nb, 1)
        even = np.maximum(np.sqrt(ext[:, 0] * ext[:, 1] / cells), ext.max(axis=1) / cells)
        h = np.clip(_PER_CELL * length / cells, even / 4, even)
        self.h = np.where(h > 0, h, 1.0)
        self.lo = np.where(nb[:, None] > 0, lo, 0)
        self.dims = np.where(nb[:, None] > 0,
                             np.floor(ext / self.h[:, None]).astype(np.int64) + 1, 0)
        size = self.dims[:, 0] * self.dims[:, 1]
        self.base = np.cumsum(size) - size
        cell = np.minimum(np.floor((Q - self.lo[bp]) / self.h[bp, None]).astype(np.int64),
                          self.dims[bp] - 1)
        key = self.base[bp] + cell[:, 1] * self.dims[bp, 0] + cell[:, 0]
        self.order = blockers[np.argsort(key, kind="stable")]
        self.count = np.bincount(key, minlength=int(size.sum()))
        self.first = np.cumsum(self.count) - self.count

    def near(self, poly, lo, hi, tol):
        """``(box, corner)``: the blockers of polygon ``poly`` (b,) in the
        cells that the boxes ``lo``..``hi`` (b,2) each meet, padded by the
        square root of the polygon's tolerance."""
        pad = np.sqrt(tol[poly])[:, None]
        c0 = np.floor((lo - pad - self.lo[poly]) / self.h[poly, None]).astype(np.int64)
        c1 = np.floor((hi + pad - self.lo[poly]) / self.h[poly, None]).astype(np.int64)
        c0, c1 = np.maximum(c0, 0), np.minimum(c1, self.dims[poly] - 1)
        span = np.maximum(c1 - c0 + 1, 0)
        n = span[:, 0] * span[:, 1]
        b = np.repeat(np.arange(poly.size), n)
        o = np.arange(b.size) - np.repeat(np.cumsum(n) - n, n)
        key = (self.base[poly[b]] + (c0[b, 1] + o // span[b, 0]) * self.dims[poly[b], 0]
               + c0[b, 0] + o % span[b, 0])
        m = self.count[key]
        box = np.repeat(b, m)
        o = np.arange(box.size) - np.repeat(np.cumsum(m) - m, m)
        return box, self.order[np.repeat(self.first[key], m) + o]

    def holds(self, P, tol, pid, tri):
        """(t,) whether the closed triangles ``tri`` (t,3) (corner ids, in
        the polygon's winding; areas within tol of 0 count as inside) hold
        a blocker of their polygon other than their own corners: first the
        blockers in the cells of 15 points spread over the triangle
        (:data:`_PROBES`: most triangles that hold one are found there),
        then in every cell the triangle meets (row by row)."""
        held = np.zeros(tri.shape[0], dtype=bool)
        if self.corner.size == 0 or tri.shape[0] == 0:
            return held
        T = P[tri]
        poly = pid[tri[:, 1]]
        probe = _PROBES @ T                                             # (t,15,2)
        t, c = np.repeat(np.arange(tri.shape[0]), len(_PROBES)), probe.reshape(-1, 2)
        t, c = t[self.dims[poly[t], 0] > 0], c[self.dims[poly[t], 0] > 0]   # (polygons with some)
        cell = np.floor((c - self.lo[poly[t]]) / self.h[poly[t], None]).astype(np.int64)
        cell = np.clip(cell, 0, np.maximum(self.dims[poly[t]] - 1, 0))
        key = self.base[poly[t]] + cell[:, 1] * self.dims[poly[t], 0] + cell[:, 0]
        n = self.count.size
        key = sorted_unique(t * n + key)                                 # (a cell once a triangle)
        box, X = self._in_cells(key // n, key % n)
        held[box[_inside(P, tol, pid, tri[box], X)]] = True
        rest = np.flatnonzero(~held)
        t, key = self._cells_met(T[rest], poly[rest], tol)
        box, X = self._in_cells(rest[t], key)
        held[box[_inside(P, tol, pid, tri[box], X)]] = True
        return held

    def _in_cells(self, box, key):
        """``(box, corner)``: the blockers in the cells ``key`` of ``box``."""
        m = self.count[key]
        b = np.repeat(box, m)
        o = np.arange(b.size) - np.repeat(np.cumsum(m) - m, m)
        return b, self.order[np.repeat(self.first[key], m) + o]

    def _cells_met(self, T, poly, tol):
        """``(triangle, cell)``: the cells (keys) each triangle ``T`` (t,3,2)
        of polygon ``poly`` meets, padded by the square root of the
        polygon's tolerance: each row's cells between the triangle's
        leftmost and rightmost points in that row."""
        h = self.h[poly]
        G = (T - self.lo[poly][:, None]) / h[:, None, None]
        pad = np.sqrt(tol[poly]) / h
        y0, y1 = G[:, :, 1].min(axis=1) - pad, G[:, :, 1].max(axis=1) + pad
        r0 = np.maximum(np.floor(y0), 0).astype(np.int64)
        r1 = np.minimum(np.floor(y1).astype(np.int64), self.dims[poly, 1] - 1)
        n = np.maximum(r1 - r0 + 1, 0)
        t = np.repeat(np.arange(poly.size), n)
        row = r0[t] + np.arange(t.size) - np.repeat(np.cumsum(n) - n, n)
        b0, b1 = np.maximum(row, y0[t]), np.minimum(row + 1, y1[t])
        x0 = np.full(t.size, np.inf)
        x1 = np.full(t.size, -np.inf)
        for e in range(3):
            U, W = G[t, e], G[t, (e + 1) % 3]
            lo_y = np.minimum(U[:, 1], W[:, 1]) - pad[t]
            hi_y = np.maximum(U[:, 1], W[:, 1]) + pad[t]
            c0, c1 = np.maximum(b0, lo_y), np.minimum(b1, hi_y)
            meets = c0 <= c1
            dy = W[:, 1] - U[:, 1]
            flat = np.abs(dy) < 1e-300
            left, right = np.minimum(U[:, 0], W[:, 0]), np.maximum(U[:, 0], W[:, 0])
            for y in (c0, c1):
                x = U[:, 0] + (y - U[:, 1]) * (W[:, 0] - U[:, 0]) / np.where(flat, 1, dy)
                x = np.clip(x, left, right)
                x0 = np.where(meets, np.minimum(x0, np.where(flat, left, x)), x0)
                x1 = np.where(meets, np.maximum(x1, np.where(flat, right, x)), x1)
        k0 = np.maximum(np.floor(x0 - pad[t]), 0)
        k1 = np.minimum(np.floor(x1 + pad[t]), self.dims[poly[t], 0] - 1)
        m = np.where(np.isfinite(k0) & np.isfinite(k1), np.maximum(k1 - k0 + 1, 0), 0)
        m = m.astype(np.int64)
        k0 = np.where(m > 0, k0, 0).astype(np.int64)
        tt = np.repeat(t, m)
        col = np.repeat(k0, m) + np.arange(tt.size) - np.repeat(np.cumsum(m) - m, m)
        return tt, self.base[poly[tt]] + np.repeat(row, m) * self.dims[poly[tt], 0] + col


def _inside(P, tol, pid, tri, X):
    """(t,) whether the corners ``X`` (t,) lie in the closed triangles
    ``tri`` (t,3) (areas within their polygon's tolerance of 0 count), and
    are none of their corners."""
    T, Y, t = P[tri], P[X], -tol[pid[X]]
    return ((_orient(T[:, 0], T[:, 1], Y) >= t) & (_orient(T[:, 1], T[:, 2], Y) >= t)
            & (_orient(T[:, 2], T[:, 0], Y) >= t) & (X != tri[:, 0]) & (X != tri[:, 1])
            & (X != tri[:, 2]))
