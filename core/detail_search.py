"""The refine detail's dense points: for each fine vertex of a binding, a
point of the dense surface near it (:func:`core.binding.bind`'s detail
search).

Two ways, chosen by ``bind(detail_search=...)``: an exact closest point on
the cleaned dense surface (:func:`exact_detail_index`, an index of the whole
scan, :func:`detail_surface`: welded, without debris or double-sided sheets;
``"auto"`` takes it up to 100,000 faces), or for larger scans a local search
around the dense vertices the bind found near each fine vertex
(:func:`dense_points_near`), on the cleaned surface up to 500,000 faces or
where the scan is unwelded (:func:`is_unwelded`), else on the scan itself::

    j has a bound dense vertex k nearest to it   closest point on k's fan; on k's
                                                 two-ring where that lands on the rim
    j has none (a scan coarser than the fine     an exact query on the scan's faces
    surface there)                               that can come that near (r: a
                                                 distance to some dense vertex,
                                                 reached over the fine edges)
"""

from typing import NamedTuple

import numpy as np

from ._clean import half_edge_ends
from .clean import clean_mesh
from .mesh import any_in_rows, mean_edge_length, row_norms, row_sums
from .near_query import cell_for_reach
from .spatial import CELL_FACTOR, TriangleIndex, point_triangle_closest, triangle_boxes
from ._groups import group_argmin, ragged_ranges, sorted_unique
from ._parallel import blocks, run_blocks, run_each

__all__ = ["DetailSurface", "detail_surface", "is_unwelded", "exact_detail_index",
           "dense_points_near"]

#: the local search looks on the cleaned scan (:func:`detail_surface`: 0.8 s CPU for a
#: clean 2M-face scan, 60% of its bind) only where more than this share of the scan's used
#: vertices have a fan of one triangle: an unwelded scan (an STL), whose fans the search
#: walks would each be one triangle (57-70% of the fine vertices refined off the scan's
#: closest point); a seam-split one has almost none
_LONE_SHARE = 0.01

#: faces a query above which the exact detail index's cells grow
#: (:func:`detail_cell_factor`): build and queries of a 200k-face scan's index for the
#: 16k fine vertices of a 2,000-face cage at two levels took 0.546 / 0.378 / 0.358 s CPU
#: with cells of 1.5 / 2.0 / 2.5 extents, the bunny's (69k) 0.208 / 0.189 / 0.152, a
#: 12k-face mesh's 0.061 / 0.064 / 0.073 (2026-12-06, one thread)
_FACES_PER_QUERY = 2.0

#: a fine vertex's nearest bound dense vertex farther from it than this many times the
#: larger of the fine surface's mean edge and the 90th percentile of those distances is
#: not searched from (a speck of debris far off, bound to a fine face where no scan vertex
#: is: its fine vertices refined 1.7e3 diagonals away); those fine vertices are searched
#: for exactly, as those with no bound dense vertex around them
_NEAREST_REACH = 16.0

#: fine faces (evenly by index) the fine surface's mean edge is measured on
_EDGE_SAMPLES = 1 << 16

#: fine vertices per block of the local detail search (``detail_search="local"``)
_DETAIL_BLOCK = 8_192

#: fine vertices per block of its two-ring search (about 24 candidate faces each: the
#: blocks' temporaries stay in cache; 54k fine vertices in one went 2x slower)
_RING_BLOCK = 2_048

#: faces per block of the search for the faces near the unbound fine vertices
_FACE_BLOCK = 65_536


class DetailSurface(NamedTuple):
    """The dense surface both detail searches look on (:func:`detail_surface`)."""

    V: np.ndarray        #: (n_s,3) float64
    F: np.ndarray        #: (m_s,3) int64
    to_surface: object   #: (n,) int64 surface vertex of each dense vertex (-1: none), or
                         #: None when the surface is the dense mesh itself


def detail_surface(V_dense, F_dense):
    """The dense surface as simplify saw it (cleaned: welded, so an unwelded
    scan's vertex has its whole fan; no debris or far speck to pull a fine
    vertex off the scan; no double-sided sheets), or the dense mesh itself
    when cleaning leaves no face."""
    surface = clean_mesh(V_dense, F_dense)
    if surface.F.shape[0]:
        return DetailSurface(surface.V, surface.F, surface.input_to_clean)
    return DetailSurface(V_dense, F_dense, None)


