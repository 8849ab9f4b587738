"""Quadric error metrics (Garland & Heckbert 1997) in batched NumPy.

A quadric stores the squared distance to a weighted set of planes. For a
plane ``n . x + d = 0`` (``|n| = 1``) with weight ``w`` it is
``w * (n . x + d)^2 = x^T A x + 2 b . x + c`` with ``A = w n n^T``,
``b = w d n``, ``c = w d^2``. Quadrics add, so the quadric of a vertex is the
sum over its planes and the quadric of a merged vertex is the sum of both.

Layout: a stack of quadrics is a ``(k, 11)`` float64 array::

    0   1   2   3   4   5   6   7   8   9   10
    Axx Axy Axz Ayy Ayz Azz bx  by  bz  c   w

where ``w`` (column 10) is the total weight (area) of the planes. Face planes
are weighted by the face area, so ``error / w`` is a mean squared distance
and :func:`quadric_distance` ``= sqrt(error / w)`` is a distance in the mesh's
units (an RMS distance to the planes the vertex stands for).
"""

import numpy as np

from ._parallel import blocks, run_blocks
from .mesh import cross_rows

#: columns of a quadric stack
N_COEFFS = 11

#: relative determinant below which the 3x3 system is treated as singular:
#: ``|det A| <= DET_EPS * (trace A / 3)^3`` (unit-free: both scale alike)
DET_EPS = 1e-7

#: an optimal point farther than this many edge lengths from the edge midpoint
#: is distrusted (nearly singular system) and replaced by the segment optimum
MAX_DRIFT = 2.0


def plane_quadrics(normals, offsets, weights):
    """Quadrics of weighted planes ``n . x + d = 0``.

    Parameters
    ----------
    normals : (k,3) float64, unit normals.
    offsets : (k,) float64, ``d`` such that ``n . x + d = 0`` on the plane.
    weights : (k,) float64, non-negative weights (areas).

    Returns
    -------
    Q : (k,11) float64 quadric stack (see the module docstring for the layout).

    Examples
    --------
    >>> Q = plane_quadrics(np.array([[0., 0., 1.]]), np.array([-1.]), np.array([2.]))
    >>> float(quadric_error(Q, np.array([[0., 0., 3.]]))[0])  # 2 * (3 - 1)^2
    8.0
    """
    n = np.asarray(normals, dtype=np.float64)
    d = np.asarray(offsets, dtype=np.float64)
    w = np.asarray(weights, dtype=np.float64)
    nx, ny, nz = (np.ascontiguousarray(n[:, i]) for i in range(3))
    wx, wy, wz, wd = w * nx, w * ny, w * nz, w * d
    # built coefficient-major, returned as a (k,11) view (accumulate needs no copy)
    QT = np.empty((N_COEFFS, n.shape[0]))
    np.multiply(wx, nx, out=QT[0])
    np.multiply(wx, ny, out=QT[1])
    np.multiply(wx, nz, out=QT[2])
    np.multiply(wy, ny, out=QT[3])
    np.multiply(wy, nz, out=QT[4])
    np.multiply(wz, nz, out=QT[5])
    np.multiply(wd, nx, out=QT[6])
    np.multiply(wd, ny, out=QT[7])
    np.multiply(wd, nz, out=QT[8])
    np.multiply(wd, d, out=QT[9])
    QT[10] = w
    return QT.T


def face_quadrics(V, F, *, area_power=1.0, return_normals=False):
    """Area-weighted plane quadric of every face, ``(m, 11)``.

    The weight of face ``f`` is ``A_f^p * mean(A)^(1-p)`` with
    ``p = area_power``: 1 is Garland & Heckbert's area weighting, 0 weighs
    every plane the same (as Blender's Decimate does); any ``p`` keeps the
    weight an area, so the error stays unit-independent. Degenerate faces
    (zero area) get a zero quadric. With ``return_normals`` also returns the
    unit face normals (m,3).
    """
    Q, unit, _ = _face_planes(V, F, area_power)
    return (Q, unit) if return_normals else Q


def _face_planes(V, F, area_power):
    """``face_quadrics`` plus both normals: ``(Q (m,11), unit (m,3), N (m,3))``,
    ``N`` the unnormalised normal (length twice the area, as
    ``core.mesh.face_normals(V, F, normalize=False)``)."""
    N, unit, d, area = _face_geometry(V, F)
    return plane_quadrics(unit, d, _plane_weights(area, area_power)), unit, N


#: faces per block of work (temporaries stay in cache)
_BLOCK = 1 << 15


