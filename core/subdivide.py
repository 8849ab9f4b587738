r"""Modified butterfly and Loop subdivision as linear operators.

Papers
------
* D. Zorin, P. Schroeder, W. Sweldens, "Interpolating Subdivision for Meshes
  with Arbitrary Topology", SIGGRAPH 1996 (the *modified butterfly*).
* C. Loop, "Smooth Subdivision Surfaces Based on Triangles", MS thesis,
  University of Utah, 1987, with J. Warren's simpler vertex weight ``beta``.
* H. Hoppe et al., "Piecewise Smooth Surface Reconstruction", SIGGRAPH 1994
  (boundary and crease curves refined as curves; corners stay put).

Each level splits every triangle into four and is a sparse linear map from the
``n`` coarse positions to the ``n + e`` fine ones. :func:`subdivision_operator`
builds the chain of levels once (topology only); ``apply`` then costs a few
gathers and sums, so an interactive edit re-applies it without rebuilding.

Numbering (deterministic, level by level)
-----------------------------------------
* Vertices: the ``n`` coarse vertices keep their indices ``0..n-1``; new
  vertex ``n + k`` sits on edge ``k`` of ``core.topology.edge_map(F, n).E``
  (unique edges ``(lo, hi)`` in lexicographic order).
* Faces: coarse face ``f = (a, b, c)`` with edge midpoints ``ma, mb, mc``
  (``m? = n + face_edge[f, ?]``, the midpoint of the edge *opposite* that
  corner) becomes fine faces ``4f + 0 .. 4f + 3``::

                 c
                / \
               / 2 \                 child 0 = (a,  mc, mb)
             mb-----ma               child 1 = (mc, b,  ma)
             / \ 3 / \               child 2 = (mb, ma, c )
            / 0 \ / 1 \              child 3 = (ma, mb, mc)
           a-----mc----b

  Child ``i < 3`` keeps the old vertex at its corner ``i``; all children keep
  the parent's orientation. After ``L`` levels fine face ``g`` lies in coarse
  face ``g // 4**L`` (``fine_to_coarse_face``), and its base-4 digits, read
  from the most significant, name the child taken at each level: composing
  the ``CHILD_BARY`` tables along them gives the barycentric coordinates of
  each fine corner in the coarse face
  (:meth:`SubdivisionOperator.fine_vertex_parent`). These are *parametric*
  positions: the subdivided surface bulges off the flat coarse face.
* Creases: a crease edge ``(a, b)`` gives crease edges ``(a, n+k)`` and
  ``(b, n+k)`` on the next level.

Sharp edges and vertex classes
------------------------------
An edge is *sharp* when it is a boundary edge (one face) or a tagged crease.
A vertex with ``s`` sharp edges is *smooth* (``s = 0``), a *curve* vertex
(``s = 2``) or a *corner* (``s = 1``: a crease ends there; ``s >= 3``).

Modified butterfly (interpolating: old vertices are copied bit for bit)
-----------------------------------------------------------------------
Regular edge (both ends smooth with valence 6), tension ``w = 1/16``::

           -1/16 ------- 1/8 ------- -1/16
                \       /   \       /
                 \     /     \     /
                  \   /       \   /
                  1/2 ------- 1/2          new vertex on the middle edge
                  /   \       /   \
                 /     \     /     \
                /       \   /       \
           -1/16 ------- 1/8 ------- -1/16

Extraordinary end (smooth, valence ``k != 6``): only its own one-ring, itself
``3/4``, its neighbours ``s_0 .. s_{k-1}`` in counter-clockwise order starting
at the edge's other end::

        k = 3:  s = 5/12, -1/12, -1/12
        k = 4:  s = 3/8, 0, -1/8, 0
        k >= 5: s_j = (1/4 + cos(2 pi j / k) + 1/2 cos(4 pi j / k)) / k

            s_2 ----- s_1
            /  \     /  \
           /    \   /    \
        s_3 ---- 3/4 ---- s_0       (s_0 = the other end of the edge)
           \    /   \    /
            \  /     \  /
            s_4 ----- s_5

Both ends extraordinary: the average of the two stencils. One end
extraordinary, the other regular or on a sharp curve: the extraordinary end's
stencil.

Sharp edge (boundary or crease): the 4-point rule along the curve::

        -1/16 ---- 9/16 ---- 9/16 ---- -1/16
          a'        a    *    b         b'

where ``a'`` is ``a``'s other sharp neighbour. If ``a`` is a corner, the rule
does not reach across it: ``a'`` is replaced by its reflection ``2a - b``
(weights ``7/16 a + 10/16 b - 1/16 b'``; two corner ends give the midpoint).

Interior (non-sharp) edge touching a sharp vertex, with no smooth
extraordinary end: the 8-point stencil, except that a wing point that does not
exist, or lies across a sharp edge, is never read. It is replaced by the
*reflected wing* (the idea OpenMesh uses): the wing across edge ``(x, y)`` of
face ``(x, y, z)`` becomes the parallelogram point ``x + y - z``, which is
where the wing sits on a regular planar grid::

              c ------- w'        edge (a, c) is on the boundary or a crease:
             / \       /          its wing w' = a + c - b is never read, its
            /   \     /           -1/16 goes to a (-1/16), c (-1/16) and
           /     \   /            b (+1/16)
          b --*-- a
           \     /                * = the new vertex on edge (a, b)
            \   /
              d

So the row still sums to 1, linear fields are reproduced (a planar region
stays planar, a flat side of a creased cube stays flat) and the two sides of
a crease never see each other. With smooth extraordinary ends the ring
stencil is used instead (those vertices have no sharp edge, so their ring is
complete).

Loop (approximating)
--------------------
Odd (edge) vertices: interior edge ``3/8 a + 3/8 b + 1/8 c + 1/8 d`` (``c``,
``d`` opposite the edge); sharp edge ``1/2 a + 1/2 b``.
Even (old) vertices: smooth of valence ``k``: ``(1 - k beta) v + beta * sum of
neighbours`` with Warren's ``beta = 3/16`` for ``k = 3`` and ``3/(8k)``
otherwise; curve vertex ``(1/8, 6/8, 1/8)`` with its two sharp neighbours;
corners and isolated vertices stay put::

            beta --- beta                 1/8 ==== 6/8 ==== 1/8
            /  \     /  \                      (curve)
        beta - 1-k*beta - beta
            \  /     \  /          1/8 -- 3/8 -- 3/8 -- 1/8 (odd: c, a, b, d)
            beta --- beta

Implementation
--------------
Everything is vectorised (``core/_refine.py``: the topology of each level;
``core/_stencils.py``: the stencils). Edges and their faces come from one sort
at the coarse level and by construction below it; one-rings of extraordinary
vertices are put in rotational order by pointer jumping along the "next face
around the vertex" map; rows are assembled by a counting scatter. A level is
a CSR matrix (rows sorted). ``apply_transpose`` is the matching
``np.bincount`` scatter. ``apply`` runs from an apply plan made once per level:
the old-vertex rows and the new-vertex rows as two padded fixed-width tables
(a butterfly's old vertices are a plain copy), so each coordinate costs one
gather and one multiply-sum, and the few rows longer than their table's width
(high-valence vertices) through ``np.add.reduceat`` on the CSR arrays
(gathered once, in the plan). The last level writes straight into the
``(n_fine, k)`` result, so no fine-sized transpose is made. No Python loop
runs over vertices, edges or faces.
"""