def is_unwelded(F_dense, n_dense, degree=None):
    """Whether the local search must look on the cleaned scan: more than
    ``_LONE_SHARE`` of the used vertices have a fan of one triangle
    (``degree``: the faces at each vertex, when the caller has counted them;
    a count of a 2M-face scan's corners is 15 ms)."""
    deg = np.bincount(F_dense.ravel(), minlength=n_dense) if degree is None else degree
    return bool(np.count_nonzero(deg == 1) > _LONE_SHARE * np.count_nonzero(deg))


def exact_detail_index(V_dense, F_dense, n_queries):
    """The :class:`~.spatial.TriangleIndex` the exact refine detail search
    queries (``n_queries`` points, the fine vertices): over
    :func:`detail_surface`, its cells :func:`detail_cell_factor` wide."""
    surface = detail_surface(V_dense, F_dense)
    return TriangleIndex(surface.V, surface.F,
                         cell_factor=detail_cell_factor(surface.F.shape[0], n_queries))


def detail_cell_factor(n_faces, n_queries):
    """The detail index's cell size in mean triangle extents: the index's
    default (``CELL_FACTOR``) for as many queries as faces, grown as
    ``(faces / queries / _FACES_PER_QUERY) ** 0.25`` where the faces are
    more: larger cells cost the build less (fewer cells per triangle) and
    each query more (more triangles per cell), and a scan has far more faces
    than its cage's fine vertices."""
    growth = max(1.0, n_faces / max(n_queries, 1) / _FACES_PER_QUERY) ** 0.25
    return CELL_FACTOR * growth


class _Fans(NamedTuple):
    """The faces around some vertices of a mesh (CSR over those vertices in
    ascending order, each fan's faces ascending)."""

    start: np.ndarray     #: (k + 1,) int64 fan of the i-th vertex: faces[start[i]:start[i+1]]
    faces: np.ndarray     #: (entries,) int64
    rank: np.ndarray      #: (n,) int64 the place i of each vertex among them (-1: none)

    def of(self, v):
        """(first entry, count) of the fans of the vertices ``v`` (each one of them)."""
        i = self.rank[v]
        return self.start[i], self.start[i + 1] - self.start[i]


