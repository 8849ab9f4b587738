"""Per-level topology of the 1-to-4 split for :mod:`core.subdivide` (private).

Whole-array code only: no Python loop over vertices, edges or faces (the only
loops run over ``log2(valence)`` pointer-jumping passes).

* Level 0 (:func:`topology`): one stable sort of the half-edge keys gives the
  edge map (the numbering of :func:`core.topology.edge_map`) and each edge's
  faces (as :func:`core.topology.edge_faces`); the manifold checks run there.
* Finer levels (:func:`refine_topology`): the fine edge map, face-edge map and
  edge faces follow from the coarse ones by construction, without sorting the
  fine mesh.
* :func:`fan_ranks` puts the corners around each vertex in rotational order
  by pointer jumping (list ranking) along the "next face around the vertex" map.

Corner ``x = 3 f + c`` is corner ``c`` of face ``f``; the half-edge "opposite
corner ``x``" runs ``F[f, c+1] -> F[f, c+2]`` (indices mod 3), the same
numbering as ``face_edge`` in :mod:`core.topology`.
"""

from typing import NamedTuple

import numpy as np

from ._groups import sorted_unique
from .errors import InvalidArgumentError, InvalidMeshError
from .topology import edge_keys

NEXT_CORNER = np.array([1, 2, 0], dtype=np.int64)


def next_corner(x):
    """The corner after ``x`` in its face (``c -> c+1 mod 3``)."""
    return x - x % 3 + NEXT_CORNER[x % 3]


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


def crease_pairs(creases, where):
    """``creases`` as given (an array, for messages) and as a (k,2) int64
    array, or (None, None) for None or an empty list; raises
    InvalidArgumentError naming ``where`` when it is not (k,2) integers."""
    if creases is None:
        return None, None
    shape = f"{where}: creases must be a (k,2) integer array of vertex pairs, got"
    try:
        C_in = np.asarray(creases)
    except ValueError:      # (NumPy's "setting an array element with a sequence")
        raise InvalidArgumentError(f"{shape} rows of different lengths") from None
    if C_in.size == 0:
        return None, None
    if C_in.ndim != 2 or C_in.shape[1] != 2 or not np.issubdtype(C_in.dtype, np.integer):
        raise InvalidArgumentError(f"{shape} {C_in.shape} {C_in.dtype}")
    # (unsigned indices past 2^63 wrap to negative ones: refused by the callers, shown as given)
    return C_in, C_in.astype(np.int64)


def crease_edge_ids(creases, E, n, where):
    """Indices into ``E`` of the undirected vertex pairs ``creases``.

    Raises InvalidArgumentError when a pair is not an edge."""
    C_in, C = crease_pairs(creases, where)
    if C is None:
        return np.zeros(0, dtype=np.int64)
    lo, hi = np.minimum(C[:, 0], C[:, 1]), np.maximum(C[:, 0], C[:, 1])
    keys = edge_keys(lo, hi, n)
    ekeys = edge_keys(E[:, 0], E[:, 1], n)
    pos = np.searchsorted(ekeys, keys)
    pos_c = np.minimum(pos, max(ekeys.shape[0] - 1, 0))
    ok = (lo >= 0) & (hi < n) & (pos < ekeys.shape[0])
    ok &= ekeys[pos_c] == keys if ekeys.shape[0] else False
    if not np.all(ok):
        i = int(np.flatnonzero(~ok)[0])
        raise InvalidArgumentError(
            f"{where}: creases must be edges of F, e.g. pair {i} = {C_in[i].tolist()} is not an edge")
    return sorted_unique(pos)


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
    t = opp[next_corner(corner_ids)]
    has = t >= 0
    nxt = np.full(q, -1, dtype=np.int64)
    nxt[has] = local[next_corner(t[has])]
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
    key = edge_keys(half[:, 0], half[:, 1], n)
    nn = np.int64(max(n, 1))
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
        same = Ff[next_corner(x0)] == Ff[next_corner(x1)]
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
    n, e = T.n, T.E.shape[0]
    halves = _half_edges(T)
    inner, kmin, kmax = _inner_edges(T)
    ar_e = np.arange(e, dtype=np.int64)
    E2 = np.empty((2 * e + 3 * T.F.shape[0], 2), dtype=np.int64)
    E2[halves[0], 0], E2[halves[0], 1] = T.E[:, 0], n + ar_e
    E2[halves[1], 0], E2[halves[1], 1] = T.E[:, 1], n + ar_e
    E2[inner.ravel(), 0] = n + kmin.ravel()
    E2[inner.ravel(), 1] = n + kmax.ravel()
    faces2, corners2 = _fine_edge_faces(T, halves, inner, E2.shape[0])
    T2 = Topology(split_faces(T.F, n, T.face_edge), n + e, E2, _fine_face_edges(T, halves, inner),
                  faces2, corners2, _opp(faces2, corners2, 4 * T.F.shape[0]),
                  None, None, None, None, None)
    return mark_sharp(T2, np.zeros(0, dtype=np.int64))


