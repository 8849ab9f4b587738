"""The batched edge-collapse engine behind :func:`core.simplify.simplify`.

State: faces ``F`` plus per half-edge arrays (``h = 3 f + c`` is the edge of
face ``f`` opposite corner ``c``, see ``core._clean``): the twin table, the
crease flag, the cached collapse cost / position / error of the edge (kept on
its representative half-edge: the one with ``twin < 0`` or ``h < twin``),
and the "rejected until the neighbourhood changes" memory. Compaction keeps
the order of faces, so a representative stays a representative.

One pass::

    recost the edges that touch a vertex moved by the previous pass
    pool = cheapest candidates (bounded share; bounded by the collapses needed)
    rounds:  chosen = pool edges whose rank is the smallest over every face
             around both endpoints  -> the stars of chosen edges are disjoint
             check chosen edges on the current mesh (link condition, flips,
             turn against the input normals, compactness and Hausdorff
             penalties); accept those within the pool's cost bound;
             their closed one-rings become untouchable for later rounds
    apply all accepted collapses at once, glue twins; removed faces and
    vertices are only marked dead until a quarter of the rows are (then compact)
"""

import numpy as np

from ._clean import _NEXT_OFF, _PREV_OFF, BOUNDARY, NON_MANIFOLD, renumber_twins
from ._parallel import blocks, run_blocks, run_each
from .quadrics import place_columns, quadric_at, rms_distance
from .spatial import _kernel, _triangle_rows

_BIG = np.iinfo(np.int64).max
DEAD = -3  #: twin of a half-edge of a removed face (before compaction)
_COMPACT = 0.75  # compact once the live faces are fewer than this share of the rows
_SQRT3x2 = 2.0 * np.sqrt(3.0)
_BLOCK = 1 << 16  # elements per block of work (see core._parallel)
_SNAP2 = 1e-12  # (distance / edge length)^2 below which a position is an endpoint
_SAMPLE = 1 << 16  # cost thresholds of larger arrays come from a sample of about this size

_take = np.take
_NEXT = np.array([1, 2, 0], dtype=np.int64)  # corner after c
_PREV = np.array([2, 0, 1], dtype=np.int64)  # corner before c

#: per half-edge cache arrays and the value a new half-edge starts with (besides
#: ``twin``, ``feat`` and the three position columns ``c_x``)
HALF_EDGE_CACHE = {"swap": False, "blk_pass": -1, "c_cost": 0.0, "c_blk": -1.0, "c_stale": True}


class State:
    """Mutable working mesh of one simplification (private)."""

    def __init__(self, V, F, twin, Q, locked, feat, Nref, forig=None):
        n, h3 = V.shape[0], twin.size
        self.V, self.locked = V.copy(), locked           # (V stays the input: relocation samples it)
        self.Q = np.ascontiguousarray(Q.T)             # (11,n): one row per coefficient
        self.VT = np.ascontiguousarray(V.T)            # (3,n) copy of V for column gathers
        self.moved = np.zeros(n, dtype=bool)
        self.orig = np.arange(n, dtype=np.int64)       # clean index of each current vertex
        self.vver = np.full(n, -1, dtype=np.int64)     # pass in which the one-ring last changed
        self.fresh = np.ones(n, dtype=bool)            # quadric / position changed: recost edges
        self.is_bnd = np.zeros(n, dtype=bool)          # on a boundary edge
        self.Nref = Nref                               # summed area normals of the input faces merged in
        hb = np.flatnonzero(twin == BOUNDARY)
        if hb.size:
            ub, wb = _ends(F, hb)
            self.is_bnd[ub] = True
            self.is_bnd[wb] = True
        self.F, self.twin, self.feat = F, twin, feat
        # input face each face descends from (the output keeps input order); caps: a rim face's
        self.forig = np.arange(F.shape[0], dtype=np.int64) if forig is None else forig
        # per half-edge cache (on representatives): survivor is the half-edge's second
        # end (swap), pass of the remembered rejection and its value (blk_pass, c_blk),
        # cost, position, and whether the cost is only a lower bound (c_stale)
        for name, fill in HALF_EDGE_CACHE.items():
            setattr(self, name, np.full(h3, fill))
        self.c_x = [np.zeros(h3), np.zeros(h3), np.zeros(h3)]
        self.cur_of_clean = np.arange(n, dtype=np.int64)
        self.parent = np.arange(n, dtype=np.int64)      # survivor of each vertex merged since the last compaction
        # removed faces and vertices stay in the arrays (faces marked dead, their
        # half-edges' twin DEAD) until enough have gone to make compaction pay
        self.alive = np.ones(F.shape[0], dtype=bool)
        self.dead_v = np.zeros(n, dtype=bool)
        self.m_live = F.shape[0]
        self.worst = 0.0
        self.wit = V.copy()                            # witness: merged input point farthest from the surface


