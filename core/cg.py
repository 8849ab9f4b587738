"""Conjugate gradients for symmetric positive (semi-)definite operators.

Hestenes & Stiefel (1952). The matrix is never formed: the caller gives a
function ``A(X)``, so the least-squares fit in :mod:`.fit` can apply
``S^T W S + lambda L^T L`` through the subdivision operator and its adjoint.
Several right-hand sides are solved at once, one independent CG recurrence per
column (the columns share every ``A`` application)::

    R = B - A(X); P = R
    loop:  alpha = (R.R) / (P.A(P))        per column
           X += alpha P;  R -= alpha A(P)
           stop when |R| <= rtol |B|       for every column
           P = R + ((R.R)_new / (R.R)_old) P
"""

from typing import NamedTuple

import numpy as np

from .errors import InvalidArgumentError


class CGResult(NamedTuple):
    """Solution and convergence record of :func:`conjugate_gradient`."""

    X: np.ndarray          #: (n,) or (n,k) float64 solution
    iterations: int        #: number of A applications after the initial residual
    residual: np.ndarray   #: (k,) float64 final relative residual |B - A X| / |B| per column
    converged: bool        #: every column reached ``rtol``


def conjugate_gradient(A, B, *, X0=None, rtol=1e-8, max_iterations=500, preconditioner=None):
    """Solve ``A X = B`` for a symmetric positive definite linear map ``A``.

    Parameters
    ----------
    A : callable
        ``A(X)`` returns the product for an array shaped like ``B``; it must be
        linear, symmetric and positive (semi-)definite on the columns.
    B : (n,) or (n,k) array_like float
        Right-hand side(s); the columns are independent systems sharing ``A``.
    X0 : array shaped like ``B``, optional
        Starting guess (zeros by default). Not modified.
    rtol : float
        Stop when ``|B - A X| <= rtol * |B|`` for every column.
    max_iterations : int
    preconditioner : callable, optional
        ``M(R)`` approximating ``A^-1 R`` (symmetric positive), e.g. a Jacobi
        diagonal scaling.

    Returns
    -------
    CGResult

    Raises
    ------
    InvalidArgumentError
        ``rtol`` not positive, ``max_iterations`` negative, or ``X0`` shaped
        unlike ``B``.

    Examples
    --------
    >>> M = np.array([[4.0, 1.0], [1.0, 3.0]])
    >>> r = conjugate_gradient(lambda x: M @ x, np.array([1.0, 2.0]))
    >>> np.allclose(M @ r.X, [1.0, 2.0])
    True
    """
    if not rtol > 0:
        raise InvalidArgumentError(f"conjugate_gradient: rtol must be > 0, got {rtol}")
    if max_iterations < 0:
        raise InvalidArgumentError(
            f"conjugate_gradient: max_iterations must be >= 0, got {max_iterations}")
    B = np.asarray(B, dtype=np.float64)
    vector = B.ndim == 1
    B2 = B.reshape(B.shape[0], -1)
    if X0 is None:
        X = np.zeros_like(B2)
        R = B2.copy()
    else:
        X0 = np.asarray(X0, dtype=np.float64)
        if X0.shape != B.shape:
            raise InvalidArgumentError(
                f"conjugate_gradient: X0 must have the shape of B {B.shape}, got {X0.shape}")
        X = X0.reshape(B2.shape).copy()
        R = B2 - _apply(A, X, vector)
    M = (lambda Z: Z) if preconditioner is None else (lambda Z: _apply(preconditioner, Z, vector))
    b_norm = np.linalg.norm(B2, axis=0)
    b_norm = np.where(b_norm > 0, b_norm, 1.0)
    Z = M(R)
    P = Z.copy()
    rz = np.einsum("ij,ij->j", R, Z)
    it = 0
    rel = np.linalg.norm(R, axis=0) / b_norm
    while it < max_iterations and np.any(rel > rtol):
        AP = _apply(A, P, vector)
        pap = np.einsum("ij,ij->j", P, AP)
        active = (rel > rtol) & (pap > 0)
        if not active.any():
            break
        alpha = np.where(active, rz / np.where(pap > 0, pap, 1.0), 0.0)
        X += alpha * P
        R -= alpha * AP
        Z = M(R)
        rz_new = np.einsum("ij,ij->j", R, Z)
        beta = np.where(active & (rz > 0), rz_new / np.where(rz > 0, rz, 1.0), 0.0)
        P = Z + beta * P
        rz = rz_new
        it += 1
        rel = np.linalg.norm(R, axis=0) / b_norm
    X_out = X.reshape(B.shape) if vector else X
    return CGResult(X_out, it, rel, bool(np.all(rel <= rtol)))


def _apply(A, X, vector):
    """Apply ``A`` to the (n,k) block ``X``, in the caller's shape convention."""
    if vector:
        return np.asarray(A(X[:, 0]), dtype=np.float64).reshape(-1, 1)
    return np.asarray(A(X), dtype=np.float64).reshape(X.shape)