def _face_geometry(V, F):
    """Unnormalised normals N (m,3), unit normals (m,3) (zero for degenerate
    faces), plane offsets d (m,) and areas (m,), block by block."""
    m = F.shape[0]
    N = np.empty((m, 3))
    unit = np.empty((m, 3))
    d = np.empty(m)
    area = np.empty(m)

    def block(a, b):
        Fb = F[a:b]
        p0 = np.take(V, Fb[:, 0], axis=0)
        Nb = N[a:b]
        cross_rows(np.take(V, Fb[:, 1], axis=0) - p0, np.take(V, Fb[:, 2], axis=0) - p0, out=Nb)
        length = np.sqrt(np.einsum("ij,ij->i", Nb, Nb))
        ub = unit[a:b]
        ub[...] = 0.0
        np.divide(Nb, length[:, None], out=ub, where=length[:, None] > 0)
        d[a:b] = -np.einsum("ij,ij->i", ub, p0)
        area[a:b] = 0.5 * length

    run_blocks(block, blocks(m, _BLOCK))
    return N, unit, d, area


def _plane_weights(area, area_power):
    """``A^p * mean(A)^(1-p)`` where ``A > 0`` (see :func:`face_quadrics`); may
    reuse ``area``."""
    if area_power != 1.0 and area.size:
        mean = float(area.mean())
        if mean > 0:
            pos = area > 0
            area[pos] = area[pos] ** area_power * mean ** (1.0 - area_power)
    return area


def vertex_face_quadrics(V, F, n, area_power, *, scratch=None):
    """Sum of the face quadrics around each vertex, coefficient-major.

    The same numbers as ``accumulate(face_quadrics(V, F, area_power=p),
    F.T.ravel(), n, repeat=3)`` (same operations, same summation order),
    without the (m,11) stack: each coefficient row is made block by block
    straight into the weights of its ``bincount``. ``scratch`` may pass a
    (3m,) float64 buffer for those weights (overwritten).

    Returns
    -------
    QT : (11,n) float64, C-contiguous.
    unit : (m,3) float64, unit face normals (zero for degenerate faces).
    N : (m,3) float64, unnormalised normals (length twice the area).
    """
    m = F.shape[0]
    N, unit, d, area = _face_geometry(V, F)
    w = _plane_weights(area, area_power)
    # plane_quadrics' products (w * first) * second, one coefficient at a time
    nx, ny, nz = unit[:, 0], unit[:, 1], unit[:, 2]
    rows = [(nx, nx), (nx, ny), (nx, nz), (ny, ny), (ny, nz), (nz, nz), (d, nx), (d, ny), (d, nz), (d, d)]
    QT = np.empty((N_COEFFS, n))
    w3 = np.empty(3 * m) if scratch is None else scratch
    index = F.T.ravel()
    spans = blocks(m, _BLOCK)
    for j in range(N_COEFFS):
        run_blocks(lambda a, b: _corner_weights(w, rows[j] if j < 10 else None, w3, m, a, b), spans)
        QT[j] = np.bincount(index, weights=w3, minlength=n)
    return QT, unit, N


def _corner_weights(w, factors, w3, m, a, b):
    """Faces ``a:b`` of one coefficient's weights ``(w * f1) * f2`` (``w``
    itself without ``factors``) into ``w3`` at each of the three corners
    (``w3[c m + f]``), while the block is in cache."""
    if factors is None:
        w3[a:b] = w[a:b]
    else:
        f1, f2 = factors
        np.multiply(w[a:b] * f1[a:b], f2[a:b], out=w3[a:b])
    w3[m + a:m + b] = w3[a:b]
    w3[2 * m + a:2 * m + b] = w3[a:b]


def edge_constraint_quadrics(V, E, face_normals, weights):
    """Quadrics of planes through edges ``E`` perpendicular to a face.

    The plane of edge ``(p, q)`` with face normal ``n`` contains the edge and
    ``n``; its normal is ``(q - p) x n`` normalised. Used for boundary edges
    (so open borders keep their shape) and sharp feature edges.

    Parameters
    ----------
    V : (n,3) float64
    E : (k,2) int64 edges.
    face_normals : (k,3) float64, unit normal of a face using each edge.
    weights : (k,) float64, weight of each plane (an area: e.g. a multiple of
        the squared edge length, so it scales with the mesh like face areas).

    Returns
    -------
    Q : (k,11) float64
    """
    p = V[E[:, 0]]
    t = cross_rows(V[E[:, 1]] - p, face_normals)
    length = np.linalg.norm(t, axis=1)
    unit = np.divide(t, length[:, None], out=np.zeros_like(t), where=length[:, None] > 0)
    d = -np.einsum("ij,ij->i", unit, p)
    return plane_quadrics(unit, d, np.where(length > 0, weights, 0.0))


