"""Final vertex relocation of a simplified cage towards the original surface.

After the collapses, every movable cage vertex is moved to reduce the squared
distance from points of the original surface to the cage (ICP-like, with the
correspondences fixed per iteration)::

    repeat iters times:
        (f_s, b_s) = closest cage face and barycentrics of each sample p_s
        minimise  sum_s |sum_c b_sc v[F[f_s, c]] - p_s|^2 + sum_j l_j |v_j - v0_j|^2
                  (conjugate gradients on the normal equations, per coordinate)
        undo the move of every vertex of a face that would flip or degenerate

Boundary, crease, locked and frozen vertices do not move, so borders,
creases and the caller's constraints are kept exactly.
"""

import numpy as np

from .spatial import TriangleIndex


def _matvec(idx, b, x, lam):
    """(B^T B + diag(lam)) x for the sample-to-cage barycentric operator B.

    ``idx`` is (3, s): the cage vertex of each sample's three corners,
    ``b`` is (3, s): their barycentric weights."""
    Bx = (b[0, :, None] * np.take(x, idx[0], axis=0) + b[1, :, None] * np.take(x, idx[1], axis=0)
          + b[2, :, None] * np.take(x, idx[2], axis=0))
    return _scatter(idx, b, Bx, x.shape[0]) + lam[:, None] * x


def _scatter(idx, b, R, n):
    """B^T R: (s,3) sample residuals to (n,3) vertex sums."""
    flat = idx.ravel()
    out = np.empty((n, 3))
    for k in range(3):
        out[:, k] = np.bincount(flat, weights=(b * R[:, k]).ravel(), minlength=n)
    return out


def _normals(V, F):
    return np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])


def relocate(V, F, P, movable, *, iters=2, cg_iters=15, reg=0.05, min_cos=0.2, N_keep=None):
    """Move ``movable`` vertices of the cage ``(V, F)`` towards points ``P``.

    Parameters
    ----------
    V : (n,3) float64 cage vertices (not modified).
    F : (m,3) int64 cage faces.
    P : (s,3) float64 points on the original surface.
    movable : (n,) bool.
    iters : int, correspondence updates.
    cg_iters : int, conjugate-gradient steps per update.
    reg : float, weight pulling each vertex to its current position, relative
        to the vertex's own sample weight (unit-free).
    min_cos : float, a moved face whose normal turns by more than
        ``acos(min_cos)`` is undone.
    N_keep : (m,3) float64 or None, reference normals: a moved face whose normal
        ends more than 90 degrees from its row is undone too (the caller passes
        the summed input normals each face stands for).

    Returns
    -------
    (n,3) float64 new positions.
    """
    V = V.copy()
    n = V.shape[0]
    if not movable.any() or F.shape[0] == 0 or P.shape[0] == 0:
        return V
    N_ref = _normals(V, F)
    for _ in range(iters):
        cp = TriangleIndex(V, F).closest(P)
        idx = np.ascontiguousarray(np.take(F, cp.face, axis=0).T)     # (3, s)
        b = np.ascontiguousarray(cp.bary.T)                           # (3, s)
        diag = np.bincount(idx.ravel(), weights=(b * b).ravel(), minlength=n)
        lam = reg * diag + reg * max(float(diag.mean()), 1e-300)
        lam[~movable] = 1e30  # pinned
        # solve (B^T B + lam) D = B^T (P - B V) for the displacement D by CG
        Bv = (b[0, :, None] * np.take(V, idx[0], axis=0) + b[1, :, None] * np.take(V, idx[1], axis=0)
              + b[2, :, None] * np.take(V, idx[2], axis=0))
        r = _scatter(idx, b, P - Bv, n)
        r[~movable] = 0.0
        D = np.zeros((n, 3))
        Rk = r.copy()
        Pk = Rk.copy()
        rs = np.einsum("ij,ij->j", Rk, Rk)
        for _ in range(cg_iters):
            Ap = _matvec(idx, b, Pk, lam)
            pAp = np.einsum("ij,ij->j", Pk, Ap)
            alpha = np.divide(rs, pAp, out=np.zeros(3), where=pAp > 0)
            D += alpha * Pk
            Rk -= alpha * Ap
            rs_new = np.einsum("ij,ij->j", Rk, Rk)
            beta = np.divide(rs_new, rs, out=np.zeros(3), where=rs > 0)
            Pk = Rk + beta * Pk
            rs = rs_new
        D[~movable] = 0.0
        # undo moves that flip or flatten a face (sweeps: undoing can expose others;
        # each sweep zeroes at least one move, and no move at all is valid)
        l0 = np.linalg.norm(N_ref, axis=1)
        while True:
            Vn = V + D
            N1 = _normals(Vn, F)
            l1 = np.linalg.norm(N1, axis=1)
            bad = np.einsum("ij,ij->i", N_ref, N1) <= min_cos * l0 * l1
            if N_keep is not None:
                bad |= np.einsum("ij,ij->i", N_keep, N1) <= 0.0
            bad &= np.any(D[F] != 0.0, axis=(1, 2))
            if not bad.any():
                break
            D[F[bad].ravel()] = 0.0
        V = V + D
    return V
