"""Exact closest points on a triangle mesh, in pure NumPy.

Point to triangle: Ericson, *Real-Time Collision Detection* (2005), 5.1.5
("ClosestPtPointTriangle"), batched over arrays of (point, triangle) pairs.
With ``ab = B - A``, ``ac = C - A``, ``ap = P - A`` and the six dot products
``d1 = ab.ap, d2 = ac.ap, d3 = ab.bp, d4 = ac.bp, d5 = ab.cp, d6 = ac.cp``
the point's Voronoi region of the triangle is, in this order of precedence::

            C
           / \\          A:  d1 <= 0 and d2 <= 0
      AC  /   \\  BC     B:  d3 >= 0 and d4 <= d3
         /  F  \\        AB: vc <= 0, d1 >= 0, d3 <= 0   (vc = d1 d4 - d3 d2)
        A-------B       C:  d6 >= 0 and d5 <= d6
            AB          AC: vb <= 0, d2 >= 0, d6 <= 0   (vb = d5 d2 - d1 d6)
                        BC: va <= 0, d4 >= d3, d5 >= d6  (va = d3 d6 - d5 d4)
                        F (inside): v = vb / (va+vb+vc), w = vc / (va+vb+vc)

and the closest point is ``A + v ab + w ac`` (barycentric ``(1-v-w, v, w)``).
The determinants lose accuracy on slivers (``sin^2`` of a corner angle
below ``_THIN_SIN2``) and are undefined on zero-area triangles, so those
triangles use a robust path instead: the best of the three clamped segment
projections and, when it falls inside, the orthogonal projection onto the
plane computed with the directly evaluated normal (skipped when even that
normal is rounding noise, ``sin^2 < _FLAT_SIN2``). Other triangles are first
projected onto their plane, so far-away points keep their in-plane accuracy.

The index (:class:`TriangleIndex`) answers "nearest triangle" exactly:

1. Triangles are put in Morton order (spatial locality for every gather) and
   referenced in each cell of a uniform grid that their bounding box and their
   plane both touch (cell size about the mean triangle extent, capped at
   ``_MAX_CELLS`` cells).
2. Queries are sorted by cell and processed in chunks. Phase 1: the triangles
   of the query's own cell (if it is empty, of the nearest non-empty one of its
   26 neighbours) give an upper bound ``u``, an exact distance to a real
   triangle. Phase 2: every other cell within ``u`` of the query (box
   distance) is examined; any triangle closer than ``u`` has a point in one of
   those cells and is referenced there, so the minimum is exact.
3. Every candidate set goes through three lower bounds of increasing cost and
   tightness (c the centroid, r the radius of a sphere around the triangle, n
   its normal, m_k / o_k its in-plane outward edge normals and their distances
   from c)::

       sphere:  (|p - c| - r)^2
       disk:    ((p - c).n)^2 + max(0, |p - c|_lateral - r)^2
       prism:   ((p - c).n)^2 + max(0, max_k (p - c).m_k - o_k)^2   <= |p - T|^2

   (the last is exact wherever the closest point is inside the triangle or on
   an edge). With a probe, the candidate with the nearest centroid is
   evaluated exactly first; then only the candidates whose three bounds are
   within the best distance. Among exactly equidistant triangles the one
   with the smallest disk bound wins (the index's rule since its first
   version, kept so that results do not change).
4. Queries with no triangle nearby, whose ball spans more than
   ``_MAX_PHASE2_CELLS`` cells (far from the surface, outside the grid) or cells
   referencing more than ``_PHASE2_CROWDED`` crowded cells' worth of triangles
   (fans of needles), or whose
   cell is crowded (more than ``crowded_cell`` references: long thin triangles,
   as a CAD cylinder's sides, cross and crowd every cell) go to a
   bounding-volume hierarchy over the same Morton order (a balanced binary tree
   of ``_LEAF``-triangle leaves, built on first need), searched by groups of
   nearby queries (a ball of centre c and radius rho holding them). Each query
   first gets an exact bound from the leaves a beam descent from its group's
   centre reaches (``_PROBE_BEAM`` nodes per level), then the tree is descended
   ``_BVH_STEP`` levels at a time, breadth first, in lockstep for all groups.
   Each node has an axis-aligned box and a cylinder (centre, axis = summed
   normal, radius, half height) that is thin for tilted flat patches; a node is
   pruned when its lower bound (the larger of the two, at c, less rho) exceeds
   the group's upper bound (its members' largest), itself tightened at every
   level by the smallest farthest-point distance of a child (at c, plus rho);
   at the leaves each member takes its group's leaves with its own bounds.
   Large frontiers are split and processed depth first, so memory stays
   bounded.
5. A few triangles far out of the rest's box (a scan's spike, a speck of
   debris far off: ``_OUTLIER_*``) are kept out of the grid, which the rest
   alone sizes, and measured apart (:class:`_Outliers`): a query outside the
   grid's box that one of them comes nearer than the box is answered by them
   alone; every other query's answer from the grid is compared with theirs
   (bounded by their boxes and planes, the one of smallest bound first).

Every (query, candidate) set is a ragged expansion (``np.repeat`` + ``cumsum``)
evaluated in vectorised kernel calls; the per-query minimum comes from
``np.minimum.reduceat`` over contiguous groups. Pruning tests carry relative
margins (``PRUNE_SLACK``) so that rounding can only keep a candidate, never drop one.
"""

import threading
from typing import NamedTuple

import numpy as np

from .errors import InvalidArgumentError
from .mesh import (check_finite_rows, check_mesh, check_number, check_points, check_reach,
                   cross_rows, row_norms, row_sums, scaled_area_normals, unit_rows)
from ._groups import group_argmin, ragged_entries, ragged_ranges, sorted_unique
from ._parallel import blocks, run_blocks, run_each
from .pages import plain_pages

#: serialises the lazy BVH builds of indexes queried from several threads at once
_LAZY_BUILD = threading.Lock()

__all__ = ["ClosestPoints", "IndexTables", "TriangleClosest", "TriangleIndex", "closest_points",
           "point_triangle_closest", "triangle_boxes"]

# --- tolerances and tuning, in one place -------------------------------------------------------
_THIN_SIN2 = 1e-4          # |ab x ac|^2 < this * |ab|^2 |ac|^2 (and same at B): robust path
_FLAT_SIN2 = 1e-16         # below this sin^2 at A a triangle is treated as its three edges
CELL_FACTOR = 1.5          # grid cell size = this * mean triangle bounding-box extent
_AREA_CELL_SHRINK = 16     # ... or of the mean triangle's area's edge, down to 1/this of it
_MAX_CELLS = 1 << 23       # dense grid cap (int64 offsets: 64 MiB)
_MAX_REFS_PER_FACE = 12    # grow the cells if triangles would be referenced more often
_MIN_REF_BUDGET = 1 << 22  # ... and more than this often in all (32 MiB)
#: thin triangles (no taller than this share of their longest edge) do not set the cell
#: size when they would make it 25% larger (a degenerate cluster of needles across the
#: mesh made cells 5x wider than the mesh's own triangles: every query met 1,500 of them)
_THIN_HEIGHT = 0.01
#: a triangle no taller (over its longest edge) than this share of a cell, and whose
#: box spans more than _LINE_CELLS cells, is referenced only in the cells near its
#: longest edge (a needle lies along it; its plane test keeps its whole box)
_NEEDLE_HEIGHT = 0.25
_LINE_CELLS = 27
_MAX_PHASE2_CELLS = 64     # queries whose ball spans more cells go to the BVH
#: ... or whose cells within it reference more than this many times ``crowded_cell``
#: triangles (fans of needles, each in many cells: the Loop surface of a filleted box
#: corner's 500-face cage, its fine vertices up to a tenth of the size inside the
#: corners, scanned 16k references each there, 2 ms a point, where the BVH takes about
#: 550 pairs; relative to ``crowded_cell``, which grows with cells made wide on purpose:
#: a fit's index of a 2M-face scan, its cells a few fine edges wide, keeps its queries)
_PHASE2_CROWDED = 4.0
CROWDED_CELL = 256         # ... and queries in a cell referencing more triangles than this
#: (on a 1M-face scan a BVH query costs about what scanning 800 references does, 20 against
#: 2.8 us for 113; but slivers pass the bounds, so a crowded cell's references are mostly
#: evaluated exactly: the 500-face cage of a CAD cylinder, one cell of 500, measured against
#: it in 27.7 s at 1,024 and 13.2 s at 128. Cells of the shared meshes hold at most 126)
_MAX_SAME_CODE = 64        # more triangles than this with one Morton code: drop repeated ones
#: a triangle no taller than this share of the mesh's size over its longest edge is
#: flat: a segment. Flat ones whose segment lies (within it) inside another's
#: are not indexed (a region collapsed onto a line by a scanner: thousands of needles
#: over one another, every query near the line met them all)
_FLAT_HEIGHT = 1e-9
#: ... grouped by line: directions and the lines' offsets from the origin rounded to
#: this share (of a unit vector, of the mesh's size); rounding may split one line's
#: segments into two groups (fewer dropped), never puts two lines in one
_LINE_ROUNDING = 1e-6
#: triangles no taller over their longest edge than this share of its length also get a
#: capsule bound (their distance to that edge less their height): needles and slivers,
#: whose bounding sphere and disk are as wide as they are long, and whose thin ones have
#: no plane to bound by (a fillet's end cap, a fan of 1,000 coplanar needles: each query
#: near it evaluated every needle exactly)
_CAPSULE_HEIGHT = 1.0 / 16
_LEAF = 8                  # BVH leaf size (triangles)
#: far queries share their BVH search by groups (:meth:`TriangleIndex._bvh_query`): for the
#: probe, those in one cube of _PROBE_CELLS grid cells; for the descent, each query in a cube
#: no wider than _GROUP_SHARE times its probe's distance (a power of two times the cells, at
#: least 2**-_GROUP_LEVELS of one). A gravel scan's fit (dense samples 1.7 to 36 cells from
#: a fine surface of small blobs, 82k of them far) searched them in 3.25 s, one by one, and
#: in 1.65 s so; probe cubes of 2, 4, 8, 16 cells: 2.56, 1.80, 1.65, 1.79 s, descent shares
#: of 0.5, 1, 2, 4 (probe cubes of 2 cells): 2.83, 2.56, 3.16, 5.69 s (CPU, 2026-12-05).
#: But a descent group of many members scans every member against every leaf the group
#: reached: 100k points spread over twice the box of a 160k-face torus (scripts/
#: bench_spatial.py's far case) took 15.0 s CPU one by one, and with a share of 1.0 over
#: 5 minutes and 20 GiB (20k of them: 58 s, 4.8 GiB; the machine killed the benchmark);
#: shares 0.25 / 0.125 / 0.0625: 55.4 / 20.6 / 14.2 s. The gravel fits at 1.0 / 0.25 /
#: 0.0625: 150 pebbles 1.77 / 1.48 / 1.60 s, the cow and 2,000 pebbles 34.6 / 34.7 / 33.0 s
#: (the same cages; CPU, one thread, 2026-12-06, load 2-4)
_PROBE_CELLS = 8
#: ... but for the queries of crowded cells (near the surface, beside long thin
#: triangles), cubes of this many cells: a beam from the centre of 8 cells beside a
#: fan's hub led each member to the needles at the centre's angle, a bound as far as
#: the cube is wide, and the descent kept every leaf within it (a cone of 10k needles:
#: 5,000 points on its flat base 1.51 -> 0.41 s, its simplify to 200 faces 17.5 -> 4.1)
_CROWDED_PROBE_CELLS = 0.5
_GROUP_SHARE = 1.0 / 16
_GROUP_LEVELS = 2
_BVH_STEP = 2              # BVH levels descended per traversal step (4 children per node)
_SLAB_LEVELS = 3           # lowest BVH levels that also get cylinder bounds
_PROBE_BEAM = 4            # BVH nodes per query per level of the probe for a first upper bound
#: a probe farther than this many times the box distance of the leaves it reached, and
#: than ``_ODD_PROBE_SHARE`` of the mesh's box diagonal, is made again with a beam of
#: ``_WIDE_BEAM``: points beside a CAD fillet's 100-long strips, inside the boxes of many
#: nodes, had a beam of 4 miss the big face they lie on (112 of a fit's 464 started 49
#: units off), and every strip within that distance was scanned
_ODD_PROBE = 4.0
_ODD_PROBE_SHARE = 0.01
_WIDE_BEAM = 16
#: a query's leaves in the BVH: its nearest one by its bound, then, where more than
#: the second of these are left within the distance found, nearest first in rounds up to
#: these ranks, each round those still within it: where the nearest leaf by its bound is
#: not the one holding the answer (the strips of a CAD fillet, within 6-9% of the
#: answer's distance), one round took every leaf within its distance: 114 leaves a
#: query, 4,002 points 2.15 -> 0.86 s
_LEAF_ROUNDS = (1, 4, 16, 64, np.inf)
#: a scan's query with more pairs than this left within the centroid probe's bound
#: evaluates the one of smallest lower bound first (:meth:`TriangleIndex._eval_lowest_first`)
_LOWEST_FIRST = 8
_PAIR_CHUNK = 1 << 18      # target own-cell (query, triangle) pairs per chunk
_QUERY_CHUNK = 1 << 16     # at most this many queries per chunk
#: pairs per block of :func:`closest_pairs` (temporaries of 128 KiB stay in cache: a
#: million pairs in one call took 1.5 us each, in blocks 0.23-0.27 us)
KERNEL_BLOCK = 1 << 14
_BRUTE_PAIRS = 1 << 24     # fewer far (query, triangle) pairs than this: no BVH, scan all
_BRUTE_QUERIES = 64        # ... and no more far queries than this (else the BVH is cheaper)
_FRONTIER_CAP = 1 << 16    # BVH frontier pairs before it is split and processed depth first
PRUNE_SLACK = 1e-9         # relative slack on pruning tests (keeps rounding conservative)
_THREADED_BUILD = 1 << 15  # from this many faces the build runs its two halves on two threads
_BUILD_BLOCK = 1 << 15     # triangles per block of the build's kernel rows and bounds
_CANDIDATE_CELLS = 1 << 20  # box cells a run of a block's triangles tests for grid references
#: a few faces far out of the rest's box (a scan's spike: one vertex 1,000 diagonals
#: off, its five or six faces crossing the whole box) are kept out of the grid, which
#: covers the rest, and measured against every query apart (:class:`_Outliers`): with
#: them the grid's cells grew to fit the box and the cap on references, the bunny's
#: 69k faces sat in cells of up to 279 and a fit of its cage took 195 s. The rest's box
#: is that of a sample of ``_OUTLIER_SAMPLE`` face centres without its
#: ``_OUTLIER_TAIL`` share at each end, grown by ``_OUTLIER_MARGIN`` of its largest
#: side; faces whose boxes leave it are the outliers when the whole box is more than
#: ``_OUTLIER_GROWTH`` times as large and they are at most ``_OUTLIER_SHARE`` of the faces
#: (a butterfly surface's spike over its neighbours too: a fit of that bunny's cage
#: 182 s, the fine surface's 424 long faces in its grid)
_OUTLIER_SAMPLE = 4096
_OUTLIER_TAIL = 0.2
_OUTLIER_MARGIN = 1.0
_OUTLIER_GROWTH = 4.0
_OUTLIER_SHARE = 0.2
#: ... and at most this many (the butterfly surface of a spiked cage spreads the spike
#: over its neighbours' fine faces: 424 of the bunny cage's 32k)
_OUTLIER_MAX = 512
#: (point, outlier) bound tests per block, of at least this many points (a block is
#: first bounded as a whole: a bind's dense vertices come in the mesh's order)
_OUTLIER_PAIRS = 1 << 16
_OUTLIER_MIN_BLOCK = 256
#: the height of a point over an outlier's plane is within this many ulps of the largest
#: coordinate (point or outlier) of its value
_HEIGHT_ULPS = 16


