"""Turn a mesh as scans arrive into a clean manifold surface, and map back.

Real scans come unwelded (STL, PLY/glTF split at seams), with bow-tie
vertices, edges shared by three or more faces, double-sided sheets, specks of
debris and degenerate clusters. :func:`clean_mesh` turns any of them into an
edge- and vertex-manifold triangle mesh that :func:`~.simplify.simplify`,
:func:`~.subdivide.subdivide`, :func:`~.fit.fit_cage` and
:func:`~.binding.bind` accept, and says what it did::

    drop faces with a repeated vertex index
    weld   vertices on open or non-manifold edges (or edges closed only by a
           copy of their face: a soup made double-sided in place) or on
           collapsed faces (no taller than weld_distance, nor than
           FLAT_SHARE of the tallest face) that coincide (exactly, or within
           weld_distance of the mesh's size, :func:`bulk_box`: soups, seams,
           collapsed clusters), and the ends of edges that short
    drop   faces degenerate after welding; of faces on the same three
           vertices keep one, or none when both orientations are there
           (a double-sided sheet) unless one side is what mends the surface;
           of a quad triangulated both ways (inside the surface) keep one way
    pair   the faces around every non-manifold edge into manifold sheets
           (consistent orientation first, then the flattest pair); the faces
           left over see the edge as a border
    split  every vertex whose faces form several fans (bow-ties, and the
           ends of the edges just cut) into one vertex per fan
    orient each component consistently: outward (positive enclosed volume)
           when its faces disagree and it is closed, or its orientations
           are near a tie with a clear inside (random per-face winding);
           else the majority's orientation wins (a consistent component,
           even inside-out, is left as it came)
    drop   debris: components whose area is below min_component_area of the
           largest component's (unless they hold many faces: DEBRIS_MAX_FACES)
    drop   coincident copies: components whose vertices all coincide (within
           weld_distance) with vertices of another one, and, when the weld
           leaves non-manifold edges, pieces lying on another face for face
           before it (:mod:`core.copies`)
    zip    T-junctions: border loops of zero width (a vertex on a
           neighbour's edge, within weld_distance), each closed by splitting
           the face across it (:func:`~.pinholes.zip_slits`)
    drop   unreferenced vertices

Nothing is averaged or moved: every output vertex sits exactly on an input
vertex (``clean_to_input``), and every output face is an input face
(``face_to_input``), possibly flipped and with split vertices, or a part
of one split at a T-junction. A mesh that is
already clean comes back with the same vertices and faces in the same order.

Welding looks at four grids of cell ``4 weld_distance``, each shifted by a
quarter cell along the diagonal: two vertices closer than ``weld_distance``
along every axis share a cell in at least one grid (each axis can separate
them in at most one grid), and vertices merge through shared cells. So every
pair within ``weld_distance`` is welded, and no pair farther apart than
``4 weld_distance`` per axis is welded directly (chains can reach farther in
clusters denser than that, which is what a degenerate cluster is).
"""

from dataclasses import asdict, dataclass, fields
from typing import NamedTuple

import numpy as np

from ._clean import (BOUNDARY, NON_MANIFOLD, coincident_pairs, corner_fans, face_keys,
                     half_edge_ends, interior_edges, non_manifold_vertices, renumber_twins,
                     twin_table)
from ._groups import member_of, ragged_entries, sorted_unique
from ._parallel import blocks, run_blocks, run_each
from .errors import InvalidMeshError
from .mesh import (any_in_rows, bounding_box, check_count, check_mesh, check_number,
                   check_vertex_mask, cross_rows, diagonal_length, face_areas, face_normals,
                   flat_faces, row_sums)
from .topology import connected_labels, edge_keys, face_components
from .copies import coincident_copies, doubled_quads, pillow_layers, stacked_copies
from .pages import plain_pages
from .pinholes import zip_slits

_WHERE = "clean_mesh"

#: defaults of :func:`clean_mesh` (relative to the mesh's size, the diagonal of its
#: :func:`bulk_box` / the largest component's area)
WELD_DISTANCE = 1e-6
MIN_COMPONENT_AREA = 1e-4
#: with the automatic weld distance: when welding at ``WELD_DISTANCE`` leaves more
#: than ``OPEN_SHARE`` of the half-edges open (a soup whose copies of a vertex drifted
#: apart, a seam-split export), each wider distance in turn, kept while it closes at
#: least half of the open ones (a scan's own holes do not close: it is not kept).
#: A rocker-arm soup jittered by 1e-6 of its size kept 7% of its half-edges open, by
#: 3e-6 or more every one (the budget's debris rule then left 3 of its 20,088 faces)
WIDER_WELDS = (1e-5, 1e-4)
OPEN_SHARE = 0.005
#: ... and a wider weld is not kept when it collapses more than this share of the faces
#: (a strip 0.5 high and 20,000 long, open along its whole length, was welded into
#: nothing at 1e-4 of its size: 'nothing is left after cleaning')
WIDER_WELD_LOSS = 0.1
#: the face budget's debris rule drops its components only when together they hold at
#: most this share of the total area: beyond, they are the mesh itself in pieces, not
#: specks, and are kept (simplify then says how far it could go and why)
BUDGET_DEBRIS_SHARE = 0.1
#: a component with more faces than both of these (a count, a share of the faces) is
#: never debris, however small its area: a sphere of 20,480 faces sharing a vertex with
#: one stray triangle 1,000 times its size was dropped as debris of that triangle (the
#: cage was the triangle, "on target"), a 9,408-face detail of a part 1e4 times larger too
DEBRIS_MAX_FACES = 1000
DEBRIS_MAX_FACE_SHARE = 0.01


@dataclass(frozen=True)
class CleanReport:
    """What :func:`clean_mesh` changed, as counts (all 0 for a clean mesh)."""

    n_welded_vertices: int = 0        #: input vertices merged into another one
    n_degenerate_faces: int = 0       #: faces with a repeated vertex (also after welding), or flat on a border
    n_duplicate_faces: int = 0        #: faces on the same vertices as a kept one
    n_doubled_quads: int = 0          #: quads triangulated both ways: one way dropped (2 faces each)
    n_double_sided_sheets: int = 0    #: face sets with both orientations, all removed ...
    n_double_sided_faces: int = 0     #: ... with this many faces
    n_non_manifold_edges: int = 0     #: edges with more than two faces, cut into sheets
    n_split_vertices: int = 0         #: bow-tie vertices split, one vertex per fan ...
    n_added_vertices: int = 0         #: ... adding this many vertices
    n_detached_faces: int = 0         #: faces cut loose where pairing could not resolve an edge
    n_flipped_faces: int = 0          #: faces turned to agree with their component
    n_non_orientable_components: int = 0  #: one-sided components (a Moebius strip), cut open ...
    n_seam_edges: int = 0             #: ... along this many edges, so they can be oriented
    n_debris_components: int = 0      #: tiny components dropped ...
    n_debris_faces: int = 0           #: ... with this many faces
    n_copies: int = 0                 #: pieces lying on another (vertex or face for face), dropped ...
    n_copy_faces: int = 0             #: ... with this many faces
    n_unreferenced_vertices: int = 0  #: vertices no kept face uses
    n_pinholes: int = 0               #: holes too small for one cage face, capped (by simplify) ...
    n_pinhole_faces: int = 0          #: ... with this many faces
    n_t_junctions: int = 0            #: zero-width holes along a face's edge, zipped
    #: the weld distance used (share of the diagonal): ``WELD_DISTANCE``, or wider
    #: when the automatic weld found the input in pieces (see :func:`clean_mesh`)
    weld_distance: float = WELD_DISTANCE
    #: whether the automatic weld (``weld_distance=None``) went wider than
    #: ``WELD_DISTANCE``: the input came in pieces
    weld_widened: bool = False

    def to_dict(self):
        """The counts as a plain ``dict`` (for JSON reports)."""
        return asdict(self)

    def __bool__(self):
        return any(getattr(self, f.name) for f in fields(self) if f.name.startswith("n_"))

    def summary(self):
        """One line of what was done, e.g. ``"welded 4,012 vertices, split 3
        bow-tie vertices, removed 2 double-sided sheets (4 faces)"``; empty when
        nothing was."""
        parts = []

        def add(count, text, extra=""):
            if count:
                parts.append(f"{text.format(f'{count:,}')}{extra}")

        within = f" (within {self.weld_distance:g} of the size" if self.weld_distance != WELD_DISTANCE \
            else ""
        add(self.n_welded_vertices, "welded {} vertices",
            within + (": the input came in pieces)" if self.weld_widened else ")" if within else ""))
        add(self.n_non_manifold_edges, "cut {} non-manifold edges into sheets")
        add(self.n_split_vertices, "split {} bow-tie vertices")
        add(self.n_double_sided_sheets, "removed {} double-sided sheets",
            f" ({self.n_double_sided_faces:,} faces)")
        add(self.n_debris_components, "dropped {} debris components",
            f" ({self.n_debris_faces:,} faces)")
        add(self.n_copies, "dropped {} coincident copies", f" ({self.n_copy_faces:,} faces "
            "lying on other parts of the mesh)")
        add(self.n_t_junctions, "zipped {} T-junctions")
        add(self.n_pinholes, "closed {} pinholes", f" ({self.n_pinhole_faces:,} faces)")
        add(self.n_degenerate_faces, "removed {} degenerate faces")
        add(self.n_duplicate_faces, "removed {} duplicate faces")
        add(self.n_doubled_quads, "removed {} quads triangulated both ways",
            f" ({2 * self.n_doubled_quads:,} faces)")
        add(self.n_detached_faces, "detached {} faces")
        add(self.n_flipped_faces, "flipped {} faces to a consistent orientation")
        add(self.n_non_orientable_components, "cut {} one-sided (non-orientable) components open",
            f" along {self.n_seam_edges:,} edges to orient them")
        add(self.n_unreferenced_vertices, "dropped {} unreferenced vertices")
        return ", ".join(parts)