def _half_edges(T):
    """The fine edges of each coarse edge's halves: (at its lower end, at
    its higher end), each (e,): grouped by old vertex, where the vertex is
    the higher end first."""
    n, e = T.n, T.E.shape[0]
    lo, hi = T.E[:, 0], T.E[:, 1]
    cnt_lo = np.bincount(lo, minlength=n)
    cnt_hi = np.bincount(hi, minlength=n)
    start1 = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(cnt_lo + cnt_hi, out=start1[1:])
    lo_first = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(cnt_lo, out=lo_first[1:])
    child_lo = start1[lo] + cnt_hi[lo] + (np.arange(e, dtype=np.int64) - lo_first[lo])
    order_hi = np.argsort(hi, kind="stable")
    hi_first = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(cnt_hi, out=hi_first[1:])
    rank_hi = np.empty(e, dtype=np.int64)
    rank_hi[order_hi] = np.arange(e, dtype=np.int64) - hi_first[hi[order_hi]]
    return child_lo, start1[hi] + rank_hi


def _inner_edges(T):
    """The edges inside faces: ``inner`` (m,3), the fine edge opposite corner
    c of the middle child, joining the midpoints of coarse edges ``kmin``,
    ``kmax`` (m,3); grouped by the smaller coarse edge, ranked by the larger."""
    FE, e = T.face_edge, T.E.shape[0]
    ar_e = np.arange(e, dtype=np.int64)
    f0, c0, f1, c1 = T.faces[:, 0], T.corners[:, 0], T.faces[:, 1], T.corners[:, 1]
    has1 = f1 >= 0
    f1s, c1s = np.where(has1, f1, 0), np.where(has1, c1, 0)
    M = np.stack([FE[f0, NEXT_CORNER[c0]], FE[f0, NEXT_CORNER[NEXT_CORNER[c0]]],
                  np.where(has1, FE[f1s, NEXT_CORNER[c1s]], -1),
                  np.where(has1, FE[f1s, NEXT_CORNER[NEXT_CORNER[c1s]]], -1)], 1)
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
    return gstart[kmin] + rank, kmin, kmax


def _fine_face_edges(T, halves, inner):
    """The fine faces' edges (4m,3): child j < 3 keeps corner j = F[f, j]; its
    edge opposite corner c != j is the half of FE[f, c] at F[f, j]; its edge
    opposite j is inner[f, j]; the middle child's are ``inner``."""
    F, FE, m = T.F, T.face_edge, T.F.shape[0]
    child_lo, child_hi = halves
    # the half of edge FE[f, c] at F[f, c+1] (a) and at F[f, c+2] (b)
    first_is_lo = T.E[FE, 0] == F[:, [1, 2, 0]]
    cl, ch = child_lo[FE], child_hi[FE]
    half_a = np.where(first_is_lo, cl, ch)
    half_b = np.where(first_is_lo, ch, cl)
    FE2 = np.empty((m, 4, 3), dtype=np.int64)
    for c in range(3):
        FE2[:, (c + 1) % 3, c] = half_a[:, c]
        FE2[:, (c + 2) % 3, c] = half_b[:, c]
        FE2[:, c, c] = inner[:, c]
    FE2[:, 3, :] = inner
    return FE2.reshape(4 * m, 3)


def _fine_edge_faces(T, halves, inner, e2):
    """Faces and corners (each (e2,2)) of each fine edge, in edge_faces order
    (smaller half-edge first; -1 for none). In f0 the coarse edge runs
    P0 -> Q0 (corners c0+1, c0+2), in f1 (if any) Q0 -> P0."""
    F, m = T.F, T.F.shape[0]
    child_lo, child_hi = halves
    f0, c0, f1, c1 = T.faces[:, 0], T.corners[:, 0], T.faces[:, 1], T.corners[:, 1]
    has1 = f1 >= 0
    j1, j2 = NEXT_CORNER[c0], NEXT_CORNER[NEXT_CORNER[c0]]
    p_is_lo = T.E[:, 0] == F[f0, j1]
    half_p = np.where(p_is_lo, child_lo, child_hi)    # the half at P0
    half_q = np.where(p_is_lo, child_hi, child_lo)    # the half at Q0
    faces2 = np.empty((e2, 2), dtype=np.int64)
    corners2 = np.empty((e2, 2), dtype=np.int64)
    faces2[half_p, 0], corners2[half_p, 0] = 4 * f0 + j1, c0
    faces2[half_q, 0], corners2[half_q, 0] = 4 * f0 + j2, c0
    hp, hq, f1h, c1h = half_p[has1], half_q[has1], f1[has1], c1[has1]
    faces2[hq, 1], corners2[hq, 1] = 4 * f1h + NEXT_CORNER[c1h], c1h
    faces2[hp, 1], corners2[hp, 1] = 4 * f1h + NEXT_CORNER[NEXT_CORNER[c1h]], c1h
    nb = ~has1
    faces2[half_p[nb], 1] = corners2[half_p[nb], 1] = -1
    faces2[half_q[nb], 1] = corners2[half_q[nb], 1] = -1
    fm = np.arange(m, dtype=np.int64)[:, None]
    jj = np.arange(3)
    faces2[inner, 0] = 4 * fm + jj
    faces2[inner, 1] = 4 * fm + 3
    corners2[inner, 0] = jj
    corners2[inner, 1] = jj
    return faces2, corners2


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
    keys = edge_keys(pairs[:, 0], pairs[:, 1], n_next)
    return np.sort(np.searchsorted(edge_keys(E_next[:, 0], E_next[:, 1], n_next), keys))


# ---------------------------------------------------------------------------
# stencil assembly
