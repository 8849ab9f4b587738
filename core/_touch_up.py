"""The farthest places of a finished cage moved or flipped (private; :func:`touch_up`).

The collapse and the least-squares relocation make the cage close to the input
on average; its largest distance to the input (the two-sided Hausdorff
distance, the "max deviation" a report gives) is set by a few places: a cage
vertex that the quadrics placed off the input (at a crease, a thin part), or a
point of the input that a cage edge cuts across. :func:`touch_up` measures
both directions on samples (the cage's vertices, edge midpoints and face
centroids to the input, the input's vertices to the cage), then tries, at
the worst few places (within ``Tuning.touch_share`` of the largest distance):

    move    a cage vertex far from the input onto its closest input point
            (or halfway there)
    flip    an edge of a cage face whose samples are far from the input, or
            of the cage face nearest an input point far from the cage (the
            other diagonal of the two faces)
    pull    a corner of a face whose samples are far from the input (its
            corners near it: it cuts across the input) moved by what would
            put its farthest sample on the input (or half that)

A change is kept when it lowers the largest distance of its *region* (by at
least ``1 - Tuning.touch_gain``: smaller gains cost more mean distance than they
are worth): the
samples on the faces it changes (their distance to the input, exact; there
the quarter points ``_SAMPLES`` too: with the corners, midpoints and centroid
alone, moves that turn a large face were taken whose other points went
farther, and the rocker-arm at 2% went from 1.20 to 1.27 of Decimate's
Hausdorff distance) and the
input vertices whose nearest cage face is one of them (their distance to the
changed faces: a bound, they may now be nearer another face). Nothing else
changes, so the cage's largest distance never grows. A change is refused when
it turns a face by more than ``acos(Tuning.relocate_min_cos)`` or ends one
more than 90 degrees from the input's normals at its corners, makes a face
less compact than ``Tuning.gamma_hard`` and than half what it was, or (a
flip) touches a border or crease edge or makes an edge the cage already has:
the cage stays the same clean manifold with the same features. The changes
of one round have disjoint regions; the distances of a changed region are
written back (the input vertices' as the bound), and the next round starts
from them.

On the 23 quality cases (the shared meshes at 10%, 2% and 1,000 faces,
against Blender's Decimate, 2026-12-04) it took the geometric mean of the
Hausdorff distance from 0.778 to 0.703 and the worst case (the beetle at
1,000 faces, a cage vertex 0.41% of the diagonal off the input) from 1.29 to
1.21, for a mean distance 0.718 -> 0.734 (a vertex on the input is not where
the squared distances want it); averaged over three jittered copies 0.778 ->
0.715 and 0.718 -> 0.738, their worst cases 1.37 / 1.35 / 1.29 -> 1.26 / 1.25
/ 1.21. It costs a search structure of the input (a
:class:`~.near_query.NearQuery`), so it runs where the relocation's backward
pull does (inputs up to ``Tuning.relocate_back_max_faces``): 20-70 ms on
5k-20k-face inputs. A cage of a few faces (``_FEW_FACES``) asks the input for
a few points only: it searches the triangles near each (:class:`_FewQueries`,
the same answers) and its own faces all (a 19k-face cube to 4 faces: 120 ->
18 ms).
"""

from typing import NamedTuple

import numpy as np

from ._groups import member_of, sorted_unique
from ._collapse import compactness
from ._face_tracker import faces_across
from .mesh import cross_rows, flat_faces, used_vertices
from .near_query import NearQuery
from .spatial import TriangleIndex, closest_pairs, closest_result, triangle_rows
from .topology import edge_keys, edge_map

__all__ = ["Gaps", "flip_flat_faces", "measure_gaps", "touch_up"]

#: rounds of :func:`flip_flat_faces` (each flips flat faces with disjoint neighbours)
_FLAT_ROUNDS = 8

#: a cage of at most this many faces is searched over all its faces (:func:`_exhaustive`),
#: and the input (:class:`_FewQueries`) indexed only once a search asks for more than
#: ``_FEW_QUERIES`` points at once: a tetrahedron of a 19k-face cube spent 72 ms on the
#: input's index and 35 ms on the input's vertices against its own for 14 input queries
_FEW_FACES = 16
_FEW_QUERIES = 64
#: (point, face) pairs per block of :class:`_FewQueries`'s bounds
_PAIRS_BLOCK = 1 << 18
#: a change whose input vertices and new faces make more pairs than this measures them
#: with an index of its new faces (:func:`_nearest_new_faces`), not pair by pair
_INDEXED_PAIRS = 1 << 18

