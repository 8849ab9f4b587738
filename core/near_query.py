"""Exact closest points of many query points near a triangle mesh (the bind's query).

:class:`~.spatial.TriangleIndex` answers "closest point on the mesh" exactly
for any query; binding a scan asks it for a million points that all lie
within a fraction of a face of the surface, and there most of its time goes
into choosing candidates. :class:`NearQuery` keeps its grid, its bounds and
its exact kernel, and reorganises the candidate search so that nearly all of
it runs on fixed-width float32 tables, a block of points at a time::

    probe cell   the point's own cell, or when that is empty the nearest
                 non-empty one of its 26 neighbours (box distance)
    phase A      squared distance to the centroid of every reference of the
                 probe cell; the nearest centroid is the probe, evaluated
                 exactly -> u (an exact upper bound)
    phase B      every other cell within u of the point (box distance)
    filters      sphere (|p - c| <= u + r) on every pair of A and B, then the
                 edge-line bound (height above the plane, lateral distance
                 beyond the edge lines; ``spatial``'s docstring) on the pairs
                 left, both in float32
    exact        the kernel on the pairs left (float64); the smallest squared
                 distance wins, exact ties go to the lowest face index

Windows: the references of cell ``c`` are a run of the cell-ordered table,
``ref[start[c] : start[c] + count[c]]``. A point's candidates are the row
``ref[start[c] : start[c] + W]`` for the width class ``W >= count[c]`` (one
fancy-indexed row of a ``sliding_window_view``, no ragged expansion); its
entries past ``count[c]`` belong to the next cells, so a row holds more
candidates than the cell, never fewer (the table ends in ``W`` padding
entries that never pass a filter). Rows are bucketed by width class.

Float32: coordinates are taken relative to the grid's origin, and every
bound is loosened by ``eps = 2**-16`` of the grid's extent (the float32
rounding of the quantities involved is below ``2**-21`` of it), so a filter
can keep a pair the float64 bound would drop, never drop one it keeps: the
result is the exact closest point, the same as ``TriangleIndex.closest``
except among exactly equidistant triangles.

Every point's result depends on the point alone (not on the block, the
order or the thread), so the answer is the same for any block size and
thread count. Points whose ball around the probe leaves the 3x3x3 block of
cells around their own cell (far from the surface), or that have no
non-empty cell in that block, are answered by ``TriangleIndex.closest``.
"""

import itertools
from typing import NamedTuple

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

from .errors import InvalidArgumentError
from .spatial import TriangleIndex, closest_on_triangles, closest_result

__all__ = ["NearQuery"]

#: points per block (float32 temporaries of a few hundred KiB)
_BLOCK = 8192

#: float32 filters are loosened by this fraction of the grid's extent
_F32_EPS = 2.0 ** -16


#: relative slack on the float64 cell tests (as ``spatial``'s)
_SLACK = 1e-9

#: smallest window widths; beyond the last, each class is twice the previous
_WIDTHS = (4, 8, 12, 16, 24, 32, 48, 64)


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
    eps: np.float32       #: float32 slack of the bounds (absolute)
    pdims: np.ndarray     #: (3,) cells per axis of the padded grid (one empty layer around)
    count: np.ndarray     #: (padded cells,) int64 references per cell
    start: np.ndarray     #: (padded cells,) int64 first reference of each cell
    offset: np.ndarray    #: (26,) int64 padded-id offsets of the 26 neighbours
    widths: np.ndarray    #: (k,) int64 window width classes
    ref: tuple            #: per width: (refs, W) windows of the references' cx, cy, cz, r
    ref_tri: np.ndarray   #: (refs + W,) int64 triangle of each reference (padding 0)
    centre: np.ndarray    #: (3, m) float32 centroids relative to lo
    prism: np.ndarray     #: (15, m) float32 edge-line bound rows
    rows: tuple           #: 16 (m,) float64 rows of the exact kernel
    tables: object        #: the index's IndexTables


