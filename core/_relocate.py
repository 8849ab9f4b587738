"""Final vertex relocation of a simplified cage towards the original surface.

After the collapses, every movable cage vertex is moved to reduce the squared
distance between the cage and the original surface in both directions
(symmetric ICP, with the correspondences fixed per iteration)::

    repeat iters times:
        forward:  (f_s, b_s) = closest cage face and barycentrics of each
                  input point p_s (surface samples, plus the input's crease
                  vertices); each input border vertex to its closest cage
                  border edge
        backward: x_t = fixed barycentric points b_t on every cage face f_t,
                  q_t = their closest points on the input surface, each row
                  weighted by the cage area it stands for (only when the
                  caller passes the input surface)
        minimise  sum_s |sum_c b_sc v[F[f_s, c]] - p_s|^2
                + sum_t w_t |sum_c b_tc v[F[f_t, c]] - q_t|^2
                + sum_j l_j |v_j - v0_j|^2
                  (conjugate gradients on the normal equations, per coordinate)
        undo the move of every vertex of a face that would flip, degenerate
        or become a sliver

The forward term alone cannot see a cage face that spans a gap of the input
(no input point is closest to it); the backward term pulls such faces in.
The input's border is matched to the cage's border edges both ways, so borders
follow the input's instead of drifting with the surface. Locked vertices (the
caller's and frozen non-manifold ones) do not move.

Every closest point is found by walking over the mesh searched
(:class:`~._face_tracker.FaceTracker`): the first round starts each input
point at the cage vertex it was merged into, and each cage point at the input
vertex nearest to it among those merged into its face's corners; later rounds
start from the last round's answers, which the small moves of a round rarely
change. No index of the whole input is built. The walks give the exact
closest points wherever the start lies on the near side (the engine's merges
put it there); where a thin part of the cage or input folds back, a few end
on a local minimum instead.
"""

import numpy as np

from ._collapse import compactness
from ._face_tracker import FaceTracker
from ._groups import group_argmin, ragged_ranges, sorted_unique, stable_argsort
from .cg import conjugate_gradient
from .mesh import (area_normals_rows, barycentric_gather, barycentric_scatter, mean_edge_length,
                   squared_edges)

#: the relocation's solves stop early only once converged this far (they run
#: ``cg_iters`` steps otherwise: a few steps are enough to move towards the samples)
CG_RTOL = 1e-10


def _gather(idx, b, x):
    """B x: the barycentric combinations (s,3) of rows of ``x`` (n,3), with
    ``idx`` (3, s) the three vertices of each row and ``b`` (3, s) their weights."""
    return barycentric_gather(x, idx.T, b.T)


def normal_blocks(group, b, n_groups):
    """B^T B of the sample-to-cage operator B (see ``_gather``) as one
    symmetric 3x3 block per triangle: ``M[:, :, g] = sum of b b^T`` over the
    rows ``b`` (3,s) on triangle ``group`` (s,). (3, 3, n_groups) float64,
    each entry's values contiguous. With the blocks a product costs the
    triangles, not the (many more) rows."""
    M = np.empty((3, 3, n_groups))
    for i in range(3):
        for j in range(i, 3):
            M[i, j] = np.bincount(group, weights=b[i] * b[j], minlength=n_groups)
            M[j, i] = M[i, j]
    return M


def block_matvec(G, M, x, lam):
    """(B^T B + diag(lam)) x from the blocks ``M`` of :func:`normal_blocks`
    on the triangles ``G`` (3,g) (row c: corner c of every triangle, in the
    rows' order); ``x`` (n,d), returns (n,d)."""
    n = x.shape[0]
    xT = np.ascontiguousarray(x.T)
    out = lam * xT                                                # (d, n)
    for d in range(x.shape[1]):
        X0, X1, X2 = (xT[d].take(G[c]) for c in range(3))
        for c in range(3):
            y = M[c, 0] * X0
            y += M[c, 1] * X1
            y += M[c, 2] * X2
            out[d] += np.bincount(G[c], weights=y, minlength=n)
    return np.ascontiguousarray(out.T)


def _compactness(V, F, l):
    """Compactness (``core._collapse.compactness``) of each face, given ``l`` =
    twice the areas."""
    return compactness(l, squared_edges(V, F).sum(axis=1))


#: barycentric points of each cage face for the backward term: the centroid and
#: the three points halfway from it to each corner
_BACK_BARY = np.array([[2.0, 2.0, 2.0], [4.0, 1.0, 1.0], [1.0, 4.0, 1.0], [1.0, 1.0, 4.0]]) / 6.0


