"""Per-level stencils of the modified butterfly and Loop schemes for
:mod:`core.subdivide` (private).

Each level is a :class:`Stencil`: a CSR matrix (rows sorted) from the level's
vertices to the next level's. Rows are built as fixed-width tables (one column
array and one weight per slot), one table per kind of row (regular, sharp,
extraordinary of valence k, ...), and assembled by a counting scatter, so no
Python loop ever runs over vertices, edges or faces; the only loops run over
the few distinct valences and over the handful of slots. The rules are drawn
in the docstring of :mod:`core.subdivide`.
"""

from typing import NamedTuple

import numpy as np

from ._groups import ragged_entries, sorted_unique
from ._parallel import blocks as blocks_of, run_each
from ._refine import NEXT_CORNER, fan_ranks, next_corner


class _Block(NamedTuple):
    """Rows ``start:stop`` of a stencil as a padded fixed-width table (ELL):
    row ``start + i`` is ``sum_j weights[i, j] * X[cols[i * width + j]]``
    (padding has weight 0), or a plain copy of ``X[start:stop]``."""

    start: int
    stop: int
    copy: bool
    width: int
    cols: np.ndarray      #: ((stop-start) * width,) int64, empty for a copy
    weights: np.ndarray   #: (stop-start, width) float64, empty for a copy


class ApplyPlan(NamedTuple):
    """How :meth:`Stencil.apply_t` evaluates a level: contiguous row blocks as
    padded tables (one gather and one multiply-sum per column, no per-row
    overhead), and the few rows longer than their block's width from the CSR
    arrays with ``np.add.reduceat``."""

    blocks: tuple
    chunks: tuple             #: ``(block, r0, r1)`` runs of rows (:func:`_apply_chunks`)
    long_rows: np.ndarray     #: (q,) int64
    long_starts: np.ndarray   #: (q,) offsets of each long row's entries in long_cols
    long_cols: np.ndarray     #: the long rows' CSR columns, row by row, gathered once
    long_weights: np.ndarray  #: ... and their weights


