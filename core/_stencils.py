"""Per-level topology and stencil tables for :mod:`core.subdivide` (private).

Everything here works on whole arrays, so no Python loop ever runs over
vertices, edges or faces; the only loops run over the few distinct valences of
extraordinary vertices, over the ``log2(valence)`` pointer-jumping passes and
over the handful of stencil slots.

* Level 0: one stable sort of the half-edge keys gives the edge map (the same
  numbering as :func:`core.topology.edge_map`) and each edge's faces (as
  :func:`core.topology.edge_faces`); the manifold checks run there.
* Finer levels: :func:`refine_topology` derives the fine edge map, face-edge
  map and edge faces from the coarse ones by construction (no sort of the
  fine mesh).
* One-rings of extraordinary vertices are put in rotational order by pointer
  jumping (list ranking) along the "next face around the vertex" map.
* Stencil rows are assembled by a counting scatter into CSR (rows sorted).

Corner ``x = 3 f + c`` is corner ``c`` of face ``f``; the half-edge "opposite
corner ``x``" runs ``F[f, c+1] -> F[f, c+2]`` (indices mod 3), the same
numbering as ``face_edge`` in :mod:`core.topology`.
"""

from typing import NamedTuple

import numpy as np

from .errors import InvalidArgumentError, InvalidMeshError


_NEXT = np.array([1, 2, 0], dtype=np.int64)


def _succ(x):
    """The corner after ``x`` in its face (``c -> c+1 mod 3``)."""
    return x - x % 3 + _NEXT[x % 3]


class Stencil(NamedTuple):
    """One subdivision level as a sparse matrix in CSR form (rows sorted).

    Row ``i`` (a fine vertex) is ``sum(weights[j] * X[cols[j]])`` for ``j`` in
    ``indptr[i]:indptr[i+1]``. Every row has at least one entry and sums to 1;
    a row may name a column twice (the weights add).
    """

    indptr: np.ndarray   #: (n_out+1,) int64
    cols: np.ndarray     #: (nnz,) int64, coarse vertex of each entry
    weights: np.ndarray  #: (nnz,) float64
    n_in: int

    @property
    def n_out(self):
        return self.indptr.shape[0] - 1

    def rows(self):
        """Row of each entry, (nnz,) int64."""
        return np.repeat(np.arange(self.n_out, dtype=np.int64), np.diff(self.indptr))

    def apply_t(self, Xt):
        """Column-major apply: ``Xt`` (k, n_in) C-contiguous -> (k, n_out)."""
        out = np.empty((Xt.shape[0], self.n_out))
        if self.n_out == 0:
            return out
        starts = self.indptr[:-1]
        for d in range(Xt.shape[0]):
            g = Xt[d][self.cols]
            g *= self.weights
            out[d] = np.add.reduceat(g, starts)
        return out

    def apply_transpose_t(self, Gt, rows=None):
        """Column-major adjoint: ``Gt`` (k, n_out) -> (k, n_in)."""
        rows = self.rows() if rows is None else rows
        out = np.empty((Gt.shape[0], self.n_in))
        for d in range(Gt.shape[0]):
            out[d] = np.bincount(self.cols, weights=self.weights * Gt[d][rows], minlength=self.n_in)
        return out

    def apply(self, X):
        """``X`` (n_in, k) float64 -> (n_out, k)."""
        return self.apply_t(np.ascontiguousarray(X.T)).T

    def apply_transpose(self, G):
        """``G`` (n_out, k) float64 -> (n_in, k), the exact adjoint of :meth:`apply`."""
        return self.apply_transpose_t(np.ascontiguousarray(G.T)).T


class Topology(NamedTuple):
    """What one level needs to know about its mesh."""

    F: np.ndarray          #: (m,3) int64
    n: int
    E: np.ndarray          #: (e,2) int64, sorted rows, lexicographic (core.topology.edge_map)
    face_edge: np.ndarray  #: (m,3) int64
    faces: np.ndarray      #: (e,2) int64, the faces of each edge (-1 missing)
    corners: np.ndarray    #: (e,2) int64, the corner opposite the edge in those faces
    opp: np.ndarray        #: (3m,) int64, corner opposite the same edge in the other face, -1 on the boundary
    sharp: np.ndarray      #: (e,) bool, boundary or crease edge
    crease: np.ndarray     #: (e,) bool, tagged crease edge (a subset of sharp, boundary excluded or not)
    n_sharp: np.ndarray    #: (n,) int64, sharp edges at each vertex
    valence: np.ndarray    #: (n,) int64, edges at each vertex
    nb_sum: np.ndarray     #: (n,) int64, sum of the sharp neighbours (the other one is nb_sum - known)


