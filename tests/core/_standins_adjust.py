"""Private stand-ins for ``core.subdivide`` and ``core.spatial`` (tests only).

The adjustment tests code against the agreed contracts of those modules.
While they are not in the checkout yet, :func:`ensure_core_modules` installs
tiny, obviously-correct versions under their module names (midpoint
subdivision, brute-force closest points) so the adjustment code can be
exercised. Once the real modules exist, nothing here is used.
"""

import hashlib
import importlib
import sys
import types
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np


def ensure_core_modules():
    """Import the real ``core.subdivide`` / ``core.spatial`` or install stand-ins.

    Returns the set of stand-in module names installed (empty when both are real).
    """
    installed = set()
    for name, build, needed in (
            ("core.subdivide", _subdivide_module, ("subdivision_operator", "subdivide")),
            ("core.spatial", _spatial_module, ("TriangleIndex", "closest_points")),
            ("core.metrics", _metrics_module, ("sample_surface", "surface_distance"))):
        try:
            mod = importlib.import_module(name)
        except ModuleNotFoundError as exc:
            if exc.name != name:
                raise
            mod = None
        if mod is None or not all(hasattr(mod, k) for k in needed):
            # absent or still being written: use the stand-in
            sys.modules[name] = build()
            installed.add(name)
    return installed


# ---------------------------------------------------------------- subdivision
def _midpoint_level(F, n):
    from core.topology import edge_map
    em = edge_map(F, n)
    E = em.E
    mid = n + em.face_edge  # mid[f, c]: vertex on the edge opposite corner c
    a, b, c = F[:, 0], F[:, 1], F[:, 2]
    ma, mb, mc = mid[:, 0], mid[:, 1], mid[:, 2]
    F2 = np.concatenate([np.stack([a, mc, mb], 1), np.stack([b, ma, mc], 1),
                         np.stack([c, mb, ma], 1), np.stack([ma, mb, mc], 1)])
    parent = np.tile(np.arange(F.shape[0]), 4)
    rows = np.concatenate([np.arange(n), n + np.arange(E.shape[0]), n + np.arange(E.shape[0])])
    cols = np.concatenate([np.arange(n), E[:, 0], E[:, 1]])
    w = np.concatenate([np.ones(n), np.full(2 * E.shape[0], 0.5)])
    return F2, n + E.shape[0], parent, (rows, cols, w)


@dataclass(frozen=True)
class _Operator:
    n_coarse: int
    n_fine: int
    F_fine: np.ndarray
    fine_to_coarse_face: np.ndarray
    stencils: tuple
    sizes: tuple
    scheme: str
    levels: int
    fingerprint: str

    def apply(self, Vc):
        X = np.asarray(Vc, dtype=np.float64)
        vec = X.ndim == 1
        X = X.reshape(X.shape[0], -1)
        for (rows, cols, w), (n_in, n_out) in zip(self.stencils, self.sizes):
            X = np.stack([np.bincount(rows, w * X[cols, k], n_out) for k in range(X.shape[1])], 1)
        return X[:, 0] if vec else X

    def apply_transpose(self, G):
        X = np.asarray(G, dtype=np.float64)
        vec = X.ndim == 1
        X = X.reshape(X.shape[0], -1)
        for (rows, cols, w), (n_in, n_out) in zip(self.stencils[::-1], self.sizes[::-1]):
            X = np.stack([np.bincount(cols, w * X[rows, k], n_in) for k in range(X.shape[1])], 1)
        return X[:, 0] if vec else X

    def support(self, ids):
        mask = np.zeros(self.n_coarse, dtype=bool)
        mask[np.asarray(ids, dtype=np.int64)] = True
        for (rows, cols, w), (n_in, n_out) in zip(self.stencils, self.sizes):
            new = np.zeros(n_out, dtype=bool)
            new[rows[mask[cols] & (w != 0)]] = True
            mask = new
        return mask


def subdivision_operator(F, n_vertices, *, levels=1, scheme="butterfly", creases=None):
    F = np.asarray(F, dtype=np.int64)
    n = int(n_vertices)
    parent = np.arange(F.shape[0])
    stencils, sizes = [], []
    Fl, nl = F, n
    for _ in range(levels):
        F2, n2, par, st = _midpoint_level(Fl, nl)
        parent = parent[par]
        stencils.append(st)
        sizes.append((nl, n2))
        Fl, nl = F2, n2
    h = hashlib.sha1(F.tobytes() + str((n, levels, scheme)).encode())
    if creases is not None:
        h.update(np.asarray(creases, dtype=np.int64).tobytes())
    return _Operator(n, nl, Fl, parent, tuple(stencils), tuple(sizes), scheme, levels, h.hexdigest())


def subdivide(V, F, *, levels=1, scheme="butterfly", creases=None):
    op = subdivision_operator(F, len(V), levels=levels, scheme=scheme, creases=creases)
    return op.apply(V), op.F_fine


def _subdivide_module():
    mod = types.ModuleType("core.subdivide")
    mod.subdivision_operator = subdivision_operator
    mod.subdivide = subdivide
    mod.STANDIN = True
    return mod