def accumulate(Q_items, index, n, *, repeat=1):
    """Sum quadrics into ``n`` bins: ``out[index[i]] += Q_items[i % k]``.

    Parameters
    ----------
    Q_items : (k,11) float64
    index : (repeat*k,) int64 in ``[0, n)``; with ``repeat > 1`` item ``i``
        goes to ``index[i], index[k+i], ...`` (e.g. ``F.T.ravel()`` with
        ``repeat=3`` sends each face quadric to its three corners).
    n : int

    Returns
    -------
    (n,11) float64
    """
    return np.ascontiguousarray(accumulate_coefficients(Q_items, index, n, repeat).T)


def accumulate_coefficients(Q_items, index, n, repeat):
    """``accumulate`` coefficient-major: (11, n). Each bin sums its items in
    the order of ``index`` (one ``bincount`` per coefficient)."""
    QT = np.ascontiguousarray(Q_items.T)
    k = QT.shape[1]
    out = np.empty((N_COEFFS, n))
    w = np.empty(k * repeat) if repeat > 1 else None
    for j in range(N_COEFFS):  # loop over the 11 coefficients, not over items
        if repeat > 1:
            for r in range(repeat):
                w[r * k:(r + 1) * k] = QT[j]
        out[j] = np.bincount(index, weights=QT[j] if w is None else w, minlength=n)
    return out


def quadric_error(Q, X):
    """Quadric error ``x^T A x + 2 b . x + c`` of points ``X`` (k,3) for
    quadrics ``Q`` (k,11); clamped at 0 against round-off."""
    return quadric_at(Q.T, X[:, 0], X[:, 1], X[:, 2])


def quadric_distance(Q, err):
    """RMS distance ``sqrt(err / w)`` in mesh units (0 where ``w`` is 0)."""
    return rms_distance(err, Q[:, 10])


def rms_distance(err, w):
    """``sqrt(err / w)`` for quadric errors ``err`` and quadric areas ``w``
    (0 where ``w`` is 0; negative round-off in ``err`` counts as 0)."""
    return np.where(w > 0, np.sqrt(np.maximum(err, 0.0) / np.where(w > 0, w, 1.0)), 0.0)


#: columns per block of :func:`place_columns`: its sixty-odd temporaries then stay
#: in cache and come from the allocator's free lists (30,000 columns at once: 8-13 ms;
#: in blocks: 4-7 ms, alternating runs)
_PLACE_BLOCK = 4096


def quadric_at(q, x, y, z):
    """Quadric error of columns ``q`` (11,k) at points ``(x, y, z)``, >= 0."""
    return np.maximum(q[0] * x * x + q[3] * y * y + q[5] * z * z
                      + 2.0 * (q[1] * x * y + q[2] * x * z + q[4] * y * z + q[6] * x + q[7] * y + q[8] * z)
                      + q[9], 0.0)


def place_columns(q, p0, p1):
    """:func:`optimal_placement` on columns: ``q`` (11,k) merged
    quadrics, ``p0``, ``p1`` (3,k) endpoints; returns ``X`` (3,k) and the error (k,).

    Same rule: closed-form 3x3 solve about the midpoint; where it is
    ill-conditioned or drifts more than ``MAX_DRIFT`` edge lengths, the best of
    the segment's minimum and the two endpoints. Columns go in blocks of
    ``_PLACE_BLOCK`` (each column's result depends on that column alone).
    """
    k = q.shape[1]
    if k <= _PLACE_BLOCK:
        return _place_block(q, p0, p1)
    X, err = np.empty((3, k)), np.empty(k)
    for s in range(0, k, _PLACE_BLOCK):
        cols = slice(s, s + _PLACE_BLOCK)
        X[:, cols], err[cols] = _place_block(q[:, cols], p0[:, cols], p1[:, cols])
    return X, err


def _place_block(q, p0, p1):
    """:func:`place_columns` on one block of columns. The 3x3 solve runs on
    the well-conditioned columns alone (on a flat or CAD mesh nearly every
    quadric is singular: the whole solve was computed, then replaced by the
    fallback); each column's result is the same bits either way."""
    q0, q1, q2, q3, q4, q5 = q[:6]
    c00 = q3 * q5 - q4 * q4
    c01 = q2 * q4 - q1 * q5
    c02 = q1 * q4 - q2 * q3
    det = q0 * c00 + q1 * c01 + q2 * c02
    tr = (q0 + q3 + q5) * (1.0 / 3.0)
    ok = np.abs(det) > DET_EPS * tr * tr * tr
    d = p1 - p0
    good = np.flatnonzero(ok)
    if good.size == 0:
        return _segment_fallback(q, p0, p1, d)
    if good.size == ok.size:
        X, err, ok = _solved(q, p0, p1, d, det, c00, c01, c02)
    else:
        X, err = np.empty(p0.shape), np.empty(ok.size)
        X[:, good], err[good], ok[good] = _solved(*(np.take(a, good, axis=-1)
                                                    for a in (q, p0, p1, d, det, c00, c01, c02)))
    bad = np.flatnonzero(~ok)
    if bad.size:
        X[:, bad], err[bad] = _segment_fallback(*(np.take(a, bad, axis=1) for a in (q, p0, p1, d)))
    return X, err


