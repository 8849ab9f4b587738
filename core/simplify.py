"""Quadric edge-collapse simplification in vectorised batches.

Garland & Heckbert, "Surface simplification using quadric error metrics"
(SIGGRAPH 1997) and Garland's thesis (1999) for the quadrics, boundary
constraint planes and the compactness term; Dey, Edelsbrunner, Guha and
Nekhayev, "Topology preserving edge contraction" (1999) for the link
condition. Instead of a sequential heap, collapses are applied in batches
of independent edges, each batch checked on the mesh as it is::

    clean the input (core.clean: a manifold, oriented mesh)
    Q[v] = sum of area-weighted face planes (+ boundary and crease planes)
    repeat (one pass):
        cost the edges around vertices moved by the last pass (cached
        otherwise): Q = Q[a] + Q[b], x = argmin Q (3x3 solve), err = Q(x)
        pool = the cheapest edges (a bounded share: never much costlier
               than the cheapest remaining ones), split into cost bands
        repeat (rounds):
            pick pool edges whose priority (cost band, length band, then a
            fixed hash) is the smallest within two rings, so their stars -- the faces around
            both endpoints -- are disjoint
            check each on the current mesh: link condition, no flipped or
            near-degenerate face, no face turned > 90 deg from the summed
            input normals it stands for; add the compactness penalty and a
            Hausdorff-aware one (distance of the merged vertices' witnesses,
            the input points they stood for that lay farthest from the
            surface, to the new faces)
            accept those still within the pool's cost bound (on a plateau,
            where the bound is about 0, the cheaper half by cost + penalty),
            lock their stars
        apply every accepted collapse with one remap (b -> a, V[a] = x,
        Q[a] += Q[b]); glue the half-edge twins of the removed faces
        (a bold pass, while the mesh has over 4x the target faces and over
        256 faces, applies
        each round before the next and locks only the merged ends, so
        neighbouring collapses go in the same pass: about a third of the
        faces per pass instead of about an eighth)
    until the target, the error bound, or no valid collapse
    move the unlocked cage vertices towards the input surface, both ways, and
    its borders onto the input's (``core._relocate``)

The mesh is kept as faces plus a half-edge twin table (``core._clean``), which
collapses update locally: no sort after the first one.

Units: the mesh is moved to its bounding-box centre and scaled to a unit
diagonal before anything else, so the result does not depend on the units.
"""

import copy
import time
from dataclasses import dataclass, replace
from typing import NamedTuple

import numpy as np

from ._groups import member_of, sorted_unique
from ._clean import (BOUNDARY, NON_MANIFOLD, edge_representatives, face_keys, half_edge_ends,
                     spatial_order, twin_table)
from ._collapse import State, compactness, run
from ._parallel import blocks, run_blocks, run_each
from ._relax import close_smallest_hole, close_triangular_holes, drop_stuck_components
from ._relocate import relocate, segment_triangles
from ._touch_up import flip_flat_faces, touch_up
from .clean import (MIN_COMPONENT_AREA, CleanedInput, CleanReport, bulk_box, check_span,
                    clean_mesh)
from .errors import InvalidArgumentError, InvalidMeshError, MeshAdjustError
from .mesh import (UNITS, all_in_rows, area_normals_rows, bbox_diagonal, bounding_box, check_flag,
                   check_mesh, check_number, check_vertex_mask, diagonal_length, dot_columns,
                   face_normals, has_area, power_of_two_scale, shown, squared_edges)
from .metrics import DistanceFrom, surface_distance
from .topology import (border_vertex_count, boundary_loops_count, collapsible_edges, edge_map,
                       face_components, soup_pieces)
from .quadrics import accumulate_coefficients, vertex_face_quadrics, edge_constraint_quadrics
from .pinholes import cap_pinholes, face_floor
from .tuning import TUNING, Tuning
from .pages import plain_pages

_WHERE = "simplify"


STOP_REASONS = ("target", "max_error", "max_dihedral", "topology_floor", "no_valid_collapse",
                "cancelled")

#: with ``symmetry``: an input whose two sides differ by more than this share of its
#: diagonal is named in the message (:attr:`SimplifyResult.asymmetry_note`). Scans are
#: seldom centred on their mirror plane: the cow (symmetric in Z to 1.9%) and the
#: bunny made symmetric in X came back 'ok' 11.9% and 35.8% off, their sides 16.6%
#: and 36.9% apart (spot in X: 0.0%)
ASYMMETRY_NOTE = 0.05
#: a cage that met its target with this many faces fewer, and this share of the target,
#: says so (:attr:`SimplifyResult.under_note`): a symmetric cage comes in steps of its
#: seam's faces (spot in X: 30 or 36, none between); a collapse removes one or two faces,
#: a mirrored pair about four. A symmetric run that far under asks its half for more first.
UNDER_SLACK = 4
UNDER_SHARE = 0.05
#: a cage within this share of its diagonal beyond ``max_error`` is within it
#: (:attr:`SimplifyResult.bound_note`): a mirrored cage of a symmetric icosphere lies
#: 2.2e-16 off it, which a bound of 0 had called over (and divided by 0 to say how far)
BOUND_ROUNDING = 1e-12
#: a cage whose small pieces, collapsed to at most ``FLOOR_PIECE_FACES`` faces each (a
#: closed piece's floor is a tetrahedron), hold more than this share of its faces while
#: a larger piece is left says so (:attr:`SimplifyResult.pieces_note`): the bunny
#: beside 100 closed pebbles of 1% of its size (too much area to be debris) came back
#: 'target' with 100 of its 500 faces on the bunny (4.1% off), beside 1,000 pebbles
#: with 20 of 4,020 (44% off)
FLOOR_PIECES_SHARE = 0.5
FLOOR_PIECE_FACES = 4
#: ... and a cage at its topology floor in at least this many pieces, every one that
#: small, says what to do to go lower (the cow beside 1,817 specks: "1,818 components
#: kept", no more; two spheres of which one is locked need no advice)
FLOOR_MANY_PIECES = 16
#: a mesh whose faces have no area and whose coordinates keep at most this many
#: significant digits of its shape (15 less the decades of its distance from the origin
#: over its size) is told that it is too far off: the faces' area may be lost in the rounding
FEW_DIGITS = 6
#: a cage stopped by max_error with at most this many times its topology floor's faces
#: says that its holes hold it there (:attr:`SimplifyResult.floor_note`)
FLOOR_NEAR = 1.05
#: a cage that no collapse could shrink further, with preserve_boundary and more than this
#: share of its vertices on open borders, says that its borders hold it there
#: (:attr:`SimplifyResult.border_note`)
BORDER_HOLDS = 0.75
#: an input whose coordinates are all float32 numbers (Blender stores positions so),
#: with float32's step at its largest coordinate above this share of its size, says that
#: its shape may have been rounded away before it arrived (:attr:`SimplifyResult.float32_note`):
#: spot 1 m across at (5e6, 4e6, 300) m in float32 (steps of 0.5 m in x) cleaned into
#: 2,864 double-sided sheets and came back '5,856 -> 8 faces' and nothing more
FLOAT32_NOTE = 1e-4


