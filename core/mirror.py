"""Mirror images of point sets: which vertex mirrors which, and exact symmetry.

The mirror plane passes through the origin, normal to an axis given as
``'X'``, ``'Y'`` or ``'Z'`` (the object's local coordinates). Used by
:mod:`core.symmetry` (symmetric cages) and :func:`core.fit.fit_cage`
(``symmetry=``: a fit that keeps them symmetric)::

    partner = mirror_partners(V, 'X')       # V[partner] == V mirrored, within a tolerance
    V = symmetrize(V, partner, 0)           # now exactly: 0.5 (V + mirror(V[partner]))
"""

import numpy as np

from .errors import InvalidArgumentError
from .mesh import bbox_diagonal, check_number, check_vertex_indices, check_vertices, shown

AXES = {"X": 0, "Y": 1, "Z": 2}
#: a mirror partner is accepted this close (share of the diagonal; ``mirror_partners``)
PARTNER_TOLERANCE = 1e-6


def axis_index(axis, where="simplify", name="symmetry"):
    """The coordinate 0, 1 or 2 of a mirror axis given as ``'X'``, ``'Y'``,
    ``'Z'`` or as that coordinate itself (0, 1, 2): the one parser of every
    ``axis`` / ``symmetry`` argument. Raises :class:`InvalidArgumentError`
    naming ``where`` and the argument ``name`` otherwise."""
    if isinstance(axis, str) and axis in AXES:
        return AXES[axis]
    if isinstance(axis, (int, np.integer)) and not isinstance(axis, (bool, np.bool_)) \
            and 0 <= axis < len(AXES):
        return int(axis)
    raise InvalidArgumentError(
        f"{where}: {name} must be 'X', 'Y' or 'Z' (or 0, 1, 2), got {shown(axis)}")


def mirror(V, axis):
    """A copy of ``V`` (n,3) with coordinate ``axis`` (0, 1, 2) negated."""
    out = np.array(V, dtype=np.float64)
    out[:, axis] = -out[:, axis]
    return out


def mirror_partners(V, axis, *, tolerance=PARTNER_TOLERANCE, where="mirror_partners"):
    """The mirror partner of every vertex.

    Parameters
    ----------
    V : (n,3) float array_like
    axis : {'X', 'Y', 'Z'} (or 0, 1, 2)
        The mirror plane goes through the origin, normal to this axis.
    tolerance : float
        Largest distance of a partner from the mirrored position, as a share
        of the bounding-box diagonal.

    Returns
    -------
    partner : (n,) int64, ``V[partner[i]]`` is ``V[i]`` mirrored (within the
        tolerance); ``partner[i] == i`` for vertices on the plane. An
        involution: ``partner[partner] == arange(n)``.

    Raises
    ------
    InvalidArgumentError
        A vertex has no partner (the points are not mirror-symmetric), or two
        vertices claim the same one.

    Examples
    --------
    >>> mirror_partners([[1.0, 0, 0], [-1.0, 0, 0], [0, 1.0, 0]], 'X').tolist()
    [1, 0, 2]
    """
    k = axis_index(axis, where, name="axis")
    axis = "XYZ"[k]
    V = check_vertices(V, where=where, copy=False)      # ((n,2), None, NaN: IndexErrors before)
    tolerance = check_number(tolerance, where=where, name="tolerance", lo=0, hi=1, open_lo=True)
    n = V.shape[0]
    if n == 0:
        return np.zeros(0, dtype=np.int64)
    tol = tolerance * (bbox_diagonal(V) or 1.0)
    M = mirror(V, k)
    partner, best = _exact_partners(V, M)
    left = np.flatnonzero(partner < 0)
    if left.size:
        partner[left], best[left] = _nearest_partners(V, M[left], 2.0 * tol)
    bad = np.flatnonzero(~(best <= tol))
    if bad.size:
        i = int(bad[0])
        raise InvalidArgumentError(
            f"{where}: the vertices are not mirror-symmetric about the {axis} plane: "
            f"{bad.size:,} have no partner within {tolerance:g} of the diagonal, e.g. vertex {i} "
            f"at {V[i].tolist()}")
    odd = _unpaired(partner)
    if odd.size:
        i = int(odd[0])
        raise InvalidArgumentError(
            f"{where}: the mirror pairing about the {axis} plane is ambiguous (two vertices at "
            f"one place?), e.g. vertex {i} and {int(partner[i])}")
    return partner