def _edge_keys(E, n):
    return E[:, 0] * np.int64(max(n, 1)) + E[:, 1]


def crease_edge_ids(creases, E, n, where):
    """Indices into ``E`` of the undirected vertex pairs ``creases``.

    Raises InvalidArgumentError when a pair is not an edge."""
    if creases is None:
        return np.zeros(0, dtype=np.int64)
    C = np.asarray(creases)
    if C.size == 0:
        return np.zeros(0, dtype=np.int64)
    if C.ndim != 2 or C.shape[1] != 2 or not np.issubdtype(C.dtype, np.integer):
        raise InvalidArgumentError(
            f"{where}: creases must be a (k,2) integer array of vertex pairs, got {C.shape} {C.dtype}")
    C = C.astype(np.int64)
    lo, hi = np.minimum(C[:, 0], C[:, 1]), np.maximum(C[:, 0], C[:, 1])
    keys = lo * np.int64(max(n, 1)) + hi
    ekeys = _edge_keys(E, n)
    pos = np.searchsorted(ekeys, keys)
    pos_c = np.minimum(pos, max(ekeys.shape[0] - 1, 0))
    ok = (lo >= 0) & (hi < n) & (pos < ekeys.shape[0])
    ok &= ekeys[pos_c] == keys if ekeys.shape[0] else False
    if not np.all(ok):
        i = int(np.flatnonzero(~ok)[0])
        raise InvalidArgumentError(
            f"{where}: creases must be edges of F, e.g. pair {i} = {C[i].tolist()} is not an edge")
    return np.unique(pos)


def fan_ranks(F, opp, corner_ids, where=None, rank=True):
    """Rotational order of the corners around their vertices.

    ``corner_ids`` must hold *all* corners of a set of vertices. Going
    counter-clockwise around vertex ``v = F[f, c]`` (seen from the side the
    normals point to), the face after ``f`` is the one across the edge
    ``(v, F[f, c+2])``. Each vertex's corners form one chain (boundary
    vertex, starting at the face whose edge ``(v, F[f, c+1])`` is a boundary
    edge) or one cycle (interior vertex, started at its smallest corner id).

    Returns
    -------
    rank : (q,) int64, position of each corner in its fan, 0 at the head
        (None when ``rank`` is False: only the manifold check is wanted).
    head : (q,) bool, fan heads.
    Raises InvalidMeshError (when ``where`` is given) if a vertex has more
    than one fan (non-manifold vertex).
    """
    q = corner_ids.shape[0]
    if q == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=bool)
    Ff = F.ravel()
    local = np.full(Ff.shape[0], -1, dtype=np.int64)
    local[corner_ids] = np.arange(q, dtype=np.int64)
    t = opp[_succ(corner_ids)]
    has = t >= 0
    nxt = np.full(q, -1, dtype=np.int64)
    nxt[has] = local[_succ(t[has])]
    prv = np.full(q, -1, dtype=np.int64)
    prv[nxt[has]] = np.flatnonzero(has)
    me = np.arange(q, dtype=np.int64)
    verts = Ff[corner_ids]
    max_fan = int(np.bincount(verts).max())
    passes = max(1, int(np.ceil(np.log2(max_fan))) + 1)
    # smallest corner of each cycle; chains run to their tail (nxt == -1)
    p = np.where(has, nxt, me)
    lab = me.copy()
    for _ in range(passes):
        lab = np.minimum(lab, lab[p])
        p = p[p]
    in_chain = nxt[p] < 0
    head = np.where(in_chain, prv < 0, lab == me)
    if where is not None:
        heads_per_vertex = np.bincount(verts[head], minlength=int(verts.max()) + 1)
        bad = np.flatnonzero(heads_per_vertex > 1)
        if bad.size:
            raise InvalidMeshError(
                f"{where}: {bad.size} non-manifold vertices (their faces form more than one fan), "
                f"e.g. vertex {bad[0]}")
    if not rank:
        return None, head
    # list ranking along prv, cut at the heads
    pred = np.where(head, me, prv)
    rank = (~head).astype(np.int64)
    for _ in range(passes):
        rank = rank + rank[pred]
        pred = pred[pred]
    return rank, head