def _back_rows(V, F, surface, total, cage_of=None):
    """Rows of the backward term: (idx (3,r), b (3,r), targets (r,3), the
    cage face of each (r,)), each row scaled by the square root of its weight
    (``total`` shared out by the area each point stands for) so it can join
    the forward rows unchanged. ``surface`` is a :class:`FaceTracker` of the
    input; on its first call the search for each point starts at the input
    vertex nearest to it among those merged into its face's corners
    (``cage_of``, see :func:`_merged_nearest`), or is exact (``None``)."""
    m, k = F.shape[0], _BACK_BARY.shape[0]
    idx = np.repeat(F.T, k, axis=1)                                   # (3, m*k)
    b = np.tile(_BACK_BARY.T, (1, m))                                 # (3, m*k)
    X = _gather(idx, b, V)
    near = None
    if surface.face is None and cage_of is not None:
        near = _merged_nearest(X, F, _BACK_BARY, V.shape[0], surface.V, cage_of)
    T = surface.closest(X, near).point
    area = np.linalg.norm(area_normals_rows(V, F.T), axis=1)
    w = np.sqrt(np.repeat(area * (total / max(k * float(area.sum()), 1e-300)), k))
    return idx, b * w, T * w[:, None], np.repeat(np.arange(m, dtype=np.int64), k)


def _merged_nearest(X, F, bary, n, Vin, cage_of):
    """For each point in ``X`` (m*k,3) (k per cage face, face by face, at the
    barycentrics ``bary`` (k,3)), the input vertex nearest to it among those
    merged into the corners of its face with the largest weight (all three
    for a centroid): ``cage_of`` (n_in,) is the cage vertex (of ``n``) each
    input vertex went to, -1 for none (or not to be used). (m*k,) int64, -1
    where no input vertex went to those corners."""
    ok = np.flatnonzero(cage_of >= 0)
    members = ok[stable_argsort(cage_of[ok])]                          # cage vertex by vertex
    count = np.bincount(cage_of[ok], minlength=n)
    j, c = np.nonzero(bary == bary.max(axis=1, keepdims=True))       # point j looks at corner c
    m, k = F.shape[0], bary.shape[0]
    corners = F[:, c].ravel()                                          # face by face
    at, own = ragged_ranges((np.cumsum(count) - count)[corners], count[corners])
    point = (np.arange(m)[:, None] * k + j).ravel()[own]
    cand = members[at]
    d2 = np.zeros(cand.size)
    for a, x in zip(Vin.T, X.T):
        d = a.take(cand) - x.take(point)
        d *= d
        d2 += d
    out = np.full(m * k, -1, dtype=np.int64)
    per = np.bincount(point, minlength=m * k)
    out[per > 0] = cand[group_argmin(d2, per[per > 0])]
    return out


#: barycentric points of each cage border edge (as a segment triangle) for the
#: backward border term: a quarter, half and three quarters along
_SEG_BARY = np.array([[0.75, 0.25, 0.0], [0.5, 0.5, 0.0], [0.25, 0.75, 0.0]])


def segment_triangles(E):
    """Edges (k,2) as zero-area triangles (k,3) ``(a, b, b)``, so the
    closest-point searches (:class:`FaceTracker`, :class:`~.spatial.TriangleIndex`)
    find closest points on polylines."""
    return np.concatenate([E, E[:, 1:]], axis=1)


def _border_rows(V, C, cage, surface, weight, near=None, cage_of=None):
    """Rows tying the cage's border edges to the input's border: each input
    border point ``C`` to its closest cage border edge (forward; ``cage`` a
    :class:`FaceTracker` of the cage's border edges as
    :func:`segment_triangles`, its searches started at ``near`` on the first
    call), and points along every cage border edge to the closest input
    border edge (backward, ``surface`` the input's, first searched from the
    input border vertices merged into the edge's ends, ``cage_of`` -1 for
    the others: see :func:`_merged_nearest`; as much weight in all as the
    forward rows, shared by length). Returns (idx (3,r), b (3,r),
    targets (r,3), the border edge of each (r,)), rows pre-scaled by the
    square roots of their weights."""
    T3 = cage.F
    cage.place(V)
    cp = cage.closest(C, near)
    idx_f = np.take(T3, cp.face, axis=0).T
    b_f = cp.bary.T * np.sqrt(weight)
    k = _SEG_BARY.shape[0]
    idx_b = np.repeat(T3.T, k, axis=1)
    b_b = np.tile(_SEG_BARY.T, (1, T3.shape[0]))
    X = _gather(idx_b, b_b, V)
    start = None
    if surface.face is None and cage_of is not None:
        start = _merged_nearest(X, T3, _SEG_BARY, V.shape[0], surface.V, cage_of)
    Tb = surface.closest(X, start).point
    length = np.linalg.norm(V[T3[:, 1]] - V[T3[:, 0]], axis=1)
    w = np.sqrt(np.repeat(length * (weight * C.shape[0] / max(k * float(length.sum()), 1e-300)), k))
    return (np.concatenate([idx_f, idx_b], axis=1), np.concatenate([b_f, b_b * w], axis=1),
            np.concatenate([C * np.sqrt(weight), Tb * w[:, None]]),
            np.concatenate([cp.face, np.repeat(np.arange(T3.shape[0], dtype=np.int64), k)]))


