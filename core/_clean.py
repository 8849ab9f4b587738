"""The half-edge twin table, face keys and fan counts (used by :mod:`.clean`
and :mod:`.simplify`).

Half-edge convention: half-edge ``h = 3 f + c`` is the edge of face ``f``
opposite corner ``c``, from ``F[f, (c+1)%3]`` to ``F[f, (c+2)%3]`` (the same
numbering as ``core.topology``'s face-edge ``c``). ``twin[h]`` is the other
half-edge on the same undirected edge (whatever its direction, so meshes
with inconsistent orientation work too), ``-1`` on a boundary edge and
``-2`` on a non-manifold edge (used by more than two faces).

Fans: the faces around a vertex ``v`` are joined across the manifold
interior edges at ``v``. Every face has two edges at ``v``, so the joins
form paths (open fans, ending on a boundary or non-manifold edge) and
cycles (closed fans)::

    corners(v) = faces around v           ends(v) = edges at v with twin < 0
    paths(v)   = ends(v) / 2              (each open fan has two ends)
    one fan  <=>  paths <= 1 and the fan through one start corner visits
                  every corner of v (walked around v through the twins)

A closed fan has at least 3 faces, so the walk is only needed where the
counts leave room for a second fan, and it stops as soon as fewer than 3
faces are left unseen; all walks advance in lock-step.
"""

import numpy as np

from ._groups import sort_keys
from ._parallel import blocks, run_blocks, run_each
from .mesh import bounding_box
from .spatial import morton_codes
from .topology import connected_labels

BOUNDARY = -1
NON_MANIFOLD = -2

#: offset from half-edge ``h`` to the next / previous half-edge of its face
NEXT_OFFSET = np.array([1, 1, -2], dtype=np.int64)
PREV_OFFSET = np.array([2, -1, -1], dtype=np.int64)
#: lock-step fan walks longer than this finish with a union-find instead
_MAX_WALK = 64
#: vertices walked together (keeps the walk's temporaries in cache)
_WALK_CHUNK = 1 << 15


_KEY_MAX_N = 2_097_151  # (n + 1)^3 <= 2^63: ``(lo n + mid) n + hi`` fits in an int64


def face_keys(F, n_in):
    """Key of each face's vertex set: equal keys for equal sets.

    ``(lo n + mid) n + hi`` of the sorted row when that fits in an int64
    (fewer than ~2.1M vertices), else the rank of the sorted row among the
    distinct rows (one lexicographic sort).
    """
    a, b, c = F[:, 0], F[:, 1], F[:, 2]
    lo = np.minimum(np.minimum(a, b), c)
    hi = np.maximum(np.maximum(a, b), c)
    mid = a + b + c - lo - hi
    if n_in <= _KEY_MAX_N:
        nn = np.int64(max(n_in, 1))
        return (lo * nn + mid) * nn + hi
    order = np.lexsort((hi, mid, lo))
    new = np.ones(order.size, dtype=bool)
    new[1:] = ((lo[order[1:]] != lo[order[:-1]]) | (mid[order[1:]] != mid[order[:-1]])
               | (hi[order[1:]] != hi[order[:-1]]))
    key = np.empty(order.size, dtype=np.int64)
    key[order] = np.cumsum(new) - 1
    return key


def renumber_twins(t, new_f):
    """Twin entries ``t`` (half-edge ids, or the negative markers, kept) once
    the faces are renumbered by ``new_f`` (old face -> new face; a half-edge
    keeps its corner: ``3 f + c`` becomes ``3 new_f[f] + c``)."""
    new_h = (3 * new_f[:, None] + np.arange(3)).ravel()
    return np.where(t >= 0, np.take(new_h, np.maximum(t, 0)), t)