import hashlib
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from . import _refine as _rf
from . import _stencils as _st
from .errors import InvalidArgumentError, InvalidMeshError
from .mesh import check_count, check_faces, check_finite_rows, check_mesh, shown
from .pages import plain_pages

SCHEMES = ("butterfly", "loop")

#: most faces a subdivision may make (2^28, 268M: about 20 GB of operator and positions)
MAX_FINE_FACES = 2 ** 28
#: most fine faces a fit or a bind works on (``fit_cage``, ``bind``, ``bind_refined``): each
#: costs about 0.8 KB in a bind and 1.1 KB in a fit (a 100-face cage bound at 8 levels,
#: 6.6M fine faces: 5.2 GB, 36 s; fitted at 7, 1.6M: 1.8 GB, 50 s), so 2^24 (16.8M: a
#: 10k-face cage at the five levels Auto takes at most) is about 13-18 GB; at 9 levels
#: a 100-face cage's fit ran out of memory in NumPy instead of being refused
MAX_BOUND_FINE_FACES = 2 ** 24
#: most levels any mesh may take (one triangle makes MAX_FINE_FACES faces at 14)
MAX_LEVELS = int(round(np.log(MAX_FINE_FACES) / np.log(4.0)))
#: most entries the butterfly's ring stencils may take a level: each edge at a vertex of
#: valence k reads its k ring vertices, k^2 entries for the vertex (a CAD cap fan of 10k
#: triangles held 5.5 GB, 40k ran out of memory; a fan of 5k, 25M entries, 1.4 GB at its
#: peak)
MAX_RING_ENTRIES = 2 ** 25

