"""Exact closest points of many query points near a triangle mesh (the bind's query).

:class:`~.spatial.TriangleIndex` answers "closest point on the mesh" exactly
for any query; binding a scan asks it for a million points that all lie
within a fraction of a face of the surface, and there most of its time goes
into choosing candidates. :class:`NearQuery` keeps its grid, its bounds and
its exact kernel, and reorganises the candidate search so that nearly all of
it is a few batched matrix products on float32 tiles, a block of points at
a time::

    probe cell   the point's own cell, or when that is empty the nearest
                 non-empty one of its 26 neighbours (box distance)
    phase A      the edge-line bound (height above the plane, lateral distance
                 beyond the farthest-out edge line, ``spatial``'s docstring)
                 of every reference of the probe cell; the smallest is the
                 probe, evaluated exactly -> u (an exact upper bound; where
                 the probe lies far and far beyond its bound, past a long
                 sliver's tip, u is the index's exact distance instead)
    phase B      the same bound on every other cell within u of the point
                 (box distance)
    exact        the kernel (float64) on the pairs whose bound is within u:
                 first each point's smallest bound, then (a point with more
                 than ``_CROWDED`` pairs left: the bound is loose past sharp
                 corners) its nearest centroid, then the others within the
                 bound that gives; the smallest squared distance wins, exact
                 ties go to the lowest face index. A block with more than
                 ``_CROWDED_BLOCK`` pairs a point is answered in halves

Tiles: points (or (point, cell) pairs) that share a cell go in tiles of
``_TILE`` rows. The references of cell ``c`` are a run of the cell-ordered
table, ``ref[start[c] : start[c] + count[c]]``; a tile reads the window
``ref[start[c] : start[c] + W]`` for the width class ``W >= count[c]`` (one
fancy-indexed row of a ``sliding_window_view``), whose entries past
``count[c]`` belong to the next cells: more candidates than the cell, never
fewer (the table ends in padding entries whose bound is infinite). Each
reference is stored as four rows ``[d, -(d.c) - o]`` (d the normal and the
three outward edge normals, c the centroid, o the edge's offset), so the
tile's heights and edge-line excesses are ``[x, y, z, 1]`` times them: four
``(t, _TILE, 4) @ (t, 4, W)`` products.

Float32: coordinates are taken relative to the grid's origin, and the bound
is loosened by ``eps = 2**-16`` of the grid's extent grown by 4 cells (for
points in the grid's box grown by 4 cells the float32 rounding of the
products is below ``2**-19`` of that; points outside go to the index), so it
can keep a pair the float64 bound would drop, never drop one it keeps: the
result is the exact
closest point, bit for bit the minimum of the kernel over every triangle
(ties to the lowest face index); ``TriangleIndex.closest`` gives the same
distances and, but for exactly equidistant triangles, the same faces.

Every point's result depends on the point alone (not on the block, the
order or the thread), so the answer is the same for any block size and
thread count. Points whose ball around the probe leaves the 3x3x3 block of
cells around their own cell (far from the surface), or that have no
non-empty cell in that block, are answered by ``TriangleIndex.closest``, and
so is every point near a mesh of needles (:func:`needle_grid`: a CAD part's fans and
strips pass the tiles' bounds and are evaluated exactly by the hundred).
"""

import itertools
from typing import NamedTuple

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

from ._groups import sorted_unique
from .errors import InvalidArgumentError
from .mesh import check_finite_rows, check_number, shown
from .spatial import (CELL_FACTOR, CROWDED_CELL, PRUNE_SLACK, BestPairs, TriangleIndex,
                      closest_pairs, closest_result)
from .pages import plain_pages
from ._parallel import run_each

__all__ = ["NEEDLE_CELL_FACTOR", "NearQuery", "cell_for_reach", "needle_grid", "search_for",
           "search_kind"]

#: points per block (float32 temporaries of a few MiB; large blocks mean fewer NumPy
#: calls, each a GIL hand-over when two threads query at once: the bind's 1M-point
#: query was about 5% faster with 65,536 than with 32,768)
_BLOCK = 65536

#: rows (points, or (point, cell) pairs) per tile of one cell: each tile's bound is a
#: small matrix product, and with 8 rows the products' per-matrix overhead was a third
#: of the bind's query; 16 took binds of a 1M-vertex torus to a 10k-face cage from
#: 1.33-1.40 s to 1.20-1.29 s (best / median of 4, alternating; 32: 1.19-1.23), of the
#: bunny x16 and x4 to 2,000-face cages 0.97 -> 0.91 s and 1.17 -> 0.97 s (medians of
#: 5), the plain bunny to 500 faces 0.27 -> 0.25 s (2026-12-04); the tiles were 95% full
_TILE = 16

#: (row, reference) pairs per set of tiles handled at once (float32 arrays of
#: 1 MiB). Smaller sets stay in cache and win on one thread; on two, each set's
#: NumPy calls hold the GIL, and 4x fewer of them made the bind of a 1M-vertex
#: scan about 10% faster (median of 12 alternating runs, 2026-12-02)
_TILE_SLOTS = 1 << 18

#: a block whose points have more pairs than this on average is answered as two
#: halves (down to ``_MIN_BLOCK`` points): a pinched scan's cage with model-long
#: slivers gave 150 pairs a point, 10M pairs a block, 1.5 us each out of cache
_CROWDED_BLOCK = 32
_MIN_BLOCK = 2048