def _ends(F, h):
    """Endpoints (U, W) of half-edges ``h``."""
    Fr = F.ravel()
    c = h % 3
    return _take(Fr, h + _take(_NEXT_OFF, c)), _take(Fr, h + _take(_PREV_OFF, c))


def compactness(l, sumsq):
    """Garland's compactness ``4 sqrt(3) area / sum of squared edge lengths``
    (1 for an equilateral triangle, 0 for a degenerate one) from ``l`` = twice
    the areas and ``sumsq`` = the sums of squared edge lengths."""
    return _SQRT3x2 * l / np.where(sumsq > 0, sumsq, 1.0)


def _corner(Fs, v):
    """Corner (0, 1, 2) of vertex ``v[i]`` in face row ``Fs[i]``, -1 where absent."""
    e0, e1, e2 = Fs[:, 0] == v, Fs[:, 1] == v, Fs[:, 2] == v
    c = (e0 | e1 | e2).astype(np.int64) - 1
    c += e1
    c += 2 * e2
    return c


def _distance(st, cost, a, b):
    """RMS distance ``sqrt(cost / w)`` of edge collapses (``w``: the merged
    quadric's area; 0 where it has none), in working units."""
    return rms_distance(cost, _take(st.Q[10], a) + _take(st.Q[10], b))


def _recost(st, rep, U, W, stale, preserve_boundary):
    """Placement and cost of the edges ``rep[stale]`` (``stale``: indices),
    written into the cache (in blocks, on the worker threads)."""
    hs_all, a_all, b_all = _take(rep, stale), _take(U, stale), _take(W, stale)

    def block(i, j):
        hs, a, b = hs_all[i:j], a_all[i:j], b_all[i:j]
        interior = st.twin[hs] >= 0
        is_bnd, lock = st.is_bnd, st.locked
        la, lb, ba, bb = lock[a], lock[b], is_bnd[a], is_bnd[b]
        valid = ~(la & lb) & ~(interior & ba & bb)
        if preserve_boundary:  # a boundary vertex never merges into a locked interior one
            valid &= ~(interior & ((la & bb) | (lb & ba)))
        # survivor: a locked endpoint, else the boundary endpoint of an interior edge
        swap = lb | (~la & preserve_boundary & interior & bb)
        a, b = np.where(swap, b, a), np.where(swap, a, b)
        la, ba = np.where(swap, lb, la), np.where(swap, bb, ba)
        q = _take(st.Q, a, axis=1)
        q += _take(st.Q, b, axis=1)
        pa, pb = _take(st.VT, a, axis=1), _take(st.VT, b, axis=1)
        X, err = place_columns(q, pa, pb)
        # a position within round-off of an endpoint is that endpoint (it stays exact)
        E = pb - pa
        tol2 = _SNAP2 * (E[0] * E[0] + E[1] * E[1] + E[2] * E[2])
        D = X - pb
        snap_b = D[0] * D[0] + D[1] * D[1] + D[2] * D[2] <= tol2
        D = X - pa
        pin = (D[0] * D[0] + D[1] * D[1] + D[2] * D[2] <= tol2) | la | (preserve_boundary & interior & ba)
        snap_b &= ~pin
        X = np.where(pin, pa, np.where(snap_b, pb, X))
        fix = np.flatnonzero(pin | snap_b)
        if fix.size:
            err[fix] = quadric_at(q[:, fix], *X[:, fix])
        st.c_cost[hs] = np.where(valid, err, np.inf)
        for c in range(3):
            st.c_x[c][hs] = X[c]
        st.swap[hs] = swap

    run_blocks(block, blocks(hs_all.size, _BLOCK))