#: barycentric points measured on each face a change rewrites besides its corners: the
#: edge midpoints, the centroid and the quarter points (a face the change turns can move
#: away from the input between the corners, midpoints and centroid: with them alone,
#: moves were taken whose other points went farther, rocker-arm 2% 1.20 -> 1.27 of
#: Decimate's Hausdorff distance)
_SAMPLES = np.array([[2, 2, 0], [0, 2, 2], [2, 0, 2], [4 / 3, 4 / 3, 4 / 3],
                     [1, 3, 0], [3, 1, 0], [0, 1, 3], [0, 3, 1], [1, 0, 3], [3, 0, 1],
                     [2, 1, 1], [1, 2, 1], [1, 1, 2]]) / 4.0
_CENTROID = 3      #: the row of _SAMPLES that is the centroid


class Gaps(NamedTuple):
    """The distances between a cage and the input, both ways, as sampled."""

    face_far: np.ndarray     #: (m,) largest distance of each cage face's samples to the input
    vertex_far: np.ndarray   #: (n,) each cage vertex's distance to the input
    vertex_near: np.ndarray  #: (n,3) its closest input point
    point_far: np.ndarray    #: (q,) each input vertex's distance to the cage
    point_face: np.ndarray   #: (q,) its nearest cage face

    @property
    def worst(self):
        """The largest distance either way."""
        return max(float(self.face_far.max(initial=0.0)), float(self.point_far.max(initial=0.0)))


def measure_gaps(V, F, inputs, P):
    """:class:`Gaps` of the cage ``(V, F)`` against the input (``inputs``, a
    :class:`~.near_query.NearQuery` or :class:`~.spatial.TriangleIndex` of
    it, and ``P``, its vertices)."""
    near = inputs.closest(V)
    far = _face_far(V, F, inputs)
    hit = _exhaustive(V, F, P) if F.shape[0] <= _FEW_FACES else NearQuery(V, F).closest(P)
    return Gaps(np.maximum(far, near.distance[F].max(axis=1)), near.distance, near.point,
                hit.distance, hit.face)


def _face_far(V, rows, inputs):
    """(r,) the largest distance to the input (``inputs``) of the centroid and
    the edge midpoints of each face ``rows`` over ``V`` (each midpoint
    measured once)."""
    em = edge_map(rows, V.shape[0])
    mid = 0.5 * (V[em.E[:, 0]] + V[em.E[:, 1]])
    d = inputs.closest(np.concatenate([mid, V[rows].mean(axis=1)])).distance
    e = mid.shape[0]
    return np.maximum(d[:e][em.face_edge].max(axis=1), d[e:])


class _Region(NamedTuple):
    """A candidate change: the faces it rewrites, and what they become."""

    faces: np.ndarray   #: (r,) rows of F it rewrites
    rows: np.ndarray    #: (r,3) the new corners of those faces
    vertex: int         #: the vertex it moves (-1: none, an edge flip)
    to: np.ndarray      #: (3,) where it moves it

    def new_edge(self, n):
        """The key (``lo * n + hi``, :func:`~.topology.edge_keys`) of the edge
        an edge flip makes, ``(c, d)`` of its rows ``(c, a, d), (c, d, b)``
        (None for a move). Two flips of one round on disjoint faces can make
        the same edge (a torus at 1e5 simplified to 28 faces: an edge of four
        faces): only the first is taken."""
        if self.vertex >= 0:
            return None
        return int(edge_keys(self.rows[0, 0], self.rows[0, 2], n))