def spatial_order(V, F, twin, box=None, ends=True):
    """The same mesh with vertices in Morton (Z-curve) order of their
    position and faces in order of their smallest new vertex index, so that
    neighbours sit near each other in memory (large meshes simplify much
    faster). Corners keep their place in each face, so half-edge ``3 f + c``
    of a face is still its edge opposite corner ``c``.

    Returns
    -------
    V2, F2, twin2 : the reordered mesh and its twin table.
    U2, W2 : ``half_edge_ends(F2)`` (None without ``ends``).
    order : (n,) int64, old index of each new vertex (``V2 = V[order]``).
    forder : (m,) int64, old index of each new face.

    ``box`` may pass ``bounding_box(V)`` when the caller has it.
    """
    n, m = V.shape[0], F.shape[0]
    if n == 0 or m == 0:
        U, W = half_edge_ends(F) if ends else (None, None)
        return V, F, twin, U, W, np.arange(n, dtype=np.int64), np.arange(m, dtype=np.int64)
    lo, hi = bounding_box(V) if box is None else box
    # unique keys: the Morton code's high bits, then the index (any sort gives the
    # same order, on every machine); the index is the key's low bits
    b = max(1, int(n).bit_length())
    code = (morton_codes(V, lo, hi - lo) >> np.uint64(b)) << np.uint64(b)
    code |= np.arange(n, dtype=np.uint64)
    code.sort()
    order = (code & np.uint64((1 << b) - 1)).astype(np.int64)
    del code
    new_v = np.empty(n, dtype=np.int64)
    new_v[order] = np.arange(n, dtype=np.int64)
    forder = _faces_by_smallest(F, new_v)
    new_f = np.empty(m, dtype=np.int64)
    new_f[forder] = np.arange(m, dtype=np.int64)
    F2 = np.empty_like(F)
    twin2 = np.empty_like(twin)
    U2, W2 = (np.empty_like(twin), np.empty_like(twin)) if ends else (None, None)
    twin3 = twin.reshape(m, 3)

    def block(a, b):
        Fb = np.take(new_v, np.take(F, forder[a:b], axis=0))
        F2[a:b] = Fb
        if ends:
            U2[3 * a:3 * b] = np.take(Fb, [1, 2, 0], axis=1).ravel()
            W2[3 * a:3 * b] = np.take(Fb, [2, 0, 1], axis=1).ravel()
        t = np.take(twin3, forder[a:b], axis=0).ravel()
        f, c = np.divmod(np.maximum(t, 0), 3)           # half-edge 3 f + c -> 3 new_f[f] + c
        h = np.take(new_f, f)
        h *= 3
        h += c
        twin2[3 * a:3 * b] = np.where(t >= 0, h, t)

    run_blocks(block, blocks(m, _PAIR_BLOCK // 3))
    return np.take(V, order, axis=0), F2, twin2, U2, W2, order, forder


def _faces_by_smallest(F, new_v):
    """Face order by (smallest new vertex index ``new_v[F]``, face index):
    ``argsort(min * m + f)``, from one sort of those unique keys."""
    m = F.shape[0]
    bits = max(1, int(m - 1).bit_length())
    key = np.empty(m, dtype=np.int64)

    def block(a, b):
        Fb = np.take(new_v, F[a:b])
        k = np.minimum(np.minimum(Fb[:, 0], Fb[:, 1]), Fb[:, 2])
        k <<= bits
        k |= np.arange(a, b, dtype=np.int64)
        key[a:b] = k

    run_blocks(block, blocks(m, _PAIR_BLOCK // 3))
    key.sort()
    key &= np.int64((1 << bits) - 1)
    return key


def half_edge_ends(F, h=None):
    """Endpoints ``(U, W)`` of every half-edge, each (3m,) int64, or of the
    half-edges ``h`` only."""
    if h is None:
        return np.take(F, [1, 2, 0], axis=1).ravel(), np.take(F, [2, 0, 1], axis=1).ravel()
    Fr = F.ravel()
    c = h % 3
    return np.take(Fr, h + np.take(NEXT_OFFSET, c)), np.take(Fr, h + np.take(PREV_OFFSET, c))


#: half-edges per slice of :func:`edge_representatives` (bounds its temporaries)
_REP_SLICE = 1 << 20


def edge_representatives(twin, boundary=True, step=_REP_SLICE):
    """One half-edge per edge, ascending: each interior edge's half-edge
    ``h < twin[h]``, and with ``boundary`` every border half-edge
    (``twin == BOUNDARY``). In slices of ``step``: no (3m,) index array is made."""
    parts = [np.zeros(0, dtype=np.int64)]
    for i in range(0, twin.size, step):
        t = twin[i:i + step]
        keep = t > np.arange(i, i + t.size, dtype=np.int64)
        if boundary:
            keep |= t == BOUNDARY
        parts.append(np.flatnonzero(keep) + i)
    return np.concatenate(parts)


def interior_edges(twin):
    """Every interior edge once: its half-edge ``h < twin[h]`` (ascending,
    :func:`edge_representatives`) and that twin, ``(h, twin[h])``, (k,) int64 each."""
    h = edge_representatives(twin, boundary=False)
    return h, np.take(twin, h)


def twin_table(F, n_vertices, *, ends=None):
    """Twin of every half-edge (see the module docstring), (3m,) int64.

    One sort of the undirected edge keys (:func:`sort_keys`); edges used once
    are boundary (``-1``), twice are paired, more than twice non-manifold
    (``-2``). ``ends`` may pass ``half_edge_ends(F)`` when the caller has it.
    """
    size = 3 * F.shape[0]
    twin = np.full(size, BOUNDARY, dtype=np.int64)
    if size == 0:
        return twin
    nn = max(n_vertices, 1)
    order, ks = sort_keys(_half_edge_keys(F, nn, ends), nn * nn)
    run_blocks(lambda a, b: _pair_runs(ks, order, twin, a, b), _run_spans(ks, _PAIR_BLOCK))
    return twin


#: half-edges per block of the twin table's passes (temporaries stay in cache)
_PAIR_BLOCK = 1 << 16


def _half_edge_keys(F, nn, ends):
    """``lo * nn + hi`` of every half-edge's ends, (3m,) int64, face block by
    face block (``ends``: ``half_edge_ends(F)`` when the caller has it)."""
    m = F.shape[0]
    key = np.empty(3 * m, dtype=np.int64)
    nn = np.int64(nn)

    def block(a, b):
        if ends is not None:
            pairs = [(ends[0][3 * a:3 * b], ends[1][3 * a:3 * b], key[3 * a:3 * b])]
        else:
            cols = [F[a:b, 0], F[a:b, 1], F[a:b, 2]]
            out = key[3 * a:3 * b].reshape(-1, 3)
            pairs = [(cols[(c + 1) % 3], cols[(c + 2) % 3], out[:, c]) for c in range(3)]
        for u, w, out in pairs:
            lo = np.minimum(u, w)
            lo *= nn
            lo += np.maximum(u, w)
            out[...] = lo

    run_blocks(block, blocks(m, _PAIR_BLOCK // 3))
    return key


def _run_spans(ks, size):
    """Blocks of about ``size`` positions of the sorted keys ``ks`` that never
    split a run of equal keys."""
    cuts = [0]
    for _, b in blocks(ks.size, size)[:-1]:
        b = int(np.searchsorted(ks, ks[b]))          # back to the start of b's run
        if b > cuts[-1]:
            cuts.append(b)
    cuts.append(ks.size)
    return list(zip(cuts[:-1], cuts[1:]))


def _pair_runs(ks, order, twin, a, b):
    """Twins of the sorted half-edges ``order[a:b]`` (whole runs of equal
    keys ``ks``): runs of two are each other's twin, longer runs
    ``NON_MANIFOLD``, single ones stay ``BOUNDARY``."""
    k = ks[a:b]
    eq = k[1:] == k[:-1]            # sorted position i and i+1 are the same edge
    if not eq.any():
        return
    o = order[a:b]
    lone = np.zeros(eq.size, dtype=bool)   # i and i+1 belong to a run of 3 or more
    lone[1:] = eq[:-1]
    lone[:-1] |= eq[1:]
    pair = np.flatnonzero(eq & ~lone)
    h0, h1 = o[pair], o[pair + 1]
    twin[h0] = h1
    twin[h1] = h0
    multi = np.flatnonzero(eq & lone)
    if multi.size:
        twin[o[multi]] = NON_MANIFOLD
        twin[o[multi + 1]] = NON_MANIFOLD


def corner_fans(F, twin, U, W, vertices, n_vertices):
    """Fan of every corner of the vertices in ``vertices``: the corners of a
    vertex are joined across its manifold interior edges (``twin >= 0``) by a
    union-find.

    Returns
    -------
    nodes : (k,) int64, the corners (``3 f + c``) of the selected vertices.
    roots : (k,) int64, for each, the smallest corner of its fan.
    """
    sel = np.zeros(n_vertices, dtype=bool)
    sel[vertices] = True
    h = edge_representatives(twin, boundary=False)
    t = twin[h]
    f_h, f_t = h - h % 3, t - t % 3
    Fr = F.ravel()

    def corner(face_base, vertex):
        # the corner of face (3*f) holding vertex
        c = np.where(Fr[face_base] == vertex, 0, np.where(Fr[face_base + 1] == vertex, 1, 2))
        return face_base + c

    pairs = []
    for v in (U[h], W[h]):
        keep = sel[v]
        pairs.append(np.stack([corner(f_h[keep], v[keep]), corner(f_t[keep], v[keep])], axis=1))
    pairs = np.concatenate(pairs)
    nodes = np.flatnonzero(sel[Fr])                 # corners of the selected vertices
    local = np.full(Fr.size, -1, dtype=np.int64)
    local[nodes] = np.arange(nodes.size)
    labels = connected_labels(nodes.size, local[pairs])
    return nodes, nodes[labels]


def _fans_union_find(F, twin, U, W, vertices, n_vertices):
    """Number of fans of each vertex in ``vertices`` (the rest 0)."""
    nodes, roots = corner_fans(F, twin, U, W, vertices, n_vertices)
    return np.bincount(F.ravel()[nodes[roots == nodes]], minlength=n_vertices)


def _walk_fans(twin, Fr, v, e, corners):
    """Lock-step walks around vertices ``v`` from the exit half-edges ``e``
    (in the first face; ``Fr``: the faces' corners, ``F.ravel()``). Returns
    the vertices found with several fans and those still walking after
    ``_MAX_WALK`` steps."""
    base0 = e - e % 3                                     # first face (3 f) of the walk
    # once a walk has seen more than corners - 3 faces, the rest cannot hold
    # another (closed) fan: one fan. A walk that ends before that is one of several.
    left = corners - 4                                    # faces to see after the next one
    found = []
    for _ in range(_MAX_WALK):
        if v.size == 0:
            break
        t = twin[e]
        jt = t % 3
        g = t - jt
        stop = (t < 0) | (g == base0)                     # open end reached / back at the start
        found.append(v[stop])
        go = np.flatnonzero(~stop & (left > 0))
        v, t, jt, base0, left = v[go], t[go], jt[go], base0[go], left[go] - 1
        # leave the new face through its other edge at v (t's first end: U[t])
        nxt = NEXT_OFFSET.take(jt)
        e = t + np.where(Fr.take(t + nxt) == v, PREV_OFFSET.take(jt), nxt)
    return np.concatenate(found) if found else v[:0], v


def _any_exit(F, walk):
    """A half-edge leaving each vertex of the mask ``walk`` (n,) (-1 elsewhere,
    int64): ``3 f + 2`` (it leaves ``F[f, 0]``) of a face with the vertex at
    corner 0, else ``3 f`` (corner 1), else ``3 f + 1`` (corner 2)."""
    start = np.full(walk.size, -1, dtype=np.int64)
    start[F[:, 0]] = 3 * np.arange(F.shape[0], dtype=np.int64) + 2
    for c, leaving in ((1, 0), (2, 1)):
        missing = walk & (start < 0)
        if not missing.any():
            break
        f = np.flatnonzero(missing.take(F[:, c]))
        start[F[f, c]] = 3 * f + leaving
    return start


def non_manifold_vertices(F, n_vertices, twin, *, ends=None, corners=None):
    """Boolean mask of vertices on a non-manifold edge or whose faces form
    more than one fan (bow-tie vertices), (n,) bool.

    ``F`` must be clean (no degenerate or duplicate faces, as after
    :func:`core.clean.clean_mesh`); ``twin`` is ``twin_table(F, n_vertices)``,
    ``ends`` may pass ``half_edge_ends(F)`` and ``corners`` the faces at
    each vertex, ``np.bincount(F.ravel(), minlength=n_vertices)``. Fans are
    counted as described in the module docstring: from the corner and
    open-edge counts, walking only around the vertices where a second closed
    fan could hide.
    """
    n = n_vertices
    bad = np.zeros(n, dtype=bool)
    if twin.size == 0:
        return bad
    Fr = F.ravel()
    nm = np.flatnonzero(twin == NON_MANIFOLD)
    for end in half_edge_ends(F, nm):
        bad[end] = True
    if corners is None:
        corners = np.bincount(Fr, minlength=n)
    hopen = np.flatnonzero(twin < 0)
    Uo, Wo = half_edge_ends(F, hopen)
    paths = (np.bincount(Uo, minlength=n) + np.bincount(Wo, minlength=n)) // 2
    bad |= paths > 1
    # a closed fan has >= 3 corners: one path plus a cycle needs 4, two cycles 6
    walk = ~bad & (corners >= np.where(paths == 0, 6, 4))
    # start: the face after an open end, else any face (a walk around one fan
    # meets every face of it from any start), leaving through an edge at v
    start = _any_exit(F, walk)
    j = hopen % 3
    start[Uo] = hopen + PREV_OFFSET[j]                      # the other edge at U in that face
    start[Wo] = hopen + NEXT_OFFSET[j]                      # the other edge at W
    todo = np.flatnonzero(walk)
    chunks = [todo[i:i + _WALK_CHUNK] for i in range(0, todo.size, _WALK_CHUNK)]
    walked = run_each(lambda v: _walk_fans(twin, Fr, v, start[v], corners[v]), chunks)
    for bad_v, _ in walked:
        bad[bad_v] = True
    rest = np.concatenate([left for _, left in walked]) if walked else todo[:0]
    if rest.size:  # very high valence: union-find the rest
        U, W = half_edge_ends(F) if ends is None else ends
        bad[rest[_fans_union_find(F, twin, U, W, rest, n)[rest] > 1]] = True
    return bad


#: bits per axis of the packed grid keys of :func:`coincident_pairs`
GRID_BITS = 21


def coincident_pairs(P, distance):
    """Pairs (k,2) of rows of the points ``P`` (k,3) that share a cell of one
    of four grids of cell ``4 distance``, each shifted by a quarter cell along
    the diagonal: two points closer than ``distance`` along every axis share
    a cell in at least one grid (each axis can separate them in at most one),
    and no pair farther than ``4 distance`` per axis does. Within a cell the
    pairs chain its points in some order (join them with
    :func:`~.topology.connected_labels`: the groups are the same in any);
    exact copies of a point pair with one of them and skip the grids.
    A far point makes the grid too wide for packed keys: its cells are then
    compared column by column; with ``distance`` 0, or cells beyond int64,
    exactly equal points."""
    P = P + 0.0                                    # -0.0 and 0.0 are the same place
    first = _first_of_equal(P)
    own = first == np.arange(P.shape[0])
    dup = np.flatnonzero(~own)
    found = [np.stack([dup, first[dup]], axis=1)]  # exact copies: to the first, no grid
    if dup.size:
        rows = np.flatnonzero(own)
        P = P[rows]
    cell = 4.0 * distance
    lo = P.min(axis=0, initial=0.0)                        # (P >= 0: the grid starts at 0)
    extent = float((P.max(axis=0, initial=0.0) - lo).max(initial=0.0))
    if cell > 0 and extent / cell + 2 < 2.0 ** 62:
        Pc = (P - lo) / cell
        grids = [_same_cell_pairs(np.floor(Pc + k / 4.0).astype(np.int64)) for k in range(4)]
    else:
        grids = [_same_cell_pairs(None, P)]
    found += [rows[g] for g in grids] if dup.size else grids
    return np.concatenate(found)


def _first_of_equal(P):
    """For every row of ``P`` (k,3) a row exactly equal to it, the same for
    all of them (the first of their hash's run; itself when it has no equal):
    one sort of a hash of the coordinates' bits, equal hashes checked
    coordinate by coordinate (a collision only leaves rows apart, for the
    grids to pair). A triangle soup as an STL file stores it, each vertex
    once per face, goes to the grids with a sixth of its rows."""
    k = P.shape[0]
    first = np.arange(k, dtype=np.int64)
    if k < 2:
        return first
    bits = np.ascontiguousarray(P).view(np.uint64)   # (equal bits: equal points, -0.0 gone)
    h = bits[:, 0] * np.uint64(0x9E3779B97F4A7C15)
    h ^= bits[:, 1] * np.uint64(0xC2B2AE3D27D4EB4F)
    h ^= bits[:, 2] * np.uint64(0x165667B19E3779F9)
    hs = np.sort(h)                                  # (values only: a fast sort)
    if not (hs[1:] == hs[:-1]).any():
        return first                                 # no two alike (a jittered soup: +7%)
    order = np.argsort(h)
    hs = h[order]
    head = np.concatenate([[True], hs[1:] != hs[:-1]])
    at = np.flatnonzero(head)[np.cumsum(head) - 1]   # sorted position of each run's first
    same = np.ones(k, dtype=bool)
    for c in range(3):
        col = bits[:, c][order]
        same &= col == col[at]
    first[order[same]] = order[at[same]]
    return first


def _same_cell_pairs(Q, P=None):
    """Pairs (k,2) of row indices that are neighbours in sorted order and
    equal: integer cells ``Q`` (k,3), >= 0 (packed into one key when they fit
    ``GRID_BITS`` per axis), or exact points ``P``."""
    if Q is not None and Q.max(initial=0) < 2 ** GRID_BITS:
        key = (Q[:, 0] << 2 * GRID_BITS) | (Q[:, 1] << GRID_BITS) | Q[:, 2]
        order = np.argsort(key)          # (not stable: 2.3x faster; the groups are the same)
        same = key[order[1:]] == key[order[:-1]]
    else:
        R = P if Q is None else Q
        order = np.lexsort((R[:, 2], R[:, 1], R[:, 0]))
        S = R[order]
        same = (S[1:] == S[:-1]).all(axis=1)
    i = np.flatnonzero(same)
    return np.stack([order[i], order[i + 1]], axis=1)