#: coarse values whose reach times the operator's ``gain`` stay below this are applied
#: as they are: no partial sum can overflow (half the largest float, for rounding)
_SAFE_REACH = float(np.finfo(np.float64).max) / 2

__all__ = ["subdivide", "subdivision_operator", "SubdivisionOperator", "SubdivisionResult", "SCHEMES"]


class SubdivisionResult(NamedTuple):
    """The subdivided mesh (unpacks as ``V_fine, F_fine = subdivide(...)``)."""

    V: np.ndarray  #: (n_fine, 3) float64
    F: np.ndarray  #: (m * 4**levels, 3) int64


@dataclass(frozen=True, eq=False)
class SubdivisionOperator:
    """The linear map from coarse to fine vertex positions, level by level.

    Attributes
    ----------
    n_coarse, n_fine : int
    F_fine : (m * 4**levels, 3) int64
    fine_to_coarse_face : (m * 4**levels,) int64, ``arange(m 4^L) // 4**L``.
    scheme : str, ``"butterfly"`` or ``"loop"``.
    levels : int
    creases : (k,2) int64, the coarse crease edges (sorted ``lo < hi`` rows, unique).
    fingerprint : str, a hash of (F, n_coarse, levels, scheme, creases).
    gain : float, a bound on ``|apply(X)| / max|X|``: the product of the
        levels' largest absolute row sums (1 for Loop; butterfly overshoots).
    stencils : tuple of per-level stencils (``core._stencils.Stencil``: CSR
        ``indptr, cols, weights`` with rows sorted, ``n_in``, and the apply
        ``plan``); the fine vertices of level ``i`` are the coarse ones of
        level ``i+1``.
    """

    n_coarse: int
    n_fine: int
    F_fine: np.ndarray
    fine_to_coarse_face: np.ndarray
    scheme: str
    levels: int
    creases: np.ndarray
    fingerprint: str
    stencils: tuple = field(repr=False)
    gain: float = 1.0

    def _as_2d(self, X, n, what):
        """``X`` as (n, k) float64 values and whether it was (n,): real
        numbers only (strings, booleans and complex numbers were taken, a
        ragged list was NumPy's ValueError). NaN is refused by :meth:`apply`
        (coarse values: few) but not by :meth:`apply_transpose`, on the hot
        path of every fit (fine values: NaN in, NaN out)."""
        try:
            A = np.asarray(X)
        except ValueError:
            A = np.asarray(X, dtype=object)
        if A.dtype.kind not in "fiu":
            raise InvalidArgumentError(
                f"SubdivisionOperator.{what}: expected ({n}, k) or ({n},) real numbers, got "
                f"{A.shape} {A.dtype}")
        X = np.asarray(A, dtype=np.float64)
        one_d = X.ndim == 1
        X2 = X[:, None] if one_d else X
        if X2.ndim != 2 or X2.shape[0] != n:
            raise InvalidArgumentError(
                f"SubdivisionOperator.{what}: expected ({n}, k) or ({n},) values, got {X.shape}")
        return X2, one_d

    def apply(self, Vc):
        """Fine positions (or any per-vertex values) from coarse ones.

        Parameters
        ----------
        Vc : (n_coarse, k) or (n_coarse,) float

        Returns
        -------
        (n_fine, k) or (n_fine,) float64, a new array.

        Raises :class:`InvalidArgumentError` for values of the wrong shape or
        kind, NaN / infinite values (naming the first coarse vertex), or
        values so large that the result would exceed the largest float.
        """
        X, one_d = self._as_2d(Vc, self.n_coarse, "apply")
        check_finite_rows(X, where="SubdivisionOperator.apply", what="coarse vertices")
        return self._within_floats(X, one_d, "SubdivisionOperator.apply", "values",
                                   InvalidArgumentError)

    def _within_floats(self, X, one_d, where, what, error):
        """:meth:`_apply` of the finite (n_coarse, k) ``X``; when ``X`` reaches
        so far that a sum could overflow (coordinates near 1e308: butterfly
        overshoots its cage), on ``X`` scaled down by a power of two (exact)
        and back, and ``error`` naming ``where`` if the result does not fit
        (it came out inf and NaN)."""
        reach = float(np.abs(X).max()) if X.size else 0.0
        if reach <= _SAFE_REACH / self.gain:
            return self._apply(X, one_d)
        scale = 2.0 ** -int(np.ceil(np.log2(reach) + np.log2(self.gain) - np.log2(_SAFE_REACH)))
        with np.errstate(over="ignore"):
            out = self._apply(X * scale, one_d) / scale
        if not np.isfinite(out).all():
            raise error(
                f"{where}: the subdivided {what} would exceed the largest float: the coarse ones "
                f"reach {reach:.3g} and {self.scheme} x{self.levels} overshoots them by "
                f"up to {self.gain:.3g}x; scale them down first")
        return out

    def _apply(self, X, one_d):
        """The fine values of the (n_coarse, k) float64 ``X``."""
        Xt = np.ascontiguousarray(X.T)          # column-major: each gather reads one column
        if not self.stencils:
            # (a copy: for one column, or one vertex, both transposes were views of Vc)
            return Xt[0].copy() if one_d else np.array(Xt.T, order="C")
        for S in self.stencils[:-1]:
            Xt = S.apply_t(Xt)
        # the last level writes straight into the (n_fine, k) result (no final transpose)
        out = np.empty((self.n_fine, Xt.shape[0]))
        self.stencils[-1].apply_t(Xt, out=out.T)
        return out[:, 0] if one_d else out

    def apply_transpose(self, G):
        """The exact adjoint: ``<apply(x), g> == <x, apply_transpose(g)>``.

        Parameters
        ----------
        G : (n_fine, k) or (n_fine,) float

        Returns
        -------
        (n_coarse, k) or (n_coarse,) float64
        """
        X, one_d = self._as_2d(G, self.n_fine, "apply_transpose")
        Xt = np.ascontiguousarray(X.T)
        for S in reversed(self.stencils):
            Xt = S.apply_transpose_t(Xt)
        return Xt[0].copy() if one_d else np.array(Xt.T, order="C")

    def triplets(self):
        """The composed coarse-to-fine matrix as triplets.

        Returns
        -------
        rows, cols : (nnz,) int64, sorted by (row, col), no repeated pair.
        weights : (nnz,) float64; each row sums to 1. Exact zeros (weights
            that cancel) are dropped.
        """
        n0 = self.n_coarse
        if not self.stencils:
            r = np.arange(n0, dtype=np.int64)
            return r, r.copy(), np.ones(n0)
        indptr, cols, w = _merge_rows(self.stencils[0], n0)
        for S in self.stencils[1:]:
            lengths = np.diff(indptr)[S.cols]
            rows_s = S.rows()
            rep = np.repeat(np.arange(S.cols.shape[0]), lengths)
            offs = np.arange(rep.shape[0]) - np.repeat(np.cumsum(lengths) - lengths, lengths)
            idx = indptr[S.cols][rep] + offs
            new = _CSR(rows_s[rep], cols[idx], S.weights[rep] * w[idx], S.n_out, n0)
            indptr, cols, w = _merge_rows(new, n0)
        rows = np.repeat(np.arange(indptr.shape[0] - 1, dtype=np.int64), np.diff(indptr))
        return rows, cols, w

    def support(self, coarse_vertex_ids):
        """Fine vertices whose position depends on the given coarse vertices.

        Structural: a fine vertex is in the support when some chain of
        nonzero stencil weights links it to one of the vertices.

        Parameters
        ----------
        coarse_vertex_ids : int array or (n_coarse,) bool mask

        Returns
        -------
        (n_fine,) bool
        """
        ids = np.asarray(coarse_vertex_ids)
        if ids.size == 0 and ids.dtype != bool:     # ([] is float64 to NumPy)
            ids = ids.astype(np.int64)
        if ids.dtype.kind not in "biu":          # ([0.5] was vertex 0, None a TypeError)
            raise InvalidArgumentError(
                f"SubdivisionOperator.support: expected coarse vertex ids (integers) or a "
                f"({self.n_coarse},) bool mask, got {ids.dtype}")
        if ids.dtype == bool:
            if ids.shape != (self.n_coarse,):
                raise InvalidArgumentError(
                    f"SubdivisionOperator.support: mask must be ({self.n_coarse},), got {ids.shape}")
            mask = ids.copy()
        else:
            ids = ids.ravel()         # (checked before the cast: uint64 past 2**63 wrapped)
            if ids.size and (ids.min() < 0 or ids.max() >= self.n_coarse):
                raise InvalidArgumentError(
                    f"SubdivisionOperator.support: vertex ids must be in [0, {self.n_coarse}), "
                    f"got {int(ids.min())}..{int(ids.max())}")
            ids = ids.astype(np.int64)
            mask = np.zeros(self.n_coarse, dtype=bool)
            mask[ids] = True
        for S in self.stencils:
            if S.n_out == 0:
                return np.zeros(0, dtype=bool)
            hit = mask[S.cols] & (S.weights != 0)
            mask = np.add.reduceat(hit.astype(np.int64), S.indptr[:-1]) > 0
        return mask

    def fine_vertex_parent(self):
        """Where each fine vertex sits in the coarse mesh's parameter domain.

        Returns
        -------
        face : (n_fine,) int64, a coarse face containing the vertex (``-1``
            for isolated vertices).
        bary : (n_fine, 3) float64, the vertex's barycentric coordinates in
            ``F[face]`` (zeros for isolated vertices). Dyadic, hence exact.
        """
        Ff = self.F_fine.ravel()
        first = np.full(self.n_fine, Ff.shape[0], dtype=np.int64)
        np.minimum.at(first, Ff, np.arange(Ff.shape[0], dtype=np.int64))
        used = first < Ff.shape[0]
        fine_face = first[used] // 3
        bary = np.zeros((used.sum(), 3))
        bary[np.arange(bary.shape[0]), first[used] % 3] = 1.0
        g = fine_face.copy()
        for _ in range(self.levels):
            child = g % 4
            # bary (in the child) -> bary in the parent: sum_j bary_j * CHILD_BARY[child, j]
            bary = np.einsum("ij,ijk->ik", bary, _rf.CHILD_BARY[child])
            g //= 4
        face = np.full(self.n_fine, -1, dtype=np.int64)
        face[used] = g
        out = np.zeros((self.n_fine, 3))
        out[used] = bary
        return face, out