class CleanResult(NamedTuple):
    """What :func:`clean_mesh` returns.

    ``input_to_clean[i]`` is a clean vertex at input vertex ``i``'s position
    (``-1`` when no kept face uses it; a split vertex maps to its first fan's
    copy); ``clean_to_input[j]`` the input vertex clean vertex ``j`` sits on;
    ``face_to_input[f]`` the input face clean face ``f`` comes from. ``twin``
    is the clean faces' half-edge twin table (``core._clean.twin_table``,
    never ``NON_MANIFOLD``); ``area[f]`` the area of input face
    ``face_to_input[f]`` as it came, in units of the squared bounding-box
    diagonal (the debris test's measure).
    """

    V: np.ndarray               #: (n,3) float64
    F: np.ndarray               #: (m,3) int64
    input_to_clean: np.ndarray  #: (n_in,) int64
    clean_to_input: np.ndarray  #: (n,) int64
    face_to_input: np.ndarray   #: (m,) int64
    twin: np.ndarray            #: (3m,) int64
    area: np.ndarray            #: (m,) float64
    report: CleanReport


class CleanedInput(NamedTuple):
    """A mesh as a cleaning left it: ``simplify``'s input
    (:attr:`~.simplify.SimplifyResult.cleaned`), which ``fit_cage`` takes
    with ``clean=False``."""

    V: np.ndarray   #: (n,3) float64, in the input's units
    F: np.ndarray   #: (m,3) int64


@plain_pages
def clean_mesh(V, F, *, weld_distance=None, min_component_area=MIN_COMPONENT_AREA,
               face_budget=None, protected=None):
    """Clean a triangle mesh into an edge- and vertex-manifold surface.

    Parameters
    ----------
    V : (n,3) float array_like
    F : (m,3) int array_like
    weld_distance : float >= 0 or None
        Vertices on open or non-manifold edges closer than this share of the
        mesh's size (the diagonal of :func:`bulk_box`: a speck far off does not
        count) along every axis are welded; exact duplicates
        always are (also with 0); so are the two ends of an edge that short,
        and the corners of faces no taller than it and than ``FLAT_SHARE`` of
        the tallest face (collapsed clusters).
        Other vertices inside a closed surface are not welded: two of them at
        one place are two sheets touching, which is already manifold.
        None (the default): ``WELD_DISTANCE``, or when that leaves more than
        ``OPEN_SHARE`` of the half-edges open, the first of ``WIDER_WELDS``
        that closes at least half of them (then the next, likewise); the
        report's ``weld_distance`` says which was used.
    min_component_area : float >= 0
        Components whose area is below this share of the largest
        component's area are debris and dropped (0 keeps everything).
    face_budget : int >= 0, optional
        The face count the mesh is meant for (``simplify``'s target):
        components too small to get one face of it, by their share of the
        total area, are debris too (they cannot be represented, and each
        would take at least one face, four when closed), unless together they
        hold more than ``BUDGET_DEBRIS_SHARE`` of the total area. A component
        with more than ``DEBRIS_MAX_FACES`` faces and ``DEBRIS_MAX_FACE_SHARE``
        of them is never debris (the bulk of a mesh beside a stray huge face).
    protected : (n,) bool, optional
        Components with a protected vertex (e.g. a locked one) are never
        debris, and a vertex welded with a protected one sits where the
        first protected one of its weld group is (its ``clean_to_input``).

    Returns
    -------
    CleanResult

    Raises
    ------
    InvalidMeshError
        Malformed input (shapes, NaN coordinates, indices out of range).
    InvalidArgumentError
        A negative or non-finite tolerance, ``face_budget`` not an integer
        >= 0, ``protected`` not one flag per vertex.

    Examples
    --------
    >>> V = [[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]]
    >>> r = clean_mesh(V, [[0, 1, 2], [3, 4, 5]])          # two unwelded triangles
    >>> r.F.tolist(), r.report.summary()
    ([[0, 1, 2], [1, 3, 2]], 'welded 2 vertices')
    """
    V, F = check_mesh(V, F, where=_WHERE)
    face_budget, protected = _checked_options(weld_distance, min_component_area, face_budget,
                                              protected, V.shape[0])
    used = np.zeros(V.shape[0], dtype=bool)
    used[F.ravel()] = True
    on_faces = V if used.all() else V[used]
    check_span(on_faces, where=_WHERE)
    box = bulk_box(on_faces)
    del on_faces
    w = _Work.of(V, F)
    weld, area = _weld_stage(w, box, weld_distance, protected)
    _drop_repeated_faces(w)
    to_input, inner, turned = _manifold_stage(w)
    inner, turned = _drop_flat_ears(w, inner, turned)
    protected_in = protected
    if protected is not None:
        # a weld group is protected when any of its vertices is (to_input: the groups' reps)
        grouped = np.zeros_like(protected)
        grouped[weld.rep[protected]] = True
        protected = grouped[to_input]
    # areas of the faces as they came (welds move corners by at most weld_distance)
    area, labels, turned = _debris_stage(w, area[w.faces], inner, float(min_component_area),
                                         face_budget, protected, turned)
    del inner
    _copies_stage(w, labels, area, box, weld.distance, protected, turned)
    _slits_stage(w, weld.distance * diagonal_length(*box))
    V, F, input_to_clean, clean_to_input = _compact(w.V, w.F, to_input, weld.rep)
    if protected_in is not None:
        V, clean_to_input = _on_protected(V, clean_to_input, w.V, weld.rep, protected_in)
    return CleanResult(V, F, input_to_clean, clean_to_input, w.faces, w.twin, w.area,
                       CleanReport(**w.counts))


def check_span(V, *, where):
    """Raise :class:`InvalidMeshError` (named ``where``) when the positions
    ``V`` (the ones the faces use) span more than the largest float along an axis: their
    differences are infinite, and every face came out degenerate ('nothing
    is left after cleaning ... (welded 158 vertices, removed 320 degenerate
    faces)' for a sphere of radius 1e308)."""
    lo, hi = bounding_box(V)
    with np.errstate(over="ignore"):
        span = hi - lo
    if not np.isfinite(span).all():
        raise InvalidMeshError(
            f"{where}: the mesh spans from {lo.min():.3g} to {hi.max():.3g}, beyond what floats "
            f"can subtract (about 1.8e308): scale it down first")