def _check(st, A, B, X, interior, star, kf, tun, haus=True):
    """:func:`_check_block` over blocks of collapses, on the worker threads.
    Same results; the star rows come back grouped by block."""
    spans = blocks(A.size, _BLOCK // 10)
    if len(spans) <= 1:
        return _check_block(st, A, B, X, interior, star, kf, tun, haus)
    starts = np.array([i for i, _ in spans], dtype=np.int64)
    blk = np.searchsorted(starts, kf, side="right") - 1
    order = np.argsort(blk, kind="stable")
    cut = np.concatenate([[0], np.cumsum(np.bincount(blk, minlength=len(spans)))])
    star, kf = star[order], kf[order]

    def block(b):
        (i, j), r0, r1 = spans[b], cut[b], cut[b + 1]
        return _check_block(st, A[i:j], B[i:j], X[i:j], interior[i:j], star[r0:r1], kf[r0:r1] - i, tun, haus)

    res = run_each(block, range(len(spans)))
    ok, pen, wnew = (np.concatenate([r[c] for r in res]) for c in (0, 1, 3))
    coll, cA, cB = (np.concatenate([r[2][c] for r in res]) for c in (2, 3, 4))
    return ok, pen, (star, kf, coll, cA, cB), wnew


def _common_pairs(ka, xa, kb, xb, n):
    """For each pair ``(kb[i], xb[i])``: is ``(kb[i], xb[i])`` among the pairs
    ``(ka, xa)``? Marks vertices with their collapse (last write wins) and
    settles the few vertices claimed by several collapses with a sort."""
    mark = np.full(n, -1, dtype=np.int64)
    mark[xa] = ka
    hit = _take(mark, xb) == kb
    lost = _take(mark, xa) != ka
    if lost.any():
        contested = np.zeros(n, dtype=bool)
        contested[xa[lost]] = True
        sa = np.flatnonzero(contested[xa])
        sb = np.flatnonzero(contested[xb])
        nn = np.int64(max(n, 1))
        keys = np.sort(ka[sa] * nn + xa[sa])
        q = kb[sb] * nn + xb[sb]
        pos = np.minimum(np.searchsorted(keys, q), keys.size - 1)
        hit[sb] = keys[pos] == q
    return hit


def _check_block(st, A, B, X, interior, star, kf, tun, haus=True):
    """Validity and compactness penalty of independent collapses B[k] -> A[k]
    at X[k], judged on the current mesh.

    ``star`` lists every face around the endpoints, ``kf`` the collapse each
    belongs to. Returns ``ok`` (k,) bool, ``penalty`` (k,), the star rows
    ``(star, kf, coll, cA, cB)``: face ids, their collapse index, whether each
    face is removed, and the corners of A and B in it (-1: absent), and the
    survivor's witness (k,3): of A's and B's witnesses, the one farther from
    the new faces.
    """
    F, V = st.F, st.V
    n, k = V.shape[0], A.size
    Fs = _take(F, star, axis=0)
    Ak, Bk = _take(A, kf), _take(B, kf)
    cA = _corner(Fs, Ak)
    cB = _corner(Fs, Bk)
    rowsA, rowsB = cA >= 0, cB >= 0
    coll = rowsA & rowsB
    ok = np.ones(k, dtype=bool)
    Fr = Fs.ravel()

    # --- link condition (Dey et al.): the common neighbours of A and B are
    # exactly the opposite vertices of the removed faces
    cidx = np.flatnonzero(coll)
    kc = _take(kf, cidx)
    cv = _take(Fr, 3 * cidx + 3 - _take(cA, cidx) - _take(cB, cidx))  # opposite vertex of each removed face
    order = np.argsort(kc, kind="stable")
    ck, cv = _take(kc, order), _take(cv, order)
    first = np.ones(ck.size, dtype=bool)
    first[1:] = ck[1:] != ck[:-1]
    opp = np.full((k, 2), -1, dtype=np.int64)
    opp[ck[first], 0] = cv[first]
    opp[ck[~first], 1] = cv[~first]
    n_removed = np.bincount(ck, minlength=k)
    ok &= n_removed == np.where(interior, 2, 1)
    # the faces that stay (each has A or B, not both), the corner that moves,
    # and its two other vertices: neighbours of A (or B) other than the opposite ones
    mv = np.flatnonzero(~coll)
    mk = _take(kf, mv)
    onA = _take(rowsA, mv)
    cm = np.where(onA, _take(cA, mv), _take(cB, mv))
    base = 3 * mv
    x1 = _take(Fr, base + _take(_NEXT, cm))
    x2 = _take(Fr, base + _take(_PREV, cm))
    ia, ib = np.flatnonzero(onA), np.flatnonzero(~onA)
    if ia.size and ib.size:
        ka = np.concatenate([_take(mk, ia), _take(mk, ia)])
        xa = np.concatenate([_take(x1, ia), _take(x2, ia)])
        qk = np.concatenate([_take(mk, ib), _take(mk, ib)])
        qx = np.concatenate([_take(x1, ib), _take(x2, ib)])
        common = _common_pairs(ka, xa, qk, qx, n)
        extra = common & (qx != _take(opp[:, 0], qk)) & (qx != _take(opp[:, 1], qk))
        ok[qk[extra]] = False
    # not the last tetrahedron (both endpoints of valence 3)
    valA = np.bincount(kf[rowsA], minlength=k)
    valB = np.bincount(kf[rowsB], minlength=k)
    ok &= ~(interior & (valA == 3) & (valB == 3))
    # not an isolated triangle; never touch a non-manifold edge
    hA = 3 * star[cidx] + _take(cA, cidx)   # edge (B, c)
    hB = 3 * star[cidx] + _take(cB, cidx)   # edge (c, A)
    tA, tB = st.twin[hA], st.twin[hB]
    bad = (tA == NON_MANIFOLD) | (tB == NON_MANIFOLD) | ((tA == BOUNDARY) & (tB == BOUNDARY))
    ok[kc[bad]] = False

    # --- geometry of the faces that move (one corner each: A or B goes to X)
    FmT = np.ascontiguousarray(_take(Fs, mv, axis=0).T)   # (contiguous index rows gather much faster)
    P0, P1, P2 = (_take(V, FmT[c], axis=0) for c in range(3))
    Xm = _take(X, mk, axis=0)
    Q0 = np.where((cm == 0)[:, None], Xm, P0)
    Q1 = np.where((cm == 1)[:, None], Xm, P1)
    Q2 = np.where((cm == 2)[:, None], Xm, P2)
    o0, o1, o2 = P1 - P0, P2 - P1, P0 - P2
    e0, e1, e2 = Q1 - Q0, Q2 - Q1, Q0 - Q2
    N0 = np.cross(o0, -o2)
    N1 = np.cross(e0, -e2)
    l0 = np.sqrt(np.einsum("ij,ij->i", N0, N0))
    l1 = np.sqrt(np.einsum("ij,ij->i", N1, N1))
    flip = (l0 > 0) & (np.einsum("ij,ij->i", N0, N1) <= tun.flip_cos * l0 * l1)
    # and never against the input surface the face stands for (the summed
    # normals of the input faces merged into its vertices): no slow drift
    if tun.ref_cos > -1.0:
        Nr = st.Nref
        moved_v = _take(Fr, base + cm)
        ref0 = _take(Nr, FmT[0], axis=0) + _take(Nr, FmT[1], axis=0) + _take(Nr, FmT[2], axis=0)
        ref = ref0 - _take(Nr, moved_v, axis=0) + _take(_take(Nr, A, axis=0) + _take(Nr, B, axis=0), mk, axis=0)
        lr = np.sqrt(np.einsum("ij,ij->i", ref, ref))
        flip |= np.einsum("ij,ij->i", ref, N1) < tun.ref_cos * lr * l1
        # a face already against its input (a fold of a noisy input) may move freely:
        # holding it would freeze its whole neighbourhood at full resolution
        flip &= np.einsum("ij,ij->i", ref0, N0) >= 0
    ok[mk[flip]] = False
    sumsq = np.einsum("ij,ij->i", e0, e0) + np.einsum("ij,ij->i", e1, e1) + np.einsum("ij,ij->i", e2, e2)
    g_new = compactness(l1, sumsq)
    osq = np.einsum("ij,ij->i", o0, o0) + np.einsum("ij,ij->i", o1, o1) + np.einsum("ij,ij->i", o2, o2)
    g_old = compactness(l0, osq)
    gmin_new = np.ones(k)
    np.minimum.at(gmin_new, mk, g_new)
    gmin_old = np.ones(k)
    np.minimum.at(gmin_old, mk, g_old)
    ok &= ~((gmin_new < tun.gamma_hard) & (gmin_new < 0.5 * gmin_old))
    area = np.bincount(mk, weights=0.5 * l1, minlength=k)
    D = _take(V, B, axis=0) - _take(V, A, axis=0)
    L2 = np.einsum("ij,ij->i", D, D)
    # only collapses that make the neighbourhood less compact than it was pay
    short = np.maximum(0.0, np.minimum(gmin_old, tun.gamma_soft) - gmin_new) / tun.gamma_soft
    penalty = tun.compact_weight * area * L2 * short * short
    # --- Hausdorff-aware term: distance of the witnesses of A and B (the input
    # points merged into them that were farthest from the surface) to the new faces
    wA, wB = _take(st.wit, A, axis=0), _take(st.wit, B, axis=0)
    wnew = wA
    if haus and tun.haus_weight > 0.0 and mk.size:
        Pa = np.concatenate([wA[mk], wB[mk]])
        _, _, d2 = _kernel(Pa[:, 0].copy(), Pa[:, 1].copy(), Pa[:, 2].copy(),
                           _triangle_rows(np.concatenate([Q0, Q0]), np.concatenate([Q1, Q1]),
                                          np.concatenate([Q2, Q2])))
        dA = np.full(k, np.inf)
        np.minimum.at(dA, mk, d2[:mk.size])
        dB = np.full(k, np.inf)
        np.minimum.at(dB, mk, d2[mk.size:])
        dA[~np.isfinite(dA)] = 0.0
        dB[~np.isfinite(dB)] = 0.0
        wnew = np.where((dB > dA)[:, None], wB, wA)
        Wq = _take(st.Q[10], A) + _take(st.Q[10], B)
        penalty = penalty + tun.haus_weight * Wq * np.maximum(dA, dB)
    return ok, penalty, (star, kf, coll, cA, cB), wnew


def _thinned(x):
    """``x`` itself up to ``4 * _SAMPLE`` values, else an evenly strided
    sample of ``_SAMPLE`` to ``2 * _SAMPLE`` of them (a view; deterministic)."""
    return x if x.size <= 4 * _SAMPLE else x[::x.size // _SAMPLE]


def _kth_smallest(x, k):
    """The ``k``-th smallest value of ``x`` (0-based). Exact for arrays of up to
    ``4 * _SAMPLE``; for larger ones estimated from :func:`_thinned`, two
    standard deviations of the estimate on the high side (a pool bound then
    takes a few more edges, never many fewer)."""
    s = _thinned(x)
    if s is x:
        return np.partition(x, k)[k]
    q = (k + 1) / x.size
    j = int(np.ceil(q * s.size + 2.0 * np.sqrt(q * (1.0 - q) * s.size)))
    j = min(max(j, 0), s.size - 1)
    return np.partition(s, j)[j]


def _pool_size(ne, m, target, tun):
    """How many of the ``ne`` candidate edges one pass may consider."""
    P = int(np.ceil(tun.pool_share * ne))
    if target is not None:
        P = min(P, int(np.ceil(tun.pool_goal_factor * (m - target) / 2.0)) + 1)
    return max(1, min(P, ne))


def _bands(x, n):
    """Band 0..n-1 of every value of ``x``: its place among ``n - 1``
    quantiles of ``x`` (of a sample on large arrays)."""
    s = _thinned(x)
    ks = (np.arange(1, n, dtype=np.int64) * s.size) // n
    return np.searchsorted(np.partition(s, ks)[ks], x, side="left").astype(np.int64)


def _priority(cost, length2, a, b, tun):
    """Unique int64 priority of each pool edge (smaller first), without a sort:
    the cost band (quantiles of the pool's costs) in the high bits, then the
    length band (shorter edges first: on a plateau of equal costs they make
    the most compact triangles), then a fixed hash of the endpoints (dense
    local minima), the pool index in the low bits (``key & (2^bits - 1)``
    gives it back)."""
    P = cost.size
    bits = max(1, int(P - 1).bit_length())
    if bits > 28:
        raise OverflowError("simplify: more than 2^28 edges in one pass")
    band = _bands(cost, tun.bands) if P > tun.bands else np.zeros(P, dtype=np.int64)
    lband = _bands(length2, tun.length_bands) if P > tun.length_bands else np.zeros(P, dtype=np.int64)
    mix = ((a * np.int64(0x9E3779B1)) ^ (b * np.int64(0x85EBCA77))) & np.int64(0x3FFFFFF)
    mix |= lband << np.int64(26)
    return (((band << np.int64(31)) | mix) << np.int64(bits)) | np.arange(P, dtype=np.int64)


def _acceptance_bound(limit, totals, tun):
    """Largest total (cost + penalties) a checked collapse may have: the
    pool's cost bound, or on a plateau -- the bound below ``plateau_share``
    of the median total of the valid collapses checked, as on a flat region
    where every cost is 0 and only the penalties differ -- that median (the
    cheaper half goes; otherwise every pass would take only the collapses
    without any penalty)."""
    if totals.size == 0:
        return limit
    med = float(np.median(totals))
    return med if limit < tun.plateau_share * med else limit


def run(st, target, max_err_n, preserve_boundary, progress, m0, tun):
    """The batched collapse loop. Returns (stopped_because, passes); the
    state is compact afterwards."""
    try:
        return _run(st, target, max_err_n, preserve_boundary, progress, m0, tun)
    finally:
        _compact(st)


def _run(st, target, max_err_n, preserve_boundary, progress, m0, tun):
    passes = 0
    while passes < tun.max_passes:
        if st.m_live < _COMPACT * st.F.shape[0]:
            _compact(st)
        F, twin = st.F, st.twin
        m, n = st.m_live, st.V.shape[0]
        if target is not None and m <= target:
            return "target", passes
        # the Hausdorff penalty matters once the cage is coarse: skip it before
        haus = target is None or m <= tun.haus_phase * target
        if progress is not None and passes > 0:
            if target is not None and m0 > target:
                frac = (m0 - m) / (m0 - target)
            else:
                frac = (m0 - m) / max(m0, 1)
            if progress(float(min(max(frac, 0.0), 1.0))) is False:
                return "cancelled", passes
        passes += 1
        h = np.arange(twin.size, dtype=np.int64)
        rep = np.flatnonzero((twin == BOUNDARY) | (twin > h))
        U, W = _ends(F, rep)
        st.c_stale[rep[st.fresh[U] | st.fresh[W]]] = True
        st.fresh[:] = False
        stale = _take(st.c_stale, rep)
        cost = _take(st.c_cost, rep)
        bv = _take(st.c_blk, rep)
        mem = np.flatnonzero(bv >= 0)           # rejections remembered until the neighbourhood changes
        blocked = np.zeros(rep.size, dtype=bool)
        blocked[mem] = _take(st.blk_pass, rep[mem]) > np.maximum(_take(st.vver, U[mem]), _take(st.vver, W[mem]))
        cost = np.where(blocked, np.maximum(cost, bv), cost)
        cand = np.isfinite(cost)
        ne = int(np.count_nonzero(cand))
        if ne == 0:
            return "no_valid_collapse", passes
        P = _pool_size(ne, m, target, tun)
        # lazy recosting: merging only adds quadrics, so the cached cost of a
        # stale edge is a lower bound of its new cost; recost only the stale
        # edges that could still be among the P cheapest
        need = stale & cand
        if max_err_n is None and P < ne:
            need &= cost <= _kth_smallest(cost, P - 1)    # (non-candidates are inf: they sort last)
        ni = np.flatnonzero(need)
        if ni.size:
            _recost(st, rep, U, W, ni, preserve_boundary)
            hn = _take(rep, ni)
            st.c_stale[hn] = False
            stale[ni] = False
            fresh_cost = _take(st.c_cost, hn)
            cost[ni] = np.where(_take(blocked, ni), np.maximum(fresh_cost, _take(bv, ni)), fresh_cost)
        cand = np.isfinite(cost)
        if max_err_n is not None:
            within = _distance(st, _take(st.c_cost, rep), U, W) <= max_err_n
            if not (cand & within).any():
                return ("max_error" if cand.any() else "no_valid_collapse"), passes
            cand &= within
        cand &= ~stale
        ci = np.flatnonzero(cand)
        if ci.size == 0:
            if stale.any():
                continue
            return "no_valid_collapse", passes
        # pool: every fresh candidate no costlier than the P-th cheapest (ties included)
        ne = ci.size
        P = max(1, min(P, ne))
        cc = cost[ci]
        limit = _kth_smallest(cc, P - 1) if P < ne else cc.max()
        pool = ci[cc <= limit]
        P = pool.size
        ph = rep[pool]
        sw = st.swap[ph]
        pa = np.where(sw, W[pool], U[pool])
        pb = np.where(sw, U[pool], W[pool])
        pX = np.stack([_take(c, ph) for c in st.c_x], axis=1)
        pint = twin[ph] >= 0
        pcost = cost[pool]
        praw = _take(st.c_cost, ph)
        D = _take(st.V, pb, axis=0) - _take(st.V, pa, axis=0)
        key = _priority(pcost, np.einsum("ij,ij->i", D, D), pa, pb, tun)

        touched = np.zeros(n, dtype=bool)
        acc_edges, acc_wit, acc_rows = [], [], []
        active = np.arange(P, dtype=np.int64)
        FT = None                               # faces that may still touch an active edge (transposed)
        imask = (np.int64(1) << np.int64(max(1, int(P - 1).bit_length()))) - 1
        for _ in range(tun.max_rounds):
            active = active[~touched[pa[active]] & ~touched[pb[active]]]
            if active.size == 0:
                break
            ka, aa, ab = key[active], pa[active], pb[active]
            vmin = np.full(n, _BIG, dtype=np.int64)
            np.minimum.at(vmin, aa, ka)
            np.minimum.at(vmin, ab, ka)
            if FT is None:                        # first round: every live face
                G = _take(vmin, F)
                fmin = np.minimum(np.minimum(G[:, 0], G[:, 1]), G[:, 2])
                del G
                fidx = np.flatnonzero((fmin < _BIG) & st.alive)
                FT = np.ascontiguousarray(_take(F, fidx, axis=0).T)
                fh = _take(fmin, fidx)
            else:
                fmin = np.minimum(np.minimum(_take(vmin, FT[0]), _take(vmin, FT[1])), _take(vmin, FT[2]))
                live = np.flatnonzero(fmin < _BIG)
                if live.size < 0.75 * fidx.size:  # keep only the faces still in play
                    FT = np.ascontiguousarray(FT[:, live])
                    fidx = fidx[live]
                    fh = _take(fmin, live)
                else:                             # (a _BIG minimum changes nothing below)
                    fh = fmin
            vmin2 = np.full(n, _BIG, dtype=np.int64)
            for j in range(3):
                np.minimum.at(vmin2, FT[j], fh)
            chosen = ka == np.minimum(_take(vmin2, aa), _take(vmin2, ab))
            sel = active[chosen]
            active = active[~chosen]
            # the star of a chosen edge is exactly the set of faces whose minimum is its key
            pos = np.full(P, -1, dtype=np.int64)
            pos[sel] = np.arange(sel.size)
            fpos = np.where(fh < _BIG, _take(pos, np.minimum(fh & imask, P - 1)), -1)
            in_star = fpos >= 0
            star = fidx[in_star]
            kf = fpos[in_star]
            ok, pen, rows, wnew = _check(st, pa[sel], pb[sel], pX[sel], pint[sel], star, kf, tun, haus)
            total = praw[sel] + pen
            acc = ok & (total <= _acceptance_bound(limit, total[ok], tun))
            # remember rejections until the neighbourhood changes
            rej = ~acc
            val = np.where(ok[rej], total[rej], np.inf)
            hr = ph[sel[rej]]
            st.c_blk[hr] = val
            st.blk_pass[hr] = passes
            if acc.any():
                rows = _keep_rows(rows, acc, sum(x.size for x in acc_edges))
                acc_edges.append(sel[acc])
                acc_wit.append(wnew[acc])
                acc_rows.append(rows)
                touched[_take(F, rows[0], axis=0).ravel()] = True
        if not acc_edges:
            continue
        acc = np.concatenate(acc_edges)
        rows = tuple(np.concatenate(c) for c in zip(*acc_rows))
        s_wit = np.concatenate(acc_wit)
        if target is not None:
            removed = np.where(pint[acc], 2, 1)
            order = np.argsort(pcost[acc], kind="stable")
            before = np.empty(acc.size, dtype=np.int64)
            before[order] = np.cumsum(removed[order]) - removed[order]
            keep_k = before < m - target
            if not keep_k.all():
                acc = acc[keep_k]
                s_wit = s_wit[keep_k]
                rows = _keep_rows(rows, keep_k)
        st.worst = max(st.worst, float(_distance(st, praw[acc], pa[acc], pb[acc]).max()))
        st.vver[touched] = passes
        st.wit[pa[acc]] = s_wit
        _apply(st, pa[acc], pb[acc], pX[acc], rows)
    return "no_valid_collapse", passes


def _keep_rows(rows, keep, offset=0):
    """The star rows ``(star, kf, coll, cA, cB)`` of the collapses ``keep``
    (bool per collapse), renumbered from ``offset``."""
    kf = rows[1]
    r = np.flatnonzero(_take(keep, kf))
    out = [_take(c, r) for c in rows]
    out[1] = _take(np.cumsum(keep) - 1 + offset, out[1])
    return tuple(out)


def _apply(st, A, B, X, rows):
    """Collapse every B[k] into A[k] at X[k] at once (stars disjoint;
    ``rows`` as returned by :func:`_check`)."""
    F, twin = st.F, st.twin
    star, kf, coll, cA, cB = rows
    rc = np.flatnonzero(coll)
    cf = _take(star, rc)
    # glue the twins of the two surviving sides of every removed face
    hA = 3 * cf + _take(cA, rc)   # edge (B, c)
    hB = 3 * cf + _take(cB, rc)   # edge (c, A)
    tA, tB = twin[hA], twin[hB]
    fl = st.feat[hA] | st.feat[hB]
    okA, okB = tA >= 0, tB >= 0
    twin[tA[okA]] = tB[okA]
    twin[tB[okB]] = tA[okB]
    st.feat[tA[okA]] = fl[okA]
    st.feat[tB[okB]] = fl[okB]
    # positions and quadrics
    VA = _take(st.VT, A, axis=1)
    st.moved[A] |= (X[:, 0] != VA[0]) | (X[:, 1] != VA[1]) | (X[:, 2] != VA[2])
    for q in st.Q:                                 # one coefficient row at a time (A are distinct)
        np.put(q, A, _take(q, A) + _take(q, B))
    st.Nref[A] = _take(st.Nref, A, axis=0) + _take(st.Nref, B, axis=0)
    st.V[A] = X
    st.VT[:, A] = X.T
    st.fresh[A] = True
    st.is_bnd[A] |= st.is_bnd[B]
    # B leaves the faces around it; the removed faces and B are marked dead
    r = np.flatnonzero(~coll & (cB >= 0))
    np.put(F, 3 * _take(star, r) + _take(cB, r), _take(A, _take(kf, r)))
    twin[(3 * cf[:, None] + np.arange(3)).ravel()] = DEAD
    st.alive[cf] = False
    st.m_live -= cf.size
    st.dead_v[B] = True
    st.parent[B] = A


def _survivors(st):
    """Current vertex of every clean input vertex (``-1``: removed), following
    the merges since the last compaction (a few pointer jumps)."""
    cur = st.cur_of_clean
    ok = cur >= 0
    c = np.where(ok, cur, 0)
    while True:
        nxt = _take(st.parent, c)
        if np.array_equal(nxt, c):
            return np.where(ok, c, -1)
        c = nxt


def _compact(st):
    """Drop the dead faces and vertices from every array (one job per array,
    on the worker threads)."""
    keep_f, keep_v = st.alive, ~st.dead_v
    if keep_f.all() and keep_v.all():
        return
    new_f = np.cumsum(keep_f) - 1
    new_v = np.cumsum(keep_v) - 1
    ih = np.flatnonzero(np.repeat(keep_f, 3))
    iv = np.flatnonzero(keep_v)

    def on_h(a):   # per half-edge
        return _take(a, ih)

    def on_v(a):   # per vertex
        return _take(a, iv, axis=0)

    def on_vt(a):  # per vertex, coefficient-major
        return _take(a, iv, axis=1)

    per_vertex = ("V", "Nref", "wit", "locked", "moved", "orig", "vver", "fresh", "is_bnd")
    rules = {"twin": lambda a: renumber_twins(_take(a, ih), new_f),
             "F": lambda a: _take(new_v, np.compress(keep_f, a, axis=0)),
             "forig": lambda a: np.compress(keep_f, a),
             "feat": on_h, **dict.fromkeys(HALF_EDGE_CACHE, on_h), **dict.fromkeys(per_vertex, on_v),
             "Q": on_vt, "VT": on_vt}

    def swap(name):  # each job replaces one array: the old one goes as soon as its job is done
        if isinstance(name, int):
            st.c_x[name] = on_h(st.c_x[name])
        else:
            setattr(st, name, rules[name](getattr(st, name)))

    run_each(swap, [*rules, 0, 1, 2])
    cur = _survivors(st)
    st.cur_of_clean = np.where(cur >= 0, _take(new_v, np.maximum(cur, 0)), -1)  # -1: removed component
    st.alive = np.ones(st.F.shape[0], dtype=bool)
    st.dead_v = np.zeros(st.V.shape[0], dtype=bool)
    st.parent = np.arange(st.V.shape[0], dtype=np.int64)
    st.m_live = st.F.shape[0]