class Stencil(NamedTuple):
    """One subdivision level as a sparse matrix in CSR form (rows sorted).

    Row ``i`` (a fine vertex) is ``sum(weights[j] * X[cols[j]])`` for ``j`` in
    ``indptr[i]:indptr[i+1]``. Every row has at least one entry and sums to 1;
    a row may name a column twice (the weights add). ``plan`` is the same
    matrix rearranged for a fast :meth:`apply_t` (see :func:`make_plan`).
    """

    indptr: np.ndarray   #: (n_out+1,) int64
    cols: np.ndarray     #: (nnz,) int64, coarse vertex of each entry
    weights: np.ndarray  #: (nnz,) float64
    n_in: int
    plan: object = None  #: ApplyPlan or None (then apply_t uses the CSR arrays)

    @property
    def n_out(self):
        return self.indptr.shape[0] - 1

    def rows(self):
        """Row of each entry, (nnz,) int64."""
        return np.repeat(np.arange(self.n_out, dtype=np.int64), np.diff(self.indptr))

    def apply_t(self, Xt, out=None):
        """Column-major apply: ``Xt`` (k, n_in) C-contiguous -> (k, n_out).

        ``out``, if given, is a (k, n_out) float64 array of any strides (e.g.
        the transpose of a C-contiguous (n_out, k) result) and is returned.
        Gathers use ``take(..., mode="wrap")``: the indices are valid by
        construction, and it is about twice as fast as fancy indexing or the
        default bounds-checked ``mode="raise"`` (same values, bit for bit).
        """
        k = Xt.shape[0]
        if out is None:
            out = np.empty((k, self.n_out))
        if self.n_out == 0:
            return out
        if self.plan is None:
            starts = self.indptr[:-1]
            for d in range(k):
                g = Xt[d].take(self.cols, mode="wrap")
                g *= self.weights
                out[d] = np.add.reduceat(g, starts)
            return out
        p = self.plan

        def chunk(c):
            b, r0, r1 = c
            if b.copy:      # row by row: a 2-D copy into a transposed ``out`` is ~7x slower
                for d in range(k):
                    out[d, b.start + r0:b.start + r1] = Xt[d, b.start + r0:b.start + r1]
                return
            cols = b.cols[r0 * b.width:r1 * b.width]
            g = np.empty(cols.shape[0])
            g2 = g.reshape(r1 - r0, b.width)
            for d in range(k):
                Xt[d].take(cols, out=g, mode="wrap")
                np.einsum("ij,ij->i", g2, b.weights[r0:r1], out=out[d, b.start + r0:b.start + r1])
        run_each(chunk, p.chunks, threads=self.n_out >= _THREADED_APPLY)
        if p.long_rows.shape[0]:
            for d in range(k):
                g = Xt[d].take(p.long_cols, mode="wrap")
                g *= p.long_weights
                out[d, p.long_rows] = np.add.reduceat(g, p.long_starts)
        return out

    def rows_t(self, Xt, r):
        """``apply_t(Xt)[:, r]`` for the rows ``r`` (sorted, distinct) alone,
        each summed as :meth:`apply_t` sums it (a block's padded table row
        by ``np.einsum``, a long row, or every row without a plan, by
        ``np.add.reduceat``): bit for bit its values (an incremental deform
        recomputes the rows an edit changes; summed in another order they
        were 1e-16 apart, which the normals of fine faces an edit folds flat
        turned into dense rows 0.4-2.5% of the diagonal apart)."""
        out = np.empty((Xt.shape[0], r.shape[0]))
        p = self.plan
        if p is None:
            self._reduce_rows_t(Xt, r, out, np.arange(r.shape[0]))
            return out
        for b in p.blocks:
            lo, hi = np.searchsorted(r, (b.start, b.stop))
            if lo == hi:
                continue
            if b.copy:
                out[:, lo:hi] = Xt[:, r[lo:hi]]
                continue
            local = r[lo:hi] - b.start
            cols = b.cols.reshape(-1, b.width)[local]
            weights = np.ascontiguousarray(b.weights[local])
            g = np.empty(cols.shape)
            for d in range(Xt.shape[0]):
                Xt[d].take(cols, out=g, mode="wrap")
                np.einsum("ij,ij->i", g, weights, out=out[d, lo:hi])
        if p.long_rows.shape[0]:
            at = np.searchsorted(r, p.long_rows)
            hit = at < r.shape[0]
            hit[hit] = r[at[hit]] == p.long_rows[hit]
            if hit.any():
                self._reduce_rows_t(Xt, p.long_rows[hit], out, at[hit])
        return out

    def _reduce_rows_t(self, Xt, rows, out, slots):
        """``out[:, slots]`` = the CSR rows ``rows`` over ``Xt``, each summed in
        entry order with ``np.add.reduceat`` (as :meth:`apply_t` sums rows
        outside its plan's blocks)."""
        counts = self.indptr[rows + 1] - self.indptr[rows]
        k = ragged_entries(self.indptr[rows], counts)
        starts = np.cumsum(counts) - counts
        for d in range(Xt.shape[0]):
            g = Xt[d].take(self.cols[k], mode="wrap")
            g *= self.weights[k]
            out[d, slots] = np.add.reduceat(g, starts)

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


_MAX_WIDTH = 16
#: rows of a plan's block evaluated at once by :meth:`Stencil.apply_t` (a chunk's
#: gathered values stay in cache), and the rows of a level from which its chunks
#: run on the worker threads (the bunny at two levels, a re-apply on two cores:
#: butterfly 17.6 -> 10.1 ms, Loop 14.4 -> 8.2 ms, the same bits)
_APPLY_CHUNK = 32768
_THREADED_APPLY = 1 << 16


def _apply_chunks(blocks):
    """``(block, r0, r1)``: the plan's ``blocks`` cut into runs of at most
    ``_APPLY_CHUNK`` rows (``r0:r1`` relative to the block's start). A row
    is summed as in its whole block (one ``np.einsum`` row), so the results
    do not depend on the cuts."""
    return tuple((b, r0, r1) for b in blocks
                 for r0, r1 in blocks_of(b.stop - b.start, _APPLY_CHUNK))


