"""Pinholes: holes too small for one face of the cage, capped when they stop it.

A scan has holes where the scanner saw nothing, and many of them are tiny: a
few missing triangles, or faces an exporter dropped as degenerate. Every hole
is a border loop, and a cage that keeps the topology keeps every loop with at
least three vertices of its own: the bunny with 5% of its faces missing (2,493
holes) stopped at 12,578 faces when 50 were asked. A hole smaller than one
face of the cage cannot be seen in it anyway, so when the collapse stops
short of its target, :func:`~.simplify.simplify` caps such holes in the
cleaned input (:func:`cap_pinholes`: a fan of triangles from one rim vertex,
oriented with the surface), reports them, and simplifies again. Holes are
capped only then: a cap spans a place where the input has no surface, so it
costs distance (suzanne's eye holes capped at 18 faces: Hausdorff 14.9% of
the diagonal instead of 9.9%).

A border loop is a *pinhole* when

    its size            a disk of its perimeter has at most ``PINHOLE_FACES``
                        times the mean area of a face of a cage of
                        ``face_budget`` faces over the surface: the hole is
                        smaller than one face of the cage, and
    its surface         (the component it borders) has at least
                        ``PINHOLE_SURFACE`` times the area of a disk of that
                        perimeter: a tiny disk or strip, whose border is all
                        there is of it, is left open (capping it would make a
                        flat double-sided pillow).

A fan whose diagonal is already an edge of the mesh (it would be used three
times) starts from another rim vertex; a loop where ``_APEX_TRIES`` of them
all clash is left open.
"""

from dataclasses import replace
from typing import NamedTuple

import numpy as np

from ._groups import member_of, sorted_unique
from ._clean import BOUNDARY, half_edge_ends, interior_edges, twin_table
from .mesh import (area_normals_rows, bounding_box, diagonal_length, face_areas, flat_faces,
                   lengths, row_norms, unit_rows)
from .topology import connected_labels, edge_keys, vertex_labels

__all__ = ["PINHOLE_FACES", "PINHOLE_SURFACE", "MAX_PINHOLE_EDGES", "Pinholes", "cap_pinholes",
           "close_pinholes", "face_floor", "Slits", "zip_slits"]

#: a disk of a pinhole's perimeter has at most this many times the area of a mean cage face
#: (a perimeter of about 2.3 mean cage edges)
PINHOLE_FACES = 1.0

#: ... and its surface at least this many times the area of a disk of that perimeter
PINHOLE_SURFACE = 10.0

#: loops of more edges are never pinholes (a hole that long is a feature of the scan)
MAX_PINHOLE_EDGES = 64

#: rim vertices tried as a fan's apex before a clashing loop is left open
_APEX_TRIES = 3


class Pinholes(NamedTuple):
    """The faces with the pinholes' caps appended (see :func:`close_pinholes`)."""

    F: np.ndarray          #: (m + k, 3) int64, the caps after the faces
    twin: np.ndarray       #: (3(m + k),) int64 their twin table
    beside: np.ndarray     #: (k,) int64 for each cap, the face beside its rim edge
    n_holes: int           #: holes closed


class _Loops(NamedTuple):
    """Border loops of a manifold mesh, as border half-edges and their order."""

    h: np.ndarray          #: (b,) int64 the border half-edges
    u: np.ndarray          #: (b,) int64 their start vertices (the loop runs u -> w)
    succ: np.ndarray       #: (b,) int64 position (in h) of the next border half-edge
    label: np.ndarray      #: (b,) int64 the loop of each, the smallest position in it
    count: np.ndarray      #: (b,) int64 per label: edges of the loop
    perimeter: np.ndarray  #: (b,) float64 per label: its length

    def heads(self):
        """(b,) bool: the first border half-edge of each loop (its label)."""
        return self.label == np.arange(self.h.shape[0])