class ClosestPoints(NamedTuple):
    """Nearest point on a triangle mesh for each query point.

    face : (q,) int64, index into F of the nearest triangle.
    point : (q,3) float64, the nearest point on that triangle.
    bary : (q,3) float64, barycentric coordinates of ``point`` in ``F[face]``
        (each in [0,1], summing to 1: ``point == bary @ V[F[face]]``).
    distance : (q,) float64, Euclidean distance from the query to ``point``.
    """
    face: np.ndarray
    point: np.ndarray
    bary: np.ndarray
    distance: np.ndarray


class IndexTables(NamedTuple):
    """The arrays of a :class:`TriangleIndex`, for another query over the same grid
    (read-only views: never modify them). Triangles are numbered in the index's
    internal (Morton) order ``t``; ``face[t]`` is the face of ``F``."""

    lo: np.ndarray          #: (3,) float64, the grid's origin (the mesh's lower corner)
    hi: np.ndarray          #: (3,) float64, the mesh's upper corner
    cell_size: float        #: edge of the cubic cells
    dims: np.ndarray        #: (3,) int64 cells per axis; cell ``x + dims[0] (y + dims[1] z)``
    cell_start: np.ndarray  #: (n_cells + 1,) int64: cell c's references are
    #:                         ``cell_tri[cell_start[c]:cell_start[c + 1]]``
    cell_tri: np.ndarray    #: (refs,) int32/int64 triangles referenced per cell, cell by cell
    rows: np.ndarray        #: (16, m) float64 :func:`triangle_rows` (the exact kernel's input)
    ball: np.ndarray        #: (4, m) float64 centroid and radius of a sphere holding each
    prism: np.ndarray       #: (16, m) float64 normal, edge normals, offsets, allowance (the
    #:                         edge-line bound's rows, see the module docstring)
    face: np.ndarray        #: (m,) int64 face of ``F`` of each internal triangle


class TriangleClosest(NamedTuple):
    """Closest point of each point on its paired triangle (see :func:`point_triangle_closest`)."""
    point: np.ndarray
    bary: np.ndarray
    distance: np.ndarray


# --- the pair kernel -----------------------------------------------------------------------------

def triangle_rows(A, B, C):
    """(16, m) float64 rows: A (3), ab (3), ac (3), |ab|^2, |ac|^2, ab.ac, unit normal (3)
    (zero for zero-area triangles), thin flag (0/1)."""
    ab = B - A
    ac = C - A
    s_ab = np.einsum("ij,ij->i", ab, ab)
    s_ac = np.einsum("ij,ij->i", ac, ac)
    s_abac = np.einsum("ij,ij->i", ab, ac)
    bc = C - B
    s_bc = np.einsum("ij,ij->i", bc, bc)
    n = cross_rows(ab, ac)
    nn = np.einsum("ij,ij->i", n, n)
    length = np.sqrt(nn)
    unit = np.divide(n, length[:, None], out=np.zeros_like(n), where=length[:, None] > 0)
    # sin^2 of the angles at A, B and C; thin (robust path) if any is tiny. The plane of
    # a thin triangle is ill-conditioned: no projection onto it (unit normal set to 0)
    thin = (nn <= _THIN_SIN2 * s_ab * s_ac) | (nn <= _THIN_SIN2 * s_ab * s_bc) \
        | (nn <= _THIN_SIN2 * s_ac * s_bc)
    unit[thin] = 0.0
    D = np.empty((16, A.shape[0]))
    D[0:3] = A.T
    D[3:6] = ab.T
    D[6:9] = ac.T
    D[9], D[10], D[11] = s_ab, s_ac, s_abac
    D[12:15] = unit.T
    D[15] = thin
    return D


def closest_on_triangles(px, py, pz, D):
    """Closest point of (px,py,pz)[k] on triangle D[:, k] (rows from :func:`triangle_rows`).

    Returns ``v, w, d2``: the point is ``A + v ab + w ac`` at squared distance ``d2``.
    """
    ax, ay, az, abx, aby, abz, acx, acy, acz, s_ab, s_ac, s_abac, nx, ny, nz, thin = D
    # work in the triangle's plane (removes the normal component before the
    # determinants, so far-away points do not lose the in-plane accuracy)
    apx = px - ax
    apy = py - ay
    apz = pz - az
    hgt = apx * nx + apy * ny + apz * nz
    apx -= hgt * nx
    apy -= hgt * ny
    apz -= hgt * nz
    d1 = abx * apx + aby * apy + abz * apz
    d2 = acx * apx + acy * apy + acz * apz
    d3 = d1 - s_ab
    d4 = d2 - s_abac
    d5 = d1 - s_abac
    d6 = d2 - s_ac
    vc = d1 * d4 - d3 * d2
    vb = d5 * d2 - d1 * d6
    va = d3 * d6 - d5 * d4
    with np.errstate(divide="ignore", invalid="ignore"):
        denom = va + vb + vc
        v = vb / denom
        w = vc / denom
        d43 = d4 - d3
        d56 = d5 - d6
        m = (va <= 0) & (d43 >= 0) & (d56 >= 0)                       # edge BC
        t = d43 / (d43 + d56)
        v = np.where(m, 1.0 - t, v)
        w = np.where(m, t, w)
        m = (vb <= 0) & (d2 >= 0) & (d6 <= 0)                         # edge AC
        v = np.where(m, 0.0, v)
        w = np.where(m, d2 / (d2 - d6), w)
        m = (d6 >= 0) & (d5 <= d6)                                    # vertex C
        v = np.where(m, 0.0, v)
        w = np.where(m, 1.0, w)
        m = (vc <= 0) & (d1 >= 0) & (d3 <= 0)                         # edge AB
        v = np.where(m, d1 / (d1 - d3), v)
        w = np.where(m, 0.0, w)
        m = (d3 >= 0) & (d4 <= d3)                                    # vertex B
        v = np.where(m, 1.0, v)
        w = np.where(m, 0.0, w)
        m = (d1 <= 0) & (d2 <= 0)                                     # vertex A
        v = np.where(m, 0.0, v)
        w = np.where(m, 0.0, w)
    ex = apx - v * abx - w * acx
    ey = apy - v * aby - w * acy
    ez = apz - v * abz - w * acz
    dist2 = ex * ex + ey * ey + ez * ez
    bad = np.flatnonzero(thin != 0)
    if bad.size:
        rv, rw, rd = _robust_kernel(apx[bad], apy[bad], apz[bad], D[:, bad])
        v[bad] = rv
        w[bad] = rw
        dist2[bad] = rd
    dist2 += hgt * hgt
    return v, w, dist2


def closest_pairs(PT, q, D, t):
    """:func:`closest_on_triangles` on the pairs (columns ``q`` of the points
    ``PT`` (3,n), columns ``t`` of the triangle rows ``D`` (16,m)), gathered
    and evaluated ``KERNEL_BLOCK`` pairs at a time: ``v, w, d2``."""
    k = q.size
    if k <= KERNEL_BLOCK:
        X = np.take(PT, q, axis=1)
        return closest_on_triangles(X[0], X[1], X[2], np.take(D, t, axis=1))
    v, w, d2 = np.empty(k), np.empty(k), np.empty(k)
    for s in range(0, k, KERNEL_BLOCK):
        e = min(s + KERNEL_BLOCK, k)
        X = np.take(PT, q[s:e], axis=1)
        v[s:e], w[s:e], d2[s:e] = closest_on_triangles(X[0], X[1], X[2],
                                                        np.take(D, t[s:e], axis=1))
    return v, w, d2


def _segment(apx, apy, apz, ox, oy, oz, ex, ey, ez):
    """Clamped projection of ap onto the segment o + t e, t in [0,1]: (t, squared distance)."""
    ee = ex * ex + ey * ey + ez * ez
    qx, qy, qz = apx - ox, apy - oy, apz - oz
    num = qx * ex + qy * ey + qz * ez
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(ee > 0, num / ee, 0.0)
    t = np.clip(t, 0.0, 1.0)
    rx, ry, rz = qx - t * ex, qy - t * ey, qz - t * ez
    return t, rx * rx + ry * ry + rz * rz


def _robust_kernel(apx, apy, apz, D):
    """Slivers and zero-area triangles: best of the three edges and, when the plane is
    well enough defined and the projection falls inside, the projection."""
    _, _, _, abx, aby, abz, acx, acy, acz = D[:9]
    zero = np.zeros_like(apx)
    t1, e1 = _segment(apx, apy, apz, zero, zero, zero, abx, aby, abz)          # AB: (t, 0)
    t2, e2 = _segment(apx, apy, apz, zero, zero, zero, acx, acy, acz)          # AC: (0, t)
    t3, e3 = _segment(apx, apy, apz, abx, aby, abz, acx - abx, acy - aby, acz - abz)  # BC
    v = np.where(e2 < e1, 0.0, t1)
    w = np.where(e2 < e1, t2, 0.0)
    d = np.minimum(e1, e2)
    v = np.where(e3 < d, 1.0 - t3, v)
    w = np.where(e3 < d, t3, w)
    d = np.minimum(d, e3)
    # inside projection, with the normal evaluated directly (accurate for slivers)
    nx = aby * acz - abz * acy
    ny = abz * acx - abx * acz
    nz = abx * acy - aby * acx
    nn = nx * nx + ny * ny + nz * nz
    # the computed normal's direction is good to eps / sin(A): below sin(A) = 1e-8 the
    # triangle is treated as its three edges (then off by at most 1e-8 of its size)
    ok = (nn > 0) & (nn > _FLAT_SIN2 * D[9] * D[10])
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = np.where(ok, 1.0 / nn, 0.0)
        # w = ((ab x ap) . n) / nn, v = ((ap x ac) . n) / nn
        wi = ((aby * apz - abz * apy) * nx + (abz * apx - abx * apz) * ny
              + (abx * apy - aby * apx) * nz) * inv
        vi = ((apy * acz - apz * acy) * nx + (apz * acx - apx * acz) * ny
              + (apx * acy - apy * acx) * nz) * inv
        h = apx * nx + apy * ny + apz * nz
        di = h * h * inv
    inside = ok & (vi >= 0) & (wi >= 0) & (vi + wi <= 1) & (di < d)
    v = np.where(inside, vi, v)
    w = np.where(inside, wi, w)
    d = np.where(inside, di, d)
    return v, w, d


def point_triangle_closest(P, A, B, C):
    """Closest point of each point ``P[k]`` on the triangle ``(A[k], B[k], C[k])``.

    Exact region classification (Ericson 2005); slivers and zero-area
    triangles (segments or points) are handled by a robust path.

    Parameters
    ----------
    P, A, B, C : (k, 3) array_like of float
        Query points and triangle corners, paired row by row.

    Returns
    -------
    TriangleClosest
        ``point`` (k,3), ``bary`` (k,3) barycentric coordinates in (A, B, C),
        each in [0,1] summing to 1, ``distance`` (k,) Euclidean.

    Raises
    ------
    InvalidArgumentError
        Arrays not (k,3), of different lengths, or not finite.

    Examples
    --------
    >>> r = point_triangle_closest([[0.2, 0.2, 1.0]], [[0, 0, 0]], [[1, 0, 0]], [[0, 1, 0]])
    >>> r.point.round(12).tolist(), float(r.distance[0])
    ([[0.2, 0.2, 0.0]], 1.0)
    """
    arrs = []
    for name, X in (("P", P), ("A", A), ("B", B), ("C", C)):
        X = np.asarray(X, dtype=np.float64)
        if X.ndim != 2 or X.shape[1] != 3:
            raise InvalidArgumentError(
                f"point_triangle_closest: {name} must be (k,3) floats, got {X.shape}")
        check_finite_rows(X, where="point_triangle_closest", what=f"rows of {name}")
        arrs.append(X)
    P, A, B, C = arrs
    if not (P.shape[0] == A.shape[0] == B.shape[0] == C.shape[0]):
        raise InvalidArgumentError(
            "point_triangle_closest: P, A, B, C must have the same number of rows, got "
            f"{P.shape[0]}, {A.shape[0]}, {B.shape[0]}, {C.shape[0]}")
    D = triangle_rows(A, B, C)
    v, w, _ = closest_on_triangles(P[:, 0].copy(), P[:, 1].copy(), P[:, 2].copy(), D)
    bary = _bary(v, w)
    point = A + v[:, None] * (B - A) + w[:, None] * (C - A)
    return TriangleClosest(point, bary, np.linalg.norm(P - point, axis=1))


def _bary(v, w):
    bary = np.stack([1.0 - v - w, v, w], axis=1)
    return np.clip(bary, 0.0, 1.0, out=bary)


def closest_result(rows, face, t, v, w, d2):
    """The :class:`ClosestPoints` of kernel results: triangles ``t`` (q,) of
    the kernel ``rows`` (16, m) (:func:`triangle_rows`; an index's
    :class:`IndexTables` ``rows``), whose faces are ``face`` (m,), the
    kernel's ``v, w`` and squared distances ``d2`` (q,) (the point
    ``A + v ab + w ac``, barycentric coordinates ``(1-v-w, v, w)`` clipped
    to [0, 1])."""
    point = np.empty((t.shape[0], 3))
    for k in range(3):
        point[:, k] = (np.take(rows[k], t) + v * np.take(rows[3 + k], t)
                       + w * np.take(rows[6 + k], t))
    return ClosestPoints(face[t].astype(np.int64), point, _bary(v, w), np.sqrt(d2))


# --- small vectorised helpers --------------------------------------------------------------------


def _spread_bits(x):
    """Spread the low 21 bits of uint64 ``x`` to every third bit (for Morton codes)."""
    x = x & np.uint64(0x1FFFFF)
    x = (x | (x << np.uint64(32))) & np.uint64(0x1F00000000FFFF)
    x = (x | (x << np.uint64(16))) & np.uint64(0x1F0000FF0000FF)
    x = (x | (x << np.uint64(8))) & np.uint64(0x100F00F00F00F00F)
    x = (x | (x << np.uint64(4))) & np.uint64(0x10C30C30C30C30C3)
    x = (x | (x << np.uint64(2))) & np.uint64(0x1249249249249249)
    return x


def morton_codes(X, lo, extent):
    """63-bit Morton codes of points X (clamped to the box ``lo + [0, extent]``).
    An axis thinner than 1e-12 of the widest counts as flat (code bits 0)."""
    extent = np.asarray(extent, dtype=np.float64)
    live = extent > 1e-12 * extent.max()
    scale = np.zeros(3)
    scale[live] = ((1 << 21) - 1) / extent[live]
    q = np.clip((X - lo) * scale, 0, (1 << 21) - 1).astype(np.uint64)
    return (_spread_bits(q[:, 0]) | (_spread_bits(q[:, 1]) << np.uint64(1))
            | (_spread_bits(q[:, 2]) << np.uint64(2)))


# --- the index ---------------------------------------------------------------------------------

def _longest_run(x):
    """Length of the longest run of equal values in the sorted array ``x``."""
    if x.size == 0:
        return 0
    starts = np.flatnonzero(np.r_[True, x[1:] != x[:-1], True])
    return int(np.diff(starts).max())