def make_plan(S, bounds):
    """The :class:`ApplyPlan` of stencil ``S`` for row blocks ``bounds[i]:bounds[i+1]``.

    A block whose rows are all ``X[i]`` becomes a copy; otherwise its width is
    its most common row length (at most 16): shorter rows are padded with
    zero weights, longer ones are evaluated from the CSR arrays.
    """
    lens = np.diff(S.indptr)
    blocks, long_rows = [], []
    for r0, r1 in zip(bounds[:-1], bounds[1:]):
        r0, r1 = int(r0), int(r1)
        if r1 <= r0:
            continue
        L = lens[r0:r1]
        first = S.indptr[r0:r1]
        if np.all(L == 1) and np.array_equal(S.cols[first], np.arange(r0, r1)) \
                and np.all(S.weights[first] == 1.0):
            blocks.append(_Block(r0, r1, True, 1, np.zeros(0, np.int64), np.zeros((0, 1))))
            continue
        width = int(min(np.bincount(L).argmax(), _MAX_WIDTH))
        if np.all(L == width):      # a uniform block is a view of the CSR arrays
            e0, e1 = S.indptr[r0], S.indptr[r1]
            blocks.append(_Block(r0, r1, False, width, S.cols[e0:e1], S.weights[e0:e1].reshape(-1, width)))
            continue
        # slots past a row's end read the next row's entries: their weight is zeroed
        idx = first[:, None] + np.arange(width)
        cols = S.cols.take(idx, mode="clip")
        w = S.weights.take(idx, mode="clip")
        short = np.flatnonzero(L < width)
        w[short] *= np.arange(width) < L[short, None]
        too_long = np.flatnonzero(L > width)
        w[too_long] = 0.0
        long_rows.append(r0 + too_long)
        blocks.append(_Block(r0, r1, False, width, cols.ravel(), w))
    long_rows = np.concatenate(long_rows) if long_rows else np.zeros(0, dtype=np.int64)
    ll = lens[long_rows]
    starts = np.zeros(long_rows.shape[0], dtype=np.int64)
    np.cumsum(ll[:-1], out=starts[1:])
    entries = np.repeat(S.indptr[long_rows] - starts, ll) + np.arange(int(ll.sum()))
    return ApplyPlan(tuple(blocks), _apply_chunks(blocks), long_rows, starts, S.cols[entries],
                     S.weights[entries])


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
        cursor[t.rows] = _write_slots(out_c, out_w, cursor[t.rows], t)
    for t in patches:
        _write_slots(out_c, out_w, indptr[t.rows], t)
    return Stencil(indptr, out_c, out_w, n_in)


def _write_slots(out_c, out_w, pos, t):
    """Write table ``t``'s slots at entry positions ``pos`` (one per row),
    consecutive slots at consecutive entries; returns the next free positions."""
    pos = pos.copy()
    for col, w in zip(t.cols, t.weights):
        out_c[pos] = col
        out_w[pos] = w
        pos += 1
    return pos


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
    ring[start[Ff[cids]] + rank] = Ff[next_corner(cids)]
    rank_of_corner = np.full(Ff.shape[0], -1, dtype=np.int64)
    rank_of_corner[cids] = rank
    return start, ring, rank_of_corner


def butterfly_level(T):
    """Modified butterfly stencil for one level (see core.subdivide): even
    vertices keep their position; an odd (edge) vertex takes the 4-point
    rule on a sharp edge (:func:`_butterfly_sharp`), the 8-point stencil
    where neither end is extraordinary (:func:`_butterfly_regular`), else
    its extraordinary ends' ring stencils (:func:`_butterfly_extraordinary`)."""
    n = T.n
    ar_n = np.arange(n, dtype=np.int64)
    smooth_x = (T.n_sharp == 0) & (T.valence != 6) & (T.valence > 0)
    not_sharp = ~T.sharp
    xa = smooth_x[T.E[:, 0]] & not_sharp
    xb = smooth_x[T.E[:, 1]] & not_sharp
    tables = [_Table(ar_n, [ar_n], [1.0])] + _butterfly_sharp(T)
    regular, patches = _butterfly_regular(T, np.flatnonzero(not_sharp & ~xa & ~xb))
    tables += regular + _butterfly_extraordinary(T, smooth_x, xa, xb)
    S = _assemble(n + T.E.shape[0], n, tables, patches)
    return S._replace(plan=make_plan(S, [0, n, n + T.E.shape[0]]))


def _butterfly_sharp(T):
    """The odd vertices of sharp edges: the 4-point rule along the curve,
    reflected at corners (a list of :class:`_Table`, empty without sharp
    edges). A corner end x is reflected, x' = 2x - y: the slot of x' holds
    (x, -2/16) and the +1/16 on y goes to y's own weight (no zero weights,
    no missing point)."""
    ks = np.flatnonzero(T.sharp)
    if not ks.size:
        return []
    a, b = T.E[ks, 0], T.E[ks, 1]
    ca = T.n_sharp[a] != 2
    cb = T.n_sharp[b] != 2
    a2 = np.where(ca, a, T.nb_sum[a] - b)
    b2 = np.where(cb, b, T.nb_sum[b] - a)
    wa = 9 / 16 + 1 / 16 * cb
    wb = 9 / 16 + 1 / 16 * ca
    return [_Table(T.n + ks, [a, b, a2, b2],
                   [wa, wb, np.where(ca, -2 / 16, -1 / 16), np.where(cb, -2 / 16, -1 / 16)])]