@dataclass(frozen=True)
class SimplifyResult:
    """What :func:`simplify` returns.

    Attributes
    ----------
    V : (n,3) float64, the cage's vertices.
    F : (m,3) int64, the cage's faces: always an edge- and vertex-manifold
        mesh (the input is cleaned first, see :mod:`core.clean`).
    vertex_map : (n_input,) int64, the cage vertex each input vertex was merged
        into (``-1`` for input vertices no kept face used: unreferenced ones,
        debris, components removed with ``preserve_topology=False``). A
        bow-tie vertex split by the cleaning maps to one of its copies.
    face_map : (m,) int64, for every cage face an input face it descends from.
    max_error : float, largest error of an accepted collapse, as a distance in
        mesh units (``sqrt(quadric error / quadric area)``, see ``core.quadrics``);
        the final relocation only moves vertices closer to the input and is
        not counted in it.
    stopped_because : str, one of ``STOP_REASONS``: ``"target"``,
        ``"max_error"`` (the next collapse would exceed it, or the measured
        distance did), ``"max_dihedral"`` (short of the target, the
        collapses left would bend adjacent faces beyond ``max_dihedral_deg``),
        ``"topology_floor"`` (short of the target, or with ``max_error``,
        every edge left would change the topology: border loops, genus,
        components or locked vertices are kept), ``"no_valid_collapse"`` (short of the
        target, the geometric checks refuse the rest) or ``"cancelled"``
        (the cleaned input is returned unchanged).
    feature_edges : (k,2) int64, cage edges (sorted rows) that descend from the
        input's sharp edges (dihedral angle above ``feature_angle_deg``):
        pass them as ``creases`` to subdivision.
    cleaning : CleanReport, what cleaning the input did (welds, splits,
        sheets and debris removed, ...).
    n_input_faces : int, faces of the input as given.
    target : int or None, the face count asked for.
    hausdorff : float or None, with ``max_error``: the two-sided Hausdorff
        distance of the cage to the cleaned input (``core.surface_distance``),
        at most ``max_error`` (with ``symmetry``, as far as the input's two
        sides allow: above it the message says so, :attr:`bound_note`).
    bound : float or None, the ``max_error`` asked (mesh units).
    n_boundary_loops, n_components : int, of the cage.
    n_border_vertices : int, the cage's vertices on its open borders.
    preserve_boundary : bool, as asked.
    n_input_pieces : int or None, the separate pieces of the cleaned input
        when it and the cage are triangle soups (:func:`~.topology.soup_pieces`),
        else None.
    represented_faces : (m_input,) bool or None, the input faces the cleaned
        input stands for (:func:`represented_faces`): kept, or on the same
        vertices as a kept one, or collapsed by the weld; not those the
        cleaning dropped as debris, coincident copies or double-sided
        sheets. None: :meth:`represented` goes by the vertex map alone.
    n_passes : int, batches applied.
    float32_step : float or None, when every input coordinate is a float32
        number: float32's step at the largest of them, as a share of the
        input's size (:func:`float32_step`); None otherwise.
    n_clean_faces : int, the faces the collapse started from (the cleaned
        input, with its capped pinholes): a cage of that many faces is the
        cleaned input unchanged.
    seconds : dict, wall-clock seconds per stage: ``"clean"``, ``"set-up"``
        (order, quadrics), the engine's own (``"candidates"``, ``"recost"``,
        ``"pool"``, ``"pick and check"``, ``"apply"``, ``"compact"``),
        ``"relocate and output"``, ``"touch-up"`` (when it ran: see
        :mod:`._touch_up`), with ``max_error`` ``"measure"`` (the distance
        measures) and ``"steps"`` (the bound's other steps), and ``"total"``;
        with ``symmetry``, the last half's stages, ``"symmetry"`` (the cut,
        the other half runs, the mirror and the maps back) and ``"total"``.
    asymmetry : float or None, with ``symmetry``: how far the cleaned input
        is from its own mirror image, as a share of its bounding-box
        diagonal (the largest distance between its positive side and its
        mirrored negative side, from the vertices of each to the other); the
        cage lies between the two sides, so above
        :data:`ASYMMETRY_NOTE` the message says so (:attr:`asymmetry_note`).
    cleaned : CleanedInput or None, the input as the cleaning left it (before
        any pinhole caps): the surface the cage stands for, in the input's
        units. ``fit_cage(*r.cleaned, r.V, r.F, clean=False)`` fits the cage
        to it without cleaning the input again (0.4 s of a 1M-face scan's
        fit), and to the same surface the collapse saw (the debris dropped for
        the target too). It holds the cleaned arrays (about the input's size)
        while the result lives.
    locked : (n_cage,) bool or None, with ``locked``: the cage vertices that
        stand for a locked input vertex, each where that vertex is (with
        ``symmetry``: those its half locked and their mirror copies, where
        the symmetric half has them; a vertex on the mirror plane is never
        locked). A cage that stopped short of its target where edges join
        two of them says so in its message (:attr:`lock_note`): such an edge
        never collapses.
    """

    V: np.ndarray
    F: np.ndarray
    vertex_map: np.ndarray
    face_map: np.ndarray
    max_error: float
    stopped_because: str
    feature_edges: np.ndarray
    cleaning: CleanReport = CleanReport()
    n_input_faces: int = 0
    target: int = None
    hausdorff: float = None
    n_boundary_loops: int = 0
    n_components: int = 0
    n_passes: int = 0
    seconds: dict = None
    asymmetry: float = None
    n_border_vertices: int = 0
    preserve_boundary: bool = True
    n_input_pieces: int = None
    represented_faces: np.ndarray = None
    n_clean_faces: int = 0
    float32_step: float = None
    bound: float = None
    locked: np.ndarray = None
    cleaned: "CleanedInput" = None

    def represented(self, F):
        """(m_in,) bool per face of ``F`` (the faces given to ``simplify``):
        whether the cage stands for it, every corner merged into a cage
        vertex (not debris, an unreferenced piece or a component removed with
        ``preserve_topology=False``) and the face itself kept by the cleaning
        (:attr:`represented_faces`: a face dropped as debris or as a copy
        whose corners other faces keep is not; the beetle's, 0.24% of its
        size off the cleaned surface, made the deviation of a cage within
        ``max_error=0.05%`` 0.28%)."""
        F = np.asarray(F, dtype=np.int64)
        mapped = (self.vertex_map[F] >= 0).all(axis=1)
        if self.represented_faces is None or self.represented_faces.shape != mapped.shape:
            return mapped
        return mapped & self.represented_faces

    def deviation(self, V, F, *, samples=None, V_cage=None):
        """:func:`~.metrics.surface_distance` between the input ``V``, ``F``
        given to ``simplify`` and the cage, over the faces the cage stands for
        (:meth:`represented`); its ``diagonal`` is theirs. A speck dropped as
        debris 1,000 diagonals away neither sets the deviation (it was 99.95%
        of a diagonal that the speck made 1,000 times the mesh's) nor slows
        the search (its grid cells grew with the box: 3.6 s for a 5k-face
        sphere's 4-face cage, now 0.2 s); the cleaning's summary says what
        was dropped. ``V_cage``: other positions of the cage's vertices (a
        fitted cage's; None: the cage's own)."""
        F = np.asarray(F, dtype=np.int64)
        return surface_distance(V, F[self.represented(F)], self.V if V_cage is None else V_cage,
                                self.F, samples=samples)

    @property
    def message(self):
        """One sentence of what happened, e.g. ``"69,451 → 1,400 faces"`` or
        ``"stopped at 216 faces of 205 asked: the topology floor (23 border
        loops, 1 component kept)"``, with the cleaning's summary after it."""
        m = self.F.shape[0]
        faces = f"{m:,} face{'s' * (m != 1)}"
        asked = f" of {self.target:,} asked" if self.target is not None else ""
        kept = (f"{self.n_boundary_loops:,} border loop{'s' * (self.n_boundary_loops != 1)}, "
                f"{self.n_components:,} component{'s' * (self.n_components != 1)} kept")
        locks = self.lock_note
        held = f" or join two locked vertices ({locks})" if locks else ""
        floor = (f"every edge left would change the topology or join two locked vertices "
                 f"({locks}, {kept})" if locks else f"the topology floor ({kept})")
        text = {
            "target": f"{self.n_input_faces:,} → {faces}{self.under_note}",
            "max_error": f"{self.n_input_faces:,} → {faces}, where the error bound stopped it",
            "max_dihedral": f"stopped at {faces}{asked}: every collapse left would bend two "
                            f"faces beyond the dihedral bound{held}",
            "topology_floor": f"stopped at {faces}{asked}: {floor}",
            "no_valid_collapse": f"stopped at {faces}{asked}: every collapse left would fold "
                                 f"or squash a face"
                                 + (f" ({kept})" if self.n_boundary_loops else "") + held,
            "cancelled": f"cancelled: the cleaned input returned unchanged ({faces})",
        }[self.stopped_because]
        for note in (self.bound_note, self.soup_note, self.floor_note, self.border_note,
                     self.sliver_note, self.asymmetry_note, self.pieces_note, self.float32_note):
            if note:
                text += f"; {note}"
        done = self.cleaning.summary()
        return f"{text}; {done}" if done else text

    @property
    def under_note(self):
        """The words after the face count, e.g. `` (of 34 asked: ...)``, when
        the cage met its target with :data:`UNDER_SLACK` faces and
        :data:`UNDER_SHARE` of it fewer (a symmetric cage comes in steps:
        none nearer within it); "" otherwise."""
        m = self.F.shape[0]
        if self.stopped_because != "target" or self.target is None or \
                self.target - m < max(UNDER_SLACK, UNDER_SHARE * self.target):
            return ""
        why = ": a mirrored cage comes in steps of its seam's faces" \
            if self.asymmetry is not None else ""
        if self.n_clean_faces and m >= self.n_clean_faces:
            why = ": the input has no more, nothing to collapse"
        return f" (of {self.target:,} asked{why})"

    @property
    def lock_note(self):
        """What the locked vertices hold, when the cage stopped short of its
        target (or, with only ``max_error``, at the topology floor) and some of
        its edges join two locked vertices (:attr:`locked`; such an edge never
        collapses): "all 642 vertices locked" or "1,152 of its 1,280 vertices
        locked, 1,701 of its 1,920 edges between two of them, unlock some to go
        lower"; "" otherwise (the message had blamed the topology floor or the
        geometry alone)."""
        short = self.stopped_because in ("topology_floor", "no_valid_collapse", "max_dihedral")
        if self.locked is None or not short or \
                (self.target is not None and self.F.shape[0] <= self.target):
            return ""
        n = self.V.shape[0]
        E = edge_map(self.F, n).E
        both = int(np.count_nonzero(self.locked[E[:, 0]] & self.locked[E[:, 1]]))
        if both == 0:
            return ""
        n_locked = int(np.count_nonzero(self.locked))
        if n_locked == n:
            return f"all {n:,} vertices locked, unlock some to go lower"
        return (f"{n_locked:,} of its {n:,} vertices locked, {both:,} of its {E.shape[0]:,} edges "
                f"between two of them, unlock some to go lower")

    @property
    def soup_note(self):
        """A sentence when the cage and the cleaned input are triangle soups
        (:attr:`n_input_pieces`: the input's faces came apart and no weld
        joined them), and what to do about it; "" otherwise. Whatever
        stopped it: without ``preserve_topology`` the lone triangles are
        dropped down to the target, which is then met by scattered
        triangles."""
        if self.n_input_pieces is None:
            return ""
        c = self.cleaning
        if c.n_welded_vertices == 0 and (c.n_split_vertices or c.n_non_manifold_edges):
            # (welded as it came: its faces met only where the cleaning cut them apart)
            return (f"the input's faces meet only at bow-tie vertices or edges of more than "
                    f"two faces, which the cleaning split: {self.n_input_pieces:,} separate "
                    f"pieces that no weld joins (preserve_topology=False drops pieces to "
                    f"reach the target)")
        return (f"the input is in {self.n_input_pieces:,} separate pieces: weld it first (Merge "
                f"by Distance in Blender, or a larger weld_distance)")

    @property
    def floor_note(self):
        """A sentence when a cage that the error bound stopped is within
        :data:`FLOOR_NEAR` of its topology floor (:func:`~.pinholes.face_floor`:
        its holes and handles allow no fewer faces), so that the holes, not the
        bound, hold it there; "" otherwise. (With ``max_error`` holes are never
        capped: fandisk with 1,295 one-face holes stopped at 6,494 faces, its
        floor 6,471, said to be stopped by the error bound alone.)"""
        if self.stopped_because != "max_error" or self.n_boundary_loops == 0:
            return ""
        floor = face_floor(self.V, self.F, twin_table(self.F, self.V.shape[0]))
        if self.F.shape[0] > FLOOR_NEAR * floor:
            return ""
        return (f"its holes hold it there too: its topology floor is {floor:,} faces for its "
                f"{self.n_boundary_loops:,} border loops (to go lower, close the input's holes "
                f"first or ask for a face count: holes smaller than a cage face are then capped)")

    @property
    def border_note(self):
        """A sentence when a cage that no collapse could shrink further has
        more than :data:`BORDER_HOLDS` of its vertices on open borders whose
        shape ``preserve_boundary`` keeps, so that the borders hold it there;
        "" otherwise. (Half a fandisk to 4 faces: 41 faces, 39 of its 41
        vertices on its border, said to be held by folds alone; 4 faces
        without ``preserve_boundary``.)"""
        n = self.V.shape[0]
        if (self.stopped_because != "no_valid_collapse" or not self.preserve_boundary
                or self.n_border_vertices <= BORDER_HOLDS * n):
            return ""
        return (f"its borders hold it there: {self.n_border_vertices:,} of its {n:,} vertices lie "
                f"on open borders, whose shape preserve_boundary keeps (turn it off to let them "
                f"move)")

    @property
    def bound_note(self):
        """A sentence when the cage is farther from the cleaned input than the
        ``max_error`` asked (:attr:`hausdorff` above :attr:`bound`), and why;
        "" otherwise. Only a symmetric cage can be: it follows the input's
        positive side, and where the other side differs in its faces (a hole
        or faces on one side only; :attr:`asymmetry` measures vertices, which
        such a side can share) it lies off the input (an icosphere holed on
        one side, 1e-3 asked: 0.0415, said to be stopped by the bound)."""
        if self.hausdorff is None or self.bound is None:
            return ""
        if not self.hausdorff > self.bound * (1 + 1e-9) + BOUND_ROUNDING * bbox_diagonal(self.V):
            return ""
        why = (": the input's two sides differ more than that (holes or faces on one side "
               "only) and the symmetric cage follows its positive side (turn symmetry off to "
               "meet the bound)" if self.asymmetry is not None else "")
        how_far = f"{self.hausdorff / self.bound:.1f}x the error bound" if self.bound > 0 \
            else "beyond the error bound"
        return (f"it lies {how_far} off the input (Hausdorff distance {self.hausdorff:.4g} "
                f"against the {self.bound:.4g} asked){why}")

    @property
    def asymmetry_note(self):
        """A sentence on an input too far from mirror-symmetric for a
        symmetric cage (:attr:`asymmetry` above :data:`ASYMMETRY_NOTE`) and
        what to do about it, or "" otherwise."""
        if self.asymmetry is None or self.asymmetry <= ASYMMETRY_NOTE:
            return ""
        return (f"the input is not mirror-symmetric about the plane: its two sides differ by up "
                f"to {100 * self.asymmetry:.1f}% of its size and the symmetric cage lies between "
                f"them (center the object on its mirror plane, or turn symmetry off)")

    @property
    def pieces_note(self):
        """A sentence when small pieces at their floor (components of at most
        :data:`FLOOR_PIECE_FACES` faces) take more than :data:`FLOOR_PIECES_SHARE`
        of the cage's faces and leave few to a larger piece, or when every
        one of at least :data:`FLOOR_MANY_PIECES` pieces is that small at the
        topology floor, and what to do about it; "" otherwise, and for a soup
        (:attr:`soup_note` says it). The cow beside 1,817 specks of 1% of its
        size (too much area together to be debris) asked for 50 faces stopped
        at 7,272, "1,818 components kept", and said no more."""
        labels, n = face_components(self.F, self.V.shape[0])
        m = self.F.shape[0]
        if n < 2 or self.n_input_pieces is not None:
            return ""
        small = np.bincount(labels, minlength=n) <= FLOOR_PIECE_FACES
        faces = int(np.count_nonzero(small[labels]))
        if faces == m and self.stopped_because == "topology_floor" and n >= FLOOR_MANY_PIECES:
            return (f"its {n:,} pieces are each down to {FLOOR_PIECE_FACES} faces or fewer: "
                    f"delete the small ones from the scan (or raise min_component_area, or "
                    f"turn preserve_topology off) to go lower")
        if faces <= FLOOR_PIECES_SHARE * m or faces == m:
            return ""
        k = int(np.count_nonzero(small))
        return (f"{k:,} small pieces, each down to {FLOOR_PIECE_FACES} faces or fewer, take "
                f"{faces:,} of the cage's {m:,} faces and leave {m - faces:,} to the "
                f"{n - k:,} larger one{'s' * (n - k != 1)}: delete them from the scan (or raise "
                f"min_component_area) or ask for more faces")

    @property
    def n_slivers(self):
        """Cage faces less compact than ``Tuning.gamma_hard`` (Garland's
        compactness: 1 for an equilateral triangle). A collapse never makes
        one less compact than the faces it replaces, so they descend from
        the input's own long thin triangles (a CAD cylinder's sides, with no
        vertex between their ends for a cage vertex to sit on)."""
        if not self.F.shape[0]:
            return 0
        # (scaled exactly: areas of a cage 1e-90 units across underflowed, every face a
        # sliver; of one 1e160 across overflowed)
        V = self.V / power_of_two_scale(self.V, self.F)
        twice_area = np.linalg.norm(area_normals_rows(V, self.F.T), axis=1)
        g = compactness(twice_area, squared_edges(V, self.F).sum(axis=1))
        return int(np.count_nonzero(g < TUNING.gamma_hard))

    @property
    def sliver_note(self):
        """A sentence on the cage's slivers (:attr:`n_slivers`) and what to do
        about them, or "" when it has none."""
        n = self.n_slivers
        if not n:
            return ""
        return (f"{n:,} of the cage's {self.F.shape[0]:,} faces are slivers, long and thin as "
                f"the input's own triangles there (nothing lies between their ends for a cage "
                f"vertex to sit on): remesh the input into even triangles (Blender's Remesh modifier, "
                f"Voxel) for a cage without them; subdividing keeps their shape")

    @property
    def float32_note(self):
        """A sentence when the input's coordinates are float32 numbers whose
        step where they lie is beyond :data:`FLOAT32_NOTE` of its size
        (:attr:`float32_step`): its shape below that step was lost before
        ``simplify`` saw it. "" otherwise."""
        if self.float32_step is None or self.float32_step <= FLOAT32_NOTE:
            return ""
        return (f"its coordinates are float32 numbers whose step where they lie is "
                f"{100 * self.float32_step:.2g}% of its size: shape finer than that was rounded "
                f"away before it arrived (keep a scan far from the origin in float64, or move it "
                f"near the origin before it is stored in float32, e.g. in Blender)")