class _Pulls:
    """The terms of one relocation: the closest-point searches, kept from
    round to round (:class:`FaceTracker`), and the rows they give."""

    def __init__(self, F, n, P, P_near, surface, back, cage_of, border, border_near, steps):
        self.F, self.P, self.P_near, self.cage_of = F, P, P_near, cage_of
        self.forward = FaceTracker(F, n, steps)
        self.backward = None
        if surface is not None and back > 0.0:
            self.backward = FaceTracker(surface[1], surface[0].shape[0], steps)
            self.backward.place(surface[0])
            self.back_total = back * P.shape[0]
        self.border = None
        if border is not None and border[1].shape[0] and border[0].shape[0]:
            C, Eb, (Vin, Sin), weight = border
            cage = FaceTracker(segment_triangles(Eb), n, steps)
            inside = FaceTracker(Sin, Vin.shape[0], steps)
            inside.place(Vin)
            on = None
            if cage_of is not None:               # only the input's border vertices
                on = np.full(cage_of.shape[0], -1, dtype=np.int64)
                on[Sin.ravel()] = cage_of[Sin.ravel()]
            self.border = (C, cage, inside, weight, border_near, on)

    def rows(self, V):
        """Rows of every term for the cage at ``V`` (idx (3,r), b (3,r),
        targets (r,3), the triangle of each (r,)) and the triangles (g,3)."""
        F = self.F
        self.forward.place(V)
        cp = self.forward.closest(self.P, self.P_near)
        # (3,s) vertices, (3,s) weights, targets, and the triangle of each row
        rows = [(np.take(F, cp.face, axis=0).T, cp.bary.T, self.P, cp.face)]
        tris = [F]
        if self.backward is not None:
            rows.append(_back_rows(V, F, self.backward, self.back_total, self.cage_of))
        if self.border is not None:
            idx, b, T, group = _border_rows(V, *self.border)
            rows.append((idx, b, T, group + F.shape[0]))
            tris.append(self.border[1].F)
        return rows, np.concatenate(tris)


def relocate(V, F, P, movable, *, iters=2, cg_iters=15, reg=0.05, min_cos=0.2, N_keep=None,
             surface=None, back=0.0, border=None, min_compact=0.0, min_move=0.0,
             P_near=None, cage_of=None, border_near=None, walk_steps=8):
    """Move ``movable`` vertices of the cage ``(V, F)`` towards points ``P``.

    Parameters
    ----------
    V : (n,3) float64 cage vertices (not modified).
    F : (m,3) int64 cage faces.
    P : (s,3) float64 points on the original surface.
    movable : (n,) bool.
    iters : int, correspondence updates (at most: see ``min_move``).
    cg_iters : int, conjugate-gradient steps per update.
    reg : float, weight pulling each vertex to its current position, relative
        to the vertex's own sample weight (unit-free).
    min_cos : float, a moved face whose normal turns by more than
        ``acos(min_cos)`` is undone.
    N_keep : (m,3) float64 or None, reference normals: a moved face whose normal
        ends more than 90 degrees from its row is undone too (the caller passes
        the summed input normals each face stands for).
    min_compact : float, a moved face less compact than this (``4 sqrt(3) area /
        sum of squared edges``, 1 for equilateral) and than half its own
        compactness before is undone too (no new slivers).
    surface : None (no backward term) or the input surface ``(Vin, Fin)``
        ((n_in,3) float64, (m_in,3) int64).
    back : float, weight of the backward term: the cage's whole area counts
        ``back`` times as much as all the forward points together.
    border : None or (C (c,3) input border points, Eb (k,2) cage border edges,
        the input's border edges as ``(Vin, segment_triangles(E_in))``,
        weight per point): ties the cage's borders to the input's in both
        directions.
    min_move : float, stop once an update moves no vertex farther than this
        share of the cage's mean edge length (it has settled: a flat cage on
        a flat input does not move at all).
    P_near : (s,) int64 or None, a cage vertex near each point of ``P`` (the
        one its input vertex was merged into; -1: unknown), where the search
        for its closest cage face starts (else: an exact search).
    cage_of : (n_in,) int64 or None, the cage vertex each input vertex was
        merged into (-1: none): the backward term's search for the input
        point closest to a cage point starts among the input vertices merged
        into its face's corners (else: an exact search).
    border_near : (c,) int64 or None, as ``P_near`` for the border points ``C``.
    walk_steps : int, the searches then walk over the meshes, and in every
        later update from the last answers, at most this many steps
        (:class:`~._face_tracker.FaceTracker`).

    Returns
    -------
    (n,3) float64 new positions.
    """
    V = V.copy()
    n = V.shape[0]
    if not movable.any() or F.shape[0] == 0 or P.shape[0] == 0:
        return V
    N_ref = area_normals_rows(V, F.T)
    g0 = _compactness(V, F, np.linalg.norm(N_ref, axis=1))  # of the cage as it came
    settled = min_move * mean_edge_length(V, F)
    pulls = _Pulls(F, n, P, P_near, surface, back, cage_of, border, border_near, walk_steps)
    for _ in range(iters):
        rows, G = pulls.rows(V)
        D = _solve(V, rows, G, movable, reg, cg_iters)
        D = _undo_bad_moves(V, F, D, N_ref, g0, N_keep, min_cos, min_compact)
        V = V + D
        if np.abs(D).max() <= settled:
            break
    return V