def _butterfly_regular(T, kr):
    """The odd vertices of the edges ``kr`` (both ends regular, or touching
    a sharp vertex): the 8-point stencil, (tables, patches). Slot A: apex
    P0, edge (Q0, c); B: apex Q0, edge (c, P0); C: apex Q0 (=P1), edge (P0,
    d); D: apex P0 (=Q1), edge (d, Q0). A wing across a sharp edge is
    reflected (:func:`_reflected_wings`, a patch of those rows)."""
    if not kr.size:
        return [], []
    n = T.n
    f0, c0 = T.faces[kr, 0], T.corners[kr, 0]
    f1, c1 = T.faces[kr, 1], T.corners[kr, 1]
    x0, x1 = 3 * f0, 3 * f1
    n0, nn0 = NEXT_CORNER[c0], NEXT_CORNER[NEXT_CORNER[c0]]
    n1, nn1 = NEXT_CORNER[c1], NEXT_CORNER[NEXT_CORNER[c1]]
    # 32-bit copies of the arrays read at random: half the cache footprint
    small = max(n, 3 * T.F.shape[0]) < 2 ** 31 - 1
    Ff = T.F.ravel().astype(np.int32) if small else T.F.ravel()
    P0, Q0 = Ff[x0 + n0], Ff[x0 + nn0]
    c, d = Ff[x0 + c0], Ff[x1 + c1]
    # the corner across each half-edge, -1 where that edge is sharp (never read across)
    wing_opp = np.where(T.sharp[T.face_edge.ravel()], -1, T.opp)
    if small:
        wing_opp = wing_opp.astype(np.int32)
    wings, miss = [], []
    for h in (x0 + n0, x0 + nn0, x1 + n1, x1 + nn1):
        t = wing_opp[h]
        wings.append(Ff[t])
        miss.append(t < 0)
    tables = [_Table(n + kr, [P0, Q0, c, d] + wings, [0.5, 0.5, 0.125, 0.125] + [-1 / 16] * 4)]
    sel = np.flatnonzero(miss[0] | miss[1] | miss[2] | miss[3])
    if not sel.size:
        return tables, []
    return tables, [_reflected_wings(n + kr[sel], P0[sel], Q0[sel], c[sel], d[sel],
                                     [w[sel] for w in wings], [mk[sel] for mk in miss])]


def _reflected_wings(rows, P, Q, c, d, wings, miss):
    """The 8-point rows ``rows`` with a missing wing (``miss``, per slot A-D),
    same slots: -1/16 (P + Q - R) for a missing wing keeps -1/16 on the
    face's third vertex (c or d) in the wing's slot and moves the +-1/16 on
    the edge's ends into their weights, so no weight is ever zero (a row may
    name c or d twice)."""
    mA, mB, mC, mD = (mk.astype(np.float64) for mk in miss)
    s16 = 1 / 16
    wP = 0.5 + s16 * (mA - mB + mD - mC)
    wQ = 0.5 + s16 * (mB - mA + mC - mD)
    wing_c = [np.where(mk, cd, w) for w, mk, cd in zip(wings, miss, (c, c, d, d))]
    return _Table(rows, [P, Q, c, d] + wing_c, [wP, wQ, 0.125, 0.125] + [-s16] * 4)