def float32_step(V):
    """float32's spacing at the largest coordinate of ``V`` (n,3) as a share
    of the diagonal of its :func:`~.clean.bulk_box`, when every coordinate is
    a float32 number (a float32 array, or float64 values that came from one);
    None otherwise, or for an empty mesh or one of no extent.

    Examples
    --------
    >>> V = np.array([[5e6, 4e6, 300.0], [5e6 + 1, 4e6, 300.0], [5e6, 4e6 + 1, 300.0]])
    >>> round(float32_step(V.astype(np.float32)), 3), float32_step(V + 1e-3)
    (0.354, None)
    """
    V = np.asarray(V)
    if V.size == 0 or V.dtype.kind != "f" or V.dtype.itemsize < 4:
        return None
    top = float(np.abs(V).max())
    # (a Python float against float32's largest: NumPy 2 would cast it to float32, overflowing)
    if not top <= float(np.finfo(np.float32).max) or \
            (V.dtype != np.float32 and not np.array_equal(V, V.astype(np.float32))):
        return None
    lo, hi = bulk_box(V)
    size = float(np.linalg.norm(hi.astype(np.float64) - lo))
    if not size > 0:
        return None
    return float(np.spacing(np.float32(top))) / size


def check_arguments(n, target_faces, ratio, max_error, feature_angle_deg, vertex_weights, locked,
                    progress, max_dihedral_deg=None):
    """Check :func:`simplify`'s arguments for an input of ``n`` vertices
    (:class:`InvalidArgumentError` naming the one that is wrong); returns the
    vertex weights and the lock mask as arrays (or None)."""
    if target_faces is None and ratio is None and max_error is None:
        raise InvalidArgumentError(
            f"{_WHERE}: give at least one of target_faces, ratio or max_error, e.g. ratio=0.1")
    if target_faces is not None:
        if isinstance(target_faces, bool) or not isinstance(target_faces, (int, np.integer)):
            raise InvalidArgumentError(
                f"{_WHERE}: target_faces must be an integer >= 0, got {shown(target_faces)}")
        if target_faces < 0:
            raise InvalidArgumentError(f"{_WHERE}: target_faces must be >= 0, got {target_faces}")
    # (each a real number: '3', [1], 1j and True were TypeErrors deep inside, or taken)
    if ratio is not None:
        check_number(ratio, where=_WHERE, name="ratio", lo=0, hi=1, open_lo=True)
    if max_error is not None:
        check_number(max_error, where=_WHERE, name="max_error (a distance)", lo=0)
    if feature_angle_deg is not None:
        check_number(feature_angle_deg, where=_WHERE, name="feature_angle_deg (or None)", lo=0,
                     hi=180, open_lo=True)
    if max_dihedral_deg is not None:
        check_number(max_dihedral_deg, where=_WHERE, name="max_dihedral_deg (or None)", lo=0,
                     hi=180, open_lo=True, open_hi=True)
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
    lk = None if locked is None else check_vertex_mask(locked, n, where=_WHERE, name="locked")
    if progress is not None and not callable(progress):
        raise InvalidArgumentError(f"{_WHERE}: progress must be callable or None, got {type(progress)}")
    return w, lk