def _checked_options(weld_distance, min_component_area, face_budget, protected, n):
    """:func:`clean_mesh`'s options checked: ``(face_budget, protected)``
    as it takes them (``n`` vertices)."""
    for name, value in (("weld_distance", WELD_DISTANCE if weld_distance is None else weld_distance),
                        ("min_component_area", min_component_area)):
        check_number(value, where=_WHERE, name=name, lo=0)   # (2**64 was a raw TypeError)
    if face_budget is not None:
        face_budget = check_count(face_budget, where=_WHERE, name="face_budget")
    if protected is not None:
        protected = check_vertex_mask(protected, n, where=_WHERE, name="protected")
    return face_budget, protected


@dataclass
class _Work:
    """The mesh between :func:`clean_mesh`'s stages, and what they found.

    ``faces`` maps each current face to its input face; ``corners`` counts
    the corners of the input faces at each vertex while ``F`` is the input's
    (None once a stage changes it); ``area`` is the area of each current face
    as it came (set by :func:`_debris_stage`); ``counts`` are the report's."""

    V: np.ndarray
    F: np.ndarray
    faces: np.ndarray
    corners: object
    counts: dict
    twin: np.ndarray = None
    area: np.ndarray = None

    @classmethod
    def of(cls, V, F):
        """The input as the stages start from it: faces with a repeated
        vertex index dropped (counted)."""
        corners = np.bincount(F.ravel(), minlength=V.shape[0])
        counts = {"n_unreferenced_vertices": int(V.shape[0] - np.count_nonzero(corners))}
        faces = np.arange(F.shape[0], dtype=np.int64)
        bad = _degenerate(F)
        counts["n_degenerate_faces"] = int(np.count_nonzero(bad))
        w = cls(V, F, faces, corners, counts)
        if counts["n_degenerate_faces"]:
            w.keep(~bad, twin=False)
        return w

    def keep(self, kept, twin=True):
        """Keep the faces ``kept`` (a mask); their twin table made again
        (``twin`` True), kept as it is (False: not made yet) or given."""
        self.F, self.faces, self.corners = self.F[kept], self.faces[kept], None
        if twin is True:
            self.twin = twin_table(self.F, self.V.shape[0])
        elif twin is not False:
            self.twin = twin


def _weld_stage(w, box, weld_distance, protected):
    """Weld ``w`` (:func:`_welded`; with pieces stacked on others dropped
    first when the weld leaves non-manifold edges, :func:`_stacked`, and the
    weld made again). Returns the :class:`_Welded` and the area of every
    input face as it came."""
    n = w.V.shape[0]
    # the twin table and the faces' shape are independent: side by side
    twin, shape = run_each(lambda job: job(), [lambda: twin_table(w.F, n),
                                                lambda: _shape(w.V, w.F, box)])
    area = np.zeros(w.faces[-1] + 1 if w.faces.size else 0)
    area[w.faces] = shape.area                             # per input face, as it came
    weld = _welded(shape, w.F, twin, w.faces, weld_distance)
    stacked, found = _stacked(shape, w.F, weld, protected)
    w.counts.update(found)
    if stacked is not None:
        w.keep(~stacked, twin=False)
        twin = twin_table(w.F, n)
        shape = shape._replace(area=shape.area[~stacked], height=shape.height[~stacked])
        weld = _welded(shape, w.F, twin, w.faces, weld_distance)
    w.counts["n_welded_vertices"] = int(np.count_nonzero(weld.rep != np.arange(n)))
    w.counts["weld_distance"] = weld.distance
    w.counts["weld_widened"] = weld_distance is None and weld.distance > WELD_DISTANCE
    w.counts["n_degenerate_faces"] += weld.n_degenerate
    if weld.F is not w.F:
        w.F, w.faces, w.corners = weld.F, weld.faces, None
    w.twin = weld.twin
    return weld, area


def _drop_repeated_faces(w):
    """Of faces on the same three vertices keep one, or none (a
    double-sided sheet): :func:`_unique_faces`; of a quad triangulated both
    ways keep one way (:func:`~.copies.doubled_quads`)."""
    keep, found = _unique_faces(w.F, w.twin, w.V)
    w.counts.update(found)
    if not keep.all():
        w.keep(keep)
    quads = doubled_quads(w.F, w.twin)
    w.counts["n_doubled_quads"] = 0 if quads is None else int(np.count_nonzero(quads)) // 2
    if quads is not None:
        w.keep(~quads)


def _manifold_stage(w):
    """Pair the faces around non-manifold edges and split multi-fan vertices
    (:func:`_make_manifold`), orient each component (:func:`_orient`) and
    split the vertices at the seams orienting leaves. Returns the input
    vertex of each vertex, the interior-edge mask and, when the orientation
    turned faces, which (a pillow's layer to drop is the turned one)."""
    w.V, w.F, w.twin, to_input, found = _make_manifold(w.V, w.F, w.twin, w.corners)
    w.counts.update(found)
    inner = interior_edges(w.twin)
    unoriented = w.F
    w.F, w.twin, found = _orient(w.V, w.F, w.twin, inner)
    turned = (w.F != unoriented).any(axis=1) if found["n_flipped_faces"] else None
    w.counts.update(found)
    if found["n_seam_edges"]:
        # the seam's edges are open in twin: their ends get one vertex per side
        w.V, w.F, to_input, _, _ = _split_fans(w.V, w.F, w.twin, to_input)
        w.twin = twin_table(w.F, w.V.shape[0])
    if found["n_flipped_faces"] or found["n_seam_edges"]:
        inner = interior_edges(w.twin)
    return to_input, inner, turned


def _drop_flat_ears(w, inner, turned):
    """Drop the faces with no area (:func:`_flat_faces`) and two open edges:
    a flat ear on a border edge (three collinear border vertices, or a fin
    folded flat onto an edge that had one face), which stayed in the surface
    and in a cage at or above the cleaned face count. Counted as degenerate.
    Returns the interior edges and the ``turned`` mask of the faces kept."""
    ears = row_sums(w.twin.reshape(-1, 3) < 0) >= 2
    cand = np.flatnonzero(ears)
    ears[cand] = flat_faces(w.V, w.F[cand])
    if not ears.any() or ears.all():                # (all flat: simplify names that)
        return inner, turned
    w.counts["n_degenerate_faces"] += int(np.count_nonzero(ears))
    w.keep(~ears)
    return interior_edges(w.twin), None if turned is None else turned[~ears]


def _debris_stage(w, area, inner, min_component_area, face_budget, protected, turned):
    """Drop the debris components (:func:`_debris`; ``area``: the current
    faces' areas as they came). Returns the kept faces' areas, component
    labels and ``turned`` mask."""
    keep, found, labels = _debris(area, w.F, inner, min_component_area, face_budget, protected)
    w.counts.update(found)
    if not keep.all():
        w.keep(keep, twin=_keep_twins(w.twin, keep))
        area, labels = area[keep], labels[keep]
        turned = None if turned is None else turned[keep]
    w.area = area
    return area, labels, turned


def _copies_stage(w, labels, area, box, distance, protected, turned):
    """Drop the coincident copies (:func:`_copies`), unless that would leave
    a non-manifold vertex."""
    copies, found = _copies(w.V, w.F, w.twin, labels, area, box, distance, protected,
                            pillows=w.counts["n_welded_vertices"] > 0, turned=turned)
    if copies is None:
        return
    # (a pillow's layers share its rim edges: the twins are found again, not renumbered)
    kept = ~copies
    twin_kept = twin_table(w.F[kept], w.V.shape[0])
    if not non_manifold_vertices(w.F[kept], w.V.shape[0], twin_kept).any():    # else: kept
        w.keep(kept, twin=twin_kept)
        w.area = area[kept]
        for name, value in found.items():
            w.counts[name] += value


