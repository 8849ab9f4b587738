"""Closest faces of a triangle mesh to query points, kept up to date by walking.

The final relocation (``core._relocate``) needs, a few times over, the closest
face of a mesh to each of many points while the points or the mesh move a
little between the calls, and it knows where each point starts: near the cage
vertex its input vertex was merged into. A walk from there costs a few
point-triangle evaluations per query where a :class:`~.spatial.TriangleIndex`
costs a grid (or tree) over the whole mesh, rebuilt whenever the mesh moves.

One step, for every query still walking, with ``h`` its distance to its face
``f`` and ``p`` its closest point there::

          C            the ball of radius h around the query reaches
         / \\           - across the edge opposite corner k when
     g  /   \\             bary_k * altitude_k <= h (the face g there is tried)
       /  p  \\         - around a corner when |p - corner| <= h (every face
      A-------B           around that corner is tried)
                       a query that found a closer face walks on (next
                       steps: every face around both ends of each edge its
                       ball crosses) until no face is closer, or ``steps``

Where the faces next to ``f`` bend away from it by at most 90 degrees, no face
touching ``f`` is closer than ``h`` unless the ball reaches across one of its
edges or around one of its corners, so a query whose ball stays inside its
face's prism has its true closest face (among those it can see). Otherwise --
a mesh folded back over itself, a query farther from the mesh than a face is
wide -- the walk ends at a local minimum: close to the answer when it starts
close, which is what the relocation gives it. Ties between equidistant faces
(a closest point on a shared edge) keep the face found first. A mesh of at most
``_EVERY_FACE`` faces is searched whole instead (exact, ties to the lowest face).
"""

from typing import NamedTuple

import numpy as np

from ._fan_index import FAN_FACES, FanIndex
from ._groups import group_argmin, ragged_ranges, stable_argsort
from .spatial import KERNEL_BLOCK, TriangleIndex, closest_pairs, triangle_rows

#: a barycentric coordinate this small puts the closest point on the edge
_ON_EDGE = 1e-12
#: meshes of at most this many faces are searched whole (exact): a walk over a
#: coarse mesh tries most of its faces anyway, a few times over (the bunny simplified
#: to its 25-face floor: relocation 23-24 -> 19 ms, medians of 7; an index per call,
#: as queries with no guess get, took 37 ms)
_EVERY_FACE = 64


def faces_across(F, n):
    """The face across the edge opposite each corner, (m,3) int64, -1 on a
    border. ``F`` (m,3) int64 over ``n`` vertices, manifold (an edge with more
    than two faces links them pairwise in sort order).

    Examples
    --------
    >>> faces_across(np.array([[0, 1, 2], [2, 1, 3]]), 4).tolist()
    [[1, -1, -1], [-1, -1, 0]]
    """
    a, b = F[:, [1, 2, 0]].ravel(), F[:, [2, 0, 1]].ravel()
    key = np.minimum(a, b) * n + np.maximum(a, b)
    o = stable_argsort(key)
    same = np.flatnonzero(key[o[1:]] == key[o[:-1]])
    out = np.full(3 * F.shape[0], -1, dtype=np.int64)
    out[o[same]] = o[same + 1] // 3
    out[o[same + 1]] = o[same] // 3
    return out.reshape(-1, 3)


class TrackedPoints(NamedTuple):
    """Closest points found by :meth:`FaceTracker.closest`."""

    face: np.ndarray    #: (q,) int64
    bary: np.ndarray    #: (q,3) float64 in ``F[face]``'s corner order
    point: np.ndarray   #: (q,3) float64


