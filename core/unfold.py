"""Fold repair: dense faces an edit turned over, put back (the guard of :func:`~.binding.deform`).

A dense vertex follows the subdivision surface of the edited cage at its
bound point. Where the cage is locally fine and an edit lifts one cage
vertex against an unmoved neighbour, the surface's displacement changes by
a large share of its own size over a short distance; a thin dense face
standing across that slope (a wall of the scan nearly along the lift) can
then turn over, whatever carries the detail: the bound points alone (no
detail) fold it too.

The repair, on the dense mesh itself:

    detect   a face is *turned over* when its normal turned by more than 90
             degrees from its rest normal ("away", the cheap test, on the
             faces the deform may have changed: :func:`away_rows`,
             :class:`FineFaceGroups`), and by more than ``TURNED_DEG`` (60)
             from its rest normal turned by the cage's rotation at its first
             corner (:func:`ring_rotations`: so a face
             that only follows a large rotation of the edit, e.g. an arm bent
             a half turn, is left alone, and one turned by 100 degrees where
             the cage turned by 20 is not)
    region   the vertices of the turned-over faces and their one-ring
    relax    ``SWEEPS`` Jacobi sweeps of ``x_i = mean(x_j) + A_i d_i`` over
             the region (neighbours ``j`` around the faces of ``i``, weighted
             by the inverse of their rest edge's length; ``d_i`` the rest
             offset from that mean, mapped by the cage's local
             linear map ``A_i`` (:func:`ring_linear_maps`: its rotation, and
             its scale and stretch, so a region of a cage scaled to half
             takes its rest shape at half the size, not at full size between
             halved neighbours, where it folded again): the region takes
             its rest shape, moved with its boundary
    repeat   up to ``ROUNDS`` times, with the one-ring of any face still
             turned over added to the region

Nothing that does not turn a face over is changed: the identity and rigid
motions stay exact. The repair depends only on the unrepaired positions
(the "raw" deform) of the region and its one-ring, so an incremental
deform that restores the last repair's raw rows and detects on the faces
around its recomputed rows and those restored ones, and on the faces the
last one found away from rest, gives what a full deform gives.
"""

from typing import NamedTuple

import numpy as np

from ._groups import (distinct, member_of, ragged_entries, ragged_ranges, sorted_unique,
                      stable_argsort)
from ._parallel import WORKERS, blocks, run_blocks, run_each
from .mesh import (DOTS_BLOCK, NORMALS_BLOCK, area_normals_rows, cross_columns, dot_columns,
                   normal_dots, unit_rows)
from .topology import edge_map

__all__ = ["CageRings", "Copies", "FaceBatch", "FaceStars", "FineFaceGroups", "Neighbours",
           "Repair", "away_rows", "nearest_rotations", "repair", "rest_normals",
           "ring_linear_maps", "ring_rotations", "turned_over"]

#: Jacobi sweeps per round of the repair
SWEEPS = 8

#: rounds of the repair at most (each re-detects and grows the region)
ROUNDS = 4

#: a face away from rest is turned over when its normal is also more than this many
#: degrees from its rest normal turned by the cage's rotation there
TURNED_DEG = 60.0

#: a face whose rest area normal is shorter than this times its longest edge squared (its
#: height over that edge below this share of it) is degenerate at rest: never turned over
FLAT_AT_REST = 1e-6

#: the relaxation weighs an edge shorter than this share of its region's mean edge as
#: that long (a zero-length edge of an unwelded scan's welded copies, or of a degenerate
#: face, would weigh infinitely)
EDGE_FLOOR = 1e-3

#: :func:`away_rows` and :class:`FaceBatch` split their faces over the worker
#: threads from this many on (below, the hand-offs cost more than they save)
_AWAY_THREADS_MIN = 8192


