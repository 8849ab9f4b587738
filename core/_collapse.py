"""The batched edge-collapse engine behind :func:`core.simplify.simplify`.

State: faces ``F`` plus per half-edge arrays (``h = 3 f + c`` is the edge of
face ``f`` opposite corner ``c``, see ``core._clean``): the twin table, the
crease flag, the cached collapse cost / position / error of the edge (kept on
its representative half-edge: the one with ``twin < 0`` or ``h < twin``),
and the "rejected until the neighbourhood changes" memory. Compaction keeps
the order of faces, so a representative stays a representative.

One pass, as stages (each a function below)::

    _candidate_edges      every live edge once with its cached cost; those around
                          vertices the last pass changed become stale, remembered
                          rejections raise the cost (_still_flips: a fan's folding
                          spokes stay refused while the faces they flip stay)
    _recost_cheapest      recost the stale edges that could be among the cheapest
    _choose_pool          the cheapest candidates (bounded share; bounded by the
                          collapses needed, a bound that grows after a pass that
                          fell short), ranked by _priority
    far from the target (more than Tuning.bold_above times its faces, and
    times bold_min_target at least), a bold
    pass (_bold_rounds): each round picks, checks and applies at once, and
    later rounds may take collapses next to earlier ones (only merged ends
    wait): about 30% of the faces go per pass instead of about 12%;
    closer to it, a careful pass, rounds (_check_rounds):
        _drop_quick_refusals  first, the pool edges around a fan's hub that fold
                          a sample of its faces, or make a sliver of one, are
                          refused (_drop_fan_slivers: from many such edges, the
                          four faces next to each edge first)
        _pick_independent pool edges whose rank is the smallest over every face
                          around both endpoints -> the stars are disjoint
        _check            on the current mesh: _link_condition, _turned_faces,
                          _min_compactness (no new sliver), _bends_too_far (with a
                          dihedral bound), _compactness_penalty, _hausdorff_penalty;
                          accept those within _acceptance_bound; their closed
                          one-rings become untouchable for later rounds
        _CheckedAhead     once few pool edges are left, all of them checked at
                          once (the mesh is still): later rounds only pick
    _trim_to_target       no more collapses than the target needs, cheapest first
    _apply                all accepted collapses at once, twins glued; removed faces
                          and vertices are only marked dead until compaction
"""

import threading
import time
from dataclasses import dataclass, field, fields, replace
from typing import NamedTuple

import numpy as np

from ._clean import BOUNDARY, NON_MANIFOLD, edge_representatives, half_edge_ends, renumber_twins
from ._groups import ragged_ranges, stable_argsort
from ._parallel import blocks, run_blocks, run_each
from .mesh import cross_columns, dot_columns, stops
from .quadrics import place_columns, quadric_at, rms_distance
from .spatial import closest_on_triangles, triangle_rows

_BIG = np.iinfo(np.int64).max
DEAD = -3  #: twin of a half-edge of a removed face (before compaction)
_SQRT3x2 = 2.0 * np.sqrt(3.0)
#: relative margin of a refusal made on a sample (rounding can only spare a collapse)
_SLACK = 1e-9


def _take(a, idx, axis=None):
    """``np.take(a, idx, axis)`` for an array ``a``, without the dispatch of
    the function form (about 1 us a call; the engine makes some 170 a pass)."""
    return a.take(idx, axis)


_NEXT = np.array([1, 2, 0], dtype=np.int64)  # corner after c
_PREV = np.array([2, 0, 1], dtype=np.int64)  # corner before c


def _array(per, fill=None, values=None, reset=False, lazy=False):
    """Declare a :class:`State` array: indexed by ``per`` ("vertex", "face",
    "half_edge"; "vertex_t" / "half_edge_t" for coefficient-major (k, n)
    arrays), ``fill`` for new rows ("index": their own index, "unset": left
    uninitialised, only ever read after being written), ``values`` ("vertex", "face" or "half_edge")
    when its entries are indices that compaction renumbers, ``reset`` when
    compaction starts it afresh (from ``fill``) instead of keeping its rows,
    ``lazy`` when it stays None until first written (:func:`_rows_of`)."""
    return field(default=None, metadata=dict(per=per, fill=fill, values=values, reset=reset, lazy=lazy))


@dataclass(init=False, eq=False)
class State:
    """Mutable working mesh of one simplification.

    Every array is declared once below with what it is indexed by; compaction
    (:func:`compact`) and appending faces (:func:`append_faces`) follow the
    declarations, so a new array cannot be left misaligned.
    """

    V: np.ndarray = _array("vertex")             #: working positions (unit-free)
    VT: np.ndarray = _array("vertex_t")          #: (3,n) copy of V for column gathers
    Q: np.ndarray = _array("vertex")             #: (n,11) quadrics, one row of coefficients per vertex
    NrefT: np.ndarray = _array("vertex_t")       #: (3,n) summed area normals of the input faces merged in
    Aref: np.ndarray = _array("vertex")          #: ... and the sum of their lengths (areas x 2)
    wit: np.ndarray = _array("vertex")           #: witness: merged input point farthest from the surface
    locked: np.ndarray = _array("vertex")
    moved: np.ndarray = _array("vertex")         #: position changed (else the input's exact one)
    orig: np.ndarray = _array("vertex")          #: clean index of each current vertex
    vver: np.ndarray = _array("vertex")          #: pass in which the one-ring last changed
    vmov: np.ndarray = _array("vertex")          #: pass in which it last survived a collapse (moved)
    fresh: np.ndarray = _array("vertex")         #: quadric / position changed: recost its edges
    is_bnd: np.ndarray = _array("vertex")        #: on a boundary edge
    dead_v: np.ndarray = _array("vertex", False, reset=True)   #: removed since the last compaction
    parent: np.ndarray = _array("vertex", "index", reset=True)  #: survivor of a merged vertex
    F: np.ndarray = _array("face", values="vertex")
    forig: np.ndarray = _array("face")           #: input face each face descends from
    alive: np.ndarray = _array("face", True, reset=True)
    twin: np.ndarray = _array("half_edge", BOUNDARY, values="half_edge")
    feat: np.ndarray = _array("half_edge", False)  #: on an input crease
    # the cache, on representatives: survivor is the second end (swap), pass of the
    # remembered rejection and its value (blk_pass, c_blk), cost, position, and
    # whether the cost is only a lower bound (c_stale)
    swap: np.ndarray = _array("half_edge", False)
    blk_pass: np.ndarray = _array("half_edge", np.int32(-1))   #: (int32: a pass count)
    c_blk: np.ndarray = _array("half_edge", -1.0)
    #: (3, 3m) faces the remembered rejection flips (-1: none): while one of them and the
    #: ends stay as they are, so does the refusal (see _still_flips)
    blk_face: np.ndarray = _array("half_edge_t", np.int32(-1), values="face", lazy=True)
    #: a face the remembered rejection makes a sliver of (-1: none) and its compactness
    #: then: while it and the ends stay as they are, and the faces around the ends no
    #: thinner, so does the refusal (see _still_slivers)
    blk_sliver: np.ndarray = _array("half_edge", np.int32(-1), values="face", lazy=True)
    blk_sliver_c: np.ndarray = _array("half_edge", "unset", lazy=True)
    c_cost: np.ndarray = _array("half_edge", 0.0)
    c_stale: np.ndarray = _array("half_edge", True)
    #: (3, 3m) cached collapse positions (read only where the cost is fresh, so new rows
    #: are left unset: at 4.4M faces, 320 MB never touched before the recost writes it)
    c_x: np.ndarray = _array("half_edge_t", "unset")
    bent: np.ndarray = _array("half_edge", False)  #: last refused only by the dihedral bound
    cur_of_clean: np.ndarray = None              #: current vertex of each clean vertex (-1: removed)
    m_live: int = 0                              #: faces not removed
    worst: float = 0.0                           #: largest error of an accepted collapse
    fan_slivers: bool = True                     #: _drop_fan_slivers still tests (see there)
    seconds: dict = None                         #: time spent per engine stage

    def __init__(self, V, F, twin, Q, locked, feat, Nref, forig=None):
        """``Nref`` (n,4): per vertex the summed area normals of its faces and their lengths."""
        n, m = V.shape[0], F.shape[0]
        self.V = V.copy()                          # (the input V stays: relocation samples it)
        self.VT = np.ascontiguousarray(V.T)
        self.Q = np.ascontiguousarray(Q)
        self.NrefT, self.wit, self.locked = np.ascontiguousarray(Nref.T[:3]), V.copy(), locked
        self.Aref = np.ascontiguousarray(Nref.T[3])
        self.moved = np.zeros(n, dtype=bool)
        self.orig = np.arange(n, dtype=np.int64)
        self.vver = np.full(n, -1, dtype=np.int64)
        self.vmov = np.full(n, -1, dtype=np.int32)          # (a pass count)
        self.fresh = np.ones(n, dtype=bool)
        self.is_bnd = np.zeros(n, dtype=bool)
        hb = np.flatnonzero(twin == BOUNDARY)
        if hb.size:
            ub, wb = half_edge_ends(F, hb)
            self.is_bnd[ub] = True
            self.is_bnd[wb] = True
        self.F, self.twin, self.feat = F, twin, feat
        self.forig = np.arange(m, dtype=np.int64) if forig is None else forig
        for name in _declared("half_edge", "half_edge_t"):
            if getattr(self, name) is None and not _meta(name)["lazy"]:
                setattr(self, name, _fresh_rows(name, 3 * m))
        for name in _declared(reset=True):
            setattr(self, name, _fresh_rows(name, m if _per(name) == "face" else n))
        self.cur_of_clean = np.arange(n, dtype=np.int64)
        self.m_live = m
        self.worst = 0.0
        self.fan_slivers = True
        self.seconds = {}

    @property
    def Nref(self):
        """(n,3) view of :attr:`NrefT`."""
        return self.NrefT.T


#: the declaration of every State array (name -> its :func:`_array` metadata), in
#: declaration order (read at each compaction: ``dataclasses.fields`` there cost ~1 ms a run)
_DECLARED = {f.name: f.metadata for f in fields(State) if f.metadata}


def _meta(name):
    return _DECLARED[name]


def _per(name):
    return _DECLARED[name]["per"]


def _declared(*per, reset=None):
    """Names of the State arrays indexed by one of ``per`` (any when empty),
    only those with that ``reset`` flag when given."""
    return [name for name, meta in _DECLARED.items()
            if (not per or meta["per"] in per) and (reset is None or meta["reset"] == reset)]


def _rows_of(st, name):
    """The lazy State array ``name``, made from its declared fill on first use."""
    if getattr(st, name) is None:
        n, m = st.V.shape[0], st.F.shape[0]
        size = {"vertex": n, "vertex_t": n, "face": m, "half_edge": 3 * m, "half_edge_t": 3 * m}[_per(name)]
        setattr(st, name, _fresh_rows(name, size))
    return getattr(st, name)