class _CSR(NamedTuple):
    rows: np.ndarray
    cols: np.ndarray
    weights: np.ndarray
    n_out: int
    n_in: int


def _merge_rows(S, n_in):
    """Canonical CSR (cols sorted in each row, repeated pairs summed, zeros dropped)."""
    if isinstance(S, _st.Stencil):
        rows, cols, w, n_out = S.rows(), S.cols, S.weights, S.n_out
    else:
        rows, cols, w, n_out = S.rows, S.cols, S.weights, S.n_out
    key = rows * np.int64(max(n_in, 1)) + cols
    uniq, inv = np.unique(key, return_inverse=True)
    wsum = np.bincount(inv.ravel(), weights=w, minlength=uniq.shape[0])
    keep = wsum != 0
    uniq, wsum = uniq[keep], wsum[keep]
    r = uniq // np.int64(max(n_in, 1))
    c = uniq % np.int64(max(n_in, 1))
    indptr = np.zeros(n_out + 1, dtype=np.int64)
    np.cumsum(np.bincount(r, minlength=n_out), out=indptr[1:])
    return indptr, c, wsum


def parametric_faces(face, bary, depth):
    """The faces ``depth`` levels finer (coarser when negative) over which the
    points at barycentric coordinates ``bary`` (k,3) of the faces ``face``
    (k,) lie parametrically: at each level the child of the 1-to-4 split
    whose triangle holds the point (child ``i`` when coordinate ``i`` is at
    least 1/2, else the middle one, 3), its coordinates taken there; going
    up, the parent (``face // 4``). The faces are an operator's levels'
    (child ``4 f + i`` of face ``f``, see the notes above), so a point of a
    coarse face is followed to the fine face it lies over in the parameter
    domain (not the closest one: the surface bulges off it).

    Returns
    -------
    (k,) int64 ndarray
    """
    if depth <= 0:
        return face // 4 ** -depth
    b = np.array(bary, dtype=np.float64)
    rows = np.arange(b.shape[0])
    for _ in range(depth):
        k = np.argmax(b, axis=1)
        corner = b[rows, k] >= 0.5
        child = np.where(corner, k, 3)
        # child i: 2 b, less 1 at i; the middle one: 1 - 2 b (CHILD_BARY inverted)
        b = np.where(corner[:, None], 2.0 * b, 1.0 - 2.0 * b)
        b[rows[corner], k[corner]] -= 1.0
        face = 4 * face + child
    return face