def touch_up(V, F, Vin, Fin, fixed, keep_edges, tun, N_keep=None):
    """Lower the cage's largest distance to the input at its worst places.

    Parameters
    ----------
    V, F : (n,3) float64, (m,3) int64
        The cage (a clean oriented manifold; not modified).
    Vin, Fin : (q,3) float64, (k,3) int64
        The input it stands for (in the same units).
    fixed : (n,) bool
        Cage vertices that must not move.
    keep_edges : (e,2) int64
        Cage edges that must not be flipped besides the border (creases).
    tun : Tuning
        ``touch_rounds``, ``touch_candidates``, ``touch_share``, ``touch_gain``,
        ``touch_floor`` (the share of the diagonal: ``V`` and ``Vin`` are in
        simplify's unit-free coordinates), ``relocate_min_cos``, ``gamma_hard``.
    N_keep : (n,3) float64 or None
        Per cage vertex, the summed normals of the input it stands for: a
        face whose normal ends more than 90 degrees from the sum of its
        corners' is refused too (the engine's no-flip rule; None: off).

    Returns
    -------
    (V, F, moved)
        The new positions and faces and the (n,) mask of the vertices moved.
    """
    V, F = V.copy(), F.copy()
    moved = np.zeros(V.shape[0], dtype=bool)
    if F.shape[0] < 2 or Fin.shape[0] == 0:
        return V, F, moved
    # (a NearQuery's queries near the input: half the time of an index's)
    inputs = _FewQueries(Vin, Fin) if F.shape[0] <= _FEW_FACES else NearQuery(Vin, Fin)
    P = Vin[used_vertices(Fin, Vin.shape[0])]
    keep = _edge_keys(keep_edges, V.shape[0])
    gaps = measure_gaps(V, F, inputs, P)
    if gaps.worst <= tun.touch_floor:
        return V, F, moved
    for _ in range(tun.touch_rounds):
        taken = np.zeros(F.shape[0], dtype=bool)
        made = set()                   # the edges this round's flips made
        changes = list(_candidates(V, F, gaps, fixed, keep, tun, inputs))
        tris = [_points_after(V, c, c.rows) for c in changes]      # (r,3,3) each
        ok = _acceptable(V, F, changes, tris, tun, N_keep)
        changes = [c for c, good in zip(changes, ok) if good]
        tris = [T for T, good in zip(tris, ok) if good]
        done = 0
        for change, after in zip(changes, _regions_after(V, changes, tris, inputs, P, gaps,
                                                         tun.touch_gain)):
            # (evaluated all at once on the round's cage: a change whose faces no
            # earlier one took sees its region as it was, and the input vertices
            # there, which a change only ever takes into its own faces)
            edge = change.new_edge(V.shape[0])
            if after is None or taken[change.faces].any() or \
                    (edge is not None and edge in made) or \
                    after.far >= tun.touch_gain * _region_was(change.faces, after.points, gaps):
                continue
            if edge is not None:
                made.add(edge)
            F[change.faces] = change.rows      # (V, F: this call's own copies)
            if change.vertex >= 0:
                V[change.vertex] = change.to
                moved[change.vertex] = True
            after.record(gaps, change)
            taken[change.faces] = True
            done += 1
        if done == 0:
            break
    return V, F, moved


def _exhaustive(V, F, P):
    """``NearQuery(V, F).closest(P)`` over every pair (for a cage of a few
    faces): the kernel on each point and face, per point the smallest squared
    distance and among exactly equal ones the lowest face (NearQuery's rule
    near the mesh)."""
    D, m, k = triangle_rows(*(V[F[:, c]] for c in range(3))), F.shape[0], P.shape[0]
    t = np.tile(np.arange(m), k)
    v, w, d2 = closest_pairs(np.ascontiguousarray(P.T), np.repeat(np.arange(k), m), D, t)
    best = np.arange(k) * m + d2.reshape(k, m).argmin(axis=1)   # (the first: the lowest face)
    return closest_result(D, np.arange(m), t[best], v[best], w[best], d2[best])


def _closest_on(D, P, q, t):
    """The :class:`~.spatial.ClosestPoints` of the points ``P`` (k,3) over the
    pairs (points ``q``, triangles ``t``; every point in some pair) of the
    triangles whose kernel rows are ``D`` (16, m): per point the smallest
    squared distance, the lowest triangle among exactly equal ones."""
    v, w, d2 = closest_pairs(np.ascontiguousarray(P.T), q, D, t)
    order = np.lexsort((t, d2, q))
    first = order[np.flatnonzero(np.diff(q[order], prepend=-1))]
    return closest_result(D, np.arange(D.shape[1]), t[first], v[first], w[first], d2[first])