def _first_of_each_triangle(V, F):
    """Mask of the faces of ``F`` whose three positions (in any order) no
    earlier face has: exact duplicates of a triangle's geometry are dropped."""
    rows = np.ascontiguousarray(V + 0.0).view(np.dtype((np.void, 24))).ravel()
    _, pos = np.unique(rows, return_inverse=True)
    P = np.sort(pos.ravel()[F], axis=1)
    _, first = np.unique(P, axis=0, return_index=True)
    keep = np.zeros(F.shape[0], dtype=bool)
    keep[first] = True
    return keep


def _used_box(V, F):
    """The lower and upper corners (3,) of the box of the vertices ``F`` uses."""
    used = np.zeros(V.shape[0], dtype=bool)
    used[F.ravel()] = True
    Vu = V[used]
    return Vu.min(axis=0), Vu.max(axis=0)


def _corners(V, F):
    """The corners ``A, B, C`` (k,3) of the triangles ``F`` (k,3)."""
    return (np.take(V, F[:, 0], axis=0), np.take(V, F[:, 1], axis=0),
            np.take(V, F[:, 2], axis=0))


def _box_of(A, B, C):
    """The triangles' boxes: lower and upper corners (k,3)."""
    lo = np.minimum(A, B)
    np.minimum(lo, C, out=lo)
    hi = np.maximum(A, B)
    np.maximum(hi, C, out=hi)
    return lo, hi


def triangle_boxes(V, F):
    """The boxes of the triangles ``F`` (k,3) over positions ``V`` (n,3):
    lower and upper corners, each (k,3) (new arrays)."""
    return _box_of(*_corners(V, F))


def _largest_sides(V, F, out):
    """Each triangle's largest box side, into ``out`` (k,)."""
    lo, hi = triangle_boxes(V, F)
    hi -= lo
    np.maximum(np.maximum(hi[:, 0], hi[:, 1], out=out), hi[:, 2], out=out)