def check_flags(**flags):
    """The on/off arguments of :func:`simplify` as bools, in the order given
    (:class:`InvalidArgumentError` for anything but True or False: 'no', 0
    and None were TypeErrors deep in the engine)."""
    return tuple(check_flag(value, where=_WHERE, name=name) for name, value in flags.items())


def _initial_quadrics(V, F, twin, preserve_boundary, feature_angle_deg, tun, scratch=None):
    """Vertex quadrics (n,11) with boundary and crease planes, the crease
    flags per half-edge, and the summed face normals around each vertex and
    their lengths (:func:`_normal_sums` of ``face_normals(V, F, normalize=False)``). The
    quadrics are the transposed view of the (11,n) C-contiguous array they
    are summed in (``State`` makes its vertex-major copy). ``scratch``: a
    (3m,) float64 buffer to work in, or None."""
    n = V.shape[0]
    QT, Nf, Nraw = vertex_face_quadrics(V, F, n, tun.area_power, scratch=scratch)  # (11, n)
    # the constraint planes and the normal sums are independent: side by side
    feat, Nref = run_each(lambda job: job(), [
        lambda: _constraint_planes(QT, V, F, twin, Nf, preserve_boundary, feature_angle_deg, tun),
        lambda: _normal_sums(F, Nraw, n, scratch)])
    return QT.T, feat, Nref  # (n,11) view of the coefficient-major sums