class FaceStars(NamedTuple):
    """The faces around each vertex (CSR): ``faces[start[v]:start[v + 1]]``."""

    start: np.ndarray   #: (n+1,) int64
    faces: np.ndarray   #: (3m,) int32 (int64 past 2^31 faces), face ids grouped by vertex
    seen: np.ndarray    #: (m,) bool scratch of :meth:`around`, all False between calls

    @classmethod
    def of(cls, F, n):
        """The stars of the ``n`` vertices of the triangles ``F``."""
        flat = F.ravel()
        start = np.zeros(n + 1, dtype=np.int64)
        np.cumsum(np.bincount(flat, minlength=n), out=start[1:])
        faces = stable_argsort(flat) // 3
        if F.shape[0] < 2**31:
            faces = faces.astype(np.int32)       # half the bytes of a 2M-face scan's 48 MB
        return cls(start, faces, np.zeros(F.shape[0], dtype=bool))

    def around(self, vertices):
        """The distinct faces (ascending, int64) touching any of ``vertices``
        (duplicates allowed), by :func:`~._groups.distinct` over the scratch
        mask ``seen``. Not for two threads at once (the repair runs under the
        binding's lock)."""
        vertices = np.asarray(vertices, dtype=np.int64)
        first = self.start[vertices]
        return distinct(self.faces[ragged_entries(first, self.start[vertices + 1] - first)],
                        self.seen)


