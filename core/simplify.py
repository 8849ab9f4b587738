"""Quadric edge-collapse simplification in vectorised batches.

Garland & Heckbert, "Surface simplification using quadric error metrics"
(SIGGRAPH 1997) and Garland's thesis (1999) for the quadrics, boundary
constraint planes and the compactness term; Dey, Edelsbrunner, Guha and
Nekhayev, "Topology preserving edge contraction" (1999) for the link
condition. Instead of a sequential heap, collapses are applied in batches
of independent edges, each batch checked on the mesh as it is::

    clean the input; freeze non-manifold edges and vertices
    Q[v] = sum of area-weighted face planes (+ boundary and crease planes)
    repeat (one pass):
        cost every edge: Q = Q[a] + Q[b], x = argmin Q (3x3 solve), err = Q(x)
        pool = the cheapest edges (a bounded share: never much costlier
               than the cheapest remaining ones)
        repeat (rounds):
            pick pool edges that are the cheapest within two rings
            (their stars -- the faces around both endpoints -- are disjoint)
            check each on the current mesh: link condition, no flipped or
            near-degenerate face; add the compactness penalty
            accept those still within the pool's cost bound, lock their stars
        apply every accepted collapse with one remap (b -> a, V[a] = x,
        Q[a] += Q[b]); glue the half-edge twins of the removed faces
    until the target, the error bound, or no valid collapse

The mesh is kept as faces plus a half-edge twin table (``core._clean``), which
collapses update locally: no sort after the first one.

Units: the mesh is moved to its bounding-box centre and scaled to a unit
diagonal before anything else, so the result does not depend on the units.
"""

from dataclasses import dataclass

import numpy as np

from ._clean import BOUNDARY, NON_MANIFOLD, clean_mesh, half_edge_ends, non_manifold_vertices, twin_table
from .errors import InvalidArgumentError
from .mesh import check_mesh
from .quadrics import (N_COEFFS, accumulate, edge_constraint_quadrics, face_quadrics, optimal_placement,
                       quadric_distance, quadric_error)

_WHERE = "simplify"


@dataclass(frozen=True)
class Tuning:
    """Every constant of the algorithm in one place (all unit-free)."""

    boundary_weight: float = 100.0   #: boundary plane weight, times the edge length squared
    feature_weight: float = 10.0     #: crease plane weight, times the edge length squared
    pool_share: float = 0.15         #: at most this share of the candidate edges per pass
    pool_goal_factor: float = 1.5    #: ... and at most this many times the collapses still needed
    max_rounds: int = 4              #: selection rounds per pass
    flip_cos: float = 0.0            #: reject if a face normal turns by more than acos(flip_cos)
    gamma_hard: float = 0.02         #: reject new triangles less compact than this (and than before)
    gamma_soft: float = 0.3          #: penalise new triangles less compact than this
    compact_weight: float = 1e-3     #: penalty scale: star area * edge length^2 * (1 - g/g_soft)^2
    snap_bits: int = 32              #: coordinates snapped to 2^-snap_bits of the diagonal
    max_passes: int = 100000


TUNING = Tuning()

_DEBUG = False
_BIG = np.iinfo(np.int64).max


@dataclass(frozen=True)
class SimplifyResult:
    """What :func:`simplify` returns.

    Attributes
    ----------
    V : (n,3) float64, the cage's vertices.
    F : (m,3) int64, the cage's faces.
    vertex_map : (n_input,) int64, the cage vertex each input vertex was merged
        into (``-1`` for input vertices no face used).
    max_error : float, largest error of an accepted collapse, as a distance in
        mesh units (``sqrt(quadric error / quadric area)``, see ``core.quadrics``).
    stopped_because : str, ``"target"``, ``"max_error"``, ``"no_valid_collapse"``
        or ``"cancelled"``.
    feature_edges : (k,2) int64, cage edges (sorted rows) that descend from the
        input's sharp edges (dihedral angle above ``feature_angle_deg``):
        pass them as ``creases`` to subdivision.
    n_degenerate_faces, n_duplicate_faces, n_unreferenced_vertices : int,
        what cleaning dropped from the input.
    n_frozen_vertices : int, vertices on non-manifold edges or with several
        fans, kept in place.
    n_passes : int, batches applied.
    """

    V: np.ndarray
    F: np.ndarray
    vertex_map: np.ndarray
    max_error: float
    stopped_because: str
    feature_edges: np.ndarray
    n_degenerate_faces: int = 0
    n_duplicate_faces: int = 0
    n_unreferenced_vertices: int = 0
    n_frozen_vertices: int = 0
    n_passes: int = 0