def check_subdivision_args(levels, scheme, where, n_faces=None, max_faces=MAX_FINE_FACES):
    """``levels`` as an int, checked with ``scheme`` for ``where`` (the public
    function the caller called, so a message names what the user called):
    :class:`InvalidArgumentError` for an unknown scheme, levels that are not
    an integer >= 0, or levels that would make more than ``max_faces``
    faces of ``n_faces`` (``levels=40`` allocated for 20 s and ran out of
    memory), or more than ``MAX_LEVELS`` when there are no faces."""
    if scheme not in SCHEMES:
        raise InvalidArgumentError(
            f"{where}: scheme must be one of {', '.join(map(repr, SCHEMES))}, got {shown(scheme)}")
    levels = check_count(levels, where=where, name="levels")
    if n_faces == 0 and levels > MAX_LEVELS:     # (no faces: no level makes one, each costs)
        raise InvalidArgumentError(
            f"{where}: levels={levels} is more than any mesh takes (at most {MAX_LEVELS}: one "
            f"triangle makes {4 ** MAX_LEVELS:,} faces)")
    room = np.log(max_faces / n_faces) / np.log(4.0) if n_faces else None   # (levels that fit)
    if room is not None and levels > room:
        made = f"{n_faces * 4.0 ** levels:.3g}" if levels < 500 else "more than 1e300"
        fits = int(np.floor(room + 1e-9))
        raise InvalidArgumentError(
            f"{where}: levels={levels} would make {made} faces of {n_faces:,} (each level "
            f"multiplies them by 4); at most {max_faces:,}"
            + (f" (levels={fits} at most for this cage)" if fits >= 0 else ""))
    return levels