def _fresh_rows(name, size):
    """``size`` new rows of the State array ``name``, from its declared fill."""
    fill = _meta(name)["fill"]
    if fill == "index":
        return np.arange(size, dtype=np.int64)
    if fill == "unset":
        return np.empty((3, size) if _per(name) == "half_edge_t" else size)
    if _per(name) == "half_edge_t":
        return np.full((3, size), fill)
    return np.full(size, fill)


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


def _merged_area(st, a, b):
    """The area of the merged quadrics of ``a[i]`` and ``b[i]`` (their
    coefficient 10). (Indexed in place: ``np.take`` of the column view would
    first copy the whole column.)"""
    return st.Q[a, 10] + st.Q[b, 10]


def _distance(st, cost, a, b):
    """RMS distance ``sqrt(cost / w)`` of edge collapses (``w``: the merged
    quadric's area; 0 where it has none), in working units."""
    return rms_distance(cost, _merged_area(st, a, b))


# ---------------------------------------------------------------- costs


def _recost(st, rep, U, W, stale, preserve_boundary, tun):
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
        q = _take(st.Q, a, axis=0)                 # (whole rows: contiguous gathers)
        q += _take(st.Q, b, axis=0)
        q = np.ascontiguousarray(q.T)
        pa, pb = _take(st.VT, a, axis=1), _take(st.VT, b, axis=1)
        X, err = place_columns(q, pa, pb)
        # a position within round-off of an endpoint is that endpoint (it stays exact)
        E = pb - pa
        tol2 = tun.snap_share * (E[0] * E[0] + E[1] * E[1] + E[2] * E[2])
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
        st.c_x[:, hs] = X
        st.swap[hs] = swap

    run_blocks(block, blocks(hs_all.size, tun.block))


class _Edges(NamedTuple):
    """Every live edge once (its representative half-edge) and its state this pass."""

    rep: np.ndarray      #: representative half-edges
    U: np.ndarray        #: ... their ends
    W: np.ndarray
    cost: np.ndarray     #: cached cost, raised by a remembered rejection (a lower bound if stale)
    stale: np.ndarray    #: bool: the cached cost is only a lower bound
    blocked: np.ndarray  #: bool: rejected, and the neighbourhood has not changed since
    bv: np.ndarray       #: the remembered rejection's value (-1: none)


def _candidate_edges(st):
    """Every live edge once, with its cached cost: the edges around vertices
    that changed in the last pass become stale, and an edge rejected since
    its neighbourhood last changed costs at least what its check found."""
    F, twin = st.F, st.twin
    rep = edge_representatives(twin)
    U, W = half_edge_ends(F, rep)
    st.c_stale[rep[st.fresh[U] | st.fresh[W]]] = True
    st.fresh[:] = False
    stale = _take(st.c_stale, rep)
    cost = _take(st.c_cost, rep)
    bv = _take(st.c_blk, rep)
    mem = np.flatnonzero(bv >= 0)           # rejections remembered until the neighbourhood changes
    blocked = np.zeros(rep.size, dtype=bool)
    since = _take(st.blk_pass, rep[mem])
    blocked[mem] = since > np.maximum(_take(st.vver, U[mem]), _take(st.vver, W[mem]))
    if st.blk_face is not None:
        blocked[mem] |= _still_flips(st, rep[mem], U[mem], W[mem], since)
    if st.blk_sliver is not None:
        blocked[mem] |= _still_slivers(st, rep[mem], U[mem], W[mem], since, blocked[mem])
    cost = np.where(blocked, np.maximum(cost, bv), cost)
    return _Edges(rep, U, W, cost, stale, blocked, bv)


def _still_flips(st, h, U, W, since):
    """Refusals (representative half-edges ``h``, ends ``U``, ``W``, made in
    pass ``since``) one of whose remembered flipped faces is alive and
    neither it nor the ends have moved since: the collapse would go to the
    same place and flip that face again, whatever changed elsewhere around
    it (a fan's hub then does not check its hundreds of folding spokes again
    after every collapse on its rim). (k,) bool."""
    out = np.zeros(h.size, dtype=bool)
    ends = np.maximum(_take(st.vmov, U), _take(st.vmov, W))
    for j in range(st.blk_face.shape[0]):
        f = _take(st.blk_face[j], h)
        r = np.flatnonzero((f >= 0) & ~out)
        if r.size == 0:
            continue
        out[_as_they_were(st, r, f[r], ends, since)] = True
    return out


def _as_they_were(st, r, f, ends, since):
    """The refusals among ``r`` whose remembered face ``f`` (one per ``r``) is
    alive and neither it nor the collapse's ends (``ends``: the pass either
    end last moved in, per refusal) have moved since the refusal's pass
    ``since``."""
    live = np.flatnonzero(_take(st.alive, f))
    r, f = r[live], f[live]
    moved = _take(st.vmov, _take(st.F, f, axis=0).ravel()).reshape(-1, 3).max(axis=1)
    return r[_take(since, r) > np.maximum(_take(ends, r), moved)]


def _still_slivers(st, h, U, W, since, held):
    """Refusals (representative half-edges ``h``, ends ``U``, ``W``, made in
    pass ``since``; ``held``: those already held otherwise) whose remembered
    sliver face is alive, neither it nor the ends have moved since, and
    still less compact than half the least compact face around the ends as
    they are now: the collapse would make the same sliver, and the whole
    check (:func:`_check_block`) would refuse it again (a cap's fan: the
    hub's spokes, each refused for the sliver it makes beside its rim
    vertex, are not sampled again after every collapse elsewhere on the
    rim). (k,) bool."""
    out = np.zeros(h.size, dtype=bool)
    f = _take(st.blk_sliver, h)
    r = np.flatnonzero((f >= 0) & ~held)
    r = _as_they_were(st, r, _take(f, r), np.maximum(_take(st.vmov, U), _take(st.vmov, W)), since)
    if r.size:
        least = _least_compactness(st, _take(U, r), _take(W, r))
        old = np.minimum(least[:r.size], least[r.size:])
        out[r[_take(st.blk_sliver_c, _take(h, r)) < 0.5 * (1.0 - _SLACK) * old]] = True
    return out


def _recost_cheapest(st, e, P, max_err_n, preserve_boundary, tun):
    """Recost (in place in ``e.cost`` / ``e.stale``) the stale edges that
    could still be among the ``P`` cheapest: merging only adds quadrics, so a
    stale cached cost is a lower bound of the new one (lazy recosting)."""
    cand = np.isfinite(e.cost)
    need = e.stale & cand
    if max_err_n is None and P < np.count_nonzero(cand):
        need &= e.cost <= _kth_smallest(e.cost, P - 1, tun.sample)   # (inf sorts last)
    ni = np.flatnonzero(need)
    if ni.size:
        _recost(st, e.rep, e.U, e.W, ni, preserve_boundary, tun)
        hn = _take(e.rep, ni)
        st.c_stale[hn] = False
        e.stale[ni] = False
        fresh_cost = _take(st.c_cost, hn)
        e.cost[ni] = np.where(_take(e.blocked, ni), np.maximum(fresh_cost, _take(e.bv, ni)), fresh_cost)