def _check_args(n, target_faces, ratio, max_error, feature_angle_deg, vertex_weights, locked, progress):
    if target_faces is None and ratio is None and max_error is None:
        raise InvalidArgumentError(
            f"{_WHERE}: give at least one of target_faces, ratio or max_error, e.g. ratio=0.1")
    if target_faces is not None:
        if isinstance(target_faces, bool) or not isinstance(target_faces, (int, np.integer)):
            raise InvalidArgumentError(
                f"{_WHERE}: target_faces must be an integer >= 0, got {target_faces!r}")
        if target_faces < 0:
            raise InvalidArgumentError(f"{_WHERE}: target_faces must be >= 0, got {target_faces}")
    if ratio is not None:
        r = float(ratio)
        if not (0.0 < r <= 1.0):
            raise InvalidArgumentError(f"{_WHERE}: ratio must be in (0, 1], got {ratio!r}")
    if max_error is not None:
        e = float(max_error)
        if not (e >= 0.0) or not np.isfinite(e):
            raise InvalidArgumentError(
                f"{_WHERE}: max_error must be a finite distance >= 0, got {max_error!r}")
    if feature_angle_deg is not None:
        a = float(feature_angle_deg)
        if not (0.0 < a <= 180.0):
            raise InvalidArgumentError(
                f"{_WHERE}: feature_angle_deg must be in (0, 180] or None, got {feature_angle_deg!r}")
    w = None
    if vertex_weights is not None:
        w = np.asarray(vertex_weights)
        if w.shape != (n,) or not (np.issubdtype(w.dtype, np.floating) or np.issubdtype(w.dtype, np.integer)):
            raise InvalidArgumentError(
                f"{_WHERE}: vertex_weights must be ({n},) numbers, got {w.shape} {w.dtype}")
        w = w.astype(np.float64)
        bad = ~np.isfinite(w) | (w < 0)
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            raise InvalidArgumentError(
                f"{_WHERE}: vertex_weights must be finite and >= 0, e.g. vertex {i} has {w[i]}")
    lk = None
    if locked is not None:
        lk = np.asarray(locked)
        if lk.shape != (n,) or not (lk.dtype == bool or np.issubdtype(lk.dtype, np.integer)):
            raise InvalidArgumentError(
                f"{_WHERE}: locked must be ({n},) booleans, got {lk.shape} {lk.dtype}")
        lk = lk.astype(bool)
    if progress is not None and not callable(progress):
        raise InvalidArgumentError(f"{_WHERE}: progress must be callable or None, got {type(progress)}")
    return w, lk


def _unit_normals(P0, P1, P2):
    N = np.cross(P1 - P0, P2 - P0)
    L = np.linalg.norm(N, axis=1)
    return np.divide(N, L[:, None], out=np.zeros_like(N), where=L[:, None] > 0), L