def _butterfly_extraordinary(T, smooth_x, xa, xb):
    """The odd vertices of edges with an extraordinary end (``xa``, ``xb``
    per edge; ``smooth_x`` per vertex): each such end's ring stencil
    (Zorin et al.'s weights, :func:`butterfly_weights`), halved when both
    ends are; a list of :class:`_Table`, one per end side and valence."""
    kx = np.flatnonzero(xa | xb)
    if not kx.size:
        return []
    start, ring, rank_of_corner = _rings(T, smooth_x)
    f0, c0 = T.faces[kx, 0], T.corners[kx, 0]
    f1, c1 = T.faces[kx, 1], T.corners[kx, 1]
    y0 = 3 * f0 + NEXT_CORNER[c0]   # corner of P0 in f0, its next vertex is Q0
    y1 = 3 * f1 + NEXT_CORNER[c1]   # corner of Q0 in f1, its next vertex is P0
    P0 = T.F[f0, NEXT_CORNER[c0]]
    a, b = T.E[kx, 0], T.E[kx, 1]
    ya = np.where(P0 == a, y0, y1)
    yb = np.where(P0 == a, y1, y0)
    both = xa[kx] & xb[kx]
    tables = []
    for v, u, y, is_x in ((a, b, ya, xa[kx]), (b, a, yb, xb[kx])):
        val = T.valence[v]
        for k in sorted_unique(val[is_x]):
            sel = np.flatnonzero(is_x & (val == k))
            f = np.where(both[sel], 0.5, 1.0)
            vs = v[sel]
            if k < 3:   # only in degenerate meshes (a vertex in two faces): midpoint
                tables.append(_Table(T.n + kx[sel], [vs, u[sel]], [0.5 * f, 0.5 * f]))
                continue
            r = rank_of_corner[y[sel]]
            base = start[vs]
            sj = butterfly_weights(k)
            js = np.flatnonzero(sj)          # the valence-4 stencil has two zeros
            cols = [vs] + [ring[base + (r + j) % k] for j in js]
            tables.append(_Table(T.n + kx[sel], cols, [0.75 * f] + [sj[j] * f for j in js]))
    return tables


def loop_beta(k):
    """Warren's beta: 3/16 for valence 3, 3/(8k) otherwise."""
    k = np.asarray(k, dtype=np.float64)
    return np.where(k == 3, 3 / 16, 3 / (8 * np.maximum(k, 1)))


def loop_level(T):
    """Loop stencil for one level (see core.subdivide): even vertices by
    :func:`_loop_even`, odd (edge) vertices by :func:`_loop_odd`."""
    n, e = T.n, T.E.shape[0]
    S = _assemble(n + e, n, _loop_even(T) + _loop_odd(T))
    return S._replace(plan=make_plan(S, [0, n, n + e]))


def _loop_even(T):
    """The even vertices' tables: corners, darts and isolated vertices stay;
    a vertex on a crease curve takes (1, 6, 1) / 8 of its curve; a smooth one
    (1 - k beta) v + beta * its k neighbours (:func:`loop_beta`), grouped by
    valence."""
    n, ns = T.n, T.n_sharp
    tables = []
    kf = np.flatnonzero((ns == 1) | (ns >= 3) | (T.valence == 0))
    if kf.size:
        tables.append(_Table(kf, [kf], [1.0]))
    kc = np.flatnonzero(ns == 2)
    if kc.size:
        Es = T.E[T.sharp]
        nb_max = np.full(n, -1, dtype=np.int64)
        np.maximum.at(nb_max, Es[:, 0], Es[:, 1])
        np.maximum.at(nb_max, Es[:, 1], Es[:, 0])
        hi = nb_max[kc]
        lo = T.nb_sum[kc] - hi
        tables.append(_Table(kc, [kc, lo, hi], [0.75, 0.125, 0.125]))
    sv = np.flatnonzero((ns == 0) & (T.valence > 0))
    if sv.size:
        start, nbr = _neighbours(T)
        val = T.valence
        for k in sorted_unique(val[sv]):
            vs = sv[val[sv] == k]
            beta = float(loop_beta(k))
            base = start[vs]
            tables.append(_Table(vs, [vs] + [nbr[base + j] for j in range(k)],
                                 [1 - k * beta] + [beta] * k))
    return tables


def _neighbours(T):
    """Every vertex's neighbours, grouped by vertex (CSR: ``start`` (n+1,),
    ``nbr`` (2e,)) without sorting: the lo-side ends of E are already
    grouped (E is sorted), the hi-side ends are placed by counting."""
    n, e = T.n, T.E.shape[0]
    lo, hi = T.E[:, 0], T.E[:, 1]
    start = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(T.valence, out=start[1:])
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
    return start, nbr


def _loop_odd(T):
    """The odd vertices' tables: the midpoint of a sharp edge, (3, 3, 1, 1) / 8
    of an interior edge's ends and opposite corners."""
    tables = []
    ks = np.flatnonzero(T.sharp)
    if ks.size:
        tables.append(_Table(T.n + ks, [T.E[ks, 0], T.E[ks, 1]], [0.5, 0.5]))
    ki = np.flatnonzero(~T.sharp)
    if ki.size:
        c = T.F[T.faces[ki, 0], T.corners[ki, 0]]
        d = T.F[T.faces[ki, 1], T.corners[ki, 1]]
        tables.append(_Table(T.n + ki, [T.E[ki, 0], T.E[ki, 1], c, d],
                             [0.375, 0.375, 0.125, 0.125]))
    return tables