class NearQuery:
    """Exact closest points on a triangle mesh for many queries near it.

    Builds a :class:`~.spatial.TriangleIndex` and answers with the float32
    window search of the module docstring; far queries go to the index.

    Parameters
    ----------
    V : (n, 3) array_like of float
    F : (m, 3) array_like of int, m >= 1

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

    def __init__(self, V, F):
        self.index = TriangleIndex(V, F)
        self._t = _build_tables(self.index.tables)

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
            queries: the one ``TriangleIndex.closest`` picks).

        Raises
        ------
        InvalidArgumentError
            P not (q,3) or not finite.
        """
        P = _check_points(P)
        T = self._t
        q = P.shape[0]
        cell3 = np.clip(np.floor((P - T.lo) / T.h), 0, T.dims - 1).astype(np.int64)
        order = np.argsort(cell3[:, 0] + T.dims[0] * (cell3[:, 1] + T.dims[1] * cell3[:, 2]))
        best = _Best.empty(q)
        far = [_block(T, P, order[s:s + _BLOCK], cell3, best) for s in range(0, q, _BLOCK)]
        far = np.concatenate(far) if far else np.zeros(0, dtype=np.int64)
        result = closest_result(T.tables, best.t, best.v, best.w, best.d2)
        if far.size:
            hit = self.index.closest(P[far])
            for out, value in zip(result, hit):
                out[far] = value
        return result


def _check_points(P):
    P = np.asarray(P, dtype=np.float64)
    if P.ndim != 2 or P.shape[1] != 3:
        raise InvalidArgumentError(
            f"NearQuery.closest: P must be (q,3) floats, got {P.shape} {P.dtype}")
    bad = ~np.isfinite(P).all(axis=1)
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        raise InvalidArgumentError(
            f"NearQuery.closest: {int(bad.sum())} query points have NaN or infinite "
            f"coordinates, e.g. point {k} = {P[k].tolist()}")
    return P


class _Best(NamedTuple):
    """Per query: internal triangle, kernel (v, w) and squared distance."""

    t: np.ndarray
    v: np.ndarray
    w: np.ndarray
    d2: np.ndarray

    @classmethod
    def empty(cls, q):
        return cls(np.zeros(q, dtype=np.int64), np.zeros(q), np.zeros(q), np.zeros(q))


# --- tables ------------------------------------------------------------------------------------

def _build_tables(tables):
    """The :class:`_Tables` of an index's :class:`~.spatial.IndexTables`: the
    padded cell grid, the window tables of the references (float32 centroid
    relative to the origin, radius plus eps; padding entries never pass a
    filter), the float32 edge-line rows and the kernel rows."""
    lo, h, dims = tables.lo, float(tables.cell_size), tables.dims
    extent = float(np.abs(tables.hi - lo).max()) + 4.0 * h + float(tables.ball[3].max())
    eps = np.float32(_F32_EPS * extent)
    count, start, pdims = _padded_grid(tables.cell_start, dims)
    widths = _width_classes(int(count.max()))
    centre = np.ascontiguousarray((tables.ball[:3] - lo[:, None]).astype(np.float32))
    radius = tables.ball[3].astype(np.float32) + eps
    tri = tables.cell_tri.astype(np.int64)
    pad = int(widths[-1])
    ref = []
    for values, fill in ((centre[0], np.inf), (centre[1], np.inf), (centre[2], np.inf),
                         (radius, 0.0)):
        run = np.full(tri.shape[0] + pad, fill, dtype=np.float32)
        np.take(values, tri, out=run[:tri.shape[0]])
        ref.append(run)
    windows = tuple(tuple(sliding_window_view(run, int(W)) for run in ref) for W in widths)
    offset = _OFFSETS[:, 0] + pdims[0] * (_OFFSETS[:, 1] + pdims[1] * _OFFSETS[:, 2])
    return _Tables(lo, h, dims, eps, pdims, count, start, offset, widths, windows,
                   np.concatenate([tri, np.zeros(pad, dtype=np.int64)]), centre,
                   np.ascontiguousarray(tables.prism[:15].astype(np.float32)),
                   tuple(np.ascontiguousarray(r) for r in tables.rows), tables)


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
    """A block of points: their rows of P, float32 offsets from the origin,
    own cell (grid coordinates and padded id), position inside the own cell,
    and the probe cell (padded id)."""

    q: np.ndarray       #: (k,) rows of P
    X: np.ndarray       #: (3, k) float64 coordinates
    x32: np.ndarray     #: (3, k) float32, relative to the grid origin
    cell3: np.ndarray   #: (k, 3) own cell
    own: np.ndarray     #: (k,) padded id of the own cell
    wall: np.ndarray    #: (3, k) position inside the own cell, 0..h (outside for clipped points)
    probe: np.ndarray   #: (k,) padded id of the probe cell


