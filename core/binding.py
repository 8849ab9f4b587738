"""Bind a dense mesh to a cage's subdivision surface, deform it, refine with detail.

The dense mesh rides on the subdivided cage as a displacement field expressed
in local frames (Botsch & Kobbelt, "Multiresolution surface representation
based on displacement volumes", 2003; Zorin, Schroeder & Sweldens,
"Interactive multiresolution mesh editing", 1997)::

    bind:    S = subdivision_operator(F_cage)        (linear: Vf = S @ Vc)
             for each dense vertex x:
                 (f, beta) = closest point of x on the fine surface (Vf, S.F_fine)
                 p = sum_k beta_k Vf[F_fine[f, k]]
                 n = normalize(sum_k beta_k N[F_fine[f, k]])    N: fine vertex normals
                 t = normalize(e - (e.n) n),  e = Vf[F_fine[f,1]] - Vf[F_fine[f,0]]
                 b = n x t
                 offset = ((x-p).t, (x-p).b, (x-p).n)
    deform:  Vf' = S @ Vc',  rebuild (p, t, b, n) from Vf' at the same (f, beta),
             x' = p + offset_0 t + offset_1 b + offset_2 n

Every quantity that does not depend on positions (the operator, the corner
indices of each bound face, transposed to a (3, q) layout so every step runs
on contiguous rows) is cached in the :class:`Binding`, so a re-deform is a
handful of gathers and elementwise operations (about 0.2 s for 1M vertices).
The binding's arrays are meant to be read-only: the cache is built from them.

The same frames carry the detail for :func:`refine`: each fine vertex is seen
as the corner of its first incident fine face (barycentric coordinates a unit
vector), its frame is built exactly like a dense vertex's, and the offset to
the dense surface is stored in it: the closest point (an index over the dense
mesh), or for very large dense meshes a point found by a local search
around the bound dense vertices (no index: see :func:`.detail_search.dense_points_near`).

Incremental deform (``deform(b, V, moved=ids, out=D)``, for live editing):
the dependency chain cage vertex -> fine positions (the operator's support)
-> fine normals (one fine ring) -> fine faces -> bound dense vertices is
followed on index sets of the fine mesh (a fine face -> dense vertices index
built on first use). Every deform keeps the subdivided cage it computed
(each level's positions and the fine normals); an incremental one
recomputes there only the positions and normals that change, and only those
dense rows: the cost is proportional to what moves, not to the dense or
the fine mesh.

Fold repair: where the cage is locally fine and an edit lifts a vertex
against an unmoved neighbour, a thin dense face standing across the slope
can turn over (the surface's map itself folds it, with or without the
detail); :mod:`.unfold` finds such faces after each deform and relaxes their
neighbourhood to its rest shape (see there).

Properties (tested): ``deform(bind(D, C), C) == D`` to rounding; a rigid motion
of the cage moves the dense mesh rigidly; moving one cage vertex moves only the
dense vertices returned by :meth:`Binding.affected` (bit-for-bit elsewhere,
unless the fold repair changed rows, which it lists);
an incremental deform equals the full one bit for bit.
"""

import threading
import weakref
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import NamedTuple

import numpy as np

from .detail_search import (DetailSurface, dense_points_near, detail_surface, exact_detail_index,
                            is_unwelded)
from .errors import CancelledError, InvalidArgumentError, InvalidMeshError, TopologyMismatchError
from .mesh import (area_normals_t, bounding_box, check_faces, check_mesh, check_number,
                   check_units, check_vertices, cross_columns, cross_rows, dot_columns, row_norms,
                   row_sums, shown, stops, UNITS)
from .near_query import NearQuery
from .spatial import TriangleIndex
from ._refine import crease_pairs
from .subdivide import (MAX_BOUND_FINE_FACES, cage_operator, check_subdivision_args,
                        parametric_faces, subdivision_operator)
from ._face_tracker import faces_across
from .topology import check_not_soup
from .unfold import (CageRings, Copies, FaceBatch, FaceStars, FineFaceGroups, Repair, away_rows,
                     nearest_rotations, repair, rest_normals, ring_linear_maps, ring_rotations,
                     turned_over)
from ._groups import distinct, ragged_entries, sorted_unique, stable_argsort
from ._parallel import WORKERS, blocks, each_in_order, in_background, run_blocks, run_each
from .pages import plain_pages

#: relative length under which a normal or tangent counts as degenerate
_DEGENERATE = 1e-12

#: a fine vertex normal (the sum of its faces' area normals) shorter than this share of
#: the square of the rest cage's size (the power of two above its extent) is none: the
#: faces around the vertex have no area (a cage vertex moved onto a neighbour folds its
#: fine faces flat) and the sum is rounding noise, whose direction fine positions 1e-16
#: apart draw at random (a cube's cage, a vertex dragged onto its neighbour: 0.10 of the
#: diagonal between two deforms of one edit); a real fine vertex's faces are some 1e5
#: times larger even at five levels of a 10k-face cage (a cage shrunk below about a
#: thousandth of its rest size falls under it: its frames take the fine faces' normals)
_NORMAL_FLOOR = 2.0 ** -40

#: a fine vertex whose faces fold back onto each other at rest (the sum of their area
#: normals at most this share of their lengths' sum: two faces within about a degree of
#: back to back, a fin of the cage's surface) has no normal in the binding's frames
#: (:func:`_rest_folds`): its direction is what is left of sums that cancel, which a
#: rounding step of the positions turns (the jittered fandisk's 100-face cage symmetric in
#: Z, rotated as a whole: rows 1.4e-6 of the diagonal off the rotated scan, 9.6e-11 on its
#: 400-face cage symmetric in X). Over the shared meshes' cages (50 to 2,000 faces, and
#: symmetric ones), two levels of either scheme, the smallest share away from such folds
#: was 0.014
_NORMAL_CANCEL = 1e-2

#: dense meshes up to this many faces get an exact spatial index for the
#: refine detail (``detail_search="auto"``); larger ones the local search. The
#: scan's own index is built on one thread: bumpy tori of 200k and 500k faces
#: (2,000-face cages, two levels) bound in 0.43 / 1.07 s with it and 0.24 / 0.49 s
#: with the local search on the cleaned scan, the refine's mean and Hausdorff
#: distance to the scan the same to 4 digits; over 29 cases of the shared meshes and
#: messy bunnies (up to 70k faces) the local search gave a mean distance 1.2% and a
#: Hausdorff 1.7% smaller (geometric means; the worst 1.33x / 1.02x) in 1.04x the
#: time (2026-12-06)
_EXACT_DETAIL_FACES = 100_000

#: the local search looks on the cleaned scan (welded, no debris, no sheets: as the
#: exact one) up to this many faces, and on an unwelded scan at any size; a larger
#: welded scan is searched as it is (cleaning a 2M-face scan was 60% of its bind; far
#: debris is kept off by dense_points_near)
_CLEAN_LOCAL_FACES = 500_000
_DETAIL_SEARCHES = ("auto", "exact", "local")

#: dense vertices per block of the bind's dense pass (closest points, offsets; one
#: worker-thread task; 16 blocks for 1M vertices keep the two threads evenly busy)
_BIND_BLOCK = 65_536

#: an edited cage counts as the rest cage mirrored when the least-squares linear map
#: between them has a negative determinant of at least this share of the volume a
#: conformal map of its size has (a mirror: all of it; a flattening: little)
_MIRROR_CONDITION = 0.25
#: the mirror the repair's maps of a mirrored cage start from (any one would do)
_MIRROR = np.array([-1.0, 1.0, 1.0])

#: the fewest points a block of the bind's passes takes: fewer than 4 ``_BIND_BLOCK``
#: are cut in 4 blocks (of at least this), so that both threads work on a 36k-vertex scan
#: and on a 2,000-face cage's 16k fine vertices (one block each: one thread)
_MIN_BIND_BLOCK = 4_096

#: above this many levels, the bind's query is told how far the dense vertices lie
#: from the fine surface (:func:`_typical_distance`, measured on the surface this many
#: levels down): a fine mesh as dense as the scan has cells smaller than the scan's
#: distance to it, and its query slows down 2-2.5x (NearQuery's ``reach``)
_REACH_LEVELS = 2

#: dense faces (or vertices) sampled (evenly by index) for :func:`_typical_distance`
_REACH_SAMPLES = 4096

#: dense rows per block of a deform's frame rebuild, full or incremental (bounds the
#: temporaries: (3, 16384) float64 is 384 KiB; a full deform of 1M rows at once made
#: five fresh (3, n) arrays: 90 ms against 61 in blocks, 2026-12-03)
_ROW_BLOCK = 16_384

#: from this many rows an incremental deform rebuilds them in a block per worker
#: thread at least (bunny x16, two levels, 5 scattered cage vertices: 24k-36k rows,
#: the whole deform 2.85 / 3.68 / 4.09 -> 2.54 / 3.34 / 3.75 ms, 2026-12-05)
_THREADED_ROWS = 8192


#: serialises incremental deforms (they share scratch tables in the binding's
#: cache; a module lock, not one per binding, so a Binding stays picklable)
_INCREMENTAL_LOCK = threading.RLock()

#: per binding, the fold repair made in each array a deform wrote: {id(array): (weak
#: reference to it, Repair)} (outside the binding's cache, which stays picklable)
_REPAIRS = weakref.WeakKeyDictionary()

#: a full deform tests every dense face for the fold repair when more than this
#: share of the cage moved from rest (else the faces around what those vertices move)
_REPAIR_ALL_SHARE = 0.25

#: the fold test goes by fine face groups when the fine mesh has at most this share of
#: the dense faces (see _away_around)
_GROUPS_SHARE = 0.25

#: a drag's gathers (the faces around its rows with their corners and rest normals, about
#: 28 bytes a face; its rows' barycentric coordinates and offsets, 48 a row) are kept for
#: its next steps up to this many bytes each (the bunny x16's 5 moved cage vertices:
#: 52k faces, 1.5 MB, and 33k rows, 1.6 MB; a million faces around the rows of a third
#: of the cage, 28 MB)
_KEPT_BATCH_BYTES = 1 << 25

#: bind_refined takes its seeds from a binding at this many levels or more (from a
#: coarser one the faces taken down the levels are too far off the closest ones: a 60-face
#: cage's binding at 0 levels to 3 gave bind's points for 94% of the fine vertices); below,
#: it binds the dense vertices again. A caller binding only to refine at more levels binds
#: at these first (the batch's refined output)
SEED_LEVELS = 2

#: keys of :meth:`Binding.to_arrays`
_ARRAY_KEYS = ("fine_face", "bary", "offset", "fine_detail", "F_cage", "n_cage", "levels",
               "scheme", "creases", "fingerprint")
#: the optional keys of :meth:`Binding.to_arrays` (the fold repair's)
_REPAIR_KEYS = ("F_dense", "V_cage_rest")
#: the array fields of a :class:`Binding` (held as read-only views)
_VIEWED_KEYS = ("fine_face", "bary", "offset", "fine_detail", "F_cage", "creases", "F_dense",
                "V_cage_rest")


class Frames(NamedTuple):
    """Points on the fine surface and their orthonormal frames, each (q,3)."""

    point: np.ndarray     #: position on the fine surface
    tangent: np.ndarray   #: unit tangent (face's first edge projected)
    bitangent: np.ndarray  #: normal x tangent
    normal: np.ndarray    #: unit normal (interpolated vertex normals)


class RefineResult(NamedTuple):
    """Subdivided edited cage carrying the dense mesh's detail."""

    V: np.ndarray  #: (n_fine,3) float64
    F: np.ndarray  #: (m_fine,3) int64, the operator's ``F_fine``