def _check_ring_entries(E, n, where):
    """:class:`InvalidMeshError` naming the vertex of largest valence when
    the butterfly's ring stencils over the edges ``E`` (e,2) of ``n``
    vertices would take more than :data:`MAX_RING_ENTRIES` (Loop's do not
    grow so: each of its rows reads at most the edge's four vertices)."""
    valence = np.bincount(E.ravel(), minlength=n)
    entries = int((valence.astype(np.int64) * (valence + 1)).sum())
    if entries > MAX_RING_ENTRIES:
        v = int(np.argmax(valence))
        raise InvalidMeshError(
            f"{where}: butterfly subdivision reads a vertex's whole ring for each of its "
            f"edges, and vertex {v} has {int(valence[v]):,} edges ({entries:,} stencil entries "
            f"a level, at most {MAX_RING_ENTRIES:,}: a fan of that many triangles, as a CAD "
            f"export caps a cylinder); use scheme='loop', or split the fan first")


def _fingerprint(F, n, levels, scheme, creases):
    h = hashlib.sha1()
    h.update(f"meshadjust-subdivision-v1|{n}|{levels}|{scheme}|{F.shape[0]}|".encode())
    h.update(np.ascontiguousarray(F, dtype=np.int64).tobytes())
    h.update(b"|creases|")
    h.update(np.ascontiguousarray(creases, dtype=np.int64).tobytes())
    return h.hexdigest()