#: points whose grid cell references more triangles than this (times the square of the
#: cells' growth for a ``reach``) go to the index (its hierarchy), not through the tiles:
#: a tile reads every reference of the 27 cells around a point, and where they are
#: slivers, which pass the bounds, each is evaluated exactly. The index's own limit also
#: grows with this module's wider cells (711 references). The 500-face cages of a CAD
#: cylinder and a fillet (one cell of 500 slivers) answered 60k points in 5.4-6.0 and
#: 7.2-9.4 s, now 1.1-1.3 and 0.5; the shared meshes, their 1,000-face cages and fine
#: surfaces have at most 214 in a cell (fandisk's fine surface: 0.21 s at any limit from
#: 256 up, 0.23 at 128)
_INDEX_CELL = CROWDED_CELL

#: a mesh whose grid references each face more than this many times on average, and
#: holds more than ``_NEEDLES_CELL`` references in a non-empty cell on average, is
#: answered by the index alone: its faces are needles (a CAD fan, a fillet's strips),
#: which pass the tiles' bounds and are evaluated by the hundred a point. Answered by an
#: index of the default cells: surface_distance of a CAD cylinder as tall as wide (caps
#: fans of 2,500 needles; 11 references a face, 253 a cell) and its 200-face cage 1.52
#: -> 0.33 s, of 5,000 3.30 -> 1.00, a CAD cylinder 10 tall 1.79 -> 1.53; a flat fan of
#: 10k needles 1.02 -> 1.69, of 40k 13.1 -> 12.3 (the NearQuery's own wider cells: 1.07,
#: 1.84, 1.78, 0.86, 11.7). The shared meshes: 1.9-2.1 and 21-28, the tiles' own
#: ground (0.4-1x the index's time)
_NEEDLES_PER_FACE = 3.0
_NEEDLES_CELL = 64

#: ... and when it is to answer at least this many queries a face, its index's cells are
#: ``NEEDLE_CELL_FACTOR`` mean triangle extents (a third of the default): a needle crosses
#: three times the cells, a cell holds a third of the needles, and each query bounds a
#: third of the pairs. 60k points near a 10k-face CAD cylinder (a fan of 2,500 needles
#: each cap) 0.72 -> 0.46 s with the build, near its 2,000-face cage 0.38 -> 0.17; a
#: 40k-face one 1.63 -> 1.35 s; with fewer queries than 3 a face the larger build did
#: not pay (5,000 points near the 40k faces 0.38 -> 0.49 s). The distances are the same,
#: exact; among exactly equidistant faces (a query at a vertex) another may be named
_NEEDLE_QUERIES = 3
NEEDLE_CELL_FACTOR = CELL_FACTOR / 3

#: a point with more pairs than this left within its bound after its first one
#: evaluates the one with the nearest centroid next (:func:`_crowded_next`)
_CROWDED = 16

#: a point whose probe lies farther than this many cells from it, and more than
#: ``_LOOSE_PROBE`` times farther than the probe's bound said, takes its ball from
#: the index's exact distance instead (:func:`_loose_probes`)
_FAR_ANSWER = 0.3
_LOOSE_PROBE = 2.0

#: references from which the four directions' rows are made on the worker threads
_THREADED_ROWS = 1 << 16

#: the float32 bound is loosened by this fraction of the grid's extent
_F32_EPS = 2.0 ** -16

#: grid cells of this many mean triangle extents (larger than the index's
#: default: the batched bound makes a reference cheap, a neighbour cell less so)
_CELL_FACTOR = 2.5

#: with ``reach`` (the queries' typical distance), cells are at least reach / this wide:
#: a 1M-point query of a 2M-face fine mesh (five levels) took 4.9 s with cells of 2.5
#: triangles (median distance 0.36 of a cell: many balls left the cells around their
#: own) and 2.0-2.6 s with the median at 0.11-0.22 of a cell
_REACH_SHARE = 0.15

#: smallest window widths; beyond the last, each class is twice the previous (a cell's
#: window is the narrowest class it fits: with 20, 28, 40 and 56 too, 9.6% fewer (point,
#: reference) pairs bounded and 3-5% less CPU time for 500k points near a 160k-face fine
#: surface, a third of them in cells of 33-48 references; classes every 4 gained no more)
_WIDTHS = (4, 8, 12, 16, 20, 24, 28, 32, 40, 48, 56, 64)