def _solved(q, p0, p1, d, det, c00, c01, c02):
    """The closed-form solve of :func:`_place_block` on well-conditioned
    columns (ends ``p0``, ``p1``, ``d = p1 - p0``; ``det`` and the first
    cofactors ``c0j`` of each quadric's 3x3 part): the points (3,k), their
    errors (k,), and whether each stays within ``MAX_DRIFT`` edge lengths
    (k,) bool."""
    q0, q1, q2, q3, q4, q5, b0, b1, b2 = q[:9]
    c11 = q0 * q5 - q2 * q2
    c12 = q1 * q2 - q0 * q4
    c22 = q0 * q3 - q1 * q1
    inv = -1.0 / det
    mid = 0.5 * (p0 + p1)
    mx, my, mz = mid
    r0 = q0 * mx + q1 * my + q2 * mz + b0
    r1 = q1 * mx + q3 * my + q4 * mz + b1
    r2 = q2 * mx + q4 * my + q5 * mz + b2
    y0 = (c00 * r0 + c01 * r1 + c02 * r2) * inv
    y1 = (c01 * r0 + c11 * r1 + c12 * r2) * inv
    y2 = (c02 * r0 + c12 * r1 + c22 * r2) * inv
    len2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2]
    ok = y0 * y0 + y1 * y1 + y2 * y2 <= (MAX_DRIFT * MAX_DRIFT) * len2
    X = np.stack([mx + np.where(ok, y0, 0.0), my + np.where(ok, y1, 0.0),
                  mz + np.where(ok, y2, 0.0)])
    return X, quadric_at(q, X[0], X[1], X[2]), ok


def _segment_fallback(qb, s0, s1, db):
    """:func:`place_columns`'s rule for columns where the solve failed
    (quadrics ``qb``, ends ``s0``, ``s1``, ``db = s1 - s0``): the best of the
    quadric's minimum on the segment and its two ends (the first of equal
    ones, in that order). Returns the points (3,k) and their errors (k,)."""
    Ad = [qb[0] * db[0] + qb[1] * db[1] + qb[2] * db[2], qb[1] * db[0] + qb[3] * db[1] + qb[4] * db[2],
          qb[2] * db[0] + qb[4] * db[1] + qb[5] * db[2]]
    dAd = db[0] * Ad[0] + db[1] * Ad[1] + db[2] * Ad[2]
    # derivative of E(s0 + t db) is 2 (db.(A s0 + b)) + 2 t dAd
    g = Ad[0] * s0[0] + Ad[1] * s0[1] + Ad[2] * s0[2] + db[0] * qb[6] + db[1] * qb[7] + db[2] * qb[8]
    t = np.clip(np.where(dAd > 0, -g / np.where(dAd > 0, dAd, 1.0), 0.5), 0.0, 1.0)
    best = s0 + t * db
    e_best = quadric_at(qb, *best)
    for end in (s0, s1):
        e_end = quadric_at(qb, *end)
        closer = e_end < e_best
        best = np.where(closer, end, best)
        e_best = np.where(closer, e_end, e_best)
    return best, e_best


def optimal_placement(Q, P0, P1):
    """Position minimising each quadric for the collapse of edge ``(P0, P1)``.

    The 3x3 systems ``A x = -b`` are solved all at once in closed form
    (adjugate / determinant). Where a system is ill-conditioned
    (``|det A| <= DET_EPS (tr A / 3)^3``) or its solution lies more than
    ``MAX_DRIFT`` edge lengths from the edge, the best of: the quadric's
    minimum on the segment ``[P0, P1]``, ``P0`` and ``P1`` is used instead
    (this includes the endpoints-and-midpoint rule of Garland & Heckbert and
    does at least as well).

    Parameters
    ----------
    Q : (k,11) float64, the merged quadric of each edge.
    P0, P1 : (k,3) float64, the endpoints.

    Returns
    -------
    X : (k,3) float64, the chosen positions.
    err : (k,) float64, the quadric error at ``X`` (>= 0).
    """
    X, err = place_columns(np.ascontiguousarray(Q.T), np.ascontiguousarray(P0.T), np.ascontiguousarray(P1.T))
    return np.ascontiguousarray(X.T), err