def _build(F, n, levels, scheme, creases, where):
    T = _rf.topology(F, n, np.zeros(0, dtype=np.int64), where, check=True)
    if scheme == "butterfly" and levels:
        _check_ring_entries(T.E, n, where)
    cids = _rf.crease_edge_ids(creases, T.E, n, where)
    crease_pairs = T.E[cids].copy()
    level_fn = _st.butterfly_level if scheme == "butterfly" else _st.loop_level
    stencils = []
    T = _rf.mark_sharp(T, cids)
    for lev in range(levels):
        if lev > 0:
            T_prev = T
            T = _rf.refine_topology(T_prev)
            if cids.size:
                cids = _rf.child_crease_ids(T_prev, cids, T.E, T.n)
                T = _rf.mark_sharp(T, cids)
        stencils.append(level_fn(T))
    Fl, nl = (T.F, T.n) if levels == 0 else \
        (_rf.split_faces(T.F, T.n, T.face_edge), T.n + T.E.shape[0])
    f2c = np.arange(Fl.shape[0], dtype=np.int64) // (4 ** levels)
    # (every row has an entry: reduceat's empty-row rule never applies)
    gain = float(np.prod([np.add.reduceat(np.abs(S.weights), S.indptr[:-1]).max()
                          for S in stencils if S.n_out]))
    return SubdivisionOperator(
        n_coarse=n, n_fine=nl, F_fine=Fl, fine_to_coarse_face=f2c, scheme=scheme, levels=levels,
        creases=crease_pairs, fingerprint=_fingerprint(F, n, levels, scheme, crease_pairs),
        stencils=tuple(stencils), gain=gain)