class FaceTracker:
    """Closest face of the mesh ``(V, F)`` to each query point, found by
    walking from a guess (see the module docstring) and remembered, so the
    next call walks from the last answer.

    Parameters
    ----------
    F : (m,3) int64 faces over ``n`` vertices.
    n : int
    steps : int, at most this many walking steps per call.

    Examples
    --------
    >>> V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], dtype=float)
    >>> tracker = FaceTracker(np.array([[0, 1, 2], [2, 1, 3]]), 4, steps=4)
    >>> tracker.place(V)
    >>> tracker.closest(np.array([[0.9, 0.9, 1.0]]), near=np.array([0])).face.tolist()
    [1]
    """

    def __init__(self, F, n, steps):
        self.F = F
        c = F.ravel()
        self._deg = np.bincount(c, minlength=n)
        self._first = np.cumsum(self._deg) - self._deg   # of each vertex's run in _ring
        self._ring = stable_argsort(c) // 3              # faces around each vertex
        self._across = np.ascontiguousarray(faces_across(F, n).T)   # (3,m)
        self._FT = np.ascontiguousarray(F.T)
        self.steps = steps
        self.face = None                                 # the last answer

    def place(self, V):
        """Put the mesh's vertices at ``V`` (n,3) for the next queries."""
        F = self.F
        self.V = V
        self._D = D = triangle_rows(V[F[:, 0]], V[F[:, 1]], V[F[:, 2]])
        s_ab, s_ac, s_abac = D[9], D[10], D[11]
        area2 = np.maximum(s_ab * s_ac - s_abac * s_abac, 0.0)          # (2 area)^2
        edge2 = np.stack([s_ab + s_ac - 2.0 * s_abac, s_ac, s_ab])
        self._alt2 = area2 / np.maximum(edge2, 1e-300)           # squared altitudes (3,m)
        self._fans = FanIndex.of(V, F, self._ring, self._first, self._deg) \
            if (self._deg > FAN_FACES).any() else None

    def closest(self, Q, near=None):
        """Closest faces of the points ``Q`` (q,3): on the first call from the
        faces around the vertex ``near[i]`` of each (-1, a vertex with no
        face, or ``near=None``: an exact search), later from the last answer
        (the same queries, moved or not).

        Returns
        -------
        TrackedPoints
            ``face`` (q,) int64, ``bary`` (q,3) (clipped to [0,1], as
            :class:`~.spatial.TriangleIndex` gives them), ``point`` (q,3).
        """
        QT = np.ascontiguousarray(Q.T)
        q = np.arange(Q.shape[0])
        if self.F.shape[0] <= _EVERY_FACE:
            face, v, w, d2 = self._every_face(QT)
        else:
            if self.face is None:
                face, v, w, d2 = self._start(QT, near)
            else:
                face = self.face.copy()
                v, w, d2 = self._pairs(QT, q, face)
            face, v, w, d2 = self._walk(QT, face, v, w, d2)
        self.face = face
        bary = np.stack([1.0 - v - w, v, w], axis=1)
        np.clip(bary, 0.0, 1.0, out=bary)
        D = np.take(self._D[0:9], face, axis=1)
        point = (D[0:3] + v * D[3:6] + w * D[6:9]).T
        return TrackedPoints(face, bary, np.ascontiguousarray(point))

    def _start(self, QT, near):
        """First answers: the best face around ``near`` (exact where -1)."""
        k = QT.shape[1]
        face, v, w, d2 = np.zeros(k, dtype=np.int64), np.zeros(k), np.zeros(k), np.zeros(k)
        has = np.zeros(k, dtype=bool)
        if near is not None:
            has = near >= 0
            has[has] = self._deg[near[has]] > 0
        q = np.flatnonzero(has)
        if q.size:
            face[q], v[q], w[q], d2[q] = self._around(QT, q, near[q], np.ones(q.size, np.int64))
        q = np.flatnonzero(~has)
        if q.size:
            cp = TriangleIndex(self.V, self.F).closest(QT[:, q].T)
            face[q] = cp.face
            v[q], w[q], d2[q] = self._pairs(QT, q, cp.face)
        return face, v, w, d2

    def _every_face(self, QT):
        """The exact closest face of every query among all faces (the first
        of equidistant ones): ``face, v, w, d2`` per query."""
        k, m = QT.shape[1], self.F.shape[0]
        face = np.empty(k, dtype=np.int64)
        v, w, d2 = np.empty(k), np.empty(k), np.empty(k)
        per = max(1, KERNEL_BLOCK // max(m, 1))     # queries whose pairs make one kernel block
        for s in range(0, k, per):
            e = min(s + per, k)
            q = np.repeat(np.arange(s, e), m)
            t = np.tile(np.arange(m), e - s)
            pv, pw, pd = self._pairs(QT, q, t)
            best = group_argmin(pd, np.full(e - s, m))
            face[s:e], v[s:e], w[s:e], d2[s:e] = t[best], pv[best], pw[best], pd[best]
        return face, v, w, d2

    def _pairs(self, QT, q, t):
        """The kernel on the pairs (queries ``q``, faces ``t``): ``v, w, d2``."""
        return closest_pairs(QT, q, self._D, t)

    def _around(self, QT, q, verts, counts):
        """Best face among those around ``verts``, ``counts[i]`` of them for
        query ``q[i]`` (in order): ``face, v, w, d2`` per query."""
        per = np.repeat(np.arange(q.size), counts)
        h2 = None if self._fans is None else self._sector_bound(QT, verts, q[per],
                                                                np.full(verts.size, np.inf))
        t, own = self._faces_around(verts, QT, q[per], h2)
        group = per[own]
        v, w, d2 = self._pairs(QT, q[group], t)
        best = group_argmin(d2, np.bincount(group, minlength=q.size))
        return t[best], v[best], w[best], d2[best]

    def _sector_bound(self, QT, verts, q, h2):
        """``h2`` (squared distances, one per vertex ``verts[i]`` and point
        ``QT[:, q[i]]``) lowered, where the vertex is a fan's hub, to the
        point's squared distance to the nearest face around it whose sector
        holds the point's angle: the faces around the hub that may be nearer
        are then few (a point in a CAD cap whose ball reached the hub tried
        hundreds of its spokes)."""
        h2 = h2.copy()
        hub = np.flatnonzero(self._fans.hub_of[verts] >= 0)
        if hub.size:
            t, own = self._faces_around(verts[hub], QT, q[hub], np.zeros(hub.size))
            best = np.full(hub.size, np.inf)
            np.minimum.at(best, own, self._pairs(QT, q[hub[own]], t)[2])
            h2[hub] = np.minimum(h2[hub], best)
        return h2

    def _faces_around(self, vert, QT, q, h2):
        """The faces around each vertex ``vert[i]`` and the ``i`` of each,
        grouped by ``i`` in order: every face, but around a fan's hub only
        those that may lie within ``sqrt(h2[i])`` of the point ``QT[:, q[i]]``
        (see :mod:`._fan_index`; ``h2`` 0: the faces whose sector holds the
        point's angle, inf: every face)."""
        if self._fans is None:
            at, own = ragged_ranges(self._first[vert], self._deg[vert])
            return self._ring[at], own
        hub = self._fans.hub_of[vert]
        plain, fan = np.flatnonzero(hub < 0), np.flatnonzero(hub >= 0)
        at, own = ragged_ranges(self._first[vert[plain]], self._deg[vert[plain]])
        faces, owner = [self._ring[at]], [plain[own]]
        if fan.size:
            starts, counts = self._fans.windows(hub[fan], QT[:, q[fan]].T, h2[fan])
            at, own = ragged_ranges(starts, counts)
            faces.append(self._fans.faces[at])
            owner.append(fan[own // 3])
        faces, owner = np.concatenate(faces), np.concatenate(owner)
        o = stable_argsort(owner)
        return faces[o], owner[o]

    def _walk(self, QT, face, v, w, d2):
        """Walk every query to a closer face while its ball reaches one (see
        the module docstring); the arrays are updated in place and returned."""
        active = np.arange(face.size)
        for step in range(self.steps):
            f, h2 = face[active], d2[active]
            B = (1.0 - v[active] - w[active], v[active], w[active])
            line = [(B[k] * B[k] * self._alt2[k].take(f) <= h2) | (B[k] <= _ON_EDGE)
                    for k in range(3)]
            keep = np.flatnonzero(line[0] | line[1] | line[2])
            if keep.size == 0:
                break
            active, f, h2 = active[keep], f[keep], h2[keep]
            line = [x[keep] for x in line]
            corner = self._corners(f, v[active], w[active], h2, line)
            if step > 0:     # walking on: around both ends of every edge crossed
                corner = [corner[k] | line[(k + 1) % 3] | line[(k + 2) % 3] for k in range(3)]
                cross = []
            else:
                cross = [line[k] & (self._across[k].take(f) >= 0) for k in range(3)]
            moved = self._try(QT, active, f, cross, corner, face, v, w, d2)
            active = active[moved]
            if active.size == 0:
                break
        return face, v, w, d2

    def _corners(self, f, v, w, h2, line):
        """Which corners of the faces ``f`` lie within the balls (squared radii
        ``h2``) around the closest points ``(v, w)``: |x ab + y ac|^2 for
        (x, y) = (v, w) less the corner's, one mask per corner. A ball that
        holds a corner reaches the lines of both edges there (``line``, one
        mask per edge, named by its opposite corner), so only those are
        measured."""
        corner = [np.zeros(f.size, dtype=bool) for _ in range(3)]
        i = np.flatnonzero(line[0].astype(np.int8) + line[1] + line[2] >= 2)
        if i.size:
            f, v, w, h2 = f[i], v[i], w[i], h2[i]
            s_ab, s_ac, s_abac = (self._D[r].take(f) for r in (9, 10, 11))
            for k, (x, y) in enumerate(((v, w), (v - 1.0, w), (v, w - 1.0))):
                corner[k][i] = x * x * s_ab + 2.0 * x * y * s_abac + y * y * s_ac <= h2
        return corner

    def _try(self, QT, active, f, cross, corner, face, v, w, d2):
        """Move each query ``active[i]`` to the closest of the faces across its
        ``cross`` edges and around its ``corner`` corners if that is closer
        (one mask per corner, the edge named by its opposite corner); which of
        them moved."""
        i = [np.flatnonzero(c) for c in cross]
        t = [self._across[k].take(f[ik]) for k, ik in enumerate(i)]
        for k, c in enumerate(corner):
            ik = np.flatnonzero(c)
            vert = self._FT[k].take(f[ik])
            a = active[ik]
            h2 = None if self._fans is None else self._sector_bound(QT, vert, a, d2[a])
            faces, own = self._faces_around(vert, QT, a, h2)
            i.append(ik[own])
            t.append(faces)
        i, t = np.concatenate(i), np.concatenate(t)
        moved = np.zeros(active.size, dtype=bool)
        if i.size:
            o = stable_argsort(i)                         # each query's faces together
            i, t = i[o], t[o]
            nv, nw, nd = self._pairs(QT, active[i], t)
            count = np.bincount(i)
            b = group_argmin(nd, count[count > 0])
            i, t, nv, nw, nd = i[b], t[b], nv[b], nw[b], nd[b]
            better = nd < d2[active[i]]
            i = i[better]
            a = active[i]
            face[a], v[a], w[a], d2[a] = t[better], nv[better], nw[better], nd[better]
            moved[i] = True
        return moved