def _slits_stage(w, distance):
    """Zip the T-junctions (:func:`~.pinholes.zip_slits`, vertices within
    ``distance``, in mesh units, of a face's edge): the parts of a split face
    map to its input face and keep its area. Up to ``SLIT_ROUNDS`` rounds
    while slits are left: a face with slits on two of its edges, or whose
    third vertex is on a slit, is zipped in a later one."""
    for _ in range(SLIT_ROUNDS):
        slits = zip_slits(w.V, w.F, w.twin, distance)
        if slits is None:
            return
        w.F, w.twin, w.corners = slits.F, slits.twin, None
        w.faces = np.concatenate([w.faces, w.faces[slits.parent]])
        w.area = np.concatenate([w.area, w.area[slits.parent]])
        w.counts["n_t_junctions"] = w.counts.get("n_t_junctions", 0) + slits.n_slits
        if slits.n_left == 0:
            return


#: rounds of :func:`_slits_stage` (each zips at most one slit per face)
SLIT_ROUNDS = 4


#: a face is collapsed (its corners weld) only when no taller than the weld distance
#: and than this share of the tallest face: a clean cow stretched 100,000 times along x
#: had most of its faces below the weld distance and lost 81% of them (the tallest, not
#: a median: a cluster collapsed to a point can be most of a mesh's faces)
FLAT_SHARE = 0.01
#: the mesh's size leaves out this share of the vertices at each end of every axis
BULK_SHARE = 0.01
#: ... found on at most this many of them (evenly by index)
BULK_SAMPLE = 1 << 16