class _FewQueries:
    """``NearQuery(V, F).closest`` for the few queries a cage of a few faces
    makes of the input: each point against the triangles whose bounding
    sphere reaches within its distance to the nearest centroid (the others
    are farther), the same kernel and rule as :func:`_exhaustive`; a
    :class:`~.near_query.NearQuery` is built (and used from then on) for a
    search of more than ``_FEW_QUERIES`` points."""

    def __init__(self, V, F):
        self.V, self.F, self.near = V, F, None
        self.D = triangle_rows(*(V[F[:, c]] for c in range(3)))
        T = V[F]
        self.centre = T.mean(axis=1)
        self.radius = np.sqrt(((T - self.centre[:, None]) ** 2).sum(axis=2).max(axis=1))

    def closest(self, P):
        """The :class:`~.spatial.ClosestPoints` of the points ``P`` (k,3) on the input."""
        if self.near is None and P.shape[0] > _FEW_QUERIES:
            self.near = NearQuery(self.V, self.F)
        if self.near is not None:
            return self.near.closest(P)
        step = max(1, _PAIRS_BLOCK // self.F.shape[0])
        none = np.zeros(0, dtype=np.int64)
        pairs = [(none, none)] + [self._near_pairs(P[s:s + step], s)
                                  for s in range(0, P.shape[0], step)]
        return _closest_on(self.D, P, *(np.concatenate(c) for c in zip(*pairs)))

    def _near_pairs(self, P, first):
        """The pairs (points ``first + i``, triangles) of :meth:`closest` for the points ``P``."""
        d = np.sqrt(sum((P[:, c, None] - self.centre[None, :, c]) ** 2 for c in range(3)))
        reach = d.min(axis=1, keepdims=True)          # a point of each face: an upper bound
        slack = 1e-9 * (1.0 + reach + self.radius.max())
        q, t = np.nonzero(d - self.radius <= reach + slack)
        return q + first, t


def _candidates(V, F, gaps, fixed, keep, tun, inputs):
    """The changes to try: each of the ``Tuning.touch_candidates`` cage
    vertices farthest from the input moved onto its closest input point, then
    halfway; each edge flipped of the faces nearest as many input vertices
    farthest from the cage and of as many faces whose samples are farthest
    from the input; then each corner of those faces moved by
    :func:`_corner_pulls`, then halfway. (A generator: each change is made
    when asked for, on the cage as it was when the round began.)"""
    k = tun.touch_candidates
    n = V.shape[0]
    bar = tun.touch_share * gaps.worst
    worst = np.argsort(-gaps.vertex_far, kind="stable")[:k]
    worst = worst[~fixed[worst] & (gaps.vertex_far[worst] >= bar)]
    off = np.argsort(-gaps.face_far, kind="stable")[:k]
    off = off[gaps.face_far[off] >= bar]
    corner = np.argsort(F.ravel(), kind="stable")
    start = np.searchsorted(F.ravel()[corner], np.arange(n + 1))

    def moves(pulls):
        for v, pull in pulls:
            star = corner[start[v]:start[v + 1]] // 3
            least = _least_move(gaps.face_far[star].max(), tun.touch_gain)
            for t in (1.0, 0.5):
                if t * np.linalg.norm(pull) > least:
                    yield _Region(star, F[star], int(v), V[v] + t * pull)

    yield from moves((v, gaps.vertex_near[v] - V[v]) for v in worst)
    far = np.argsort(-gaps.point_far, kind="stable")[:k]
    faces = sorted_unique(np.concatenate([gaps.point_face[far[gaps.point_far[far] >= bar]], off]))
    if faces.size:
        across, edges = _across(F, n)
    for f in faces:
        for j in range(3):
            flip = _flipped(F, f, j, across, edges, keep, n)
            if flip is not None:
                yield _Region(flip[0], flip[1], -1, None)
    # a face that cuts across the input (its corners near it): a corner moved so that
    # its farthest sample would land on the input, after the flips (which may do better)
    yield from moves((c, pull) for c, pull in _corner_pulls(V, F, off, inputs) if not fixed[c])


def _least_move(far, gain):
    """The shortest move of a cage vertex that may be kept when the largest
    distance of its faces' samples to the input is ``far``: a move of ``d``
    moves every sample of its faces, and the faces themselves, by at most
    ``d``, so the largest distance around it (at least ``far``) falls by at
    most ``d``, and a change is kept only where it falls below ``gain`` of
    what it was (half of that, a margin for rounding; a flat fan's cage
    weighed moves of its hub by 1e-14, each rewriting its 200 faces)."""
    return 0.5 * (1.0 - gain) * far


def _corner_pulls(V, F, faces, inputs):
    """For each corner of the ``faces`` that carries the face's sample
    farthest from the input (edge midpoints and centroid): the move (3,) that
    would put that sample on its closest input point were the corner moved
    alone by it, as (corner, move) pairs (a face cutting across a corner of
    the input: its own corners near it, an edge's midpoint far)."""
    if faces.size == 0:
        return []
    T = V[F[faces]]                                         # (f,3,3)
    S = np.concatenate([0.5 * (T + np.roll(T, -1, axis=1)), T.mean(axis=1)[:, None]], axis=1)
    hit = inputs.closest(S.reshape(-1, 3))
    d = hit.distance.reshape(-1, 4)
    far = np.argmax(d, axis=1)
    pull = (hit.point.reshape(-1, 4, 3) - S)[np.arange(faces.size), far]
    # the corners that carry the sample: an edge midpoint's two, the centroid's three
    return [(int(F[f, j]), pull[i]) for i, f in enumerate(faces) for j in range(3)
            if far[i] == 3 or j in (far[i], (far[i] + 1) % 3)]


def _edge_keys(E, n):
    """Sorted :func:`~.topology.edge_keys` of the edges ``E`` (e,2)."""
    E = np.asarray(E, dtype=np.int64).reshape(-1, 2)
    return np.sort(edge_keys(E[:, 0], E[:, 1], n))


def _has(keys, a, b, n):
    """Whether the edge (a, b) is among the sorted ``keys`` (:func:`_edge_keys`)."""
    key = edge_keys(a, b, n)
    i = int(np.searchsorted(keys, key))
    return i < keys.shape[0] and keys[i] == key


def _across(F, n):
    """(m,3) the face across the edge opposite each corner (-1 at a border,
    :func:`~._face_tracker.faces_across`), and the cage's edge keys
    (:func:`_edge_keys`)."""
    return faces_across(F, n), sorted_unique(edge_keys(F.ravel(), F[:, [1, 2, 0]].ravel(), n))


def _flipped(F, f, j, across, edges, keep, n):
    """The flip of the edge opposite corner ``j`` of face ``f``: (faces, new
    rows), or None where it is a border or kept edge or its new edge exists."""
    g = across[f, j]
    if g < 0:
        return None
    c, a, b = int(F[f, j]), int(F[f, (j + 1) % 3]), int(F[f, (j + 2) % 3])
    d = int(F[g][(F[g] != a) & (F[g] != b)][0])
    if c == d or _has(keep, a, b, n) or _has(edges, c, d, n):
        return None
    return np.array([f, g]), np.array([[c, a, d], [c, d, b]])


def _acceptable(V, F, changes, tris, tun, N_keep):
    """(k,) bool: whether each change (``tris``: its new faces' corners,
    (r,3,3) each) rewrites no face turned by more than
    ``acos(relocate_min_cos)`` from the face it replaces (a flip: from the
    pair's summed normal), none less compact than ``gamma_hard`` and than
    half the least compact of those it replaces, and (with ``N_keep``) none
    more than 90 degrees from its corners' summed input normals. All the
    changes' faces at once."""
    if not changes:
        return np.zeros(0, dtype=bool)
    owner = np.repeat(np.arange(len(changes)), [c.faces.size for c in changes])
    first = np.concatenate([[0], np.cumsum([c.faces.size for c in changes])[:-1]])
    old_rows = F[np.concatenate([c.faces for c in changes])]
    rows = np.concatenate([c.rows for c in changes])
    T_old, T = V[old_rows], np.concatenate(tris)
    old, new = _normals(T_old), _normals(T)
    flip = np.array([c.vertex < 0 for c in changes])[owner]
    pair = np.add.reduceat(old, first, axis=0)[owner]               # a flip's two faces
    reference = np.where(flip[:, None], pair, old)
    cos = np.einsum("ij,ij->i", new, reference)
    ok = cos > tun.relocate_min_cos * np.maximum(
        np.linalg.norm(reference, axis=1) * np.linalg.norm(new, axis=1), 1e-300)
    if N_keep is not None:
        ok &= np.einsum("ij,ij->i", new, N_keep[rows].sum(axis=1)) > 0
    g_old = np.minimum.reduceat(_compactness(T_old, old), first)[owner]
    ok &= _compactness(T, new) >= np.minimum(tun.gamma_hard, 0.5 * g_old)
    return np.logical_and.reduceat(ok, first)


def _normals(T):
    """(k,3) the area normals of the triangles with corners ``T`` (k,3,3)
    (those of :func:`~.mesh.area_normals_rows`, the same bits)."""
    return cross_rows(T[:, 1] - T[:, 0], T[:, 2] - T[:, 0])


def _compactness(T, N):
    """:func:`~._collapse.compactness` of the triangles with corners ``T``
    (k,3,3) and area normals ``N`` (k,3) (edge sums as
    :func:`~.mesh.squared_edges` makes them)."""
    E = np.roll(T, -1, axis=1) - T
    return compactness(np.linalg.norm(N, axis=1), np.einsum("ijk,ijk->ij", E, E).sum(axis=1))


def _region_was(faces, points, gaps):
    """The largest distance of a region as ``gaps`` has it: its ``faces``'
    samples and the input vertices ``points`` whose nearest cage face is one
    of them."""
    return max(float(gaps.face_far[faces].max()), float(gaps.point_far[points].max(initial=0.0)))


class _After(NamedTuple):
    """A region's distances after a change (:func:`_regions_after`)."""

    face_far: np.ndarray   #: (r,) of its new faces (their corners and ``_SAMPLES``)
    vertices: np.ndarray   #: (c,) its faces' corners ...
    near: object           #: ... their closest input points (ClosestPoints)
    points: np.ndarray     #: (p,) the input vertices whose nearest face was one of its old ones ...
    point_far: np.ndarray  #: ... their distance to the new faces (a bound) ...
    point_face: np.ndarray  #: ... and the nearest of those

    @property
    def far(self):
        """The region's largest distance either way."""
        return max(float(self.face_far.max()), float(self.point_far.max(initial=0.0)))

    def record(self, gaps, change):
        """Write these distances into ``gaps`` (in place) once ``change`` is made."""
        gaps.face_far[change.faces] = self.face_far
        gaps.vertex_far[self.vertices] = self.near.distance
        gaps.vertex_near[self.vertices] = self.near.point
        gaps.point_far[self.points] = self.point_far
        gaps.point_face[self.points] = self.point_face


def _regions_after(V, changes, tris, inputs, P, gaps, gain):
    """The :class:`_After` of each of the ``changes`` on the cage ``V`` (each
    alone; ``tris``: its new faces' corners, (r,3,3) each): its new faces'
    corners and ``_SAMPLES`` to the input, and the
    input vertices whose nearest cage face was one of its old ones to the
    new faces (the nearest of them: a bound, they may be nearer another face
    now). None for a change whose new faces alone are already at least
    ``gain`` times its region's largest distance (it cannot be kept: its
    input vertices are not measured). Two closest-point queries (the
    corners and centroids first: a change they find hopeless has its other
    samples left unmeasured; a cone of needles' cage moved its hubs, 101
    faces each, 90% of the samples of two rounds in such changes) and one
    pass of the point-triangle kernel for all of them."""
    if not changes:
        return []
    corners = [sorted_unique(c.rows) for c in changes]
    samples = [np.einsum("sk,rkd->rsd", _SAMPLES, T) for T in tris]       # (r, s, 3) each
    ends = [_points_after(V, c, k) for c, k in zip(changes, corners)]
    first = inputs.closest(np.concatenate([x[:, _CENTROID] for x in samples] + ends))
    by_face = np.argsort(gaps.point_face, kind="stable")      # the input vertices of each face
    start = np.searchsorted(gaps.point_face[by_face], np.arange(gaps.face_far.shape[0] + 1))
    at = [0, sum(x.shape[0] for x in samples)]
    hope = []
    for c, k, x in zip(changes, corners, samples):
        r = x.shape[0]
        near = type(first)(*(a[at[1]:at[1] + k.size] for a in first))
        seen = np.maximum(first.distance[at[0]:at[0] + r],
                          near.distance[np.searchsorted(k, c.rows)].max(axis=1))
        m = np.sort(np.concatenate([by_face[start[f]:start[f + 1]] for f in c.faces]))
        was = _region_was(c.faces, m, gaps)
        hope.append(None if float(seen.max()) >= gain * was else (seen, near, m, was))
        at = [at[0] + r, at[1] + k.size]
    live = [x.reshape(-1, 3) for x, h in zip(samples, hope) if h is not None]
    hit = inputs.closest(np.concatenate(live)) if live else None
    found, at = [], 0
    for k, x, Tc, h in zip(corners, samples, tris, hope):
        if h is None:
            found.append(None)
            continue
        seen, near, m, was = h
        r, n = x.shape[0], x.shape[0] * x.shape[1]
        face_far = np.maximum(hit.distance[at:at + n].reshape(r, -1).max(axis=1), seen)
        found.append(None if float(face_far.max()) >= gain * was else (face_far, k, near, m, Tc))
        at += n
    return _with_points(found, changes, P)


def _with_points(found, changes, P):
    """The :class:`_After` of each change from ``found`` (its new faces'
    distances, corners, their closest input points, its input vertices and
    its new faces' corners; None stays None): the input vertices' distances
    to the new faces, one pass of the point-triangle kernel for all but the
    changes of more than ``_INDEXED_PAIRS`` (vertex, face) pairs, whose
    vertices are searched in an index of their new faces
    (:func:`_nearest_new_faces`)."""
    live = [f for f in found if f is not None and f[3].size * f[4].shape[0] <= _INDEXED_PAIRS]
    d, pair = _new_face_distances(live, P), 0
    out = []
    for c, f in zip(changes, found):
        if f is None:
            out.append(None)
            continue
        face_far, k, near, m, Tc = f
        r = Tc.shape[0]
        if m.size * r > _INDEXED_PAIRS:
            dist, best = _nearest_new_faces(P[m], Tc)
        else:
            dm = d[pair:pair + m.size * r].reshape(-1, r)
            best = np.argmin(dm, axis=1)
            dist = dm[np.arange(m.size), best]
            pair += m.size * r
        out.append(_After(face_far, k, near, m, dist, c.faces[best]))
    return out


def _new_face_distances(live, P):
    """The distances of each ``live`` change's input vertices to each of its
    new faces, one pass of the point-triangle kernel over the pairs for all
    (flat: a change's ``(m, r)`` block after another's; the faces' kernel
    rows made once, not a copy of the corners per pair: a CAD cylinder's
    cage at 200 faces, whose caps are fans of 51 faces, measured 888 input
    vertices against each of a move's 51 new faces)."""
    if not live:
        return np.zeros(0)
    faces = np.concatenate([T for *_, T in live])                  # (every change's, in turn)
    first = np.cumsum([0] + [T.shape[0] for *_, T in live])
    q = np.concatenate([np.repeat(m, T.shape[0]) for *_, m, T in live])
    t = np.concatenate([f + np.tile(np.arange(T.shape[0]), m.size)
                        for (*_, m, T), f in zip(live, first)])
    rows = triangle_rows(*faces.transpose(1, 0, 2))
    return np.sqrt(closest_pairs(np.ascontiguousarray(P.T), q, rows, t)[2])


def _nearest_new_faces(X, T):
    """The distance of each point ``X`` to the nearest of the triangles
    ``T`` (r,3,3), and which (among exactly equidistant ones, the index's
    pick): a :class:`~.spatial.TriangleIndex` of them (a flat fan of 40k
    needles moved its cage's hub: 40k input vertices against 200 new faces,
    four times, 41 s by pairs)."""
    hit = TriangleIndex(T.reshape(-1, 3), np.arange(3 * T.shape[0]).reshape(-1, 3)).closest(X)
    return hit.distance, hit.face


def _points_after(V, change, idx):
    """The positions ``V[idx]`` (any shape of vertex ids) after ``change``."""
    X = V[idx]
    if change.vertex >= 0:
        X[idx == change.vertex] = change.to
    return X


def flip_flat_faces(V, F, creases):
    """The cage ``(V, F)`` without its flat faces where an edge flip removes
    them: a face with no area (:func:`~.mesh.flat_faces`) has one corner on
    its longest edge, and flipping that edge with the face across it puts the
    corner on that face's far corner: the two new faces tile the face across
    (the surface does not change) and both have area. (A pinched scan's fan,
    folded onto the grid around it, kept a flat input face in the cage: its
    edges were creases, the fold's, and every collapse next to it was
    refused.)

    A flipped crease ``(a, b)`` of ``creases`` (k,2) becomes the two creases
    through the corner on it (the same line). Not flipped: a border edge, an
    edge whose new edge the cage already has, one whose new faces would have
    no area or turn from the face across. Flips of one round touch disjoint
    faces; ``_FLAT_ROUNDS`` rounds at most. Returns the faces and the creases
    (``F`` and ``creases`` themselves when nothing was flipped; face ids stay)."""
    out, creases = F, np.asarray(creases, dtype=np.int64).reshape(-1, 2)
    for _ in range(_FLAT_ROUNDS):
        flat = flat_faces(V, out)
        if not flat.any():
            break
        flips = _flat_flips(V, out, np.flatnonzero(flat), flat)
        if flips is None:
            break
        out = out.copy() if out is F else out
        out[flips.faces] = flips.rows
        creases = _creases_after(creases, flips, V.shape[0])
    return out, creases


class _Flips(NamedTuple):
    """Edge flips of flat faces: the faces rewritten and their new rows, and
    per flip the edge ``(a, b)`` flipped and the corner ``c`` on it."""

    faces: np.ndarray   #: (2k,) the flat faces, then the faces across
    rows: np.ndarray    #: (2k,3)
    ab: np.ndarray      #: (k,2)
    c: np.ndarray       #: (k,)


def _flat_flips(V, F, faces, flat):
    """One round of :func:`flip_flat_faces` over the flat ``faces`` (their
    mask ``flat``): the :class:`_Flips` taken, or None."""
    n = V.shape[0]
    P = V[F[faces]]
    opposite = np.stack([np.square(P[:, (j + 2) % 3] - P[:, (j + 1) % 3]).sum(axis=1)
                         for j in range(3)], axis=1)
    j = np.argmax(opposite, axis=1)
    c, a, b = F[faces, j], F[faces, (j + 1) % 3], F[faces, (j + 2) % 3]
    across, edges = _across(F, n)
    g = across[faces, j]
    inside = np.flatnonzero(g >= 0)       # (a longest edge on the border has no face across)
    faces, c, a, b, g = faces[inside], c[inside], a[inside], b[inside], g[inside]
    d = F[g].sum(axis=1) - a - b
    ok = ~flat[g] & (c != d)
    ok &= ~member_of(edge_keys(c, d, n), edges)
    new = np.stack([np.stack([c, a, d], axis=1), np.stack([c, d, b], axis=1)], axis=1)  # (k,2,3)
    ok &= ~flat_faces(V, new.reshape(-1, 3)).reshape(-1, 2).any(axis=1)
    Ng = cross_rows(V[F[g, 1]] - V[F[g, 0]], V[F[g, 2]] - V[F[g, 0]])
    for t in range(2):
        T = V[new[:, t]]
        ok &= np.einsum("ij,ij->i", cross_rows(T[:, 1] - T[:, 0], T[:, 2] - T[:, 0]), Ng) > 0
    # the flat faces are distinct and never across (those are not flat): one flip per
    # face across a round, and one per new edge (two flat faces with one corner c on two
    # edges whose faces across share d both make (c, d): an edge of four faces)
    sel = np.flatnonzero(ok)[np.unique(g[ok], return_index=True)[1]]
    first = np.unique(edge_keys(c[sel], d[sel], n), return_index=True)[1]
    sel = sel[member_of(np.arange(sel.size), first)]
    if not sel.size:
        return None
    return _Flips(np.concatenate([faces[sel], g[sel]]), np.concatenate([new[sel, 0], new[sel, 1]]),
                  np.stack([a[sel], b[sel]], axis=1), c[sel])


def _creases_after(creases, flips, n):
    """``creases`` (k,2) with each flipped one ``(a, b)`` replaced by
    ``(a, c)`` and ``(c, b)`` (each crease once)."""
    key = edge_keys(creases[:, 0], creases[:, 1], n)
    hit = member_of(edge_keys(flips.ab[:, 0], flips.ab[:, 1], n), key)
    if not hit.any():
        return creases
    a, b, c = flips.ab[hit, 0], flips.ab[hit, 1], flips.c[hit]
    gone = member_of(key, edge_keys(a, b, n))
    E = np.concatenate([creases[~gone], np.stack([a, c], axis=1), np.stack([c, b], axis=1)])
    _, first = np.unique(edge_keys(E[:, 0], E[:, 1], n), return_index=True)
    return E[np.sort(first)]