@dataclass(frozen=True, eq=False)
class Binding:
    """A dense mesh bound to a cage's subdivision surface (plain arrays).

    Per dense vertex ``i``: ``fine_face[i]`` (face of the subdivided cage),
    ``bary[i]`` (barycentric coordinates in ``F_fine[fine_face[i]]``) and
    ``offset[i]`` (tangent, bitangent, normal components of the displacement).
    Per fine vertex ``j``: ``fine_detail[j]``, the frame components of the
    offset from fine vertex ``j`` to the dense surface (used by :func:`refine`).

    The cage topology (``F_cage``, ``n_cage``), ``levels``, ``scheme`` and
    ``creases`` rebuild the subdivision operator; ``fingerprint`` is that
    operator's fingerprint. The operator and the corner indices are cached
    (private, built once per binding).
    """

    fine_face: np.ndarray    #: (n_dense,) int64
    bary: np.ndarray         #: (n_dense,3) float64
    offset: np.ndarray       #: (n_dense,3) float64, (tangent, bitangent, normal) components
    fine_detail: np.ndarray  #: (n_fine,3) float64, same convention, per fine vertex
    F_cage: np.ndarray       #: (m_cage,3) int64
    n_cage: int
    levels: int
    scheme: str
    creases: object          #: None or (k,2) int64 coarse vertex pairs
    fingerprint: str
    #: the dense triangles and the cage bound to (None: bound without them); with
    #: both, deform repairs the dense faces an edit turns over (:mod:`.unfold`)
    F_dense: object = None   #: None or (m_dense,3) int64
    V_cage_rest: object = None  #: None or (n_cage,3) float64
    _operator: object = field(default=None, repr=False, compare=False)
    _cache: dict = field(default=None, repr=False, compare=False)
    #: what the cache and operator were made for: (the operator's arrays' identities and
    #: counts, every array's identity, the fingerprint)
    _owner: tuple = field(default=None, repr=False, compare=False)

    def __post_init__(self):
        # the arrays as read-only views: a deform told to write into one (out=b.offset,
        # C-contiguous after from_arrays) rewrote the binding itself, and every later
        # deform and to_arrays with it
        for key in _VIEWED_KEYS:
            value = getattr(self, key)
            if isinstance(value, np.ndarray) and value.flags.writeable:
                value = value.view()
                value.flags.writeable = False
                object.__setattr__(self, key, value)
        # a cache and operator handed over from another binding (dataclasses.replace
        # passes them) are kept only for the same arrays and counts: replace(b,
        # offset=...) had deformed with the old offsets, replace(b, levels=3) with the
        # old operator
        # (what the operator is made of first: F_cage, creases and the counts)
        made_of = (id(self.F_cage), id(self.creases), self.n_cage, self.levels, self.scheme)
        owner = (made_of, tuple(id(getattr(self, key)) for key in _VIEWED_KEYS),
                 self.fingerprint)
        given = self._owner
        if given is not None and given != owner:
            object.__setattr__(self, "_cache", None)
            if given[0] != made_of:
                object.__setattr__(self, "_operator", None)
        op = self._operator
        if op is None:
            op = subdivision_operator(self.F_cage, self.n_cage, levels=self.levels,
                                      scheme=self.scheme, creases=self.creases)
            object.__setattr__(self, "_operator", op)
        if op.fingerprint != self.fingerprint:
            raise TopologyMismatchError(
                f"Binding: the cage topology does not match the binding's fingerprint "
                f"(stored {self.fingerprint!r}, rebuilt {op.fingerprint!r})")
        m_fine = op.F_fine.shape[0]
        if self.fine_face.size and (self.fine_face.min() < 0 or self.fine_face.max() >= m_fine):
            raise InvalidArgumentError(
                f"Binding: fine_face must index the {m_fine} fine faces, got values in "
                f"[{self.fine_face.min()}, {self.fine_face.max()}]")
        if self.fine_detail.shape != (op.n_fine, 3):
            raise InvalidArgumentError(
                f"Binding: fine_detail must be ({op.n_fine}, 3), got {self.fine_detail.shape}")
        if self.F_dense is not None and self.F_dense.size and (
                self.F_dense.min() < 0 or self.F_dense.max() >= self.n_dense):
            raise InvalidArgumentError(
                f"Binding: F_dense must index the {self.n_dense} dense vertices, got values in "
                f"[{self.F_dense.min()}, {self.F_dense.max()}]")
        if self.V_cage_rest is not None and self.V_cage_rest.shape != (self.n_cage, 3):
            raise InvalidArgumentError(
                f"Binding: V_cage_rest must be ({self.n_cage}, 3), got {self.V_cage_rest.shape}")
        if self._cache is None:
            # everything deform / refine need that does not depend on positions,
            # transposed to (3, q) so every operation runs on contiguous rows
            d_face, d_bary = _vertex_corners(op.F_fine, op.n_fine)
            FfT = np.ascontiguousarray(op.F_fine.T)   # (F_fine[face].T made contiguous: 30x)
            object.__setattr__(self, "_cache", {
                "corners_t": np.take(FfT, self.fine_face, axis=1),
                "bary_t": np.ascontiguousarray(self.bary.T),
                "offset_t": np.ascontiguousarray(self.offset.T),
                "detail_corners_t": np.take(FfT, d_face, axis=1),
                "detail_bary_t": np.ascontiguousarray(d_bary.T),
                "detail_offset_t": np.ascontiguousarray(self.fine_detail.T),
            })
        object.__setattr__(self, "_owner", owner)

    @property
    def operator(self):
        """The cached :class:`~.subdivide.SubdivisionOperator`."""
        return self._operator

    @property
    def n_dense(self):
        """Number of bound dense vertices."""
        return int(self.fine_face.shape[0])

    def to_arrays(self):
        """The binding as a dict of NumPy arrays and small scalars.

        Keys: ``fine_face`` (n_dense,) int64, ``bary`` (n_dense,3) float64,
        ``offset`` (n_dense,3) float64, ``fine_detail`` (n_fine,3) float64,
        ``F_cage`` (m,3) int64, ``creases`` (k,2) int64 (k = 0 for none), and the
        scalars ``n_cage``, ``levels``, ``scheme``, ``fingerprint``; and when
        the binding has them, ``F_dense`` (m_dense,3) int64 and
        ``V_cage_rest`` (n_cage,3) float64 (the fold repair's). Arrays are
        copies (writable). :meth:`from_arrays` accepts them back, also as
        int32/float32.
        """
        creases = np.zeros((0, 2), np.int64) if self.creases is None else self.creases.copy()
        arrays = {"fine_face": self.fine_face.copy(), "bary": self.bary.copy(),
                  "offset": self.offset.copy(), "fine_detail": self.fine_detail.copy(),
                  "F_cage": self.F_cage.copy(), "n_cage": int(self.n_cage),
                  "levels": int(self.levels), "scheme": str(self.scheme), "creases": creases,
                  "fingerprint": str(self.fingerprint)}
        for key in _REPAIR_KEYS:
            if getattr(self, key) is not None:
                arrays[key] = getattr(self, key).copy()
        return arrays

    @classmethod
    def from_arrays(cls, arrays):
        """Rebuild a :class:`Binding` from :meth:`to_arrays` output. The
        binding keeps copies: changing the arrays given afterwards changes
        nothing in it.

        Raises
        ------
        InvalidArgumentError
            A key is missing, an array has the wrong shape or kind (indices
            must be integers, the others real numbers), or a value is NaN or
            infinite.
        InvalidMeshError
            ``V_cage_rest`` beyond the units deform takes (``core.mesh.UNITS``).
        TopologyMismatchError
            The stored fingerprint does not match the rebuilt operator's.
        """
        if not isinstance(arrays, Mapping):
            raise InvalidArgumentError(
                f"Binding.from_arrays: arrays must be a mapping of names to arrays (what "
                f"Binding.to_arrays gives, or an np.load of it), got {type(arrays).__name__}")
        missing = [k for k in _ARRAY_KEYS if k not in arrays]
        if missing:
            raise InvalidArgumentError(f"Binding.from_arrays: missing keys {missing}")
        # copies, checked (np.asarray had kept the caller's float64 arrays, so a buffer
        # reused after loading, e.g. the rest cage, moved the binding's rest; a NaN offset
        # deformed to NaN, a float index was truncated, a ragged array was NumPy's
        # ValueError)
        fine_face = _stored(arrays, "fine_face", 1)
        n = fine_face.shape[0]
        bary = _stored(arrays, "bary", 3)
        offset = _stored(arrays, "offset", 3)
        if bary.shape[0] != n or offset.shape[0] != n:
            raise InvalidArgumentError(
                f"Binding.from_arrays: fine_face, bary and offset must have one row per dense "
                f"vertex, got {n}, {bary.shape[0]}, {offset.shape[0]}")
        creases = np.zeros((0, 2), np.int64) if arrays["creases"] is None \
            else _stored(arrays, "creases", 2)
        rest = None if arrays.get("V_cage_rest") is None else _stored(arrays, "V_cage_rest", 3)
        if rest is not None:
            check_units(rest, where="Binding.from_arrays", name="V_cage_rest")
        # the counts as integers ('x' and None were ValueErrors from int(); a 0-d array, as
        # np.load gives them, is one)
        n_cage, levels = (check_number(np.asarray(arrays[k]).item() if np.ndim(arrays[k]) == 0
                                       else arrays[k], where="Binding.from_arrays", name=k,
                                       lo=0, integer=True) for k in ("n_cage", "levels"))
        return cls(fine_face=fine_face, bary=bary, offset=offset,
                   fine_detail=_stored(arrays, "fine_detail", 3),
                   F_cage=_stored(arrays, "F_cage", 3), n_cage=n_cage, levels=levels,
                   scheme=str(arrays["scheme"]), creases=creases if creases.shape[0] else None,
                   fingerprint=str(arrays["fingerprint"]),
                   F_dense=None if arrays.get("F_dense") is None
                   else _stored(arrays, "F_dense", 3),
                   V_cage_rest=rest)

    def affected(self, cage_vertex_ids):
        """Dense vertices that may move when the given cage vertices move.

        A dense vertex depends on the positions and vertex normals of its
        fine face's corners; a fine vertex normal depends on the faces around
        it. So: fine vertices in the operator's support, then every corner of
        a fine face touching them, then the dense vertices bound to a face with
        such a corner. All other dense vertices stay bit-for-bit.

        Returns
        -------
        (n_dense,) bool ndarray
        """
        op = self._operator
        # checked as influenced() checks them ([3.7] was vertex 3, "3" was taken)
        moved = op.support(_check_moved(self, cage_vertex_ids, "Binding.affected"))
        touched = moved[op.F_fine].any(axis=1)
        normal_changed = np.zeros(op.n_fine, dtype=bool)
        normal_changed[op.F_fine[touched].ravel()] = True
        return normal_changed[self._cache["corners_t"]].any(axis=0)

    def repaired(self, D):
        """The dense vertices the fold repair moved in ``D``, an array
        :func:`deform` returned or wrote (sorted; empty when nothing turned
        over, for any other array, or when the binding has no ``F_dense`` /
        ``V_cage_rest``). An incremental deform into ``D`` may rewrite the
        rows of its repair before as well as its own: a caller copying only
        the changed rows takes :meth:`influenced`, this before the deform
        and this after.

        Returns
        -------
        (k,) int64 ndarray (a copy)
        """
        with _INCREMENTAL_LOCK:
            return _repair_of(self, D).rows.copy()

    def influenced(self, cage_vertex_ids, *, ordered=True):
        """The dense vertices an incremental :func:`deform` recomputes when
        the given cage vertices move (a subset of :meth:`affected`, found
        without touching the dense mesh: O(fine support + result)).

        The first call (also with an empty list) builds the indices the
        incremental deform uses (fine face -> dense vertices, fine vertex ->
        fine faces, each level's stencil transposed, and the fold repair's
        faces around the dense vertices), so a caller can pay for them up
        front.

        Parameters
        ----------
        cage_vertex_ids : (k,) int, duplicates allowed
        ordered : bool, keyword-only
            Sort the result (the default). False returns the same rows
            grouped by the fine face they are bound to, faces ascending (no
            sort: about 1 ms less for 25k rows; a live update that copies
            the rows needs no order).

        Returns
        -------
        (r,) int64 ndarray, distinct (sorted when ``ordered``)

        Raises
        ------
        InvalidArgumentError
            An index is out of range or not an integer.
        """
        ids = _check_moved(self, cage_vertex_ids, "Binding.influenced")
        _incremental_index(self)            # built on first use, also for an empty list
        _repair_index(self)
        if ids.size == 0:
            return np.zeros(0, dtype=np.int64)
        with _INCREMENTAL_LOCK:
            rows = _influenced_dense(self, ids).rows
        return np.sort(rows) if ordered else rows.copy()

    def rest_as_a_whole(self, V_cage):
        """The rest cage (centred) taken by the linear map that best takes it
        to ``V_cage`` as a whole (least squares about the centroids; the map
        :func:`deform` finds a mirrored cage by), so that a cage mirrored,
        turned or scaled as a whole turns no face of it over by that alone
        (``core.turned_faces(b.rest_as_a_whole(V), V, F)``); the rest cage
        itself for a flat one, None without one.

        Returns
        -------
        (n_cage,3) float64 ndarray or None

        Raises
        ------
        TopologyMismatchError
            ``V_cage`` has another vertex count than the bound cage.
        InvalidMeshError
            ``V_cage`` is not (n,3) finite numbers.
        """
        Vc = _check_cage(self, V_cage, None, "Binding.rest_as_a_whole")
        if self.V_cage_rest is None:
            return None
        M = _rest_map(self, Vc)
        if M is None:
            return self.V_cage_rest
        return _rest_moments(self)[0] @ M.T

    def refined_rows(self, cage_vertex_ids):
        """The fine vertices an incremental :func:`refine` recomputes when
        the given cage vertices move (the rows of its ``V`` that may change;
        found without touching the whole fine mesh). The first call (also
        with an empty list) builds the indices the incremental refine uses.

        Parameters
        ----------
        cage_vertex_ids : (k,) int, duplicates allowed

        Returns
        -------
        (r,) int64 ndarray, distinct and ascending

        Raises
        ------
        InvalidArgumentError
            An index is out of range or not an integer.
        """
        ids = _check_moved(self, cage_vertex_ids, "Binding.refined_rows")
        with _INCREMENTAL_LOCK:
            _incremental_index(self)
            if ids.size == 0:
                return np.zeros(0, dtype=np.int64)
            return _influenced_fine(self, ids).rows.copy()


def _stored(arrays, key, cols):
    """``arrays[key]`` for :meth:`Binding.from_arrays`: a new C-contiguous int64
    (the index keys) or float64 array of ``cols`` columns (1: flat), checked:
    integers for indices (not booleans or floats), finite real numbers for the
    rest; :class:`InvalidArgumentError` naming the key otherwise."""
    where = "Binding.from_arrays"
    integer = key in ("fine_face", "F_cage", "creases", "F_dense")
    a = np.asarray(arrays[key])
    if a.dtype.kind not in ("iu" if integer else "iuf"):
        raise InvalidArgumentError(
            f"{where}: {key} must be {'integer indices' if integer else 'real numbers'}, got "
            f"{a.dtype}")
    if a.size % cols or (cols > 1 and a.ndim == 2 and a.shape[1] != cols):
        raise InvalidArgumentError(f"{where}: {key} must have {cols} columns, got {a.shape}")
    if integer and a.dtype.kind == "u" and a.size and int(a.max()) > np.iinfo(np.int64).max:
        raise InvalidArgumentError(f"{where}: {key} holds an index {int(a.max())} out of range")
    out = a.astype(np.int64 if integer else np.float64).reshape((-1, cols) if cols > 1 else -1)
    if not integer and not np.isfinite(out).all():
        row = int(np.flatnonzero(~np.isfinite(out).reshape(out.shape[0], -1).all(axis=1))[0])
        raise InvalidArgumentError(
            f"{where}: {key} has NaN or infinite values, e.g. row {row} = {out[row].tolist()}")
    if key in ("offset", "fine_detail") and out.size and float(np.abs(out).max()) > UNITS[1]:
        raise InvalidArgumentError(
            f"{where}: {key} reaches {float(np.abs(out).max()):.3g}; deform takes coordinates "
            f"up to {UNITS[1]:g}")
    return out


@plain_pages
def bind(V_dense, F_dense, V_cage, F_cage, *, levels=2, scheme="butterfly", creases=None,
         detail_search="auto", progress=None):
    """Bind a dense mesh to the subdivision surface of a cage.

    Parameters
    ----------
    V_dense : (n,3) float
        Dense vertex positions (the mesh that keeps its topology, UVs, ...).
    F_dense : (m,3) int
        Dense triangles; used to carry the detail for :func:`refine`.
    V_cage, F_cage : (n_c,3) float, (m_c,3) int
        The cage (usually :func:`fit_cage`'s positions).
    levels : int
        Subdivision levels (>= 0; at most ``core.subdivide.MAX_BOUND_FINE_FACES``
        fine faces, about 1 KB of memory each).
    scheme : str
        ``"butterfly"`` or ``"loop"`` (whatever ``subdivision_operator`` accepts).
    creases : None or (k,2) int
        Cage edges refined as sharp curves.
    detail_search : {"auto", "exact", "local"}
        How the refine detail (the dense surface point of each fine vertex)
        is found, both on the dense mesh cleaned (welded, without debris):
        ``"exact"`` builds a :class:`~.spatial.TriangleIndex` over it (the
        closest point); ``"local"`` searches around the dense vertices
        bound near each fine vertex, without an index (for
        very large meshes: the closest point for about 99.5% of fine
        vertices, a farther point of the dense surface for the rest);
        ``"auto"`` is exact up to 100,000 dense faces. The local search
        looks on the cleaned dense mesh up to 500,000 faces (and on an
        unwelded one at any size); a larger welded one as it is.
    progress : callable(float) -> bool or None, optional
        Called with the fraction done (0..1) between blocks of the
        closest-point searches (from the calling thread); returning False
        stops the bind with :class:`~.errors.CancelledError`.

    Returns
    -------
    Binding

    Raises
    ------
    InvalidMeshError
        A mesh is malformed or the cage has no faces.
    CancelledError
        ``progress`` returned False.

    Examples
    --------
    >>> b = bind(V_dense, F_dense, V_cage, F_cage, levels=2)          # doctest: +SKIP
    >>> np.allclose(deform(b, V_cage), V_dense)                       # doctest: +SKIP
    True
    """
    F_in = F_dense
    # V_dense is only read: not copied (24 MB at 1M vertices); the binding keeps its own F_dense
    V_dense, F_dense = check_mesh(V_dense, F_dense, where="bind", names=("V_dense", "F_dense"),
                                  copy=False)
    shared = isinstance(F_in, np.ndarray) and np.may_share_memory(F_dense, F_in)
    V_cage, F_cage = check_mesh(V_cage, F_cage, where="bind", names=("V_cage", "F_cage"),
                                allow_empty=False)
    check_not_soup(F_cage, V_cage.shape[0], F_dense, V_dense.shape[0], "bind")
    check_units(V_dense, where="bind", name="V_dense")
    check_units(V_cage, where="bind", name="V_cage")
    creases = _normalise_creases(creases, "bind")
    if detail_search not in _DETAIL_SEARCHES:
        raise InvalidArgumentError(
            f"bind: detail_search must be one of {_DETAIL_SEARCHES}, got {shown(detail_search)}")
    if progress is not None and not callable(progress):
        raise InvalidArgumentError(f"bind: progress must be callable or None, got {type(progress)}")
    check_subdivision_args(levels, scheme, "bind", F_cage.shape[0], max_faces=MAX_BOUND_FINE_FACES)
    detail = _detail_mode(detail_search, F_dense)
    # everything relative to the origin deform takes for this cage (_working_origin)
    origin, step = _origin_and_step(V_cage)
    # beside the cage's subdivision (one thread; 0.5 s at five levels of a 2,000-face cage)
    aside = in_background(lambda: _faces_aside(F_dense, V_dense.shape[0], shared,
                                               detail == "local"))
    typical = in_background(lambda: _typical_distance(V_dense, F_dense, V_cage, F_cage, scheme,
                                                      creases, origin)) \
        if levels > _REACH_LEVELS else None
    op = cage_operator(F_cage, V_cage.shape[0], where="bind", levels=levels, scheme=scheme,
                       creases=creases)
    shifted = bool(origin.any())
    Vf = op.apply(V_cage - origin)
    VfT = np.ascontiguousarray(Vf.T)
    NfT, folds = _normals_and_folds(VfT, op.F_fine, _normal_floor(step))
    F_own, degree = aside.result()
    reach = typical.result() if typical is not None else None
    # the fine faces at each fine edge and vertex and the fine vertices' frames (one thread;
    # 1.1 s at five levels), made beside the fine surface's index, which leaves a core idle
    # part of the time
    fine = in_background(lambda: _fine_vertex_parts(op, VfT, NfT, detail is not None))
    query, surface, dense_index = _searches(V_dense, F_dense, Vf, op, detail, degree, reach,
                                            origin if shifted else None)
    ties, d_face, d_bary, vfr = fine.result()
    near = _near_search(surface, degree, vfr.point) if surface is not None else None
    try:
        dense = _bind_dense(query, V_dense, VfT, NfT, op.F_fine, ties,
                            _reporter(progress, 0.05, 0.6), near, origin if shifted else None)
    except BaseException:
        if dense_index is not None:
            dense_index.cancel()            # (not started yet: dropped; else it finishes unread)
        raise
    fine_detail = _fine_detail(detail, op, vfr, reach, index=dense_index,
                               surface=surface, nearest=dense.nearest,
                               report=_reporter(progress, 0.65, 0.95))
    return Binding(fine_face=dense.face, bary=dense.bary_t.T, offset=dense.offset_t.T,
                   fine_detail=fine_detail, F_cage=F_cage, n_cage=int(V_cage.shape[0]),
                   levels=int(levels), scheme=str(scheme), creases=creases,
                   fingerprint=op.fingerprint, F_dense=F_own, V_cage_rest=V_cage,
                   _operator=op,
                   _cache=_binding_cache(dense, op.F_fine, d_face, d_bary, fine_detail, folds))