@plain_pages
def subdivision_operator(F, n_vertices, *, levels=1, scheme="butterfly", creases=None):
    """Build the coarse-to-fine subdivision operator of a triangle mesh.

    Parameters
    ----------
    F : (m, 3) int array
        Triangles of a manifold, consistently oriented mesh (several
        components, boundaries and isolated vertices are fine).
    n_vertices : int
        Number of coarse vertices (>= F.max() + 1).
    levels : int, keyword-only
        Number of 1-to-4 splits (0 gives the identity).
    scheme : {"butterfly", "loop"}, keyword-only
    creases : None or (k, 2) int array, keyword-only
        Undirected coarse edges to refine as sharp curves (boundary edges are
        always sharp).

    Returns
    -------
    SubdivisionOperator

    Raises
    ------
    InvalidMeshError
        Bad F (see ``check_mesh``), degenerate faces, a non-manifold edge or
        vertex, or faces that disagree on orientation; the message names the
        first offending edge, vertex or face.
    InvalidArgumentError
        Unknown scheme, ``levels < 0``, too many levels or vertices
        (``MAX_FINE_FACES``), or a crease that is not an edge.

    Examples
    --------
    >>> from core.subdivide import subdivision_operator
    >>> op = subdivision_operator([[0, 1, 2]], 3, levels=2, scheme="loop")
    >>> op.n_fine, op.F_fine.shape
    (15, (16, 3))
    """
    where = "subdivision_operator"
    levels = check_subdivision_args(levels, scheme, where)
    n = check_count(n_vertices, where=where, name="n_vertices")
    if n > MAX_FINE_FACES:    # (NumPy's 'array is too big', an OverflowError or a MemoryError)
        raise InvalidArgumentError(
            f"{where}: n_vertices={n} is more than a subdivision may hold (at most "
            f"{MAX_FINE_FACES:,})")
    F = check_faces(F, n, where=where)
    check_subdivision_args(levels, scheme, where, F.shape[0])
    return _build(F, n, levels, scheme, creases, where)


def cage_operator(F_cage, n_cage, *, where, levels, scheme, creases):
    """:func:`subdivision_operator` of a cage for the public function
    ``where`` (``bind``, ``fit_cage``): its refusals (a non-manifold or
    inconsistently oriented cage, a crease that is no edge) name ``where``
    and ``F_cage``, not ``subdivision_operator``, which the caller never
    called."""
    try:
        return subdivision_operator(F_cage, n_cage, levels=levels, scheme=scheme, creases=creases)
    except (InvalidMeshError, InvalidArgumentError) as exc:
        msg = str(exc)
        head = "subdivision_operator: "
        if not msg.startswith(head):
            raise
        raise type(exc)(f"{where}: the cage (F_cage): {msg[len(head):]}") from None


@plain_pages
def subdivide(V, F, *, levels=1, scheme="butterfly", creases=None):
    """Subdivide a triangle mesh with the modified butterfly or Loop scheme.

    Parameters
    ----------
    V : (n, 3) float array
    F : (m, 3) int array, a manifold, consistently oriented triangle mesh.
    levels : int, keyword-only, number of 1-to-4 splits (>= 0).
    scheme : {"butterfly", "loop"}, keyword-only
    creases : None or (k, 2) int array of coarse edges kept sharp, keyword-only

    Returns
    -------
    SubdivisionResult
        ``V`` (n + ..., 3) float64 and ``F`` (m * 4**levels, 3) int64; see
        the module docstring for the numbering.

    Raises
    ------
    InvalidMeshError, InvalidArgumentError
        As :func:`subdivision_operator`.

    Examples
    --------
    >>> import numpy as np
    >>> from core.subdivide import subdivide
    >>> V = np.array([[0., 0, 0], [1, 0, 0], [0, 1, 0]])
    >>> Vf, Ff = subdivide(V, [[0, 1, 2]], levels=1)
    >>> Vf.shape, Ff.shape
    ((6, 3), (4, 3))
    """
    where = "subdivide"
    levels = check_subdivision_args(levels, scheme, where)
    V, F = check_mesh(V, F, where=where)
    check_subdivision_args(levels, scheme, where, F.shape[0])
    op = _build(F, V.shape[0], levels, scheme, creases, where)
    return SubdivisionResult(op._within_floats(V, False, where, "positions", InvalidMeshError),
                             op.F_fine)