def _block(T, P, q, cell3, best):
    """Answer the points ``q`` (rows of ``P``) into ``best``; returns the rows
    left for ``TriangleIndex.closest``."""
    B, lost = _start_block(T, P, q, cell3)
    t0, v0, w0, d0, stored = _probe(T, B)
    u32 = _bound32(T, d0)
    owner_a, tri_a = _probe_cell_survivors(T, stored, u32)
    point_b, cell_b, far = _neighbour_cells(T, B, np.sqrt(d0))
    owner_b, tri_b = _window_survivors(T, B.x32, point_b, cell_b, u32)
    owner = np.concatenate([owner_a, owner_b])
    tri = np.concatenate([tri_a, tri_b])
    lb = _edge_line_bound(T, B.x32, owner, tri)
    keep = np.flatnonzero(lb <= np.square(u32[owner]))
    owner, tri, lb = owner[keep], tri[keep], lb[keep]
    # the pair with the smallest bound of each point first: usually the closest,
    # so the bound it gives leaves few of the others
    first = _lowest_per_point(owner, lb, d0.shape[0])
    t, v, w, d2 = _fold(T, B.X, owner[first], tri[first], t0, v0, w0, d0)
    rest = np.ones(owner.shape[0], dtype=bool)
    rest[first] = False
    rest &= lb <= np.square(_bound32(T, d2)[owner])
    t, v, w, d2 = _fold(T, B.X, owner[rest], tri[rest], t, v, w, d2)
    best.t[B.q], best.v[B.q], best.w[B.q], best.d2[B.q] = t, v, w, d2
    return np.concatenate([lost, B.q[far]])


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
    """The :class:`_Block` of the points ``q``, and the points with no
    non-empty cell among their own and its 26 neighbours."""
    g = cell3[q]
    own = (g[:, 0] + 1) + T.pdims[0] * ((g[:, 1] + 1) + T.pdims[1] * (g[:, 2] + 1))
    X = np.ascontiguousarray(P[q].T)
    wall = X - T.lo[:, None] - g.T * T.h
    probe = own.copy()
    empty = np.flatnonzero(T.count[own] == 0)
    if empty.size:
        probe[empty] = _nearest_filled(T, own[empty], wall[:, empty])
    ok = probe >= 0
    lost = q[~ok]
    if lost.size:
        q, X, g, own, wall, probe = q[ok], X[:, ok], g[ok], own[ok], wall[:, ok], probe[ok]
    x32 = (X - T.lo[:, None]).astype(np.float32)
    return _Block(q, X, x32, g, own, wall, probe), lost


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


def _classes(T, counts):
    """Rows bucketed by window width class: (order, [(lo, hi, class index)])
    such that ``order[lo:hi]`` are the rows of one class."""
    cls = np.searchsorted(T.widths, counts).astype(np.int16)
    order = np.argsort(cls, kind="stable")
    if order.size == 0:
        return order, []
    cls = cls[order]
    cuts = np.flatnonzero(np.concatenate([[True], cls[1:] != cls[:-1], [True]]))
    return order, [(a, b, int(cls[a])) for a, b in zip(cuts[:-1], cuts[1:])]


def _where2(mask):
    """Row and column indices of the True entries of a 2-D mask, row-major
    (``np.nonzero``, about 2.5x faster through the flat indices)."""
    flat = np.flatnonzero(mask)
    row = flat // mask.shape[1]
    return row, flat - row * mask.shape[1]


def _centre_d2(windows, s, x32, rows):
    """(k, W) float32 squared distances from the points ``rows`` to the
    centroids of the window rows starting at references ``s``."""
    d = windows[0][s]
    d -= x32[0, rows, None]
    dc2 = d * d
    for axis in (1, 2):
        d = windows[axis][s]
        d -= x32[axis, rows, None]
        d *= d
        dc2 += d
    return dc2


def _probe(T, B):
    """Phase A: per point, the nearest centroid among the references of its
    probe cell's window, evaluated exactly. Returns the probe (t, v, w, d2)
    and, per width class, (rows, starts, dc2, chosen column, radii) for the
    sphere filter once the bound is known."""
    count = T.count[B.probe]
    starts = T.start[B.probe]
    order, classes = _classes(T, count)
    t0 = np.empty(count.shape[0], dtype=np.int64)
    stored = []
    for lo, hi, c in classes:
        rows = order[lo:hi]
        s = starts[rows]
        dc2 = _centre_d2(T.ref[c], s, B.x32, rows)
        col = np.argmin(dc2, axis=1)
        t0[rows] = T.ref_tri[s + col]
        stored.append((rows, s, dc2, col, T.ref[c][3]))
    v0, w0, d0 = _kernel(T, B.X, np.arange(count.shape[0]), t0)
    return t0, v0, w0, d0, stored