class FineFaceGroups(NamedTuple):
    """Per fine face of a binding, the dense faces with a corner bound to it,
    with their corner rows and rest normals laid out in that order: the faces
    around the rows an incremental deform rewrote (the rows of some fine
    faces) are then a few contiguous runs, not a search around each row.

    A face is *owned* by the fine face its first corner is bound to and
    *shared* with its other distinct fine faces (listed again under each,
    after all the owned entries); :meth:`entries` lists a shared entry only
    when its owner is not asked for, so a face is tested once (twice only
    when it lies over three fine faces, two of them asked for and not its
    owner): two levels on the bunny x16, 5 cage vertices moved, 52k faces
    tested instead of 80k.

    The fine faces come in blocks of ``block`` consecutive ones (those of one
    cage face); each fine face's shared entries owned in another block come
    first, those owned in its own block after ``near_start``. An asked block
    is usually whole (every fine face of it owning entries asked for), and
    the shared entries owned in a whole block are never listed: not even
    looked at (5 cage vertices of the bunny x16 moved: 2k shared entries
    looked at instead of 39k, the 37k others owned by asked faces)."""

    start: np.ndarray         #: (m_fine+1,) int64, owned entries of each fine face
    shared_start: np.ndarray  #: (m_fine+1,) int64, its shared entries (offset by the owned ones)
    near_start: np.ndarray    #: (m_fine,) int64, its shared entries owned in its own block
    owning: np.ndarray        #: (m_fine // block + 1,) int64, fine faces owning entries per block
    block: int                #: fine faces per block
    faces: np.ndarray         #: (e,) int32 (int64 past 2^31 faces)
    owner: np.ndarray         #: (e - m,) int32 (as faces), the owner of each shared entry
    corners: np.ndarray       #: (3,e) int32 (int64 past 2^31 vertices), the faces' corners
    rest: np.ndarray          #: (3,e) the faces' rest normals
    seen: np.ndarray          #: (m_fine,) bool scratch of :meth:`entries`, all False between calls

    @classmethod
    def of(cls, F, fine_face, m_fine, rest_normals, block=1):
        """The groups of the faces ``F`` (m,3) whose vertices are bound to the
        fine faces ``fine_face`` (n,) (of ``m_fine``), with their
        ``rest_normals`` (3,m); ``block``: fine faces per block (any positive
        count gives the same :meth:`entries`; those of a cage face, the
        fastest)."""
        g = fine_face[F]
        second = np.flatnonzero(g[:, 1] != g[:, 0])
        third = np.flatnonzero((g[:, 2] != g[:, 0]) & (g[:, 2] != g[:, 1]))
        shared_group = np.concatenate([g[second, 1], g[third, 2]])
        shared = np.concatenate([second, third])
        near = g[shared, 0] // block == shared_group // block
        order = stable_argsort(2 * shared_group + near)  # (by group, far first)
        shared, shared_group, near = shared[order], shared_group[order], near[order]
        faces = np.concatenate([stable_argsort(g[:, 0]), shared])
        start, shared_start = (np.zeros(m_fine + 1, dtype=np.int64) for _ in range(2))
        owned_count = np.bincount(g[:, 0], minlength=m_fine)
        np.cumsum(owned_count, out=start[1:])
        np.cumsum(np.bincount(shared_group, minlength=m_fine), out=shared_start[1:])
        shared_start += F.shape[0]
        near_start = shared_start[1:] - np.bincount(shared_group[near], minlength=m_fine)
        owning = np.bincount(np.flatnonzero(owned_count) // block,
                             minlength=m_fine // block + 1)
        FT = np.ascontiguousarray(F.T, dtype=np.int32 if F.shape[0] and F.max() < 2**31
                                  else np.int64)
        corners = np.take(FT, faces, axis=1)       # (F[faces].T made contiguous: 8x the time)
        rest = np.ascontiguousarray(np.take(rest_normals, faces, axis=1))
        small = np.int32 if max(F.shape[0], m_fine) < 2**31 else np.int64  # (a 2M-face scan
        return cls(start, shared_start, near_start, owning, int(block),   # at five levels:
                   faces.astype(small), g[shared, 0].astype(small),       # 3M entries)
                   corners, rest, np.zeros(m_fine, dtype=bool))

    def entries(self, fine_faces):
        """The entries (positions in ``faces``) of the faces with a corner
        bound to one of the distinct ``fine_faces``: their owned entries and
        the shared ones whose owner is not among them. Not for two threads
        at once (the scratch mask ``seen``; the repair runs under the
        binding's lock)."""
        first = self.start[fine_faces]
        owned = ragged_entries(first, self.start[fine_faces + 1] - first)
        # (in a whole block, the shared entries owned in the block are owned by asked faces)
        block = fine_faces // self.block
        asked = np.bincount(block[self.start[fine_faces + 1] > first],
                            minlength=self.owning.shape[0])
        first = self.shared_start[fine_faces]
        end = np.where(asked[block] == self.owning[block], self.near_start[fine_faces],
                       self.shared_start[fine_faces + 1])
        shared = ragged_entries(first, end - first)
        self.seen[fine_faces] = True
        shared = shared[~self.seen[self.owner[shared - self.start[-1]]]]
        self.seen[fine_faces] = False
        return np.concatenate([owned, shared])


class FaceBatch(NamedTuple):
    """Faces the fold test reads again and again (those around the rows of a
    drag, moved again at every step), their corner rows and rest normals as
    the first test gathered them, block by block: each test then reads them
    in order (no gathers but the positions')."""

    columns: np.ndarray   #: (k,) int, the columns of the triangles gathered
    faces: object         #: (c,) int face of each column (None: the columns are the faces)
    blocks: dict          #: first column of each :func:`_below_zero` block -> corners, rest (3,b)

    @staticmethod
    def size(FT, columns, rest_normals):
        """The bytes the batch of :meth:`tested` takes."""
        return columns.shape[0] * (3 * FT.itemsize + 3 * rest_normals.itemsize
                                   + columns.itemsize)

    @classmethod
    def tested(cls, X, FT, columns, rest_normals, faces=None, keep=True):
        """``(away, batch)``: the faces (distinct, ascending, int64) of the
        ``columns`` (k,) of the triangles ``FT`` (3,c) and their
        ``rest_normals`` (3,c) whose normal on ``X`` points away from rest
        (:func:`away_rows`' test, its blocks gathered as it gathers them; the
        face of column ``j`` is ``faces[j]``, or ``j`` for None: a column
        may stand for a face twice, :class:`FineFaceGroups`' entries), and the
        batch of those columns: the gathered blocks kept (None without
        ``keep``)."""
        batch = cls(columns, faces, {}) if keep else None

        def dots(s, e):
            T, R = _gathered(FT, rest_normals, columns[s:e])
            if keep:
                batch.blocks[s] = (T, R)
            return normal_dots(X, T, R)
        return _faces_of(columns[_below_zero(columns.shape[0], dots)], faces), batch

    def away(self, X):
        """The faces (distinct, ascending, int64) whose area normal over ``X``
        (n,3) points away from their rest normal (:func:`away_rows`' test)."""
        at = _below_zero(self.columns.shape[0], lambda s, e: normal_dots(X, *self.blocks[s]))
        return _faces_of(self.columns[at], self.faces)


def _faces_of(columns, faces):
    """The distinct faces (ascending int64) of ``columns`` (``faces[columns]``, or
    the columns themselves for ``faces`` None)."""
    return sorted_unique(columns if faces is None else faces[columns]).astype(np.int64, copy=False)


class CageRings(NamedTuple):
    """The cage's vertex one-rings (CSR over its distinct edges, both ways),
    its faces and the faces around each vertex, for :func:`ring_rotations`."""

    start: np.ndarray   #: (n+1,) int64
    other: np.ndarray   #: (2e,) int64, the ring of each vertex in turn
    F: np.ndarray       #: (m,3) int64
    stars: FaceStars    #: the faces around each vertex

    @classmethod
    def of(cls, F, n):
        E = edge_map(F, n).E
        a, b = E[:, 0], E[:, 1]
        src, dst = np.concatenate([a, b]), np.concatenate([b, a])
        order = stable_argsort(src)
        start = np.zeros(n + 1, dtype=np.int64)
        np.cumsum(np.bincount(src, minlength=n), out=start[1:])
        return cls(start, dst[order], F, FaceStars.of(F, n))

    def normals(self, V, vertices):
        """The area-weighted unit normals (k,3) at the cage ``vertices`` on
        positions ``V`` (those of :func:`~.mesh.vertex_normals`, from their own
        faces only, summed in another order)."""
        first = self.stars.start[vertices]
        k, owner = ragged_ranges(first, self.stars.start[vertices + 1] - first)
        n = area_normals_rows(V, self.F[self.stars.faces[k]].T)
        total = np.stack([np.bincount(owner, n[:, c], vertices.shape[0]) for c in range(3)],
                         axis=1)
        return unit_rows(total)


def nearest_rotations(M):
    """The rotations (k,3,3) nearest the matrices ``M`` (k,3,3) (polar
    factor, a reflection made a rotation)."""
    U, _, Vt = np.linalg.svd(M)
    d = np.sign(np.linalg.det(U @ Vt))
    U[:, :, 2] *= np.where(d == 0, 1.0, d)[:, None]
    return U @ Vt


def ring_rotations(V0, V1, rings, vertices):
    """Per cage vertex of ``vertices``: the rotation (k,3,3) that best takes
    its one-ring's edges (and its area normal, so a flat or straight ring
    still has one) on ``V0`` to those on ``V1`` (least squares: Procrustes).
    Exact for a rigid motion."""
    a, b, owner = _ring_edges(V0, V1, rings, vertices)
    M = _outer_sums(b, a, owner, vertices.shape[0])
    n0, n1 = (rings.normals(V, vertices) for V in (V0, V1))
    scale = np.bincount(owner, np.einsum("ij,ij->i", a, a), vertices.shape[0])
    M += scale[:, None, None] * n1[:, :, None] * n0[:, None, :]
    return nearest_rotations(M)


def _ring_edges(V0, V1, rings, vertices):
    """The one-ring edges of the cage ``vertices`` on ``V0`` and on ``V1``
    ((e,3) each, from the vertex) and the row of ``vertices`` each is of."""
    counts = rings.start[vertices + 1] - rings.start[vertices]
    k, owner = ragged_ranges(rings.start[vertices], counts)
    j = rings.other[k]
    return V0[j] - V0[vertices[owner]], V1[j] - V1[vertices[owner]], owner


def _outer_sums(x, y, owner, q):
    """(q,3,3) per row ``r < q`` the sum of the outer products ``x_e y_e^T``
    of the rows ``e`` with ``owner[e] == r`` (a bincount per entry: in the
    rows' order, as ``np.add.at`` adds, several times faster)."""
    out = np.empty((q, 3, 3))
    for r in range(3):
        for c in range(3):
            out[:, r, c] = np.bincount(owner, x[:, r] * y[:, c], q)
    return out


def ring_linear_maps(V0, V1, rings, vertices):
    """Per cage vertex of ``vertices``: the linear map (k,3,3) that best takes
    its one-ring's edges on ``V0`` to those on ``V1`` (least squares), its
    area normal going to the new one stretched as the ring's edges are on
    average (so a flat ring has one too); where that map is undefined (a
    degenerate ring) or turns the ring inside out (a folded edit), the
    ring's rotation (:func:`ring_rotations`, from the same sums) times that
    stretch. A rigid motion gives its rotation (to rounding), a uniform
    scale by ``s`` that scale."""
    a, b, owner = _ring_edges(V0, V1, rings, vertices)
    q = vertices.shape[0]
    BA, AA = _outer_sums(b, a, owner, q), _outer_sums(a, a, owner, q)
    n0, n1 = (rings.normals(V, vertices) for V in (V0, V1))
    sa = AA[:, 0, 0] + AA[:, 1, 1] + AA[:, 2, 2]
    sb = np.bincount(owner, np.einsum("ij,ij->i", b, b), q)
    stretch = np.sqrt(np.divide(sb, sa, out=np.ones(q), where=sa > 0))
    normal_term = n1[:, :, None] * n0[:, None, :]
    procrustes = BA + sa[:, None, None] * normal_term          # ring_rotations' matrix
    BA += (sa * stretch)[:, None, None] * normal_term
    AA += sa[:, None, None] * n0[:, :, None] * n0[:, None, :]
    A = np.empty((q, 3, 3))
    good = np.zeros(q, dtype=bool)
    ok = np.flatnonzero(np.linalg.det(AA) > 1e-9 * sa ** 3)
    if ok.size:
        M = BA[ok] @ _inverses(AA[ok])
        keep = np.linalg.det(M) > 0
        A[ok[keep]] = M[keep]
        good[ok[keep]] = True
    bad = np.flatnonzero(~good)
    if bad.size:
        A[bad] = nearest_rotations(procrustes[bad]) * stretch[bad, None, None]
    return A


def _inverses(A):
    """The inverses (k,3,3) of the invertible matrices ``A`` (k,3,3), by the
    adjugate (the cross products of the rows over the determinant).
    ``np.linalg.inv`` on a stack of 3x3 matrices goes through LAPACK's
    ``gesv`` once per matrix, whose triangular solves OpenBLAS runs on its
    threads: on this 2-core machine under load (numpy#17166, OpenBLAS#4387)
    0.45-1.3 s for 1,000 matrices against 0.3 ms with one thread, so a
    fold repair around 1,000 cage vertices (an incremental deform of the
    bunny, 1,000 cage vertices moved) took 190 ms of its 230 in it."""
    r0, r1, r2 = A[:, 0], A[:, 1], A[:, 2]
    adj = np.stack([np.cross(r1, r2), np.cross(r2, r0), np.cross(r0, r1)], axis=2)
    det = np.einsum("ij,ij->i", r0, adj[:, :, 0])
    return adj / det[:, None, None]


class Repair(NamedTuple):
    """What a repair changed: the rows and their unrepaired ("raw")
    positions; and the faces found pointing away from their rest normal
    (those turned over, and those only turned with the cage: a later move
    of the cage elsewhere may change their rotation, so an incremental
    deform tests them again)."""

    rows: np.ndarray    #: (k,) int64, ascending
    raw: np.ndarray     #: (k,3) float64
    away: np.ndarray    #: (j,) int64, ascending

    @classmethod
    def none(cls):
        return cls(np.zeros(0, dtype=np.int64), np.zeros((0, 3)), np.zeros(0, dtype=np.int64))


def rest_normals(PT, FT):
    """The rest area normals (3,m) float32 of the faces ``FT`` (3,m) over
    positions ``PT`` (3,n), zero for faces degenerate at rest (area normal
    shorter than ``FLAT_AT_REST`` times their longest edge squared: collinear
    corners). Such a face has no side to turn over; with the rounding noise
    its normal had, a deform and an incremental one (the same positions to
    1e-16, not bit for bit) could disagree on whether it folded and repair
    different regions: a scan with 3% of its faces collinear, its 4-face
    cage's vertex lifted 1% of the diagonal, had 2,011 rows repaired against
    2,054, 0.4% of the diagonal apart (64 rows now, in both)."""
    out = np.empty(FT.shape, np.float32)

    def block(s, e):
        P0, P1, P2 = (np.take(PT, FT[c, s:e], axis=1) for c in range(3))
        e1, e2, e3 = P1 - P0, P2 - P0, P2 - P1
        out[:, s:e] = cross_columns(e1, e2)       # (area_normals_t's arithmetic)
        longest = np.maximum(np.maximum(dot_columns(e1, e1), dot_columns(e3, e3)),
                             dot_columns(e2, e2))
        n = out[:, s:e].astype(np.float64)          # (the float32 normal, tested)
        flat = dot_columns(n, n) <= FLAT_AT_REST ** 2 * longest * longest
        out[:, s + np.flatnonzero(flat)] = 0.0
    run_blocks(block, blocks(FT.shape[1], NORMALS_BLOCK))
    return out


def away_rows(X, FT, faces, rest_normals):
    """The faces whose area normal over positions ``X`` (n,3) points away
    from their rest normal (negative dot product), among the columns
    ``faces`` (None: every one, ascending) of the triangles ``FT`` (3,k) and
    their ``rest_normals`` (3,k) (in their order: ascending stays
    ascending): :func:`~.mesh.normal_dots` below 0, in a part per worker
    thread from ``_AWAY_THREADS_MIN`` columns on (the gathers are most of
    it: 48k faces around 5 moved cage vertices' rows, 1.66 -> 1.28 ms on
    two), each part ``DOTS_BLOCK`` columns at a time (their corners and rest
    normals gathered for the block: 0.15 of 1.7 ms against the part's at
    once; every face: the blocks are slices)."""
    if faces is None:
        return _below_zero(FT.shape[1],
                           lambda s, e: normal_dots(X, FT[:, s:e], rest_normals[:, s:e]))
    at = _below_zero(faces.shape[0],
                     lambda s, e: normal_dots(X, *_gathered(FT, rest_normals, faces[s:e])))
    return faces[at]


def _gathered(FT, rest_normals, columns):
    """The corners and rest normals (3, b) of the triangles' ``columns`` (in
    range: "wrap" gathers, half the time of "raise")."""
    return (np.take(FT, columns, axis=1, mode="wrap"),
            np.take(rest_normals, columns, axis=1, mode="wrap"))


def _below_zero(n, dots):
    """The columns (ascending int64) of ``range(n)`` whose ``dots(s, e)``
    (the values of columns ``s:e``) are below 0: ``DOTS_BLOCK`` columns at a
    time, in a part per worker thread from ``_AWAY_THREADS_MIN`` on."""
    def part(span):
        found = [np.flatnonzero(dots(s, min(s + DOTS_BLOCK, span[1])) < 0) + s
                 for s in range(span[0], span[1], DOTS_BLOCK)]
        return np.concatenate(found) if found else np.zeros(0, dtype=np.int64)
    return np.concatenate(run_each(part, blocks(n, -(-n // WORKERS)) or [(0, 0)],
                                   threads=n >= _AWAY_THREADS_MIN))


def turned_over(X, FT, away, rest_normals, rotate):
    """The faces among ``away`` (faces :func:`away_rows` gives, ascending) turned
    over on ``X`` (n,3): their normal is also more than ``TURNED_DEG`` from
    their rest normal turned by ``rotate(vertices, vectors)`` (the frame
    rotation at their first corner). (With 90 degrees, faces of the bunny
    x16 turned by 90-113 degrees where the cage turned by 13-23 were left
    folded: 49 on a one-ring lifted by 1% of the diagonal, 2 with 60.)"""
    if away.shape[0] == 0:
        return away
    n = area_normals_rows(X, np.take(FT, away, axis=1))
    turned = rotate(FT[0, away], np.ascontiguousarray(np.take(rest_normals, away, axis=1).T))
    bound = np.cos(np.radians(TURNED_DEG)) * np.sqrt(
        np.einsum("ij,ij->i", turned, turned) * np.einsum("ij,ij->i", n, n))
    return away[np.einsum("ij,ij->i", turned, n) < bound]


class Copies(NamedTuple):
    """Dense vertices at one point (an unwelded scan's), for :func:`repair`:
    each vertex's representative (the first at its position) and, per
    representative, its copies (CSR, itself included)."""

    weld: np.ndarray    #: (n,) int64 the representative of each vertex
    start: np.ndarray   #: (n+1,) int64 copies of vertex v: order[start[v]:start[v+1]]
    order: np.ndarray   #: (n,) int64 vertices grouped by representative

    @classmethod
    def of(cls, V):
        """The copies among the positions ``V`` (n,3) (bit-identical rows), or
        None when every vertex has a point of its own."""
        n = V.shape[0]
        # first one sort of a hash of the bits (distinct hashes: distinct points; 0.07
        # of the 0.39 s a lexsort takes for a million points)
        bits = np.ascontiguousarray(V, dtype=np.float64).view(np.uint64)
        h = np.sort(bits[:, 0] * np.uint64(0x9E3779B97F4A7C15) ^ bits[:, 1] * np.uint64(
            0xC2B2AE3D27D4EB4F) ^ bits[:, 2] * np.uint64(0x165667B19E3779F9))
        if n < 2 or (h[1:] != h[:-1]).all():
            return None
        order = np.lexsort((V[:, 2], V[:, 1], V[:, 0]))
        S = V[order]
        first = np.ones(n, dtype=bool)
        first[1:] = (S[1:] != S[:-1]).any(axis=1)
        if first.all():
            return None
        group = np.cumsum(first) - 1
        weld = np.empty(n, dtype=np.int64)
        weld[order] = np.minimum.reduceat(order, np.flatnonzero(first))[group]
        start = np.zeros(n + 1, dtype=np.int64)
        np.cumsum(np.bincount(weld, minlength=n), out=start[1:])
        return cls(weld, start, stable_argsort(weld))

    def of_vertices(self, reps):
        """Every copy of the representatives ``reps`` (distinct), ascending."""
        return np.sort(self.order[ragged_entries(self.start[reps],
                                                 self.start[reps + 1] - self.start[reps])])


def ring(stars, F, faces):
    """The vertices of ``faces`` and their one-ring (ascending)."""
    return sorted_unique(F[stars.around(sorted_unique(F[faces]))])


class Neighbours(NamedTuple):
    """Per vertex of a region, the other corners of its faces (each counted
    once per face), grouped by region vertex in runs starting at ``start``
    (each at least 2 long: every vertex is on a face), each weighted by the
    inverse of its rest edge's length (``weight``; ``total``: their sum per
    region vertex)."""

    other: np.ndarray   #: (p,) int64, neighbour vertices, region vertex by region vertex
    start: np.ndarray   #: (r,) int64, where each region vertex's run begins
    weight: np.ndarray  #: (p,) float64, 1 / the rest length of each neighbour's edge
    total: np.ndarray   #: (r,) float64, the weights' sum per region vertex

    @classmethod
    def of(cls, F, stars, region, V_rest):
        """The neighbours of ``region`` (distinct vertices, ascending) on the
        faces ``F``, weighted by the rest positions ``V_rest`` (an edge shorter
        than ``EDGE_FLOOR`` of the region's mean edge counts as that long; a
        region of zero-length edges alone weighs them all equally)."""
        T = F[stars.around(region)]
        owner, other = [], []
        for k in range(3):
            s = np.minimum(np.searchsorted(region, T[:, k]), region.shape[0] - 1)
            keep = region[s] == T[:, k]
            for j in (1, 2):
                owner.append(s[keep])
                other.append(T[keep, (k + j) % 3])
        owner, other = np.concatenate(owner), np.concatenate(other)
        order = stable_argsort(owner)
        owner, other = owner[order], other[order]
        count = np.bincount(owner, minlength=region.shape[0])
        edge = V_rest[region[owner]] - V_rest[other]
        length = np.sqrt(np.einsum("ij,ij->i", edge, edge))
        floor = EDGE_FLOOR * float(length.mean())
        weight = 1.0 / np.maximum(length, floor) if floor > 0 else np.ones_like(length)
        start = np.cumsum(count) - count
        return cls(other, start, weight, np.add.reduceat(weight, start))

    def means(self, X):
        """The weighted mean neighbour position of each region vertex, (r,3)."""
        return np.add.reduceat(X[self.other] * self.weight[:, None], self.start,
                               axis=0) / self.total[:, None]


def relax(X, V_rest, F, stars, region, transform):
    """``SWEEPS`` Jacobi sweeps of ``x_i = mean(x_j) + A_i d_i`` over
    ``region`` of ``X`` (in place), the means weighted by the inverse rest
    edge lengths (:class:`Neighbours`); ``transform(vertices, vectors)`` maps
    the rest offsets ``d_i`` by the cage's local map ``A_i``.

    Weighted, a short edge keeps its length where the uniform mean stretched
    it as much as a long one: the region's boundary moves a share of the
    edit's slope onto each edge, and on a scan's thin triangles the uniform
    share of a short edge turned them over (faces left turned over after the
    repair, 100 edits of 3% on 1,000-face cages: rocker-arm 28 -> 2, bunny
    219 -> 101, homer 149 -> 98, cow 24 -> 19; the relaxation itself had
    turned faces the raw deform had not)."""
    near = Neighbours.of(F, stars, region, V_rest)
    offset = transform(region, V_rest[region] - near.means(V_rest))
    for _ in range(SWEEPS):
        X[region] = near.means(X) + offset


def repair(X, V_rest, F, FT, stars, folded, rest_normals, rotate, away, transform=None,
           copies=None):
    """Put the turned-over faces ``folded`` of ``X`` back (in place);
    ``away`` the faces found pointing away from rest (kept in the result);
    ``rotate`` turns rest normals for the test, ``transform`` (default
    ``rotate``) maps the rest shape's offsets in the relaxation. With
    ``copies`` (:class:`Copies`), ``F`` and ``stars`` are the welded faces
    (``FT`` the faces as they are), the region is relaxed on the welded
    vertices and every copy follows its vertex (an unwelded scan, every
    triangle on vertices of its own, was relaxed triangle by triangle and
    opened cracks up to 45% of its size).

    Returns
    -------
    Repair
        The rows changed and their positions before the repair.
    """
    if folded.shape[0] == 0:
        return Repair.none()._replace(away=away)
    region = np.zeros(0, dtype=np.int64)
    rows, raw = [], []
    for _ in range(ROUNDS):
        grown = sorted_unique(np.concatenate([region, ring(stars, F, folded)]))
        new = grown[~member_of(grown, region)]
        if copies is not None:
            new = copies.of_vertices(new)
        rows.append(new)
        raw.append(X[new])
        region = grown
        relax(X, V_rest, F, stars, region, rotate if transform is None else transform)
        if copies is not None:
            every = copies.of_vertices(region)
            X[every] = X[copies.weld[every]]
        left = away_rows(X, FT, stars.around(region), rest_normals)
        folded = turned_over(X, FT, left, rest_normals, rotate)
        if folded.shape[0] == 0:
            break
    rows = np.concatenate(rows)
    order = np.argsort(rows)
    return Repair(rows[order], np.concatenate(raw)[order], away)