# ---------------------------------------------------------------- closest points
class ClosestPoints(NamedTuple):
    face: np.ndarray
    point: np.ndarray
    bary: np.ndarray
    distance: np.ndarray


class SurfaceSamples(NamedTuple):
    points: np.ndarray
    face: np.ndarray
    bary: np.ndarray


def _closest_on_triangles(p, a, b, c):
    """Ericson's closest point on triangle, vectorised; returns (point, bary)."""
    ab, ac, ap = b - a, c - a, p - a
    d1 = np.einsum("ij,ij->i", ab, ap)
    d2 = np.einsum("ij,ij->i", ac, ap)
    bp = p - b
    d3 = np.einsum("ij,ij->i", ab, bp)
    d4 = np.einsum("ij,ij->i", ac, bp)
    cp = p - c
    d5 = np.einsum("ij,ij->i", ab, cp)
    d6 = np.einsum("ij,ij->i", ac, cp)
    va = d3 * d6 - d5 * d4
    vb = d5 * d2 - d1 * d6
    vc = d1 * d4 - d3 * d2
    q = p.shape[0]
    bary = np.zeros((q, 3))
    done = np.zeros(q, dtype=bool)

    def put(mask, u, v, w):
        m = mask & ~done
        bary[m, 0], bary[m, 1], bary[m, 2] = u[m], v[m], w[m]
        done[m] = True

    z, o = np.zeros(q), np.ones(q)
    with np.errstate(divide="ignore", invalid="ignore"):
        put((d1 <= 0) & (d2 <= 0), o, z, z)
        put((d3 >= 0) & (d4 <= d3), z, o, z)
        put((d6 >= 0) & (d5 <= d6), z, z, o)
        v = d1 / (d1 - d3)
        put((vc <= 0) & (d1 >= 0) & (d3 <= 0), 1 - v, v, z)
        w = d2 / (d2 - d6)
        put((vb <= 0) & (d2 >= 0) & (d6 <= 0), 1 - w, z, w)
        w = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        put((va <= 0) & ((d4 - d3) >= 0) & ((d5 - d6) >= 0), z, 1 - w, w)
        den = va + vb + vc
        v = vb / den
        w = vc / den
        put(np.ones(q, dtype=bool), 1 - v - w, v, w)
    point = bary[:, 0:1] * a + bary[:, 1:2] * b + bary[:, 2:3] * c
    return point, bary


class TriangleIndex:
    def __init__(self, V, F):
        self.V = np.asarray(V, dtype=np.float64)
        self.F = np.asarray(F, dtype=np.int64)

    def closest(self, P):
        P = np.asarray(P, dtype=np.float64)
        m = self.F.shape[0]
        A, B, C = self.V[self.F[:, 0]], self.V[self.F[:, 1]], self.V[self.F[:, 2]]
        out_f = np.empty(P.shape[0], dtype=np.int64)
        out_b = np.empty((P.shape[0], 3))
        out_p = np.empty((P.shape[0], 3))
        out_d = np.empty(P.shape[0])
        chunk = max(1, 2_000_000 // max(m, 1))
        for s in range(0, P.shape[0], chunk):
            p = P[s:s + chunk]
            k = p.shape[0]
            pp = np.repeat(p, m, axis=0)
            pt, bc = _closest_on_triangles(pp, np.tile(A, (k, 1)), np.tile(B, (k, 1)),
                                           np.tile(C, (k, 1)))
            d = np.linalg.norm(pt - pp, axis=1).reshape(k, m)
            j = np.argmin(d, axis=1)
            idx = np.arange(k) * m + j
            out_f[s:s + k] = j
            out_b[s:s + k] = bc[idx]
            out_p[s:s + k] = pt[idx]
            out_d[s:s + k] = d[np.arange(k), j]
        return ClosestPoints(out_f, out_p, out_b, out_d)


def closest_points(V, F, P):
    return TriangleIndex(V, F).closest(P)


def sample_surface(V, F, n_samples, *, seed=0):
    V = np.asarray(V, dtype=np.float64)
    F = np.asarray(F, dtype=np.int64)
    rng = np.random.default_rng(seed)
    area = 0.5 * np.linalg.norm(np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]), axis=1)
    face = rng.choice(F.shape[0], size=n_samples, p=area / area.sum())
    r1, r2 = rng.random(n_samples), rng.random(n_samples)
    s = np.sqrt(r1)
    bary = np.stack([1 - s, s * (1 - r2), s * r2], axis=1)
    pts = np.einsum("ij,ijk->ik", bary, V[F[face]])
    return SurfaceSamples(pts, face, bary)


def _spatial_module():
    mod = types.ModuleType("core.spatial")
    mod.TriangleIndex = TriangleIndex
    mod.ClosestPoints = ClosestPoints
    mod.closest_points = closest_points
    mod.sample_surface = sample_surface
    mod.SurfaceSamples = SurfaceSamples
    mod.STANDIN = True
    return mod


def _metrics_module():
    mod = types.ModuleType("core.metrics")
    mod.sample_surface = sample_surface
    mod.SurfaceSamples = SurfaceSamples
    mod.STANDIN = True
    return mod