def _searches(V_dense, F_dense, Vf, op, detail, degree, reach, origin):
    """The searches :func:`bind` makes: ``(query, surface, dense_index)``,
    the fine surface's :class:`~.near_query.NearQuery` (``Vf``, ``op.F_fine``;
    queries at about ``reach``), and for the ``detail`` search the dense
    mesh's cleaned surface (``"local"``: :func:`_local_surface`, else None)
    or its index (``"exact"``: started on a worker thread, else None).
    ``origin``: the fine surface's, or None (at the origin already)."""
    surface = dense_index = None
    if detail == "exact":
        # the dense mesh's index (on one thread: 0.4 of a 0.6 s bind of a 100k-vertex scan)
        # is not needed before the dense vertices are bound: built beside that work
        dense_index = in_background(
            lambda: exact_detail_index(V_dense - origin if origin is not None else V_dense,
                                       F_dense, op.n_fine))
        query = NearQuery(Vf, op.F_fine, reach=reach)
    elif detail == "local" and _cleans_local(F_dense, V_dense.shape[0], degree):
        # made beside the index
        query, surface = run_each(lambda build: build(), [
            lambda: NearQuery(Vf, op.F_fine, reach=reach),
            lambda: _local_surface(V_dense, F_dense, origin, True)])
    elif detail == "local":
        # the index built on both threads
        query = NearQuery(Vf, op.F_fine, reach=reach)
        surface = _local_surface(V_dense, F_dense, origin, False)
    else:
        query = NearQuery(Vf, op.F_fine, reach=reach)      # halves on the threads
    return query, surface, dense_index


def bind_refined(binding, V_dense, levels, *, V_cage=None, detail_search="auto",
                 progress=None):
    """The binding :func:`refine` needs to refine the cage of ``binding`` at
    other ``levels``: the same dense mesh's detail at those levels, found
    from ``binding`` instead of binding every dense vertex again.

    :func:`bind` at ``levels`` spends most of its time binding each dense
    vertex to the finer surface (its closest point there), which a refine
    only uses to seed the search of each fine vertex's detail (the dense
    vertex nearest to it among those bound around it). Here each dense
    vertex's finer face is taken from ``binding`` instead: its face and
    barycentric coordinates followed down (or up) the levels of the 1-to-4
    split (the child whose parametric triangle holds the point), the face
    it lies over parametrically rather than the closest one. The detail is
    then found as :func:`bind` finds it (``detail_search``), so it is the
    same wherever the closest dense triangle is within reach of the seed
    (the detail search's two-ring) and, with ``"exact"`` (the default up to
    100,000 dense faces), always: no seed is used. From a binding at fewer
    than two levels the local search is seeded as :func:`bind` seeds it
    (the dense vertices bound again: the faces taken down from a coarse one
    are too far off the closest ones). A 1M-vertex scan at five
    levels of a 2,000-face cage: 2.6x less CPU time than :func:`bind` (5.5
    against 14.3 s on a loaded machine, 2026-12-06), the refine's points
    the same for 99.4% of the fine vertices, the closest for about as many;
    a 60-face cage of a 9k-face torus from two levels to three to five:
    98.9-99.9% the same.

    Parameters
    ----------
    binding : Binding
        The dense mesh's binding, with its dense faces (``F_dense``).
    V_dense : (n_dense,3) float
        The dense positions ``binding`` binds (e.g. ``deform(binding,
        binding.V_cage_rest)``: the mesh as bound).
    levels : int
        Subdivision levels of the result (>= 0; usually more than
        ``binding.levels``; at most ``subdivide.MAX_BOUND_FINE_FACES`` fine faces).
    V_cage : (n_cage,3) float, optional
        The cage to bind to; the binding's rest cage by default (the one its
        faces and barycentric coordinates are on: another cage makes worse
        seeds, not wrong detail).
    detail_search, progress
        As :func:`bind`.

    Returns
    -------
    Binding
        For :func:`refine` only: no dense vertices (``n_dense`` 0; its
        :func:`deform` gives an empty array), no dense faces, the rest cage
        ``V_cage``.

    Raises
    ------
    InvalidArgumentError
        ``binding`` is not a Binding or has no dense faces or rest cage (and
        no ``V_cage`` is given), or an argument is out of range.
    InvalidMeshError
        ``V_dense`` or ``V_cage`` has the wrong shape or non-finite values.
    CancelledError
        ``progress`` returned False.
    """
    V_dense, V_cage = _refined_args(binding, V_dense, levels, V_cage, detail_search, progress)
    F_dense = binding.F_dense
    detail = _detail_mode(detail_search, F_dense)
    if detail == "local" and binding.levels < SEED_LEVELS:
        return _without_dense(bind(V_dense, F_dense, V_cage, binding.F_cage, levels=levels,
                                   scheme=binding.scheme, creases=binding.creases,
                                   detail_search=detail_search, progress=progress))
    origin, step = _origin_and_step(V_cage)
    shifted = origin if origin.any() else None
    typical = in_background(lambda: _typical_distance(
        V_dense, F_dense, V_cage, binding.F_cage, binding.scheme, binding.creases, origin)) \
        if levels > _REACH_LEVELS and detail == "local" else None
    op = cage_operator(binding.F_cage, binding.n_cage, where="bind_refined", levels=levels,
                       scheme=binding.scheme, creases=binding.creases)
    VfT = np.ascontiguousarray(op.apply(V_cage - origin).T)
    NfT, folds = _normals_and_folds(VfT, op.F_fine, _normal_floor(step))
    vfr = _fine_frames(VfT, NfT, op.F_fine, *_vertex_corners(op.F_fine, op.n_fine))
    if progress is not None:                 # (a point cloud has no search to cancel in)
        _reporter(progress, 0.0, 0.05)(1.0)
    index = surface = nearest = None
    if detail == "exact":
        index = in_background(lambda: exact_detail_index(
            V_dense if shifted is None else V_dense - shifted, F_dense, op.n_fine))
    elif detail == "local":
        degree = np.bincount(F_dense.ravel(), minlength=V_dense.shape[0])
        surface = _local_surface(V_dense, F_dense, shifted,
                                 _cleans_local(F_dense, V_dense.shape[0], degree))
        nearest = _seeded_nearest(binding, V_dense, shifted, op.F_fine, levels,
                                  _near_search(surface, degree, vfr.point),
                                  _reporter(progress, 0.05, 0.4))
    fine_detail = _fine_detail(detail, op, vfr, typical.result() if typical is not None else None,
                               index=index, surface=surface, nearest=nearest,
                               report=_reporter(progress, 0.45, 0.95))
    none = np.zeros((0, 3))
    refined = Binding(fine_face=np.zeros(0, dtype=np.int64), bary=none, offset=none,
                      fine_detail=fine_detail, F_cage=binding.F_cage, n_cage=binding.n_cage,
                      levels=int(levels), scheme=binding.scheme, creases=binding.creases,
                      fingerprint=op.fingerprint, V_cage_rest=V_cage, _operator=op)
    refined._cache["folds"] = folds       # (what _rest_folds would find again, subdividing)
    return refined


def _without_dense(binding):
    """``binding`` without its dense vertices and faces (what a refine needs:
    the fine detail, the cage, the rest cage)."""
    none = np.zeros((0, 3))
    return replace(binding, fine_face=np.zeros(0, dtype=np.int64), bary=none, offset=none,
                   F_dense=None)


def _refined_args(binding, V_dense, levels, V_cage, detail_search, progress):
    """:func:`bind_refined`'s arguments checked (its Raises); returns the
    dense and cage positions as float64 (the rest cage for ``V_cage`` None)."""
    where = "bind_refined"
    if not isinstance(binding, Binding):
        raise InvalidArgumentError(f"{where}: expected a Binding, got {type(binding).__name__}")
    if binding.F_dense is None:
        raise InvalidArgumentError(f"{where}: the binding has no dense faces (F_dense); bind "
                                   f"the dense mesh again, or use bind()")
    V_cage = binding.V_cage_rest if V_cage is None else V_cage
    if V_cage is None:
        raise InvalidArgumentError(f"{where}: the binding has no rest cage: give V_cage")
    V_dense = _checked_positions(V_dense, binding.n_dense, where, "V_dense", "dense vertices")
    V_cage = _checked_positions(V_cage, binding.n_cage, where, "V_cage", "cage vertices")
    if detail_search not in _DETAIL_SEARCHES:
        raise InvalidArgumentError(
            f"{where}: detail_search must be one of {_DETAIL_SEARCHES}, got {shown(detail_search)}")
    if progress is not None and not callable(progress):
        raise InvalidArgumentError(f"{where}: progress must be callable or None, got "
                                   f"{type(progress)}")
    check_subdivision_args(levels, binding.scheme, where, binding.F_cage.shape[0],
                           max_faces=MAX_BOUND_FINE_FACES)
    return V_dense, V_cage


def _checked_positions(V, n, where, name, what):
    """``V`` as (n,3) finite float64 within the units deform takes (no copy
    when it already is), else :class:`~.errors.InvalidMeshError` naming it."""
    V = check_vertices(V, where=where, name=name, copy=False)
    if V.shape[0] != n:
        raise InvalidMeshError(f"{where}: {name} has {V.shape[0]} rows but the binding has {n} "
                               f"{what}")
    check_units(V, where=where, name=name)
    return V


def _seeded_nearest(binding, V_dense, origin, F_fine, levels, near, report):
    """Each fine vertex's nearest dense vertex among those whose finer face
    (:func:`~.subdivide.parametric_faces` of their face in ``binding``) has it as a corner,
    -1 for none (:func:`_nearest_parts` over the dense vertices in blocks,
    ``report(fraction)`` after each, in order); positions relative to
    ``origin`` (None: as they are)."""
    n = V_dense.shape[0]
    face = parametric_faces(binding.fine_face, binding.bary, levels - binding.levels)
    FfT = np.ascontiguousarray(F_fine.T)

    def block(span):
        start, stop = span
        P = V_dense[start:stop] if origin is None else V_dense[start:stop] - origin
        corners = np.take(FfT, face[start:stop], axis=1)
        return _nearest_parts(near, P, start, corners, face[start:stop], n), stop

    parts = []
    for part, stop in each_in_order(block, _bind_blocks(n)):
        parts.append(part)
        if report is not None:
            report(stop / n)
    return _nearest_of(parts, n) if parts else np.full(near.P.shape[0], -1, dtype=np.int64)


def _cleans_local(F_dense, n_dense, degree):
    """Whether the local detail search looks on the cleaned dense mesh: up to
    ``_CLEAN_LOCAL_FACES`` faces, or an unwelded one at any size (its
    vertices have fans of one triangle; debris near the surface pulled fine
    vertices off it); a larger welded one is searched as it is (cleaning it
    was 60% of a 2M-face bind; far debris is kept off by
    :func:`~.detail_search.dense_points_near`). ``degree``: the faces at
    each dense vertex."""
    return F_dense.shape[0] <= _CLEAN_LOCAL_FACES or is_unwelded(F_dense, n_dense, degree)


def _local_surface(V_dense, F_dense, origin, clean):
    """The :class:`~.detail_search.DetailSurface` the local detail search
    looks on: the dense mesh cleaned (``clean``, :func:`_cleans_local`) or
    as it is, positions relative to ``origin`` (None: as they are)."""
    V = V_dense if origin is None else V_dense - origin
    return detail_surface(V, F_dense) if clean else DetailSurface(V, F_dense, None)


def _near_search(surface, degree, points):
    """The :class:`_NearSearch` of the fine vertex ``points`` over the dense
    vertices the local detail search can start from: those on the cleaned
    surface (``surface.to_surface``), or on some face (``degree``)."""
    on = surface.to_surface
    return _NearSearch(points, _used_vertices(degree) if on is None
                       else (None if (on >= 0).all() else on >= 0))


def _fine_detail(detail, op, vfr, reach, *, index=None, surface=None, nearest=None,
                 report=None):
    """The detail (n_fine,3) of the fine vertices of the operator ``op``: the
    offset from each one's frame point to its point of the dense surface, in
    its frame ``vfr``.
    ``detail`` (:func:`_detail_mode`): ``"exact"``, the closest point on
    ``index`` (a future of :func:`~.detail_search.exact_detail_index`;
    ``report(fraction)`` as it goes); ``"local"``,
    :func:`~.detail_search.dense_points_near` on ``surface`` from
    ``nearest`` (each fine vertex's nearest dense vertex, in the dense
    mesh's numbering; -1 for none); None, zeros."""
    if detail is None:
        return np.zeros((op.n_fine, 3))
    if detail == "exact":
        q = _closest_on(index.result(), vfr.point, report, point=True)
    else:
        on = surface.to_surface
        if on is not None:
            nearest = np.where(nearest >= 0, on[nearest], -1)
        q = dense_points_near(surface.V, surface.F, op.F_fine, nearest, vfr.point, reach)
    return _to_frame(q - vfr.point, vfr)


