"""The faces around a fan's hub, ordered by angle (private, for
:class:`core._face_tracker.FaceTracker`).

CAD exports cap a disc or a fillet's end with a fan of thousands of needles
from one vertex; a walk that reaches that vertex would try every face around
it, for every query near it. Seen from the hub, projected on a plane across
its normal, each face around it spans an angle (its sector); a point within
``h`` of a face projects within ``h`` of the face's projection (projection
never lengthens), so a query whose projection lies ``r > h`` from the hub's
can only be within ``h`` of faces whose sector meets the window
``theta +- asin(h / r)`` around its own angle ``theta``. The faces of each hub
are sorted by the middle of their sector; a window widened by the hub's
widest half-sector is a range of them (two where it wraps around): a superset
of the faces within ``h``, so the walk finds what trying every face finds.
"""

from typing import NamedTuple

import numpy as np

from ._groups import ragged_ranges
from .mesh import area_normals_rows, unit_rows

#: hubs are vertices with more than this many faces around them
FAN_FACES = 64
#: a face whose other corner projects closer than this share of its length to
#: the hub has no angle there, and a face whose half-sector is wider than this
#: (radians) would widen every window of its hub: both are tried always
_STEEP = 1e-6
_WIDE = 0.05
_TWO_PI = 2.0 * np.pi


class FanIndex(NamedTuple):
    """The faces around each hub sorted by the middle angle of their sector."""

    hub_of: np.ndarray   #: (n,) int64 hub number of each vertex (-1: not a hub)
    start: np.ndarray    #: (h+1,) int64 each hub's run in ``faces`` / ``key``
    wide: np.ndarray     #: (h,) int64 how many faces of the run, first, are tried always
    faces: np.ndarray    #: (s,) int64 the faces around the hubs, hub by hub, by angle
    key: np.ndarray      #: (s,) float64 hub number * 8 + middle angle + pi (ascending; -0.5: wide)
    spread: np.ndarray   #: (h,) widest half-sector of each hub's other faces
    origin: np.ndarray   #: (h,3) hub positions
    u: np.ndarray        #: (h,3) unit axes of each hub's plane
    v: np.ndarray        #: (h,3)

    @classmethod
    def of(cls, V, F, ring, first, deg):
        """The index of the hubs of ``(V, F)``; ``ring``, ``first``, ``deg``:
        the faces around each vertex (CSR, as :class:`FaceTracker` keeps them)."""
        hubs = np.flatnonzero(deg > FAN_FACES)
        hub_of = np.full(deg.size, -1, dtype=np.int64)
        hub_of[hubs] = np.arange(hubs.size)
        at, owner = ragged_ranges(first[hubs], deg[hubs])
        f = ring[at]
        origin = V[hubs]
        u, v = _planes(V, F, f, owner, hubs.size)
        Fo = F[f]
        corner = np.argmax(Fo == hubs[owner][:, None], axis=1)       # the hub's corner
        rows = np.arange(f.size)
        ang = []
        steep = np.zeros(f.size, dtype=bool)
        for k in (1, 2):                                              # the two other corners
            d = V[Fo[rows, (corner + k) % 3]] - origin[owner]
            x, y = (d * u[owner]).sum(axis=1), (d * v[owner]).sum(axis=1)
            steep |= x * x + y * y <= (_STEEP * _STEEP) * (d * d).sum(axis=1)
            ang.append(np.arctan2(y, x))
        turn = np.remainder(ang[1] - ang[0] + np.pi, _TWO_PI) - np.pi   # (-pi, pi]
        mid = np.remainder(ang[0] + 0.5 * turn + np.pi, _TWO_PI) - np.pi
        half = 0.5 * np.abs(turn)
        wide = steep | (half > _WIDE)
        spread = np.zeros(hubs.size)
        np.maximum.at(spread, owner[~wide], half[~wide])
        key = owner * 8.0 + np.where(wide, -0.5, mid + np.pi)      # the wide ones first
        o = np.argsort(key, kind="stable")
        start = np.zeros(hubs.size + 1, dtype=np.int64)
        np.cumsum(deg[hubs], out=start[1:])
        return cls(hub_of, start, np.bincount(owner[wide], minlength=hubs.size), f[o], key[o], spread,
                   origin, u, v)

    def windows(self, hub, Q, h2):
        """Ranges of ``faces`` that hold every face around hub number
        ``hub[i]`` within ``sqrt(h2[i])`` of the point ``Q[i]`` (k,3): three
        ``(starts, counts)`` per query (the window, its part that wraps
        around or nothing, the hub's wide faces), (3k,) each, query by query."""
        d = Q - self.origin[hub]
        x, y = (d * self.u[hub]).sum(axis=1), (d * self.v[hub]).sum(axis=1)
        r2 = x * x + y * y
        far = r2 > h2
        half = np.full(hub.size, np.pi)
        half[far] = np.arcsin(np.sqrt(h2[far] / r2[far]))
        half += self.spread[hub]
        theta = np.arctan2(y, x) + np.pi                      # [0, 2 pi]
        lo, hi = theta - half, theta + half
        whole = half >= np.pi
        base = hub * 8.0
        # (lo, hi) within [0, 2 pi], and the wrapped part of a window that leaves it
        a = np.clip(lo, 0.0, _TWO_PI)
        b = np.clip(hi, 0.0, _TWO_PI)
        wa = np.where(lo < 0.0, lo + _TWO_PI, np.where(hi > _TWO_PI, 0.0, 1.0))
        wb = np.where(lo < 0.0, _TWO_PI, np.where(hi > _TWO_PI, hi - _TWO_PI, 0.0))
        s1 = np.searchsorted(self.key, base + a, side="left")
        e1 = np.searchsorted(self.key, base + b, side="right")
        s2 = np.searchsorted(self.key, base + wa, side="left")
        e2 = np.searchsorted(self.key, base + wb, side="right")
        first, wide = self.start[hub], self.wide[hub]
        s1 = np.where(whole, first + wide, s1)
        e1 = np.where(whole, self.start[hub + 1], e1)
        e2 = np.where(whole, s2, np.maximum(e2, s2))
        starts = np.stack([s1, s2, first], axis=1).ravel()
        counts = np.stack([e1 - s1, e2 - s2, wide], axis=1).ravel()
        return starts, counts


def _planes(V, F, f, owner, h):
    """Unit axes ``u``, ``v`` (h,3) of a plane across each hub's normal (the
    sum of its faces' area normals ``f``, ``owner`` giving each one's hub;
    any plane where that sum vanishes)."""
    N = np.zeros((h, 3))
    np.add.at(N, owner, area_normals_rows(V, F[f].T))
    N = unit_rows(N)
    N[~N.any(axis=1)] = [0.0, 0.0, 1.0]
    helper = np.where((np.abs(N[:, 0]) < 0.9)[:, None], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
    u = np.cross(N, helper)
    u /= np.linalg.norm(u, axis=1)[:, None]
    return u, np.cross(N, u)