def _probe_cell_survivors(T, stored, u32):
    """Phase A's pairs (point, triangle) within the sphere bound ``u32`` of
    each point (the probe itself left out)."""
    owners, tris = [np.zeros(0, dtype=np.int64)], [np.zeros(0, dtype=np.int64)]
    for rows, s, dc2, col, radius in stored:
        reach = radius[s]
        reach += u32[rows, None]
        reach *= reach
        keep = dc2 <= reach
        keep[np.arange(rows.shape[0]), col] = False
        i, j = _where2(keep)
        owners.append(rows[i])
        tris.append(T.ref_tri[s[i] + j])
    return np.concatenate(owners), np.concatenate(tris)


def _neighbour_cells(T, B, u):
    """Phase B's cells: (point, padded cell) pairs for every non-empty cell of
    the 3x3x3 block around the own cell within ``u`` (box distance) of the
    point, other than the probe cell; and the mask of points whose ball
    leaves that block (answered by the index instead)."""
    ub = u * (1 + 4 * _SLACK)
    u2 = ub * ub
    below = np.square(np.maximum(B.wall, 0.0))          # (3, k) to the lower walls
    above = np.square(np.maximum(T.h - B.wall, 0.0))    # (3, k) to the upper walls
    reach = below[0] <= u2
    for side in (below[1], below[2], above[0], above[1], above[2]):
        reach |= side <= u2
    far = ub >= _block_clearance(T, B)
    sel = np.flatnonzero(reach & ~far)
    d2 = np.zeros((sel.shape[0], 7))
    d2[:, 0:6:2] = below[:, sel].T
    d2[:, 1:6:2] = above[:, sel].T
    need = d2[:, _WALL_A] + d2[:, _WALL_B] + d2[:, _WALL_C]
    i, k = _where2(need <= u2[sel, None])
    point = sel[i]
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


def _window_survivors(T, x32, point, cell, u32):
    """Phase B: the pairs (point, triangle) of the windows of ``cell`` (one
    per pair) within the sphere bound ``u32`` of ``point``."""
    order, classes = _classes(T, T.count[cell])
    starts = T.start[cell]
    owners, tris = [np.zeros(0, dtype=np.int64)], [np.zeros(0, dtype=np.int64)]
    for lo, hi, c in classes:
        rows = order[lo:hi]
        who = point[rows]
        s = starts[rows]
        dc2 = _centre_d2(T.ref[c], s, x32, who)
        reach = T.ref[c][3][s]
        reach += u32[who, None]
        reach *= reach
        i, j = _where2(dc2 <= reach)
        owners.append(who[i])
        tris.append(T.ref_tri[s[i] + j])
    return np.concatenate(owners), np.concatenate(tris)


def _edge_line_bound(T, x32, owner, t):
    """(k,) float32 lower bound of the squared distance from the points
    ``owner`` to the triangles ``t``: height above the plane and lateral
    distance beyond the farthest-out edge line, each less ``eps``."""
    x = np.take(x32[0], owner) - np.take(T.centre[0], t)
    y = np.take(x32[1], owner) - np.take(T.centre[1], t)
    z = np.take(x32[2], owner) - np.take(T.centre[2], t)

    def dot(row):
        out = np.take(T.prism[row], t)
        out *= x
        tmp = np.take(T.prism[row + 1], t)
        tmp *= y
        out += tmp
        np.take(T.prism[row + 2], t, out=tmp)
        tmp *= z
        out += tmp
        return out

    height = np.abs(dot(0))
    lateral = dot(3) - np.take(T.prism[12], t)
    np.maximum(lateral, dot(6) - np.take(T.prism[13], t), out=lateral)
    np.maximum(lateral, dot(9) - np.take(T.prism[14], t), out=lateral)
    for part in (height, lateral):
        part -= T.eps
        np.maximum(part, 0.0, out=part)
        part *= part
    height += lateral
    return height


def _kernel(T, X, owner, t):
    """The exact kernel (v, w, d2) on the pairs (points ``owner`` of X, triangles t)."""
    D = np.empty((16, t.shape[0]))
    for k in range(16):
        np.take(T.rows[k], t, out=D[k])
    return closest_on_triangles(np.take(X[0], owner), np.take(X[1], owner),
                                np.take(X[2], owner), D)


def _fold(T, X, owner, t, t0, v0, w0, d0):
    """Evaluate the pairs left and fold them into the probes: per point the
    smallest squared distance, among equal ones the lowest face index."""
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