def _constraint_planes(QT, V, F, twin, Nf, preserve_boundary, feature_angle_deg, tun):
    """Add the boundary and crease constraint planes to the vertex quadrics
    ``QT`` (11,n) in place (``Nf``: unit face normals); returns the crease
    flags per half-edge."""
    feat = np.zeros(twin.size, dtype=bool)
    items, ends = [], []
    if preserve_boundary:
        hb = np.flatnonzero(twin == BOUNDARY)
        E = np.stack(half_edge_ends(F, hb), axis=1)
        L2 = np.einsum("ij,ij->i", V[E[:, 1]] - V[E[:, 0]], V[E[:, 1]] - V[E[:, 0]])
        items.append(edge_constraint_quadrics(V, E, Nf[hb // 3], tun.boundary_weight * L2))
        ends.append(E)
    if feature_angle_deg is not None:
        hs, ts = _sharp_edges(Nf, F, twin, np.cos(np.radians(feature_angle_deg)))
        feat[hs] = True
        feat[ts] = True
        E = np.stack(half_edge_ends(F, hs), axis=1)
        L2 = np.einsum("ij,ij->i", V[E[:, 1]] - V[E[:, 0]], V[E[:, 1]] - V[E[:, 0]])
        for side in (hs, ts):
            items.append(edge_constraint_quadrics(V, E, Nf[side // 3], tun.feature_weight * L2))
            ends.append(E)
    if items:
        Qc = np.concatenate(items)
        Ec = np.concatenate(ends)
        Qc[:, 10] = 0.0  # constraint planes do not count as surface area
        # only the vertices on constraint edges change (adding 0.0 elsewhere is exact)
        vc, local = np.unique(Ec, return_inverse=True)
        QT[:, vc] += accumulate_coefficients(Qc, local.reshape(Ec.shape).T.ravel(), vc.size, 2)
    return feat


#: half-edges (faces) per block of :func:`_sharp_edges` (:func:`_normal_sums`)
_SET_UP_BLOCK = 1 << 16


def _sharp_edges(Nf, F, twin, cos_max):
    """The interior edges whose faces' unit normals ``Nf`` meet at a cosine
    below ``cos_max``, as ``(h, twin[h])`` with ``h < twin[h]`` ascending;
    half-edge block by half-edge block."""

    def block(a, b):
        h = np.flatnonzero(twin[a:b] > np.arange(a, b)) + a
        t = np.take(twin, h)
        cosang = np.einsum("ij,ij->i", np.take(Nf, h // 3, axis=0), np.take(Nf, t // 3, axis=0))
        # faces that disagree on the edge's direction (twins that start at the same
        # end: they share both) have opposite normal conventions
        np.negative(cosang, out=cosang, where=half_edge_ends(F, h)[0] == half_edge_ends(F, t)[0])
        sharp = np.flatnonzero(cosang < cos_max)
        return h[sharp], t[sharp]

    found = run_blocks(block, blocks(twin.size, _SET_UP_BLOCK))
    empty = np.zeros(0, dtype=np.int64)
    return (np.concatenate([empty] + [h for h, _ in found]),
            np.concatenate([empty] + [t for _, t in found]))


def _normal_sums(F, N, n, scratch=None):
    """Sum of the face normals ``N`` (m,3) around each vertex and of their
    lengths, (n,4) float64 (each bin adds its faces in face order), the
    transposed view of a (4,n) C-contiguous array (``State`` keeps that
    layout); ``scratch``: a (3m,) float64 buffer to work in, or None."""
    out = np.zeros((4, n))
    if F.shape[0] == 0:
        return out.T
    Fr = F.ravel()
    w = np.empty(Fr.size) if scratch is None else scratch
    w3 = w.reshape(-1, 3)
    spans = blocks(F.shape[0], _SET_UP_BLOCK)
    for k in range(4):

        def fill(a, b):             # np.repeat(N[:, k], 3) without a new array, block by block
            w3[a:b] = N[a:b, k, None] if k < 3 else np.sqrt(dot_columns(N[a:b].T, N[a:b].T))[:, None]

        run_blocks(fill, spans)
        out[k] = np.bincount(Fr, weights=w, minlength=n)
    return out.T


def _bend_cosines(mesh):
    """Cosine of the angle between the normals of the two faces of every
    interior edge of the (compact) engine mesh off the input's creases, one
    per edge in half-edge order (1 where a face has no area)."""
    F, V, twin = mesh.F, mesh.V, mesh.twin
    h = edge_representatives(twin, boundary=False)
    h = h[~mesh.feat[h]]
    N = face_normals(V, F, normalize=False)
    Na, Nb = N[h // 3], N[twin[h] // 3]
    la = np.linalg.norm(Na, axis=1)
    lb = np.linalg.norm(Nb, axis=1)
    d = la * lb
    return np.where(d > 0, np.einsum("ij,ij->i", Na, Nb) / np.where(d > 0, d, 1.0), 1.0)


def _relocate_cage(mesh, Vn, creases, Eb_in, surface, tun):
    """Move the unlocked cage vertices towards the input (see ``core._relocate``):
    the input's crease vertices ``creases`` join the surface samples, its
    border edges ``Eb_in`` (k,2) are tied to the cage's, and ``surface`` (the
    input faces, or None) turns on the backward pull. Borders, creases and
    corners move too, towards the input's (pinning them measured worse: their
    collapse positions are often off the input). The searches for closest
    points start where the engine merged each input vertex."""
    Fm = mesh.F
    movable = ~mesh.locked
    samples = max(tun.relocate_samples, tun.relocate_per_vertex * mesh.V.shape[0])
    if tun.relocate_max_per_vertex:
        samples = min(samples, tun.relocate_max_per_vertex * mesh.V.shape[0])
    step = max(1, int(np.ceil(Vn.shape[0] / samples)))
    at = np.concatenate([np.arange(0, Vn.shape[0], step), creases[::step]])
    border = None
    if Eb_in.shape[0]:
        hb = np.flatnonzero(mesh.twin == BOUNDARY)
        Eb = np.stack(half_edge_ends(Fm, hb), axis=1)
        ends = sorted_unique(Eb_in)[::step]
        border = (Vn[ends], Eb, (Vn, segment_triangles(Eb_in)), tun.relocate_border_weight)
    Nkeep = mesh.Nref[Fm].sum(axis=1) if tun.ref_cos > -1.0 else None
    back = dict(surface=(Vn, surface), back=tun.relocate_back,
                iters=tun.relocate_back_iters) if surface is not None else dict(iters=tun.relocate_iters)
    Vnew = relocate(mesh.V, Fm, Vn[at], movable, reg=tun.relocate_reg, N_keep=Nkeep, border=border,
                    min_compact=tun.gamma_hard, cg_iters=tun.relocate_cg_iters,
                    min_cos=tun.relocate_min_cos, min_move=tun.relocate_min_move,
                    P_near=mesh.cur_of_clean[at], cage_of=mesh.cur_of_clean,
                    border_near=None if border is None else mesh.cur_of_clean[ends],
                    walk_steps=tun.relocate_walk_steps, **back)
    mesh.moved |= np.any(Vnew != mesh.V, axis=1)
    mesh.V = Vnew


class _Cage(NamedTuple):
    """A cage in terms of the cleaned input (what one collapse run gives)."""

    V: np.ndarray
    F: np.ndarray
    of_clean: np.ndarray      #: (n_clean,) cage vertex of each clean vertex, -1 if removed
    face_from: np.ndarray     #: (m,) clean face each cage face descends from
    feature_edges: np.ndarray
    worst: float
    stopped: str
    passes: int
    seconds: dict = {}        #: time per stage (set-up, engine stages, relocation)


def _unchanged(clean):
    """The cleaned input as a cage (nothing collapsed)."""
    n, m = clean.V.shape[0], clean.F.shape[0]
    return _Cage(clean.V.copy(), clean.F.copy(), np.arange(n, dtype=np.int64),
                 np.arange(m, dtype=np.int64), np.zeros((0, 2), np.int64), 0.0, "cancelled", 0)


class _SetUp(NamedTuple):
    """The engine's state at the start and what turning it back into a cage needs."""

    mesh: State
    V_clean: np.ndarray    #: the clean vertices (``V_clean[order]``: in working order)
    Vn: np.ndarray         #: ... centred, scaled to a unit diagonal, snapped
    order: np.ndarray      #: clean index of each working vertex
    centre: np.ndarray
    scale: float
    creases: np.ndarray    #: the input's crease vertices (for the relocation)
    Eb_in: np.ndarray      #: the input's border edges
    Fin: np.ndarray        #: the input's faces for the backward pull, or None
    m0: int
    seconds: dict          #: {"set-up": its time}


def _set_up(clean, opts):
    """The engine on the cleaned (manifold) mesh: working order, unit-free
    coordinates, quadrics, normals (see :class:`_SetUp`)."""
    tun = opts["tuning"]
    t0 = time.perf_counter()
    if (clean.twin == NON_MANIFOLD).any():
        raise MeshAdjustError(f"{_WHERE}: cleaning left a non-manifold edge (a bug)")
    lo, hi = bounding_box(clean.V)
    Vc, Fc, twin, _, _, order, forder = spatial_order(clean.V, clean.F, clean.twin, box=(lo, hi),
                                                      ends=False)
    n, m0 = Vc.shape[0], Fc.shape[0]
    lock = np.zeros(n, dtype=bool) if opts["locked"] is None else opts["locked"][order]
    # unit-free working coordinates: centred, unit diagonal, snapped to a grid
    centre = 0.5 * (lo + hi)
    scale = diagonal_length(lo, hi) or 1.0
    grid = float(2 ** tun.snap_bits)
    Vn = (Vc - centre) / scale
    del Vc                       # (clean.V[order]: the set-up keeps clean.V itself)
    Vn *= grid
    np.round(Vn, out=Vn)
    Vn /= grid
    scratch = np.empty(twin.size)  # one (3m,) buffer for the quadrics' and the normals' sums
    Q, feat, Nref = _initial_quadrics(Vn, Fc, twin, opts["preserve_boundary"],
                                      opts["feature_angle_deg"], tun, scratch)
    del scratch
    # for the final relocation: the input's border edges and crease vertices, and its
    # faces when small enough for the backward pull (the engine rewrites Fc)
    Eb_in = np.stack(half_edge_ends(Fc, np.flatnonzero(twin == BOUNDARY)), axis=1)
    creases = sorted_unique(np.concatenate(half_edge_ends(Fc, np.flatnonzero(feat))))
    Fin = Fc.copy() if m0 <= tun.relocate_back_max_faces else None
    if opts["weights"] is not None:
        Q *= opts["weights"][order][:, None]
    mesh = State(Vn, Fc, twin, Q, lock, feat, Nref, forig=forder)  # Fc is spatial_order's own array
    return _SetUp(mesh, clean.V, Vn, order, centre, scale, creases, Eb_in, Fin, m0,
                  {"set-up": time.perf_counter() - t0})


def _cage_of(su, mesh, stopped, passes, opts, relocate=True):
    """The engine's ``mesh`` (compact) as a cage in the clean mesh's order and
    the caller's units, after the final relocation when ``relocate``."""
    tun = opts["tuning"]
    t0 = time.perf_counter()
    F_out, touched = mesh.F, None
    features = _feature_edges(mesh)       # (the touch-up flips none: the same after it)
    if (relocate and tun.relocate_iters > 0 and passes > 0 and mesh.worst > tun.free_error
            and mesh.F.shape[0] <= min(tun.relocate_max_faces, tun.relocate_max_share * su.m0)):
        cos_max = opts["dihedral_cos"]
        V0, moved0 = mesh.V, mesh.moved.copy()
        bend0 = None if cos_max is None else _bend_cosines(mesh)
        _relocate_cage(mesh, su.Vn, su.creases, su.Eb_in, su.Fin, tun)
        if cos_max is not None and ((_bend_cosines(mesh) < cos_max) & (bend0 >= cos_max)).any():
            mesh.V, mesh.moved = V0, moved0      # it would bend faces beyond the bound: undone
        elif cos_max is None and su.Fin is not None and tun.touch_rounds > 0:
            t1 = time.perf_counter()
            F_out = _touched_up(su, mesh, features, tun)
            touched = time.perf_counter() - t1
    F_out, features = flip_flat_faces(mesh.V, F_out, features)
    # back to the caller's units; vertices never moved keep their exact input position
    Vout = mesh.V * su.scale + su.centre
    still = ~mesh.moved
    Vout[still] = su.V_clean[su.order[mesh.orig[still]]]
    # and the faces flat there (the working positions are snapped: a flat input face kept
    # was not flat in them, and came out flat in a cage at or above the input's face count)
    F_out, features = flip_flat_faces(Vout, F_out, features)
    # back to the clean mesh's order: cage vertices in the order of the clean vertices
    # they keep, faces in the order of the clean faces they descend from
    vorder = np.argsort(su.order[mesh.orig])  # (distinct keys)
    new_v = np.empty(vorder.size, dtype=np.int64)
    new_v[vorder] = np.arange(vorder.size, dtype=np.int64)
    cur = mesh.cur_of_clean
    of_clean = np.empty(su.order.size, dtype=np.int64)
    of_clean[su.order] = np.where(cur >= 0, new_v[np.maximum(cur, 0)], -1)
    a, b = (new_v[e] for e in features.T)
    fe = np.stack([np.minimum(a, b), np.maximum(a, b)], axis=1)
    fe = fe[np.lexsort((fe[:, 1], fe[:, 0]))]
    forder_out = np.argsort(mesh.forig, kind="stable")
    seconds = {**su.seconds, **mesh.seconds,
               "relocate and output": time.perf_counter() - t0 - (touched or 0.0)}
    if touched is not None:
        seconds["touch-up"] = touched
    return _Cage(Vout[vorder], new_v[F_out[forder_out]], of_clean, mesh.forig[forder_out],
                 fe.astype(np.int64), float(mesh.worst * su.scale), stopped, passes, seconds)


def _feature_edges(mesh):
    """(k,2) the engine mesh's feature edges (its own vertex ids), each once."""
    hf = np.flatnonzero(mesh.feat)
    tf = mesh.twin[hf]
    hf = hf[(tf > hf) | (tf == BOUNDARY)]  # one half-edge per feature edge
    return np.stack(half_edge_ends(mesh.F, hf), axis=1)


def _touched_up(su, mesh, features, tun):
    """The relocated cage's farthest places from the input touched up
    (:func:`~._touch_up.touch_up`; its locked vertices stay, its feature
    edges ``features`` are not flipped): ``mesh.V`` and ``mesh.moved``
    updated, the new faces returned (``mesh.F``, whose half-edge tables they
    would no longer match, is left as it is)."""
    V, F, moved = touch_up(mesh.V, mesh.F, su.Vn, su.Fin, mesh.locked, features, tun,
                           mesh.Nref if tun.ref_cos > -1.0 else None)
    mesh.V = V
    mesh.moved |= moved
    return F


def _collapse(su, clean, target, opts, progress):
    """Collapse the cleaned mesh (set up as ``su``) to ``target`` (see :func:`simplify`)."""
    stopped, passes = _run_all(su.mesh, target, None, opts, progress, su.m0)
    if stopped == "cancelled":
        return _unchanged(clean)
    return _cage_of(su, su.mesh, stopped, passes, opts)


def _run_all(mesh, target, max_err_n, opts, progress, m0):
    """The collapse loop, and with ``preserve_topology=False`` the topology
    changes that let it go on (see ``core._relax``)."""
    tun = opts["tuning"]
    if target is not None and m0 <= target:
        return "target", 0
    stopped, passes = run(mesh, target, max_err_n, opts["preserve_boundary"], progress, m0, tun,
                          opts["dihedral_cos"])
    while not opts["preserve_topology"] and stopped == "no_valid_collapse":
        # the link condition stopped every collapse: close 3-edge holes, drop
        # components that cannot shrink, cap the shortest longer hole, and go on
        need = mesh.F.shape[0] - target if target is not None else mesh.F.shape[0]
        before, m_before = copy.deepcopy(mesh), mesh.m_live
        changed = close_triangular_holes(mesh)
        if not changed:
            size = tun.relax_max_size if max_err_n is None else min(tun.relax_max_size, max_err_n)
            changed = drop_stuck_components(mesh, need, size)
        if not changed:
            changed = close_smallest_hole(mesh, tun)
        if not changed:
            break
        stopped, more = run(mesh, target, max_err_n, opts["preserve_boundary"], progress, m0, tun,
                            opts["dihedral_cos"])
        passes += more
        if stopped == "no_valid_collapse" and mesh.m_live >= m_before:
            _restore(mesh, before)
            break
    return stopped, passes


def _restore(mesh, before):
    """Put the engine state ``mesh`` back as its copy ``before`` was (its
    seconds kept): a cap whose faces nothing could collapse (every vertex of
    its rim locked) had left the cage with more faces than the input (an
    icosphere with 8% of its faces removed, every vertex locked, asked for
    20 faces: 1,182 -> 1,320)."""
    seconds = mesh.seconds
    vars(mesh).update(vars(before))
    mesh.seconds = seconds


def _stop_reason(cage, target, opts):
    """``"topology_floor"`` instead of ``"no_valid_collapse"`` or
    ``"max_error"`` when, short of the target (or with none), every edge left
    would change the topology or touch only locked vertices: no bound could
    have let another collapse through (a tetrahedron with a max_error said
    "max_error" or "no_valid_collapse" by the bound's size)."""
    if cage.stopped not in ("no_valid_collapse", "max_error") \
            or (target is not None and cage.F.shape[0] <= target):
        return cage.stopped
    if not opts["preserve_topology"]:
        return cage.stopped
    em, ok = collapsible_edges(cage.F, cage.V.shape[0])
    if opts["locked"] is not None:
        locked = _cage_locks(cage.of_clean, opts["locked"], cage.V.shape[0])
        ok &= ~(locked[em.E[:, 0]] & locked[em.E[:, 1]])
    return "topology_floor" if not ok.any() else cage.stopped


def _within_max_error(su, clean, target, max_error, opts, progress):
    """Collapse with ``max_error`` as a guarantee: the cage's two-sided
    Hausdorff distance to the cleaned input, as ``surface_distance`` measures
    it, is at most ``max_error``.

    The collapse bound is an RMS distance to the planes of the faces a vertex
    stands for, which the worst point can exceed, so the bound is raised in
    steps (``Tuning.max_error_steps`` of ``max_error``), the engine going on from a
    copy of where the last step left it, each step's cage measured quickly
    (``Tuning.max_error_quick_samples``); the first step over the bound is undone
    (when even the first is, smaller first steps are tried), and the gap
    between the last step within it and the first over it is halved
    ``Tuning.max_error_halvings`` times (the cow at 2%: the step from 0.3 to
    0.5 of the bound went from 0.74% to over 2%, so it stopped at the 936
    faces a 1% bound gives). The last step's
    cage is then measured as ``surface_distance`` does by default, relocated
    and not; if both are over, the step before is tried; if every one is
    (the quick measure missed a face's far inside: fandisk with 10 far-apart
    vertex pairs pinched, measured on its vertices alone, came back as the
    cleaned input itself), the engine runs afresh at half the smallest
    step's share, a quarter, ... (``Tuning.max_error_retries``), each fully
    measured, down to the cleaned input itself (distance 0). ``su``: the
    set-up of ``clean``. Returns the cage and its distance.
    """

    t0 = time.perf_counter()
    measure = _HausdorffMeasure(clean)

    def timed(cage, d):
        return _with_step_seconds(cage, time.perf_counter() - t0, measure.seconds), d

    good = _error_steps(su, target, max_error, opts, progress, measure)
    if good is None:
        return timed(_unchanged(clean), 0.0)
    for mesh, st, passes, _ in reversed(good):
        found = _measured_cage(su, mesh, st, passes, opts, measure, max_error)
        if found is not None:
            return timed(*found)
    share = min((g[3] for g in good), default=0.0)     # (no step within: nothing to retry)
    for _ in range(opts["tuning"].max_error_retries if good else 0):
        share /= 2
        trial = copy.deepcopy(su.mesh)
        st, passes = _run_all(trial, target, share * max_error / su.scale, opts, progress, su.m0)
        if st == "cancelled":
            return timed(_unchanged(clean), 0.0)
        found = _measured_cage(su, trial, st, passes, opts, measure, max_error)
        if found is not None:
            return timed(*found)
    found = _by_face_count(su, target, max_error, opts, progress, measure)
    if found is not None:
        return timed(*found)
    return timed(_unchanged(clean)._replace(stopped="max_error"), 0.0)


class _HausdorffMeasure:
    """The two-sided Hausdorff distance of a cage to the cleaned input
    ``clean``, as ``surface_distance`` measures it (``samples``: the quick
    measure's count), in the input's units; the input's index and samples
    made once, and ``seconds`` spent measuring."""

    def __init__(self, clean):
        self.clean = clean
        self.centre, self.scale = measuring_frame(clean.V)
        self.source = DistanceFrom((clean.V - self.centre) / self.scale, clean.F)
        self.seconds = 0.0

    def __call__(self, cage, samples=None):
        if _is_input(cage, self.clean):
            # nothing collapsed or moved: the input's own surface (a soup of 30k separate
            # triangles, which the bound stopped at once, was measured against itself six
            # times: 95-105 s)
            return 0.0
        t = time.perf_counter()
        d = self.scale * self.source.to((cage.V - self.centre) / self.scale, cage.F,
                                        samples=samples,
                                        shared=_shared_faces(cage, self.clean)).hausdorff
        self.seconds += time.perf_counter() - t
        return d


def _error_steps(su, target, max_error, opts, progress, measure):
    """The steps of :func:`_within_max_error`'s raised bound: the engine run
    on from the last step within ``max_error`` (a copy of its state) at each
    share of ``Tuning.max_error_steps``, each cage measured quickly
    (``measure``, a :class:`_HausdorffMeasure`, on
    ``Tuning.max_error_quick_samples``); a step over the bound is dropped and
    the gap to it halved ``Tuning.max_error_halvings`` times (smaller first
    steps when the first is over). Returns the steps within, in order, each
    ``(engine state, stop reason, passes, share)``, or None when cancelled."""
    tun = opts["tuning"]
    steps = list(tun.max_error_steps)
    good = []
    bad, halvings = None, 0                       # the smallest share found over the bound
    while steps:
        share = steps.pop(0)
        mesh, passes = (good[-1][0], good[-1][2]) if good else (su.mesh, 0)
        trial = copy.deepcopy(mesh)
        st, more = _run_all(trial, target, share * max_error / su.scale, opts, progress, su.m0)
        if st == "cancelled":
            return None
        quick = measure(_cage_of(su, trial, st, passes + more, opts, relocate=False),
                        tun.max_error_quick_samples)
        if quick > max_error:
            bad = share
            if not good and share > tun.max_error_steps[0] / 16:
                steps = [share / 2]               # even the first step is over: start lower
                continue
        else:
            good.append((trial, st, passes + more, share))
            if st != "max_error":
                break                             # the target (or the floor) came first
        if bad is not None:                       # halve the gap between the last good share and it
            if not good or halvings == tun.max_error_halvings:
                break
            halvings += 1
            steps = [0.5 * (good[-1][3] + bad)]
    return good


def _shared_faces(cage, clean):
    """``(on_clean, on_cage)``: the faces of the cleaned input that are faces
    of ``cage`` too, and those of the cage that are input faces, for
    :meth:`~.metrics.DistanceFrom.to`'s ``shared``: a cage face whose corners
    are those of the input face it descends from, each a cage vertex never
    moved (bit for bit the input vertex it kept). Found from the cage's
    faces alone: 1-2 ms a measure for a 2,395-face cage of the 1.1M-face
    bunny x16, where matching the input's face keys took 33 ms. None when
    there is none."""
    corners = clean.F[cage.face_from]                   # (m_cage, 3) clean vertices
    at = cage.of_clean[corners]
    same = (np.sort(at, axis=1) == np.sort(cage.F, axis=1)).all(axis=1)
    rows = np.flatnonzero(same)
    rows = rows[(clean.V[corners[rows]] == cage.V[at[rows]]).all(axis=(1, 2))]
    if rows.size == 0:
        return None
    on_cage = np.zeros(cage.F.shape[0], dtype=bool)
    on_cage[rows] = True
    on_clean = np.zeros(clean.F.shape[0], dtype=bool)
    on_clean[cage.face_from[rows]] = True
    return on_clean, on_cage


def _is_input(cage, clean):
    """Whether ``cage`` is the cleaned input's own surface: every vertex
    where it was, as many faces (no collapse; at most a flat face flipped,
    which leaves the surface as it was)."""
    return cage.F.shape[0] == clean.F.shape[0] and cage.V.shape == clean.V.shape \
        and np.array_equal(cage.V, clean.V)


def _by_face_count(su, target, max_error, opts, progress, measure):
    """When no share of the bound gave a cage within ``max_error``: the
    fewest faces found by halving the face count between the cleaned input
    (``su.m0`` faces, distance 0) and ``target`` (or 1)
    ``Tuning.max_error_count_halvings`` times, each cage made with the bound
    and measured fully: (cage, distance) with ``stopped == "max_error"``, or
    None. A mesh whose collapses all cost
    nothing (the cow in float32 at (5e6, 4e6, 300) m, folded onto a few planes:
    a vertex slides within its planes) went as far at every share, always
    beyond the bound, and came back unchanged (5,530 faces at 2% of its size,
    where 2,000 faces are 0.42% off)."""
    lo, hi, best = max(target or 0, 1), su.m0, None
    for _ in range(opts["tuning"].max_error_count_halvings):
        mid = (lo + hi) // 2
        if mid <= lo:
            break
        trial = copy.deepcopy(su.mesh)
        st, passes = _run_all(trial, mid, max_error / su.scale, opts, progress, su.m0)
        if st == "cancelled":
            return None
        found = _measured_cage(su, trial, "max_error", passes, opts, measure, max_error)
        if found is None:
            lo = mid
        else:
            hi, best = min(mid, found[0].F.shape[0]), found
    return best


def _with_step_seconds(cage, elapsed, measured):
    """``cage`` with the seconds of :func:`_within_max_error` beyond its own
    stages: ``"measure"`` (the distance measures) and ``"steps"`` (the runs of
    the bound's other steps, their copies and cages). A bunny with a bound of
    half its size took 47 s, of which its stages said 2."""
    own = sum((cage.seconds or {}).values())
    return cage._replace(seconds={**(cage.seconds or {}), "measure": measured,
                                  "steps": max(0.0, elapsed - measured - own)})


def measuring_frame(V):
    """``(centre, scale)`` of the frame ``max_error`` is measured in, for
    the positions ``V``: ``(V - centre) / scale`` goes to ``surface_distance``
    and its distances are multiplied by ``scale``. The mesh's own units
    (``(0, 1)``) when ``surface_distance`` takes them (:data:`~.mesh.UNITS`),
    else centred on its bounding box and scaled to a unit diagonal: a part
    1e-18 across or 1e15 from the origin was refused with
    ``surface_distance``'s message ('... (simplify takes any units)') by a
    simplify with ``max_error``."""
    lo, hi = bounding_box(V)
    reach = float(np.maximum(np.abs(lo), np.abs(hi)).max(initial=0.0))
    size = diagonal_length(lo, hi)
    if reach <= UNITS[1] and not 0.0 < size < UNITS[0]:
        return np.zeros(3), 1.0
    return 0.5 * (lo + hi), size or 1.0


def _measured_cage(su, mesh, stopped, passes, opts, measure, max_error):
    """The cage of the engine state ``mesh`` (relocated, else not) and its
    distance, measured by ``measure``, if one is within ``max_error``; else
    None."""
    for relocated in (True, False):
        cage = _cage_of(su, copy.deepcopy(mesh), stopped, passes, opts, relocate=relocated)
        d = measure(cage)
        if d <= max_error:
            return cage, d
    return None


@plain_pages
def simplify(V, F, *, target_faces=None, ratio=None, max_error=None, preserve_boundary=True,
             preserve_topology=True, feature_angle_deg=60.0, vertex_weights=None, locked=None,
             weld_distance=None, min_component_area=MIN_COMPONENT_AREA, symmetry=None,
             max_dihedral_deg=None, close_pinholes=True, progress=None, tuning=None):
    """Simplify a triangle mesh to a coarse, clean manifold cage (QEM).

    The input is cleaned first (:func:`core.clean.clean_mesh`: welded,
    bow-ties and non-manifold edges split, double-sided sheets and debris
    removed, oriented), so the cage is always an edge- and vertex-manifold
    mesh, whatever arrives; ``cleaning`` in the result says what was done.

    Parameters
    ----------
    V : (n,3) float array_like
    F : (m,3) int array_like
    target_faces : int >= 0, optional
        Stop once the cage has at most this many faces.
    ratio : float in (0, 1], optional
        Target as a share of the cleaned input's faces, ``round(ratio * m)``.
    max_error : float >= 0, optional
        A guarantee, in the mesh's units: the cage's two-sided Hausdorff
        distance to the cleaned input, as :func:`core.surface_distance`
        measures it (default samples and seed; on the mesh scaled to a unit
        size when it is outside the units that takes, :data:`~.mesh.UNITS`),
        is at most this. Collapses
        whose error (the RMS distance of the new vertex to the planes of the
        input faces it stands for) exceeds the bound are refused, and when the
        measured distance would exceed it the last step of the bound is undone
        (see ``_within_max_error``). At least one of ``target_faces``,
        ``ratio``, ``max_error`` is needed; the run stops at whichever is
        reached first.
    max_dihedral_deg : float in (0, 180), optional
        Refuse every collapse that would bend two adjacent cage faces (the
        angle between their normals) by more than this, except across the
        input's creases (``feature_angle_deg``); the final relocation is
        undone if it would, and a pinhole whose cap would is left open
        (``close_pinholes``). Short of the target for that reason,
        ``stopped_because == "max_dihedral"``.
    preserve_boundary : bool
        Add heavy constraint planes on open borders so they keep their shape;
        an interior edge with one boundary endpoint collapses onto it.
    preserve_topology : bool
        Enforce the link condition: genus, boundary loops and components
        kept (pinholes aside: see ``min_component_area``); a target below
        what that allows stops at the topology floor
        (``stopped_because == "topology_floor"``). With ``False``, once the
        link condition stops every collapse before the target, holes bounded
        by three edges are closed with a triangle and components that cannot
        shrink any further (a tetrahedron, a lone triangle; at most a quarter
        of the mesh's size and no larger than ``max_error`` when it is given;
        never the largest component or one with locked vertices) are
        removed, smallest first, and simplification goes on. The output is
        still a clean manifold; input vertices of removed components map to ``-1``.
    feature_angle_deg : float in (0, 180] or None
        Edges whose faces meet at more than this angle get constraint planes
        (creases and corners survive) and are reported in ``feature_edges``.
    vertex_weights : (n,) float >= 0, optional
        Importance of each input vertex: scales its quadric.
    locked : (n,) bool, optional
        Locked vertices are never moved or removed.
    weld_distance, min_component_area : float >= 0 (weld_distance: or None)
        Cleaning tolerances, see :func:`core.clean.clean_mesh` (shares of the
        bounding-box diagonal and of the largest component's area; the
        default weld widens itself on an input that comes in pieces). With a
        target and no ``max_error``, components too small for one face of
        the target (by their share of the area) are dropped as debris too,
        and reported, never one with a locked vertex. When the collapse
        stops short of the target with the topology kept, holes smaller than
        one face of the target (pinholes, see :mod:`core.pinholes`) are
        capped, reported, and the input simplified again: a scan with
        thousands of tiny holes still reaches its target (``close_pinholes``).
    close_pinholes : bool
        Cap the pinholes when they stop the cage short of its target (see
        ``min_component_area``); False keeps every hole.
    symmetry : {None, 'X', 'Y', 'Z'}
        Make the cage mirror-symmetric about the plane through the origin
        normal to this axis (see :func:`core.symmetry.simplify_symmetric`).
    progress : callable(float) -> bool or None, optional
        Called after every pass with the fraction done (0..1); returning
        ``False`` stops with ``stopped_because == "cancelled"`` and the
        cleaned input, unchanged, as the cage.
    tuning : :class:`core.tuning.Tuning` or None
        Advanced: the engine's constants (pool sizes, penalty weights,
        relocation, block sizes); ``None`` for the measured defaults
        (``core.tuning.TUNING``).

    Returns
    -------
    SimplifyResult

    Raises
    ------
    InvalidMeshError
        NaN/inf coordinates, indices out of range, wrong shapes or dtypes,
        nothing left after cleaning (every face degenerate or duplicate), or
        no face with an area (every face's corners on one line, up to
        rounding: :func:`core.mesh.has_area`).
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
    progress = _never_back(progress)
    if symmetry is not None:
        from .symmetry import simplify_symmetric
        return simplify_symmetric(
            V, F, axis=symmetry, target_faces=target_faces, ratio=ratio, max_error=max_error,
            preserve_boundary=preserve_boundary, preserve_topology=preserve_topology,
            feature_angle_deg=feature_angle_deg, vertex_weights=vertex_weights, locked=locked,
            weld_distance=weld_distance, min_component_area=min_component_area,
            max_dihedral_deg=max_dihedral_deg, close_pinholes=close_pinholes, progress=progress,
            tuning=tuning)
    if tuning is not None and not isinstance(tuning, Tuning):
        raise InvalidArgumentError(f"{_WHERE}: tuning must be a core.tuning.Tuning, not "
                                   f"{type(tuning).__name__}")
    V, F = check_mesh(V, F, where=_WHERE)
    n_in = V.shape[0]
    step = float32_step(V)
    weights, lk = check_arguments(n_in, target_faces, ratio, max_error, feature_angle_deg,
                                  vertex_weights, locked, progress, max_dihedral_deg)
    preserve_boundary, preserve_topology, close_pinholes = check_flags(
        preserve_boundary=preserve_boundary, preserve_topology=preserve_topology,
        close_pinholes=close_pinholes)
    t0 = time.perf_counter()
    clean = cleaned_input(V, F, weld_distance, min_component_area,
                          debris_budget(target_faces, ratio, max_error, F.shape[0]), lk)
    t_clean = time.perf_counter() - t0
    cleaned = CleanedInput(clean.V, clean.F)      # (before any pinhole caps)
    m_in = F.shape[0]
    stood_for = represented_faces(F, clean)
    del V, F                     # check_mesh's copies: the clean mesh is all that is needed now
    target = target_count(target_faces, ratio, clean.F.shape[0])
    opts = dict(tuning=TUNING if tuning is None else tuning, preserve_boundary=preserve_boundary,
                preserve_topology=preserve_topology, feature_angle_deg=feature_angle_deg,
                dihedral_cos=dihedral_cos(max_dihedral_deg),
                weights=None if weights is None else per_clean_vertex(weights, clean),
                locked=None if lk is None else per_clean_vertex(lk, clean))
    hausdorff = None
    if clean.F.shape[0] == 0:
        cage = _unchanged(clean)._replace(stopped="target")
    elif max_error is None:
        capped = cap_pinholes(clean, target, opts["dihedral_cos"]) \
            if close_pinholes and target is not None and opts["preserve_topology"] else None
        uncapped = None
        if capped is not None and \
                face_floor(clean.V, clean.F, clean.twin) > opts["tuning"].pinhole_floor_share * target:
            clean, capped, uncapped = capped, None, clean   # the holes could not reach it: below
        cage, clean = _collapsed(clean, target, opts, progress)
        if capped is not None:
            cage, clean = _through_pinholes(cage, clean, capped, target, progress, opts)
        elif uncapped is not None and cage.F.shape[0] > uncapped.F.shape[0]:
            # the caps stayed (their rims locked): the input without them is closer
            cage, clean = _through_pinholes(cage, clean, uncapped, target, progress, opts)
    else:
        su = _set_up(clean, opts)
        clean = clean._replace(twin=None, area=None)   # (3m,) and (m,): not needed past the set-up
        cage, hausdorff = _within_max_error(su, clean, target, max_error, opts, progress)
        cage = cage._replace(stopped=_stop_reason(cage, target, opts))
    cage = cage._replace(seconds={"clean": t_clean, **cage.seconds})
    return replace(
        _result(cage, clean, m_in, n_in, target, hausdorff, t0, preserve_boundary, stood_for, step),
        bound=None if max_error is None else float(max_error), cleaned=cleaned,
        locked=None if lk is None else _cage_locks(cage.of_clean, opts["locked"], cage.V.shape[0]))


def _cage_locks(cage_of, locked, n_cage):
    """(n_cage,) bool: the cage vertices that a ``locked`` vertex maps to
    (``cage_of``: each vertex's cage vertex, -1 for none). A cage vertex
    that merged a locked vertex is locked, whatever the others it merged:
    the collapse kept it where the locked one is. Taken over the cleaned
    input's vertices (``SimplifyResult.locked`` had been taken over the
    input's, through ``vertex_map``, which names one of the copies a locked
    bow-tie vertex is split into: the engine held both, the result marked one)."""
    mask = np.zeros(n_cage, dtype=bool)
    mask[cage_of[(cage_of >= 0) & locked]] = True
    return mask


def _collapsed(clean, target, opts, progress):
    """The cage of ``clean`` at ``target`` (set up, collapsed, its stop reason
    said), and ``clean`` without its twin table and face areas (not needed past
    the set-up)."""
    su = _set_up(clean, opts)
    clean = clean._replace(twin=None, area=None)
    cage = _collapse(su, clean, target, opts, progress)
    return cage._replace(stopped=_stop_reason(cage, target, opts)), clean


def _through_pinholes(cage, clean, capped, target, progress, opts):
    """When the cage of ``clean`` stopped short of the target (every hole
    keeps three vertices of its own): the cage of ``capped``, ``clean`` with
    its pinholes (holes smaller than one face of the target,
    :func:`~.pinholes.cap_pinholes`) capped, ``progress`` going on from where
    the first run left it; the closer of the two cages to the target wins.
    Returns the cage and the cleaned input it was made from. (When the
    topology rules the target out, :func:`simplify` starts from ``capped``:
    :func:`~.pinholes.face_floor`, the fewest faces Euler's formula allows a
    cage of ``clean`` with all its holes and handles, is above
    ``Tuning.pinhole_floor_share`` of the target; the
    bunny with 5% of its faces missing has 2,491 pinholes for a 50-face
    target. The second run is then left for targets just under that floor,
    where the collapse may still stop short; and with the roles swapped, when
    that cage kept more faces than ``clean`` without its caps has: every rim
    locked, the caps could not collapse.)"""
    if cage.F.shape[0] <= target or cage.stopped not in ("no_valid_collapse", "topology_floor"):
        return cage, clean
    done = (clean.F.shape[0] - cage.F.shape[0]) / max(clean.F.shape[0] - target, 1)
    again, capped = _collapsed(capped, target, opts, _going_on(progress, done))
    if again.stopped == "cancelled":
        return _unchanged(clean), clean
    if again.F.shape[0] >= cage.F.shape[0]:
        return cage, clean
    first = sum(v for k, v in cage.seconds.items() if k != "total")
    return again._replace(seconds={**again.seconds, "stopped short (pinholes)": first}), capped


def _never_back(progress):
    """``progress`` told the largest fraction so far: the steps of a
    ``max_error`` bound start again from the last one kept, and a symmetric
    run's half again for fewer faces, so the fractions went back (0.80 to
    0.79 on a cow with holes, 0.99 to 0.25 symmetric), and a progress bar
    with them. Its answer (False: cancel) is passed on; None, anything not
    callable (for the argument check to name) and one already wrapped come
    back as they are."""
    if progress is None or not callable(progress) or getattr(progress, "never_back", False):
        return progress
    most = [0.0]

    def told(fraction):
        most[0] = max(most[0], float(fraction))
        return progress(most[0])

    told.never_back = True
    return told


def _going_on(progress, done):
    """``progress`` for a second run mapped onto what is left after ``done`` (0..1)."""
    if progress is None:
        return None
    done = min(max(done, 0.0), 1.0)
    return lambda fraction: progress(done + (1.0 - done) * fraction)


def cleaned_input(V, F, weld_distance, min_component_area, budget, locked):
    """The cleaned input (:func:`core.clean.clean_mesh`), or a clear error
    when nothing with area is left of it."""
    used = np.zeros(V.shape[0], dtype=bool)
    used[F.ravel()] = True
    check_span(V[used], where=_WHERE)
    clean = clean_mesh(V, F, weld_distance=weld_distance, min_component_area=min_component_area,
                       face_budget=None if budget is None else max(budget, 1), protected=locked)
    if clean.F.shape[0] == 0 and F.shape[0] > 0:
        raise InvalidMeshError(
            f"{_WHERE}: nothing is left after cleaning the {F.shape[0]:,} faces "
            f"({clean.report.summary() or 'no faces'}): no cage can be made")
    if clean.F.shape[0] and not has_area(clean.V, clean.F):
        raise InvalidMeshError(
            f"{_WHERE}: the {clean.F.shape[0]:,} faces left after cleaning have no area (their "
            f"corners are collinear{_far_off(clean.V)}): no cage can be made")
    return clean


def input_vertex_map(clean, of_clean):
    """(n_in,) int64: the cage vertex of each input vertex of the cleaned
    input ``clean``, given the cage vertex of each clean vertex ``of_clean``
    (-1: none): that of its first copy (``input_to_clean``), or when that one
    is gone, of another copy that a bow-tie split made (a piece removed with
    ``preserve_topology=False`` took the first copy, and a vertex of the cage
    was said to stand for no input vertex); -1 when none is left."""
    out = np.full(clean.input_to_clean.shape[0], -1, dtype=np.int64)
    kept = np.flatnonzero(clean.input_to_clean >= 0)
    first = clean.input_to_clean[kept]
    out[kept] = of_clean[first]
    gone = np.flatnonzero(out[kept] < 0)
    if gone.size:
        alive = np.flatnonzero(of_clean >= 0)
        other = np.full(clean.input_to_clean.shape[0], -1, dtype=np.int64)
        other[clean.clean_to_input[alive]] = of_clean[alive]     # by the weld group's vertex
        out[kept[gone]] = other[clean.clean_to_input[first[gone]]]
    return out


def per_clean_vertex(values, clean):
    """The per-input-vertex ``values`` (n_in,) (weights, or lock flags) as
    one per vertex of the cleaned input ``clean``: the largest (for flags:
    any) of the input vertices welded into it. Taken from the one it sits on
    (``clean_to_input``, the first of its weld group), a lock on any other
    copy of an unwelded (STL) input's vertex was lost, and the vertex moved."""
    i = np.flatnonzero(clean.input_to_clean >= 0)
    out = values.copy()
    np.maximum.at(out, clean.clean_to_input[clean.input_to_clean[i]], values[i])
    return out[clean.clean_to_input]


def represented_faces(F, clean):
    """(m,) bool per input face ``F`` (checked): whether the cleaned input
    ``clean`` (:class:`~.clean.CleanResult` of it) stands for it: kept (or
    split at a T-junction), on the same vertices as a kept face (a duplicate,
    the dropped side of a double-sided sheet that mends the surface), or with
    two corners welded into one (no area left); not a face dropped as debris,
    as a coincident copy or as a double-sided sheet removed whole, even when
    other faces keep its corners."""
    K = clean.input_to_clean[F]
    mapped = all_in_rows(K >= 0)
    kept = np.zeros(F.shape[0], dtype=bool)
    kept[clean.face_to_input] = True
    collapsed = (K[:, 0] == K[:, 1]) | (K[:, 1] == K[:, 2]) | (K[:, 0] == K[:, 2])
    out = kept | (mapped & collapsed)
    rest = np.flatnonzero(mapped & ~out)
    if rest.size:
        keys = face_keys(np.concatenate([K[kept], K[rest]]), clean.V.shape[0])
        n_kept = int(np.count_nonzero(kept))
        out[rest] = member_of(keys[n_kept:], keys[:n_kept])
    return out


def _far_off(V):
    """A hint for :func:`cleaned_input`'s error when the mesh lies so far
    from the origin for its size that its coordinates hold at most
    :data:`FEW_DIGITS` significant digits of its shape (a millimetre part
    placed a thousand kilometres off): then the faces' area is lost in the
    coordinates' rounding; empty otherwise."""
    lo, hi = bounding_box(V)
    size = diagonal_length(lo, hi)
    far = float(np.abs(np.concatenate([lo, hi])).max())
    if size > 0 and far == 0:
        return ""
    digits = max(0, 15 - int(np.floor(np.log10(far / size)))) if size > 0 else 0
    if digits > FEW_DIGITS:
        return ""
    return (f", or lost in rounding: the mesh is {size:.3g} across and {far:.3g} from the origin, "
            f"so its coordinates keep only {digits} significant digits of its shape: move it to "
            f"the origin first")


def dihedral_cos(max_dihedral_deg):
    """The cosine the engine compares adjacent faces' normals with for
    ``max_dihedral_deg`` (None for none)."""
    return None if max_dihedral_deg is None else float(np.cos(np.radians(max_dihedral_deg)))


def debris_budget(target_faces, ratio, max_error, m):
    """The face count below which a component is too small for one face of
    the target (debris), or None: never with ``max_error`` (dropping a
    component could break its bound). (A target of 0 faces is the smallest
    cage: a budget of 1 face, not None, which had kept the debris.)"""
    if max_error is not None:
        return None
    return target_faces if ratio is None else max(target_faces or 0, round(ratio * m))


def target_count(target_faces, ratio, m0):
    """The face count asked for (the larger of the two when both are given),
    None with only ``max_error``."""
    target = None if target_faces is None else int(target_faces)
    if ratio is not None:
        t = int(round(float(ratio) * m0))
        if ratio > 0 and m0 > 0:
            t = max(t, 1)              # (a ratio of 1e-9 had asked for 0 faces)
        target = t if target is None else max(target, t)
    return target


def _result(cage, clean, m_in, n_in, target, hausdorff, t0, preserve_boundary, stood_for,
            step=None):
    """The :class:`SimplifyResult` of ``cage``, mapped back to the input
    (``stood_for``: :func:`represented_faces` of the input)."""
    vertex_map = input_vertex_map(clean, cage.of_clean)
    _, n_comp = face_components(cage.F, cage.V.shape[0])
    em = edge_map(cage.F, cage.V.shape[0])          # (for both border counts)
    return SimplifyResult(
        V=cage.V, F=cage.F, vertex_map=vertex_map, face_map=clean.face_to_input[cage.face_from],
        max_error=cage.worst, stopped_because=cage.stopped, feature_edges=cage.feature_edges,
        cleaning=clean.report, n_input_faces=int(m_in), target=target, hausdorff=hausdorff,
        n_boundary_loops=boundary_loops_count(cage.F, cage.V.shape[0], em), n_components=n_comp,
        n_passes=cage.passes, seconds={**cage.seconds, "total": time.perf_counter() - t0},
        n_border_vertices=border_vertex_count(cage.F, cage.V.shape[0], em),
        preserve_boundary=preserve_boundary,
        n_input_pieces=soup_pieces(cage.F, cage.V.shape[0], clean.F, clean.V.shape[0], n_comp),
        represented_faces=stood_for, n_clean_faces=int(clean.F.shape[0]), float32_step=step)