def _exact_partners(V, M):
    """Partners of the vertices whose mirror image ``M`` is exactly another
    vertex, also among coincident vertices: a group of ``c`` vertices at one
    place pairs, in index order, with the ``c`` at its mirror image (on the
    plane, with itself). Returns ``(partner, distance)``, -1 / inf where
    there is no such match."""
    n = V.shape[0]
    P = np.vstack([V, M])
    order = np.lexsort((P[:, 2], P[:, 1], P[:, 0]))
    Ps = P[order]
    new = np.ones(2 * n, dtype=bool)
    new[1:] = (Ps[1:] != Ps[:-1]).any(axis=1)           # -0.0 == 0.0: one group
    gid = np.empty(2 * n, dtype=np.int64)
    gid[order] = np.cumsum(new) - 1
    gV, gM = gid[:n], gid[n:]
    size = np.bincount(gV, minlength=int(gid.max()) + 1)
    by_group = np.argsort(gV, kind="stable")              # vertices by group, then index
    start = np.concatenate([[0], np.cumsum(size)[:-1]])
    rank = np.empty(n, dtype=np.int64)
    rank[by_group] = np.arange(n) - start[gV[by_group]]
    ok = size[gM] == size[gV]
    partner = np.full(n, -1, dtype=np.int64)
    partner[ok] = by_group[start[gM[ok]] + rank[ok]]
    return partner, np.where(ok, 0.0, np.inf)


def _nearest_partners(V, Mq, cell):
    """The vertex of ``V`` nearest each mirrored point of ``Mq`` among the
    27 grid cells (side ``cell``) around it, and its distance."""
    lo = np.minimum(V.min(axis=0), Mq.min(axis=0))
    Q = np.floor((V - lo) / cell).astype(np.int64) + 1
    QM = np.floor((Mq - lo) / cell).astype(np.int64) + 1
    dims = np.maximum(Q.max(axis=0), QM.max(axis=0)) + 2
    key = (Q[:, 0] * dims[1] + Q[:, 1]) * dims[2] + Q[:, 2]
    order = np.argsort(key, kind="stable")
    skey = key[order]
    partner = np.full(Mq.shape[0], -1, dtype=np.int64)
    best = np.full(Mq.shape[0], np.inf)
    # the cell of the mirrored point and its 26 neighbours; each cell holds few points
    for off in np.stack(np.meshgrid([-1, 0, 1], [-1, 0, 1], [-1, 0, 1], indexing="ij"), -1).reshape(-1, 3):
        q = QM + off
        qk = (q[:, 0] * dims[1] + q[:, 1]) * dims[2] + q[:, 2]
        start = np.searchsorted(skey, qk, side="left")
        stop = np.searchsorted(skey, qk, side="right")
        while True:
            has = np.flatnonzero(start < stop)
            if has.size == 0:
                break
            cand = order[start[has]]
            d = np.linalg.norm(V[cand] - Mq[has], axis=1)
            better = d < best[has]
            partner[has[better]] = cand[better]
            best[has[better]] = d[better]
            start[has] += 1
    return partner, best


def _unpaired(partner):
    """The vertices that are not the partner of their partner (ascending)."""
    return np.flatnonzero(partner[partner] != np.arange(partner.shape[0]))


def _chain(partner, i):
    """Vertex ``i``, its partner and its partner's partner."""
    return i, partner[i], partner[partner[i]]


def symmetrize(V, partner, axis):
    """Exactly mirror-symmetric positions: each vertex averaged with its
    partner's mirrored position.

    Parameters
    ----------
    V : (n,3) float array_like
    partner : (n,) int array_like
        Every vertex's mirror partner, in ``[0, n)`` (:func:`mirror_partners`;
        ``partner[i] == i`` for a vertex on the plane). There is no "no
        partner" value: a vertex without one cannot be made symmetric.
    axis : {'X', 'Y', 'Z'} or {0, 1, 2}
        The mirror axis, as :func:`mirror_partners` takes it (or its coordinate).

    Returns
    -------
    (n,3) float64, a new array: partners exact mirror images, vertices on
    the plane exactly on it.

    Raises
    ------
    InvalidMeshError
        ``V`` not (n,3) finite numbers.
    InvalidArgumentError
        ``axis`` not one of the above; ``partner`` not (n,) integers in ``[0, n)``.

    Examples
    --------
    >>> symmetrize([[1.0, 2, 0], [-1.2, 2, 0]], [1, 0], 'X').tolist()
    [[1.1, 2.0, 0.0], [-1.1, 2.0, 0.0]]
    """
    where = "symmetrize"
    k = axis_index(axis, where, name="axis")
    V = check_vertices(V, where=where, copy=False)
    partner = check_vertex_indices(partner, V.shape[0], where=where, name="partner")
    # a pairing: any other map gave positions that are not mirror images (np.roll of one)
    odd = _unpaired(partner)
    if odd.size:
        raise InvalidArgumentError(f"{where}: partner must pair the vertices (each the partner of "
                                   f"its partner), but {odd.size:,} are not, e.g. vertex "
                                   f"{' -> '.join(str(int(v)) for v in _chain(partner, odd[0]))}")
    out = 0.5 * (V + mirror(V[partner], k))
    # 0.5 (a + (-b)) and 0.5 (b + (-a)) are exact negatives; (a + b) / 2 and (b + a) / 2 equal
    out[partner == np.arange(V.shape[0]), k] = 0.0
    return out