def _fine_vertex_parts(op, VfT, NfT, frames_too):
    """What the bind needs of the fine surface ``op`` (positions and normals
    ``VfT``, ``NfT``) besides its index: its :class:`_TieFaces`, each fine
    vertex's face and barycentric coordinates (:func:`_vertex_corners`) and,
    when ``frames_too``, their frames (:func:`_fine_frames`; else None)."""
    d_face, d_bary = _vertex_corners(op.F_fine, op.n_fine)
    return (_TieFaces.of(op.F_fine, op.n_fine), d_face, d_bary,
            _fine_frames(VfT, NfT, op.F_fine, d_face, d_bary) if frames_too else None)


def _faces_aside(F_dense, n_dense, copy, degree):
    """The binding's own dense faces (a copy of ``F_dense`` when ``copy``:
    the caller's array) and, when ``degree``, the number of faces at each of
    the ``n_dense`` vertices (whether the scan is unwelded, which vertices
    are used), else None: made on a worker beside the cage's subdivision
    (about 40 ms of a 2M-face scan's bind)."""
    return (F_dense.copy() if copy else F_dense,
            np.bincount(F_dense.ravel(), minlength=n_dense) if degree else None)


def _typical_distance(V_dense, F_dense, V_cage, F_cage, scheme, creases, origin):
    """The median distance of the dense surface to the cage's subdivision
    surface ``_REACH_LEVELS`` levels down, on ``_REACH_SAMPLES`` samples:
    the first corner of dense faces taken evenly by index, each weighted by
    its face's area (dense vertices evenly by index, unweighted, when there
    are no faces): about their distance to any finer level, at the cost of
    a small index (None without dense vertices); positions taken relative
    to ``origin``. Weighted by area, because a scan's floating specks can
    be most of its vertices and faces (a halo of 4,000 triangles 1e-5 of the
    size around a 5,120-face sphere): their median was a speck's distance, a
    share of the object, the query's cells grew to it, and a bind at three
    levels took 3.8 s where it takes 0.07 without the specks (0.9 with)."""
    if V_dense.shape[0] == 0:
        return None
    op = subdivision_operator(F_cage, V_cage.shape[0], levels=_REACH_LEVELS, scheme=scheme,
                              creases=creases)
    if F_dense.shape[0]:
        T = V_dense[F_dense[::max(1, F_dense.shape[0] // _REACH_SAMPLES)]]
        P, weight = T[:, 0], row_norms(cross_rows(T[:, 1] - T[:, 0], T[:, 2] - T[:, 0]))
    else:
        P, weight = V_dense[::max(1, V_dense.shape[0] // _REACH_SAMPLES)], None
    distance = TriangleIndex(op.apply(V_cage - origin), op.F_fine).closest(P - origin).distance
    if weight is None or not weight.sum() > 0:
        return float(np.median(distance))
    order = np.argsort(distance, kind="stable")
    cumulative = np.cumsum(weight[order])
    return float(distance[order[np.searchsorted(cumulative, 0.5 * cumulative[-1])]])


def _detail_mode(detail_search, F_dense):
    """How :func:`bind` finds the refine detail: ``"exact"`` (an index over
    the dense mesh), ``"local"`` (:func:`.detail_search.dense_points_near`), or None when
    the dense mesh has no faces."""
    if not F_dense.shape[0]:
        return None
    if detail_search == "exact" or (detail_search == "auto"
                                    and F_dense.shape[0] <= _EXACT_DETAIL_FACES):
        return "exact"
    return "local"


def _binding_cache(dense, F_fine, d_face, d_bary, fine_detail, folds):
    """The :class:`Binding` cache (the arrays deform and refine read,
    transposed (3, q)) from the dense pass's :class:`_DenseBound`, the fine
    vertices' corners and the rest cage's folds (:func:`_folds_of`): what
    ``Binding.__post_init__`` and :func:`_rest_folds` would build."""
    return {"corners_t": dense.corners_t, "bary_t": dense.bary_t, "offset_t": dense.offset_t,
            "detail_corners_t": np.take(np.ascontiguousarray(F_fine.T), d_face, axis=1),
            "detail_bary_t": np.ascontiguousarray(d_bary.T),
            "detail_offset_t": np.ascontiguousarray(fine_detail.T), "folds": folds}


@plain_pages
def deform(binding, V_cage_edited, *, F_cage=None, moved=None, out=None):
    """Place the dense vertices on the subdivision of an edited cage.

    Parameters
    ----------
    binding : Binding
    V_cage_edited : (n_cage,3) float
        New cage positions (same vertex order as at bind time).
    F_cage : (m,3) int, optional
        The edited cage's faces; when given they must equal the bound ones.
    moved : (k,) int, optional
        Incremental update: the cage vertices whose positions differ from
        the ones ``out`` was computed from (duplicates allowed, empty for
        none). Only the dense vertices they influence (a subset of
        :meth:`Binding.affected`) are recomputed, in ``out``; the others
        are left as they are. Needs ``out``.
    out : (n_dense,3) float64 C-contiguous ndarray, optional
        Where to write the result (returned). Without ``moved`` every row is
        written; with it, only the influenced rows and the fold repair's
        (:meth:`Binding.repaired`), and ``out`` must be the array a deform
        of this binding last wrote (the binding remembers the repair it made
        there; for a copy of it the result may differ where that repair
        was).

    Returns
    -------
    (n_dense,3) float64 ndarray
        ``out`` when given, else a new array. An incremental update equals a
        full deform of ``V_cage_edited`` bit for bit (the same row-wise frame
        rebuild; its fine positions are each level's stencil rows summed as
        the operator's apply plan sums them), a drag (the same vertices
        moved again and again) included.

    Notes
    -----
    A binding that has the dense faces and the rest cage (``bind`` keeps
    them) repairs the dense faces the edit turned over (:mod:`.unfold`): a
    face whose normal turned by more than 90 degrees from rest, and from
    its rest normal turned by the local rotation of the cage, is put back
    with its neighbourhood's rest shape (``Binding.repaired(D)`` lists the
    rows). Nothing else changes: no edit and rigid motions stay exact (to
    rounding: the fine surface and its frames are computed relative to a
    working origin near the cage (:func:`_deform_origin`), so a scan or a
    cage far from the origin is as exact as one near it, to a few rounding
    steps of the largest coordinate: 1e-12 of the diagonal up to about 1e3
    diagonals from the origin; the unedited cage gives the scan back to
    half a step). A vertex far off the surface carries its frame's rounding
    times its offset: unreferenced strays a diagonal from the cow, 1e3
    diagonals from the origin, 1.1-1.7e-11 of the diagonal (its own
    vertices 1-2e-13).

    Every deform keeps the subdivided cage it computed in the binding's
    cache (each level's positions and the fine normals, about 57 bytes per
    fine vertex) for the incremental deforms that follow; an incremental
    deform whose ``V_cage_edited`` differs from the kept cage elsewhere than
    at ``moved`` recomputes that subdivided cage whole first, but still
    rewrites only the rows ``moved`` influences: ``moved`` is taken at its
    word, so a cage vertex that changed and is not listed leaves the rows
    it influences as they were (list every changed vertex, or make a full
    deform). Consecutive incremental deforms moving the same vertices (a
    drag) keep what they gather for the next steps (the rows' coordinates
    and offsets, the faces around them: up to 32 MB each).

    Raises
    ------
    TopologyMismatchError
        The edited cage has a different vertex count or different faces.
    InvalidMeshError
        Positions are not (n,3) finite numbers.
    InvalidArgumentError
        ``moved`` holds a non-integer or out-of-range index, ``moved`` is
        given without ``out``, or ``out`` is not a writable (n_dense,3)
        float64 C-contiguous array.

    Examples
    --------
    >>> D = deform(b, V_cage)                                     # doctest: +SKIP
    >>> V_cage[[3, 7]] += 0.01                                    # doctest: +SKIP
    >>> deform(b, V_cage, moved=[3, 7], out=D)                    # doctest: +SKIP
    """
    if out is not None:
        _check_out(binding, out)
    if moved is not None:
        if out is None:
            raise InvalidArgumentError(
                "deform: moved needs out (the dense positions computed before the move)")
        ids = _check_moved(binding, moved)
        Vc = _apart_from(_check_cage(binding, V_cage_edited, F_cage, "deform"), out)
        if ids.size:
            holds, handed = _incremental_holds(binding, Vc, "deform")
            if not holds:
                return deform(binding, V_cage_edited, F_cage=F_cage, out=out)
            with _INCREMENTAL_LOCK:
                hit = _influenced_dense(binding, ids)
                P, N, origin = _update_fine_geometry(binding, Vc, ids, hit)
                last = _repair_of(binding, out)
                out[last.rows] = last.raw       # the rows as deformed, before out's repair
                if hit.rows.size:
                    _deform_rows(binding, P, N, hit, out, origin, handed)
                _keep_repair(binding, out, _unfold(binding, out, Vc, hit, last))
        return out
    Vc = _apart_from(_check_cage(binding, V_cage_edited, F_cage, "deform"), out)
    PT, NT, origin, handed = _full_geometry(binding, Vc, "deform")
    c = binding._cache
    parts = (c["offset_t"], c["corners_t"], c["bary_t"], PT, NT, origin, handed)
    D = None if out is not None else _positions_t(*parts, rows=np.empty((binding.n_dense, 3)))
    with _INCREMENTAL_LOCK:          # (``out`` is written under it, as incremental deforms do)
        if D is None:
            D = _positions_t(*parts, rows=out)
        _keep_repair(binding, D, _unfold(binding, D, Vc))
    return D


def _apart_from(Vc, out):
    """The cage ``Vc``, copied when it shares memory with ``out`` (the fold
    repair reads it after the rows are written: a cage held in the output's
    buffer had been overwritten by then, and a deform that repaired faces came
    out 0.1 of the size off)."""
    return Vc.copy() if out is not None and np.may_share_memory(Vc, out) else Vc


def _repair_state(binding):
    """The fold repair's rest data, built on first use and cached (None when
    the binding was made without the dense faces or the cage): the dense
    positions on the rest cage, the dense faces' corner rows and rest area
    normals (3, m; float32), the cage's one-rings, and the indices of the
    faces around dense vertices (built when first needed)."""
    if binding.F_dense is None or binding.V_cage_rest is None or not binding.F_dense.shape[0]:
        return None
    c = binding._cache
    if "repair" not in c:
        origin = _deform_origin(binding, binding.V_cage_rest)
        VrT = _fine_levels(binding, binding.V_cage_rest, origin)[-1]
        NrT = _vertex_normals_t(VrT, binding._operator.F_fine, _binding_floor(binding),
                                _rest_folds(binding))
        rest = _positions_t(c["offset_t"], c["corners_t"], c["bary_t"], VrT, NrT, origin)
        FT = np.ascontiguousarray(binding.F_dense.T)
        c["repair"] = {"V_rest": np.ascontiguousarray(rest.T), "F_t": FT,
                       # float32: every test reads these same values (half the bytes)
                       "normals": rest_normals(rest, FT),
                       "cage_rings": CageRings.of(binding.F_cage, binding.n_cage),
                       "stars": None, "groups": None,
                       # the faces (or group entries) around the last rows tested, by their
                       # _Influenced, and their FaceBatch (see _away_around)
                       "around": None}
    return c["repair"]


def _repair_index(binding):
    """Build the fold repair's state and the indices its incremental test
    and repair use (see :func:`_away_around`) now, if the binding can repair."""
    state = _repair_state(binding)
    if state is not None:          # (the two indices side by side on the worker threads)
        run_each(lambda build: build(binding, state),
                 [_stars, _groups] if _by_groups(binding) else [_stars])


def _by_groups(binding):
    """Whether the fold test finds the faces around rows by fine face groups."""
    return binding._operator.F_fine.shape[0] <= _GROUPS_SHARE * binding.F_dense.shape[0]


def _away_around(binding, state, D, hit, incremental=False):
    """The faces around the rows of ``hit`` (an :class:`_Influenced`) whose
    normal on ``D`` points away from rest: by the fine faces' groups
    (:class:`~.unfold.FineFaceGroups`, each face with a corner on a fine face
    of ``hit`` once; bunny x16 at two levels, 5 cage vertices moved: 2.0 ms
    against 3.4 around each row) when the fine mesh has at most a
    ``_GROUPS_SHARE`` of the dense mesh's faces, else around each row (at
    five levels, as many fine faces as dense ones, a dense face lies over
    three fine faces: the groups would hold 5.8M entries, 200 MB, for a 2M-face
    scan, and save 2 of 25 ms a live update). The faces or entries are kept
    for the next call with the same ``hit``; from the second ``incremental``
    deform testing them (a drag asks again for the same rows at every
    step), with their corners and rest normals as gathered (a
    :class:`~.unfold.FaceBatch`, up to ``_KEPT_BATCH_BYTES``: keeping them
    costs the test that makes it 0.1-0.2 ms of fresh memory, and saves the
    next ones their gathers, 0.5 of 3 ms a step of the bunny x16's drag)."""
    around = state.get("around")
    if around is None or around["hit"] is not hit:
        columns = _groups(binding, state).entries(hit.faces) if _by_groups(binding) \
            else _stars(binding, state).around(hit.rows)
        around = state["around"] = {"hit": hit, "columns": columns, "batch": None,
                                    "incremental": False}
    if around["batch"] is not None:
        return around["batch"].away(D)
    if _by_groups(binding):
        groups = _groups(binding, state)
        FT, rest, faces = groups.corners, groups.rest, groups.faces
    else:
        FT, rest, faces = state["F_t"], state["normals"], None
    keep = around["incremental"] and \
        FaceBatch.size(FT, around["columns"], rest) <= _KEPT_BATCH_BYTES
    away, around["batch"] = FaceBatch.tested(D, FT, around["columns"], rest, faces, keep)
    around["incremental"] |= incremental
    return away


def _groups(binding, state):
    """The :class:`~.unfold.FineFaceGroups` of the repair state (built on first use)."""
    if state["groups"] is None:
        state["groups"] = FineFaceGroups.of(binding.F_dense, binding.fine_face,
                                            binding._operator.F_fine.shape[0], state["normals"],
                                            block=4 ** binding.levels)   # (a cage face's)
    return state["groups"]


def _stars(binding, state):
    """The dense vertex -> faces index of the repair state (built on first use)."""
    if state["stars"] is None:
        state["stars"] = FaceStars.of(binding.F_dense, binding.n_dense)
    return state["stars"]


def _repair_of(binding, D):
    """The :class:`~.unfold.Repair` made in the array ``D`` by the last
    deform that wrote it (none for an array no deform repaired; callers hold
    ``_INCREMENTAL_LOCK``)."""
    kept = _REPAIRS.get(binding, {}).get(id(D))
    return kept[1] if kept is not None and kept[0]() is D else Repair.none()


def _keep_repair(binding, D, repaired):
    """Remember ``repaired`` as the repair of the array ``D`` (by identity,
    through a weak reference; entries of arrays gone are dropped)."""
    kept = _REPAIRS.setdefault(binding, {})
    for key in [k for k, (ref, _) in kept.items() if ref() is None]:
        del kept[key]
    if repaired.rows.size or repaired.away.size:
        kept[id(D)] = (weakref.ref(D), repaired)
    else:
        kept.pop(id(D), None)


def _rotation(binding, Vc, handed=1.0):
    """``(rotate, transform)``, each ``f(vertices, vectors)`` -> (j,3): the
    vectors turned by the rotation of the cage where each dense vertex lies
    (over its fine face's coarse face: the mean of its corners'
    :func:`~.unfold.ring_rotations` from the rest cage to ``Vc``, made a
    rotation again), or mapped by its local linear map (the mean of its
    corners' :func:`~.unfold.ring_linear_maps`: also scaled and stretched as
    the cage is there). A rigid motion of the cage turns them by exactly its
    rotation (to rounding). Each cage vertex's rotation and map are computed
    once, when a coarse face it is a corner of is first asked for. For a
    mirrored cage (``handed`` -1, :func:`_handedness`), the maps are those
    from the rest cage mirrored (x -> -x) after that mirror, and a normal
    (which follows the faces' winding, turned inside out by a mirror) is
    turned and then reversed."""
    rings = _repair_state(binding)["cage_rings"]
    V_rest = binding.V_cage_rest
    if handed < 0:
        V_rest = V_rest * _MIRROR

    ring_R = np.empty((binding.n_cage, 3, 3))
    ring_A = np.empty((binding.n_cage, 3, 3))
    known = np.zeros((2, binding.n_cage), dtype=bool)
    per_face = 4 ** binding.levels

    def corners_of(vertices, kind, table, of):
        faces, at = np.unique(binding.fine_face[vertices] // per_face, return_inverse=True)
        corners = binding.F_cage[faces]
        new = sorted_unique(corners)
        new = new[~known[kind, new]]
        if new.size:
            table[new] = of(V_rest, Vc, rings, new)
            known[kind, new] = True
        return corners, at.ravel()

    def rotate(vertices, vectors):
        corners, at = corners_of(vertices, 0, ring_R, ring_rotations)
        R = nearest_rotations(ring_R[corners].sum(axis=1))
        if handed < 0:
            return -np.einsum("kij,kj->ki", R[at], vectors * _MIRROR)
        return np.einsum("kij,kj->ki", R[at], vectors)

    def transform(vertices, vectors):
        corners, at = corners_of(vertices, 1, ring_A, ring_linear_maps)
        if handed < 0:
            vectors = vectors * _MIRROR
        return np.einsum("kij,kj->ki", ring_A[corners].mean(axis=1)[at], vectors)
    return rotate, transform


def _unfold(binding, D, Vc, hit=None, last=None):
    """Repair the faces of ``D`` (in place), deformed on the cage ``Vc``,
    turned over (:mod:`.unfold`); returns the :class:`~.unfold.Repair`
    (callers hold ``_INCREMENTAL_LOCK``). The faces tested: for an
    incremental deform, those around the rows it rewrote (``hit``, its
    :class:`_Influenced`), those around the rows of the ``last`` repair and the
    faces it found away from rest (their rotation may have changed): every
    other face is as it was then, so not turned over; for a full one
    (``hit`` None), those around the dense vertices the cage
    vertices moved from rest influence (the others are where they were at
    rest, bit for bit), or every face when
    more than ``_REPAIR_ALL_SHARE`` of the cage moved or the cage reads as
    mirrored (:func:`_handedness`: every row changed)."""
    state = _repair_state(binding)
    if state is None:
        return Repair.none()
    FT, rest = state["F_t"], state["normals"]
    handed = binding._cache.get("handed", 1.0)
    if hit is None:
        moved = np.flatnonzero((Vc != binding.V_cage_rest).any(axis=1))
        if moved.shape[0] > _REPAIR_ALL_SHARE * binding.n_cage or handed < 0:
            # (a mirrored cage changes every row: one cage vertex of the cow's pushed 2
            # diagonals through it made the cage read as mirrored, and the faces away from
            # rest elsewhere went untested, unlike the incremental updates that followed)
            away = away_rows(D, FT, None, rest)
        elif moved.size:
            away = _away_around(binding, state, D, _influenced_dense(binding, moved))
        else:
            away = np.zeros(0, dtype=np.int64)
    else:
        away = _away_around(binding, state, D, hit, incremental=True)
        if last.rows.size or last.away.size:
            around = sorted_unique(np.concatenate([_stars(binding, state).around(last.rows),
                                                   last.away]))
            away = sorted_unique(np.concatenate([away, away_rows(D, FT, around, rest)]))
    rotate, transform = _rotation(binding, Vc, handed)
    folded = turned_over(D, FT, away, rest, rotate)
    if not folded.size:
        return repair(D, state["V_rest"], binding.F_dense, FT, None, folded, rest, rotate, away)
    welded = _welded(binding, state)
    if welded is None:
        return repair(D, state["V_rest"], binding.F_dense, FT, _stars(binding, state), folded,
                      rest, rotate, away, transform)
    return repair(D, state["V_rest"], welded[0], FT, welded[1], folded, rest, rotate, away,
                  transform, welded[2])


def _welded(binding, state):
    """The dense faces on welded vertices, their faces around each vertex and
    the :class:`~.unfold.Copies` (the repair relaxes a region on them), or
    None when no two dense vertices sit at one rest point; found at the
    first repair (a sort of the rest positions) and kept."""
    if "welded" not in state:
        copies = Copies.of(state["V_rest"])
        state["welded"] = None if copies is None else (
            copies.weld[binding.F_dense], FaceStars.of(copies.weld[binding.F_dense],
                                                       binding.n_dense), copies)
    return state["welded"]


def _check_out(binding, out, rows=None, where="deform"):
    """Raise :class:`InvalidArgumentError` unless ``out`` is a writable
    C-contiguous (rows, 3) float64 array (rows: the dense vertices' count
    when None)."""
    rows = binding.n_dense if rows is None else rows
    if not isinstance(out, np.ndarray) or out.shape != (rows, 3) \
            or out.dtype != np.float64 or not out.flags.c_contiguous or not out.flags.writeable:
        desc = (f"{out.shape} {out.dtype}"
                + ("" if out.flags.c_contiguous else ", not C-contiguous")
                + ("" if out.flags.writeable else ", read-only") if isinstance(out, np.ndarray)
                else type(out).__name__)
        raise InvalidArgumentError(
            f"{where}: out must be a writable C-contiguous ({rows}, 3) float64 "
            f"array, got {desc}")


def _check_moved(binding, moved, where="deform"):
    """``moved`` as distinct sorted int64 cage vertex ids, checked."""
    ids = np.asarray(moved)
    if ids.size == 0:
        return np.zeros(0, dtype=np.int64)
    if not np.issubdtype(ids.dtype, np.integer):
        raise InvalidArgumentError(
            f"{where}: moved must be integer cage vertex indices, got {ids.dtype}")
    if ids.dtype.kind == "u" and int(ids.max()) >= binding.n_cage:
        raise InvalidArgumentError(            # (as int64 it wrapped to a negative index)
            f"{where}: moved index {int(ids.max())} is out of range [0, {binding.n_cage})")
    ids = ids.astype(np.int64).ravel()
    bad = (ids < 0) | (ids >= binding.n_cage)
    if bad.any():
        raise InvalidArgumentError(
            f"{where}: moved index {int(ids[bad][0])} is out of range [0, {binding.n_cage}) "
            f"({int(bad.sum())} such)")
    return sorted_unique(ids)


class _Influenced(NamedTuple):
    """What an incremental deform recomputes (see :func:`_influenced_dense`)."""

    rows: np.ndarray       #: (r,) int64 dense vertices, grouped by fine face
    sorted_at: np.ndarray  #: (r,) int64 their positions in the face-sorted order
    faces: np.ndarray      #: (f,) int64 the fine faces they are bound to, ascending
    changed: tuple         #: per level 1..L, the (k_l,) int64 vertices whose position changes
    normals: np.ndarray    #: (j,) int64 fine vertices whose normal changes (ascending)


def _deform_rows(binding, P, N, hit, out, origin, handed=1.0):
    """Rebuild the dense rows ``hit.rows`` of ``out`` on the fine positions
    and normals ``P``, ``N`` (3, n_fine), relative to ``origin`` (3,), the
    normal components times ``handed`` (:func:`_handedness`) (the
    incremental deform's row work).

    The rows are grouped by fine face, so the face's corner, edges and
    corner normals are gathered once per face and repeated over its rows,
    and the rows' barycentric coordinates and offsets come from the
    face-sorted copies (contiguous runs, not a scattered gather); blocks of
    whole faces, about ``_ROW_BLOCK`` rows each, on the worker threads from
    ``_THREADED_ROWS`` rows (each block writes its own rows); a drag's
    blocks keep their gathered coordinates and offsets (:func:`_kept_rows`:
    4.47 -> 4.23 ms a step of the bunny x16's). Each row goes through the
    operations of :func:`_frames_t` in the same order, so it is bit for bit
    what a full deform gives on the same fine positions and normals."""
    idx = binding._cache["incremental"]
    per_face = _face_rows(idx, P, N, hit.faces)
    count = idx["dense_count"][hit.faces]
    end = np.cumsum(count)
    # blocks of whole faces, about _ROW_BLOCK rows each, and from _THREADED_ROWS
    # rows at least one per worker thread
    threads = int(end[-1]) >= _THREADED_ROWS
    size = min(_ROW_BLOCK, -(-int(end[-1]) // WORKERS)) if threads else _ROW_BLOCK
    cuts = sorted_unique(np.concatenate([[0], np.searchsorted(
        end, np.arange(size, int(end[-1]), size)) + 1, [per_face.shape[1]]]))
    at = 3 * hit.rows                 # row starts in the flat (C-contiguous) out
    flat = out.reshape(-1)
    moved_origin = bool(origin.any())
    kept = _kept_rows(idx, hit)

    def block(span):
        f0, f1 = span
        s, e = int(end[f0 - 1]) if f0 else 0, int(end[f1 - 1])
        c = count[f0:f1]
        if f0 in kept:
            b0, b1, b2, offsets = kept[f0]
        else:
            runs = hit.sorted_at[s:e]     # (in range: "wrap" gathers, half the time of "raise")
            b0, b1, b2 = (np.take(idx["bary_by_face"][k], runs, mode="wrap") for k in range(3))
            offsets = np.take(idx["offset_by_face"], runs, axis=1, mode="wrap")
            if kept.keep:
                kept[f0] = b0, b1, b2, offsets
        # each face's rows repeated over its dense rows: one gather (np.repeat holds the
        # GIL, and seven of them a block kept the two worker threads waiting on each other)
        G = np.take(per_face, np.repeat(np.arange(f0, f1), c), axis=1, mode="wrap")
        point, e1, e2, normal = G[0:3], G[3:6], G[6:9], G[9:12]
        tmp = np.multiply(b1, e1)     # from here the operations of _frames_t
        point += tmp
        np.multiply(b2, e2, out=tmp)
        point += tmp
        normal *= b0
        np.multiply(G[12:15], b1, out=tmp)
        normal += tmp
        np.multiply(G[15:18], b2, out=tmp)
        normal += tmp
        X = _compose_t(offsets, *_frames_finish(point, e1, e2, normal, tmp, G[18]), handed)
        if moved_origin:
            X += origin[:, None]
        for d in range(3):            # a coordinate at a time: no (r,3) copy to scatter (indexed
            flat[d:][at[s:e]] = X[d]  # assignment to an offset view: half np.put's time)
    run_each(block, list(zip(cuts[:-1].tolist(), cuts[1:].tolist())), threads=threads)


def _face_rows(idx, P, N, faces):
    """Per fine face of ``faces``, as :func:`_frames_t` takes them, the rows
    (19, f) of :func:`_deform_rows`: its first corner (0:3), edges (3:6, 6:9)
    and corner normals (9:12, 12:15, 15:18) from the fine positions and
    normals ``P``, ``N`` (3, n_fine), and the longer edge's length (18)."""
    Fh = np.take(idx["corners_t"], faces, axis=1)
    rows = np.empty((19, faces.shape[0]))
    A = np.take(P, Fh[0], axis=1, out=rows[0:3])
    np.subtract(np.take(P, Fh[1], axis=1), A, out=rows[3:6])
    np.subtract(np.take(P, Fh[2], axis=1), A, out=rows[6:9])
    for k in range(3):
        np.take(N, Fh[k], axis=1, out=rows[9 + 3 * k:12 + 3 * k])
    rows[18] = _edges_size(rows[3:6], rows[6:9])
    return rows


class _KeptRows(dict):
    """The gathered barycentric coordinates and offsets of a drag's rows,
    by the first fine face of each block of :func:`_deform_rows` (the blocks
    depend on the rows alone); ``keep``: whether the blocks gathered now are
    to be kept."""

    def __init__(self, hit, keep=False):
        super().__init__()
        self.hit, self.keep = hit, keep


def _kept_rows(idx, hit):
    """The :class:`_KeptRows` of ``hit`` (an :class:`_Influenced`) in the
    incremental index ``idx``: kept from the second deform of the same rows (a
    drag's second step; its first is any move's, and pays nothing for it)
    while they take at most ``_KEPT_BATCH_BYTES``."""
    kept = idx.get("kept_rows")
    if kept is None or kept.hit is not hit:
        kept = idx["kept_rows"] = _KeptRows(hit)          # (a first deform of these rows)
    elif not kept.keep and not kept:
        kept.keep = 48 * hit.rows.shape[0] <= _KEPT_BATCH_BYTES
    else:
        kept.keep = False                                 # (kept, or too large to keep)
    return kept


def _influenced_dense(binding, ids):
    """Dense vertices whose deformed position depends on the cage vertices
    ``ids``, as an :class:`_Influenced` (the rows grouped by fine face, those
    faces, each level's changed positions and the changed fine normals).

    The chain, all on index sets of the fine mesh (O(fine support + result),
    never O(dense or fine mesh): distinct values by :func:`_distinct`, whose
    cost is bounded by a multiple of its input's): fine vertices the stencils
    reach from ``ids`` level by level with nonzero weights (positions change)
    -> every corner of a fine face touching them (normals change) -> the
    fine faces with such a corner
    (their bound dense vertices move). The fine face -> dense vertices, fine
    vertex -> fine faces and transposed stencil indices are built on first
    use and cached in the binding, with the last answer (so
    :meth:`Binding.influenced` followed by the deform of the same ids
    searches once).
    """
    idx = _incremental_index(binding)
    key = ids.tobytes()
    last = idx.get("last")
    if last is not None and last[0] == key:    # Binding.influenced, then deform, same ids
        return last[1]
    changed, fine = _changed_levels(idx, ids)
    touched = _faces_around(idx, fine)
    normal_changed = _distinct(np.take(idx["corners_t"], touched, axis=1).ravel(), idx)
    faces = _faces_around(idx, normal_changed, with_rows=True)      # ascending
    k = ragged_entries(idx["dense_start"][faces], idx["dense_count"][faces])
    result = _Influenced(idx["dense_by_face"][k], k, faces, changed, normal_changed)
    idx["last"] = (key, result)
    return result


def _changed_levels(idx, ids):
    """Per level 1..L, the vertices (ascending int64) whose position changes
    when the cage vertices ``ids`` move: level by level, the rows of the
    transposed stencils (``idx["levels_t"]``) reading a changed vertex.
    Returns ``(changed, fine)``: that tuple and the fine level's (``ids``
    at zero levels)."""
    changed, pos_changed = [], ids
    for T in idx["levels_t"]:
        start = T.indptr[pos_changed]
        k = ragged_entries(start, T.indptr[pos_changed + 1] - start)
        pos_changed = _distinct(T.cols[k], idx)
        changed.append(pos_changed)
    return tuple(changed), pos_changed


def _incremental_index(binding):
    """The cached fine face -> bound dense vertices and fine vertex ->
    incident fine faces indices (CSR: order, start, count)."""
    c = binding._cache
    if "incremental" not in c:
        op = binding._operator
        m_fine = op.F_fine.shape[0]
        d_count = np.bincount(binding.fine_face, minlength=m_fine)
        flat = op.F_fine.ravel()
        v_count = np.bincount(flat, minlength=op.n_fine)
        faces_by_vertex = stable_argsort(flat) // 3
        # the same, for the faces with bound dense vertices only (fewer than the
        # fine faces when the fine mesh is denser than the dense one)
        has_rows = d_count > 0
        row_faces = faces_by_vertex[has_rows[faces_by_vertex]]
        r_count = np.bincount(flat[np.repeat(has_rows, 3)], minlength=op.n_fine)
        by_face = stable_argsort(binding.fine_face)
        c["incremental"] = {
            "dense_by_face": by_face,
            # the rows' barycentric coordinates and offsets in that order: the rows of
            # an incremental deform are runs of it
            "bary_by_face": np.ascontiguousarray(np.take(c["bary_t"], by_face, axis=1)),
            "offset_by_face": np.ascontiguousarray(np.take(c["offset_t"], by_face, axis=1)),
            "dense_count": d_count, "dense_start": np.cumsum(d_count) - d_count,
            "faces_by_vertex": faces_by_vertex,
            "vertex_count": v_count, "vertex_start": np.cumsum(v_count) - v_count,
            "row_faces_by_vertex": row_faces,
            "row_vertex_count": r_count, "row_vertex_start": np.cumsum(r_count) - r_count,
            "levels_t": [_transposed(S) for S in op.stencils],
            # the fine faces' corners as three contiguous rows (int32 where they fit): the
            # corner gathers of an incremental deform are 3-4x faster than F_fine[faces]
            "corners_t": np.ascontiguousarray(
                op.F_fine.T, dtype=np.int32 if op.n_fine < 2**31 else np.int64),
            # scratch for _distinct, over fine vertices and faces (incremental deforms
            # share it: they run under _INCREMENTAL_LOCK)
            "stamp": np.empty(max(op.n_fine, m_fine, binding.n_cage), dtype=np.int64),
            "seen": np.zeros(max(op.n_fine, m_fine, binding.n_cage), dtype=bool),
        }
    return c["incremental"]


def _transposed(S):
    """The structural transpose of one level's stencil ``S``: for each input
    vertex, the output vertices reading it with a nonzero weight."""
    rows, cols = S.rows(), S.cols
    keep = S.weights != 0
    rows, cols = rows[keep], cols[keep]
    order = stable_argsort(cols)
    indptr = np.zeros(S.n_in + 1, dtype=np.int64)
    np.cumsum(np.bincount(cols, minlength=S.n_in), out=indptr[1:])
    return _Rows(indptr, rows[order], np.zeros(0), S.n_out)


def _faces_around(idx, vertices, with_rows=False):
    """Distinct fine faces incident to the given distinct fine vertices
    (ascending); with ``with_rows``, only faces some dense vertex is bound to."""
    pre = "row_" if with_rows else ""
    k = ragged_entries(idx[pre + "vertex_start"][vertices], idx[pre + "vertex_count"][vertices])
    return _distinct(idx[pre + "faces_by_vertex"][k], idx)


def _distinct(values, idx):
    """:func:`~._groups.distinct` over the incremental index's scratch arrays
    (``seen`` and ``stamp``, over fine vertices and faces)."""
    return distinct(values, idx["seen"], idx["stamp"])


@plain_pages
def refine(binding, V_cage_edited, *, F_cage=None, moved=None, out=None):
    """The subdivided edited cage with the dense mesh's detail as displacements.

    Each fine vertex is moved by its stored offset to the dense surface,
    expressed in its own frame (normal: the fine vertex normal), so the
    unedited cage refines onto the dense surface and an edited one carries
    the detail along. The result has the regular connectivity ``F_fine``.

    Parameters
    ----------
    binding : Binding
    V_cage_edited : (n_cage,3) float
        New cage positions (same vertex order as at bind time).
    F_cage : (m,3) int, optional
        The edited cage's faces; when given they must equal the bound ones.
    moved : (k,) int, optional
        Incremental update, as :func:`deform`'s: the cage vertices whose
        positions differ from the ones ``out`` was computed from
        (duplicates allowed, empty for none). Only the fine vertices they
        move (:meth:`Binding.refined_rows`) are recomputed, in ``out``; the
        others are left as they are. Needs ``out``, written by a refine of
        this binding (before any, or when the cage was mirrored since, the
        whole of ``out`` is written).
    out : (n_fine,3) float64 C-contiguous ndarray, optional
        Where to write the refined positions (returned as ``V``).

    Returns
    -------
    RefineResult
        ``(V, F)``: (n_fine,3) float64 (``out`` when given) and (m_fine,3)
        int64: a copy of the fine faces, or with ``out`` a read-only view
        of the binding's (no copy of 24 bytes a face at every update). An
        incremental update equals a full refine bit for bit.

    Notes
    -----
    Every refine keeps the subdivided cage it computed in the binding's
    cache, as :func:`deform` does (they share it), for the incremental
    updates that follow; ``moved`` is taken at its word, as there.

    Raises
    ------
    TopologyMismatchError, InvalidMeshError
        As :func:`deform`.
    InvalidArgumentError
        ``moved`` holds a non-integer or out-of-range index, ``moved`` is
        given without ``out``, or ``out`` is not a writable (n_fine,3)
        float64 C-contiguous array.

    Examples
    --------
    >>> R = refine(b, V_cage).V                                   # doctest: +SKIP
    >>> V_cage[[3, 7]] += 0.01                                    # doctest: +SKIP
    >>> refine(b, V_cage, moved=[3, 7], out=R)                    # doctest: +SKIP
    """
    if out is not None:
        _check_out(binding, out, binding._operator.n_fine, "refine")
    Vc = _apart_from(_check_cage(binding, V_cage_edited, F_cage, "refine"), out)
    if moved is not None:
        if out is None:
            raise InvalidArgumentError(
                "refine: moved needs out (the refined positions computed before the move)")
        ids = _check_moved(binding, moved, "refine")
        holds, handed = _incremental_holds(binding, Vc, "refine") if ids.size else (True, None)
        if ids.size and holds:
            with _INCREMENTAL_LOCK:
                hit = _influenced_fine(binding, ids)
                # (a row reads its own normal: the others of its frame face weigh 0)
                P, N, origin = _update_fine_geometry(binding, Vc, ids, hit, read=hit.rows)
                out[hit.rows] = _refined_t(binding, hit.rows, P, N, origin, handed).T
        if holds:
            return RefineResult(out, _fine_faces_view(binding))
    PT, NT, origin, handed = _full_geometry(binding, Vc, "refine")
    into = np.empty((binding._operator.n_fine, 3)) if out is None else out
    V = _refined_t(binding, None, PT, NT, origin, handed, into)
    return RefineResult(V, binding._operator.F_fine.copy() if out is None
                        else _fine_faces_view(binding))


#: per kind of output, the cache keys of the handedness and working origin its last
#: full update used, and the handedness taken when none is kept (a refine's output
#: none wrote is written whole)
_FRAME_KEYS = {"deform": ("handed", "deform_origin", 1.0),
               "refine": ("refined_handed", "refined_origin", None)}


def _full_geometry(binding, Vc, kind):
    """The subdivided cage ``Vc`` a full deform or refine (``kind``) reads:
    fine positions and normals (3, n_fine), the working origin
    (:func:`_deform_origin`) and the handedness (:func:`_handedness`). Kept
    in the binding's cache for the incremental updates that follow (deform's
    and refine's alike; a new object: one in use by an incremental update is
    never changed under it), the origin and handedness under ``kind``'s
    keys (:func:`_incremental_holds`)."""
    origin = _deform_origin(binding, Vc)
    X = _fine_levels(binding, Vc, origin)
    floor = _binding_floor(binding)
    NT = _vertex_normals_t(X[-1], binding._operator.F_fine, floor, _rest_folds(binding))
    handed = _handedness(binding, Vc)
    c = binding._cache
    handed_key, origin_key, _ = _FRAME_KEYS[kind]
    c[handed_key], c[origin_key] = handed, origin
    c["geometry"] = _Geometry.of(Vc, X, NT, origin, floor)
    return X[-1], NT, origin, handed


def _incremental_holds(binding, Vc, kind):
    """``(holds, handed)``: whether an incremental deform or refine
    (``kind``) of the cage ``Vc`` can keep the rows it does not recompute
    (the last full one used the same handedness and working origin: a cage
    mirrored, or moved far away or back, changes every row; a kept origin
    had left rows 9e-8 of the diagonal off the full result for a cage 1e9
    away), and the cage's handedness."""
    handed_key, origin_key, assumed = _FRAME_KEYS[kind]
    c = binding._cache
    handed = _handedness(binding, Vc)
    kept = c.get(origin_key)
    moved = kept is not None and not np.array_equal(kept, _deform_origin(binding, Vc))
    return handed == c.get(handed_key, assumed) and not moved, handed


def _refined_t(binding, rows, VfT, NfT, origin, handed, into=None):
    """The refined positions (3, k) of the fine vertices ``rows`` (None: all)
    on the fine positions and normals ``VfT``, ``NfT`` (3, n_fine) relative
    to ``origin``: :func:`_positions_t` of their detail (column by column, so
    a subset is bit for bit the same columns of the whole); written into the
    (k, 3) array ``into`` instead when given (returned)."""
    c = binding._cache
    parts = (c["detail_offset_t"], c["detail_corners_t"], c["detail_bary_t"])
    if rows is not None:
        parts = (np.take(a, rows, axis=1) for a in parts)
    return _positions_t(*parts, VfT, NfT, origin, handed, rows=into)


def _fine_faces_view(binding):
    """The binding's fine faces as a read-only view."""
    F = binding._operator.F_fine.view()
    F.flags.writeable = False
    return F


def _influenced_fine(binding, ids):
    """The fine vertices whose refined position depends on the cage vertices
    ``ids``, as an :class:`_Influenced` whose ``rows`` are those fine
    vertices (ascending; no ``faces``). A fine vertex's frame is taken at
    its own corner of its frame face (:func:`_vertex_corners`): it reads its
    own normal (the other corners' weigh 0: their normals are not brought up
    to date for it, :func:`_update_fine_geometry`'s ``read``; the same
    values, the sign of a zero aside) and the face's corner positions (its
    edges). So the rows are the
    vertices whose normal changes: the corners of the fine faces around a
    changed position (each level's, as :func:`_influenced_dense`), which
    include every vertex whose frame face has a changed corner. The last
    answer is kept (so :meth:`Binding.refined_rows` followed by the refine
    of the same ids searches once)."""
    idx = _incremental_index(binding)
    key = ids.tobytes()
    last = idx.get("last_fine")
    if last is not None and last[0] == key:
        return last[1]
    changed, fine = _changed_levels(idx, ids)
    touched = _faces_around(idx, fine)
    rows = _distinct(np.take(idx["corners_t"], touched, axis=1).ravel(), idx)
    none = np.zeros(0, dtype=np.int64)
    result = _Influenced(rows, none, none, changed, rows)
    idx["last_fine"] = (key, result)
    return result


def frames(Vf, Nf, corners, bary):
    """Points and orthonormal frames at barycentric locations of fine faces.

    Parameters
    ----------
    Vf, Nf : (n_fine,3) float64
        Fine vertex positions and unit vertex normals.
    corners : (q,3) int64
        Vertex indices of the face each query lies in (``F_fine[face]``).
    bary : (q,3) float64
        Barycentric coordinates in that face.

    Returns
    -------
    Frames
        ``normal`` is the normalised barycentric blend of the corner normals
        (face normal where the blend vanishes); ``tangent`` is the face's
        first edge ``corner1 - corner0`` made orthogonal to the normal
        (second edge, then any perpendicular, when degenerate);
        ``bitangent = normal x tangent``. Each row is computed on its own, so
        rows with identical inputs give bit-identical outputs.
    """
    corners = np.asarray(corners, dtype=np.int64)
    return _fine_frames(np.ascontiguousarray(np.asarray(Vf, dtype=np.float64).T),
                        np.ascontiguousarray(np.asarray(Nf, dtype=np.float64).T),
                        corners, np.arange(corners.shape[0]), np.asarray(bary, dtype=np.float64))


def _fine_frames(VfT, NfT, F_fine, face, bary):
    """:func:`frames` of the points at ``bary`` (q,3) of the fine faces
    ``face`` (q,), on the fine positions and normals ``VfT``, ``NfT`` (3,
    n_fine): :func:`_frames_t` a block of ``_ROW_BLOCK`` points at a time on
    the worker threads, each row as on the whole arrays (the fine vertices'
    frames of a five-level bind: 266 ms on one thread with the transposed
    copies of the whole arrays, 130 ms so)."""
    out = Frames(*(np.empty((face.shape[0], 3)) for _ in range(4)))
    FfT = np.ascontiguousarray(F_fine.T)

    def block(s, e):
        parts = _frames_t(VfT, NfT, np.take(FfT, face[s:e], axis=1),
                          np.ascontiguousarray(bary[s:e].T))
        for whole, part in zip(out, parts):
            whole[s:e] = part.T
    run_blocks(block, blocks(face.shape[0], _ROW_BLOCK))
    return out


def _positions_t(oT, cT, bT, VfT, NfT, origin=None, handed=1.0, rows=None):
    """The points (3, n) at the frame components ``oT`` of the fine surface
    points at corners ``cT``, barycentric coordinates ``bT`` (each (3, n)),
    on fine positions and normals ``VfT``, ``NfT`` (3, n_fine) relative to
    ``origin`` (3,) (added to the result; None or zeros: none), the normal
    components times ``handed`` (:func:`_handedness`):
    :func:`_frames_t` and :func:`_compose_t` a block of ``_ROW_BLOCK``
    points at a time (the temporaries stay small and are reused), bit for
    bit the same as on the whole arrays. ``rows``: an (n, 3) array to write
    the points into instead (returned), each block transposed while it is
    in cache (a full deform of a 1M-vertex scan: no 24 MB (3, n) array
    made, paged in and copied, 45 -> 32 ms)."""
    n = oT.shape[1]
    out = np.empty((3, n)) if rows is None else rows
    shift = origin is not None and bool(origin.any())

    def block(s, e):
        X = _compose_t(oT[:, s:e], *_frames_t(VfT, NfT, cT[:, s:e], bT[:, s:e]), handed)
        if shift:
            X += origin[:, None]
        if rows is None:
            out[:, s:e] = X
        else:
            out[s:e] = X.T
    run_blocks(block, blocks(n, _ROW_BLOCK))
    return out


def _frames_t(VfT, NfT, cornersT, baryT):
    """:func:`frames` on transposed, contiguous (3, .) arrays (the fast layout:
    every operation runs on contiguous rows, in place where it can). Returns
    (point, tangent, bitangent, normal), each a new (3, q) array."""
    b0, b1, b2 = baryT[0], baryT[1], baryT[2]
    i0, i1, i2 = cornersT[0], cornersT[1], cornersT[2]
    point = np.take(VfT, i0, axis=1)              # np.take: 2-3x faster than VfT[:, i0]
    e1 = np.take(VfT, i1, axis=1)
    e1 -= point
    e2 = np.take(VfT, i2, axis=1)
    e2 -= point
    tmp = np.multiply(b1, e1)
    point += tmp                                   # a + b1 e1
    np.multiply(b2, e2, out=tmp)
    point += tmp                                   # ... + b2 e2
    normal = np.take(NfT, i0, axis=1)
    normal *= b0
    np.take(NfT, i1, axis=1, out=tmp)
    tmp *= b1
    normal += tmp
    np.take(NfT, i2, axis=1, out=tmp)
    tmp *= b2
    normal += tmp
    return _frames_finish(point, e1, e2, normal, tmp)


def _frames_finish(point, e1, e2, normal, tmp, size=None):
    """The rest of :func:`_frames_t` from the point, the face's edges
    ``e1``, ``e2``, the blended normal (not yet normalised) and a scratch
    (3, q) array; all are reused for the result. ``size`` (q,): the longer
    of ``e1`` and ``e2`` where the caller has it (the incremental deform
    computes it once per face: the same values), else computed here.

    Degenerate is relative to the face's size (the longer of ``e1`` and
    ``e2``), not to the edge itself: an edge between two corners at the same
    point is rounding noise some 1e-17 long, whose direction a rotation of
    the cage changes at random (a cage with a zero-area face, from a scan
    whose bow-tie vertex was split, refined 0.2% of its size off the rotated
    result where that noise was taken for a tangent)."""
    bad = _normalise_t(normal, 1.0)
    if size is None:
        size = _edges_size(e1, e2)
    if bad.any():
        fn = cross_columns(e1[:, bad], e2[:, bad])
        fbad = _normalise_t(fn, size[bad] * size[bad])
        fn[:, fbad] = np.array([[0.0], [0.0], [1.0]])
        normal[:, bad] = fn
    np.multiply(dot_columns(e1, normal), normal, out=tmp)
    tangent = e1
    tangent -= tmp                                 # e1 - (e1.n) n
    bad = _normalise_t(tangent, size)
    if bad.any():
        nb = normal[:, bad]
        t2 = e2[:, bad]
        t2 -= dot_columns(t2, nb) * nb
        bad2 = _normalise_t(t2, size[bad])
        if bad2.any():
            # any unit vector perpendicular to the normal
            nn = nb[:, bad2]
            axis = np.zeros_like(nn)
            axis[np.argmin(np.abs(nn), axis=0), np.arange(nn.shape[1])] = 1.0
            axis -= dot_columns(axis, nn) * nn
            _normalise_t(axis, 1.0)
            t2[:, bad2] = axis
        tangent[:, bad] = t2
    bitangent = tmp
    np.multiply(normal[1], tangent[2], out=bitangent[0])
    bitangent[0] -= normal[2] * tangent[1]
    np.multiply(normal[2], tangent[0], out=bitangent[1])
    bitangent[1] -= normal[0] * tangent[2]
    np.multiply(normal[0], tangent[1], out=bitangent[2])
    bitangent[2] -= normal[1] * tangent[0]
    return point, tangent, bitangent, normal


def _edges_size(e1, e2):
    """The longer of the edges ``e1``, ``e2`` (3, q) of each column, (q,):
    what :func:`_frames_finish` measures degeneracy against."""
    return np.maximum(_length_t(e1), _length_t(e2))


def _check_cage(binding, V_cage_edited, F_cage, where):
    """Check an edited cage against the binding; return it as float64."""
    if not isinstance(binding, Binding):
        raise InvalidArgumentError(f"{where}: expected a Binding, got {type(binding).__name__}")
    # (n,3) real numbers, finite: strings, booleans and complex numbers were taken
    Vc = check_vertices(V_cage_edited, where=where, name="V_cage_edited", copy=False)
    if Vc.shape[0] != binding.n_cage:
        raise TopologyMismatchError(
            f"{where}: the edited cage has {Vc.shape[0]} vertices but the binding was made for "
            f"{binding.n_cage} (fingerprint {binding.fingerprint}); rebind after changing the "
            f"cage's topology")
    if F_cage is not None:
        Fc = check_faces(F_cage, binding.n_cage, where=where)
        if Fc.shape != binding.F_cage.shape or not np.array_equal(Fc, binding.F_cage):
            raise TopologyMismatchError(
                f"{where}: the edited cage's faces {Fc.shape} differ from the bound cage's "
                f"{binding.F_cage.shape} (fingerprint {binding.fingerprint}); rebind after "
                f"changing the cage's topology")
    check_units(Vc, where=where, name="V_cage_edited")
    return Vc


def _normal_floor(step):
    """The length (float) under which a fine vertex normal's sum of area
    normals is none, for a cage whose size's power of two above is ``step``
    (:func:`_origin_and_step`): ``_NORMAL_FLOOR`` times its square."""
    return _NORMAL_FLOOR * step ** 2


def _binding_floor(binding):
    """:func:`_normal_floor` of the binding's rest cage: one value per
    binding, whatever the edit, so a full deform and every incremental one
    agree (it had followed the edited cage's size class: a cage collapsed
    and put back vertex by vertex deformed 2.5% of the diagonal apart from a
    full deform, rows kept from before a change of class); 0.0 for a binding
    without its rest cage (no floor: the normals as they sum)."""
    if binding.V_cage_rest is None:
        return 0.0
    return _normal_floor(_rest_origin(binding)[1])


def _vertex_normals_t(PT, F, floor=0.0, folds=None):
    """:func:`~.mesh.vertex_normals` in the transposed layout: positions
    (3, n) -> unit normals (3, n), area-weighted, zero where no face (or
    only degenerate ones) meets a vertex, where the sum of the area
    normals is not longer than ``floor`` (:func:`_normal_floor`), or where
    ``folds`` (n,) bool (:func:`_rest_folds`; None: nowhere) is set. The same
    operations in the same order (face normals as ``np.cross`` forms them,
    summed corner 0, 1, 2 with ``bincount``), so bit-identical to it above
    ``floor``, about 3x faster."""
    return _unit_columns(_area_sums_t(PT, F)[1], floor, folds)


def _normals_and_folds(PT, F, floor):
    """``(normals, folds)``: :func:`_vertex_normals_t` of a rest surface
    (positions ``PT`` (3, n), triangles ``F``) with its own
    :func:`_folds_of`, from one pass of area normals (a bind's)."""
    fn, summed = _area_sums_t(PT, F)
    folds = _fold_mask(fn, summed, F)
    return _unit_columns(summed, floor, folds), folds


def _area_sums_t(PT, F):
    """The area normals (3, m) of the triangles ``F`` (m,3) over the
    positions ``PT`` (3, n), and their sums at each vertex (3, n), summed
    corner 0, 1, 2 with ``bincount``."""
    n = PT.shape[1]
    i = [np.ascontiguousarray(F[:, k]) for k in range(3)]
    fn = area_normals_t(PT, tuple(i))
    out = np.empty((3, n))
    for k in range(3):
        out[k] = np.bincount(i[0], fn[k], n) + np.bincount(i[1], fn[k], n) \
            + np.bincount(i[2], fn[k], n)
    return fn, out


def _folds_of(PT, F):
    """The vertices (n,) bool of the triangles ``F`` over the positions
    ``PT`` (3, n) whose faces fold back onto each other: the sum of their
    area normals at most ``_NORMAL_CANCEL`` of the sum of those normals'
    lengths (and that sum not zero); None when there is none."""
    return _fold_mask(*_area_sums_t(PT, F), F)


def _fold_mask(fn, summed, F):
    """:func:`_folds_of` from the area normals ``fn`` (3, m) of ``F`` and
    their sums ``summed`` (3, n) at the vertices (:func:`_area_sums_t`)."""
    total = np.bincount(F.ravel(), np.repeat(_length_t(fn), 3), summed.shape[1])
    folds = (_length_t(summed) <= _NORMAL_CANCEL * total) & (total > 0)
    return folds if folds.any() else None


def _rest_folds(binding):
    """:func:`_folds_of` the binding's fine surface at rest (its rest cage
    subdivided, as :func:`bind` made it), the fine vertices whose normal is
    none in every frame of the binding; None without folds or without a rest
    cage (a binding restored without one keeps the normals there). Kept in
    its cache."""
    c = binding._cache
    if "folds" not in c:
        c["folds"] = None if binding.V_cage_rest is None else _folds_of(
            _fine_levels(binding, binding.V_cage_rest, _rest_origin(binding)[0])[-1],
            binding._operator.F_fine)
    return c["folds"]


def _unit_columns(out, floor=0.0, none=None):
    """``out`` (3, k) with every column scaled to unit length, in place;
    columns not longer than ``floor`` (zero ones too), and those ``none``
    (k,) bool marks (None: no other), become zero."""
    length = _length_t(out)
    ok = length > floor
    if none is not None:
        ok &= ~none
    np.divide(out, length, out=out, where=ok)
    out[:, ~ok] = 0.0
    return out


class _Geometry(NamedTuple):
    """The subdivided cage of the last deform, kept for incremental ones."""

    V_cage: np.ndarray   #: (n_cage,3) float64, the cage it was computed from
    levels: list         #: per level 0..L, positions transposed (3, n_l); 0 the cage
    normals: np.ndarray  #: (3, n_fine) fine vertex normals, valid where not ``stale``
    stale: np.ndarray    #: (n_fine,) bool: normal changed, not recomputed (no row reads it)
    origin: np.ndarray   #: (3,) the levels' positions are relative to it (_working_origin)
    floor: float         #: the normals' :func:`_normal_floor`

    @classmethod
    def of(cls, Vc, X, normals, origin, floor):
        return cls(Vc.copy(), X, normals, np.zeros(normals.shape[1], dtype=bool), origin, floor)


def _working_origin(Vc):
    """The point (3,) float64 the fine surface and the frames are computed
    relative to for the cage positions ``Vc`` (n,3): zero for a cage near the
    origin (within twice its size: the results bit for bit as without one),
    else the centre of its bounding box rounded to a multiple of the power
    of two just above its size.

    Frames come from differences of fine positions: at 1e6 from the origin
    each carried a rounding step of 1e6 (1.2e-10), which the offsets
    multiplied by their length over a fine edge (a scan at 1e5-1e6, or a cage
    moved a thousand sizes away, deformed 1e-10 to 1e-8 of its size off the
    rigid result). Relative to this origin the frames are as exact as near
    the origin, and the one rounding left is the output's own."""
    return _origin_and_step(Vc)[0]


def _origin_and_step(Vc):
    """:func:`_working_origin` and the power of two just above the cage's size."""
    if Vc.shape[0] == 0:
        return np.zeros(3), 1.0
    lo, hi = bounding_box(Vc)
    mid = 0.5 * (lo + hi)
    step = float(np.ldexp(1.0, int(np.frexp(max(float((hi - lo).max()), 1e-300))[1])))
    if float(np.abs(mid).max()) <= 2.0 * step:
        return np.zeros(3), step
    return np.round(mid / step) * step, step


def _deform_origin(binding, Vc):
    """The working origin of a deform or refine of the cage ``Vc``: the rest
    cage's (the bind's: the unedited cage gives the scan back to half a
    rounding step) while the edited cage's box centre stays within twice
    the rest cage's size of it, so an edit of some vertices changes no
    other row, not even by a rounding step (the origin of the edited cage
    itself moved with its box, and rows of a scan far from the origin that
    the edit does not reach changed in their last bit); else (the cage moved
    far away) the edited cage's own."""
    if binding.V_cage_rest is None:
        return _working_origin(Vc)
    origin, step = _rest_origin(binding)
    lo, hi = bounding_box(Vc)
    if float(np.abs(0.5 * (lo + hi) - origin).max()) <= 2.0 * step:
        return origin
    return _working_origin(Vc)


def _rest_origin(binding):
    """:func:`_origin_and_step` of the binding's rest cage (it has one),
    kept in its cache."""
    c = binding._cache
    if "rest_origin" not in c:
        c["rest_origin"] = _origin_and_step(binding.V_cage_rest)
    return c["rest_origin"]


def _fine_levels(binding, Vc, origin=None):
    """Positions of every level, transposed (3, n_l), level 0 the cage (the
    apply of :meth:`~.subdivide.SubdivisionOperator.apply`, its
    intermediates kept; the same values), relative to ``origin`` when given."""
    X = [np.ascontiguousarray(Vc.T)]
    if origin is not None:
        X[0] -= origin[:, None]
    for S in binding._operator.stencils:
        X.append(S.apply_t(X[-1]))
    return X


def _update_fine_geometry(binding, Vc, ids, hit, read=None):
    """Fine positions and normals (3, n_fine) for the cage ``Vc``, from the
    kept :class:`_Geometry` (callers hold ``_INCREMENTAL_LOCK``), and the
    origin (3,) the positions are relative to (the kept geometry's).

    When the kept cage differs from ``Vc`` at most at ``ids``, only what
    they move is recomputed, in place: each level's changed vertices
    (``hit.changed``) from their stencil rows over the level below, then the
    changed normals the rows read (``read``, distinct fine vertices; by
    default the corners of ``hit.faces``) from the faces around them
    (:func:`_normals_at`). A
    changed normal at a vertex with no bound dense vertex on its faces (a
    fine mesh denser than the dense one) is never read: it is only marked
    stale. Each value is recomputed from the level below, never updated
    by a difference, so nothing drifts over many updates (rows summed as
    the apply plan sums them: a full evaluation's values bit for bit).
    Otherwise (nothing kept yet, or another cage)
    everything is evaluated and kept."""
    c = binding._cache
    g = c.get("geometry")
    other = None
    if g is not None:
        other = (g.V_cage != Vc).any(axis=1)
        other[ids] = False
    origin = _deform_origin(binding, Vc)
    if g is None or other.any() or not np.array_equal(g.origin, origin):
        X = _fine_levels(binding, Vc, origin)
        floor = _binding_floor(binding)
        g = _Geometry.of(Vc, X, _vertex_normals_t(X[-1], binding._operator.F_fine, floor,
                                                  _rest_folds(binding)), origin, floor)
        c["geometry"] = g
        return g.levels[-1], g.normals, g.origin
    X = g.levels
    X[0][:, ids] = (Vc[ids] - g.origin).T
    g.V_cage[ids] = Vc[ids]
    _restencil(binding._operator, X, hit)
    VfT, NfT = X[-1], g.normals
    g.stale[hit.normals] = True
    idx = c["incremental"]
    if read is None:
        read = _distinct(np.take(idx["corners_t"], hit.faces, axis=1).ravel(), idx)
    redo = read[g.stale[read]]
    if redo.size:
        NfT[:, redo] = _normals_at(idx, VfT, redo, g.floor, _rest_folds(binding))
        g.stale[redo] = False
    return VfT, NfT, g.origin


def _restencil(op, X, hit):
    """Each level's changed positions (``hit.changed``) of the kept levels
    ``X`` recomputed in place from their stencil rows over the level below,
    each summed as the full deform's apply sums it (``Stencil.rows_t``:
    bit for bit; a sum of the rows' entries in another order had left them
    1e-16 apart, which the normals of fine faces an edit folds flat, rounding
    noise, turned into dense rows 0.4-2.5% of the diagonal apart)."""
    for S, r, below, level in zip(op.stencils, hit.changed, X[:-1], X[1:]):
        r = np.sort(r)
        level[:, r] = S.rows_t(below, r)


def _normals_at(idx, PT, vertices, floor, folds=None):
    """Unit normals (3, k) at the given fine vertices (each on at least one
    face), bit for bit :func:`_vertex_normals_t`'s there (with ``folds``): every face around
    them (from the fine vertex -> faces index, ascending) gets its normal
    once, and each vertex sums those where it is corner 0, 1 and 2 with
    ``bincount``, in face order, as there (the other corners go to a spare
    slot), then normalised as there (57k vertices at five levels: 8.1-8.8
    -> 7.9-8.4 ms, where a gather and ``np.add.reduceat`` per vertex gave
    the same to rounding only)."""
    counts = idx["vertex_count"][vertices]
    around = idx["faces_by_vertex"][ragged_entries(idx["vertex_start"][vertices], counts)]
    T = np.take(idx["corners_t"], _distinct(around, idx), axis=1)
    fn = area_normals_t(PT, T)
    k = vertices.shape[0]
    slot = idx["stamp"]
    slot[T] = k                                # every corner to the spare slot ...
    slot[vertices] = np.arange(k)              # ... but those asked for
    at = [slot[T[c]] for c in range(3)]
    out = np.empty((3, k + 1))
    for d in range(3):
        out[d] = np.bincount(at[0], fn[d], k + 1) + np.bincount(at[1], fn[d], k + 1) \
            + np.bincount(at[2], fn[d], k + 1)
    return _unit_columns(out[:, :k], floor,   # (a view: the spare slot left off)
                         None if folds is None else folds[vertices])


class _Rows(NamedTuple):
    """A sparse map as CSR rows (here: a stencil's structural transpose)."""

    indptr: np.ndarray  #: (n_rows + 1,) int64
    cols: np.ndarray    #: (nnz,) int64
    weights: np.ndarray  #: (nnz,) float64 (empty when only the structure is kept)
    n_out: int          #: number of columns (the map's outputs)


def _closest_on(index, P, report=None, point=False):
    """Closest points of ``P`` on an indexed mesh: (face (q,) int64, bary (q,3)
    float64), or with ``point`` the (q,3) points, queried in fixed blocks of
    :func:`_bind_blocks` on the worker threads (NumPy releases the GIL in
    the index's array work; the blocks depend on the size alone, so results
    do not depend on the number of threads), a round of blocks at a time,
    ``report(fraction)`` after each round."""
    face = np.empty(P.shape[0], dtype=np.int64)
    bary = np.empty((P.shape[0], 3))

    def query(start, stop):
        hit = index.closest(P[start:stop])
        face[start:stop] = hit.face
        bary[start:stop] = hit.point if point else hit.bary

    spans = _bind_blocks(P.shape[0])
    for i in range(0, len(spans), WORKERS):
        run_blocks(query, spans[i:i + WORKERS])
        if report is not None:
            report(spans[min(i + WORKERS, len(spans)) - 1][1] / P.shape[0])
    return bary if point else (face, bary)


class _DenseBound(NamedTuple):
    """Every dense vertex's fine face, corners, barycentric coordinates and
    offset, transposed as the binding's cache holds them (its ``bary`` and
    ``offset`` fields are views of these: no second layout to write and keep,
    48 bytes a dense vertex)."""

    face: np.ndarray        #: (n,) int64
    corners_t: np.ndarray   #: (3,n) int64 corners of each fine face
    bary_t: np.ndarray      #: (3,n) float64
    offset_t: np.ndarray    #: (3,n) float64
    nearest: object         #: (n_fine,) int64 nearest bound dense vertex (_NearSearch), or None


class _NearSearch(NamedTuple):
    """What the dense pass needs to find, for the local detail search, each
    fine vertex's nearest bound dense vertex (:func:`_nearest_parts`)."""

    P: np.ndarray       #: (n_fine,3) fine vertex positions (the frames' points)
    used: object        #: (n_dense,) bool, dense vertices on a face; None: all are


def _used_vertices(degree):
    """(n,) bool mask of the vertices some face uses (``degree``: the faces at
    each), or None when all are."""
    used = degree > 0
    return None if used.all() else used


def _bind_dense(query, V_dense, VfT, NfT, F_fine, ties, report=None, near=None, origin=None):
    """The :class:`_DenseBound` of the dense vertices: closest points on the
    fine surface (``query``, a :class:`~.near_query.NearQuery`), then the
    frame components of each vertex's offset from its point (the frames in
    the transposed layout of deform, bit-identical to :func:`frames`), block
    by block on the worker threads (fixed blocks, :func:`_bind_blocks`: results
    do not depend on the number of threads), ``report(fraction)`` as each
    block is done, in order (returning False cancels the blocks not yet
    started). With ``near`` (a :class:`_NearSearch`), each block also
    offers its vertices as the nearest bound ones of its faces' corners
    (:func:`_nearest_parts`), combined into ``nearest``. With ``origin``
    (3,), the fine surface is relative to it: so are the dense vertices,
    a block at a time (no copy of the whole dense mesh). ``ties``: the fine
    surface's :class:`_TieFaces`."""
    n = V_dense.shape[0]
    out = _DenseBound(np.empty(n, dtype=np.int64), np.empty((3, n), dtype=np.int64),
                      np.empty((3, n)), np.empty((3, n)), None)
    parts = []
    FfT = np.ascontiguousarray(F_fine.T)

    def block(start, stop):
        P = V_dense[start:stop] if origin is None else V_dense[start:stop] - origin
        hit = query.closest(P)
        face, bary = ties.canonical(hit.face, hit.bary)
        out.face[start:stop] = face
        corners = np.take(FfT, face, axis=1)
        bary = np.ascontiguousarray(bary.T)
        out.corners_t[:, start:stop] = corners
        out.bary_t[:, start:stop] = bary
        p, t, bt, nrm = _frames_t(VfT, NfT, corners, bary)
        d = np.array(P.T, order="C")      # a copy (one row: P.T was a view of V_dense)
        d -= p
        for k, axis in enumerate((t, bt, nrm)):
            out.offset_t[k, start:stop] = dot_columns(d, axis)
        if near is not None:
            return _nearest_parts(near, P, start, corners, hit.face, n)
        return None

    def run(span):
        return block(*span), span[1]

    for part, stop in each_in_order(run, _bind_blocks(n)):
        parts.append(part)
        if report is not None:
            report(stop / n)
    return out._replace(nearest=_nearest_of(parts, n)) if near is not None else out


#: a barycentric coordinate at most this is a point on the edge opposite its corner
#: (:class:`_TieFaces`)
_TIE_BARY = 1e-12


class _TieFaces(NamedTuple):
    """The face a point on a fine edge or vertex is bound to, whichever of
    the faces there the closest-point search named: the lowest-numbered. A
    frame's tangent is its face's first edge, so the faces at an edge give a
    point there different frames, and rounding chose between them: Suzanne
    bound again 1e3 units off (dense, cage and edit moved alike) moved 10 of
    its 507 vertices differently under an edit, up to 1.7e-4 of the diagonal
    (14% of the vertex's move)."""

    F: np.ndarray        #: (m,3) the fine faces
    across: np.ndarray   #: (m,3) the face across the edge opposite each corner (-1: none)
    lowest: np.ndarray   #: (n,) the lowest-numbered face at each fine vertex

    @classmethod
    def of(cls, F, n):
        lowest = np.full(n, np.iinfo(np.int64).max)
        np.minimum.at(lowest, F.ravel(), np.repeat(np.arange(F.shape[0]), 3))
        return cls(F, faces_across(F, n), lowest)

    def canonical(self, face, bary):
        """``(face, bary)`` (k,), (k,3) with every point on an edge (one
        coordinate at most ``_TIE_BARY``, which becomes 0: rounding left
        5.6e-17 where the same point moved away had 0) or at a corner (two)
        moved to the lowest-numbered face there, its coordinates on that
        face's corners (new arrays)."""
        small = bary <= _TIE_BARY
        zeros = row_sums(small)
        edge = np.flatnonzero(zeros == 1)
        corner = np.flatnonzero(zeros == 2)
        if not (edge.size or corner.size):
            return face, bary
        face, bary = face.copy(), np.where(small, 0.0, bary)
        bary /= row_sums(bary)[:, None]
        if edge.size:
            j = np.argmax(small[edge], axis=1)                    # the zero corner
            g = self.across[face[edge], j]
            take = (g >= 0) & (g < face[edge])
            self._move(face, bary, edge[take], g[take])
        if corner.size:
            j = np.argmax(bary[corner], axis=1)                   # the corner it is at
            g = self.lowest[self.F[face[corner], j]]
            self._move(face, bary, corner[g < face[corner]], g[g < face[corner]])
        return face, bary

    def _move(self, face, bary, rows, g):
        """Re-express the points ``rows`` on the faces ``g`` (in place): each
        of ``g``'s corners takes the coordinate of the same vertex (0 if the
        old face has none)."""
        old, new = self.F[face[rows]], self.F[g]
        b = bary[rows]
        moved = np.zeros_like(b)
        for k in range(3):
            moved += b[:, k:k + 1] * (new == old[:, k:k + 1])
        bary[rows] = moved
        face[rows] = g


def _bind_blocks(n):
    """The blocks of the bind's passes over ``n`` points: ``_BIND_BLOCK``
    each, or a quarter of them (at least ``_MIN_BIND_BLOCK``) when that is
    smaller; fixed by ``n`` alone (every point's answer is its own, and
    :func:`_nearest_of` combines blocks in any cut the same)."""
    return blocks(n, min(_BIND_BLOCK, max(_MIN_BIND_BLOCK, -(-n // 4))))


def _nearest_parts(near, V, start, corners, face, n_dense):
    """One block's offer for the nearest bound dense vertex of each fine
    vertex: the block's dense vertices ``start + i`` (positions ``V``, bound
    to ``face`` with ``corners`` (3, b)) paired with their face's corners,
    the smallest squared distance per fine vertex and, among the pairs at
    that distance, the smallest key ``face * n_dense + vertex`` (the order of
    the candidates the definition takes the first of). Returns (d2, key),
    each (n_fine,): inf / the largest int64 where the block offers none."""
    n_f = near.P.shape[0]
    vertex = np.arange(start, start + V.shape[0], dtype=np.int64)
    keep = slice(None) if near.used is None else near.used[vertex]
    j = corners[:, keep].ravel()
    k = np.tile(vertex[keep], 3)
    key = np.tile(face[keep], 3) * np.int64(n_dense) + k
    d = np.take(V, k - start, axis=0)
    d -= np.take(near.P, j, axis=0)
    d2 = _dot(d, d)
    best = np.full(n_f, np.inf)
    np.minimum.at(best, j, d2)
    low = np.full(n_f, np.iinfo(np.int64).max)
    at = d2 == best[j]
    np.minimum.at(low, j[at], key[at])
    return best, low


def _nearest_of(parts, n_dense):
    """The nearest bound dense vertex of each fine vertex (-1 for none) from
    the blocks' :func:`_nearest_parts` (in block order): the smallest squared
    distance over the blocks, the smallest key among the blocks at it."""
    none = np.iinfo(np.int64).max
    best = parts[0][0].copy()
    for d2, _ in parts[1:]:            # (in place: no (blocks, n_fine) stack)
        np.minimum(best, d2, out=best)
    key = np.full(best.shape[0], none)
    for d2, low in parts:
        np.minimum(key, low, out=key, where=d2 == best)
    return np.where(key == none, -1, key % n_dense)


def _reporter(progress, lo, hi):
    """``report(fraction)`` for a stage spanning ``lo..hi`` of ``progress``:
    raises :class:`~.errors.CancelledError` when it returns False (None when
    there is no ``progress``)."""
    if progress is None:
        return None

    def report(fraction):
        if stops(progress(lo + (hi - lo) * fraction)):
            raise CancelledError("bind: cancelled")
    return report


def _vertex_corners(F, n):
    """For every vertex, its first incident face and the barycentric
    coordinates selecting that vertex (a unit vector). Isolated vertices get
    face 0 and a corner that is not theirs (they have no frame)."""
    flat = F.ravel()
    first = np.full(n, flat.shape[0], dtype=np.int64)
    np.minimum.at(first, flat, np.arange(flat.shape[0], dtype=np.int64))
    first[first == flat.shape[0]] = 0
    face = first // 3
    bary = np.zeros((n, 3))
    bary[np.arange(n), first % 3] = 1.0
    return face, bary


def _normalise_creases(creases, where):
    """``creases`` as a (k,2) int64 array (None for None or none), checked
    as :func:`~._refine.crease_pairs` checks them."""
    return crease_pairs(creases, where)[1]


def _to_frame(d, fr):
    """Components of vectors ``d`` in the frames ``fr``, (q,3)."""
    return np.stack([_dot(d, fr.tangent), _dot(d, fr.bitangent), _dot(d, fr.normal)], axis=1)


def _compose_t(oT, point, tangent, bitangent, normal, handed=1.0):
    """Points ``point + o0 tangent + o1 bitangent + handed o2 normal`` from
    (3,q) inputs (``oT`` the components; ``handed`` -1 for a mirrored cage,
    :func:`_handedness`): ``point``, updated in place (the frame vectors are
    overwritten)."""
    tangent *= oT[0]
    point += tangent
    bitangent *= oT[1]
    point += bitangent
    normal *= oT[2]
    if handed < 0:
        np.negative(normal, out=normal)
    point += normal
    return point


def _handedness(binding, Vc):
    """-1.0 when the cage ``Vc`` is the rest cage mirrored as a whole (the
    least-squares linear map M between them, both centred, has a negative
    determinant and fills at least ``_MIRROR_CONDITION`` of the volume a
    conformal map of its size would: |det M| against (|M|_F / sqrt 3)^3),
    else 1.0. A frame's normal follows the faces' winding, which a mirror
    turns inside out while it keeps the tangent and the bitangent (``n x t``)
    as the mirror takes them: the detail's normal components are then turned
    back, and the mirrored cage gives the mirrored mesh (they went inward:
    bumps became dents). A flat cage has no such map (1.0: its mirror across
    its own plane does not move it; a binding without its rest cage,
    :meth:`Binding.from_arrays` without the repair's keys: 1.0 too). No
    LAPACK call (a 3x3 solve there costs milliseconds on a loaded machine:
    ``test_the_repair_maps_need_no_lapack_solve``)."""
    M = _rest_map(binding, Vc)
    if M is None:
        return 1.0
    det_m = float(M[0] @ np.cross(M[1], M[2]))
    size = float(np.sqrt((M * M).sum() / 3.0))
    return -1.0 if det_m < -_MIRROR_CONDITION * size ** 3 else 1.0


def _rest_map(binding, Vc):
    """The linear map M (3,3) that best takes the rest cage to the cage
    ``Vc`` as a whole (least squares about their centroids: ``Vc - mean ~
    (rest - mean) @ M.T``), from the rest's kept moments; None without a
    rest cage or for a flat one."""
    rest = _rest_moments(binding)
    if rest is None:
        return None
    X, adjugate, det_xx = rest
    return ((Vc - Vc.mean(axis=0)).T @ X) @ adjugate / det_xx


def _rest_moments(binding):
    """What :func:`_handedness` needs of the rest cage, computed once per
    binding (kept in its cache): the centred rest positions X, the adjugate
    of X^T X and its determinant; None without a rest cage or for a flat
    one (no linear map to the rest: no mirror to find)."""
    c = binding._cache
    if "rest_moments" not in c:
        rest = None
        if binding.V_cage_rest is not None:
            X = binding.V_cage_rest - binding.V_cage_rest.mean(axis=0)
            XX = X.T @ X
            adjugate = np.cross(XX[[1, 2, 0]], XX[[2, 0, 1]])          # rows: XX symmetric
            det_xx = float(XX[0] @ adjugate[0])
            if det_xx > 1e-12 * float(np.trace(XX)) ** 3:
                rest = (X, adjugate, det_xx)
        c["rest_moments"] = rest
    return c["rest_moments"]


def _dot(a, b):
    return a[:, 0] * b[:, 0] + a[:, 1] * b[:, 1] + a[:, 2] * b[:, 2]


def _length_t(v):
    return np.sqrt(dot_columns(v, v))


def _normalise_t(v, reference):
    """Normalise the columns of the (3,q) ``v`` in place; return the mask of
    columns shorter than ``_DEGENERATE`` times ``reference`` (scalar or per
    column), which are left as they are."""
    length = _length_t(v)
    bad = ~(length > _DEGENERATE * reference)
    length[bad] = 1.0
    v /= length
    return bad