def _fans_of(F, vertices):
    """:class:`_Fans` of the distinct ``vertices`` of the triangles ``F``: one
    scan of F for the corners at them, then those (vertex, face) entries
    sorted by vertex (stable: faces ascending, as a full vertex -> face
    table lists them). Vertices are placed by a rank table, not a search
    (at five levels on a 2M-face scan 0.44 of the 0.78 s this took)."""
    vertices = sorted_unique(vertices)
    flat = F.ravel()
    n = max(int(flat.max()) + 1 if flat.size else 0, int(vertices.max()) + 1 if vertices.size else 0)
    rank = np.full(n, -1, dtype=np.int32 if vertices.shape[0] < 2**31 else np.int64)
    rank[vertices] = np.arange(vertices.shape[0])

    def scan(s, e):          # the corners at the vertices among F's corners s:e
        r = rank.take(flat[s:e])
        hit = np.flatnonzero(r >= 0)
        return hit + s, r[hit]
    parts = run_blocks(scan, blocks(flat.shape[0], 3 * _FACE_BLOCK)) or [(np.zeros(0, np.int64),) * 2]
    hit = np.concatenate([p[0] for p in parts])
    r = np.concatenate([p[1] for p in parts]).astype(np.int64)
    order = np.argsort(r, kind="stable")
    counts = np.bincount(r, minlength=vertices.shape[0])
    return _Fans(np.concatenate([[0], np.cumsum(counts)]), hit[order] // 3, rank)


def dense_points_near(V_dense, F_dense, F_fine, nearest, P, reach=None):
    """A point of the dense surface near each fine vertex position ``P[j]``.

    Searched without an index of the whole dense mesh, using the binding:
    take ``nearest[j]``, the dense vertex nearest to ``P[j]`` among those
    bound to the fine faces around ``j`` (found by the bind's dense pass),
    and return the closest point of ``P[j]`` on that vertex's triangle fan,
    or on its two-ring where the fan's best point lies on the fan's rim (the
    surface may come closer beyond it). Fine vertices with no bound dense
    vertex around them (a dense mesh coarser than the cage there) get their
    exact closest point, from an index of only the dense faces that can come
    as near as some dense vertex is (:func:`_distance_bound`,
    :func:`_faces_near`; at five levels on a 2M-face scan 20% of its faces:
    0.7 s where the whole scan's index took 2.8-7 s), its cells sized for
    ``reach``, the typical distance between the surfaces, when known. Every
    returned point lies on the dense surface; it is the closest one whenever
    the closest triangle lies in the two-ring of the nearest bound vertex
    (the usual case for a cage near the surface).

    Parameters
    ----------
    V_dense, F_dense : (n,3) float64, (m,3) int64
        The dense mesh.
    F_fine : (m_f,3) int64
        The fine mesh (the subdivided cage's faces).
    nearest : (n_f,) int64
        Each fine vertex's nearest bound dense vertex, -1 for none.
    P : (n_f,3) float64
        The fine vertex positions.
    reach : float, optional

    Returns
    -------
    (n_f,3) float64 ndarray
    """
    n_f = P.shape[0]
    q = np.empty((n_f, 3))
    nearest = _near_enough(V_dense, F_fine, nearest, P)
    has = np.flatnonzero(nearest >= 0)
    fans = _fans_of(F_dense, nearest[has])
    rim = np.zeros(n_f, dtype=bool)

    def on_fan(s, e):
        # fine vertices has[s:e]: the closest point on the fan of their nearest vertex;
        # where it lands on the fan's rim (zero weight on the centre), the two-ring
        j, k = has[s:e], nearest[has[s:e]]
        first, count = fans.of(k)
        idx, owner = ragged_ranges(first, count)
        point, corners, bary = _closest_in_groups(V_dense, F_dense, P, j[owner],
                                                  fans.faces[idx], count)
        q[j] = point
        rim[j] = row_sums(bary * (corners == k[:, None])) <= 0.0

    run_blocks(on_fan, blocks(has.shape[0], _DETAIL_BLOCK))
    if rim.any():
        _two_ring_points(V_dense, F_dense, P, np.flatnonzero(rim), nearest, fans, q)
    missing = np.flatnonzero(nearest < 0)
    if missing.size:
        r = _distance_bound(V_dense, F_fine, nearest, P, missing)
        part = F_dense if r is None else F_dense[_faces_near(V_dense, F_dense, P[missing], r)]
        index = TriangleIndex(V_dense, part, min_cell=cell_for_reach(reach))
        q[missing] = index.closest(P[missing]).point
    return q


def _near_enough(V_dense, F_fine, nearest, P):
    """``nearest`` with -1 where the dense vertex lies beyond ``_NEAREST_REACH``
    times the typical such distance from its fine vertex (a copy when any does)."""
    has = np.flatnonzero(nearest >= 0)
    if has.size == 0:
        return nearest
    d = row_norms(V_dense[nearest[has]] - P[has])
    edge = mean_edge_length(P, F_fine, _EDGE_SAMPLES)
    far = d > _NEAREST_REACH * max(float(np.percentile(d, 90)), edge)
    if not far.any():
        return nearest
    nearest = nearest.copy()
    nearest[has[far]] = -1
    return nearest


def _distance_bound(V_dense, F_fine, nearest, P, missing):
    """A distance within which every fine vertex of ``missing`` (no bound
    dense vertex around it) has a point of the dense surface: the largest
    distance from one to the nearest bound dense vertex of a fine vertex
    that has one, reached over the fine edges in rounds (each round, a
    missing vertex takes the dense vertex of a neighbour that has one);
    None when no fine vertex has one."""
    # the edges into missing vertices lie on the fine faces with a missing corner
    U, W = half_edge_ends(F_fine[any_in_rows(nearest[F_fine] < 0)])
    src, dst = np.concatenate([U, W]), np.concatenate([W, U])      # both ways along each
    into = nearest[dst] < 0
    src, dst = src[into], dst[into]
    found = nearest.copy()
    while True:
        step = (found[src] >= 0) & (found[dst] < 0)
        if not step.any():
            break
        found[dst[step]] = found[src[step]]
    got = found[missing]
    if (got < 0).any():
        return None
    return float(row_norms(P[missing] - V_dense[got]).max())


def _faces_near(V, F, P, r):
    """The faces of ``(V, F)`` (ascending indices) that may come within
    ``r`` of a point of ``P``: those whose bounding-box centre lies in the
    cells (edge ``s``, ``r`` plus the largest bounding-box half-diagonal)
    of the points or next to them. A face with a point within ``r`` of
    ``P[j]`` has its centre within ``s`` of it, so in the cell of ``P[j]`` or
    a neighbour: none is left out."""
    spans = blocks(F.shape[0], _FACE_BLOCK)

    def boxes(span):
        lo, hi = triangle_boxes(V, F[span[0]:span[1]])
        hi -= lo
        lo += 0.5 * hi
        return lo, 0.5 * float(np.sqrt(np.einsum("ij,ij->i", hi, hi).max(initial=0.0)))
    centres = run_each(boxes, spans)
    rho = max(part[1] for part in centres)
    lo, hi = P.min(axis=0), P.max(axis=0)
    # a margin for the rounding of the centres and cells (relative to the coordinates'
    # size), and cells few enough for int64 keys
    size = max(float(np.abs(V).max(initial=0.0)), float(np.abs(P).max(initial=0.0)), 1e-300)
    s = max((r + rho) * (1 + 1e-6) + 1e-9 * size, float((hi - lo).max()) / 2e6)
    dims = np.floor((hi - lo) / s).astype(np.int64) + 3        # a cell of margin each side
    pc = np.floor((P - lo) / s).astype(np.int64) + 1
    near = pc[:, None, :] + np.array(list(np.ndindex(3, 3, 3))) - 1
    keys = sorted_unique(near[..., 0] + dims[0] * (near[..., 1] + dims[1] * near[..., 2]))

    def kept(i):
        c = np.floor((centres[i][0] - lo) / s) + 1
        inside = ((c >= 0) & (c < dims)).all(axis=1)
        c = c[inside].astype(np.int64)
        k = c[:, 0] + dims[0] * (c[:, 1] + dims[1] * c[:, 2])
        at = np.minimum(np.searchsorted(keys, k), keys.shape[0] - 1)
        return spans[i][0] + np.flatnonzero(inside)[keys[at] == k]
    return np.concatenate(run_each(kept, range(len(spans))))


def _two_ring_points(V_dense, F_dense, P, js, nearest, fans, q):
    """For the fine vertices ``js`` whose fan point lies on the rim, the
    closest point over the two-ring of their nearest dense vertex (the fans
    of the fan's vertices), into ``q``."""
    n_d = V_dense.shape[0]
    first, count = fans.of(nearest[js])
    idx, owner = ragged_ranges(first, count)
    ring_j, ring_v = _unique_pairs(np.repeat(js[owner], 3),
                                   F_dense[fans.faces[idx]].ravel(), n_d)
    ring = _fans_of(F_dense, ring_v)
    first, count = ring.of(ring_v)
    idx, owner = ragged_ranges(first, count)
    cand_j, cand_f = _unique_pairs(ring_j[owner], ring.faces[idx], F_dense.shape[0])
    counts = np.bincount(cand_j)
    j = np.flatnonzero(counts)
    starts = np.concatenate([[0], np.cumsum(counts[j])])

    def block(a, b):
        # fine vertices j[a:b], their candidates contiguous (sorted by fine vertex)
        s, e = starts[a], starts[b]
        q[j[a:b]] = _closest_in_groups(V_dense, F_dense, P, cand_j[s:e], cand_f[s:e],
                                       counts[j[a:b]])[0]
    run_blocks(block, blocks(j.shape[0], _RING_BLOCK))


def _closest_in_groups(V, F, P, j, face, counts):
    """Closest point of ``P[j[k]]`` over the candidate faces ``face[k]``,
    grouped contiguously by ``j`` (``counts`` per group, each > 0). Returns
    the best point, its face's corners and barycentric coordinates per group."""
    T = np.take(F, face, axis=0)
    hit = point_triangle_closest(np.take(P, j, axis=0), np.take(V, T[:, 0], axis=0),
                                 np.take(V, T[:, 1], axis=0), np.take(V, T[:, 2], axis=0))
    best = group_argmin(hit.distance, counts)
    return hit.point[best], T[best], hit.bary[best]


def _unique_pairs(a, b, n_b):
    """Distinct pairs ``(a[k], b[k])`` sorted by ``a`` then ``b``."""
    key = sorted_unique(a * np.int64(n_b) + b)
    return key // n_b, key % n_b