def cap_pinholes(clean, face_budget, bend_cos=None):
    """The :class:`~.clean.CleanResult` ``clean`` with its pinholes for a cage
    of ``face_budget`` faces capped: the caps after its faces, each mapped to
    the input face beside its rim edge (``face_to_input``, ``area``), the twin
    table rebuilt, ``n_pinholes`` / ``n_pinhole_faces`` in its report; None
    when it has no pinhole. With ``bend_cos`` (the cosine of a dihedral
    bound), a hole whose cap would bend two adjacent faces beyond it is left
    open (see :func:`close_pinholes`)."""
    n = clean.V.shape[0]
    twin = clean.twin if clean.twin is not None else twin_table(clean.F, n)
    lo, hi = bounding_box(clean.V)
    Vs = (clean.V - lo) / (diagonal_length(lo, hi) or 1.0)    # unit-free: no overflow at 1e200
    area = face_areas(Vs, clean.F)
    capped = close_pinholes(Vs, clean.F, twin, area, face_budget, bend_cos)
    if capped is None:
        return None
    report = replace(clean.report, n_pinholes=capped.n_holes,
                     n_pinhole_faces=int(capped.beside.shape[0]))
    return clean._replace(
        F=capped.F, twin=capped.twin, report=report,
        face_to_input=np.concatenate([clean.face_to_input, clean.face_to_input[capped.beside]]),
        area=None if clean.area is None else np.concatenate([clean.area, clean.area[capped.beside]]))


def close_pinholes(V, F, twin, face_area, face_budget, bend_cos=None):
    """Cap the pinholes (see the module docstring) of the oriented
    vertex-manifold mesh ``(V, F)`` with twin table ``twin``; ``face_area``
    (m,) the faces' areas, ``face_budget`` the cage's face count. With
    ``bend_cos``, a hole whose cap has two adjacent faces (among its own and
    those around its rim) whose normals' cosine is below it is left open: a
    cap is a fan over the rim, which on a bumpy surface bends where the
    surface did not, and ``simplify(max_dihedral_deg=)`` promises no such
    bend (a bumpy torus with 20 one-ring holes, bent 18 degrees at most, had
    capped edges bent 60 degrees with a bound of 30). Returns
    :class:`Pinholes`, or None when there is none."""
    if face_budget is None or F.shape[0] == 0:
        return None
    loops = _border_loops(V, F, twin)
    if loops is None:
        return None
    # (a target of 0 faces is the smallest cage: a budget of 1)
    longest = np.sqrt(4.0 * np.pi * PINHOLE_FACES * float(face_area.sum()) / max(face_budget, 1))
    heads = np.flatnonzero(loops.heads() & (loops.count >= 3) & (loops.count <= MAX_PINHOLE_EDGES)
                           & (loops.perimeter <= longest))
    if heads.size == 0:
        return None
    heads = heads[_on_large_surface(F, twin, face_area, loops, heads)]
    if heads.size == 0:
        return None
    rim, count = _rims(loops, heads)
    caps, beside = _fans(V, F, rim, count, loops)
    if caps.shape[0] == 0:
        return None
    F2 = np.concatenate([F, caps])
    twin2 = twin_table(F2, V.shape[0])
    if bend_cos is not None:
        keep = _caps_within(V, F2, twin2, F.shape[0], beside[:, 1], bend_cos)
        if not keep.all():
            caps, beside = caps[keep], beside[keep]
            if caps.shape[0] == 0:
                return None
            F2 = np.concatenate([F, caps])
            twin2 = twin_table(F2, V.shape[0])
    n_holes = int(sorted_unique(beside[:, 1]).shape[0])
    return Pinholes(F2, twin2, beside[:, 0], n_holes)


def _caps_within(V, F2, twin, m, hole, bend_cos):
    """(k,) bool: the cap faces (``F2[m:]``, twin table ``twin``) of the
    holes whose every cap face meets each of its neighbours (the other faces
    of its cap, the faces around the rim) with normals whose cosine is at
    least ``bend_cos`` (``hole``: each cap face's hole; a cap face with no
    area has no normal: bent)."""
    across = twin[3 * m:].reshape(-1, 3) // 3                  # the faces beside each cap edge
    cap = area_normals_rows(V, F2[m:].T)
    beside = unit_rows(area_normals_rows(V, F2[np.maximum(across, 0).ravel()].T))
    cos = np.einsum("kij,kj->ki", beside.reshape(-1, 3, 3), unit_rows(cap))
    bent = ((cos < bend_cos) & (across >= 0)).any(axis=1) | (row_norms(cap) == 0)
    return ~member_of(hole, hole[bent])