def _initial_quadrics(V, F, twin, U, W, preserve_boundary, feature_angle_deg, tun):
    """Vertex quadrics with boundary and crease planes, and the crease flags
    per half-edge."""
    n = V.shape[0]
    Qf = face_quadrics(V, F)
    Q = accumulate(np.repeat(Qf, 3, axis=0), F.ravel(), n)
    Nf, _ = _unit_normals(V[F[:, 0]], V[F[:, 1]], V[F[:, 2]])
    h = np.arange(twin.size, dtype=np.int64)
    feat = np.zeros(twin.size, dtype=bool)
    items, ends = [], []
    if preserve_boundary:
        hb = np.flatnonzero(twin == BOUNDARY)
        E = np.stack([U[hb], W[hb]], axis=1)
        L2 = np.einsum("ij,ij->i", V[E[:, 1]] - V[E[:, 0]], V[E[:, 1]] - V[E[:, 0]])
        items.append(edge_constraint_quadrics(V, E, Nf[hb // 3], tun.boundary_weight * L2))
        ends.append(E)
    if feature_angle_deg is not None:
        hi = np.flatnonzero(twin > h)
        t = twin[hi]
        n0, n1 = Nf[hi // 3], Nf[t // 3]
        consistent = U[hi] == W[t]
        cosang = np.einsum("ij,ij->i", n0, n1) * np.where(consistent, 1.0, -1.0)
        sharp = cosang < np.cos(np.radians(feature_angle_deg))
        hs, ts = hi[sharp], t[sharp]
        feat[hs] = True
        feat[ts] = True
        E = np.stack([U[hs], W[hs]], axis=1)
        L2 = np.einsum("ij,ij->i", V[E[:, 1]] - V[E[:, 0]], V[E[:, 1]] - V[E[:, 0]])
        for side in (hs, ts):
            items.append(edge_constraint_quadrics(V, E, Nf[side // 3], tun.feature_weight * L2))
            ends.append(E)
    if items:
        Qc = np.concatenate(items)
        Ec = np.concatenate(ends)
        Qc[:, 10] = 0.0  # constraint planes do not count as surface area
        Q += accumulate(np.concatenate([Qc, Qc]), np.concatenate([Ec[:, 0], Ec[:, 1]]), n)
    return Q, feat


class _Mesh:
    """Mutable working state of one simplification (private)."""

    def __init__(self, V, F, twin, Q, locked, feat):
        self.V, self.F, self.twin, self.Q, self.locked, self.feat = V, F, twin, Q, locked, feat
        n = V.shape[0]
        self.moved = np.zeros(n, dtype=bool)
        self.orig = np.arange(n, dtype=np.int64)      # clean index of each current vertex
        self.blocked = np.full(twin.size, -1.0)       # per half-edge: -1 free, else cost to accept
        self.cur_of_clean = np.arange(n, dtype=np.int64)


def _faces_in_stars(F, n, A, B):
    """For a set of independent edges (A[k], B[k]): per face, the edge whose
    star contains it (-1 if none) and how many of its corners are endpoints."""
    eov = np.full(n, -1, dtype=np.int64)
    k = np.arange(A.size, dtype=np.int64)
    eov[A] = k
    eov[B] = k
    fe = eov[F]
    star = np.flatnonzero((fe >= 0).any(axis=1))
    fes = fe[star]
    return star, fes, fes.max(axis=1), (fes >= 0).sum(axis=1)


def _check(mesh, A, B, X, interior, valence, tun):
    """Validity and compactness penalty of independent collapses B -> A at X.

    Returns ``(ok, penalty)``: ``ok`` (k,) bool (link condition, no flipped
    or near-degenerate face), ``penalty`` (k,) float64 to add to the cost.
    """
    F, V, n = mesh.F, mesh.V, mesh.V.shape[0]
    k = A.size
    star, fes, kf, nend = _faces_in_stars(F, n, A, B)
    Fs = F[star]
    ok = np.ones(k, dtype=bool)

    # --- link condition: common neighbours of A and B
    keys, sides = [], []
    for j in range(3):
        at = fes[:, j] >= 0
        side = Fs[:, j] == B[kf]
        for o in ((j + 1) % 3, (j + 2) % 3):
            sel = at & (fes[:, o] < 0)
            keys.append(kf[sel] * np.int64(n) + Fs[sel, o])
            sides.append(side[sel])
    keys = np.concatenate(keys)
    sides = np.concatenate(sides)
    common = np.intersect1d(np.unique(keys[~sides]), np.unique(keys[sides]), assume_unique=True)
    n_common = np.bincount(common // np.int64(max(n, 1)), minlength=k)
    need = np.where(interior, 2, 1)
    ok &= n_common == need
    # interior: not the last tetrahedron; boundary: not an isolated triangle
    ok &= ~(interior & (valence[A] == 3) & (valence[B] == 3))
    coll = nend == 2
    cf = star[coll]
    ck = kf[coll]
    cfes = fes[coll]
    # the two other half-edges of each removed face (opposite the A and B corners)
    hA = 3 * cf + np.argmax(cfes >= 0, axis=1)
    hB = 3 * cf + 2 - np.argmax((cfes >= 0)[:, ::-1], axis=1)
    tA, tB = mesh.twin[hA], mesh.twin[hB]
    bad = (tA == NON_MANIFOLD) | (tB == NON_MANIFOLD) | ((tA == BOUNDARY) & (tB == BOUNDARY))
    ok[ck[bad]] = False

    # --- geometry of the moving faces
    mv = ~coll
    mf, mk, mfes = Fs[mv], kf[mv], fes[mv]
    P = V[mf]                                  # (s,3,3)
    N0 = np.cross(P[:, 1] - P[:, 0], P[:, 2] - P[:, 0])
    moving_corner = np.argmax(mfes >= 0, axis=1)
    Pn = P.copy()
    Pn[np.arange(mf.shape[0]), moving_corner] = X[mk]
    e0, e1, e2 = Pn[:, 1] - Pn[:, 0], Pn[:, 2] - Pn[:, 1], Pn[:, 0] - Pn[:, 2]
    N1 = np.cross(e0, -e2)
    l0, l1 = np.linalg.norm(N0, axis=1), np.linalg.norm(N1, axis=1)
    flip = (l0 > 0) & (np.einsum("ij,ij->i", N0, N1) <= tun.flip_cos * l0 * l1)
    sumsq = (np.einsum("ij,ij->i", e0, e0) + np.einsum("ij,ij->i", e1, e1)
             + np.einsum("ij,ij->i", e2, e2))
    gamma_new = 2.0 * np.sqrt(3.0) * l1 / np.where(sumsq > 0, sumsq, 1.0)
    o0, o1, o2 = P[:, 1] - P[:, 0], P[:, 2] - P[:, 1], P[:, 0] - P[:, 2]
    osq = (np.einsum("ij,ij->i", o0, o0) + np.einsum("ij,ij->i", o1, o1)
           + np.einsum("ij,ij->i", o2, o2))
    gamma_old = 2.0 * np.sqrt(3.0) * l0 / np.where(osq > 0, osq, 1.0)
    gmin_new = np.ones(k)
    np.minimum.at(gmin_new, mk, gamma_new)
    gmin_old = np.ones(k)
    np.minimum.at(gmin_old, mk, gamma_old)
    ok[mk[flip]] = False
    ok &= ~((gmin_new < tun.gamma_hard) & (gmin_new < 0.5 * gmin_old))
    area = np.bincount(mk, weights=0.5 * l1, minlength=k)
    D = V[B] - V[A]
    L2 = np.einsum("ij,ij->i", D, D)
    short = np.maximum(0.0, 1.0 - gmin_new / tun.gamma_soft)
    penalty = tun.compact_weight * area * L2 * short * short
    return ok, penalty, star, kf


def simplify(V, F, *, target_faces=None, ratio=None, max_error=None, preserve_boundary=True,
             preserve_topology=True, feature_angle_deg=60.0, vertex_weights=None, locked=None,
             progress=None):
    """Simplify a triangle mesh to a coarse, clean manifold cage (QEM).

    Parameters
    ----------
    V : (n,3) float array_like
    F : (m,3) int array_like
    target_faces : int >= 0, optional
        Stop once the cage has at most this many faces.
    ratio : float in (0, 1], optional
        Target as a share of the (cleaned) input's faces, ``round(ratio * m)``.
    max_error : float >= 0, optional
        Never accept a collapse whose error exceeds this distance, in the
        mesh's units. The error of a collapse is ``sqrt(E / W)``: ``E`` the
        quadric error of the merged vertex (area-weighted squared distances to
        the planes of the input faces it stands for) and ``W`` their total
        area, i.e. the RMS distance of the new vertex to those planes.
        At least one of ``target_faces``, ``ratio``, ``max_error`` is needed;
        the run stops at whichever is reached first.
    preserve_boundary : bool
        Add heavy constraint planes on open borders so they keep their shape;
        an interior edge with one boundary endpoint collapses onto it.
    preserve_topology : bool
        Enforce the link condition (genus, boundary loops and components kept,
        never a non-manifold edge or vertex). ``False`` is accepted for API
        compatibility and currently behaves the same (the output is never
        allowed to become non-manifold either way).
    feature_angle_deg : float in (0, 180] or None
        Edges whose faces meet at more than this angle get constraint planes
        (creases and corners survive) and are reported in ``feature_edges``.
    vertex_weights : (n,) float >= 0, optional
        Importance of each input vertex: scales its quadric.
    locked : (n,) bool, optional
        Locked vertices are never moved or removed.
    progress : callable(float) -> bool or None, optional
        Called after every pass with the fraction done (0..1); returning
        ``False`` stops cleanly with ``stopped_because == "cancelled"``.

    Returns
    -------
    SimplifyResult

    Raises
    ------
    InvalidMeshError
        NaN/inf coordinates, indices out of range, wrong shapes or dtypes.
    InvalidArgumentError
        No target given, ``target_faces < 0``, ``ratio`` outside (0, 1],
        negative ``max_error``, badly shaped weights or lock mask.

    Examples
    --------
    >>> from tests.mesh_factory import icosphere
    >>> V, F = icosphere(3)
    >>> r = simplify(V, F, target_faces=100)
    >>> r.F.shape[0] <= 100, r.stopped_because
    (True, 'target')
    """
    tun = TUNING
    V, F = check_mesh(V, F, where=_WHERE)
    n_in = V.shape[0]
    weights, lk = _check_args(n_in, target_faces, ratio, max_error, feature_angle_deg, vertex_weights,
                              locked, progress)
    clean = clean_mesh(V, F)
    Vc, Fc = clean.V, clean.F
    n, m0 = Vc.shape[0], Fc.shape[0]

    target = None
    if target_faces is not None:
        target = int(target_faces)
    if ratio is not None:
        t = int(round(float(ratio) * m0))
        target = t if target is None else max(target, t)

    twin = twin_table(Fc, n)
    U, W = half_edge_ends(Fc)
    frozen = non_manifold_vertices(Fc, n, twin) if m0 else np.zeros(n, dtype=bool)
    lock = frozen.copy()
    if lk is not None:
        lock |= lk[clean.clean_to_vertex]

    # unit-free working coordinates: centred, unit diagonal, snapped to a grid
    lo, hi = (Vc.min(axis=0), Vc.max(axis=0)) if n else (np.zeros(3), np.zeros(3))
    centre = 0.5 * (lo + hi)
    scale = float(np.linalg.norm(hi - lo)) or 1.0
    grid = float(2 ** tun.snap_bits)
    Vn = np.round((Vc - centre) / scale * grid) / grid

    Q, feat = _initial_quadrics(Vn, Fc, twin, U, W, preserve_boundary, feature_angle_deg, tun)
    if weights is not None:
        Q *= weights[clean.clean_to_vertex][:, None]
    mesh = _Mesh(Vn, Fc.copy(), twin, Q, lock, feat)
    max_err_n = None if max_error is None else float(max_error) / scale

    worst = 0.0
    stopped = "target"
    passes = 0
    if target is None or m0 > target:
        stopped, worst, passes = _run(mesh, target, max_err_n, preserve_boundary, progress, m0, tun)

    # back to the caller's units; vertices never moved keep their exact input position
    Vout = mesh.V * scale + centre
    still = ~mesh.moved
    Vout[still] = Vc[mesh.orig[still]]
    vertex_map = np.full(n_in, -1, dtype=np.int64)
    vertex_map[clean.clean_to_vertex] = mesh.cur_of_clean
    Fo = mesh.F
    Uo, Wo = half_edge_ends(Fo)
    hf = np.flatnonzero(mesh.feat & ((mesh.twin > np.arange(mesh.twin.size)) | (mesh.twin == BOUNDARY)))
    fe = np.sort(np.stack([Uo[hf], Wo[hf]], axis=1), axis=1)
    fe = fe[np.lexsort((fe[:, 1], fe[:, 0]))] if fe.shape[0] else fe.reshape(0, 2)
    return SimplifyResult(
        V=Vout, F=Fo.copy(), vertex_map=vertex_map, max_error=float(worst * scale),
        stopped_because=stopped, feature_edges=fe.astype(np.int64),
        n_degenerate_faces=clean.n_degenerate_faces, n_duplicate_faces=clean.n_duplicate_faces,
        n_unreferenced_vertices=clean.n_unreferenced_vertices, n_frozen_vertices=int(frozen.sum()),
        n_passes=passes)


def _run(mesh, target, max_err_n, preserve_boundary, progress, m0, tun):
    """The batched collapse loop. Returns (stopped_because, worst error, passes)."""
    worst = 0.0
    passes = 0
    while passes < tun.max_passes:
        F, V, twin = mesh.F, mesh.V, mesh.twin
        m, n = F.shape[0], V.shape[0]
        if target is not None and m <= target:
            return "target", worst, passes
        if progress is not None and passes > 0:
            frac = (m0 - m) / (m0 - target) if target is not None and m0 > target else (m0 - m) / max(m0, 1)
            if progress(float(min(max(frac, 0.0), 1.0))) is False:
                return "cancelled", worst, passes
        passes += 1
        U, W = half_edge_ends(F)
        h = np.arange(3 * m, dtype=np.int64)
        is_bnd = np.zeros(n, dtype=bool)
        hb = twin == BOUNDARY
        is_bnd[U[hb]] = True
        is_bnd[W[hb]] = True
        valence = np.bincount(F.ravel(), minlength=n)

        eh = np.flatnonzero(hb | (twin > h))
        blk = mesh.blocked[eh]
        a, b = U[eh], W[eh]
        interior = twin[eh] >= 0
        lock = mesh.locked
        valid = ~(lock[a] & lock[b]) & ~(interior & is_bnd[a] & is_bnd[b]) & ~np.isinf(blk)
        if preserve_boundary:  # a boundary vertex never merges into a locked interior one
            valid &= ~(interior & ((lock[a] & is_bnd[b]) | (lock[b] & is_bnd[a])))
        eh, a, b, interior, blk = eh[valid], a[valid], b[valid], interior[valid], blk[valid]
        if eh.size == 0:
            return "no_valid_collapse", worst, passes
        # the survivor is `a`: a locked endpoint, else the boundary endpoint of an interior edge
        keep_b = lock[b] | (~lock[a] & preserve_boundary & interior & is_bnd[b])
        a, b = np.where(keep_b, b, a), np.where(keep_b, a, b)
        Qe = mesh.Q[a] + mesh.Q[b]
        X, err = optimal_placement(Qe, V[a], V[b])
        pin = lock[a] | (preserve_boundary & interior & is_bnd[a])
        if pin.any():
            X[pin] = V[a[pin]]
            err[pin] = quadric_error(Qe[pin], X[pin])
        dist = quadric_distance(Qe, err)
        cost = np.where(blk >= 0, np.maximum(err, blk), err)
        if max_err_n is not None:
            within = dist <= max_err_n
            if not within.any():
                return "max_error", worst, passes
            eh, a, b, interior, X, cost, dist, Qe = (arr[within] for arr in
                                                      (eh, a, b, interior, X, cost, dist, Qe))
        # pool: the cheapest share of the candidates
        ne = eh.size
        P = int(np.ceil(tun.pool_share * ne))
        if target is not None:
            P = min(P, int(np.ceil(tun.pool_goal_factor * (m - target) / 2.0)) + 1)
        P = max(1, min(P, ne))
        pool = np.argpartition(cost, P - 1)[:P] if P < ne else np.arange(ne)
        pool = pool[np.argsort(cost[pool], kind="stable")]
        limit = cost[pool[-1]]
        rank = np.empty(ne, dtype=np.int64)
        rank[pool] = np.arange(P)

        touched = np.zeros(n, dtype=bool)
        acc_parts = []
        active = pool
        Fr = F.ravel()
        for _ in range(tun.max_rounds):
            active = active[~touched[a[active]] & ~touched[b[active]]]
            if active.size == 0:
                break
            rk = rank[active]
            vmin = np.full(n, _BIG, dtype=np.int64)
            np.minimum.at(vmin, a[active], rk)
            np.minimum.at(vmin, b[active], rk)
            fmin = vmin[F].min(axis=1)
            hit = np.flatnonzero(fmin < _BIG)
            vmin2 = np.full(n, _BIG, dtype=np.int64)
            np.minimum.at(vmin2, F[hit].ravel(), np.repeat(fmin[hit], 3))
            chosen = rk == np.minimum(vmin2[a[active]], vmin2[b[active]])
            sel = active[chosen]
            active = active[~chosen]
            ok, pen, star, kf = _check(mesh, a[sel], b[sel], X[sel], interior[sel], valence, tun)
            total = cost[sel] + pen
            acc = ok & (total <= limit)
            # remember rejections until the neighbourhood changes
            rej = sel[~acc]
            val = np.where(ok[~acc], total[~acc], np.inf)
            mesh.blocked[eh[rej]] = val
            tw = twin[eh[rej]]
            has = tw >= 0
            mesh.blocked[tw[has]] = val[has]
            if _DEBUG: print('  round', m, P, sel.size, int(ok.sum()), int(acc.sum()))
            if acc.any():
                acc_parts.append(sel[acc])
                sf = star[acc[kf]]
                touched[F[sf].ravel()] = True
        if not acc_parts:
            continue
        acc = np.concatenate(acc_parts)
        if target is not None:
            acc = acc[np.argsort(cost[acc], kind="stable")]
            removed = np.where(interior[acc], 2, 1)
            before = np.cumsum(removed) - removed
            acc = acc[before < m - target]
        worst = max(worst, float(dist[acc].max()))
        _apply(mesh, a[acc], b[acc], X[acc], Qe[acc], touched)
    return "no_valid_collapse", worst, passes


def _apply(mesh, A, B, X, QA, touched):
    """Collapse every B[k] into A[k] at X[k] at once (edges independent)."""
    F, twin = mesh.F, mesh.twin
    n, m = mesh.V.shape[0], F.shape[0]
    star, fes, kf, nend = _faces_in_stars(F, n, A, B)
    coll = nend == 2
    cf = star[coll]
    cfes = fes[coll]
    # glue the twins of the two surviving sides of every removed face
    hA = 3 * cf + np.argmax(cfes >= 0, axis=1)
    hB = 3 * cf + 2 - np.argmax((cfes >= 0)[:, ::-1], axis=1)
    tA, tB = twin[hA], twin[hB]
    fl = mesh.feat[hA] | mesh.feat[hB]
    okA, okB = tA >= 0, tB >= 0
    twin[tA[okA]] = tB[okA]
    twin[tB[okB]] = tA[okB]
    mesh.feat[tA[okA]] = fl[okA]
    mesh.feat[tB[okB]] = fl[okB]
    # positions and quadrics
    moved = np.any(X != mesh.V[A], axis=1)
    mesh.V[A] = X
    mesh.Q[A] = QA
    mesh.moved[A] |= moved
    # blocked edges near a change are free again
    U, W = half_edge_ends(F)
    dirty = touched.copy()
    dirty[F[star].ravel()] = True
    mesh.blocked[dirty[U] | dirty[W]] = -1.0
    # remap vertices and drop the removed faces
    remap = np.arange(n, dtype=np.int64)
    remap[B] = A
    keep_f = np.ones(m, dtype=bool)
    keep_f[cf] = False
    new_f = np.cumsum(keep_f) - 1
    keep_h = np.repeat(keep_f, 3)
    h = np.flatnonzero(keep_h)
    new_h = np.full(3 * m, -1, dtype=np.int64)
    new_h[h] = 3 * new_f[h // 3] + h % 3
    tw = twin[keep_h]
    tw = np.where(tw >= 0, new_h[np.maximum(tw, 0)], tw)
    keep_v = np.ones(n, dtype=bool)
    keep_v[B] = False
    new_v = np.cumsum(keep_v) - 1
    mesh.F = new_v[remap[F[keep_f]]]
    mesh.twin = tw
    mesh.feat = mesh.feat[keep_h]
    mesh.blocked = mesh.blocked[keep_h]
    mesh.V = mesh.V[keep_v]
    mesh.Q = mesh.Q[keep_v]
    mesh.locked = mesh.locked[keep_v]
    mesh.moved = mesh.moved[keep_v]
    mesh.orig = mesh.orig[keep_v]
    mesh.cur_of_clean = new_v[remap[mesh.cur_of_clean]]