def _thinned(x, sample):
    """``x`` itself up to ``4 * sample`` values, else an evenly strided
    sample of ``sample`` to ``2 * sample`` of them (a view; deterministic)."""
    return x if x.size <= 4 * sample else x[::x.size // sample]


def _kth_smallest(x, k, sample):
    """The ``k``-th smallest value of ``x`` (0-based). Exact for arrays of up to
    ``4 * sample``; for larger ones estimated from :func:`_thinned`, two
    standard deviations of the estimate on the high side (a pool bound then
    takes a few more edges, never many fewer)."""
    s = _thinned(x, sample)
    if s is x:
        return np.partition(x, k)[k]
    q = (k + 1) / x.size
    j = int(np.ceil(q * s.size + 2.0 * np.sqrt(q * (1.0 - q) * s.size)))
    j = min(max(j, 0), s.size - 1)
    return np.partition(s, j)[j]


# ---------------------------------------------------------------- the pool


def _pool_size(ne, m, target, tun, bold=False, grow=1.0, stalled=0):
    """How many of the ``ne`` candidate edges one pass (``bold``: see
    :func:`_bold_rounds`) may consider; ``grow`` widens the bound set by the
    collapses still needed (see ``Tuning.slow_pass_share``), ``stalled`` (the
    careful passes in a row that accepted nothing) doubles the share each
    time past ``Tuning.stall_grace``: a messy homer stuck short of its
    target refused a fifth of its 3,384 candidates a pass, 36 passes each
    time it was stuck, 10,370 in all (17 s for 21k faces; now 2,712, 10 s).
    Doubling from the first such pass changed the cow at 2% (Hausdorff
    0.738 -> 0.754 of Decimate's)."""
    # (at most 2^8 times: the default shares reach every candidate after 3 doublings,
    # and 2.0 ** stalled would overflow a long stall; P is cut to ne below)
    share = (tun.bold_pool_share if bold else tun.pool_share) \
        * 2.0 ** min(max(stalled - tun.stall_grace, 0), 8)
    P = int(np.ceil(share * ne))
    if target is not None:
        goal = grow * tun.pool_goal_factor * (m - target) / 2.0    # (grow may reach inf)
        if goal < P:
            P = min(P, int(np.ceil(goal)) + 1)
    return max(1, min(P, ne))


class _Pool(NamedTuple):
    """The edges one pass may collapse, B -> A at X."""

    h: np.ndarray         #: representative half-edges
    A: np.ndarray         #: survivors
    B: np.ndarray         #: removed ends
    XT: np.ndarray        #: (3,P) positions
    interior: np.ndarray  #: bool: two faces go (else one: a border edge)
    cost: np.ndarray      #: ranking cost (raised by remembered rejections)
    raw: np.ndarray       #: quadric cost at X
    key: np.ndarray       #: unique priority (:func:`_priority`)
    limit: float          #: the pool's cost bound


def _choose_pool(st, e, ci, P, tun, reach=None):
    """Every fresh candidate ``ci`` no costlier than the ``P``-th cheapest
    (ties included), with its survivor, position and priority; with
    ``reach`` (:func:`_collapse_reach`), those of them whose RMS distance is
    within it, when there are any."""
    P = max(1, min(P, ci.size))
    cc = e.cost[ci]
    limit = _kth_smallest(cc, P - 1, tun.sample) if P < ci.size else cc.max()
    pool = ci[cc <= limit]
    if reach is not None:
        near = _distance(st, _take(st.c_cost, e.rep[pool]), e.U[pool], e.W[pool]) <= reach
        if near.any() and not near.all():
            pool = pool[near]
    ph = e.rep[pool]
    sw = st.swap[ph]
    pa = np.where(sw, e.W[pool], e.U[pool])
    pb = np.where(sw, e.U[pool], e.W[pool])
    pX = _take(st.c_x, ph, axis=1)
    key = _priority(e.cost[pool], _squared_lengths(st.VT, pa, pb), pa, pb, tun)
    return _Pool(ph, pa, pb, pX, st.twin[ph] >= 0, e.cost[pool], _take(st.c_cost, ph), key, limit)


def _bands(x, n, sample):
    """Band 0..n-1 of every value of ``x``: its place among ``n - 1``
    quantiles of ``x`` (of a sample on large arrays); up to ``n`` values,
    its rank (equal values share one)."""
    if x.size <= n:
        return np.unique(x, return_inverse=True)[1].astype(np.int64).reshape(-1)
    s = _thinned(x, sample)
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
    band = _bands(cost, tun.bands, tun.sample)
    lband = _bands(length2, tun.length_bands, tun.sample)
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
    if totals.size == 0 or limit >= tun.plateau_share * float(totals.max()):
        return limit             # (the median is at most the largest: no plateau)
    med = _median(totals)
    return med if limit < tun.plateau_share * med else limit


def _median(x):
    """``float(np.median(x))`` of a non-empty float array whose largest value
    is not NaN (the same bits: the middle value, or the mean of the two
    middle ones), without ``np.median``'s overhead (some 20 us a call; a
    pass judges a few dozen rounds)."""
    k = x.size // 2
    if x.size % 2:
        return float(np.partition(x, k)[k])
    part = np.partition(x, (k - 1, k))
    return float((part[k - 1] + part[k]) / 2.0)


# ---------------------------------------------------------------- independent collapses


class _Faces(NamedTuple):
    """The live faces that may still touch an active pool edge (transposed
    rows), their ids, and the smallest key around each."""

    FT: np.ndarray
    fidx: np.ndarray
    fh: np.ndarray


def _scratch(n, P):
    """Scratch of the rounds of one pass: two (n,) int64 arrays of ``_BIG``
    for the per-vertex minima and a (P,) one of -1 for the chosen pool edges
    (each round puts back what it wrote: small rounds on a large mesh then
    cost what they touch, not the mesh's size)."""
    return (np.full(n, _BIG, dtype=np.int64), np.full(n, _BIG, dtype=np.int64),
            np.full(P, -1, dtype=np.int64))


def _put_back(buf, *idx):
    """Reset ``buf`` to ``_BIG`` where the index arrays ``idx`` wrote."""
    if sum(i.size for i in idx) > buf.size:
        buf.fill(_BIG)
    else:
        for i in idx:
            buf[i] = _BIG


def _pick_independent(st, pool, active, faces, tun, scratch, stars=True):
    """One selection round: the ``active`` pool edges whose key is the
    smallest over every face around both endpoints (so their stars are
    disjoint). Returns ``(sel, active left, star, kf, faces)``: the chosen
    pool edges, the others, every face of the chosen edges' stars with the
    chosen edge it belongs to (None without ``stars``), and the faces still
    in play. ``scratch``: :func:`_scratch` of the vertex count and the pool size."""
    F, P = st.F, pool.key.size
    ka, aa, ab = pool.key[active], pool.A[active], pool.B[active]
    vmin, vmin2, pos = scratch
    np.minimum.at(vmin, aa, ka)
    np.minimum.at(vmin, ab, ka)
    if faces is None:                        # first round: every live face
        G = _take(vmin, F)
        fmin = np.minimum(np.minimum(G[:, 0], G[:, 1]), G[:, 2])
        del G
        fidx = np.flatnonzero((fmin < _BIG) & st.alive)
        faces = _Faces(np.ascontiguousarray(_take(F, fidx, axis=0).T), fidx, _take(fmin, fidx))
    else:
        FT, fidx = faces.FT, faces.fidx
        fmin = np.minimum(np.minimum(_take(vmin, FT[0]), _take(vmin, FT[1])), _take(vmin, FT[2]))
        live = np.flatnonzero(fmin < _BIG)
        if live.size < tun.face_cache_share * fidx.size:   # keep only the faces still in play
            faces = _Faces(np.ascontiguousarray(FT[:, live]), fidx[live], _take(fmin, live))
        else:                                # (a _BIG minimum changes nothing below)
            faces = _Faces(FT, fidx, fmin)
    for j in range(3):
        np.minimum.at(vmin2, faces.FT[j], faces.fh)
    chosen = ka == np.minimum(_take(vmin2, aa), _take(vmin2, ab))
    _put_back(vmin, aa, ab)
    _put_back(vmin2, *faces.FT)
    sel = active[chosen]
    if not stars:
        return sel, active[~chosen], None, None, faces
    # the star of a chosen edge is exactly the set of faces whose minimum is its key
    imask = (np.int64(1) << np.int64(max(1, int(P - 1).bit_length()))) - 1
    pos[sel] = np.arange(sel.size)
    fpos = np.where(faces.fh < _BIG, _take(pos, np.minimum(faces.fh & imask, P - 1)), -1)
    pos[sel] = -1
    in_star = fpos >= 0
    return sel, active[~chosen], faces.fidx[in_star], fpos[in_star], faces


class _Accepted(NamedTuple):
    """The collapses a pass accepted (pool indices), their star rows and witnesses."""

    idx: np.ndarray
    rows: tuple
    wit: np.ndarray


def _check_rounds(st, pool, passes, haus, dihedral_cos, tun):
    """Selection rounds over the pool: pick independent collapses, check
    them, accept those within the bound, lock their closed one-rings.
    Rejections are remembered (``c_blk``) until their neighbourhood changes.
    Returns the accepted collapses (or None) and the touched vertices."""
    n, P = st.V.shape[0], pool.key.size
    touched = np.zeros(n, dtype=bool)
    acc_edges, acc_wit, acc_rows = [], [], []
    active = np.arange(P, dtype=np.int64)
    faces = owned = ahead = None
    scratch = _scratch(n, P)
    faces_at = np.bincount(st.F[st.alive].ravel(), minlength=n)
    around = _take(faces_at, pool.A) + _take(faces_at, pool.B)    # faces around each edge's ends
    active = _drop_quick_refusals(st, pool, active, passes, tun, around)
    for _ in range(tun.max_rounds):
        active = active[~touched[pool.A[active]] & ~touched[pool.B[active]]]
        if active.size == 0:
            break
        if ahead is None and active.size <= tun.check_ahead:
            first = _ahead_of(active, around, tun)
            if first.size:
                ahead = _CheckedAhead.of(st, pool, first, faces, tun, haus, dihedral_cos,
                                         partial=first.size < active.size)
                active = _drop_invalid(st, pool, ahead, active, passes)
                if active.size == 0:
                    break
        sel, active, star, kf, faces = _pick_independent(
            st, pool, active, faces, tun, scratch, stars=ahead is None or ahead.partial)
        c = _checked(st, pool, sel, star, kf, ahead, tun, haus, dihedral_cos)
        rows = c.rows
        acc = _judge(st, pool, sel, c, passes, tun)
        if dihedral_cos is not None and acc.any():   # each bend was judged against still faces
            if owned is None:
                owned = np.zeros(st.F.shape[0], dtype=bool)
            acc &= ~_next_to_another(st, pool.key[sel], rows, acc, owned)
            owned[rows[0][_take(acc, rows[1])]] = True
        if acc.any():
            rows = _keep_rows(rows, acc, sum(x.size for x in acc_edges))
            acc_edges.append(sel[acc])
            acc_wit.append(c.wit[acc])
            acc_rows.append(rows)
            touched[_take(st.F, rows[0], axis=0).ravel()] = True
    if not acc_edges:
        return None, touched
    rows = tuple(np.concatenate(col) for col in zip(*acc_rows))
    return _Accepted(np.concatenate(acc_edges), rows, np.concatenate(acc_wit)), touched


def _ahead_of(active, around, tun):
    """The ``active`` pool edges to check ahead (:class:`_CheckedAhead`): all
    of them, or when their stars (``around``: the faces around each pool
    edge's ends) hold more than ``Tuning.check_ahead_rows`` faces, those
    whose star is not big (below ``Tuning.hold_star`` faces; the big ones
    wait for their picks: a hub's spokes are picked one a round, and
    checking them all ahead read the hub's faces for each: a 10k-face
    cylinder's caps, 780 spokes, 1.1M rows)."""
    mine = _take(around, active)
    return active if int(mine.sum()) <= tun.check_ahead_rows else active[mine < tun.hold_star]


def _checked(st, pool, sel, star, kf, ahead, tun, haus, dihedral_cos):
    """The :class:`_Checked` results of the picked pool edges ``sel`` (their
    star rows ``star``, ``kf``): from ``ahead`` (a :class:`_CheckedAhead`)
    for those it checked, the others checked now."""
    now = np.ones(sel.size, dtype=bool) if ahead is None else _take(ahead.at, sel) < 0
    if not now.any():
        return ahead.results(sel)
    i = np.flatnonzero(now)
    if i.size < sel.size:
        r = np.flatnonzero(_take(now, kf))
        star, kf = _take(star, r), _take(np.cumsum(now) - 1, _take(kf, r))
    e = sel[i]
    c = _check(st, pool.A[e], pool.B[e], pool.XT[:, e], pool.interior[e], star, kf, tun, haus,
               dihedral_cos, quick=False)    # (_drop_quick_refusals sampled the big stars)
    if i.size == sel.size:
        return c
    return _merged(ahead.results(sel[~now]), np.flatnonzero(~now), c, i, sel.size)


def _merged(c1, i1, c2, i2, k):
    """The :class:`_Checked` of ``k`` collapses from ``c1`` (of collapses
    ``i1``) and ``c2`` (of ``i2``), star rows by collapse."""
    ok, pen, bent = np.zeros(k, dtype=bool), np.zeros(k), np.zeros(k, dtype=bool)
    wit, flip = np.zeros((k, 3)), np.zeros((k, 3), dtype=np.int64)
    for c, i in ((c1, i1), (c2, i2)):
        ok[i], pen[i], bent[i], wit[i], flip[i] = c.ok, c.pen, c.bent, c.wit, c.flip
    kf = np.concatenate([_take(i1, c1.rows[1]), _take(i2, c2.rows[1])])
    o = np.argsort(kf, kind="stable")
    star, coll, cA, cB = (_take(np.concatenate([c1.rows[j], c2.rows[j]]), o) for j in (0, 2, 3, 4))
    return _Checked(ok, pen, (star, _take(kf, o), coll, cA, cB), wit, bent, flip)


def _drop_quick_refusals(st, pool, active, passes, tun, around):
    """The ``active`` pool edges but those with a big star (at least
    ``Tuning.hold_star`` faces around the ends; ``around``: the live faces
    around each pool edge's ends) refused on a sample of it (:func:`_flips_on`: a
    face turned over, or from ``Tuning.sliver_star`` faces on, made a
    sliver, :func:`_sliver_samples`), remembered as :func:`_judge`
    remembers them, before any pick: a fan's spoke picked would keep the
    whole fan waiting a round (every face of the hub is in its star), and a
    pass has few rounds. The slivers next to a huge star's edge are looked
    for first (:func:`_drop_fan_slivers`), the sample only where they are not."""
    active = _drop_fan_slivers(st, pool, active, passes, tun, around)
    big = np.flatnonzero(_take(around, active) >= tun.hold_star)
    if big.size == 0:
        return active
    e = active[big]
    A, B = pool.A[e], pool.B[e]
    star, kf = _sampled_stars(st, A, B, tun.hold_sample)
    even, least = star.size, np.zeros(2 * e.size)
    huge = np.flatnonzero(_take(around, e) >= tun.sliver_star)
    if huge.size:
        more, mk, low = _sliver_samples(st, pool.h[e[huge]], A[huge], B[huge], tun.hold_sample)
        star, kf = np.concatenate([star, more]), np.concatenate([kf, _take(huge, mk)])
        least[huge], least[e.size + huge] = low[:huge.size], low[huge.size:]
    refused, flip, sliver = _flips_on(st, A, B, pool.XT[:, e], star, kf, tun, least, even)
    return _without_refused(st, pool, active, big, refused, flip, sliver, passes)


def _drop_fan_slivers(st, pool, active, passes, tun, around):
    """The ``active`` pool edges but those with a huge star (at least
    ``Tuning.sliver_star`` faces around the ends) that make a sliver of one
    of the two faces next to the edge on either side of either end
    (:func:`_fans_near`, against the least compact face around the ends as
    they are: a refusal the whole check makes), remembered as
    :func:`_judge` remembers them: a fan's spokes, each refused for the
    sliver it makes beside the rim vertex it merges into, are found on four
    faces each, not on the sample of 80 that :func:`_drop_quick_refusals`
    takes for what this leaves (a CAD cylinder's 3,700 spokes a pass). A
    test that refuses fewer than ``Tuning.fan_slivers_share`` of them is not
    made again in the run: a star glyph's spokes fold faces farther off, and
    its 26,000 tests refused 13 (35 ms for nothing)."""
    huge = np.flatnonzero(_take(around, active) >= tun.sliver_star)
    if not st.fan_slivers or huge.size < tun.fan_slivers_min:
        return active
    e = active[huge]
    A, B = pool.A[e], pool.B[e]
    star, kf = _fans_near(st, pool.h[e], A, B, 1)
    least = _least_compactness(st, A, B)
    refused, flip, sliver = _flips_on(st, A, B, pool.XT[:, e], star, kf, tun, least, 0)
    st.fan_slivers = np.count_nonzero(refused) >= tun.fan_slivers_share * e.size
    return _without_refused(st, pool, active, huge, refused, flip, sliver, passes)


def _without_refused(st, pool, active, tested, refused, flip, sliver, passes):
    """The ``active`` pool edges but those of its rows ``tested`` that a
    check before the picks ``refused`` ((t,) bool; their flipped faces
    ``flip`` and :class:`_Slivers` ``sliver``), remembered as :func:`_judge`
    remembers them."""
    if not refused.any():
        return active
    gone = tested[refused]
    h = pool.h[active[gone]]
    st.bent[h] = False
    _remember_refused(st, h, np.inf, passes, flip[refused], sliver.of(refused))
    keep = np.ones(active.size, dtype=bool)
    keep[gone] = False
    return active[keep]


def _judge(st, pool, sel, c, passes, tun):
    """Which of the checked collapses ``sel`` (their :class:`_Checked` ``c``)
    are accepted: valid, and their total (cost + penalties) within
    :func:`_acceptance_bound`. The others are remembered as rejected (their
    total, or inf when invalid) until their neighbourhood changes. (k,) bool."""
    st.bent[pool.h[sel]] = c.bent
    total = pool.raw[sel] + c.pen
    acc = c.ok & (total <= _acceptance_bound(pool.limit, total[c.ok], tun))
    rej = ~acc
    _remember_refused(st, pool.h[sel[rej]], np.where(c.ok[rej], total[rej], np.inf), passes, c.flip[rej])
    return acc


def _remember_refused(st, h, total, passes, flip, sliver=None):
    """Remember the refused collapses of the representative half-edges ``h``
    with their ``total`` (cost + penalties; inf when invalid) until their
    neighbourhood changes, or, for those that flip faces (``flip`` (k,3):
    up to three of their ids, -1 for none), while one of those faces and the
    collapse's ends stay as they are (:func:`_still_flips`), or, for those
    that make a sliver (``sliver``, a :class:`_Slivers`; None: none), while it
    stays one the whole check refuses (:func:`_still_slivers`). Every
    refusal overwrites what was remembered of the half-edge before."""
    st.c_blk[h] = total
    st.blk_pass[h] = passes
    if st.blk_face is not None or (flip >= 0).any():
        _rows_of(st, "blk_face")[:, h] = flip.T
    if sliver is not None and (st.blk_sliver is not None or (sliver.face >= 0).any()):
        _rows_of(st, "blk_sliver")[h] = sliver.face
        _rows_of(st, "blk_sliver_c")[h] = sliver.after
    elif st.blk_sliver is not None:
        st.blk_sliver[h] = -1


def _bold_rounds(st, pool, passes, haus, dihedral_cos, tun, target):
    """Selection rounds of a bold pass, far from the target: each round
    picks independent collapses among the pool edges whose ends no earlier
    round merged, checks them on the mesh as it is and applies those
    accepted at once, so a later round may take a collapse next to an
    earlier one (its cost is still exact: neither end changed). About three
    times the collapses of a careful pass (:func:`_check_rounds`), for a
    slightly less even mesh. The pass ends after ``Tuning.bold_rounds``
    rounds, or after a round that took fewer than ``bold_round_share`` of the
    first round's collapses. Returns the number of collapses applied.

    The picks read the faces in play as they were at the start of the pass:
    a collapse only renames a merged vertex (no longer the end of any active
    edge) into another, so every face's smallest active key, and with it
    every pick and star, is the same; only the faces removed are dropped
    from the stars (the checks read the current rows)."""
    n = st.V.shape[0]
    merged = np.zeros(n, dtype=bool)
    scratch, done, first = _scratch(n, pool.key.size), 0, 0
    picked = _pick_independent(st, pool, np.arange(pool.key.size, dtype=np.int64), None, tun, scratch)
    for rounds in range(1, tun.bold_rounds + 1):
        sel, active, star, kf, faces = picked
        live = np.flatnonzero(_take(st.alive, star))   # (faces removed by earlier rounds)
        star, kf = _take(star, live), _take(kf, live)
        c = _check(st, pool.A[sel], pool.B[sel], pool.XT[:, sel], pool.interior[sel], star, kf, tun, haus,
                   dihedral_cos)
        acc = _judge(st, pool, sel, c, passes, tun)
        if dihedral_cos is not None and acc.any():
            acc &= ~_next_to_another(st, pool.key[sel], c.rows, acc, np.zeros(st.F.shape[0], dtype=bool))
        jobs, took = [], 0
        if acc.any():
            a = _trim_to_target(pool, _Accepted(sel[acc], _keep_rows(c.rows, acc), c.wit[acc]), st.m_live,
                                target)
            took = a.idx.size
            st.vver[_take(st.F, a.rows[0], axis=0).ravel()] = passes
            merged[pool.A[a.idx]] = True
            merged[pool.B[a.idx]] = True
            done += a.idx.size
            jobs.append(lambda a=a: _apply_accepted(st, pool, a, passes))
        active = active[~merged[pool.A[active]] & ~merged[pool.B[active]]]
        if rounds == 1:
            first = took
        more = rounds < tun.bold_rounds and active.size > 0 and took >= tun.bold_round_share * first
        if more:    # the next pick reads no row the apply writes: both at once
            jobs.append(lambda: _pick_independent(st, pool, active, faces, tun, scratch))
        out = run_each(lambda job: job(), jobs, threads=active.size >= tun.threads_min_edges)
        if not more or (target is not None and st.m_live <= target):
            break
        picked = out[-1]
    return done


class _CheckedAhead(NamedTuple):
    """:func:`_check` results of pool edges checked before they are picked
    (the mesh does not change during a pass, so neither do they): once few
    edges are left, one check of them all costs less than the rounds' many
    small ones. Each star is listed in the order a pick gives it (ascending
    face ids), so the results are the same bits."""

    at: np.ndarray       #: (P,) row of each pool edge in the results (-1: not checked)
    found: "_Checked"
    start: np.ndarray    #: (k+1,) the star rows of result i are ``start[i]:start[i + 1]``
    partial: bool        #: whether some pool edges in play were left to be checked when picked

    @classmethod
    def of(cls, st, pool, active, faces, tun, haus, dihedral_cos, partial=False):
        """Check every ``active`` pool edge on its whole star; ``faces`` are
        the faces in play (None: all live faces); ``partial``: others in
        play are not among ``active``."""
        A, B = pool.A[active], pool.B[active]
        ends = np.zeros(st.V.shape[0], dtype=bool)
        ends[A] = True
        ends[B] = True
        FT = faces.FT if faces is not None else st.F.T
        fidx = faces.fidx if faces is not None else np.arange(st.F.shape[0], dtype=np.int64)
        near = ends[FT[0]] | ends[FT[1]] | ends[FT[2]]
        if faces is None:
            near &= st.alive
        star, kf = _whole_stars(st.F, fidx[near], A, B)
        found = _check(st, A, B, pool.XT[:, active], pool.interior[active], star, kf, tun, haus, dihedral_cos)
        at = np.full(pool.key.size, -1, dtype=np.int64)
        at[active] = np.arange(active.size)
        # (the rows come by collapse: a round's results are runs of them, not a mask of all)
        start = np.searchsorted(found.rows[1], np.arange(active.size + 1, dtype=np.int64))
        return cls(at, found, start, partial)

    def results(self, sel):
        """The results of the pool edges ``sel`` (ascending), as :func:`_check`
        returns them for that selection."""
        i = _take(self.at, sel)
        first, count = _take(self.start, i), _take(self.start, i + 1) - _take(self.start, i)
        kf = np.repeat(np.arange(i.size, dtype=np.int64), count)
        r = np.arange(kf.size, dtype=np.int64) + _take(first - (np.cumsum(count) - count), kf)
        c = self.found
        star, _, coll, cA, cB = (_take(col, r) for col in c.rows)
        return _Checked(_take(c.ok, i), _take(c.pen, i), (star, kf, coll, cA, cB),
                        _take(c.wit, i, axis=0), _take(c.bent, i), _take(c.flip, i, axis=0))


def _drop_invalid(st, pool, ahead, active, passes):
    """The ``active`` pool edges that their checked-ahead results
    (:class:`_CheckedAhead`) find valid, or that it did not check. The others
    are rejected at once, and
    remembered as :func:`_judge` remembers them (:func:`_remember_refused`), instead of each taking a
    round of the pass: picked alone (its key the smallest around), refused,
    and meanwhile keeping every valid collapse near it waiting (the tail of
    a flat mesh took 16 rounds a pass that way, one refusal per round)."""
    i = _take(ahead.at, active)
    ok = (i < 0) | _take(ahead.found.ok, np.maximum(i, 0))
    bad = np.flatnonzero(~ok)
    hr = pool.h[_take(active, bad)]
    st.bent[hr] = _take(ahead.found.bent, _take(i, bad))
    _remember_refused(st, hr, np.inf, passes, _take(ahead.found.flip, _take(i, bad), axis=0))
    return active[ok]


def _whole_stars(F, fidx, A, B):
    """Every face (among ``fidx``: ascending, and every face around the ends
    among them) around ``A[k]`` or ``B[k]``, as rows ``(star, kf)`` sorted by
    collapse, then face; stars may overlap."""
    k = A.size
    fs, start, count = _faces_at(F, fidx, np.concatenate([A, B]))
    a0, b0, na, nb = start[:k], start[k:], count[:k], count[k:]
    cnt = na + nb
    kf = np.repeat(np.arange(k, dtype=np.int64), cnt)
    j = np.arange(kf.size, dtype=np.int64) - np.repeat(np.cumsum(cnt) - cnt, cnt)
    from_b = j >= _take(na, kf)
    star = _take(fs, np.where(from_b, _take(b0, kf) + j - _take(na, kf), _take(a0, kf) + j))
    has_a = _corner(_take(F, star, axis=0), _take(A, kf)) >= 0
    r = np.flatnonzero(~(from_b & has_a))            # the faces of the edge come with A
    star, kf = _take(star, r), _take(kf, r)
    o = np.argsort(kf * np.int64(F.shape[0]) + star, kind="stable")
    return _take(star, o), _take(kf, o)


def _faces_at(F, fidx, ends):
    """The faces among ``fidx`` (ascending) around each vertex of ``ends``:
    ``(fs, start, count)``, those of ``ends[i]`` being
    ``fs[start[i]:start[i] + count[i]]``, ascending."""
    v = _take(F, fidx, axis=0).ravel()
    order = np.argsort(v, kind="stable")            # faces stay ascending within each vertex
    vs, fs = _take(v, order), _take(np.repeat(fidx, 3), order)
    start = np.searchsorted(vs, ends, side="left")
    return fs, start, np.searchsorted(vs, ends, side="right") - start


def _next_to_another(st, key, rows, acc, owned):
    """With a dihedral bound: the collapses ``acc`` (bool per chosen one) a
    face of whose star borders the star of an accepted collapse (``owned``
    faces, earlier rounds) or of one chosen now with a smaller ``key``: the
    bend across that edge was judged against the face as it is, so they
    wait for the next pass. (k,) bool."""
    star, kf, coll, cA, cB = rows
    mine = _take(acc, kf)
    now = np.full(st.F.shape[0], _BIG, dtype=np.int64)
    now[star[mine]] = _take(key, kf[mine])
    r = np.flatnonzero(mine & ~coll)
    h = 3 * star[r] + np.where(cA[r] >= 0, cA[r], cB[r])   # the far edge of each moved face
    t = st.twin[h]
    inner = t >= 0
    r, fo = r[inner], t[inner] // 3
    k = kf[r]
    hit = owned[fo] | (now[fo] < _take(key, k))
    wait = np.zeros(acc.size, dtype=bool)
    wait[k[hit]] = True
    return wait


def _trim_to_target(pool, acc, m, target):
    """The accepted collapses the target still needs, cheapest first."""
    if target is None:
        return acc
    removed = np.where(pool.interior[acc.idx], 2, 1)
    if int(removed.sum()) <= m - target:       # (all kept: no sort)
        return acc
    order = np.argsort(pool.cost[acc.idx], kind="stable")
    before = np.empty(acc.idx.size, dtype=np.int64)
    before[order] = np.cumsum(removed[order]) - removed[order]
    keep = before < m - target
    if keep.all():
        return acc
    return _Accepted(acc.idx[keep], _keep_rows(acc.rows, keep), acc.wit[keep])


def _keep_rows(rows, keep, offset=0):
    """The star rows ``(star, kf, coll, cA, cB)`` of the collapses ``keep``
    (bool per collapse), renumbered from ``offset``."""
    kf = rows[1]
    r = np.flatnonzero(_take(keep, kf))
    out = [_take(c, r) for c in rows]
    out[1] = _take(np.cumsum(keep) - 1 + offset, out[1])
    return tuple(out)


# ---------------------------------------------------------------- checks


class _Checked(NamedTuple):
    """What :func:`_check` finds for k collapses."""

    ok: np.ndarray       #: (k,) bool: valid
    pen: np.ndarray      #: (k,) penalties (compactness, Hausdorff)
    rows: tuple          #: star rows ``(star, kf, coll, cA, cB)``
    wit: np.ndarray      #: (k,3) the survivor's witness
    bent: np.ndarray     #: (k,) bool: refused only by the dihedral bound
    flip: np.ndarray     #: (k,3) faces the collapse flips (-1: none; big stars only)


def _check(st, A, B, XT, interior, star, kf, tun, haus=True, dihedral_cos=None, quick=True):
    """:func:`_check_block` over blocks of collapses, on the worker threads,
    with ``quick`` after :func:`_quick_refusals` (a big star refused on a sample of its
    faces is not checked whole: its star rows are left out, its penalty is
    0 and its witness A's, as :func:`_check_block` leaves a refused one's).
    Otherwise the same results; the star rows come back grouped by block."""
    refused, flip = _quick_refusals(st, A, B, XT, star, kf, tun) if quick else (None, None)
    if refused is None or not refused.any():
        return _check_blocks(st, A, B, XT, interior, star, kf, tun, haus, dihedral_cos)
    rest = np.flatnonzero(~refused)
    new = np.cumsum(~refused) - 1
    r = np.flatnonzero(~_take(refused, kf))
    c = _check_blocks(st, A[rest], B[rest], XT[:, rest], interior[rest], star[r], _take(new, kf[r]), tun, haus,
                      dihedral_cos)
    ok, pen, bent = np.zeros(A.size, dtype=bool), np.zeros(A.size), np.zeros(A.size, dtype=bool)
    wit = _take(st.wit, A, axis=0)
    ok[rest], pen[rest], wit[rest], bent[rest], flip[rest] = c.ok, c.pen, c.wit, c.bent, c.flip
    star_c, kf_c, coll, cA, cB = c.rows
    return _Checked(ok, pen, (star_c, _take(rest, kf_c), coll, cA, cB), wit, bent, flip)


def _quick_refusals(st, A, B, XT, star, kf, tun):
    """The collapses with at least ``Tuning.hold_star`` faces around their
    ends (a fan's hub) that turn over one of about ``Tuning.hold_sample`` of
    those faces, evenly spread: refused without checking the hundreds of others (a hub's spokes
    fold half the fan). Returns the (k,) bool refusals and their flipped
    faces (k,3) (see :func:`_witnesses`; -1 elsewhere)."""
    k = A.size
    count = np.bincount(kf, minlength=k)
    big = count >= tun.hold_star
    refused, flip = np.zeros(k, dtype=bool), np.full((k, 3), -1, dtype=np.int64)
    if not big.any():
        return refused, flip
    r = np.flatnonzero(_take(big, kf))
    r = r[np.argsort(_take(kf, r), kind="stable")]
    kr = _take(kf, r)
    step = np.maximum(_take(count, kr) // tun.hold_sample, 1)
    first = np.searchsorted(kr, kr)
    r = r[(np.arange(r.size) - first) % step == 0]
    return _flips_on(st, A, B, XT, _take(star, r), _take(kf, r), tun)[:2]


def _flips_on(st, A, B, XT, star, kf, tun, least=None, even=None):
    """Which collapses turn over one of the faces ``star`` (rows: ``kf``
    gives each one's collapse), and three of those faces (:func:`_witnesses`).
    With ``least`` ((2k,): the least compact face around each of ``A`` and
    then ``B`` as they are, :func:`_least_compact_around`; 0 for none) also
    those that make one of them a sliver (less compact than
    ``Tuning.gamma_hard`` and than half of ``least``). On a sample of the
    stars both are refusals the whole star's check makes (its new faces
    include the sample's, and its old ones are no less compact than
    ``least``): a CAD cap's hub, its spokes each refused for the sliver it
    makes beside the rim vertex it merges into, waited for one spoke a
    round (a 10k-face cylinder to 200 faces took 197 passes). Only the
    first ``even`` rows (all when None) are tested for turned faces (more
    of them held more collapses back until those faces change: a flat grid
    to 4 faces took 59 passes, not 54). Returns the (k,) bool refusals, the
    witnesses (k,3) and the :class:`_Slivers` of the sliver refusals (none
    without ``least``)."""
    k = A.size
    s = _star_of(st.F, A, B, star, kf)
    p = s.mv.size if even is None else int(np.searchsorted(s.mv, even))
    g = _moved_faces(st, s, XT, p)
    turned = np.flatnonzero(_turned_faces(st, *_first_moved(s, g, p), A, B, tun))
    refused = np.zeros(k, dtype=bool)
    refused[s.mk[turned]] = True
    sliver = _Slivers(np.full(k, -1, dtype=np.int64), np.ones(k))
    if least is not None:
        after = compactness(g.l1, _edge_squares(*g.Q))
        gmin_new = _least_of(k, s.mk, after)
        old = np.minimum(least[:k], least[k:])
        thin = (gmin_new < tun.gamma_hard) & (gmin_new < 0.5 * (1.0 - _SLACK) * old)
        refused |= thin
        sliver = _sliver_witnesses(s, after, gmin_new, thin)
    return refused, _witnesses(s, turned, np.ones(k, dtype=bool)), sliver


class _Slivers(NamedTuple):
    """The sliver each of k collapses makes (from :func:`_flips_on`)."""

    face: np.ndarray     #: (k,) the face it makes least compact (-1: no sliver refusal)
    after: np.ndarray    #: (k,) ... and that face's compactness after

    def of(self, k):
        """Those of the collapses ``k`` (an index or a mask)."""
        return _Slivers(self.face[k], self.after[k])


def _sliver_witnesses(s, after, least, thin):
    """The :class:`_Slivers` of the collapses ``thin`` (k,) bool of the star
    rows ``s``: for each, its first face that stays whose compactness
    ``after`` (one per face that stays) is its ``least``."""
    face = np.full(s.k, -1, dtype=np.int64)
    rows = np.flatnonzero((after == _take(least, s.mk)) & _take(thin, s.mk))
    k, first = np.unique(_take(s.mk, rows), return_index=True)
    face[k] = _take(s.star, _take(s.mv, rows[first]))
    return _Slivers(face, least)


class _LeastCompact(NamedTuple):
    """The least compact faces around the ends of some collapses (as
    :func:`_min_compactness` measures them, on the mesh as it is)."""

    least: np.ndarray   #: (2k,) the smallest compactness around each of A, then B (1: none)
    faces: np.ndarray   #: up to ``per`` faces of smallest compactness around each end ...
    k: np.ndarray       #: ... and the collapse of each


def _compactness_near(st, ends):
    """The live faces with a corner among ``ends``: ``(f, FT, g)``, their ids
    (ascending), corners (3,r) and compactness (:func:`_min_compactness`'s
    measure, on the mesh as it is)."""
    near = np.zeros(st.V.shape[0], dtype=bool)
    near[ends] = True
    f = np.flatnonzero(st.alive & (near[st.F[:, 0]] | near[st.F[:, 1]] | near[st.F[:, 2]]))
    FT = np.ascontiguousarray(_take(st.F, f, axis=0).T)
    P0, P1, P2 = (_take(st.VT, FT[c], axis=1) for c in range(3))
    N = cross_columns(P1 - P0, P2 - P0)
    return f, FT, compactness(np.sqrt(dot_columns(N, N)), _edge_squares(P0, P1, P2))


def _least_compactness(st, A, B):
    """(2k,) the smallest compactness of the live faces around each of ``A``,
    then ``B`` (1 where there are none): :class:`_LeastCompact`'s ``least``
    without the sort that lists the faces."""
    ends = np.concatenate([A, B])
    _, FT, g = _compactness_near(st, ends)
    least = np.full(st.V.shape[0], np.inf)
    for c in range(3):
        np.minimum.at(least, FT[c], g)
    least = _take(least, ends)
    return np.where(np.isfinite(least), least, 1.0)


def _least_compact_around(st, A, B, per):
    """The :class:`_LeastCompact` of the collapses ``B[k] -> A[k]``: their
    ``per`` least compact faces around each end are the ones a move of it
    most likely makes slivers."""
    ends = np.concatenate([A, B])
    f, FT, g = _compactness_near(st, ends)
    g = np.tile(g, 3)
    v, fv = FT.ravel(), np.tile(f, 3)
    o = np.lexsort((g, v))                        # by vertex, then compactness
    v, fv, g = _take(v, o), _take(fv, o), _take(g, o)
    start = np.searchsorted(v, ends)
    count = np.searchsorted(v, ends, side="right") - start
    least = np.where(count > 0, _take(g, np.minimum(start, max(g.size - 1, 0))), 1.0)
    k, i = ragged_ranges(start, np.minimum(count, per))
    return _LeastCompact(least, _take(fv, k), i % A.size)


def _sampled_stars(st, A, B, per):
    """About ``per`` of the live faces around each of ``A[k]`` and ``B[k]``,
    evenly spread (every one up to ``per``), as star rows ``(star, kf)``."""
    ends = np.concatenate([A, B])
    fs, start, count = _faces_at(st.F, np.flatnonzero(st.alive), ends)
    step = np.maximum(count // per, 1)
    j, g = ragged_ranges(np.zeros(ends.size, dtype=np.int64), (count + step - 1) // step)
    star = _take(fs, _take(start, g) + j * _take(step, g))
    return star, g % A.size


def _sliver_samples(st, h, A, B, per):
    """For the slivers the collapses of the edges ``h[k]`` (``B[k] -> A[k]``)
    would make: the faces near each edge (``per // 2`` each way around each
    end, :func:`_fans_near`) and the ``per // 4`` least compact ones around
    each end, as star rows ``(star, kf)``, and the least compactness around
    each of A and then B (a :class:`_LeastCompact`'s ``least``)."""
    least = _least_compact_around(st, A, B, per // 4)
    near, nk = _fans_near(st, h, A, B, per // 2)
    return np.concatenate([near, least.faces]), np.concatenate([nk, least.k]), least.least


def _fans_near(st, h, A, B, steps):
    """The faces met walking around each end of the edge ``h[k]`` (``A[k]``,
    ``B[k]``) from the face of ``h``, ``steps`` faces each way (past the
    faces the collapse removes; a border or a non-manifold edge ends a
    walk): where the merged fan's new faces are thinnest. Rows ``(faces, k)``."""
    k = np.arange(h.size, dtype=np.int64)
    v0, f0, k0 = np.concatenate([A, B]), np.tile(h // 3, 2), np.tile(k, 2)
    faces, ks = [], []
    for turn in (_PREV, _NEXT):     # (crossing the edge after v, or before it, turns one way)
        v, f, kk = v0, f0, k0
        for _ in range(steps + 1):
            c = _corner(_take(st.F, f, axis=0), v)
            t = _take(st.twin, 3 * f + _take(turn, np.maximum(c, 0)))
            on = np.flatnonzero((c >= 0) & (t >= 0))
            v, f, kk = _take(v, on), _take(t, on) // 3, _take(kk, on)
            faces.append(f)
            ks.append(kk)
    return np.concatenate(faces), np.concatenate(ks)


def _witnesses(s, turned, hold):
    """Three of the faces each collapse of the star rows ``s`` turns over
    (``turned``: rows of ``s.mv``), at 1/6, 1/2 and 5/6 of them in ``s``'s
    order, for the collapses ``hold`` (k,) bool; (k,3), -1 where none."""
    flip = np.full((s.k, 3), -1, dtype=np.int64)
    if turned.size and hold.any():
        turned = turned[np.argsort(s.mk[turned], kind="stable")]
        cnt = np.bincount(s.mk[turned], minlength=s.k)
        first = np.cumsum(cnt) - cnt
        has = np.flatnonzero((cnt > 0) & hold)
        for j, q in enumerate((1, 3, 5)):
            flip[has, j] = s.star[s.mv[turned[first[has] + (cnt[has] * q) // 6]]]
    return flip


def _check_blocks(st, A, B, XT, interior, star, kf, tun, haus, dihedral_cos):
    """:func:`_check_block` over blocks of collapses, on the worker threads."""
    spans = blocks(A.size, tun.block // 10)
    if len(spans) <= 1:
        return _check_block(st, A, B, XT, interior, star, kf, tun, haus, dihedral_cos)
    starts = np.array([i for i, _ in spans], dtype=np.int64)
    blk = np.searchsorted(starts, kf, side="right") - 1
    order = stable_argsort(blk)
    cut = np.concatenate([[0], np.cumsum(np.bincount(blk, minlength=len(spans)))])
    star, kf = star[order], kf[order]

    def block(b):
        (i, j), r0, r1 = spans[b], cut[b], cut[b + 1]
        return _check_block(st, A[i:j], B[i:j], XT[:, i:j], interior[i:j], star[r0:r1], kf[r0:r1] - i, tun,
                            haus, dihedral_cos)

    res = run_each(block, range(len(spans)))
    ok, pen, wit, bent, flip = (np.concatenate([r[c] for r in res]) for c in (0, 1, 3, 4, 5))
    coll, cA, cB = (np.concatenate([r[2][c] for r in res]) for c in (2, 3, 4))
    return _Checked(ok, pen, (star, kf, coll, cA, cB), wit, bent, flip)


class _Star(NamedTuple):
    """The faces around the endpoints of k independent collapses B -> A."""

    k: int
    star: np.ndarray     #: face ids
    kf: np.ndarray       #: the collapse each belongs to
    Fs: np.ndarray       #: their rows
    cA: np.ndarray       #: corner of A in each (-1: absent)
    cB: np.ndarray       #: corner of B
    coll: np.ndarray     #: bool: removed (has both)
    mv: np.ndarray       #: rows of the faces that stay (one corner moves)
    mk: np.ndarray       #: ... their collapse
    cm: np.ndarray       #: ... the corner that moves
    onA: np.ndarray      #: ... whether it is A's


def _star_of(F, A, B, star, kf):
    """The star rows of collapses ``B[k] -> A[k]`` (see :class:`_Star`)."""
    Fs = _take(F, star, axis=0)
    cA = _corner(Fs, _take(A, kf))
    cB = _corner(Fs, _take(B, kf))
    coll = (cA >= 0) & (cB >= 0)
    mv = np.flatnonzero(~coll)
    onA = _take(cA >= 0, mv)
    cm = np.where(onA, _take(cA, mv), _take(cB, mv))
    return _Star(A.size, star, kf, Fs, cA, cB, coll, mv, _take(kf, mv), cm, onA)


def _link_condition(st, s, interior):
    """Collapses that keep the mesh a manifold of the same topology (Dey et
    al.): the common neighbours of A and B are exactly the opposite vertices
    of the removed faces; not the last tetrahedron (both ends of valence
    3), not an isolated triangle, never a non-manifold edge. (k,) bool."""
    k, n = s.k, st.V.shape[0]
    ok = np.ones(k, dtype=bool)
    Fr = s.Fs.ravel()
    cidx = np.flatnonzero(s.coll)
    kc = _take(s.kf, cidx)
    cv = _take(Fr, 3 * cidx + 3 - _take(s.cA, cidx) - _take(s.cB, cidx))  # opposite vertex of each removed face
    order = np.argsort(kc, kind="stable")
    ck, cv = _take(kc, order), _take(cv, order)
    first = np.ones(ck.size, dtype=bool)
    first[1:] = ck[1:] != ck[:-1]
    opp = np.full((k, 2), -1, dtype=np.int64)
    opp[ck[first], 0] = cv[first]
    opp[ck[~first], 1] = cv[~first]
    ok &= np.bincount(ck, minlength=k) == np.where(interior, 2, 1)
    # the two other vertices of each face that stays: neighbours of A (or B)
    # other than the opposite ones; a neighbour of both is an extra common one
    base = 3 * s.mv
    x1 = _take(Fr, base + _take(_NEXT, s.cm))
    x2 = _take(Fr, base + _take(_PREV, s.cm))
    ia, ib = np.flatnonzero(s.onA), np.flatnonzero(~s.onA)
    if ia.size and ib.size:
        ka = np.concatenate([_take(s.mk, ia), _take(s.mk, ia)])
        xa = np.concatenate([_take(x1, ia), _take(x2, ia)])
        qk = np.concatenate([_take(s.mk, ib), _take(s.mk, ib)])
        qx = np.concatenate([_take(x1, ib), _take(x2, ib)])
        common = _common_pairs(ka, xa, qk, qx, n)
        extra = common & (qx != _take(opp[:, 0], qk)) & (qx != _take(opp[:, 1], qk))
        ok[qk[extra]] = False
    valA = np.bincount(s.kf[s.cA >= 0], minlength=k)
    valB = np.bincount(s.kf[s.cB >= 0], minlength=k)
    ok &= ~(interior & (valA == 3) & (valB == 3))
    hA = 3 * s.star[cidx] + _take(s.cA, cidx)   # edge (B, c)
    hB = 3 * s.star[cidx] + _take(s.cB, cidx)   # edge (c, A)
    tA, tB = st.twin[hA], st.twin[hB]
    bad = (tA == NON_MANIFOLD) | (tB == NON_MANIFOLD) | ((tA == BOUNDARY) & (tB == BOUNDARY))
    ok[kc[bad]] = False
    return ok


def _pairs_among(ka, xa, kb, xb, n):
    """For each pair ``(kb[i], xb[i])``: is it among the pairs ``(ka, xa)``?
    By one sort of the keys ``k * n + x``."""
    nn = np.int64(max(n, 1))
    keys = np.sort(ka * nn + xa)
    q = kb * nn + xb
    if keys.size == 0:
        return np.zeros(q.size, dtype=bool)
    return keys[np.minimum(np.searchsorted(keys, q), keys.size - 1)] == q


def _common_pairs(ka, xa, kb, xb, n):
    """For each pair ``(kb[i], xb[i])``: is ``(kb[i], xb[i])`` among the pairs
    ``(ka, xa)``? Marks vertices with their collapse (last write wins) and
    settles the few vertices claimed by several collapses with a sort."""
    if 8 * (xa.size + xb.size) < n:          # few pairs on a large mesh: a sort costs less than marks
        return _pairs_among(ka, xa, kb, xb, n)
    mark = _marks(n)
    mark[xa] = ka
    hit = _take(mark, xb) == kb
    lost = _take(mark, xa) != ka
    if lost.any():
        mark[xa[lost]] = -2                  # contested: claimed by several collapses
        sa = np.flatnonzero(_take(mark, xa) == -2)
        sb = np.flatnonzero(_take(mark, xb) == -2)
        hit[sb] = _pairs_among(ka[sa], xa[sa], kb[sb], xb[sb], n)
    mark[xa] = -1
    return hit


_local = threading.local()


def _marks(n):
    """An int64 array of at least ``n`` entries of -1, one per thread, kept
    between calls (its user puts back -1 where it wrote)."""
    mark = getattr(_local, "mark", None)
    if mark is None or mark.size < n:
        mark = _local.mark = np.full(n, -1, dtype=np.int64)
    return mark


class _Moved(NamedTuple):
    """The faces that stay, before (P) and after (Q) their corner moves to X;
    coordinates first: ``P[c]`` is the (3, r) corner c of every face."""

    FT: np.ndarray       #: (3, r) their vertex rows
    P: np.ndarray        #: (3, 3, r) corners before
    Q: tuple             #: three (3, r) corners after
    N0: np.ndarray       #: (3, r) area normals before
    N1: np.ndarray       #: ... after
    l0: np.ndarray       #: twice the areas before
    l1: np.ndarray       #: ... after


def _squared_lengths(VT, a, b):
    """Squared lengths of the edges ``(a[i], b[i])`` from the (3, n) positions ``VT``."""
    D = _take(VT, b, axis=1)
    D -= _take(VT, a, axis=1)
    return dot_columns(D, D)


def _moved_faces(st, s, XT, before=None):
    """Geometry of the faces that stay, one corner moved to its collapse's X
    (their normals before for the first ``before`` of them only, when given)."""
    FmT = np.ascontiguousarray(_take(s.Fs, s.mv, axis=0).T)   # (contiguous index rows gather much faster)
    r = FmT.shape[1]
    P = _take(st.VT, FmT.ravel(), axis=1).reshape(3, 3, r).transpose(1, 0, 2)
    Xm = _take(XT, s.mk, axis=1)
    Q = tuple(np.where(s.cm == c, Xm, P[c]) for c in range(3))
    b = slice(0, r if before is None else before)
    N0 = cross_columns(P[1, :, b] - P[0, :, b], P[2, :, b] - P[0, :, b])
    N1 = cross_columns(Q[1] - Q[0], Q[2] - Q[0])
    return _Moved(FmT, P, Q, N0, N1, np.sqrt(dot_columns(N0, N0)), np.sqrt(dot_columns(N1, N1)))


def _turned_faces(st, s, g, A, B, tun):
    """Per moved face: does it flip (its normal turns by more than
    ``acos(flip_cos)``), or end against the input surface it stands for
    (the summed normals of the input faces merged into its vertices: no
    slow drift)? A face already against its input (a fold of a noisy
    input) may move freely: holding it would freeze its neighbourhood."""
    flip = (g.l0 > 0) & (dot_columns(g.N0, g.N1) <= tun.flip_cos * g.l0 * g.l1)
    if tun.ref_cos > -1.0:
        Nr = st.NrefT
        moved_v = _take(s.Fs.ravel(), 3 * s.mv + s.cm)
        ref0 = _take(Nr, g.FT.ravel(), axis=1).reshape(3, 3, -1)
        ref0 = ref0[:, 0] + ref0[:, 1] + ref0[:, 2]
        AB = _take(Nr, A, axis=1) + _take(Nr, B, axis=1)
        ref = ref0 - _take(Nr, moved_v, axis=1) + _take(AB, s.mk, axis=1)
        lr = np.sqrt(dot_columns(ref, ref))
        against = dot_columns(ref, g.N1) < tun.ref_cos * lr * g.l1
        if tun.ref_agree > 0.0:
            # where the input under the face agrees on a side: on a thin part (a
            # plate's rim, its two sides merged) the normals cancel and say nothing
            Ar = st.Aref
            area = _take(Ar, g.FT.ravel()).reshape(3, -1).sum(axis=0) - _take(Ar, moved_v) \
                + _take(_take(Ar, A) + _take(Ar, B), s.mk)
            against &= lr >= tun.ref_agree * area
        flip |= against
        flip &= dot_columns(ref0, g.N0) >= 0
    return flip


def _min_compactness(s, g):
    """Smallest compactness around each collapse, (before, after), (k,) each."""
    return (_least_of(s.k, s.mk, compactness(g.l0, _edge_squares(*g.P))),
            _least_of(s.k, s.mk, compactness(g.l1, _edge_squares(*g.Q))))


def _least_of(k, mk, values):
    """The smallest of ``values`` of each of ``k`` collapses (1 for none):
    ``mk`` the collapse of each value."""
    least = np.ones(k)
    np.minimum.at(least, mk, values)
    return least


def _first_moved(s, g, p):
    """The star rows ``s`` (a :class:`_Star`) and their geometry ``g`` (a
    :class:`_Moved` whose normals before are the first ``p`` faces' only) of
    the first ``p`` faces that stay only (views)."""
    cut = slice(0, p)
    return (s._replace(mv=s.mv[cut], mk=s.mk[cut], cm=s.cm[cut], onA=s.onA[cut]),
            _Moved(g.FT[:, cut], g.P[:, :, cut], tuple(q[:, cut] for q in g.Q), g.N0,
                   g.N1[:, cut], g.l0, g.l1[cut]))


def _edge_squares(P0, P1, P2):
    """The sums of the squared edge lengths of the triangles of corners
    ``P0``, ``P1``, ``P2`` (3, k) each (compactness's denominator; one
    formula for :func:`_min_compactness` and :func:`_least_compact_around`,
    whose refusals on a sample hold only while they measure alike)."""
    return sum(dot_columns(D, D) for D in (P1 - P0, P2 - P1, P0 - P2))


def _compactness_penalty(st, s, g, A, B, gmin_old, gmin_new, tun):
    """Only collapses that make the neighbourhood less compact than it was
    (below ``gamma_soft``) pay: star area * edge length^2 * shortfall^2."""
    area = np.bincount(s.mk, weights=0.5 * g.l1, minlength=s.k)
    L2 = _squared_lengths(st.VT, A, B)
    short = np.maximum(0.0, np.minimum(gmin_old, tun.gamma_soft) - gmin_new) / tun.gamma_soft
    return tun.compact_weight * area * L2 * short * short


def _hausdorff_penalty(st, s, g, A, B, ok, tun):
    """Distance of the witnesses of A and B (the input points merged into
    them that were farthest from the surface) to the new faces: the penalty
    ``haus_weight * merged area * max distance^2`` (k,), and the survivor's
    witness (k,3): the farther of the two. Measured for the valid collapses
    (``ok``) only: a refused one's penalty and witness are never read (0 and A's)."""
    wA, wB = _take(st.wit, A, axis=0), _take(st.wit, B, axis=0)
    k = s.k
    rows = np.flatnonzero(_take(ok, s.mk))
    mk = _take(s.mk, rows)
    D = triangle_rows(*(_take(q, rows, axis=1).T for q in g.Q))  # the new faces, once for both witnesses

    def nearest(w):
        P = np.ascontiguousarray(_take(w, mk, axis=0).T)
        d = np.full(k, np.inf)
        np.minimum.at(d, mk, closest_on_triangles(P[0], P[1], P[2], D)[2])
        d[~np.isfinite(d)] = 0.0
        return d

    dA, dB = nearest(wA), nearest(wB)
    penalty = tun.haus_weight * _merged_area(st, A, B) * np.maximum(dA, dB)
    return penalty, np.where((dB > dA)[:, None], wB, wA)


def _bends_too_far(st, s, g, dihedral_cos):
    """Per collapse: would a pair of adjacent faces it changes bend by more
    than ``acos(dihedral_cos)`` (the angle between their normals), away from
    the input's creases? The pairs are the new fan's edges at A (both faces
    moved) and each moved face's far edge (against the current face beyond).
    (k,) bool."""
    n = st.V.shape[0]
    f = _take(s.star, s.mv)
    x1 = _take(s.Fs.ravel(), 3 * s.mv + _take(_NEXT, s.cm))
    x2 = _take(s.Fs.ravel(), 3 * s.mv + _take(_PREV, s.cm))
    N, l = g.N1, g.l1
    bad = np.zeros(s.k, dtype=bool)
    # the fan: the face whose edge A -> x1 runs to x meets the one whose x2 is x
    k1 = s.mk * np.int64(n) + x1
    k2 = s.mk * np.int64(n) + x2
    o2 = np.argsort(k2, kind="stable")
    pos = np.minimum(np.searchsorted(k2[o2], k1), max(k2.size - 1, 0))
    if k2.size:
        b = o2[pos]
        pair = np.flatnonzero(k2[b] == k1)
        b = b[pair]
        crease = (st.feat[3 * f[pair] + _take(_PREV, s.cm[pair])]
                  | st.feat[3 * f[b] + _take(_NEXT, s.cm[b])])
        cos_ok = dot_columns(_take(N, pair, axis=1), _take(N, b, axis=1)) >= dihedral_cos * l[pair] * l[b]
        bad[s.mk[pair[~cos_ok & ~crease]]] = True
    # the far edge of each moved face, against the (unchanged) face beyond it
    h = 3 * f + s.cm
    t = st.twin[h]
    out = np.flatnonzero((t >= 0) & ~st.feat[h])
    if out.size:
        Fo = _take(st.F, t[out] // 3, axis=0)
        Vo = [_take(st.VT, Fo[:, c], axis=1) for c in range(3)]
        No = cross_columns(Vo[1] - Vo[0], Vo[2] - Vo[0])
        lo = np.sqrt(dot_columns(No, No))
        cos_ok = dot_columns(_take(N, out, axis=1), No) >= dihedral_cos * l[out] * lo
        bad[s.mk[out[~cos_ok]]] = True
    return bad


def _check_block(st, A, B, XT, interior, star, kf, tun, haus=True, dihedral_cos=None):
    """Validity and penalty of independent collapses B[k] -> A[k] at XT[:, k],
    judged on the current mesh (``dihedral_cos``: also refuse collapses that
    bend adjacent faces too far, see :func:`_bends_too_far`).

    ``star`` lists every face around the endpoints, ``kf`` the collapse each
    belongs to. Returns ``ok`` (k,) bool, ``penalty`` (k,), the star rows
    ``(star, kf, coll, cA, cB)``: face ids, their collapse index, whether each
    face is removed, and the corners of A and B in it (-1: absent), the
    survivor's witness (k,3), and ``bent`` (k,) bool: refused only by the
    dihedral bound, and ``flip`` (k,3): three of the faces each collapse
    flips, spread over them (-1: none; only for stars of at least
    ``Tuning.hold_star`` faces, whose refusals are then held, see
    :func:`_still_flips`). A :class:`_Checked`.
    """
    s = _star_of(st.F, A, B, star, kf)
    ok = _link_condition(st, s, interior)
    g = _moved_faces(st, s, XT)
    turned = np.flatnonzero(_turned_faces(st, s, g, A, B, tun))
    ok[s.mk[turned]] = False
    flip = _witnesses(s, turned, np.bincount(s.kf, minlength=s.k) >= tun.hold_star)
    gmin_old, gmin_new = _min_compactness(s, g)
    ok &= ~((gmin_new < tun.gamma_hard) & (gmin_new < 0.5 * gmin_old))   # no new sliver
    bent = np.zeros(s.k, dtype=bool)
    if dihedral_cos is not None:
        bent = ok & _bends_too_far(st, s, g, dihedral_cos)
        ok &= ~bent
    penalty = _compactness_penalty(st, s, g, A, B, gmin_old, gmin_new, tun)
    wnew = _take(st.wit, A, axis=0)
    if haus and tun.haus_weight > 0.0 and s.mk.size:
        pen_h, wnew = _hausdorff_penalty(st, s, g, A, B, ok, tun)
        penalty = penalty + pen_h
    return _Checked(ok, penalty, (star, kf, s.coll, s.cA, s.cB), wnew, bent, flip)


# ---------------------------------------------------------------- the loop


def run(st, target, max_err_n, preserve_boundary, progress, m0, tun, dihedral_cos=None):
    """The batched collapse loop. Returns (stopped_because, passes); the
    state is compact afterwards. With ``dihedral_cos``, collapses that would
    bend two adjacent faces (off the input's creases) by more than its
    arccos are refused, and a stop for want of valid collapses while some
    were refused only for that reads ``"max_dihedral"``."""
    _forget_refusals(st)
    # no compaction when _run raises (an interrupt may land mid-pass, the
    # state half-updated: compacting it would hide the interrupt behind an
    # IndexError, and the state is dropped anyway)
    stopped, passes = _run(st, target, max_err_n, preserve_boundary, progress, m0, tun, dihedral_cos)
    compact(st, tun.threads_min_edges)
    if stopped == "no_valid_collapse" and dihedral_cos is not None:
        if st.bent[edge_representatives(st.twin)].any():
            stopped = "max_dihedral"
    return stopped, passes


def _forget_refusals(st):
    """Start a run with no remembered refusal: its passes count from 1
    again, and the topology changes between runs (``core._relax``) may have
    made any of them wrong."""
    st.c_blk[:] = -1.0
    st.vver[:] = -1
    st.vmov[:] = -1


def _progress(progress, m0, m, target):
    """Report the fraction done; False when the caller asks to stop."""
    frac = (m0 - m) / (m0 - target) if target is not None and m0 > target else (m0 - m) / max(m0, 1)
    return not stops(progress(float(min(max(frac, 0.0), 1.0))))


def _run(st, target, max_err_n, preserve_boundary, progress, m0, tun, dihedral_cos):
    passes, grow, m_last, bold_on, stalled = 0, 1.0, None, True, 0
    reach = _collapse_reach(st, target, tun) if max_err_n is None else None
    clock = _Clock(st.seconds)
    while passes < tun.max_passes:
        if st.m_live < tun.compact_share * st.F.shape[0]:
            compact(st, tun.threads_min_edges)
            clock.lap("compact")
        m = st.m_live
        if target is not None and m <= target:
            return "target", passes
        if progress is not None and passes > 0 and not _progress(progress, m0, m, target):
            return "cancelled", passes
        if m_last is not None and target is not None:
            grow = grow * tun.pool_growth if m_last - m < tun.slow_pass_share * (m_last - target) else 1.0
        m_last = m
        passes += 1
        e = _candidate_edges(st)
        ne = int(np.count_nonzero(np.isfinite(e.cost)))
        clock.lap("candidates")
        if ne == 0:
            if (tun := _unstuck(st, tun)) is None:
                return "no_valid_collapse", passes
            continue
        bold = bold_on and target is not None and m > tun.bold_above * max(target, tun.bold_min_target)
        P = _pool_size(ne, m, target, tun, bold, grow, stalled)
        _recost_cheapest(st, e, P, max_err_n, preserve_boundary, tun)
        clock.lap("recost")
        cand = np.isfinite(e.cost)
        if max_err_n is not None:
            within = _distance(st, _take(st.c_cost, e.rep), e.U, e.W) <= max_err_n
            if not (cand & within).any():
                return ("max_error" if cand.any() else "no_valid_collapse"), passes
            cand &= within
        ci = np.flatnonzero(cand & ~e.stale)
        if ci.size == 0:
            if e.stale.any():
                continue
            if (tun := _unstuck(st, tun)) is None:
                return "no_valid_collapse", passes
            continue
        pool = _choose_pool(st, e, ci, P, tun, reach)
        clock.lap("pool")
        # the Hausdorff penalty matters once the cage is coarse: skip it before
        haus = target is None or m <= tun.haus_phase * target
        if bold:
            _bold_rounds(st, pool, passes, haus, dihedral_cos, tun, target)
            bold_on = m - st.m_live >= tun.bold_min_share * m
            clock.lap("pick, check and apply (bold)")
            continue
        acc, touched = _check_rounds(st, pool, passes, haus, dihedral_cos, tun)
        clock.lap("pick and check")
        if acc is None:
            stalled += 1
            continue
        stalled = 0
        st.vver[touched] = passes
        _apply_accepted(st, pool, _trim_to_target(pool, acc, m, target), passes)
        clock.lap("apply")
    return "no_valid_collapse", passes


def _collapse_reach(st, target, tun):
    """The largest RMS distance (working units) a collapse of a run to
    ``target`` faces may have while others are within it:
    ``Tuning.collapse_reach`` times the edge of an equilateral triangle of
    the mesh's area shared by ``target`` faces (None without a target).
    Area-weighted costs price a vertex that stands for little area (the rim
    of a fan of thin needles) low however far it moves: a CAD cylinder of
    25,000 segments to 500 faces merged its top and bottom rims there,
    9.6% of its size off."""
    if target is None or target <= 0 or tun.collapse_reach <= 0:
        return None
    # the input's area: each face's doubled area is in ``Aref`` at its three corners, and
    # merges add them up (a run starts compact: every vertex live)
    area = float(st.Aref.sum()) / 6.0
    return tun.collapse_reach * np.sqrt(4.0 * area / (np.sqrt(3.0) * target))


def _unstuck(st, tun):
    """When no valid collapse is left short of the target: the tuning with
    the reference-normal test held only where the input agrees on a side
    (``Tuning.ref_agree_stuck``), every remembered refusal forgotten so each
    edge is checked again; None when that is already so (the run stops)."""
    if tun.ref_agree >= tun.ref_agree_stuck or tun.ref_cos <= -1.0:
        return None
    st.c_blk[:] = -1.0
    return replace(tun, ref_agree=tun.ref_agree_stuck)


class _Clock:
    """Adds the seconds since the last lap to ``seconds[stage]``."""

    def __init__(self, seconds):
        self.seconds, self.t = seconds, time.perf_counter()

    def lap(self, stage):
        now = time.perf_counter()
        self.seconds[stage] = self.seconds.get(stage, 0.0) + (now - self.t)
        self.t = now


# ---------------------------------------------------------------- applying, compacting


def _apply_accepted(st, pool, acc, passes):
    """Apply the accepted collapses ``acc`` of ``pool`` (:class:`_Accepted`) in
    pass ``passes``: the largest error so far, the survivors' witnesses and
    pass, then :func:`_apply`."""
    i = acc.idx
    st.vmov[pool.A[i]] = passes
    st.worst = max(st.worst, float(_distance(st, pool.raw[i], pool.A[i], pool.B[i]).max()))
    st.wit[pool.A[i]] = acc.wit
    _apply(st, pool.A[i], pool.B[i], _take(pool.XT, i, axis=1), acc.rows)


def _apply(st, A, B, XT, rows):
    """Collapse every B[k] into A[k] at XT[:, k] at once (stars disjoint;
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
    st.moved[A] |= (XT[0] != VA[0]) | (XT[1] != VA[1]) | (XT[2] != VA[2])
    st.Q[A] = _take(st.Q, A, axis=0) + _take(st.Q, B, axis=0)   # (A are distinct)
    st.NrefT[:, A] = _take(st.NrefT, A, axis=1) + _take(st.NrefT, B, axis=1)
    st.Aref[A] = _take(st.Aref, A) + _take(st.Aref, B)
    st.V[A] = XT.T
    st.VT[:, A] = XT
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


def survivors(st):
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


def compact(st, threads_min_faces=0):
    """Drop the dead faces and vertices from every declared array (one job
    per array, on the worker threads when the arrays have at least
    ``threads_min_faces`` faces: below, the hand-offs cost more)."""
    threads = st.F.shape[0] >= threads_min_faces
    keep_f, keep_v = st.alive, ~st.dead_v
    if keep_f.all() and keep_v.all():
        return
    new_f = np.cumsum(keep_f) - 1
    new_v = np.cumsum(keep_v) - 1
    iv, ih = np.flatnonzero(keep_v), np.flatnonzero(np.repeat(keep_f, 3))
    rows = {"vertex": (iv, 0), "vertex_t": (iv, 1), "face": (np.flatnonzero(keep_f), 0),
            "half_edge": (ih, 0), "half_edge_t": (ih, 1)}
    renumber = {"vertex": lambda a: _take(new_v, a), "half_edge": lambda a: renumber_twins(a, new_f),
                "face": lambda a: _renumber_faces(a, keep_f, new_f)}

    def swap(name):  # each job replaces one array: the old one goes as soon as its job is done
        meta = _meta(name)
        if getattr(st, name) is None:         # (a lazy one not made yet)
            return
        idx, axis = rows[meta["per"]]
        a = _take(getattr(st, name), idx, axis=axis)
        setattr(st, name, a if meta["values"] is None else renumber[meta["values"]](a))

    run_each(swap, _declared(reset=False), threads=threads)
    cur = survivors(st)
    st.cur_of_clean = np.where(cur >= 0, _take(new_v, np.maximum(cur, 0)), -1)  # -1: removed component
    for name in _declared(reset=True):
        setattr(st, name, _fresh_rows(name, st.F.shape[0] if _per(name) == "face" else st.V.shape[0]))
    st.m_live = st.F.shape[0]


def _renumber_faces(a, keep_f, new_f):
    """Face ids ``a`` (-1: none) after compaction; a removed face's is -1."""
    f = np.maximum(a, 0)
    return np.where((a >= 0) & _take(keep_f, f), _take(new_f, f), -1).astype(a.dtype)


def append_faces(st, faces, forig):
    """Append ``faces`` (k,3) descending from input faces ``forig`` (k,):
    every per-face and per-half-edge array grows by its declared fill (the
    new half-edges are borders until the caller glues them); the state must
    be compact."""
    k = faces.shape[0]
    st.F = np.concatenate([st.F, faces])
    st.forig = np.concatenate([st.forig, forig])
    for name in _declared("face", "half_edge", "half_edge_t", reset=False):
        if name in ("F", "forig") or getattr(st, name) is None:
            continue
        axis = 1 if _per(name).endswith("_t") else 0
        size = 3 * k if _per(name).startswith("half_edge") else k
        setattr(st, name, np.concatenate([getattr(st, name), _fresh_rows(name, size)], axis=axis))
    for name in _declared("face", reset=True):
        setattr(st, name, _fresh_rows(name, st.F.shape[0]))
    st.m_live = st.F.shape[0]