def _solve(V, rows, G, movable, reg, cg_iters):
    """The displacement D (n,3) of the cage vertices ``V`` that minimises the
    squared residuals of ``rows`` (idx (3,r), b (3,r), targets (r,3), the
    triangle of ``G`` (g,3) of each) plus ``lam_j |D_j|^2`` (``lam`` ``reg``
    times each vertex's own row weight plus the mean), ``cg_iters`` steps of
    conjugate gradients on the normal equations; D = 0 where not ``movable``."""
    n = V.shape[0]
    idx = np.concatenate([r[0] for r in rows], axis=1)   # C-contiguous copies
    b = np.concatenate([r[1] for r in rows], axis=1)
    T = np.concatenate([r[2] for r in rows])
    M = normal_blocks(np.concatenate([r[3] for r in rows]), b, G.shape[0])
    diag = np.bincount(idx.ravel(), weights=(b * b).ravel(), minlength=n)
    lam = reg * diag + reg * max(float(diag.mean()), 1e-300)
    lam[~movable] = 1e30  # pinned
    # solve (B^T B + lam) D = B^T (T - B V) for the displacement D by CG
    r = barycentric_scatter(T - _gather(idx, b, V), idx.T, b.T, n)
    r[~movable] = 0.0
    GT = np.ascontiguousarray(G.T)
    D = conjugate_gradient(lambda X: block_matvec(GT, M, X, lam), r, rtol=CG_RTOL,
                           max_iterations=cg_iters).X
    D[~movable] = 0.0
    return D


def _undo_bad_moves(V, F, D, N_ref, g0, N_keep, min_cos, min_compact):
    """``D`` with the moves of every vertex of a face that would flip (turn by
    more than ``acos(min_cos)`` from ``N_ref``, or end more than 90 degrees
    from ``N_keep``) or become a new sliver undone (sweeps: undoing can expose
    others, among the faces around the vertices it stopped; each sweep zeroes
    at least one move, and no move at all is valid)."""
    l0 = np.linalg.norm(N_ref, axis=1)
    faces = np.arange(F.shape[0])
    ring = None
    while faces.size:
        Fs = F[faces]
        Vn = V + D
        N1 = area_normals_rows(Vn, Fs.T)
        l1 = np.linalg.norm(N1, axis=1)
        bad = np.einsum("ij,ij->i", N_ref[faces], N1) <= min_cos * l0[faces] * l1
        if N_keep is not None:
            bad |= np.einsum("ij,ij->i", N_keep[faces], N1) <= 0.0
        if min_compact > 0.0:
            g1 = _compactness(Vn, Fs, l1)
            bad |= (g1 < min_compact) & (g1 < 0.5 * g0[faces])
        bad &= np.any(D[Fs] != 0.0, axis=(1, 2))
        if not bad.any():
            break
        stopped = sorted_unique(Fs[bad])
        D[stopped] = 0.0
        if ring is None:
            ring = stable_argsort(F.ravel()) // 3, np.bincount(F.ravel(), minlength=V.shape[0])
        at, _ = ragged_ranges((np.cumsum(ring[1]) - ring[1])[stopped], ring[1][stopped])
        faces = sorted_unique(ring[0][at])
    return D