def bulk_box(V):
    """Corners ``(lo, hi)`` of the box of the bulk of the points ``V`` (n,3):
    per axis, from the ``BULK_SHARE`` to the ``1 - BULK_SHARE`` quantile (of
    at most ``BULK_SAMPLE`` of them, evenly by index); the whole bounding box
    when that box is a point. Its diagonal is the mesh's size, the unit of
    :func:`clean_mesh`'s tolerances: a speck far off, which the bounding box
    would stretch (one stray triangle 1,000 diagonals away made the weld
    distance 1e-3 of the scan and welded away 965 of the bunny's faces), is
    left out.

    Examples
    --------
    >>> V = np.vstack([np.random.default_rng(0).random((1000, 3)), [[1e6, 1e6, 1e6]]])
    >>> lo, hi = bulk_box(V)
    >>> bool((hi < 1.0).all()), bool((lo > 0.0).all())
    (True, True)
    """
    V = np.asarray(V, dtype=np.float64)
    if V.shape[0] == 0:
        return bounding_box(V)
    sample = V[::max(1, V.shape[0] // BULK_SAMPLE)]
    k = int(BULK_SHARE * (sample.shape[0] - 1))
    cols = np.partition(sample, [k, sample.shape[0] - 1 - k], axis=0)
    lo, hi = cols[k].copy(), cols[sample.shape[0] - 1 - k].copy()
    return (lo, hi) if diagonal_length(lo, hi) > 0 else bounding_box(V)


def _degenerate(F):
    """Faces with a repeated vertex index, (m,) bool."""
    return (F[:, 0] == F[:, 1]) | (F[:, 1] == F[:, 2]) | (F[:, 0] == F[:, 2])


class _Welded(NamedTuple):
    """The faces after a weld (:func:`_weld`)."""

    rep: np.ndarray     #: (n,) the weld's representative of every vertex
    F: np.ndarray       #: the faces welded, degenerate ones dropped (``F`` itself: no weld)
    faces: np.ndarray   #: input face of each
    twin: np.ndarray    #: their twin table
    n_degenerate: int   #: faces degenerate after the weld (dropped)
    distance: float     #: the weld distance


def _weld(shape, F, twin, faces, distance):
    """The :class:`_Welded` faces ``F`` (twin table ``twin``, input faces
    ``faces``) at the weld distance ``distance``."""
    n = shape.V.shape[0]
    rep = _weld_map(shape, F, twin, distance)
    if not (rep != np.arange(n)).any():
        return _Welded(rep, F, faces, twin, 0, distance)
    W = rep[F]
    bad = _degenerate(W)
    return _Welded(rep, W[~bad], faces[~bad], twin_table(W[~bad], n),
                   int(np.count_nonzero(bad)), distance)


def _welded(shape, F, twin, faces, weld_distance):
    """:func:`_weld` at ``weld_distance``, or :func:`_automatic_weld` when None."""
    if weld_distance is not None:
        return _weld(shape, F, twin, faces, float(weld_distance))
    return _automatic_weld(shape, F, twin, faces)


def _stacked(shape, F, weld, protected):
    """The faces of pieces stacked on others (:func:`~.copies.stacked_copies`;
    None when there is none) and the counts for the report. Looked for only
    when the faces ``weld`` (:class:`_Welded`) leaves have non-manifold
    edges (a copy welded to its original at the rims of two holes an edge
    apart gives that edge four faces); other copies the weld leaves whole
    or makes a pillow, and :func:`_copies` finds them. A seam-split scan,
    welded into a manifold, pays nothing (looking anyway took 0.15 s of a
    1.1M-face one in 8 pieces)."""
    found = {"n_copies": 0, "n_copy_faces": 0}
    if not (weld.twin == NON_MANIFOLD).any():
        return None, found
    drop = stacked_copies(shape.V, F, shape.area, weld.distance, protected)
    if drop is None:
        return None, found
    found["n_copies"] = int(sorted_unique(face_components(F, shape.V.shape[0])[0][drop]).shape[0])
    found["n_copy_faces"] = int(np.count_nonzero(drop))
    return drop, found


def _automatic_weld(shape, F, twin, faces):
    """:func:`_weld` at ``WELD_DISTANCE``, then each of ``WIDER_WELDS`` in
    turn while the weld kept leaves more than ``OPEN_SHARE`` of the
    half-edges open: a wider weld is kept when it closes at least half of
    them and collapses at most ``WIDER_WELD_LOSS`` of the faces. One that
    does not is passed over, not the end: a soup whose
    copies drifted by 2e-5 to 5e-5 of its size closes a few percent at
    1e-5 (a pair welds only when every axis is within the distance) and
    all at 1e-4 (homer's soup stayed 12,000 one-face pieces). Open edges of
    faces the wider weld collapses are not counted as closed by it: a scan
    with a halo of floating specks 1e-5 of its size across welded them to
    points at 1e-5 and said the input came in pieces. Half of the open
    half-edges it could close, that is: those with an end it joins to
    another vertex (:func:`_joining_ends`); the others' borders stay open at
    any weld: a bunny soup drifted by 1e-6 of its size with 3,000 two-face
    specks of 1e-3 beside it, their 12,000 border half-edges counted, closed
    11,886 of 24,109 at 1e-5, was left at 1e-6 (2,048 border loops, 149 of
    its own pieces dropped as debris, simplify stopped at 963 faces of 50)."""
    best = _weld(shape, F, twin, faces, WELD_DISTANCE)
    for distance in WIDER_WELDS:
        open_best = _open_half_edges(best)
        if np.count_nonzero(open_best) <= OPEN_SHARE * best.twin.size:
            break
        wider = _weld(shape, F, twin, faces, distance)
        # closed by joining: open half-edges of faces the wider weld keeps (by input face)
        # that it leaves no longer open; at least half of the open ones it could close
        kept_open = np.count_nonzero(open_best.reshape(-1, 3)[member_of(best.faces, wider.faces)])
        joined = kept_open - np.count_nonzero(_open_half_edges(wider))
        closable = np.count_nonzero(open_best & _joining_ends(best, wider))
        if 0 < joined and joined >= 0.5 * closable and \
                wider.n_degenerate - best.n_degenerate <= WIDER_WELD_LOSS * F.shape[0]:
            best = wider
    return best


def _joining_ends(best, wider):
    """(3m,) bool: the half-edges of ``best``'s faces (a :class:`_Welded`)
    with an end that the ``wider`` weld joins to another of ``best``'s
    vertices (half-edge ``3f + c`` runs from corner ``c`` to ``c + 1``)."""
    # a wider class (named by its representative) holds two of best's when one of its
    # vertices is in another best class than the representative
    joining = np.zeros(best.rep.shape[0], dtype=bool)
    joining[wider.rep[best.rep != best.rep[wider.rep]]] = True
    joins = joining[wider.rep[best.F]]                      # (m,3) per corner
    return (joins | np.roll(joins, -1, axis=1)).ravel()


def _open_half_edges(w):
    """(3m,) bool: which half-edges of the welded faces (:class:`_Welded`)
    are open, counting as open those that meet a copy of their face (the
    same three vertices: its corner across the edge is theirs). A soup
    exported twice in place, its corners drifted apart, welds each face to
    its copy and few to their neighbours: edges closed by a copy, which the
    duplicate faces' removal opens again. Counted closed, they kept the wider
    welds from being tried (the icosphere so stayed 1,280 one-face pieces)."""
    t = w.twin
    across = w.F.ravel()                      # the corner across each half-edge (h = 3f + c)
    meets_copy = (t >= 0) & (across == across.take(np.maximum(t, 0)))
    return (t == BOUNDARY) | meets_copy


class _Shape(NamedTuple):
    """The input in unit-free form: coordinates scaled to a unit box
    diagonal (no overflow near the float limits) and, per face, its area and
    its height over its longest edge."""

    V: np.ndarray       #: (n,3) float64, (V - lo) / diagonal
    area: np.ndarray    #: (m,) float64
    height: np.ndarray  #: (m,) float64
    tallest: float      #: the largest ``height`` (of the faces as they came)


def _shape(V, F, box):
    """:class:`_Shape` of the faces ``F`` (coordinate by coordinate: two edge
    vectors, their cross product, three squared lengths; face block by face
    block); ``box``: the :func:`bulk_box` ``(lo, hi)`` of the vertices they use."""
    lo, hi = box
    d = diagonal_length(lo, hi) or 1.0
    cols = np.subtract(V.T, lo[:, None], order="C")     # (V - lo) / d, coordinate-major
    cols /= d
    m = F.shape[0]
    area, height = np.empty(m), np.empty(m)
    run_blocks(lambda a, b: _face_shape(cols, F[a:b], area[a:b], height[a:b]),
               blocks(m, _FACE_BLOCK))
    return _Shape(cols.T, area, height, float(height.max(initial=0.0)))


#: faces per block of :func:`_shape` and the sheet candidates (temporaries stay in cache)
_FACE_BLOCK = 1 << 14


def _face_shape(cols, F, area, height):
    """Area and height over the longest edge of the faces ``F`` (k,3), into
    ``area`` and ``height`` (k,); ``cols``: the coordinates, (3,n)."""
    e1, e2 = [], []
    for c in cols:
        a = np.take(c, F[:, 0])
        e1.append(np.take(c, F[:, 1]) - a)
        e2.append(np.take(c, F[:, 2]) - a)
    twice2 = ((e1[1] * e2[2] - e1[2] * e2[1]) ** 2 + (e1[2] * e2[0] - e1[0] * e2[2]) ** 2
              + (e1[0] * e2[1] - e1[1] * e2[0]) ** 2)
    l1 = e1[0] ** 2 + e1[1] ** 2 + e1[2] ** 2
    l2 = e2[0] ** 2 + e2[1] ** 2 + e2[2] ** 2
    l3 = (e2[0] - e1[0]) ** 2 + (e2[1] - e1[1]) ** 2 + (e2[2] - e1[2]) ** 2
    longest2 = np.maximum(np.maximum(l1, l2), l3)
    height2 = np.divide(twice2, longest2, out=np.zeros_like(twice2), where=longest2 > 0)
    np.sqrt(twice2, out=area)
    area *= 0.5
    np.sqrt(height2, out=height)


def _weld_map(shape, F, twin, weld_distance):
    """Representative of every vertex, (n,) int64: vertices on an open or
    non-manifold edge (``twin < 0``, or closed only by a copy of its face:
    :func:`_copy_closed`) or on a collapsed face (no taller than
    ``weld_distance`` over its longest edge, nor than ``FLAT_SHARE`` of the
    tallest face: a degenerate cluster, or an edge that short, since a face is
    no taller than its shortest edge) that coincide, exactly or within
    ``weld_distance`` of the size (see the
    module docstring), map to the smallest index of their group; every other
    vertex to itself."""
    V, tol = shape.V, weld_distance
    n = V.shape[0]
    rep = np.arange(n, dtype=np.int64)
    h = np.flatnonzero(twin < 0)
    h = np.concatenate([h, _copy_closed(F, twin)])
    flat = np.flatnonzero(shape.height <= min(tol, FLAT_SHARE * shape.tallest))
    if h.size == 0 and flat.size == 0:
        return rep
    cand = sorted_unique(np.concatenate([*half_edge_ends(F, h), F[flat].ravel()]))
    pairs = coincident_pairs(V[cand], tol)     # (rows of cand)
    if pairs.shape[0] == 0:
        return rep
    rep[cand] = cand[connected_labels(cand.size, pairs)]
    return rep


def _copy_closed(F, twin):
    """Half-edges closed only by a copy of their face (the face across is on
    the same three vertices: its corner across the edge is theirs). A soup
    made double-sided in place (each triangle and its reverse on the same
    three vertices) has no open edge, and its exact copies of each vertex
    were never welded: the cage was its lone triangles."""
    across = F.ravel()
    return np.flatnonzero((twin >= 0) & (across == across.take(np.maximum(twin, 0))))


def _orientation_sign(F):
    """True where a face runs lo -> mid -> hi (its sorted vertices) around."""
    a, b, c = F[:, 0], F[:, 1], F[:, 2]
    lo = np.minimum(np.minimum(a, b), c)
    hi = np.maximum(np.maximum(a, b), c)
    mid = a + b + c - lo - hi
    after_lo = np.where(a == lo, b, np.where(b == lo, c, a))
    return after_lo == mid


def _unique_faces(F, twin, V):
    """Faces to keep among those on the same three vertices (of the positions
    ``V``): one of a set with one orientation, none of a set with both (a
    double-sided sheet), unless one side mends the surface (see
    :func:`_one_side_mends`) or removing them would leave less surface than
    one side of them holds (:func:`_sheets_are_the_surface`).

    Such faces share all three edges, so they meet the same face across two
    edges or sit on a non-manifold edge: only those are compared by key.
    """
    n = V.shape[0]
    keep = np.ones(F.shape[0], dtype=bool)
    found = {"n_duplicate_faces": 0, "n_double_sided_sheets": 0, "n_double_sided_faces": 0}
    if F.shape[0] == 0:
        return keep, found
    cand = np.empty(F.shape[0], dtype=bool)
    run_blocks(lambda a, b: _may_repeat(twin[3 * a:3 * b], cand[a:b]), blocks(F.shape[0], _FACE_BLOCK))
    ci = np.flatnonzero(cand)
    if ci.size < 2:
        return keep, found
    _, first, group, size = np.unique(face_keys(F[ci], n), return_index=True,
                                      return_inverse=True, return_counts=True)
    group = group.ravel()
    forward = np.bincount(group, weights=_orientation_sign(F[ci]), minlength=size.size)
    sheet = (forward > 0) & (forward < size)
    sheet[sheet] = ~_one_side_mends(F, twin, n, ci[first[sheet]], size[sheet])
    drop = ci[size[group] > 1]
    keep[drop] = False
    keep[ci[first[~sheet & (size > 1)]]] = True
    if sheet.any() and _sheets_are_the_surface(V, F, keep, ci[first[sheet]]):
        keep[ci[first[sheet]]] = True
        sheet[:] = False                           # keep one side of each
    found["n_double_sided_sheets"] = int(np.count_nonzero(sheet))
    found["n_double_sided_faces"] = int(size[sheet].sum())
    found["n_duplicate_faces"] = int(drop.size - found["n_double_sided_faces"]
                                     - np.count_nonzero(~sheet & (size > 1)))
    return keep, found


def _sheets_are_the_surface(V, F, kept, sides):
    """Whether the double-sided sheets of one side ``sides`` (faces) hold
    more area than the faces ``kept`` (the rest, one face of each other
    repeated set included): then they are the model (a thin flat part made
    double-sided, its rim pinched, beside a speck: removing them left the
    speck as the whole cage), not a fold on top of it, and keep one side."""
    rest = np.flatnonzero(kept)
    return rest.size == 0 or float(face_areas(V, F[sides]).sum()) > float(
        face_areas(V, F[rest]).sum())


def _may_repeat(twin, out):
    """Whether each face of the twin rows ``twin`` (3k,) meets one face
    across two of its edges or has a non-manifold edge (all a face on the
    same three vertices as another can do), into ``out`` (k,)."""
    t = twin.reshape(-1, 3)
    g = np.where(t >= 0, t // 3, -1 - np.arange(3))   # distinct negatives never match
    np.equal(g[:, 0], g[:, 1], out=out)
    out |= (g[:, 1] == g[:, 2]) | (g[:, 0] == g[:, 2])
    out |= any_in_rows(t == NON_MANIFOLD)


def _one_side_mends(F, twin, n, faces, size):
    """For sets of ``size`` faces on the vertices of ``faces`` (sets with
    both orientations), whether to keep one face of each rather than none.

    Sets sharing edges form regions, decided as a whole: the choice that
    leaves fewer broken edges wins, keeping one side on a tie (nothing is
    lost). An edge is broken when it ends with more than two faces, or with
    one face next to faces that are not the set's (a new hole). So a reversed
    copy of a patch of the surface keeps one side, a pair folded on top of a
    closed surface goes, and a free double-sided sheet keeps one side.
    """
    g = faces.size
    h = (3 * faces[:, None] + np.arange(3)).ravel()
    U, W = half_edge_ends(F)
    key = edge_keys(U[h], W[h], n)
    t = twin[h]
    count = np.where(t >= 0, 2, 1)
    nm = t == NON_MANIFOLD
    if nm.any():
        hn = np.flatnonzero(twin == NON_MANIFOLD)
        keys = np.sort(edge_keys(U[hn], W[hn], n))
        count[nm] = np.searchsorted(keys, key[nm], side="right") - np.searchsorted(keys, key[nm])
    edges, e_of, e_first = _unique_inverse_first(key)
    owner = np.repeat(np.arange(g), 3)
    in_sets = np.bincount(e_of, weights=np.repeat(size, 3), minlength=edges.size)
    k = np.bincount(e_of, minlength=edges.size)
    rest = count[e_first] - in_sets                   # faces of each edge outside the sets
    broken_if_removed = (rest == 1) | (rest > 2)
    broken_if_kept = (rest + k > 2) | ((rest + k == 1) & (rest > 0))
    # regions: sets joined through shared edges
    order = np.argsort(e_of, kind="stable")
    same = e_of[order[1:]] == e_of[order[:-1]]
    region = connected_labels(g, np.stack([owner[order[1:]][same], owner[order[:-1]][same]], axis=1))
    edge_region = region[owner[e_first]]
    removed = np.bincount(edge_region, weights=broken_if_removed, minlength=g)
    kept = np.bincount(edge_region, weights=broken_if_kept, minlength=g)
    return (kept <= removed)[region]


def _unique_inverse_first(key):
    """``np.unique(key)`` with each entry's index into it and the first
    entry of each unique value."""
    edges, first, inverse = np.unique(key, return_index=True, return_inverse=True)
    return edges, inverse.ravel(), first


#: non-manifold edges with more faces than this pair them in index order
#: instead of scoring every pair
_MAX_SCORED_FAN = 16
#: rounds of cutting open the non-manifold edges whose pairings disagree
_MAX_RECUTS = 16


def _pair_sheets(V, F, twin):
    """Twin table with every non-manifold edge resolved: its faces paired
    (consistent orientation first, then the flattest pair: largest dot
    product of the unit normals; faces with no area last), the unpaired ones
    left as borders.

    Returns the new twin table and the number of non-manifold edges.
    """
    hn = np.flatnonzero(twin == NON_MANIFOLD)
    if hn.size == 0:
        return twin, 0
    twin = twin.copy()
    U, W = half_edge_ends(F)
    key = np.minimum(U[hn], W[hn]) * np.int64(max(V.shape[0], 1)) + np.maximum(U[hn], W[hn])
    order = np.argsort(key, kind="stable")
    hn, key = hn[order], key[order]
    start = np.flatnonzero(np.r_[True, key[1:] != key[:-1]])
    size = np.diff(np.r_[start, key.size])
    group = np.repeat(np.arange(start.size), size)
    pos = np.arange(hn.size) - start[group]
    big = size[group] > _MAX_SCORED_FAN
    # every pair (i, j > i) of a small group; consecutive pairs of a big one
    n_after = np.where(big, (pos % 2 == 0) & (pos + 1 < size[group]), size[group] - pos - 1)
    n_after = n_after.astype(np.int64)
    i = np.repeat(np.arange(hn.size), n_after)
    j = i + 1 + (np.arange(i.size) - np.repeat(np.cumsum(n_after) - n_after, n_after))
    hi, hj = hn[i], hn[j]
    N = face_normals(V, F[hn // 3])                # of the faces on non-manifold edges, by hn
    score = 2.0 * (U[hi] == W[hj]) + np.einsum("ij,ij->i", N[i], N[j])
    # a face with no area (corners collinear: a fin folded flat onto the edge) pairs last,
    # whatever its winding: it won over a real neighbour wound the other way, and stayed
    flat = flat_faces(V, F[hn // 3])
    score[flat[i] | flat[j]] -= 8.0
    by = np.lexsort((-score, group[i]))
    i, j = i[by], j[by]
    matched = np.zeros(hn.size, dtype=bool)
    while True:
        alive = np.flatnonzero(~matched[i] & ~matched[j])
        if alive.size == 0:
            break
        _, best = np.unique(group[i[alive]], return_index=True)
        a, b = i[alive[best]], j[alive[best]]
        matched[a] = matched[b] = True
        twin[hn[a]] = hn[b]
        twin[hn[b]] = hn[a]
    twin[hn[~matched]] = BOUNDARY
    return twin, int(start.size)


def _split_fans(V, F, twin, to_input, corners=None):
    """One vertex per fan: every vertex whose faces form several fans (across
    ``twin``) keeps its index for the fan of its smallest corner and gets a
    new vertex, at the same position, for each other fan (``corners``: the
    faces at each vertex, when the caller has them).

    Returns the new V, F, to_input (vertex -> input vertex) and the numbers of
    vertices split and added.
    """
    n = V.shape[0]
    bad = np.flatnonzero(non_manifold_vertices(F, n, twin, corners=corners))
    if bad.size == 0:
        return V, F, to_input, 0, 0
    U, W = half_edge_ends(F)
    nodes, roots = corner_fans(F, twin, U, W, bad, n)
    Fr = F.ravel()
    owner = Fr[nodes]
    # fans of one vertex in order of their smallest corner: the first keeps the vertex
    fan_key = owner * np.int64(Fr.size) + roots
    fans, fan_of = np.unique(fan_key, return_inverse=True)
    fan_owner = fans // Fr.size
    first = np.r_[True, fan_owner[1:] != fan_owner[:-1]]
    new_id = np.where(first, fan_owner, 0)
    extra = np.flatnonzero(~first)
    new_id[extra] = n + np.arange(extra.size)
    F = Fr.copy()
    F[nodes] = new_id[fan_of.ravel()]
    from_vertex = np.r_[np.arange(n), fan_owner[extra]]
    return (V[from_vertex], F.reshape(-1, 3), to_input[from_vertex],
            int(sorted_unique(fan_owner[extra]).size), int(extra.size))


def _make_manifold(V, F, twin, corners=None):
    """Pair the faces of non-manifold edges into sheets and split every
    vertex into its fans (see :func:`_pair_sheets`, :func:`_split_fans`).

    Pairings are made edge by edge, so along a chain of non-manifold edges
    they may disagree: the sheets then still meet in one fan at a chain
    vertex and an edge stays shared by three faces. Such an edge is cut open
    (its pairs too) and the fans split again, until none is left; a face that
    still shares a cut edge with two others (a surface touching itself along
    the edge) is detached (three vertices of its own). ``corners``: the faces
    at each vertex, when the caller has them. Returns V, F, the twin table,
    the input vertex of every vertex and the counts.
    """
    pairing, n_nm = _pair_sheets(V, F, twin)
    ident = np.arange(V.shape[0], dtype=np.int64)
    for _ in range(_MAX_RECUTS):
        V2, F2, to_input, n_split, n_added = _split_fans(V, F, pairing, ident, corners)
        if n_nm == 0 and n_added == 0:
            return V, F, twin, ident, {"n_non_manifold_edges": 0, "n_split_vertices": 0,
                                       "n_added_vertices": 0, "n_detached_faces": 0}
        twin = twin_table(F2, V2.shape[0])
        left = np.flatnonzero(twin == NON_MANIFOLD)
        if left.size == 0 or not (pairing[left] >= 0).any():
            break
        partner = pairing[left]
        pairing = pairing.copy()
        pairing[left] = BOUNDARY
        pairing[partner[partner >= 0]] = BOUNDARY
    V, F = V2, F2
    n_detached = 0
    if left.size:
        faces = sorted_unique(left // 3)
        n = V.shape[0]
        corners = (3 * faces[:, None] + np.arange(3)).ravel()
        Fr = F.ravel().copy()
        from_vertex = np.r_[np.arange(n), Fr[corners]]
        Fr[corners] = n + np.arange(corners.size)
        V, F, to_input = V[from_vertex], Fr.reshape(-1, 3), to_input[from_vertex]
        n_detached = int(faces.size)
        twin = twin_table(F, V.shape[0])
        V, F, to_input, s, a = _split_fans(V, F, twin, to_input)
        n_split, n_added = n_split + s, n_added + a
        twin = twin_table(F, V.shape[0])
    return V, F, twin, to_input, {"n_non_manifold_edges": n_nm, "n_split_vertices": n_split,
                                  "n_added_vertices": n_added, "n_detached_faces": n_detached}


def _orient(V, F, twin, inner):
    """Flip faces so that every component is consistent, keeping the
    orientation most of its faces have, or the outward one where the
    majority says little (:func:`_outward_sides`); a one-sided
    (non-orientable) component is cut open along a seam first.

    The faces' orientations are the components of a double cover: node
    ``2f`` is face ``f`` as it is, ``2f+1`` flipped; two faces on an edge
    that agree join (as is, as is) and (flipped, flipped), two that disagree
    (as is, flipped) and (flipped, as is). A component whose face meets
    itself flipped is one-sided: its faces are oriented along a spanning
    tree (:func:`_tree_flips`) and the edges that tree leaves inconsistent,
    its seam, are opened in the returned twin table (their vertices are
    still shared: the caller splits them, one per side). ``inner``: the
    interior edges, ``interior_edges(twin)``. Returns F, twin and the counts.
    """
    found = {"n_flipped_faces": 0, "n_non_orientable_components": 0, "n_seam_edges": 0}
    h, t = inner
    if h.size == 0:
        return F, twin, found
    # twins share their two ends, so they agree when they start at different ones
    U = np.take(F, [1, 2, 0], axis=1).ravel()              # half_edge_ends(F)[0]
    agree = np.take(U, h) != np.take(U, t)
    if agree.all():
        return F, twin, found
    m = F.shape[0]
    fh, ft = h // 3, t // 3
    other = np.where(agree, 0, 1)
    pairs = np.concatenate([np.stack([2 * fh, 2 * ft + other], axis=1),
                            np.stack([2 * fh + 1, 2 * ft + 1 - other], axis=1)])
    labels = connected_labels(2 * m, pairs)
    as_is, flipped = labels[0::2], labels[1::2]
    orientable = as_is != flipped
    comp = np.minimum(as_is, flipped)
    # faces of each component on the side of its smallest label: the side with most faces stays
    on_low = as_is == comp
    n_low = np.bincount(comp, weights=orientable & on_low, minlength=2 * m)
    n_all = np.bincount(comp, weights=orientable, minlength=2 * m)
    keep_low = _outward_sides(V, F, twin, comp, on_low, n_low, n_all)
    flip = orientable & (on_low != keep_low[comp])
    seam = np.zeros(0, dtype=np.int64)
    if not orientable.all():
        one_sided = ~orientable
        # (a one-sided component's smallest node is 2 f for its lowest face f)
        roots = sorted_unique(comp[one_sided]) // 2
        flip |= one_sided & _tree_flips(m, fh, ft, agree, one_sided, roots)
        seam = np.flatnonzero(one_sided[fh] & (agree != (flip[fh] == flip[ft])))
        found["n_non_orientable_components"] = int(roots.size)
        found["n_seam_edges"] = int(seam.size)
    if not flip.any() and seam.size == 0:
        return F, twin, found
    found["n_flipped_faces"] = int(np.count_nonzero(flip & orientable))   # (the seam's are its own)
    F = F.copy()
    F[flip, 1], F[flip, 2] = F[flip, 2], F[flip, 1].copy()
    # a flipped face's half-edges 1 and 2 swap places (0 stays: corners 1 and 2 swapped)
    perm = np.arange(twin.size, dtype=np.int64).reshape(-1, 3)
    perm[flip, 1], perm[flip, 2] = perm[flip, 2], perm[flip, 1].copy()
    perm = perm.ravel()
    new_twin = np.empty_like(twin)
    new_twin[perm] = np.where(twin >= 0, perm[np.maximum(twin, 0)], twin)
    new_twin[perm[h[seam]]] = BOUNDARY
    new_twin[perm[t[seam]]] = BOUNDARY
    return F, new_twin, found


#: a closed component whose faces disagree is turned outward (positive enclosed
#: volume) unless its volume is below this share of the unsigned sum of its faces'
#: cones from its centre (shared meshes 65-96%, a sponge lattice 26%): a thin or flat
#: one keeps the majority's (a thin-walled vase, wall 0.1% of its size: 0.4%; a
#: pillow, a copy's two layers welded at the rim, whose turned layer is dropped).
#: Photogrammetry with random per-face winding (half the faces reversed) came out
#: inside-out in about half the runs (cow, spot, homer, rocker-arm, bunny: the
#: majority is a coin toss there)
FLAT_VOLUME = 0.01
#: an open component is turned outward only when its smaller orientation holds at
#: least this share of its faces (the majority is a tie) and its volume, closed
#: through its centre, is at least ``CLEAR_VOLUME`` of the unsigned sum (a scan
#: with holes; a bowl or a sheet has no clear inside: the majority decides)
WEAK_MAJORITY = 0.35
CLEAR_VOLUME = 0.5


def _outward_sides(V, F, twin, comp, on_low, n_low, n_all):
    """(2m,) bool per component label of :func:`_orient`: whether its faces
    on the low side (``on_low``) keep their orientation. The side with most
    faces, except in a component whose faces disagree and that is closed, or
    open with a near tie and a clear inside: there the side with a positive
    enclosed volume (cones from the component's centre, the faces as on
    the low side), so that the normals point out."""
    keep_low = n_low * 2 >= n_all
    mixed = (n_low > 0) & (n_low < n_all)
    if not mixed.any():
        return keep_low
    size = keep_low.size
    faces = np.flatnonzero(mixed[comp])
    c, low = comp[faces], on_low[faces]
    T = V[F[faces]]                                        # (k,3,3) corners
    corners = 3 * np.maximum(np.bincount(c, minlength=size), 1)
    S = T.sum(axis=1)
    centre = np.stack([np.bincount(c, weights=S[:, j], minlength=size) for j in range(3)],
                      axis=1)
    T -= (centre[c] / corners[c][:, None])[:, None, :]
    T /= max(float(T.max()), -float(T.min())) or 1.0      # no overflow at 1e150
    cone = np.einsum("ij,ij->i", T[:, 0], cross_rows(T[:, 1], T[:, 2]))
    del T
    volume = np.bincount(c, weights=np.where(low, cone, -cone), minlength=size)
    unsigned = np.bincount(c, weights=np.abs(cone), minlength=size)
    open_ = np.bincount(c, weights=(twin.reshape(-1, 3)[faces] < 0).any(axis=1), minlength=size) > 0
    tie = np.minimum(n_low, n_all - n_low) >= WEAK_MAJORITY * n_all
    clear = np.abs(volume) > np.where(open_, CLEAR_VOLUME, FLAT_VOLUME) * unsigned
    decide = mixed & clear & (~open_ | tie)
    keep_low[decide] = volume[decide] > 0
    return keep_low


def _tree_flips(m, fa, fb, agree, faces, roots):
    """(m,) bool: which of the ``faces`` (mask) to flip so that each face
    agrees with the one it was reached from, breadth first from ``roots``
    (one per component, kept as it is) over the edges between faces ``fa``
    and ``fb`` (``agree``: whether they agree as they are). The loop runs
    over the tree's levels (at most the number of faces), each level one
    set of array operations; a face reached from several at once takes the
    first edge (in edge order) that reaches it."""
    inside = faces[fa]
    src = np.concatenate([fa[inside], fb[inside]])
    dst = np.concatenate([fb[inside], fa[inside]])
    keeps = np.concatenate([agree[inside], agree[inside]])
    order = np.argsort(src, kind="stable")
    dst, keeps = dst[order], keeps[order]
    start = np.zeros(m + 1, dtype=np.int64)
    np.cumsum(np.bincount(src, minlength=m), out=start[1:])
    src = src[order]
    flip = np.zeros(m, dtype=bool)
    seen = np.zeros(m, dtype=bool)
    seen[roots] = True
    frontier = roots
    while frontier.size:
        e = ragged_entries(start[frontier], start[frontier + 1] - start[frontier])
        e = e[~seen[dst[e]]]
        reached, first = np.unique(dst[e], return_index=True)
        e = e[first]
        flip[reached] = flip[src[e]] != ~keeps[e]
        seen[reached] = True
        frontier = reached
    return flip


def _debris(area, F, inner, min_component_area, face_budget, protected):
    """Faces to keep: all but those of components (joined across the
    manifold edges ``inner``, ``interior_edges(twin)``) whose area (``area``:
    per face) is below ``min_component_area`` times the largest's, or below
    the total over ``face_budget`` (never the largest, one with more than
    ``DEBRIS_MAX_FACES`` and ``DEBRIS_MAX_FACE_SHARE`` of the faces, nor one
    with a ``protected`` vertex)."""
    keep = np.ones(F.shape[0], dtype=bool)
    found = {"n_debris_components": 0, "n_debris_faces": 0}
    if (min_component_area <= 0 and not face_budget) or F.shape[0] == 0:
        return keep, found, None
    h, t = inner
    pairs = np.empty((h.size, 2), dtype=np.int32 if F.shape[0] < 2 ** 31 else np.int64)
    np.floor_divide(h, 3, out=pairs[:, 0], casting="unsafe")
    np.floor_divide(t, 3, out=pairs[:, 1], casting="unsafe")
    labels = connected_labels(F.shape[0], pairs)
    del pairs
    comp_area = np.bincount(labels, weights=area, minlength=F.shape[0])
    roots = np.flatnonzero(labels == np.arange(F.shape[0]))
    tiny = comp_area < min_component_area * comp_area.max()
    if face_budget:
        tiny |= _budget_debris(comp_area, roots, face_budget)
    tiny[np.argmax(comp_area)] = False
    comp_faces = np.bincount(labels, minlength=F.shape[0])
    tiny[comp_faces > max(DEBRIS_MAX_FACES, DEBRIS_MAX_FACE_SHARE * F.shape[0])] = False
    if protected is not None:
        tiny[labels[protected[F].any(axis=1)]] = False
    keep = ~tiny[labels]
    found["n_debris_components"] = int(np.count_nonzero(tiny[roots]))
    found["n_debris_faces"] = int(np.count_nonzero(~keep))
    return keep, found, labels


def _copies(V, F, twin, labels, area, box, distance, protected, pillows, turned):
    """The faces of coincident copies and, with ``pillows`` (only a weld
    makes them), of the second layers of flat pillows (:mod:`core.copies`;
    None when there is none), and the counts for the report. ``labels``: the
    faces' components (None: found here from ``twin``), ``box`` the input's
    bulk box (the unit of ``distance``), ``turned`` the faces the
    orientation turned (None: none)."""
    found = {"n_copies": 0, "n_copy_faces": 0}
    if F.shape[0] == 0:
        return None, found
    if labels is None:
        h, t = interior_edges(twin)
        labels = connected_labels(F.shape[0], np.stack([h // 3, t // 3], axis=1))
    several = not (labels == labels[0]).all()
    if not (several or pillows):
        return None, found
    Vs = (V - box[0]) / (diagonal_length(*box) or 1.0)
    drop = coincident_copies(Vs, F, labels, area, distance, protected) if several else None
    layers = pillow_layers(Vs, F, labels, twin, distance, turned) if pillows else None
    if layers is not None:
        drop = layers if drop is None else drop | layers
    if drop is None:
        return None, found
    found["n_copies"] = int(sorted_unique(labels[drop]).shape[0])
    found["n_copy_faces"] = int(np.count_nonzero(drop))
    return drop, found


def _budget_debris(comp_area, roots, face_budget):
    """(m,) bool over component labels: the components too small for one
    face of ``face_budget`` by their share of the total area (equal parts:
    none) -- or none of them when together they hold more than
    ``BUDGET_DEBRIS_SHARE`` of the area (then they are the mesh in pieces)."""
    total = comp_area.sum()
    small = roots[comp_area[roots] * face_budget < total * (1 - 1e-9)]
    out = np.zeros(comp_area.shape[0], dtype=bool)
    if comp_area[small].sum() <= BUDGET_DEBRIS_SHARE * total:
        out[small] = True
    return out


def _keep_twins(twin, keep):
    """The twin table of ``F[keep]`` when the removed faces are whole
    components (no kept face has a twin among them)."""
    new_f = np.cumsum(keep) - 1
    t = twin.reshape(-1, 3)[keep].ravel()
    return renumber_twins(t, new_f)


def _on_protected(V, clean_to_input, V_in, rep, protected):
    """The clean positions ``V`` and ``clean_to_input`` (new arrays where
    changed) with every clean vertex of a weld group (``rep``, the weld's
    representative of each input vertex) that holds a ``protected`` input
    vertex moved onto the first of those (``V_in``: the input positions).
    The weld puts a group where its first vertex is: a lock on another copy
    of an unwelded, drifted input's vertex left the cage vertex up to the
    drift away from the locked one (a cow soup drifted by 1e-6 of its size,
    1% of its vertices locked: 108 of 142 off)."""
    marked = np.flatnonzero(protected)[::-1]
    first = np.full(rep.shape[0], -1, dtype=np.int64)
    first[rep[marked]] = marked                          # (the smallest of each group wins)
    to = first[clean_to_input]
    move = np.flatnonzero((to >= 0) & (to != clean_to_input))
    if move.size == 0:
        return V, clean_to_input
    V, clean_to_input = V.copy(), clean_to_input.copy()
    V[move] = V_in[to[move]]
    clean_to_input[move] = to[move]
    return V, clean_to_input


def _compact(V, F, to_input, rep):
    """Drop the vertices no face uses and build the maps back to the input
    (``rep``: the weld's representative of every input vertex)."""
    n = V.shape[0]
    used = np.zeros(n, dtype=bool)
    used[F.ravel()] = True
    kept = np.flatnonzero(used)
    new = np.full(n, -1, dtype=np.int64)
    new[kept] = np.arange(kept.size)
    clean_to_input = to_input[kept]
    input_to_clean = np.full(rep.size, -1, dtype=np.int64)
    input_to_clean[clean_to_input[::-1]] = np.arange(kept.size - 1, -1, -1)  # first copy wins
    input_to_clean = input_to_clean[rep]
    if kept.size == n:
        return V, F, input_to_clean, clean_to_input
    return V[kept], new[F], input_to_clean, clean_to_input