def face_floor(V, F, twin):
    """The fewest faces a cage of the oriented vertex-manifold mesh ``(V, F)``
    (twin table ``twin``) can have and keep its topology, by
    Euler's formula: a component with Euler characteristic chi, b border loops
    and B border edges has F = 2V - B - 2 chi faces, and V >= B >= 3b, so at
    least 3b - 2 chi (a sphere with h holes: 5h - 4); a closed one at least 4.
    Summed over the components (see ``Tuning.pinhole_floor_share``)."""
    n, m = V.shape[0], F.shape[0]
    if m == 0:
        return 0
    comp = _surfaces(m, twin)
    faces = np.bincount(comp, minlength=m)
    border = np.flatnonzero(twin == BOUNDARY)
    edges = np.bincount(comp[border // 3], minlength=m)             # border edges per component
    vc = vertex_labels(F, comp, n)
    verts = np.bincount(vc[vc >= 0], minlength=m)
    loops = np.zeros(m, dtype=np.int64)
    found = _border_loops(V, F, twin)
    if found is not None:
        loops = np.bincount(comp[found.h[found.heads()] // 3], minlength=m)
    chi = verts - (3 * faces + edges) // 2 + faces
    floor = np.where(loops > 0, 3 * loops - 2 * chi, 4)
    return int(floor[faces > 0].sum())


class Slits(NamedTuple):
    """The faces with the T-junctions' slits zipped (see :func:`zip_slits`)."""

    F: np.ndarray          #: (m + k, 3) int64, each split face in place, its other parts after the faces
    twin: np.ndarray       #: (3(m + k),) int64 their twin table
    parent: np.ndarray     #: (k,) int64 for each part after the faces, the face it was split from
    n_slits: int           #: slits zipped
    n_left: int            #: slits found but left open (see :func:`zip_slits`)


def zip_slits(V, F, twin, distance):
    r"""Zip the T-junctions of the oriented vertex-manifold mesh ``(V, F)``
    (twin table ``twin``): border loops of zero width, a chain of edges
    ``a -> m_1 -> ... -> b`` along one edge ``b -> a`` of a face ``(b, a, x)``,
    every vertex within ``distance`` (mesh units) of that edge and the chain
    no longer than it by more than ``2 distance`` per vertex. A scan or a CAD
    export split a face at a point of its edge and left the neighbour whole:
    the surface is closed there, but the mesh has a hole that a cage keeping
    its topology must keep (three vertices of its own), and no cap is needed
    to close it. The face ``(b, a, x)`` becomes the fan ``(m_1, a, x), ...,
    (b, m_k, x)`` (the first in its place, the others after the faces), so
    no vertex moves and no area changes (the tests run unit-free: no overflow
    at 1e200). A slit is left open when its face
    already has one zipped, when ``x`` is on the chain of a slit, or when an edge
    ``x - m_i`` is already there (it would get three faces). Returns
    :class:`Slits`, or None when there is none.

    ::

        a ----- m ----- b          a ----- m ----- b     the faces above the
         \             /            \      |      /      chain a -> m -> b as
          \           /      ->      \     |     /       they were; (b, a, x)
           \         /                \    |    /        below becomes (m, a, x)
                x                          x             and (b, m, x)
    """
    border = np.flatnonzero(twin == BOUNDARY)
    if border.shape[0] < 3:
        return None                                # closed: nothing to scale
    V, size = _scaled_rim(V, np.concatenate(half_edge_ends(F, border)))
    loops = _border_loops(V, F, twin)
    if loops is None:
        return None
    found, longest = _slit_loops(V, loops, distance / size)
    if found.size == 0:
        return None
    heads, x = _zippable(F, V.shape[0], loops, found, longest)
    if heads.size == 0:
        return None
    rim, count = _rims(loops, heads)
    # rim[:, 0] is the long edge b -> a (heads start there), the chain follows it
    chain = rim[:, 1:]
    live = chain >= 0
    row = np.nonzero(live)[0]
    p = chain[live]
    w = loops.u[loops.succ[p]]
    parts = np.stack([w, loops.u[p], x[row]], axis=1)          # (q, p, x) for chain edge p -> q
    first = np.r_[True, row[1:] != row[:-1]]
    face = loops.h[heads] // 3
    F2 = F.copy()
    F2[face] = parts[first]
    F2 = np.concatenate([F2, parts[~first]])
    return Slits(F2, twin_table(F2, V.shape[0]), face[row[~first]], int(heads.size),
                 int(found.size - heads.size))


def _scaled_rim(V, rim):
    """``V`` with the rows ``rim`` (the border vertices, repeats allowed)
    moved and scaled to the unit diagonal of their box, the other rows 0, and
    that diagonal: the slit tests run unit-free (no overflow at 1e200) and
    read the rim alone. The zeros are pages never written (a 4.4M-face
    scan's whole mesh scaled took 50 ms a round, for five small holes)."""
    P = V[rim]
    lo, hi = P.min(axis=0), P.max(axis=0)
    size = diagonal_length(lo, hi) or 1.0
    out = np.zeros(V.shape)
    out[rim] = (P - lo) / size
    return out, size


def _slit_loops(V, loops, distance):
    """The loops of zero width (see :func:`zip_slits`), as their longest
    border half-edge's position, and that position for every border half-edge's loop."""
    u, w = loops.u, loops.u[loops.succ]
    length = lengths(V[w] - V[u])
    order = np.lexsort((length, loops.label))
    lab = loops.label[order]
    last = np.r_[lab[1:] != lab[:-1], True]
    longest = np.zeros(loops.h.shape[0], dtype=np.int64)
    longest[lab[last]] = order[last]
    L = longest[loops.label]
    A, B, P = V[w[L]], V[u[L]], V[u]
    AB = B - A
    t = np.clip(np.einsum("ij,ij->i", P - A, AB) / np.maximum(np.einsum("ij,ij->i", AB, AB), 1e-300),
                0.0, 1.0)
    far = np.linalg.norm(A + t[:, None] * AB - P, axis=1) > distance
    wide = np.bincount(loops.label, weights=far, minlength=far.shape[0]) > 0
    long_chain = loops.perimeter > 2.0 * length[longest] + 2.0 * distance * loops.count
    pos = np.flatnonzero(loops.heads() & (loops.count >= 3) & (loops.count <= MAX_PINHOLE_EDGES)
                         & ~wide & ~long_chain)
    return longest[pos], L


def _zippable(F, n, loops, heads, longest):
    """Of the slits whose long edges are ``heads`` (positions), those that
    can be zipped (see :func:`zip_slits`), and the third vertex ``x`` of the
    face of each long edge."""
    h = loops.h[heads]
    face, x = h // 3, F[h // 3, h % 3]
    _, one = np.unique(face, return_index=True)
    keep = np.zeros(heads.shape[0], dtype=bool)
    keep[one] = True
    # the chain vertices m: each loop's but its long edge's ends
    slot = np.full(loops.h.shape[0], -1, dtype=np.int64)
    slot[heads] = np.arange(heads.shape[0])
    mine = slot[longest[loops.label]]
    inner = (mine >= 0) & (longest[loops.label] != np.arange(loops.h.shape[0])) \
        & (loops.succ[longest[loops.label]] != np.arange(loops.h.shape[0]))
    m, k = loops.u[inner], mine[inner]
    # x on a chain: its own (a degenerate face) or another's (two new edges could meet)
    on_chain = np.zeros(n, dtype=bool)
    on_chain[m] = True
    keep &= ~on_chain[x]
    # an edge x - m already there
    clash = member_of(edge_keys(x[k], m, n), _edges_among(F, n, np.concatenate([x, m])))
    keep &= np.bincount(k[clash], minlength=heads.shape[0]) == 0
    return heads[keep], x[keep]


def _border_loops(V, F, twin):
    """The :class:`_Loops` of the mesh (None without border half-edges). In a vertex-manifold mesh each rim vertex starts
    exactly one border half-edge, so the successor of ``u -> w`` is the one
    starting at ``w``."""
    h = np.flatnonzero(twin == BOUNDARY)
    if h.shape[0] < 3:
        return None
    u, w = half_edge_ends(F, h)
    start = np.full(V.shape[0], -1, dtype=np.int64)
    start[u] = np.arange(h.shape[0])
    succ = start[w]
    if (succ < 0).any():                      # not vertex-manifold: no loops to trust
        return None
    pos = np.arange(h.shape[0], dtype=np.int64)
    label = connected_labels(h.shape[0], np.stack([pos, succ], axis=1))
    length = lengths(V[w] - V[u])
    count = np.bincount(label, minlength=h.shape[0])
    perimeter = np.bincount(label, weights=length, minlength=h.shape[0])
    return _Loops(h, u, succ, label, count, perimeter)


def _surfaces(m, twin):
    """The surface of each of the ``m`` faces: its component across the
    interior edges of ``twin`` (the label of its smallest face)."""
    ih, it = interior_edges(twin)
    return connected_labels(m, np.stack([ih // 3, it // 3], axis=1))


def _on_large_surface(F, twin, face_area, loops, heads):
    """Mask of the loops ``heads`` whose component's area is at least
    ``PINHOLE_SURFACE`` times that of a disk of the loop's perimeter."""
    faces = _surfaces(F.shape[0], twin)
    area = np.bincount(faces, weights=face_area, minlength=F.shape[0])
    p = loops.perimeter[heads]
    return area[faces[loops.h[heads] // 3]] >= PINHOLE_SURFACE * p * p / (4.0 * np.pi)


def _rims(loops, heads):
    """Rim positions (in ``loops.h``) of the loops of ``heads`` in loop order
    from the head (any position of its loop), (k, longest) (-1 past each loop's end), and their counts;
    one step of all loops at a time (at most ``MAX_PINHOLE_EDGES`` steps)."""
    count = loops.count[loops.label[heads]]
    rim = np.full((heads.shape[0], int(count.max())), -1, dtype=np.int64)
    pos = heads.copy()
    for step in range(rim.shape[1]):
        live = step < count
        rim[live, step] = pos[live]
        pos = loops.succ[pos]
    return rim, count


def _fans(V, F, rim, count, loops):
    """The caps of the loops ``rim`` (positions, from :func:`_rims`): a fan
    from one rim vertex, triangles ``(r_a, r_{a+i+1}, r_{a+i})`` (the rim
    edges' twins), the apex moved on where a diagonal is already an edge or
    a triangle would have no area (a rim through two copies of a bow-tie
    vertex, at one point: a cage kept two such faces). Returns the caps
    (c, 3) and, per cap, (the face beside its rim edge, its loop's row)."""
    n = V.shape[0]
    k = count[:, None]
    cols = np.arange(rim.shape[1])
    R = np.where(rim >= 0, loops.u[np.maximum(rim, 0)], -1)
    existing = _edges_among(F, n, R[rim >= 0])
    caps, beside = [], []
    todo = np.arange(rim.shape[0])
    for apex in range(_APEX_TRIES):
        if todo.size == 0:
            break
        kk = k[todo]
        at = (apex + cols[None, :]) % kk                        # the rim from this apex
        r = np.take_along_axis(R[todo], at, axis=1)
        p = np.take_along_axis(rim[todo], at, axis=1)
        diag = (cols[None, 2:] <= kk - 2)                       # diagonals r_0 - r_j, 2 <= j <= k-2
        keys = edge_keys(r[:, :1], r[:, 2:], n)
        clash = (diag & member_of(keys, existing)).any(axis=1)
        row, col = np.nonzero(cols[None, 1:-1] <= kk - 2)       # triangles 1 <= i <= k-2
        tri = np.stack([r[row, 0], r[row, col + 2], r[row, col + 1]], axis=1)
        clash[row[flat_faces(V, tri)]] = True
        fine = ~clash[row]
        caps.append(tri[fine])
        beside.append(np.stack([loops.h[p[row, col + 1]] // 3, todo[row]], axis=1)[fine])
        todo = todo[clash]
    if not caps:
        return np.zeros((0, 3), dtype=np.int64), np.zeros((0, 2), dtype=np.int64)
    return np.concatenate(caps), np.concatenate(beside)


def _edges_among(F, n, vertices):
    """Sorted keys (:func:`~.topology.edge_keys`) of the mesh edges with both
    ends among ``vertices``."""
    mark = np.zeros(n, dtype=bool)
    mark[vertices] = True
    near = np.flatnonzero(np.count_nonzero(mark[F], axis=1) >= 2)     # (the faces with such an edge)
    a, b = half_edge_ends(F[near])
    both = mark[a] & mark[b]
    return sorted_unique(edge_keys(a[both], b[both], n))