def _edge_map_faces(F, n):
    """``core.topology.edge_map`` plus ``edge_faces`` from one stable sort."""
    m = F.shape[0]
    half = F[:, [1, 2, 2, 0, 0, 1]].reshape(-1, 2)
    lo = np.minimum(half[:, 0], half[:, 1])
    hi = np.maximum(half[:, 0], half[:, 1])
    nn = np.int64(max(n, 1))
    key = lo * nn + hi
    order = np.argsort(key, kind="stable")
    sk = key[order]
    first = np.ones(sk.shape[0], dtype=bool)
    first[1:] = sk[1:] != sk[:-1]
    starts = np.flatnonzero(first)
    e = starts.shape[0]
    eid = np.cumsum(first) - 1
    FE = np.empty(3 * m, dtype=np.int64)
    FE[order] = eid
    cnt = np.diff(np.append(starts, sk.shape[0]))
    uniq = sk[starts]
    E = np.stack([uniq // nn, uniq % nn], axis=1)
    faces = np.full((e, 2), -1, dtype=np.int64)
    corners = np.full((e, 2), -1, dtype=np.int64)
    h0 = order[starts]
    faces[:, 0], corners[:, 0] = h0 // 3, h0 % 3
    has2 = cnt >= 2
    h1 = order[starts[has2] + 1]
    faces[has2, 1], corners[has2, 1] = h1 // 3, h1 % 3
    return E, FE.reshape(m, 3), cnt, faces, corners


def _opp(faces, corners, m):
    two = faces[:, 1] >= 0
    h0 = 3 * faces[two, 0] + corners[two, 0]
    h1 = 3 * faces[two, 1] + corners[two, 1]
    opp = np.full(3 * m, -1, dtype=np.int64)
    opp[h0] = h1
    opp[h1] = h0
    return opp


def topology(F, n, crease_ids, where, check):
    """Edge map, half-edge twins, sharp edges and vertex classes of one level.

    ``crease_ids`` are indices into this level's ``E``. With ``check``,
    raises InvalidMeshError on degenerate faces, non-manifold edges,
    inconsistent orientation and non-manifold vertices.
    """
    m = F.shape[0]
    if check and m:
        deg = np.flatnonzero((F[:, 0] == F[:, 1]) | (F[:, 1] == F[:, 2]) | (F[:, 0] == F[:, 2]))
        if deg.size:
            raise InvalidMeshError(
                f"{where}: {deg.size} degenerate faces (a repeated vertex), e.g. face {deg[0]} = "
                f"{F[deg[0]].tolist()}")
    E, FE, cnt, faces, corners = _edge_map_faces(F, n)
    e = E.shape[0]
    if check:
        bad = np.flatnonzero(cnt > 2)
        if bad.size:
            k = bad[0]
            raise InvalidMeshError(
                f"{where}: {bad.size} non-manifold edges (used by more than two faces), "
                f"e.g. ({E[k, 0]}, {E[k, 1]})")
    two = cnt == 2
    opp = _opp(faces, corners, m)
    Ff = F.ravel()
    if check and two.any():
        k2 = np.flatnonzero(two)
        x0 = 3 * faces[k2, 0] + corners[k2, 0]
        x1 = 3 * faces[k2, 1] + corners[k2, 1]
        same = Ff[_succ(x0)] == Ff[_succ(x1)]
        if same.any():
            k = k2[np.flatnonzero(same)[0]]
            f0, f1 = faces[k]
            raise InvalidMeshError(
                f"{where}: faces are not consistently oriented, e.g. edge ({E[k, 0]}, {E[k, 1]}) "
                f"runs the same way in faces {f0} and {f1}")
        dup = Ff[x0] == Ff[x1]
        if dup.any():
            f0, f1 = faces[k2[np.flatnonzero(dup)[0]]]
            raise InvalidMeshError(
                f"{where}: duplicate faces (same three vertices), e.g. faces {f0} = {F[f0].tolist()} "
                f"and {f1} = {F[f1].tolist()}")
    if check and m:
        fan_ranks(F, opp, np.arange(3 * m, dtype=np.int64), where=where, rank=False)
    T = Topology(F, n, E, FE, faces, corners, opp, None, None, None, None, None)
    return mark_sharp(T, crease_ids)


def mark_sharp(T, crease_ids):
    """Fill in the sharp edges (boundary + creases ``crease_ids``) and vertex classes."""
    n, E = T.n, T.E
    crease = np.zeros(E.shape[0], dtype=bool)
    crease[crease_ids] = True
    cnt_one = T.faces[:, 1] < 0
    sharp = crease | cnt_one
    Es = E[sharp]
    n_sharp = np.bincount(Es.ravel(), minlength=n).astype(np.int64)
    valence = np.bincount(E.ravel(), minlength=n).astype(np.int64)
    nb_sum = np.rint(np.bincount(Es[:, 0], weights=Es[:, 1], minlength=n)
                     + np.bincount(Es[:, 1], weights=Es[:, 0], minlength=n)).astype(np.int64)
    return T._replace(sharp=sharp, crease=crease, n_sharp=n_sharp, valence=valence, nb_sum=nb_sum)


def refine_topology(T):
    """The next level's :class:`Topology` (creases not marked), derived from
    this level's without sorting the fine mesh.

    Equal to ``topology(split_faces(T.F, T.n, T.face_edge), T.n + e, ...)``:
    fine edges come in ``edge_map`` order: first the halves ``(v, n+k)`` grouped by
    old vertex ``v`` (edges where ``v`` is the larger end first, since their
    index is smaller), then the edges inside faces ``(n+k1, n+k2)``, ``k1 < k2``,
    grouped by ``k1``.
    """
    F, n, E, FE = T.F, T.n, T.E, T.face_edge
    m, e = F.shape[0], E.shape[0]
    n2 = n + e
    F2 = split_faces(F, n, FE)
    ar_e = np.arange(e, dtype=np.int64)
    lo, hi = E[:, 0], E[:, 1]
    cnt_lo = np.bincount(lo, minlength=n)
    cnt_hi = np.bincount(hi, minlength=n)
    start1 = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(cnt_lo + cnt_hi, out=start1[1:])
    lo_first = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(cnt_lo, out=lo_first[1:])
    child_lo = start1[lo] + cnt_hi[lo] + (ar_e - lo_first[lo])
    order_hi = np.argsort(hi, kind="stable")
    hi_first = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(cnt_hi, out=hi_first[1:])
    rank_hi = np.empty(e, dtype=np.int64)
    rank_hi[order_hi] = np.arange(e, dtype=np.int64) - hi_first[hi[order_hi]]
    child_hi = start1[hi] + rank_hi

    # edges inside faces: group by the smaller coarse edge, rank by the larger
    f0, c0, f1, c1 = T.faces[:, 0], T.corners[:, 0], T.faces[:, 1], T.corners[:, 1]
    has1 = f1 >= 0
    f1s, c1s = np.where(has1, f1, 0), np.where(has1, c1, 0)
    M = np.stack([FE[f0, _NEXT[c0]], FE[f0, _NEXT[_NEXT[c0]]],
                  np.where(has1, FE[f1s, _NEXT[c1s]], -1), np.where(has1, FE[f1s, _NEXT[_NEXT[c1s]]], -1)], 1)
    M = np.where(M > ar_e[:, None], M, -1)
    g = (M >= 0).sum(axis=1)
    gstart = np.zeros(e + 1, dtype=np.int64)
    np.cumsum(g, out=gstart[1:])
    gstart += 2 * e
    k1 = FE[:, [1, 2, 0]]
    k2 = FE[:, [2, 0, 1]]
    kmin, kmax = np.minimum(k1, k2), np.maximum(k1, k2)
    Mk = M[kmin]                                   # (m,3,4)
    rank = ((Mk >= 0) & (Mk < kmax[..., None])).sum(axis=2)
    inner = gstart[kmin] + rank                   # (m,3) fine edge opposite corner c of child 3

    E2 = np.empty((2 * e + 3 * m, 2), dtype=np.int64)
    E2[child_lo, 0], E2[child_lo, 1] = lo, n + ar_e
    E2[child_hi, 0], E2[child_hi, 1] = hi, n + ar_e
    E2[inner.ravel(), 0] = n + kmin.ravel()
    E2[inner.ravel(), 1] = n + kmax.ravel()

    # face_edge: child j < 3 keeps corner j = F[f, j]; its edge opposite corner c != j
    # is the half of FE[f, c] at F[f, j]; its edge opposite j is inner[f, j]
    # the half of edge FE[f, c] at F[f, c+1] (A) and at F[f, c+2] (B)
    first_is_lo = E[FE, 0] == F[:, [1, 2, 0]]
    cl, ch = child_lo[FE], child_hi[FE]
    half_a = np.where(first_is_lo, cl, ch)
    half_b = np.where(first_is_lo, ch, cl)
    FE2 = np.empty((m, 4, 3), dtype=np.int64)
    for c in range(3):
        FE2[:, (c + 1) % 3, c] = half_a[:, c]
        FE2[:, (c + 2) % 3, c] = half_b[:, c]
        FE2[:, c, c] = inner[:, c]
    FE2[:, 3, :] = inner
    FE2 = FE2.reshape(4 * m, 3)

    # faces / corners of each fine edge, in edge_faces order (smaller half-edge first).
    # In f0 the edge runs P0 -> Q0 (corners c0+1, c0+2), in f1 (if any) Q0 -> P0.
    j1, j2 = _NEXT[c0], _NEXT[_NEXT[c0]]
    p_is_lo = lo == F[f0, j1]
    half_p = np.where(p_is_lo, child_lo, child_hi)    # the half at P0
    half_q = np.where(p_is_lo, child_hi, child_lo)    # the half at Q0
    e2 = E2.shape[0]
    faces2 = np.empty((e2, 2), dtype=np.int64)
    corners2 = np.empty((e2, 2), dtype=np.int64)
    faces2[half_p, 0], corners2[half_p, 0] = 4 * f0 + j1, c0
    faces2[half_q, 0], corners2[half_q, 0] = 4 * f0 + j2, c0
    hp, hq, f1h, c1h = half_p[has1], half_q[has1], f1[has1], c1[has1]
    faces2[hq, 1], corners2[hq, 1] = 4 * f1h + _NEXT[c1h], c1h
    faces2[hp, 1], corners2[hp, 1] = 4 * f1h + _NEXT[_NEXT[c1h]], c1h
    nb = ~has1
    faces2[half_p[nb], 1] = corners2[half_p[nb], 1] = -1
    faces2[half_q[nb], 1] = corners2[half_q[nb], 1] = -1
    fm = np.arange(m, dtype=np.int64)[:, None]
    jj = np.arange(3)
    faces2[inner, 0] = 4 * fm + jj
    faces2[inner, 1] = 4 * fm + 3
    corners2[inner, 0] = jj
    corners2[inner, 1] = jj
    opp2 = _opp(faces2, corners2, 4 * m)
    T2 = Topology(F2, n2, E2, FE2, faces2, corners2, opp2, None, None, None, None, None)
    return mark_sharp(T2, np.zeros(0, dtype=np.int64))


def split_faces(F, n, face_edge):
    """The 1-to-4 split: child ``4 f + i`` of face ``f = (a, b, c)``.

    With ``ma, mb, mc = n + face_edge[f]`` (midpoints opposite a, b, c):
    child 0 = (a, mc, mb), 1 = (mc, b, ma), 2 = (mb, ma, c), 3 = (ma, mb, mc).
    """
    m = F.shape[0]
    A = np.empty((m, 6), dtype=np.int64)      # a, b, c, ma, mb, mc
    A[:, :3] = F
    np.add(face_edge, n, out=A[:, 3:])
    return np.take(A, _CHILD_CORNERS, axis=1).reshape(4 * m, 3)


#: columns of (a, b, c, ma, mb, mc) forming children 0..3
_CHILD_CORNERS = np.array([[0, 5, 4], [5, 1, 3], [4, 3, 2], [3, 4, 5]], dtype=np.int64).ravel()


#: barycentric coordinates of child i's corners in the parent face, CHILD_BARY[i, corner] (3,)
CHILD_BARY = np.array([
    [[1, 0, 0], [.5, .5, 0], [.5, 0, .5]],
    [[.5, .5, 0], [0, 1, 0], [0, .5, .5]],
    [[.5, 0, .5], [0, .5, .5], [0, 0, 1]],
    [[0, .5, .5], [.5, 0, .5], [.5, .5, 0]],
])


def child_crease_ids(T, crease_ids, E_next, n_next):
    """Crease edges of the next level: both halves of every crease edge."""
    if crease_ids.shape[0] == 0:
        return crease_ids
    mid = T.n + crease_ids
    pairs = np.concatenate([np.stack([T.E[crease_ids, 0], mid], 1),
                            np.stack([T.E[crease_ids, 1], mid], 1)])
    keys = pairs[:, 0] * np.int64(max(n_next, 1)) + pairs[:, 1]
    return np.sort(np.searchsorted(_edge_keys(E_next, n_next), keys))


# ---------------------------------------------------------------------------
# stencil assembly


class _Table(NamedTuple):
    """Entries of some rows: ``rows`` (r,) unique, and for each slot j a column
    array ``cols[j]`` (r,) and a weight (a float or an (r,) array)."""

    rows: np.ndarray
    cols: list
    weights: list


def _assemble(n_out, n_in, tables, patches=()):
    """CSR from :class:`_Table` s (several tables may fill the same row).

    A counting scatter (no sort) puts every entry at its row's next free slot.
    ``patches`` are tables overwriting rows that one table filled on its own
    (same width, entries in the same slots). The stencils never produce a
    zero weight, so every entry is kept.
    """
    counts = np.zeros(n_out, dtype=np.int64)
    for t in tables:
        counts[t.rows] += len(t.cols)
    indptr = np.zeros(n_out + 1, dtype=np.int64)
    np.cumsum(counts, out=indptr[1:])
    nnz = int(indptr[-1])
    out_c = np.empty(nnz, dtype=np.int64)
    out_w = np.empty(nnz, dtype=np.float64)
    cursor = indptr[:-1].copy()
    for t in tables:
        pos = cursor[t.rows]
        for col, w in zip(t.cols, t.weights):
            out_c[pos] = col
            out_w[pos] = w
            pos += 1
        cursor[t.rows] = pos
    for t in patches:
        pos = indptr[t.rows]
        for col, w in zip(t.cols, t.weights):
            out_c[pos] = col
            out_w[pos] = w
            pos += 1
    return Stencil(indptr, out_c, out_w, n_in)


def butterfly_weights(k):
    """Zorin-Schroeder-Sweldens weights s_0..s_{k-1} of an extraordinary vertex
    of valence k (its own weight is 3/4)."""
    if k == 3:
        return np.array([5 / 12, -1 / 12, -1 / 12])
    if k == 4:
        return np.array([3 / 8, 0.0, -1 / 8, 0.0])
    j = np.arange(k)
    return (0.25 + np.cos(2 * np.pi * j / k) + 0.5 * np.cos(4 * np.pi * j / k)) / k


def _rings(T, verts_mask):
    """Counter-clockwise one-rings of the (interior) vertices in ``verts_mask``.

    Returns ``start`` (n+1,) CSR offsets, ``ring`` flat neighbours and
    ``rank_of_corner`` (3m,) giving each selected corner's position
    (-1 elsewhere). ``ring[start[v] + r]`` is ``F[f, c+1]`` for the corner of
    rank r, so consecutive entries are consecutive neighbours.
    """
    F = T.F
    Ff = F.ravel()
    cmask = verts_mask[Ff]
    cids = np.flatnonzero(cmask)
    rank, _ = fan_ranks(F, T.opp, cids)
    cnt = np.bincount(Ff[cids], minlength=T.n)
    start = np.zeros(T.n + 1, dtype=np.int64)
    np.cumsum(cnt, out=start[1:])
    ring = np.empty(cids.shape[0], dtype=np.int64)
    ring[start[Ff[cids]] + rank] = Ff[_succ(cids)]
    rank_of_corner = np.full(Ff.shape[0], -1, dtype=np.int64)
    rank_of_corner[cids] = rank
    return start, ring, rank_of_corner


def butterfly_level(T):
    """Modified butterfly stencil for one level (see core.subdivide)."""
    n, E = T.n, T.E
    e = E.shape[0]
    F = T.F
    ar_n = np.arange(n, dtype=np.int64)
    tables = [_Table(ar_n, [ar_n], [1.0])]
    patches = []
    a_all, b_all = E[:, 0], E[:, 1]

    # --- sharp edges: 4-point rule along the curve, reflected at corners
    ks = np.flatnonzero(T.sharp)
    if ks.size:
        a, b = a_all[ks], b_all[ks]
        ca = T.n_sharp[a] != 2
        cb = T.n_sharp[b] != 2
        # a corner end x is reflected, x' = 2x - y: the slot of x' holds (x, -2/16)
        # and the +1/16 on y goes to y's own weight (no zero weights, no missing point)
        a2 = np.where(ca, a, T.nb_sum[a] - b)
        b2 = np.where(cb, b, T.nb_sum[b] - a)
        wa = 9 / 16 + 1 / 16 * cb
        wb = 9 / 16 + 1 / 16 * ca
        tables.append(_Table(n + ks, [a, b, a2, b2],
                             [wa, wb, np.where(ca, -2 / 16, -1 / 16), np.where(cb, -2 / 16, -1 / 16)]))

    smooth_x = (T.n_sharp == 0) & (T.valence != 6) & (T.valence > 0)
    not_sharp = ~T.sharp
    xa = smooth_x[a_all] & not_sharp
    xb = smooth_x[b_all] & not_sharp

    # --- 8-point stencil (both ends regular, or touching a sharp vertex), reflected wings
    kr = np.flatnonzero(not_sharp & ~xa & ~xb)
    if kr.size:
        f0, c0 = T.faces[kr, 0], T.corners[kr, 0]
        f1, c1 = T.faces[kr, 1], T.corners[kr, 1]
        x0, x1 = 3 * f0, 3 * f1
        n0, nn0 = _NEXT[c0], _NEXT[_NEXT[c0]]
        n1, nn1 = _NEXT[c1], _NEXT[_NEXT[c1]]
        # 32-bit copies of the arrays read at random: half the cache footprint
        small = max(n, 3 * T.F.shape[0]) < 2 ** 31 - 1
        Ff = T.F.ravel().astype(np.int32) if small else T.F.ravel()
        P0, Q0 = Ff[x0 + n0], Ff[x0 + nn0]
        c, d = Ff[x0 + c0], Ff[x1 + c1]
        # slot A: apex P0, edge (Q0, c); B: apex Q0, edge (c, P0);
        # C: apex Q0 (=P1), edge (P0, d); D: apex P0 (=Q1), edge (d, Q0)
        # the corner across each half-edge, -1 where that edge is sharp (never read across)
        wing_opp = np.where(T.sharp[T.face_edge.ravel()], -1, T.opp)
        if small:
            wing_opp = wing_opp.astype(np.int32)
        wings, miss = [], []
        for h in (x0 + n0, x0 + nn0, x1 + n1, x1 + nn1):
            t = wing_opp[h]
            ok = t >= 0
            wings.append(Ff[t])
            miss.append(~ok)
        tables.append(_Table(n + kr, [P0, Q0, c, d] + wings, [0.5, 0.5, 0.125, 0.125] + [-1 / 16] * 4))
        sel = np.flatnonzero(miss[0] | miss[1] | miss[2] | miss[3])
        if sel.size:
            # rows with reflected wings, same slots: -1/16 (P + Q - R) for a missing
            # wing keeps -1/16 on the face's third vertex (c or d) in the wing's slot
            # and moves the +-1/16 on the edge's ends into their weights, so no
            # weight is ever zero (a row may name c or d twice)
            c_s = c[sel]
            mA, mB, mC, mD = (mk[sel].astype(np.float64) for mk in miss)
            s16 = 1 / 16
            wP = 0.5 + s16 * (mA - mB + mD - mC)
            wQ = 0.5 + s16 * (mB - mA + mC - mD)
            d_s = d[sel]
            wing_c = [np.where(mk[sel], cd, w[sel]) for w, mk, cd in zip(wings, miss, (c_s, c_s, d_s, d_s))]
            patches.append(_Table(n + kr[sel], [P0[sel], Q0[sel], c_s, d_s] + wing_c,
                                  [wP, wQ, 0.125, 0.125] + [-s16] * 4))

    # --- extraordinary ends: their own ring stencil (halved when both ends are)
    kx = np.flatnonzero(xa | xb)
    if kx.size:
        start, ring, rank_of_corner = _rings(T, smooth_x)
        f0, c0 = T.faces[kx, 0], T.corners[kx, 0]
        f1, c1 = T.faces[kx, 1], T.corners[kx, 1]
        y0 = 3 * f0 + _NEXT[c0]   # corner of P0 in f0, its next vertex is Q0
        y1 = 3 * f1 + _NEXT[c1]   # corner of Q0 in f1, its next vertex is P0
        P0 = F[f0, _NEXT[c0]]
        a, b = a_all[kx], b_all[kx]
        ya = np.where(P0 == a, y0, y1)
        yb = np.where(P0 == a, y1, y0)
        both = xa[kx] & xb[kx]
        for v, u, y, is_x in ((a, b, ya, xa[kx]), (b, a, yb, xb[kx])):
            val = T.valence[v]
            for k in np.unique(val[is_x]):
                sel = np.flatnonzero(is_x & (val == k))
                f = np.where(both[sel], 0.5, 1.0)
                vs = v[sel]
                if k < 3:   # only in degenerate meshes (a vertex in two faces): midpoint
                    tables.append(_Table(n + kx[sel], [vs, u[sel]], [0.5 * f, 0.5 * f]))
                    continue
                r = rank_of_corner[y[sel]]
                base = start[vs]
                sj = butterfly_weights(k)
                js = np.flatnonzero(sj)          # the valence-4 stencil has two zeros
                cols = [vs] + [ring[base + (r + j) % k] for j in js]
                ws = [0.75 * f] + [sj[j] * f for j in js]
                tables.append(_Table(n + kx[sel], cols, ws))
    return _assemble(n + e, n, tables, patches)


def loop_beta(k):
    """Warren's beta: 3/16 for valence 3, 3/(8k) otherwise."""
    k = np.asarray(k, dtype=np.float64)
    return np.where(k == 3, 3 / 16, 3 / (8 * np.maximum(k, 1)))


def loop_level(T):
    """Loop stencil for one level (see core.subdivide)."""
    n, E = T.n, T.E
    e = E.shape[0]
    F = T.F
    tables = []
    ns = T.n_sharp
    fixed = (ns == 1) | (ns >= 3) | (T.valence == 0)
    kf = np.flatnonzero(fixed)
    if kf.size:
        tables.append(_Table(kf, [kf], [1.0]))
    # curve vertices: (1, 6, 1) / 8
    kc = np.flatnonzero(ns == 2)
    if kc.size:
        Es = E[T.sharp]
        nb_max = np.full(n, -1, dtype=np.int64)
        np.maximum.at(nb_max, Es[:, 0], Es[:, 1])
        np.maximum.at(nb_max, Es[:, 1], Es[:, 0])
        hi = nb_max[kc]
        lo = T.nb_sum[kc] - hi
        tables.append(_Table(kc, [kc, lo, hi], [0.75, 0.125, 0.125]))
    # smooth vertices: (1 - k beta) v + beta * sum of neighbours, grouped by valence
    smooth = (ns == 0) & (T.valence > 0)
    if smooth.any():
        # neighbours grouped by vertex without sorting: the lo-side ends of E are
        # already grouped (E is sorted), the hi-side ends are placed by counting
        lo, hi = E[:, 0], E[:, 1]
        val = T.valence
        start = np.zeros(n + 1, dtype=np.int64)
        np.cumsum(val, out=start[1:])
        cnt_hi = np.bincount(hi, minlength=n)
        lo_first = np.zeros(n + 1, dtype=np.int64)
        np.cumsum(np.bincount(lo, minlength=n), out=lo_first[1:])
        nbr = np.empty(2 * e, dtype=np.int64)
        ar_e = np.arange(e, dtype=np.int64)
        nbr[start[lo] + cnt_hi[lo] + ar_e - lo_first[lo]] = hi
        order_hi = np.argsort(hi, kind="stable")
        hs = hi[order_hi]
        hi_first = np.zeros(n + 1, dtype=np.int64)
        np.cumsum(cnt_hi, out=hi_first[1:])
        nbr[start[hs] + ar_e - hi_first[hs]] = lo[order_hi]
        sv = np.flatnonzero(smooth)
        for k in np.unique(val[sv]):
            vs = sv[val[sv] == k]
            beta = float(loop_beta(k))
            base = start[vs]
            tables.append(_Table(vs, [vs] + [nbr[base + j] for j in range(k)], [1 - k * beta] + [beta] * k))
    # odd vertices
    ks = np.flatnonzero(T.sharp)
    if ks.size:
        tables.append(_Table(n + ks, [E[ks, 0], E[ks, 1]], [0.5, 0.5]))
    ki = np.flatnonzero(~T.sharp)
    if ki.size:
        c = F[T.faces[ki, 0], T.corners[ki, 0]]
        d = F[T.faces[ki, 1], T.corners[ki, 1]]
        tables.append(_Table(n + ki, [E[ki, 0], E[ki, 1], c, d], [0.375, 0.375, 0.125, 0.125]))
    return _assemble(n + e, n, tables)