def _area_edge(V, F):
    """The edge of an equilateral triangle of the geometric mean area of
    the triangles ``F`` with an area (of an even sample of 4,096, measured
    unit-free; 0 for none): the cells' size where long slivers make the mean
    box side no measure of how finely the surface is cut (a CAD cylinder,
    half its triangles its full height long and a thousandth of it wide, the
    other half a fan of needles on each cap: its mean box side made one cell
    of every triangle, and a query scanned hundreds of them: 20,000 points
    near a 4,000-face one took 5.4 s and 2.6 GB, near a 24,000-face one more
    than 24 GB; 0.8 s and 0.3 GB with cells of this size)."""
    # (scaled by s: no underflow at 1e-200, no overflow at 1e200; the true areas are s^2 x)
    N, s = scaled_area_normals(V, F[::max(1, F.shape[0] // 4096)])
    twice = row_norms(N)
    twice = twice[twice > 0]
    if not twice.size:
        return 0.0
    return s * float(np.sqrt(2.0 * np.exp(np.log(twice).mean()) / np.sqrt(3.0)))


def _long_thin(V, F, ext):
    """(m,) bool: the triangles ``F`` (largest box sides ``ext``) more than
    twice as long as the median one (of an even sample of 4,096) and no
    taller than ``_THIN_HEIGHT`` of their longest edge (only those long ones
    are measured: the needles that could widen the cells)."""
    thin = np.zeros(ext.shape[0], dtype=bool)
    if ext.size:
        long = np.flatnonzero(ext > 2.0 * np.median(ext[::max(1, ext.shape[0] // 4096)]))
        edge = _LongestEdges.of(*_corners(V, F[long]))
        thin[long] = edge.height2 < _THIN_HEIGHT ** 2 * edge.length2
    return thin


class _LongestEdges(NamedTuple):
    """Each triangle's longest edge and its height over it (every point of a
    triangle lies within that height of that edge)."""

    start: np.ndarray    #: (k,3) one end of the edge
    edge: np.ndarray     #: (k,3) the edge, to its other end
    length2: np.ndarray  #: (k,) its squared length
    height2: np.ndarray  #: (k,) the squared height over it (0 for a point)

    @classmethod
    def of(cls, A, B, C, nrm=None):
        """Of the triangles ``(A, B, C)`` (each (k,3); ``nrm`` their area normals when known)."""
        nrm = cross_rows(B - A, C - A) if nrm is None else nrm
        edges = np.stack([B - A, C - B, A - C], axis=1)                # (k,3 edges,3)
        length2 = np.einsum("ijk,ijk->ij", edges, edges)
        longest = np.argmax(length2, axis=1)
        at = np.arange(A.shape[0])
        l2 = length2[at, longest]
        height2 = np.einsum("ij,ij->i", nrm, nrm) / np.where(l2 > 0, l2, 1.0)
        return cls(np.stack([A, B, C], axis=1)[at, longest], edges[at, longest], l2, height2)


def _covered_needles(V, F, thin, size):
    """(m,) bool: the triangles of ``F`` that are flat (no taller than
    ``_FLAT_HEIGHT * size`` over their longest edge) and whose longest edge
    lies inside another flat one's on the same line (both within that
    height of it): every point of such a triangle is within twice that
    height of the other one, so dropping it changes no distance by more.
    Of identical segments the first is kept. Only the ``thin`` ones are
    measured unless an even sample of 4,096 triangles has a flat one (a
    region collapsed onto a line can be most of a mesh: its needles are
    then no longer than the median triangle)."""
    drop = np.zeros(F.shape[0], dtype=bool)
    tol = _FLAT_HEIGHT * size
    sample = _LongestEdges.of(*_corners(V, F[::max(1, F.shape[0] // 4096)]))
    rows = np.arange(F.shape[0]) if (sample.height2 <= tol * tol).any() else np.flatnonzero(thin)
    rows, P, E = _flat_among(V, F, rows, tol)
    if rows.size < 2:
        return drop
    group, a, b, tight = _on_lines(P, E, size, tol)
    if np.count_nonzero(tight) < 2:
        return drop
    rows, group, lo, hi = rows[tight], group[tight], np.minimum(a, b)[tight], np.maximum(a, b)[tight]
    order = np.lexsort((-hi, lo, group))
    _, rank = np.unique(hi, return_inverse=True)
    key = (group * np.int64(rank.max() + 1) + rank.ravel())[order]
    # sorted by group, then start: one is inside an earlier one of its group when the
    # largest end before it (a running maximum of keys stays within a group) reaches its own
    before = np.concatenate([[-1], np.maximum.accumulate(key)[:-1]])
    drop[rows[order[before >= key]]] = True
    return drop


def _flat_among(V, F, rows, tol):
    """The triangles among ``rows`` of ``F`` no taller than ``tol`` over their
    longest edge (of positive length): (rows, one end of that edge, the edge),
    measured a block at a time on the worker threads (a scan with 0.2% of its
    1.1M faces flat measured them all at once: 0.56 s, a quarter of its index
    build; whole-mesh temporaries)."""
    def part(span):
        r = rows[span[0]:span[1]]
        edge = _LongestEdges.of(*_corners(V, F[r]))
        flat = (edge.height2 <= tol * tol) & (edge.length2 > 0)
        return r[flat], edge.start[flat], edge.edge[flat]
    parts = run_each(part, blocks(rows.shape[0], _BUILD_BLOCK), threads=rows.shape[0] >= _THREADED_BUILD)
    if not parts:
        return rows, np.zeros((0, 3)), np.zeros((0, 3))
    return tuple(np.concatenate(col) for col in zip(*parts))


def _on_lines(P, E, size, tol):
    """The segments ``P`` -> ``P + E`` (k,3) grouped by line (rounded
    direction and offset, ``_LINE_ROUNDING``): (group (k,) int64, the ends'
    places a, b along the group's line (its first segment's), and whether
    both ends lie within ``tol`` of that line)."""
    U = unit_rows(E)
    axis = np.argmax(np.abs(U), axis=1)
    U *= np.sign(U[np.arange(U.shape[0]), axis])[:, None]       # one direction per line
    foot = P - np.einsum("ij,ij->i", P, U)[:, None] * U            # the line's point nearest 0
    key = np.round(np.hstack([U, foot / size]) / _LINE_ROUNDING).astype(np.int64)
    _, first, group = np.unique(key, axis=0, return_index=True, return_inverse=True)
    group = group.ravel()
    p0, u0 = P[first][group], U[first][group]
    ends = []
    for X in (P - p0, P + E - p0):
        t = np.einsum("ij,ij->i", X, u0)
        off = X - t[:, None] * u0
        ends.append((t, np.einsum("ij,ij->i", off, off) <= tol * tol))
    (a, ok_a), (b, ok_b) = ends
    return group, a, b, ok_a & ok_b


def _cell_ranges(A, B, C, lo, h, dims):
    """Each triangle's first cell (k,3) and cells per axis (k,3) of its box."""
    tlo, thi = _box_of(A, B, C)
    c0 = _cell_range(tlo, lo, h, dims)
    nr = _cell_range(thi, lo, h, dims)
    nr -= c0
    nr += 1
    return c0, nr


def _morton_order(V, F, lo, extent):
    """The triangles of ``F`` in Morton order of their boxes' centres
    (stable), a block at a time; where more than ``_MAX_SAME_CODE`` share a
    code (a degenerate cluster: faces on a few points), one of each distinct
    triangle only, or every query would scan them all."""
    m = F.shape[0]
    codes = np.empty(m, dtype=np.uint64)

    def code(span):
        tlo, thi = triangle_boxes(V, F[span[0]:span[1]])
        tlo += thi
        tlo *= 0.5
        codes[span[0]:span[1]] = morton_codes(tlo, lo, extent)
    run_each(code, blocks(m, _BUILD_BLOCK), threads=m >= _THREADED_BUILD)
    order = np.argsort(codes, kind="stable")
    if _longest_run(codes[order]) > _MAX_SAME_CODE:
        order = order[_first_of_each_triangle(V, F[order])]
    return order


def _bounding_rows(A, B, C, n):
    """The two lower-bound tables of the triangles ``(A, B, C)`` (each (m,3)) with
    unit normals ``n`` (m,3) (zero for thin triangles, as in :func:`triangle_rows`).

    ``ball`` (4, m): centroid c and radius r of a sphere holding the triangle;
    ``prism`` (16, m): n, the three in-plane outward edge normals m_AB, m_BC,
    m_CA, their distances o_k from c, and a rounding allowance e. For a point
    at d = p - c the distance to the triangle is at least ``|d| - r`` and
    ``sqrt(max(|d.n| - e, 0)^2 + max(max_k d.m_k - o_k - e, 0)^2)`` (height
    above the plane, lateral distance beyond the farthest-out edge line).
    r, o_k and e carry margins far above rounding. Thin triangles get
    n = m_k = 0, so their second bound is 0.
    """
    centre = (A + B + C) / 3.0
    r = np.sqrt(np.max([np.einsum("ij,ij->i", X - centre, X - centre) for X in (A, B, C)],
                       axis=0))
    scale = np.abs(centre).max(axis=1) + r
    r = r * (1 + 1e-9) + 1e-12 * scale
    prism = np.empty((16, A.shape[0]))
    prism[0:3] = n.T
    corners = (A, B, C)
    # edge k runs from corner k to corner k+1; (edge x n) points away from the third corner
    for k in range(3):
        a, b = corners[k] - centre, corners[(k + 1) % 3] - centre
        mk = unit_rows(cross_rows(b - a, n))
        o = np.maximum(np.einsum("ij,ij->i", a, mk), np.einsum("ij,ij->i", b, mk))
        prism[3 + 3 * k:6 + 3 * k] = mk.T
        prism[12 + k] = o * (1 + 1e-9) + 1e-9 * r
    prism[15] = 1e-12 * scale
    return np.ascontiguousarray(np.vstack([centre.T, r])), prism


def _capsule_rows(A, B, C, S, ball, first):
    """The capsule bound's rows of the needles among the triangles ``(A, B,
    C)`` (numbered from ``first``; ``S`` their rows |ab|^2, |ac|^2, ab.ac of
    :func:`triangle_rows`, ``ball`` their bounding spheres (4, k)): those no
    taller over their longest edge than ``_CAPSULE_HEIGHT`` of its length.
    Every point of a triangle lies within its height h of its longest edge,
    so a point's distance to the triangle is at least its distance to that
    edge less h. Returns (triangles (j,), rows (7, j): the edge's start
    relative to the centroid, the edge, h with a rounding margin)."""
    s_ab, s_ac, s_abac = S
    longest = np.maximum(np.maximum(s_ab, s_ac), s_ab + s_ac - 2.0 * s_abac)
    area2 = np.maximum(s_ab * s_ac - s_abac * s_abac, 0.0)          # |ab x ac|^2
    rows = np.flatnonzero(area2 <= _CAPSULE_HEIGHT ** 2 * longest * longest)
    edge = _LongestEdges.of(A[rows], B[rows], C[rows])
    c, r = ball[:3, rows], ball[3, rows]
    out = np.empty((7, rows.size))
    out[0:3] = edge.start.T - c
    out[3:6] = edge.edge.T
    scale = np.abs(c).max(axis=0) + r
    out[6] = np.sqrt(edge.height2) * (1 + 1e-9) + 1e-9 * r + 1e-12 * scale
    return rows + first, out


def _capsule_gap(X, C):
    """How far beyond its capsule each point ``X`` (3, k) lies: its distance
    to the segment of ``C`` (7, k) less the radius (negative inside), for
    the rows :func:`_capsule_rows` and :func:`_rod_rows` make (the segment's
    start and the segment, in the points' frame, and the radius)."""
    _, d2 = _segment(X[0], X[1], X[2], C[0], C[1], C[2], C[3], C[4], C[5])
    gap = np.sqrt(d2)
    gap -= C[6]
    return gap


def _capsule_table(m, parts):
    """The capsule bound's tables from the blocks' :func:`_capsule_rows`:
    each triangle's column in the rows (-1 for none; None when no triangle
    has one) and the rows (7, j)."""
    rows = np.concatenate([p[0] for p in parts]) if parts else np.zeros(0, dtype=np.int64)
    if rows.size == 0:
        return None, np.zeros((7, 0))
    at = np.full(m, -1, dtype=np.int32 if m < 2**31 else np.int64)
    at[rows] = np.arange(rows.size)
    return at, np.concatenate([p[1] for p in parts], axis=1)


#: BVH nodes per block of :func:`_leaf_cylinders` (its temporaries stay in cache)
_CYLINDER_BLOCK = 4096


def _leaf_cylinders(Xg, Ng, valid):
    """The cylinder bounds of the BVH nodes of one of the lowest levels from
    their triangles' corners ``Xg`` (g, 3 * group, 3), area normals ``Ng``
    (g, group, 3) and which triangles are real ``valid`` (g, group), and
    their rods (:func:`_rod_rows`): (centre, unit axis, lateral radius, half
    height, size, real triangles, summed normal, rod rows (7, g)), node by
    node as :meth:`TriangleIndex._build_slabs` defines them, blocks of nodes
    on the worker threads (the 2M faces of a cage at five levels: the
    temporaries of the whole level were 144 MB an operation, and building
    the hierarchy took 4.7 s)."""
    g = Xg.shape[0]
    c, n, nsum = np.empty((g, 3)), np.empty((g, 3)), np.empty((g, 3))
    r, t, size = np.empty(g), np.empty(g), np.empty(g)
    rod = np.empty((7, g))

    def block(a, b):
        X = Xg[a:b]
        c[a:b] = X.mean(axis=1)
        nsum[a:b] = Ng[a:b].sum(axis=1)
        n[a:b] = unit_rows(nsum[a:b])
        rel = X - c[a:b, None, :]
        h = np.einsum("gkj,gj->gk", rel, n[a:b])
        lat2 = np.einsum("gkj,gkj->gk", rel, rel) - h * h
        r[a:b] = np.sqrt(np.maximum(lat2.max(axis=1), 0.0))
        t[a:b] = np.abs(h).max(axis=1)
        size[a:b] = np.abs(rel).max(axis=(1, 2))
        rod[:, a:b] = _rod_rows(c[a:b], rel, size[a:b])
    run_blocks(block, blocks(g, _CYLINDER_BLOCK))
    return c, n, r, t, size, valid.sum(axis=1), nsum, rod


def _rod_rows(c, rel, size):
    """Rods (capsules) holding the BVH nodes of a low level: per node, the
    segment along the direction from its centre ``c`` (g,3) to its farthest
    point (``rel`` (g,k,3): its triangles' corners less ``c``) that spans the
    corners' projections, and the largest distance of a corner from it (with
    rounding margins; ``size`` the corners' largest offset). (7, g): the
    segment's start (3), the segment (3), the radius. A node of needles side
    by side (a fan's) is a thin rod where its box and its cylinder around the
    summed normal are as wide as the needles are long."""
    g = rel.shape[0]
    d2 = np.einsum("gkj,gkj->gk", rel, rel)
    axis = unit_rows(rel[np.arange(g), np.argmax(d2, axis=1)])
    along = np.einsum("gkj,gj->gk", rel, axis)
    off = rel - along[:, :, None] * axis[:, None, :]      # (not d2 - along^2: it cancels)
    radius = np.sqrt(np.einsum("gkj,gkj->gk", off, off).max(axis=1))
    lo, hi = along.min(axis=1), along.max(axis=1)
    scale = np.abs(c).max(axis=1) + size
    radius = radius * (1 + 1e-9) + 1e-9 * size + 1e-12 * scale
    return np.ascontiguousarray(np.vstack([(c + lo[:, None] * axis).T,
                                           ((hi - lo)[:, None] * axis).T, radius]))


def _cell_range(X, lo, h, dims):
    """Grid cell (k,3) int64 of the points ``X`` (k,3), clipped to the grid:
    ``clip(floor((X - lo) / h), 0, dims - 1)``, with one float temporary."""
    t = X - lo
    t /= h
    np.floor(t, out=t)
    cell = t.astype(np.int64)
    return np.clip(cell, 0, dims - 1, out=cell)


def _plane_cells(A, B, C, sides, ext, c0, nr, lo, h, dims, first, dtype):
    """The grid references of the triangles ``(A, B, C)`` (numbered from
    ``first``; ``sides`` |AB| |AC|, ``ext`` their boxes' largest sides): every cell of each one's
    box (first cell ``c0``, ``nr`` cells per axis, in x, then y, then z
    order) that its plane passes through, conservatively: with the
    unnormalised normal n and o = n.A, a cell whose centre x has
    |n.x - o| > h/2 (|nx| + |ny| + |nz|) plus a rounding margin is left out.
    The margin also covers the rounding of n itself, about eps |AB| |AC|: on
    a needle with no height to speak of, n is all rounding and points
    anywhere (a needle across a sphere was left out of most cells it crosses).
    Returns (cell, triangle), in triangle order, as ``dtype``; triangles
    whose boxes hold more than ``_CANDIDATE_CELLS`` cells in all are taken a
    run at a time (a logo's fan of 20k needles across a box's side: 12M
    candidates, 2.8 GB at once)."""
    box = np.prod(nr, axis=1)
    if box.sum() > _CANDIDATE_CELLS and box.size > 1:
        ends = np.searchsorted(np.cumsum(box), np.arange(1, box.sum() // _CANDIDATE_CELLS + 1)
                               * _CANDIDATE_CELLS, side="right")
        cuts = sorted_unique(np.concatenate([[0], np.maximum(ends, 1), [box.size]]))
        parts = [_plane_cells(A[a:b], B[a:b], C[a:b], sides[a:b], ext[a:b], c0[a:b], nr[a:b], lo,
                              h, dims, first + a, dtype) for a, b in zip(cuts[:-1], cuts[1:])]
        return tuple(np.concatenate(col) for col in zip(*parts))
    nrm = cross_rows(B - A, C - A)
    off = np.einsum("ij,ij->i", nrm, A)
    l1 = np.abs(nrm).sum(axis=1)
    reach = 0.5 * h * l1 + PRUNE_SLACK * (l1 * (np.abs(A).max(axis=1) + ext + 2 * h)
                                          + sides * (ext + 2 * h))
    needles = _needles(A, B, C, box, h, nrm)
    tri, cells = _slab_cells(nrm, off, reach, c0, nr, lo, h,
                             None if needles is None else _needle_reach(needles, c0, nr, lo, h, ext))
    if needles is not None:
        keep = _near_needle(needles, tri, lo + h * (cells + 0.5), h, ext)
        tri, cells = tri[keep], cells[keep]
    cell = cells[:, 0] + dims[0] * (cells[:, 1] + dims[1] * cells[:, 2])
    return cell.astype(dtype), (tri + first).astype(dtype)


def _slab_cells(nrm, off, reach, c0, nr, lo, h, lines=None):
    """The cells of each triangle's box (first cell ``c0``, ``nr`` per axis)
    whose centre x has ``|nrm . x - off| <= reach``: those its plane's slab
    crosses. Enumerated by columns along the axis ``w`` of each normal's
    largest component, where the slab is a range of cells found from the
    plane's height over the column's centre (``|nrm_w| |x_w - w_c| <=
    reach``), never the box's every cell: a triangle whose box spans 200
    cells each way had 8M candidates of which 120k were kept (a scan spike's
    five long faces: 3 GB). A triangle without a normal keeps its whole box.
    With ``lines`` (a :class:`_NeedleReach`), a needle's columns are only
    those whose centre lies within its reach of its longest edge, seen
    along ``w`` (:func:`_line_columns`; the cells :func:`_near_needle` keeps
    are among them): a cone's 10k spokes across a 23-cell grid had 91
    candidates each, 27 kept.
    Returns the triangle (k,) of each cell and the cells (k,3) (x, y, z)."""
    w = np.argmax(np.abs(nrm), axis=1)
    flat = np.abs(nrm[np.arange(w.size), w]) == 0        # no normal: every cell of the box
    w[flat] = 2
    u, v = (w + 1) % 3, (w + 2) % 3
    rows = np.arange(w.size)
    nu, nv, nw = nr[rows, u], nr[rows, v], nr[rows, w]
    span = np.where(flat, nw, 1)                          # cells per column taken whole
    boxed = nu * nv * span
    line = np.zeros(w.size, dtype=bool) if lines is None else lines.is_line & ~flat
    boxed[line] = 0
    local, tri = ragged_ranges(np.zeros(w.size, dtype=np.int64), boxed)
    cu = c0[tri, u[tri]] + local % nu[tri]
    cv = c0[tri, v[tri]] + (local // nu[tri]) % nv[tri]
    if line.any():
        lt, lu, lv = _line_columns(lines, np.flatnonzero(line), u, v, c0, nu, nv, lo, h)
        order = np.argsort(np.concatenate([tri, lt]), kind="stable")   # (in triangle order)
        tri, cu, cv = (np.concatenate(x)[order] for x in ((tri, lt), (cu, lu), (cv, lv)))
        local = np.concatenate([local, np.zeros(lt.size, dtype=np.int64)])[order]
    t_u, t_v, t_w = u[tri], v[tri], w[tri]
    first_w = c0[tri, t_w]
    x0 = lo + 0.5 * h
    n = nrm[tri]
    ns = np.take_along_axis
    n_u, n_v, n_w = (ns(n, a[:, None], axis=1)[:, 0] for a in (t_u, t_v, t_w))
    centre_u, centre_v = x0[t_u] + cu * h, x0[t_v] + cv * h
    with np.errstate(divide="ignore", invalid="ignore"):
        wc = (off[tri] - n_u * centre_u - n_v * centre_v) / n_w
        half = reach[tri] / np.abs(n_w)
    # the column's cells with |w - wc| <= half (a hair wider: the test before was on products)
    k_lo = np.ceil((wc - half * (1 + 1e-12) - x0[t_w]) / h)
    k_hi = np.floor((wc + half * (1 + 1e-12) - x0[t_w]) / h)
    last_w = first_w + nr[tri, t_w] - 1
    flat_col = flat[tri]
    k_lo = np.where(flat_col, first_w + local // (nu[tri] * nv[tri]), np.maximum(k_lo, first_w))
    k_hi = np.where(flat_col, k_lo, np.minimum(k_hi, last_w))
    count = np.where(k_hi >= k_lo, k_hi - k_lo + 1, 0).astype(np.int64)
    step, col = ragged_ranges(np.zeros(count.size, dtype=np.int64), count)
    cells = np.empty((col.size, 3), dtype=np.int64)
    at = np.arange(col.size)
    cells[at, t_u[col]] = cu[col]
    cells[at, t_v[col]] = cv[col]
    cells[at, t_w[col]] = k_lo[col].astype(np.int64) + step
    return tri[col], cells


class _NeedleReach(NamedTuple):
    """The needles among some triangles as lines: each one's longest edge
    and how far from it :func:`_near_needle` keeps a cell centre, at most."""

    is_line: np.ndarray    #: (k,) bool over the triangles
    P: np.ndarray          #: (k,3) one end of the longest edge
    U: np.ndarray          #: (k,3) the edge (to its other end)
    reach: np.ndarray      #: (k,) the distance bound (a margin wider than the test's)


def _needle_reach(needles, c0, nr, lo, h, ext):
    """The :class:`_NeedleReach` of ``needles`` (a :class:`_Needles`) of
    triangles whose boxes start at cell ``c0`` and span ``nr`` cells:
    :func:`_near_needle`'s reach with its rounding slack doubled, from the
    largest coordinate of any cell centre in the box."""
    far = np.maximum(np.abs(lo + h * (c0 + 0.5)), np.abs(lo + h * (c0 + nr - 0.5))).max(axis=1)
    return _NeedleReach(needles.is_needle, needles.P, needles.U,
                        _needle_test_reach(needles.height, h, far, ext, 2 * PRUNE_SLACK))


def _line_columns(lines, rows, u, v, c0, nu, nv, lo, h):
    """The columns (along each triangle's axis ``w``) of the needles ``rows``
    whose centres lie within ``lines.reach`` of the needle's longest edge
    in the plane of the axes ``u``, ``v`` (seen along ``w``, closer than in
    space): for each column of the box along ``u``, the cells along ``v``
    from the edge's lowest to highest ``v`` where its ``u`` is within the
    reach of the column's, each widened by the reach. Returns the triangle,
    ``u`` and ``v`` cells of each column, in triangle order."""
    i, g = ragged_ranges(np.zeros(rows.size, dtype=np.int64), nu[rows])
    t = rows[g]
    tu, tv = u[t], v[t]
    x0 = lo + 0.5 * h
    cu = c0[t, tu] + i
    Pu, Pv = lines.P[t, tu], lines.P[t, tv]
    Uu, Uv = lines.U[t, tu], lines.U[t, tv]
    r = lines.reach[t]
    x = x0[tu] + cu * h - Pu
    with np.errstate(divide="ignore", invalid="ignore"):
        s1, s2 = (x - r) / Uu, (x + r) / Uu
    along = Uu != 0
    s_lo = np.where(along, np.maximum(np.minimum(s1, s2), 0.0), np.where(np.abs(x) <= r, 0.0, 2.0))
    s_hi = np.where(along, np.minimum(np.maximum(s1, s2), 1.0), 1.0)
    v1, v2 = Pv + s_lo * Uv, Pv + s_hi * Uv
    k_lo = np.ceil((np.minimum(v1, v2) - r - x0[tv]) / h)
    k_hi = np.floor((np.maximum(v1, v2) + r - x0[tv]) / h)
    first = c0[t, tv]
    k_lo = np.maximum(k_lo, first).astype(np.int64)
    k_hi = np.minimum(k_hi, first + nv[t] - 1).astype(np.int64)
    count = np.where((s_lo <= s_hi) & (k_hi >= k_lo), k_hi - k_lo + 1, 0)
    j, c = ragged_ranges(np.zeros(count.size, dtype=np.int64), count)
    return t[c], cu[c], k_lo[c] + j


class _Needles(NamedTuple):
    """The needles among some triangles (:func:`_needles`): each one's
    longest edge and height over it."""

    is_needle: np.ndarray  #: (k,) bool over the triangles
    P: np.ndarray          #: (k,3) one end of each triangle's longest edge
    U: np.ndarray          #: (k,3) the edge (to its other end)
    height: np.ndarray     #: (k,) the triangle's height over it


def _needles(A, B, C, cnt, h, nrm=None):
    """The :class:`_Needles` of the triangles ``(A, B, C)`` (boxes of ``cnt``
    cells of side ``h``; their area normals ``nrm`` when known): those no
    taller than ``_NEEDLE_HEIGHT h`` over their longest edge whose box spans
    more than ``_LINE_CELLS`` cells; None when there is none."""
    rows = np.flatnonzero(cnt > _LINE_CELLS)
    if rows.size == 0:
        return None
    edge = _LongestEdges.of(A[rows], B[rows], C[rows], None if nrm is None else nrm[rows])
    height = np.sqrt(edge.height2)
    needle = height <= _NEEDLE_HEIGHT * h
    if not needle.any():
        return None
    is_needle = np.zeros(cnt.shape[0], dtype=bool)
    is_needle[rows[needle]] = True
    k = cnt.shape[0]
    return _Needles(is_needle, _spread(edge.start, rows, k), _spread(edge.edge, rows, k),
                    _spread(height, rows, k))


def _spread(x, rows, k):
    """``x`` (r, ...) placed at ``rows`` of a zero array of ``k`` rows."""
    out = np.zeros((k,) + x.shape[1:], dtype=x.dtype)
    out[rows] = x
    return out


def _near_needle(needles, tri, X, h, ext):
    """(q,) bool: the cell centres ``X`` (q,3) of the references ``tri`` are
    not of a needle, or lie within the needle's height plus half a cell's
    diagonal of its longest edge (every point of a triangle lies within its
    height of its longest edge; a rounding margin added)."""
    ok = ~needles.is_needle[tri]
    k = np.flatnonzero(~ok)
    t = tri[k]
    U = needles.U[t]
    D = X[k] - needles.P[t]
    u2 = np.einsum("ij,ij->i", U, U)
    s = np.clip(np.einsum("ij,ij->i", D, U) / np.where(u2 > 0, u2, 1.0), 0.0, 1.0)
    D -= s[:, None] * U
    reach = _needle_test_reach(needles.height[t], h, np.abs(X[k]).max(axis=1), ext[t])
    ok[k] = np.einsum("ij,ij->i", D, D) <= reach * reach
    return ok


def _needle_test_reach(height, h, far, ext, slack=PRUNE_SLACK):
    """How far from a needle's longest edge :func:`_near_needle` keeps a cell
    centre: the needle's ``height`` plus half a cell's diagonal (cells of
    side ``h``), plus ``slack`` of the centre's largest coordinate ``far``
    (or a bound of it), the needle's box side ``ext`` and two cells."""
    return height + 0.5 * np.sqrt(3.0) * h + slack * (far + ext + 2 * h)


def _box_gap2(X, lo, hi):
    """Squared distances of the points ``X`` to the boxes ``lo``-``hi``
    (broadcast over the leading axes; the last is x, y, z)."""
    gap = np.maximum(lo - X, 0) + np.maximum(X - hi, 0)
    gap *= gap
    return gap[..., 0] + gap[..., 1] + gap[..., 2]


def _box_corners(X):
    """The 8 corners (8,3) of the box of the points ``X`` (k,3): corner
    ``i`` takes the upper side along the axes of its bits (0 the lower
    corner, 7 the upper)."""
    lo, hi = X.min(axis=0), X.max(axis=0)
    pick = np.array([[i >> k & 1 for k in range(3)] for i in range(8)], dtype=bool)
    return np.where(pick, hi, lo)


class _Outliers(NamedTuple):
    """The few faces far out of the rest's box that an index keeps out of its
    grid (``_OUTLIER_*``), measured against every query apart."""

    inliers: np.ndarray   #: (k,) int64 faces of F in the grid
    face: np.ndarray      #: (r,) int64 faces of F kept out
    rows: np.ndarray      #: (16, r) their kernel rows (:func:`triangle_rows`)
    lo: np.ndarray        #: (r,3) their boxes' lower corners
    hi: np.ndarray        #: (r,3) ... and upper corners
    normal: np.ndarray    #: (3, r) their unit normals (zero for a face without one)
    offset: np.ndarray    #: (r,) ``normal . A`` (a height over the plane: ``p . n - offset``)
    size: float           #: their largest coordinate (in absolute value)

    @classmethod
    def of(cls, V, F, lo, hi):
        """The outliers of the mesh ``(V, F)`` (its faces' box ``lo``-``hi``),
        or None (none, or too many to be outliers)."""
        m = F.shape[0]
        step = max(1, m // _OUTLIER_SAMPLE)
        tlo, thi = triangle_boxes(V, F[::step])
        centre = 0.5 * (tlo + thi)
        bulk_lo, bulk_hi = np.quantile(centre, [_OUTLIER_TAIL, 1 - _OUTLIER_TAIL], axis=0)
        grow = _OUTLIER_MARGIN * float((bulk_hi - bulk_lo).max())
        if not float((hi - lo).max()) > _OUTLIER_GROWTH * (float((bulk_hi - bulk_lo).max())
                                                           + 2 * grow):
            return None
        tlo, thi = triangle_boxes(V, F)
        out = ((tlo < bulk_lo - grow) | (thi > bulk_hi + grow)).any(axis=1)
        face = np.flatnonzero(out)
        if face.size == 0 or face.size > min(_OUTLIER_SHARE * m, _OUTLIER_MAX):
            return None
        A, B, C = _corners(V, F[face])
        n = unit_rows(cross_rows(B - A, C - A))
        return cls(np.flatnonzero(~out), face, triangle_rows(A, B, C), tlo[face], thi[face],
                   np.ascontiguousarray(n.T), np.einsum("ij,ij->i", n, A),
                   float(max(np.abs(tlo[face]).max(), np.abs(thi[face]).max())))

    def combined(self, P, lo, hi, search):
        """The closest points of ``P`` among every face: ``search(X)`` gives
        them among the others, all inside the box ``lo``-``hi``. Points
        outside that box and nearer some outlier than the box (a fit's
        samples along a scan's spike, whose search among the others is a
        far query, 3 ms each) are answered by the outliers alone."""
        gap2 = _box_gap2(P, lo, hi)
        out = np.flatnonzero(gap2 > 0)
        q, t, v, w, e2 = self._nearest(P[out], gap2[out])
        near = e2 < gap2[out[q]]
        apart = out[q[near]]
        if apart.size == 0:                 # (no copy of the points to search)
            return self.closer(P, search(P))
        rest = np.ones(P.shape[0], dtype=bool)
        rest[apart] = False
        rest = np.flatnonzero(rest)
        hit = self.closer(P[rest], search(P[rest]))
        alone = closest_result(self.rows, self.face, t[near], v[near], w[near], e2[near])
        result = ClosestPoints(*(np.empty((P.shape[0],) + a.shape[1:], dtype=a.dtype)
                                 for a in hit))
        for whole, part_rest, part_apart in zip(result, hit, alone):
            whole[rest] = part_rest
            whole[apart] = part_apart
        return result

    def closer(self, P, hit):
        """``hit`` (:class:`ClosestPoints` of the points ``P`` among the other
        faces) where an outlier is closer (exactly as close: the lower face)."""
        d2 = hit.distance ** 2
        q, t, v, w, e2 = self._nearest(P, d2)
        take = (e2 < d2[q]) | ((e2 == d2[q]) & (self.face[t] < hit.face[q]))
        if not take.any():
            return hit
        q, near = q[take], closest_result(self.rows, self.face, t[take], v[take], w[take], e2[take])
        out = ClosestPoints(*(np.array(a) for a in hit))
        for a, b in zip(out, near):
            a[q] = b
        return out

    def _nearest(self, P, bound2):
        """Each point of ``P``'s closest outlier among those within its
        squared distance ``bound2`` (the lowest face among exactly equal
        ones), for the points with any: ``(q, t, v, w, d2)``, the points'
        rows, the outliers' rows and the kernel's results. Blocks of points
        are bounded as a whole first (:meth:`_block_bounds`), then each point
        (:meth:`_point_bounds`)."""
        parts = [tuple(np.zeros(0, dtype=dt) for dt in (np.int64,) * 2 + (float,) * 3)]
        PT = np.ascontiguousarray(P.T)
        step = max(_OUTLIER_MIN_BLOCK, _OUTLIER_PAIRS // self.face.size)
        for s in range(0, P.shape[0], step):
            X, cap = P[s:s + step], bound2[s:s + step]
            # the outliers that can come within the block's largest bound of its box
            sub = np.flatnonzero(self._block_bounds(X) <= cap.max() * (1 + PRUNE_SLACK))
            if sub.size == 0:
                continue
            lb = self._point_bounds(X, sub)
            # the outlier of smallest bound first: its distance bounds the others
            t0 = sub[np.argmin(lb, axis=1)]
            q0 = np.arange(t0.size)
            bound = np.minimum(cap, closest_pairs(PT[:, s:s + step], q0, self.rows, t0)[2])
            qi, ti = np.nonzero(lb <= bound[:, None] * (1 + PRUNE_SLACK))
            qi = np.concatenate([q0, qi])
            ti = np.concatenate([t0, sub[ti]])
            v, w, d2 = closest_pairs(PT[:, s:s + step], qi, self.rows, ti)
            order = np.lexsort((self.face[ti], d2, qi))
            first = order[np.flatnonzero(np.diff(qi[order], prepend=-1))]
            keep = first[d2[first] <= cap[qi[first]] * (1 + PRUNE_SLACK)]
            parts.append((qi[keep] + s, ti[keep], v[keep], w[keep], d2[keep]))
        return tuple(np.concatenate(c) for c in zip(*parts))

    def _point_bounds(self, X, sub):
        """(b, r) lower bounds of the squared distances of the points ``X``
        (b,3) to the outliers ``sub``: the larger of the squared distance to
        each one's box and to its plane (:meth:`_plane_gap2`)."""
        height = X @ self.normal[:, sub]
        height -= self.offset[sub]
        return np.maximum(_box_gap2(X[:, None], self.lo[sub][None], self.hi[sub][None]),
                          self._plane_gap2(height, X))

    def _block_bounds(self, X):
        """(r,) lower bounds of the squared distances of any point in the box
        of the points ``X`` (b,3) to each outlier: the larger of the squared
        distance between the two boxes and, when the box's 8 corners are all
        on one side of the outlier's plane, of the nearest corner's to it."""
        C = _box_corners(X)
        height = C @ self.normal
        height -= self.offset
        side = np.where((height > 0).all(axis=0), height.min(axis=0),
                        np.where((height < 0).all(axis=0), -height.max(axis=0), 0.0))
        lo, hi = C[0], C[7]
        gap = np.maximum(self.lo - hi, 0) + np.maximum(lo - self.hi, 0)
        return np.maximum(row_sums(gap * gap), self._plane_gap2(side, C))

    def _plane_gap2(self, height, X):
        """The squared ``height`` (any shape) of points over planes, less a
        rounding slack of ``_HEIGHT_ULPS`` ulps of the largest coordinate of
        the points ``X`` and the outliers (never below 0)."""
        slack = _HEIGHT_ULPS * np.finfo(float).eps * (np.abs(X).max() + self.size)
        gap = np.maximum(np.abs(height) - slack, 0)
        gap *= gap
        return gap


class TriangleIndex:
    """Exact nearest-triangle queries on a triangle mesh (pure NumPy).

    Build once, query many times; see the module docstring for the method.

    Parameters
    ----------
    V : (n, 3) array_like of float
    F : (m, 3) array_like of int, m >= 1. Degenerate triangles are allowed.
    cell_factor : float, keyword-only
        Grid cell size in mean triangle bounding-box extents (default 1.5;
        the answers are exact for any, ties among exactly equidistant
        triangles aside).
    min_cell : float or None, keyword-only
        Cells at least this wide (in the mesh's units): for queries that
        lie farther from the surface than a few triangles (a ball crossing
        many small cells costs more than larger cells' extra triangles).

    Attributes
    ----------
    V, F : the checked copies of the mesh (float64 / int64).
    crowded_cell : float
        Queries whose grid cell references more triangles than this go to
        the hierarchy (``CROWDED_CELL``, more where the cells were made
        wider than the default: their population grows with their area).
    cell_growth : float
        How many times wider than ``cell_factor`` mean extents ``min_cell``
        made the cells (1: not at all).
    n_faces : int
        Triangles in the grid: the faces of F, less repeated copies of one
        triangle's geometry where more than ``_MAX_SAME_CODE`` share a cell
        of the Morton order (a degenerate cluster), and less the few far out
        of the rest's box that are measured apart (a scan's spike,
        ``_OUTLIER_*``).

    Raises
    ------
    InvalidMeshError
        Bad shapes, NaN coordinates, out-of-range indices, or no faces.

    Examples
    --------
    >>> index = TriangleIndex([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]])
    >>> r = index.closest([[1.0, 1.0, 0.0], [0.25, 0.25, -2.0]])
    >>> r.face.tolist(), r.distance.round(6).tolist()
    ([0, 0], [0.707107, 2.0])
    """

    @plain_pages
    def __init__(self, V, F, *, cell_factor=CELL_FACTOR, min_cell=None):
        V, F = check_mesh(V, F, where="TriangleIndex", allow_empty=False)
        check_reach(V, where="TriangleIndex", name="V")
        # (1e-300 never found a grid: an UnboundLocalError; a bool passed as a number)
        cell_factor = check_number(cell_factor, where="TriangleIndex", name="cell_factor",
                                   lo=CELL_FACTOR / 1e3, hi=CELL_FACTOR * 1e3)
        if min_cell is not None:
            min_cell = check_number(min_cell, where="TriangleIndex", name="min_cell (or None)",
                                    lo=0, open_lo=True)
        self.V = V
        self.F = F
        self._lo, self._hi = _used_box(V, F)
        self._outliers = _Outliers.of(V, F, self._lo, self._hi)
        inliers = None if self._outliers is None else self._outliers.inliers
        F_in = F if inliers is None else F[inliers]
        if inliers is not None:
            self._lo, self._hi = _used_box(V, F_in)
        extent = self._hi - self._lo
        order = _morton_order(V, F_in, self._lo, extent)
        if inliers is not None:
            order = inliers[order]
        self._order = order                       # internal id -> face id
        m = order.shape[0]                        # internal triangles (duplicates dropped)
        Fo = F[order]
        spans = blocks(m, _BUILD_BLOCK)
        # the triangles' largest box sides, then the cells (every other per-triangle
        # array is made a block at a time: a 2M-face build made 850 MB of whole-mesh
        # temporaries, each page of which this machine's kernel was slow to hand out)
        ext = np.empty(m)
        run_each(lambda span: _largest_sides(V, Fo[span[0]:span[1]], ext[span[0]:span[1]]),
                 spans, threads=m >= _THREADED_BUILD)
        thin = _long_thin(V, Fo, ext)
        covered = _covered_needles(V, Fo, thin, float(extent.max()))
        if covered.any():
            keep = ~covered
            order, Fo, ext, thin = order[keep], Fo[keep], ext[keep], thin[keep]
            self._order, m = order, order.shape[0]
            spans = blocks(m, _BUILD_BLOCK)
        h, dims, natural, boxed = self._cell_size(V, Fo, spans, ext, thin, extent, cell_factor,
                                                  min_cell)
        self._h, self._dims = h, dims
        # cells made wider on purpose (cell_factor, min_cell, the references' cap) hold more
        # by design; cells made wider only to fit the box in _MAX_CELLS do not: a speck 1,000
        # diagonals off the bunny put all of it in one cell, 69,451 faces that did not count
        # as crowded, and a NearQuery's windows over it took 24 GB
        self.crowded_cell = CROWDED_CELL * max(1.0, (h / boxed / natural) ** 2 if natural > 0 else 1.0)
        # (natural / CELL_FACTOR is the mean extent the cell_factor multiplies)
        own = cell_factor * natural / CELL_FACTOR
        self.cell_growth = max(1.0, min(h / boxed, min_cell or 0.0) / own) if own > 0 else 1.0
        self._build_tables(V, Fo, spans, ext, h, dims)
        self._bvh = None                          # built on first need (far queries)
        self._bvh_ready = False                   # ... with its cylinder bounds
        self._normal = np.ascontiguousarray(self._D[12:15])      # the disk bound's rows
        self.n_faces = m

    def _build_tables(self, V, Fo, spans, ext, h, dims):
        """The kernel rows (``_D``), the two lower-bound tables (``_ball``,
        ``_prism``: :func:`_bounding_rows`) and the grid's cell -> triangles
        table (:func:`_plane_cells`) of the triangles ``Fo`` (internal
        order), a block of ``spans`` at a time on the worker threads."""
        m = Fo.shape[0]
        self._D, self._ball, self._prism = np.empty((16, m)), np.empty((4, m)), np.empty((16, m))
        small = np.int32 if m < 2**31 else np.int64        # (cells <= _MAX_CELLS < 2**31)

        def build_block(span):
            s = slice(*span)
            A, B, C = _corners(V, Fo[s])
            self._D[:, s] = triangle_rows(A, B, C)
            self._ball[:, s], self._prism[:, s] = _bounding_rows(A, B, C, self._D[12:15, s].T)
            c0, nr = _cell_ranges(A, B, C, self._lo, h, dims)
            sides = np.sqrt(self._D[9, s] * self._D[10, s])
            return _plane_cells(A, B, C, sides, ext[s], c0, nr, self._lo, h, dims, span[0], small) \
                + _capsule_rows(A, B, C, self._D[9:12, s], self._ball[:, s], span[0])
        parts = run_each(build_block, spans, threads=m >= _THREADED_BUILD)
        cell = np.concatenate([p[0] for p in parts])
        tri = np.concatenate([p[1] for p in parts])
        self._capsule_at, self._capsule = _capsule_table(m, [p[2:] for p in parts])
        del parts
        self._cell_tri = tri[np.argsort(cell, kind="stable")]
        self._cell_start = np.zeros(int(np.prod(dims)) + 1, dtype=np.int64)
        np.cumsum(np.bincount(cell, minlength=int(np.prod(dims))), out=self._cell_start[1:])

    # -- grid ---------------------------------------------------------------------------------
    def _cell_size(self, V, Fo, spans, ext, thin, extent, cell_factor, min_cell):
        """The grid's cell size and cells per axis: ``cell_factor`` mean
        largest box sides (of the triangles not ``thin``, when theirs is 25%
        smaller; at least ``min_cell``), grown by 1.25 until the
        grid has at most ``_MAX_CELLS`` cells and the triangles' boxes cover
        at most ``_MAX_REFS_PER_FACE`` cells each on average; the size the
        default ``CELL_FACTOR`` alone gives; and the factor by which the
        cells grew for the cap on cells alone (a box much larger than its
        triangles: an outlier far off)."""
        m = ext.shape[0]
        mean = float(ext.mean())
        if thin.any() and not thin.all():
            mean = min(mean, 1.25 * float(ext[~thin].mean()))
        mean = min(mean, max(1.25 * _area_edge(V, Fo), mean / _AREA_CELL_SHRINK))
        span = float(extent.max())
        # (a min_cell a million times the mesh is one cell all the same: 1e300 overflowed below)
        h = max(cell_factor * mean, min(min_cell or 0.0, 1e6 * span))
        natural = CELL_FACTOR * mean
        if not h > 0:
            h = span / 64 if span > 0 else 1.0
        boxed = 1.0
        for _ in range(200):
            dims_f = np.floor(extent / h) + 1
            if float(np.prod(dims_f)) > _MAX_CELLS:
                h *= 1.25
                boxed *= 1.25
                continue
            dims = dims_f.astype(np.int64)

            def covered(span):
                A, B, C = _corners(V, Fo[span[0]:span[1]])
                c0, nr = _cell_ranges(A, B, C, self._lo, h, dims)
                cnt = np.prod(nr, axis=1)
                needles = _needles(A, B, C, cnt, h)
                if needles is not None:      # (about the cells of a tube around a line through it)
                    line = 6 * nr.max(axis=1)
                    cnt = np.where(needles.is_needle, np.minimum(cnt, line), cnt)
                return int(cnt.sum())
            nrefs = sum(run_each(covered, spans, threads=m >= _THREADED_BUILD))
            if int(np.prod(dims)) <= _MAX_CELLS and nrefs <= max(_MAX_REFS_PER_FACE * m,
                                                                 _MIN_REF_BUDGET):
                break
            h *= 1.25
        return h, dims, natural, boxed

    # -- BVH ----------------------------------------------------------------------------------
    def _build_hierarchy(self):
        """Build the BVH and its cylinder bounds, once: queries run on worker
        threads, so the first far query of each thread may get here together
        (a lock; the flag is set only once both are complete)."""
        with _LAZY_BUILD:
            if self._bvh_ready:
                return
            # corners as the kernel sees them (A + ab, A + ac); bounds carry rounding margins
            A = self._D[0:3].T
            B = A + self._D[3:6].T
            C = A + self._D[6:9].T
            self._build_bvh(np.minimum(np.minimum(A, B), C), np.maximum(np.maximum(A, B), C))
            self._build_slabs(A, B, C)
            self._bvh_ready = True

    def _build_bvh(self, tlo, thi):
        m = tlo.shape[0]
        n_leaves = -(-m // _LEAF)
        depth = max(0, int(np.ceil(np.log2(n_leaves)))) if n_leaves > 1 else 0
        n_pad = 1 << depth
        pad = n_pad * _LEAF - m
        # a margin of 1e-12 of the coordinates' magnitude covers every rounding difference
        margin = 1e-12 * float(np.abs(np.concatenate([self._lo, self._hi])).max() + 1e-300)
        blo = np.vstack([tlo - margin, np.full((pad, 3), np.inf)]).reshape(n_pad, _LEAF, 3)
        bhi = np.vstack([thi + margin, np.full((pad, 3), -np.inf)]).reshape(n_pad, _LEAF, 3)
        blo, bhi = blo.min(axis=1), bhi.max(axis=1)
        los, his = [blo], [bhi]
        while los[-1].shape[0] > 1:
            los.append(np.minimum(los[-1][0::2], los[-1][1::2]))
            his.append(np.maximum(his[-1][0::2], his[-1][1::2]))
        # level k has 2**k nodes: rows lo x, y, z, hi x, y, z
        self._bvh = [np.ascontiguousarray(np.vstack([lo_.T, hi_.T]))
                     for lo_, hi_ in zip(los[::-1], his[::-1])]
        self._depth = depth

    def _build_slabs(self, A, B, C):
        """Cylinder bounds of every BVH node: centre c, unit axis n (the summed face normal,
        0 if it cancels), lateral radius r and half height t such that every point x of the
        node's triangles has |x - c|_lateral <= r and |(x - c).n| <= t. Tilted, nearly flat
        patches get a thin cylinder where their axis-aligned box is fat.

        The lowest _SLAB_LEVELS levels are computed from the vertices; the levels above
        from the two children's cylinders (a child's point is c_i + a + b n_i with a _|_ n_i,
        |a| <= r_i, |b| <= t_i, so its height is within |h(c_i)| + r_i |n_i x n| + t_i |n_i.n|
        and its lateral offset within lat(c_i) + r_i + t_i).
        """
        m = A.shape[0]
        n_pad = 1 << self._depth
        pad = n_pad * _LEAF - m
        # padding repeats the last triangle: a real triangle, so every bound stays valid
        X = np.stack([A, B, C], axis=1)
        N = cross_rows(B - A, C - A)
        if pad:
            X = np.concatenate([X, np.repeat(X[-1:], pad, axis=0)])
            N = np.concatenate([N, np.zeros((pad, 3))])
        valid = np.arange(n_pad * _LEAF) < m
        self._slab, self._rod = {}, {}
        low = min(_SLAB_LEVELS, self._depth + 1)
        for j in range(low):
            g = n_pad >> j
            c, n, r, t, size, cnt, nsum, rod = _leaf_cylinders(
                X.reshape(g, -1, 3), N.reshape(g, -1, 3), valid.reshape(g, -1))
            self._store_slab(self._depth - j, c, n, r, t, size, cnt, nsum)
            self._rod[self._depth - j] = rod
        for level in range(self._depth - low, -1, -1):
            cc, nn, rr, tt, cnt, ns = self._slab_parts[level + 1]
            cnt2 = cnt[0::2] + cnt[1::2]
            w0 = (cnt[0::2] / np.maximum(cnt2, 1))[:, None]
            c = w0 * cc[0::2] + (1 - w0) * cc[1::2]
            nsum = ns[0::2] + ns[1::2]
            n = unit_rows(nsum)
            r = np.full(c.shape[0], -np.inf)
            t = np.full(c.shape[0], -np.inf)
            size = np.zeros(c.shape[0])
            for k in (0, 1):
                ci, ni, ri, ti, ok = cc[k::2], nn[k::2], rr[k::2], tt[k::2], cnt[k::2] > 0
                d = ci - c
                hc = np.einsum("ij,ij->i", d, n)
                latc = np.sqrt(np.maximum(np.einsum("ij,ij->i", d, d) - hc * hc, 0.0))
                cos = np.abs(np.einsum("ij,ij->i", ni, n))
                sin = np.linalg.norm(cross_rows(ni, n), axis=1)
                hk = np.abs(hc) + ri * sin + ti * cos
                lk = latc + ri + ti
                r = np.where(ok, np.maximum(r, lk), r)
                t = np.where(ok, np.maximum(t, hk), t)
                size = np.where(ok, np.maximum(size, np.abs(d).max(axis=1) + ri + ti), size)
            self._store_slab(level, c, n, r, t, size, cnt2, nsum)
        del self._slab_parts

    def _store_slab(self, level, c, n, r, t, size, cnt, nsum):
        scale = np.abs(c).max(axis=1) + size
        r = r * (1 + 1e-9) + 1e-9 * size + 1e-12 * scale     # rounding margins (lat2 cancels)
        t = t * (1 + 1e-9) + 1e-9 * size + 1e-12 * scale
        empty = cnt == 0                  # padding: bounds that prune and never bind
        c = np.where(empty[:, None], 0.0, c)
        r = np.where(empty, np.inf, r)
        t = np.where(empty, np.inf, t)
        if not hasattr(self, "_slab_parts"):
            self._slab_parts = {}
        self._slab_parts[level] = (c, n, np.where(empty, 0.0, r), np.where(empty, 0.0, t),
                                   cnt, nsum)
        self._slab[level] = np.ascontiguousarray(np.vstack([c.T, n.T, r, t]))


    # -- queries -------------------------------------------------------------------------------
    @plain_pages
    def closest(self, P, *, crowded_cell=None):
        """Nearest point on the mesh for every query point.

        Parameters
        ----------
        P : (q, 3) array_like of float, finite.
        crowded_cell : float or None, keyword-only
            Points whose grid cell references more triangles than this go
            to the hierarchy (None: :attr:`crowded_cell`; the answers are the
            same, only the time changes).

        Returns
        -------
        ClosestPoints
            ``face`` (q,) int64, ``point`` (q,3), ``bary`` (q,3), ``distance`` (q,).
            Exact (the true nearest triangle; among equidistant triangles any one).

        Raises
        ------
        InvalidArgumentError
            P not (q,3) or not finite.
        """
        P = check_points(P, where="TriangleIndex.closest")
        if crowded_cell is not None:
            crowded_cell = check_number(crowded_cell, where="TriangleIndex.closest",
                                        name="crowded_cell", lo=0)
        return self.with_outliers(P, lambda X: self.grid_closest(X, crowded_cell=crowded_cell))

    def with_outliers(self, P, search):
        """The closest points of ``P`` (checked) on the mesh, from
        ``search(X)``'s among the faces of the grid (:meth:`grid_closest`,
        or another search of them): the faces kept out of it (a scan's
        spike, ``_OUTLIER_*``) taken into account, when there are any."""
        if self._outliers is None:
            return search(P)
        return self._outliers.combined(P, self._lo, self._hi, search)

    def grid_closest(self, P, *, crowded_cell=None):
        """:meth:`closest` among the faces of the grid only (every face but
        those kept out of it, ``_OUTLIER_*``): ``P`` checked, ``crowded_cell``
        as there."""
        nq = P.shape[0]
        best = BestPairs(nq)
        if nq:
            PT = np.ascontiguousarray(P.T)
            h, dims, lo = self._h, self._dims, self._lo
            cc = np.clip(np.floor((P - lo) / h), 0, dims - 1).astype(np.int64)
            cid = cc[:, 0] + dims[0] * (cc[:, 1] + dims[1] * cc[:, 2])
            crowded, order, cnt = self.split_crowded(cid, limit=crowded_cell)
            far = [crowded]
            if order.size:
                csum = np.cumsum(cnt[order])
                # chunks of about _PAIR_CHUNK own-cell pairs and at most _QUERY_CHUNK queries
                cuts = np.searchsorted(csum, np.arange(1, int(csum[-1]) // _PAIR_CHUNK + 1)
                                       * _PAIR_CHUNK)
                nk = order.size
                bounds = sorted_unique(
                    np.concatenate([[0, nk], cuts, np.arange(0, nk, _QUERY_CHUNK)]))
                # (on the worker threads: each chunk writes its own queries' rows of best)
                far += run_each(lambda span: self._grid_chunk(PT, order[span[0]:span[1]], cc,
                                                              cid, best),
                                [(s, e) for s, e in zip(bounds[:-1], bounds[1:]) if e > s])
            far = np.concatenate(far)
            if far.size:
                self._bvh_query(PT, far, best, crowded.size)
        return closest_result(self.tables.rows, self.tables.face, best.t, best.v, best.w,
                              best.d2)

    def split_crowded(self, cid, limit=None):
        """For queries in the grid cells ``cid``: those whose cell is crowded
        (more than ``limit`` references, None: :attr:`crowded_cell`; long thin
        triangles, as on a CAD cylinder's sides, cross many cells and crowd
        them all), which the hierarchy answers; the others in cell order
        (stable: a mesh's own order is coherent, and stable sorts it fast);
        and each one's cell's reference count."""
        cnt = self._cell_start[cid + 1] - self._cell_start[cid]
        crowded = cnt > (self.crowded_cell if limit is None else limit)
        order = np.flatnonzero(~crowded)
        return np.flatnonzero(crowded), order[np.argsort(cid[order], kind="stable")], cnt

    @property
    def tables(self):
        """The index's arrays as :class:`IndexTables` (read-only views)."""
        return IndexTables(self._lo, self._hi, self._h, self._dims, self._cell_start,
                           self._cell_tri, self._D, self._ball, self._prism, self._order)

    def _fold(self, q, t, v, w, d2, counts, best):
        """Fold pair results (contiguous groups, one per query) into ``best``."""
        nz = counts[counts > 0]
        if nz.size == 0:
            return
        win = group_argmin(d2, nz)
        qq = q[win]
        better = d2[win] < best.d2[qq]
        qq, win = qq[better], win[better]
        best.put(qq, t[win], v[win], w[win], d2[win])

    def _fold_lowest_face(self, q, t, v, w, d2, best):
        """Fold pair results (points ``q``, triangles ``t``) into ``best``:
        per query the smallest squared distance and, among exactly equal ones
        (the best so far too), the lowest face of ``F``, whatever the order
        the pairs came in (the hierarchy's rule: its searches by groups visit
        the leaves in another order than one query's search)."""
        if q.size == 0:
            return
        face = self._order[t]
        order = np.lexsort((face, d2, q))
        qs = q[order]
        head = np.concatenate([[True], qs[1:] != qs[:-1]])
        win, qq = order[head], qs[head]
        old = best.d2[qq]
        better = (d2[win] < old) | ((d2[win] == old) & (face[win] < self._order[best.t[qq]]))
        qq, win = qq[better], win[better]
        best.put(qq, t[win], v[win], w[win], d2[win])

    def _scan(self, PT, q, t, best, probe=True, edges=True, lowest_face=False):
        """Exact minimum over candidate pairs (q, t), grouped contiguously by query.

        Two cheap lower bounds (:func:`_bounding_rows`) discard most pairs: the
        bounding sphere on every pair, then the height and the lateral distance
        beyond the edge lines on those left; only the pairs within the query's
        bound are evaluated exactly. With ``probe``, the pair with the nearest
        centroid is evaluated first, for a tight bound (see :meth:`_fold_probe`
        for which pair wins a tie). Without ``edges``, the edge-line bound is
        left out (far queries: it prunes little there and costs 16 rows a pair).
        With ``lowest_face``, a tie goes to the lowest face instead
        (:meth:`_fold_lowest_face`).
        """
        if q.size == 0:
            return
        S = np.take(self._ball, t, axis=1)
        X = np.take(PT, q, axis=1)
        X -= S[:3]
        dc2 = X[0] * X[0]
        dc2 += X[1] * X[1]
        dc2 += X[2] * X[2]
        if not probe:
            bound = best.d2[q]
            keep, lb = self._within(X, S[3], dc2, t, bound, edges, bounds=True)
            # the query's best triangle again cannot do better (the same exact value)
            other = best.t[q[keep]] != t[keep]
            keep, lb = keep[other], lb[other]
            if keep.size:
                at, v, w, d2 = self._eval_lowest_first(PT, q, t, keep, lb, bound)
                if lowest_face:
                    self._fold_lowest_face(q[at], t[at], v, w, d2, best)
                    return
                order = np.argsort(at, kind="stable")          # (the scan's order: same ties)
                at, v, w, d2 = at[order], v[order], w[order], d2[order]
                self._fold(q[at], t[at], v, w, d2, _run_lengths(q[at]), best)
            return
        counts = _run_lengths(q)
        starts = np.cumsum(counts) - counts
        first = group_argmin(dc2, counts)
        v0, w0, d0 = self._eval(PT, q[first], t[first])
        pre = best.d2[q[starts]]
        bound = np.repeat(np.minimum(pre, d0), counts)
        keep, lb = self._within(X, S[3], dc2, t, bound, edges, bounds=True)
        is_first = np.zeros(q.size, dtype=bool)
        is_first[first] = True
        left = ~is_first[keep]
        keep, lb = keep[left], lb[left]
        at, v, w, d2 = self._eval_lowest_first(PT, q, t, keep, lb, bound)
        at = np.concatenate([first, at])
        v, w, d2 = np.concatenate([v0, v]), np.concatenate([w0, w]), np.concatenate([d0, d2])
        if lowest_face:
            self._fold_lowest_face(q[at], t[at], v, w, d2, best)
            return
        order = np.argsort(at, kind="stable")
        self._fold_probe(q, t, X, S, dc2, counts, pre, at[order], v[order], w[order], d2[order],
                         best)

    def _eval_lowest_first(self, PT, q, t, keep, lb, bound):
        """Evaluate the scan's pairs ``keep`` (ascending, their lower bounds
        ``lb``; ``bound`` the squared bound so far, per pair): where a
        query has more than ``_LOWEST_FIRST`` of them, the one of smallest
        bound first, and then only the others its distance leaves within
        bounds. Slivers side by side (a CAD fillet's strips) all pass the
        centroid probe's bound, and the nearest centroid is rarely the closest
        strip: a fit's queries near a 10k-face fillet evaluated 1,100 pairs
        each. A pair dropped here lies beyond a distance already found, so
        the minimum and its ties (every pair within it) are the same.
        Returns the pairs evaluated (positions in the scan) and their (v, w, d2)."""
        qk = q[keep]
        counts = _run_lengths(qk)
        crowded = np.repeat(counts > _LOWEST_FIRST, counts)
        if not crowded.any():
            return (keep, *self._eval(PT, qk, t[keep]))
        c = np.flatnonzero(crowded)
        cc = counts[counts > _LOWEST_FIRST]
        low = c[group_argmin(lb[c], cc)]
        v0, w0, d0 = self._eval(PT, qk[low], t[keep[low]])
        limit = np.repeat(np.minimum(bound[keep[low]], d0), cc)
        rest = np.ones(keep.size, dtype=bool)
        rest[low] = False
        rest[c] &= lb[c] <= limit * (1 + PRUNE_SLACK)
        rest = np.flatnonzero(rest)
        v1, w1, d1 = self._eval(PT, qk[rest], t[keep[rest]])
        pos = np.concatenate([low, rest])
        return (keep[pos], np.concatenate([v0, v1]), np.concatenate([w0, w1]),
                np.concatenate([d0, d1]))

    def _within(self, X, r, dc2, t, bound, edges=True, bounds=False):
        """Indices of the pairs (offsets X from the centroids (3, k), squared
        lengths dc2, triangles t) whose lower bounds (sphere, disk and, with
        ``edges``, edge lines) are all within ``bound``; with ``bounds``, also
        the largest of those bounds of each (squared, as ``bound``)."""
        reach = np.sqrt(bound)
        reach += r
        reach *= reach
        keep = np.flatnonzero(dc2 <= reach * (1 + 4 * PRUNE_SLACK))
        lb = np.zeros(keep.size)
        if keep.size:
            X, t, dc2, bound = np.take(X, keep, axis=1), t[keep], dc2[keep], bound[keep]
            lb = self._disk_bound(X, t, dc2, r[keep])
            sub = np.flatnonzero(lb <= bound * (1 + PRUNE_SLACK))
            keep, lb = keep[sub], lb[sub]
            if edges:
                X, t, dc2, bound = np.take(X, sub, axis=1), t[sub], dc2[sub], bound[sub]
                lb = np.maximum(lb, self._prism_bound(X, t, dc2))
                sub = np.flatnonzero(lb <= bound * (1 + PRUNE_SLACK))
                keep, lb = keep[sub], lb[sub]
        return (keep, lb) if bounds else keep

    def _disk_bound(self, X, t, dc2, r):
        """Squared-distance lower bound of the points ``c_t + X`` to the triangles
        ``t``: height above the plane and lateral excess beyond the bounding disk
        (radius ``r``), less a rounding margin of ``dc2`` (the squared ``|X|``)."""
        n = np.take(self._normal, t, axis=1)
        hh = X[0] * n[0] + X[1] * n[1] + X[2] * n[2]
        hh *= hh
        lat = np.sqrt(np.maximum(dc2 - hh, 0.0)) - r
        np.maximum(lat, 0.0, out=lat)
        lat *= lat
        hh += lat
        hh -= 1e-14 * dc2
        return self._capsule_bound(X, t, dc2, hh)

    def needle_bounds(self, P, owner, t):
        """The pairs (points ``owner`` of ``P`` (3, n), internal triangles
        ``t``) whose triangle has a capsule bound (needles and slivers:
        :func:`_capsule_rows`): their positions (ascending) and their
        squared-distance lower bounds, the distance to the triangle's
        longest edge less its height, less a rounding margin."""
        if self._capsule_at is None:
            return np.zeros(0, dtype=np.int64), np.zeros(0)
        k = np.take(self._capsule_at, t)
        j = np.flatnonzero(k >= 0)
        X = np.take(P, owner[j], axis=1) - np.take(self._ball[:3], t[j], axis=1)
        return j, self._capsule_gap2(X, k[j], np.einsum("ij,ij->j", X, X))

    def _capsule_bound(self, X, t, dc2, lb):
        """``lb`` (squared-distance lower bounds of the points ``c_t + X`` to
        the triangles ``t``) raised, in place, to the capsule bound where the
        triangle has one (:meth:`needle_bounds`)."""
        if self._capsule_at is None:
            return lb
        k = np.take(self._capsule_at, t)
        j = np.flatnonzero(k >= 0)
        if j.size:
            lb[j] = np.maximum(lb[j], self._capsule_gap2(np.take(X, j, axis=1), k[j], dc2[j]))
        return lb

    def _capsule_gap2(self, X, k, dc2):
        """The capsule bound of the points ``c + X`` (3, j) (offsets from the
        centroids of the triangles with capsule rows ``k``, squared lengths
        ``dc2``): the squared distance beyond each capsule, less 1e-12 of the
        offset's length."""
        gap = _capsule_gap(X, np.take(self._capsule, k, axis=1))
        gap -= 1e-12 * np.sqrt(dc2)
        np.maximum(gap, 0.0, out=gap)
        gap *= gap
        return gap

    def _prism_bound(self, X, t, dc2):
        """Squared-distance lower bound of the points ``c_t + X`` (X (3, k)) to the
        triangles ``t``: height above the plane and lateral distance beyond the
        farthest-out edge line, less the rounding allowances."""
        P = np.take(self._prism, t, axis=1)
        x, y, z = X
        e = P[15]
        h = np.abs(x * P[0] + y * P[1] + z * P[2])
        h -= e
        np.maximum(h, 0.0, out=h)
        lat = x * P[3] + y * P[4] + z * P[5] - P[12]
        np.maximum(lat, x * P[6] + y * P[7] + z * P[8] - P[13], out=lat)
        np.maximum(lat, x * P[9] + y * P[10] + z * P[11] - P[14], out=lat)
        lat -= e
        np.maximum(lat, 0.0, out=lat)
        h *= h
        lat *= lat
        h += lat
        h -= 1e-14 * dc2
        return h

    def _fold_probe(self, q, t, X, S, dc2, counts, pre, at, v, w, d2, best):
        """Fold a probed scan's exact results (pairs ``at`` of the scan, ascending;
        every group has one) into ``best``.

        A group's winner is its smallest distance; among exactly equal ones, the
        pair with the smallest bounding-disk bound (height, lateral excess
        beyond the bounding disk) among those within ``pre``, the bound before
        the scan, else the first in the scan's order. That is the rule the
        index has always had, kept so that results stay bit-identical.
        """
        qa = q[at]
        c2 = _run_lengths(qa)
        s2 = np.cumsum(c2) - c2
        win = group_argmin(d2, c2)
        tied = d2 == np.repeat(d2[win], c2)
        groups = np.flatnonzero(np.add.reduceat(tied, s2) > 1)
        if groups.size:
            # the old probe of each tied group: the smallest disk bound in the whole group
            k, own = ragged_ranges(np.cumsum(counts)[groups] - counts[groups], counts[groups])
            x, y, z = X[:, k]
            n = np.take(self._prism[0:3], t[k], axis=1)
            hh = x * n[0] + y * n[1] + z * n[2]
            hh *= hh
            lat = np.sqrt(np.maximum(dc2[k] - hh, 0.0)) - S[3, k]
            lb = hh + np.square(np.maximum(lat, 0.0)) - 1e-14 * dc2[k]
            lb[lb > pre[groups][own] * (1 + PRUNE_SLACK)] = np.inf
            probe = k[group_argmin(lb, counts[groups])]
            # where that pair is among the tied ones, it wins
            mine = np.flatnonzero(tied)
            g_of = np.searchsorted(s2, mine, side="right") - 1
            slot = np.full(c2.size, -1, dtype=np.int64)
            slot[groups] = np.arange(groups.size)
            sel = slot[g_of] >= 0
            mine, g_of = mine[sel], g_of[sel]
            hit = at[mine] == probe[slot[g_of]]
            win[g_of[hit]] = mine[hit]
        qq = qa[win]
        better = d2[win] < best.d2[qq]
        qq, win = qq[better], win[better]
        best.put(qq, t[at[win]], v[win], w[win], d2[win])

    def _eval(self, PT, q, t):
        """The exact kernel on the pairs (query columns q of PT, internal triangles t)."""
        return closest_pairs(PT, q, self._D, t)

    def _cell_pairs(self, qi, g):
        """Pairs (query, triangle) for the (query, cell) list (qi, g), grouped by query."""
        start = self._cell_start
        ref, own = ragged_ranges(start[g], start[g + 1] - start[g])
        return qi[own], self._cell_tri[ref]

    def _grid_chunk(self, PT, qi, cc, cid, best):
        """Grid search of the queries ``qi``; returns those left for the BVH."""
        h, dims, lo = self._h, self._dims, self._lo
        start = self._cell_start
        # phase 1: the query's own cell; for an empty cell, the nearest non-empty one of its
        # 26 neighbours (box distance)
        c0 = cid[qi]
        self._scan(PT, *self._cell_pairs(qi, c0), best)
        done = c0.copy()                                # a second cell already scanned
        empty = np.flatnonzero(~np.isfinite(best.d2[qi]))
        if empty.size:
            k, own = ragged_ranges(np.zeros(empty.size, dtype=np.int64),
                             np.full(empty.size, 27, dtype=np.int64))
            g3 = cc[qi[empty]][own] + np.stack([k % 3, (k // 3) % 3, k // 9], axis=1) - 1
            ok = ((g3 >= 0) & (g3 < dims)).all(axis=1)
            own, g3 = own[ok], g3[ok]
            g = g3[:, 0] + dims[0] * (g3[:, 1] + dims[1] * g3[:, 2])
            ok = (g != c0[empty][own]) & (start[g + 1] > start[g])
            own, g3, g = own[ok], g3[ok], g[ok]
            if own.size:
                pq = PT[:, qi[empty][own]].T
                cell_lo = lo + g3 * h
                dd = np.maximum(np.maximum(cell_lo - pq, pq - (cell_lo + h)), 0.0)
                nearest = group_argmin(np.einsum("ij,ij->i", dd, dd), _run_lengths(own))
                own, g = own[nearest], g[nearest]
                self._scan(PT, *self._cell_pairs(qi[empty][own], g), best)
                done[empty[own]] = g
        # phase 2: every other cell within the bound
        u2 = best.d2[qi]
        finite = np.isfinite(u2)
        u = np.sqrt(np.where(finite, u2, 0.0)) * (1 + PRUNE_SLACK)
        p = PT[:, qi].T
        c_lo = np.clip(np.floor((p - u[:, None] - lo) / h), 0, dims - 1).astype(np.int64)
        c_hi = np.clip(np.floor((p + u[:, None] - lo) / h), 0, dims - 1).astype(np.int64)
        span = c_hi - c_lo + 1
        ncell = np.prod(span, axis=1)
        far = ~finite | (ncell > _MAX_PHASE2_CELLS)
        sel = np.flatnonzero(~far & (ncell > 1))
        if sel.size:
            k, own = ragged_ranges(np.zeros(sel.size, dtype=np.int64), ncell[sel])
            sp = span[sel][own]
            g3 = c_lo[sel][own] + np.stack(
                [k % sp[:, 0], (k // sp[:, 0]) % sp[:, 1], k // (sp[:, 0] * sp[:, 1])], axis=1)
            g = g3[:, 0] + dims[0] * (g3[:, 1] + dims[1] * g3[:, 2])
            pq = p[sel][own]
            cell_lo = lo + g3 * h
            dd = np.maximum(np.maximum(cell_lo - pq, pq - (cell_lo + h)), 0.0)
            dd2 = np.einsum("ij,ij->i", dd, dd)
            keep = (g != c0[sel][own]) & (g != done[sel][own])
            keep &= dd2 <= u2[sel][own] * (1 + 4 * PRUNE_SLACK)
            refs = start[g + 1] - start[g]
            keep &= refs > 0
            heavy = np.bincount(own[keep], refs[keep], sel.size) \
                > _PHASE2_CROWDED * self.crowded_cell
            if heavy.any():
                far[sel[heavy]] = True
                keep &= ~heavy[own]
            self._scan(PT, *self._cell_pairs(qi[sel][own[keep]], g[keep]), best, probe=False)
        return qi[far]

    def _scan_all(self, PT, far, best):
        """A handful of far queries ``far``: every triangle through the
        lower-bound filter (it costs less than building the hierarchy)."""
        m = self.n_faces
        per = max(1, _PAIR_CHUNK // m)
        for s in range(0, far.size, per):
            qs = far[s:s + per]
            self._scan(PT, np.repeat(qs, m), np.tile(np.arange(m), qs.size), best, edges=False,
                       lowest_face=True)

    def _node_bounds(self, p, child, level):
        """Squared distance bounds from the points ``p`` (3, k) to the BVH
        nodes ``child`` (k,) of ``level``: the nearest a triangle in the node
        can be (the larger of its box's and its cylinder's bounds) and the
        farthest every triangle in it is within (the smaller of the two,
        widened by the pruning slack)."""
        box = np.take(self._bvh[level], child, axis=1)
        near2 = np.zeros(p.shape[1])
        far2 = np.zeros(p.shape[1])
        for k in range(3):
            a = box[k] - p[k]                    # lo - p
            b = p[k] - box[k + 3]                # p - hi
            near = np.maximum(np.maximum(a, b), 0.0)
            near2 += near * near
            fa = np.maximum(np.abs(a), np.abs(b))
            far2 += fa * fa
        S = np.take(self._slab[level], child, axis=1)      # the node's cylinder
        dx, dy, dz = p[0] - S[0], p[1] - S[1], p[2] - S[2]
        dc2 = dx * dx + dy * dy + dz * dz
        hh = np.abs(dx * S[3] + dy * S[4] + dz * S[5])
        lat = np.sqrt(np.maximum(dc2 - hh * hh, 0.0))
        el = np.maximum(lat - S[6], 0.0)
        eh = np.maximum(hh - S[7], 0.0)
        near2 = np.maximum(near2, el * el + eh * eh - 1e-14 * dc2)
        fl = lat + S[6]
        fh = hh + S[7]
        far2 = np.minimum(far2, fl * fl + fh * fh + 1e-14 * dc2)
        far2 *= 1 + 4 * PRUNE_SLACK
        R = self._rod.get(level)
        if R is not None:                                   # the lowest levels' rods
            gap = _capsule_gap(p, np.take(R, child, axis=1))
            np.maximum(gap, 0.0, out=gap)
            near2 = np.maximum(near2, gap * gap - 1e-14 * dc2)
        return near2, far2

    def _bvh_query(self, PT, far, best, crowded=0):
        """Exact search of the queries ``far`` (its first ``crowded`` from
        crowded cells, the others far from the surface) through the BVH, in
        groups.

        Queries close together share their work (:meth:`_query_groups`: the
        queries of one cell, a ball of centre ``c`` and radius ``rho``
        holding them). A group's probe is one beam descent from ``c``
        (:meth:`_beam`); each member scans the leaves it reached, an exact
        upper bound. Then the tree is descended breadth first, in lockstep
        for all groups, the groups now sized to their members' bounds: a
        node's distance from a member is at least its distance from ``c``
        less ``rho`` and every triangle of it lies within its farthest-point
        distance from ``c`` plus ``rho``; the group's bound ``ub`` (the
        largest of its members' exact bounds, tightened at every level by
        the smallest farthest-point one of a child) prunes every child whose
        nearest point lies beyond it. At the leaves each member takes the
        group's leaves again with its own bounds: its nearest leaf first (a
        tight exact bound), then the leaves within it. A group of one is
        the search of one query, as before. A gravel scan's fit asked for
        82k samples far from its fine surface (small blobs, one in each
        pebble and in the cow, whose cage is a tetrahedron): 1,776 probe
        groups, and 20k descent groups (28k of its samples, the cow's, in
        1,219 groups of 10 or more).
        """
        if not self._bvh_ready and far.size * self.n_faces <= _BRUTE_PAIRS \
                and far.size <= _BRUTE_QUERIES:
            self._scan_all(PT, far, best)
            return
        if not self._bvh_ready:
            self._build_hierarchy()
        self._probe_groups(PT, far, best, crowded=crowded)
        size = _GROUP_SHARE * np.sqrt(best.d2[far])
        q_all, counts, centre, rho = self._query_groups(PT, far, size)
        starts = np.cumsum(counts) - counts
        ub = np.maximum.reduceat(best.d2[q_all], starts)
        # chunks of groups holding at most _QUERY_CHUNK // 4 queries (a group larger than
        # that is a chunk of its own)
        cuts = sorted_unique(np.concatenate([[0, counts.size], np.searchsorted(
            np.cumsum(counts), np.arange(1, far.size // (_QUERY_CHUNK // 4) + 1)
            * (_QUERY_CHUNK // 4), side="right")]))
        cuts = cuts[cuts <= counts.size]
        spans = [(a, b) for a, b in zip(cuts[:-1].tolist(), cuts[1:].tolist()) if b > a]
        # (on the worker threads: a chunk's groups, bounds and queries are its own)
        run_each(lambda span: self._descend(PT, q_all, starts, counts, centre, rho, ub, span,
                                            best), spans)

    def _descend(self, PT, q_all, starts, counts, centre, rho, ub, span, best):
        """:meth:`_bvh_query`'s descent of the groups ``span[0] .. span[1]``
        (their bounds ``ub`` tightened in place), then their members' scans
        of the leaves reached."""
        a, b = span
        stack = [(0, np.arange(a, b), np.zeros(b - a, dtype=np.int64))]
        while stack:
            level, g, node = stack.pop()
            if level == self._depth:
                self._scan_group_leaves(PT, q_all, starts, counts, g, node, best)
                continue
            # descend _BVH_STEP levels at once (a 2**_BVH_STEP-ary tree)
            step = min(_BVH_STEP, self._depth - level)
            child = ((node[:, None] << step) + np.arange(1 << step)).ravel()
            g = np.repeat(g, 1 << step)
            level += step - 1
            near2, far2 = self._node_bounds(np.take(centre, g, axis=1), child, level + 1)
            near2, far2 = _widen_bounds(near2, far2, rho[g])
            runs = _run_lengths(g)
            first = np.cumsum(runs) - runs
            ug = g[first]
            ub[ug] = np.minimum(ub[ug], np.minimum.reduceat(far2, first))
            keep = near2 <= ub[g] * (1 + 4 * PRUNE_SLACK)
            g, child = g[keep], child[keep]
            if g.size > _FRONTIER_CAP:
                pieces = -(-g.size // _FRONTIER_CAP)
                for gg, cn in reversed(list(zip(np.array_split(g, pieces),
                                                np.array_split(child, pieces)))):
                    stack.append((level + 1, gg, cn))
            elif g.size:
                stack.append((level + 1, g, child))

    def _scan_group_leaves(self, PT, q_all, starts, counts, g, leaf, best):
        """The leaves ``leaf`` the groups ``g`` reached, for each of their
        members (``q_all[starts[g] : starts[g] + counts[g]]``) with its own
        bounds: its nearest leaf first, then those within the distance found
        (a member with more than ``_LEAF_ROUNDS[1]`` of them: nearest first,
        in rounds, :meth:`_scan_in_rounds`)."""
        member, own = ragged_ranges(starts[g], counts[g])
        q = q_all[member]
        order = np.argsort(q, kind="stable")                  # grouped by query
        q, leaf = q[order], leaf[own[order]]
        near2, _ = self._node_bounds(np.take(PT, q, axis=1), leaf, self._depth)
        first = group_argmin(near2, _run_lengths(q))
        self._scan_leaves(PT, q[first], leaf[first], best)
        rest = near2 <= best.d2[q] * (1 + 4 * PRUNE_SLACK)
        rest[first] = False
        rest = np.flatnonzero(rest)
        runs = _run_lengths(q[rest])                          # (still grouped by query)
        many = np.repeat(runs > _LEAF_ROUNDS[1], runs)
        self._scan_leaves(PT, q[rest[~many]], leaf[rest[~many]], best, probe=False)
        if many.any():
            self._scan_in_rounds(PT, q[rest[many]], leaf[rest[many]], near2[rest[many]], best)

    def _scan_in_rounds(self, PT, q, leaf, near2, best):
        """Scan the leaves ``leaf`` (bounds ``near2``) of the queries ``q``
        nearest first, in rounds up to each query's ``_LEAF_ROUNDS[k]``-th
        nearest, each round those still within the distance found (the
        answers are the same in any order: ties go to the lowest face)."""
        order = np.lexsort((near2, q))
        q, leaf, near2 = q[order], leaf[order], near2[order]
        runs = _run_lengths(q)
        rank = ragged_entries(np.zeros(runs.size, dtype=np.int64), runs)   # (each in its query)
        left = np.ones(q.size, dtype=bool)
        for upto in _LEAF_ROUNDS[1:]:
            left &= near2 <= best.d2[q] * (1 + 4 * PRUNE_SLACK)
            now = np.flatnonzero(left & (rank < upto))
            self._scan_leaves(PT, q[now], leaf[now], best, probe=False)
            left[now] = False

    def _query_groups(self, PT, q, size):
        """The queries ``q`` grouped by cell, each query's cell of an edge of
        ``h`` times a power of two, the largest not above its ``size`` (q,)
        (at least ``h / 2**_GROUP_LEVELS``): (the queries, group by group;
        the groups' counts (G,); centres (3, G) and radii (G,) of balls
        holding their members, with rounding margins)."""
        h = self._h
        k = np.floor(np.log2(np.maximum(size, h * 2.0 ** -_GROUP_LEVELS) / h))
        edge = h * np.exp2(k)
        X = np.take(PT, q, axis=1)
        cell = np.clip(np.floor((X - self._lo[:, None]) / edge), -2.0 ** 52, 2.0 ** 52)
        order = np.lexsort((cell[2], cell[1], cell[0], k))
        cell, k, q, X = cell[:, order], k[order], q[order], X[:, order]
        brk = np.flatnonzero((cell[:, 1:] != cell[:, :-1]).any(axis=0) | (k[1:] != k[:-1])) + 1
        starts = np.concatenate([[0], brk])
        counts = np.diff(np.concatenate([starts, [q.size]]))
        lo = np.minimum.reduceat(X, starts, axis=1)
        hi = np.maximum.reduceat(X, starts, axis=1)
        centre = 0.5 * (lo + hi)
        rho = 0.5 * np.sqrt(np.square(hi - lo).sum(axis=0))
        rho = rho * (1 + 1e-9) + 1e-12 * np.abs(centre).max(axis=0)
        return q, counts, centre, rho

    def _probe_groups(self, PT, far, best, width=None, crowded=0):
        """The probe of the queries ``far`` (an exact upper bound before the
        descent), by groups of queries in cells of ``_PROBE_CELLS`` grid
        cells (the first ``crowded``, queries of crowded cells,
        ``_CROWDED_PROBE_CELLS``): a beam descent (:meth:`_beam`, ``width`` nodes a level) from
        each group's centre, whose leaves every member scans. Members whose
        probe lies beyond ``_ODD_PROBE`` times their box distance to the
        leaves they scanned and beyond ``_ODD_PROBE_SHARE`` of the mesh's
        diagonal are probed again so, with a beam of ``_WIDE_BEAM``: a beam
        that followed boxes holding the point but not the triangle it lies
        on (a point far from the mesh is as far from the boxes, and is not
        probed again)."""
        cells = np.full(far.size, float(_PROBE_CELLS))
        cells[:crowded] = _CROWDED_PROBE_CELLS
        q, counts, centre, _ = self._query_groups(PT, far, cells * self._h)
        beam = self._beam(centre, width)[np.repeat(np.arange(counts.size), counts)]
        n_leaves = 1 << self._depth
        pair = sorted_unique(beam + n_leaves * np.arange(q.size)[:, None])  # grouped by query
        self._scan_leaves(PT, q[pair // n_leaves], pair % n_leaves, best)
        if width is not None:
            return
        box = np.take(self._bvh[self._depth], beam, axis=1)                 # (6, k, width)
        p = np.take(PT, q, axis=1)[:, :, None]
        with np.errstate(invalid="ignore"):                                 # (padding: empty boxes)
            gap = np.maximum(np.maximum(box[:3] - p, p - box[3:]), 0.0)
            near2 = np.einsum("kqj,kqj->qj", gap, gap)
        near2[~np.isfinite(near2)] = np.inf
        d2 = best.d2[q]
        far2 = _ODD_PROBE_SHARE ** 2 * float(np.square(self._hi - self._lo).sum())
        odd = q[(d2 > _ODD_PROBE ** 2 * near2.min(axis=1)) & (d2 > far2)]
        if odd.size:
            self._probe_groups(PT, odd, best, width=_WIDE_BEAM)

    def _beam(self, p, width=None):
        """The leaves a beam search from the points ``p`` (3, k) reaches: at
        each level the ``width`` (default ``_PROBE_BEAM``) children nearest
        each point by their bounds (:meth:`_node_bounds`: box, cylinder and,
        low down, rod; by the box alone, a point inside a cone of needles
        followed the boxes of its sides, which hold it, away from the base it
        lies on), plus a billionth of the distance to the
        box's centre to break ties among boxes holding it. Without it a query
        starts with the farthest-point bounds of the boxes only, which prune
        nothing where the triangles are long (a CAD cylinder's sides: every
        leaf was visited, 2 ms a query on 64k faces). Returns the leaves
        (k, width)."""
        width = _PROBE_BEAM if width is None else width
        k = p.shape[1]
        beam = np.zeros((k, 1), dtype=np.int64)
        p = p[:, :, None]
        for level in range(1, self._depth + 1):
            node = ((beam[:, :, None] << 1) + np.arange(2)).reshape(k, -1)
            box = np.take(self._bvh[level], node, axis=1)          # (6, k, 2 * beam)
            with np.errstate(invalid="ignore"):                    # (padding: empty boxes)
                off = p - 0.5 * (box[:3] + box[3:])
                near2, _ = self._node_bounds(np.broadcast_to(p, off.shape).reshape(3, -1),
                                             node.ravel(), level)
                key = near2.reshape(node.shape) + 1e-9 * np.einsum("kqj,kqj->qj", off, off)
            key[~np.isfinite(key)] = np.inf
            if node.shape[1] > width:
                pick = np.argpartition(key, width - 1, axis=1)[:, :width]
                node, key = (np.take_along_axis(a, pick, axis=1) for a in (node, key))
            best_node = np.take_along_axis(node, key.argmin(axis=1)[:, None], axis=1)
            beam = np.where(np.isfinite(key), node, best_node)   # (a padding node: the best)
        return beam

    def _scan_leaves(self, PT, q, leaf, best, probe=True):
        """Scan the triangles of the leaves ``leaf`` for the queries ``q``
        (grouped by query); ties to the lowest face."""
        t, own = ragged_ranges(leaf * _LEAF, np.full(q.size, _LEAF, dtype=np.int64))
        ok = t < self.n_faces
        self._scan(PT, q[own[ok]], t[ok], best, probe, edges=False, lowest_face=True)


class BestPairs:
    """Running per-query best of a closest-point search: squared distance
    (infinite until one is found), internal triangle id and the kernel's
    ``(v, w)`` (:func:`closest_result` makes the answers of them)."""

    def __init__(self, n):
        self.d2 = np.full(n, np.inf)
        self.t = np.zeros(n, dtype=np.int64)
        self.v = np.zeros(n)
        self.w = np.zeros(n)

    def put(self, rows, t, v, w, d2):
        """Make the pairs ``(t, v, w, d2)`` the best of the queries ``rows``."""
        self.t[rows] = t
        self.v[rows] = v
        self.w[rows] = w
        self.d2[rows] = d2


def _widen_bounds(near2, far2, rho):
    """Squared node bounds from a ball's centre (``near2``, ``far2``, from
    :meth:`TriangleIndex._node_bounds`) made bounds for every point of the
    ball (radius ``rho``): the nearest distance less ``rho`` (at least 0),
    the farthest plus ``rho``, with relative margins far above rounding."""
    near = np.sqrt(np.maximum(near2, 0.0))
    near *= 1 - 1e-12
    near -= rho
    np.maximum(near, 0.0, out=near)
    far = np.sqrt(far2)
    far *= 1 + 1e-12
    far += rho
    return near * near, far * far


def _run_lengths(q):
    """Lengths of the runs of equal consecutive values of ``q``."""
    if q.size == 0:
        return np.zeros(0, dtype=np.int64)
    brk = np.flatnonzero(q[1:] != q[:-1]) + 1
    return np.diff(np.concatenate([[0], brk, [q.size]]))


@plain_pages
def closest_points(V, F, P):
    """Nearest point on the mesh ``(V, F)`` for every row of ``P`` (builds a
    :class:`TriangleIndex` and queries it once; build the index yourself to
    query the same mesh several times).

    Returns
    -------
    ClosestPoints
        ``face`` (q,) int64, ``point`` (q,3), ``bary`` (q,3), ``distance`` (q,).

    Examples
    --------
    >>> r = closest_points([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]], [[0.2, 0.2, 1.0]])
    >>> r.point.round(12).tolist(), r.bary.round(12).tolist()
    ([[0.2, 0.2, 0.0]], [[0.6, 0.2, 0.2]])
    """
    return TriangleIndex(V, F).closest(P)