def _neighbour_offsets():
    """The 26 neighbour offsets (26, 3) and, for each, its cell's squared box
    distance as a sum of per-side terms: columns ``a, b, c`` of the (q, 7)
    table of squared distances to the 6 walls (column 6 is 0), so the box
    distance of neighbour k is ``W[:, a[k]] + W[:, b[k]] + W[:, c[k]]``.
    Wall ``2 axis + side`` (side 0: below, 1: above)."""
    walls = []
    for k in (1, 2, 3):
        for axes in itertools.combinations(range(3), k):
            for sides in itertools.product((0, 1), repeat=k):
                walls.append([2 * a + s for a, s in zip(axes, sides)] + [6] * (3 - k))
    walls = np.array(walls)
    off = np.zeros((26, 3), dtype=np.int64)
    for k, row in enumerate(walls):
        for wall in row[row < 6]:
            off[k, wall // 2] = 1 if wall % 2 else -1
    return off, walls[:, 0], walls[:, 1], walls[:, 2]


_OFFSETS, _WALL_A, _WALL_B, _WALL_C = _neighbour_offsets()


class _Tables(NamedTuple):
    """Everything the query reads, built once per :class:`NearQuery`."""

    lo: np.ndarray        #: (3,) grid origin
    h: float              #: cell size
    dims: np.ndarray      #: (3,) cells per axis
    eps: np.float32       #: float32 slack of the bound (absolute)
    box: np.ndarray       #: (2, 3) the box the float32 bound holds in (the grid's, grown by 4h)
    pdims: np.ndarray     #: (3,) cells per axis of the padded grid (one empty layer around)
    count: np.ndarray     #: (padded cells,) int64 references per cell
    start: np.ndarray     #: (padded cells,) int64 first reference of each cell
    offset: np.ndarray    #: (26,) int64 padded-id offsets of the 26 neighbours
    widths: np.ndarray    #: (k,) int64 window width classes
    tri: tuple            #: per width: (refs, W) windows of the referenced triangles
    lines: tuple          #: per width: 4 directions' (refs, 4, W) windows of [d, -(d.c) - o]
    tables: object        #: the index's IndexTables


class NearQuery:
    """Exact closest points on a triangle mesh for many queries near it.

    Builds a :class:`~.spatial.TriangleIndex` (cells of ``_CELL_FACTOR``
    mean triangle extents) and answers with the tiled search of the module
    docstring; far queries go to the index. A mesh of needles (its grid
    references each face more than ``_NEEDLES_PER_FACE`` times, and a cell
    more than ``_NEEDLES_CELL`` faces, on average: a CAD part's fans and
    strips) gets an index of the default cells instead, which answers every
    query (of a third of them for ``queries`` of at least
    ``_NEEDLE_QUERIES`` a face).

    Parameters
    ----------
    V : (n, 3) array_like of float
    F : (m, 3) array_like of int, m >= 1
    reach : float or None, keyword-only
        The typical (median) distance of the queries to come, if known:
        the cells are then at least ``reach / _REACH_SHARE`` wide, so that most
        balls stay in the cells around the point's own (the answers are
        the same; only the time changes).
    queries : int or None, keyword-only
        How many points it is to answer, if known (it sizes a mesh of
        needles' cells; the distances are the same either way).

    Attributes
    ----------
    index : TriangleIndex
        The index over ``(V, F)`` (also answers the far queries).

    Raises
    ------
    InvalidMeshError
        As :class:`~.spatial.TriangleIndex`.

    Examples
    --------
    >>> q = NearQuery([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]])
    >>> r = q.closest([[0.2, 0.2, 0.1]])
    >>> r.face.tolist(), r.bary.round(6).tolist()
    ([0], [[0.6, 0.2, 0.2]])
    """

    @plain_pages
    def __init__(self, V, F, *, reach=None, queries=None):
        if reach is not None and not (isinstance(reach, (int, float)) and 0 <= reach < np.inf):
            raise InvalidArgumentError(
                f"NearQuery: reach must be a finite number >= 0 or None, got {shown(reach)}")
        if queries is not None:
            queries = check_number(queries, where="NearQuery", name="queries (or None)", lo=0,
                                   integer=True)
        self.index = TriangleIndex(V, F, cell_factor=_CELL_FACTOR, min_cell=cell_for_reach(reach))
        self._t = None
        if needle_grid(self.index.tables):  # (the index's default cells suit it better)
            many = queries is not None and queries >= _NEEDLE_QUERIES * self.index.F.shape[0]
            self.index = TriangleIndex(V, F, min_cell=cell_for_reach(reach),
                                       cell_factor=NEEDLE_CELL_FACTOR if many else CELL_FACTOR)
        else:
            self._t = _build_tables(self.index.tables)
        self._index_cell = _INDEX_CELL * self.index.cell_growth ** 2

    def closest(self, P):
        """Closest point on the mesh of every query point.

        Parameters
        ----------
        P : (q, 3) array_like of float, finite.

        Returns
        -------
        ClosestPoints
            ``face`` (q,) int64, ``point`` (q,3), ``bary`` (q,3), ``distance``
            (q,): the exact closest points, as ``TriangleIndex.closest``;
            among exactly equidistant triangles the lowest face index (far
            queries, and every query of a mesh of needles: the one
            ``TriangleIndex.closest`` picks).

        Raises
        ------
        InvalidArgumentError
            P not (q,3) or not finite.
        """
        return self.index.with_outliers(_check_points(P), self._closest)

    def _closest(self, P):
        """:meth:`closest` among the faces of the index's grid (every face
        but a scan's spike's, ``spatial._OUTLIER_*``)."""
        T = self._t
        if T is None:                           # (a mesh of needles: needle_grid)
            return self.index.grid_closest(P)
        q = P.shape[0]
        cell3 = np.clip(np.floor((P - T.lo) / T.h), 0, T.dims - 1).astype(np.int64)
        key = cell3[:, 0] + T.dims[0] * (cell3[:, 1] + T.dims[1] * cell3[:, 2])
        # points in a crowded cell (see _INDEX_CELL) go to the index's
        # hierarchy: a cage of long thin triangles, a CAD cylinder's, made cells of thousands
        crowded, order, _ = self.index.split_crowded(key, limit=self._index_cell)
        best = BestPairs(q)
        far = [crowded]
        # (on the worker threads: each block writes its own points' rows of best)
        far += run_each(lambda s: _block(T, self.index, P, order[s:s + _BLOCK], cell3, best),
                        range(0, order.size, _BLOCK))
        far = np.concatenate(far)
        result = closest_result(T.tables.rows, T.tables.face, best.t, best.v, best.w, best.d2)
        if far.size:
            hit = self.index.grid_closest(P[far], crowded_cell=self._index_cell)
            for out, value in zip(result, hit):
                out[far] = value
        return result


def needle_grid(tables):
    """Whether the index's grid ``tables`` are those of a mesh of needles
    (``_NEEDLES_PER_FACE``, ``_NEEDLES_CELL``)."""
    count = np.diff(tables.cell_start)
    refs, faces, cells = tables.cell_tri.size, tables.face.size, int(np.count_nonzero(count))
    return refs > _NEEDLES_PER_FACE * faces and refs > _NEEDLES_CELL * cells


def search_for(V, F, n_queries, *, reach=None):
    """The closest-point search over ``(V, F)`` for ``n_queries`` points near
    it (the same exact distances either way), of the kind :func:`search_kind`
    names, its cells at least :func:`cell_for_reach` of ``reach`` (the
    queries' typical distance, when known) wide. Among exactly equidistant
    faces the two kinds may name different ones."""
    kind = search_kind(F.shape[0], n_queries)
    if kind is NearQuery:
        return NearQuery(V, F, reach=reach, queries=n_queries)
    return TriangleIndex(V, F, min_cell=cell_for_reach(reach))


def search_kind(n_faces, n_queries):
    """The closest-point search for ``n_queries`` points near a mesh of
    ``n_faces`` faces: :class:`NearQuery` when they are at least as many as
    the faces (its searches take about half the time: the bunny against a
    1,000-face cage 1.1-1.2 -> 0.54-0.59 s in ``surface_distance``), else a
    plain :class:`~.spatial.TriangleIndex` (a 1.1M-face scan against its
    10k-face cage, 205k queries on its side: the build is most of the time,
    and a NearQuery's takes 190 MiB more)."""
    return NearQuery if n_faces <= n_queries else TriangleIndex


def cell_for_reach(reach):
    """The smallest grid cell for queries at a typical distance ``reach``
    (``reach / _REACH_SHARE``; None for None or 0: the default cells), as
    :class:`~.spatial.TriangleIndex`'s ``min_cell``."""
    return reach / _REACH_SHARE if reach else None


def _check_points(P):
    """``P`` as a (q,3) float64 array; raises :class:`~.errors.InvalidArgumentError`
    naming the shape, or the first row that is not finite."""
    P = np.asarray(P, dtype=np.float64)
    if P.ndim != 2 or P.shape[1] != 3:
        raise InvalidArgumentError(
            f"NearQuery.closest: P must be (q,3) floats, got {P.shape} {P.dtype}")
    check_finite_rows(P, where="NearQuery.closest", what="query points")
    return P


# --- tables ------------------------------------------------------------------------------------

def _build_tables(tables):
    """The :class:`_Tables` of an index's :class:`~.spatial.IndexTables`: the
    padded cell grid, the windows of the references (triangles and the
    edge-line rows)."""
    lo, h, dims = tables.lo, float(tables.cell_size), tables.dims
    extent = float(np.abs(tables.hi - lo).max()) + 4.0 * h + float(tables.ball[3].max())
    count, start, pdims = _padded_grid(tables.cell_start, dims)
    widths = _width_classes(int(count.max()))
    pad = int(widths[-1])
    tri = np.concatenate([tables.cell_tri.astype(np.int64), np.zeros(pad, dtype=np.int64)])
    eps = np.float32(_F32_EPS * extent)
    lines = _line_rows(tables, tri[:tri.shape[0] - pad], pad, eps)
    offset = _OFFSETS[:, 0] + pdims[0] * (_OFFSETS[:, 1] + pdims[1] * _OFFSETS[:, 2])
    box = np.stack([lo - 4.0 * h, tables.hi + 4.0 * h])
    return _Tables(lo, h, dims, eps, box, pdims, count, start, offset,
                   widths, tuple(sliding_window_view(tri, int(W)) for W in widths),
                   tuple(tuple(sliding_window_view(r, int(W), axis=0) for r in lines)
                         for W in widths), tables)


def _line_rows(tables, tri, pad, eps):
    """Per reference (cell-major, then ``pad`` padding entries) and for each of
    the edge-line bound's four directions d (normal, three edge normals): the
    rows [d_x, d_y, d_z, -(d.c) - o] (c the centroid relative to the origin, o
    the edge's offset less the slack ``eps``, 0 for the normal), float32
    (refs + pad, 4) (a reference's four values together: the table is one
    gather of 16-byte rows, 4-6x faster than four of floats, and a tile
    reads its windows as it multiplies them), so that [x, y, z, 1] times them is the signed height /
    the edge-line excess less eps of the point x (relative to the origin).
    Padding rows give +inf."""
    P = tables.prism
    c = tables.ball[:3] - tables.lo[:, None]

    def rows(direction):
        d, off = direction
        per_face = np.empty((d.shape[1], 4), dtype=np.float32)
        per_face[:, :3] = d.T
        per_face[:, 3] = -np.einsum("ij,ij->j", d, c) - off
        out = np.empty((tri.shape[0] + pad, 4), dtype=np.float32)
        # ("wrap": the indices are in range, and "raise" buffers an out: 3.5x the time)
        np.take(per_face, tri, axis=0, out=out[:tri.shape[0]], mode="wrap")
        out[tri.shape[0]:] = (0.0, 0.0, 0.0, np.inf)
        return out
    return run_each(rows, [(P[0:3], 0.0), (P[3:6], P[12] + eps), (P[6:9], P[13] + eps),
                           (P[9:12], P[14] + eps)], threads=tri.shape[0] >= _THREADED_ROWS)


def _padded_grid(cell_start, dims):
    """Reference counts and starts on the grid padded with one empty layer of
    cells on every side (so every neighbour of a real cell has an id):
    (count, start, padded dims)."""
    pdims = dims + 2
    shape = (int(dims[2]), int(dims[1]), int(dims[0]))
    count = np.zeros((pdims[2], pdims[1], pdims[0]), dtype=np.int64)
    start = np.zeros_like(count)
    count[1:-1, 1:-1, 1:-1] = np.diff(cell_start).reshape(shape)
    start[1:-1, 1:-1, 1:-1] = cell_start[:-1].reshape(shape)
    return count.ravel(), start.ravel(), pdims


def _width_classes(most):
    """Window widths: ``_WIDTHS`` then doubling, up to the first >= ``most``."""
    widths = list(_WIDTHS)
    while widths[-1] < most:
        widths.append(2 * widths[-1])
    widths = np.array(widths, dtype=np.int64)
    return widths[:int(np.searchsorted(widths, most)) + 1]


# --- one block -----------------------------------------------------------------------------------

class _Block(NamedTuple):
    """A block of points: their rows of P, coordinates, own cell (grid
    coordinates and padded id), position inside the own cell, probe cell."""

    q: np.ndarray       #: (k,) rows of P
    X: np.ndarray       #: (3, k) float64 coordinates
    A: np.ndarray       #: (k, 4) float32 [x, y, z, 1], x relative to the grid origin
    cell3: np.ndarray   #: (k, 3) own cell
    own: np.ndarray     #: (k,) padded id of the own cell
    wall: np.ndarray    #: (3, k) position inside the own cell, 0..h (outside for clipped points)
    probe: np.ndarray   #: (k,) padded id of the probe cell


def _block(T, index, P, q, cell3, best, known=None):
    """Answer the points ``q`` (rows of ``P``) into ``best``; returns the rows
    left for ``TriangleIndex.closest``. ``known`` (len(P),), when given: the
    index's exact distance of the loose probes among them (NaN elsewhere;
    a crowded block's halves are told what the whole block asked for)."""
    B, lost = _start_block(T, P, q, cell3)
    n = B.q.shape[0]
    tiles, t0, lb0 = _probe(T, B)
    v0, w0, d0 = _kernel(T, B.X, np.arange(n), t0)
    u2 = np.square(_bound32(T, d0))
    reach = np.sqrt(d0)
    loose = _loose_probes(T, d0, lb0)
    if loose.any():                   # their ball from the index's exact distance
        reach[loose] = _loose_reach(index, B, loose, known)
        u2[loose] = np.square(_bound32(T, np.square(reach[loose])))
    owner_a, tri_a, lb_a = _within(tiles, np.arange(n), u2)
    point_b, cell_b, far = _neighbour_cells(T, B, reach)
    owner_b, tri_b, lb_b = _within(_tiles(T, B.A, point_b, cell_b, once=True), point_b, u2)
    if owner_a.size + owner_b.size > _CROWDED_BLOCK * n and n > _MIN_BLOCK:
        # hundreds of pairs a point: halves, whose arrays stay in cache (a point's
        # answer does not depend on its block)
        half = B.q.shape[0] // 2
        if loose.any():
            if known is None:
                known = np.full(P.shape[0], np.nan)
            known[B.q[loose]] = reach[loose]
        return np.concatenate([lost, _block(T, index, P, B.q[:half], cell3, best, known),
                               _block(T, index, P, B.q[half:], cell3, best, known)])
    owner = np.concatenate([owner_a, owner_b])
    tri = np.concatenate([tri_a, tri_b])
    # a triangle is referenced in every cell it crosses, and windows overlap the
    # next cells: the probe and other pairs come again, evaluated once only
    again = np.flatnonzero(tri != t0[owner])
    owner, tri, lb = owner[again], tri[again], np.concatenate([lb_a, lb_b])[again]
    _raise_for_needles(index, B.X, owner, tri, lb)
    # the pair with the smallest bound of each point first: usually the closest,
    # so the bound it gives leaves few of the others
    first = _lowest_per_point(owner, lb, n)
    t, v, w, d2 = _fold(T, B.X, owner[first], tri[first], t0, v0, w0, d0)
    done = t0.copy()
    done[owner[first]] = tri[first]
    rest = lb <= np.square(_bound32(T, d2)[owner])
    rest &= tri != done[owner]
    t, v, w, d2, rest = _crowded_next(T, B.X, owner, tri, lb, rest, (t, v, w, d2))
    t, v, w, d2 = _fold(T, B.X, owner[rest], tri[rest], t, v, w, d2)
    best.put(B.q, t, v, w, d2)
    return np.concatenate([lost, B.q[far]])


def _raise_for_needles(index, X, owner, tri, lb):
    """Raise the float32 bounds ``lb`` of the pairs (points ``owner`` of
    ``X``, triangles ``tri``), in place, to the index's capsule bound where
    the triangle is a needle (:meth:`~.spatial.TriangleIndex.needle_bounds`,
    rounded down): a thin triangle has no plane and its edge lines are
    zero rows here, so its tile bound is 0 wherever the point is; a CAD
    cylinder's sides and its cage are all such needles."""
    j, cap = index.needle_bounds(X, owner, tri)
    if j.size:
        cap = cap.astype(np.float32)
        cap *= np.float32(1.0 - 2.0 ** -20)            # (rounded to float32: kept below)
        lb[j] = np.maximum(lb[j], cap)


def _loose_reach(index, B, loose, known):
    """The index's exact distance of the block ``B``'s ``loose`` probes: from
    ``known`` (see :func:`_block`) where it has one, else asked (a point's
    probe, and so whether it is loose, does not depend on its block)."""
    rows = B.q[loose]
    reach = np.full(rows.shape[0], np.nan) if known is None else known[rows]
    ask = np.isnan(reach)
    if ask.any():
        reach[ask] = index.closest(B.X[:, np.flatnonzero(loose)[ask]].T).distance
    return reach


def _crowded_next(T, X, owner, tri, lb, rest, current):
    """Where a point still has more than ``_CROWDED`` pairs within its bound
    (the ``rest`` of the pairs ``owner``, ``tri`` with bounds ``lb``), the
    pair with the nearest centroid among them is evaluated next and the
    others are held to the bound it gives. Near a triangle's sharp corner
    the edge lines nearly meet, and their bound stays near 0 far beyond it:
    a cage with model-long slivers (a pinched scan) left points whose
    smallest bound was a triangle 35 times farther than the closest, with
    hundreds of pairs each. ``current``: (t, v, w, d2); returns them updated
    and the pairs left."""
    t, v, w, d2 = current
    left = np.flatnonzero(rest)
    crowded = np.bincount(owner[left], minlength=d2.shape[0]) > _CROWDED
    sel = left[crowded[owner[left]]]
    if sel.size == 0:
        return t, v, w, d2, rest
    D = np.take(X, owner[sel], axis=1)
    D -= np.take(T.tables.ball[:3], tri[sel], axis=1)
    near = (D[0] * D[0] + D[1] * D[1] + D[2] * D[2]).astype(np.float32)
    pick = sel[_lowest_per_point(owner[sel], near, d2.shape[0])]
    t, v, w, d2 = _fold(T, X, owner[pick], tri[pick], t, v, w, d2)
    rest = rest.copy()
    rest[pick] = False
    rest &= lb <= np.square(_bound32(T, d2)[owner])
    return t, v, w, d2, rest


def _bound32(T, d2):
    """float32 distance bounds from exact squared distances: never below the
    distance, loosened by ``eps``."""
    return (np.sqrt(d2) * (1 + 1e-6)).astype(np.float32) + T.eps


def _lowest_per_point(owner, value, n):
    """Index of the pair with the smallest ``value`` (float32 >= 0) of each
    point that has one (the first among equal ones)."""
    if owner.size == 0:
        return owner
    key = value.view(np.int32).astype(np.int64) << 32
    key |= np.arange(owner.shape[0], dtype=np.int64)
    low = np.full(n, np.iinfo(np.int64).max)
    np.minimum.at(low, owner, key)
    return low[low != np.iinfo(np.int64).max] & 0xFFFFFFFF


def _start_block(T, P, q, cell3):
    """The :class:`_Block` of the points ``q``, and the points left for the
    index: those with no non-empty cell among their own and its 26
    neighbours, and those outside ``T.box`` (where the float32 rounding of
    the bound could exceed its slack)."""
    g = cell3[q]
    own = (g[:, 0] + 1) + T.pdims[0] * ((g[:, 1] + 1) + T.pdims[1] * (g[:, 2] + 1))
    X = np.ascontiguousarray(P[q].T)
    wall = X - T.lo[:, None] - g.T * T.h
    probe = own.copy()
    empty = np.flatnonzero(T.count[own] == 0)
    if empty.size:
        probe[empty] = _nearest_filled(T, own[empty], wall[:, empty])
    ok = probe >= 0
    ok &= ((X >= T.box[0][:, None]) & (X <= T.box[1][:, None])).all(axis=0)
    lost = q[~ok]
    if lost.size:
        q, X, g, own, wall, probe = q[ok], X[:, ok], g[ok], own[ok], wall[:, ok], probe[ok]
    A = np.ones((q.shape[0], 4), dtype=np.float32)
    A[:, :3] = (X - T.lo[:, None]).T
    return _Block(q, X, A, g, own, wall, probe), lost


def _nearest_filled(T, own, wall):
    """For points whose own cell is empty: the padded id of the nearest
    non-empty neighbour (box distance; the lowest neighbour number among equal
    ones), -1 where all 26 are empty."""
    d2 = _wall_distances(T, wall)
    box = d2[:, _WALL_A] + d2[:, _WALL_B] + d2[:, _WALL_C]
    cells = own[:, None] + T.offset
    box[T.count[cells] == 0] = np.inf
    k = np.argmin(box, axis=1)
    found = np.isfinite(box[np.arange(k.shape[0]), k])
    return np.where(found, cells[np.arange(k.shape[0]), k], -1)


def _wall_distances(T, wall):
    """(k, 7) float64 squared distances from each point to the 6 walls of its
    own cell (0 where it is beyond the wall), column 6 zero."""
    d2 = np.zeros((wall.shape[1], 7))
    for axis in range(3):
        d2[:, 2 * axis] = np.square(np.maximum(wall[axis], 0.0))
        d2[:, 2 * axis + 1] = np.square(np.maximum(T.h - wall[axis], 0.0))
    return d2


# --- tiles ---------------------------------------------------------------------------------------

class _Tile(NamedTuple):
    """One set of tiles of one window width: tiles ``first .. first + t`` of
    their :class:`_Tiles`, the cells' windows of triangles, and the bound of
    every (row, window entry)."""

    first: int          #: the set's first tile
    tri: np.ndarray     #: (t, W) internal triangles of the cells' windows
    lb: np.ndarray      #: (t, _TILE, W) float32 squared edge-line bound (less eps)


class _Tiles(NamedTuple):
    """Rows grouped in tiles of up to ``_TILE`` rows that share a cell, the
    tiles ordered by window width and cut into :class:`_Tile` sets."""

    rows: np.ndarray    #: (tiles, _TILE) rows of the tiled set (a short tile repeats its last row)
    valid: np.ndarray   #: (tiles, _TILE) bool, False for the repeats
    sets: object        #: the :class:`_Tile` sets, in tile order (a list, or an iterator)


def _tiles(T, A, point, cell, once=False):
    """The rows ``(point[i], cell[i])`` grouped by cell into :class:`_Tiles`,
    the tiles cut into sets of one window width class; ``A`` (k, 4) the
    points' [x, y, z, 1]. The index work is done once for all tiles (a set
    only slices it): fewer, larger NumPy calls. With ``once`` (tiles read
    once), ``sets`` is an iterator that makes each set as it is read: one
    set's bounds in memory at a time, not all of them (a 65,536-point block
    of a five-level bind held tens of MB of them, fresh pages every block)."""
    if point.size == 0:
        return _Tiles(np.zeros((0, _TILE), dtype=np.int64), np.zeros((0, _TILE), dtype=bool), [])
    order = np.argsort(cell, kind="stable")          # cells come in sorted runs: stable is fast
    cs = cell[order]
    first = np.flatnonzero(np.concatenate([[True], cs[1:] != cs[:-1]]))
    size = np.diff(np.concatenate([first, [cs.shape[0]]]))
    per = -(-size // _TILE)
    group = np.repeat(np.arange(first.shape[0]), per)
    k = np.arange(group.shape[0]) - np.repeat(np.cumsum(per) - per, per)
    begin = first[group] + _TILE * k
    length = np.minimum(_TILE, size[group] - _TILE * k)
    cls = np.searchsorted(T.widths, T.count[cs[begin]]).astype(np.int16)
    by_class = np.argsort(cls, kind="stable")
    begin, length, cls = begin[by_class], length[by_class], cls[by_class]
    lane = np.arange(_TILE)
    rows = order[begin[:, None] + np.minimum(lane, length[:, None] - 1)]
    start = T.start[cs[begin]]
    Arows = A[point[rows]]
    cuts = np.flatnonzero(np.concatenate([[True], np.diff(cls) != 0, [True]]))
    # at most _TILE_SLOTS (row, reference) pairs per set: its arrays stay in cache
    cuts = sorted_unique(np.concatenate([cuts] + [np.arange(a, b, max(1, _TILE_SLOTS // (
        _TILE * int(T.widths[cls[a]])))) for a, b in zip(cuts[:-1], cuts[1:])]))
    sets = _tile_sets(T, Arows, cls, start, cuts)
    return _Tiles(rows, lane < length[:, None], sets if once else list(sets))


def _tile_sets(T, Arows, cls, start, cuts):
    """Yield the :class:`_Tile` sets between the ``cuts`` (tile indices),
    each made when asked for."""
    for a, b in zip(cuts[:-1].tolist(), cuts[1:].tolist()):
        c, s = int(cls[a]), start[a:b]
        yield _Tile(a, T.tri[c][s], _edge_line_bound(T, Arows[a:b], s, c))


def _edge_line_bound(T, A, s, c):
    """(t, _TILE, W) float32 squared edge-line bound of the tile rows' points
    ``A`` (t, _TILE, 4) to the references of the windows at ``s`` (width class
    ``c``): max(|height| - eps, 0)^2 + max(max_k excess_k - eps, 0)^2, the
    height and the three edge-line excesses each one batched product."""
    height, *excess = (np.matmul(A, line[s]) for line in T.lines[c])
    np.abs(height, out=height)
    height -= T.eps
    lateral = excess[0]                                     # the excesses come less eps
    np.maximum(lateral, excess[1], out=lateral)
    np.maximum(lateral, excess[2], out=lateral)
    for part in (height, lateral):
        np.maximum(part, 0.0, out=part)
        part *= part
    height += lateral
    return height


def _probe(T, B):
    """Phase A: the tiles of the probe cells and, per point, the triangle of
    the smallest bound in its probe cell's window (the bound's float32 bits
    with the column in the lowest ones, one minimum: about twice as fast as
    an argmin over the last axis; which of two nearly equal bounds wins does
    not matter, any probe gives the same answer)."""
    n = B.q.shape[0]
    tiles = _tiles(T, B.A, np.arange(n), B.probe)
    best = [np.zeros((0, _TILE), dtype=np.int64)]
    bound = [np.zeros((0, _TILE), dtype=np.int32)]
    for tile in tiles.sets:
        W = tile.lb.shape[2]
        low = (1 << max(1, (W - 1).bit_length())) - 1
        key = tile.lb.view(np.int32) & np.int32(~low)         # bounds are >= 0: bits sort as values
        key |= np.arange(W, dtype=np.int32)
        key = np.minimum.reduce(key, axis=2)
        best.append(np.take_along_axis(tile.tri, key & low, axis=1))
        bound.append(key & np.int32(~low))
    t0 = np.empty(n, dtype=np.int64)
    lb0 = np.empty(n, dtype=np.float32)
    valid = tiles.valid
    t0[tiles.rows[valid]] = np.concatenate(best)[valid]
    lb0[tiles.rows[valid]] = np.concatenate(bound)[valid].view(np.float32)
    return tiles, t0, lb0


def _loose_probes(T, d0, lb0):
    """The points whose probe (at squared distance ``d0``, bound ``lb0``,
    its float32 bits truncated: never above the bound) lies more than
    ``_FAR_ANSWER`` cells away and more than ``_LOOSE_PROBE`` times farther
    than its bound said: past the sharp corner of a long sliver, whose edge
    lines nearly meet, the bound stays near 0 far beyond the triangle, and
    the smallest bound of the probe cell can be such a sliver far from a
    point lying on another face. The ball that probe gives holds hundreds of
    pairs a point (a cage with 20 model-long slivers of a pinched scan: 590
    a point, 16x the time of the index's search of the same points), so
    their ball comes from the index's exact distance instead (the pairs in
    it still decide the answer: the lowest face index among equal ones)."""
    loose = d0 > np.square(_FAR_ANSWER * T.h)
    loose &= d0 > _LOOSE_PROBE ** 2 * lb0.astype(np.float64)
    return loose


def _within(tiles, who, u2):
    """(owner, triangle, bound) of the tile pairs whose bound is within the
    rows' ``u2``; ``who`` maps tile rows to points."""
    pts = who[tiles.rows]
    bound = np.where(tiles.valid, u2[pts], np.float32(-1.0))[:, :, None]   # repeats: none pass
    owners = [np.zeros(0, dtype=np.int64)]
    tris = [np.zeros(0, dtype=np.int64)]
    lbs = [np.zeros(0, dtype=np.float32)]
    for tile in tiles.sets:
        t, _, W = tile.lb.shape
        flat = np.flatnonzero(tile.lb <= bound[tile.first:tile.first + t])
        i, rest = np.divmod(flat, _TILE * W)
        j, col = np.divmod(rest, W)
        owners.append(pts[i + tile.first, j])
        tris.append(tile.tri[i, col])
        lbs.append(tile.lb.reshape(-1)[flat])
    return np.concatenate(owners), np.concatenate(tris), np.concatenate(lbs)


# --- neighbours, exact evaluation ------------------------------------------------------------

def _neighbour_cells(T, B, u):
    """Phase B's cells: (point, padded cell) pairs for every non-empty cell of
    the 3x3x3 block around the own cell within ``u`` (box distance) of the
    point, other than the probe cell; and the mask of points whose ball
    leaves that block (answered by the index instead). The 6 face neighbours
    from one test per wall; the 20 edge and corner ones only for the points
    whose ball crosses two walls or more."""
    ub = u * (1 + 4 * PRUNE_SLACK)
    u2 = ub * ub
    far = ub >= _block_clearance(T, B)
    d2 = np.empty((7, B.q.shape[0]))                # squared distance to each wall, then 0
    d2[0:6:2] = np.square(np.maximum(B.wall, 0.0))
    d2[1:6:2] = np.square(np.maximum(T.h - B.wall, 0.0))
    d2[6] = 0.0
    crossed = d2[:6] <= u2
    crossed &= ~far
    points, ks = [], []
    for wall in range(6):                           # face neighbour k = wall k
        p = np.flatnonzero(crossed[wall])
        points.append(p)
        ks.append(np.full(p.shape[0], wall))
    sel = np.flatnonzero(crossed.sum(axis=0) >= 2)
    if sel.size:
        D = d2[:, sel]
        need = (D[_WALL_A[6:]] + D[_WALL_B[6:]] + D[_WALL_C[6:]]) <= u2[sel]     # (20, s)
        flat = np.flatnonzero(need)
        k, i = np.divmod(flat, sel.shape[0])
        points.append(sel[i])
        ks.append(k + 6)
    point, k = np.concatenate(points), np.concatenate(ks)
    cell = B.own[point] + T.offset[k]
    keep = (T.count[cell] > 0) & (cell != B.probe[point])
    return point[keep], cell[keep], far


def _block_clearance(T, B):
    """Distance from each point to the boundary of the 3x3x3 block of cells
    around its own cell, sides on the grid's border excepted (nothing lies
    beyond them)."""
    out = np.full(B.q.shape[0], np.inf)
    for axis in range(3):
        g, wall = B.cell3[:, axis], B.wall[axis]
        np.minimum(out, np.where(g > 0, wall + T.h, np.inf), out=out)
        np.minimum(out, np.where(g < T.dims[axis] - 1, 2 * T.h - wall, np.inf), out=out)
    return out


def _kernel(T, X, owner, t):
    """The exact kernel (v, w, d2) on the pairs (points ``owner`` of X, triangles t),
    in blocks (:func:`~.spatial.closest_pairs`: a fine surface with model-long
    slivers gave 5.5M pairs in one block of a bind, 17 s when evaluated at once)."""
    return closest_pairs(X, owner, T.tables.rows, t)


def _fold(T, X, owner, t, t0, v0, w0, d0):
    """Evaluate the pairs left and fold them into the current best: per point
    the smallest squared distance, among equal ones the lowest face index."""
    if owner.size == 0:
        return t0, v0, w0, d0
    v, w, d2 = _kernel(T, X, owner, t)
    keep = d2 <= d0[owner]
    owner, t, v, w, d2 = owner[keep], t[keep], v[keep], w[keep], d2[keep]
    if owner.size == 0:
        return t0, v0, w0, d0
    best = d0.copy()
    np.minimum.at(best, owner, d2)
    face = T.tables.face
    low = np.where(best == d0, face[t0], np.iinfo(np.int64).max)
    tie = d2 == best[owner]
    np.minimum.at(low, owner[tie], face[t[tie]])
    win = tie & (face[t] == low[owner])
    t_out, v_out, w_out = t0.copy(), v0.copy(), w0.copy()
    i = owner[win]
    t_out[i], v_out[i], w_out[i] = t[win], v[win], w[win]
    return t_out, v_out, w_out, best
