"""Coincident copies: components that lie on another component, vertex for vertex.

A mesh exported with an object duplicated in place, or a scan with a patch
stacked twice, has components whose vertices all coincide (exactly, or
within the weld distance) with vertices of another component. The weld
leaves them apart (vertices inside a closed surface are not welded: two of
them at one place are two sheets touching), so each became a cage of its own
lying on the other: the cow twice gave a 300-face cage of two coincident
150-face shells. :func:`~.clean.clean_mesh` drops such a copy and reports it.

An open surface twice in place is one component: the weld joins the two
layers along their open borders (open-edge vertices that coincide are
welded) into a closed, flat *pillow*. :func:`pillow_layers` finds closed
components with next to no volume whose every face coincides with another
(corner for corner) and drops the second layer. (A mesh squashed flat has
faces that coincide here and there: not a pillow; dropping them left the
cow squashed to 1e-6 of its size with 163 non-manifold vertices.)

Before the weld, :func:`stacked_copies` drops the pieces of the input (faces
joined by shared vertex indices) that lie on other pieces face for face: a copy
with holes of its own (a scan exported twice, each with its dropouts) would
otherwise be welded to its original at every hole's rim, and where two rims
are one edge apart that edge ends up with four faces (the cow with 2% of its
faces missing, twice in place: 51 non-manifold edges cut, 86 bow-ties split
and both layers kept; the bunny's cage then stopped at 20,711 faces of 300).
A piece lying on another but for a few faces (each copy with dropouts of its
own, a fin on one) loses the faces it duplicates and keeps the others, which
the weld joins to the original: its holes are filled where the copy has the
faces (the bunny twice in place, 10% of the faces missing at random and 8
fins: 8,986 non-manifold edges cut and a cage of 19,547 faces of 1,000).

A component A is a *copy* of a component B when every vertex of A coincides
with a vertex of B (shares a cell of :func:`~._clean.coincident_pairs` with
one, directly or through other coincident vertices); of two components that
are copies of each other, the one of smaller area goes (of equal areas, to
``_SAME_AREA``, the later one). Components touching at some vertices (bow-ties split into two
pieces, a lid on a rim) keep vertices of their own and stay.
"""

import numpy as np

from ._clean import BOUNDARY, NON_MANIFOLD, coincident_pairs, half_edge_ends
from ._groups import ragged_ranges, sorted_unique
from .mesh import face_areas, row_sums
from .topology import connected_labels, face_components, numbered, vertex_labels

__all__ = ["coincident_copies", "doubled_quads", "pillow_layers", "stacked_copies"]

#: two components whose areas differ by less than this share have the same area (a copy
#: moved by a weld distance rounds its area differently): the later one goes
_SAME_AREA = 1e-6

#: a closed component whose volume is below this share of (its area)^(3/2) is flat: a
#: pillow (a sphere's share is 0.094, a cube's 0.068; two layers 1e-7 apart, about 1e-7)
FLAT_VOLUME = 1e-4

#: a component's bounding box lies mostly inside another's when they overlap over at
#: least this share of its extent on every axis (a copy's box with a fin sticking out
#: of it, 15% of the size, was not inside its original's, and the copy stayed)
BOX_COVER = 0.5

#: components tried as the original of a copy: the largest this many (by area)
_CONTAINERS = 64


def coincident_copies(V, F, labels, area, distance, protected=None):
    """(m,) bool mask of the faces of coincident copies (see the module
    docstring), or None when there is none. ``V`` (n,3) positions in units of
    the bounding-box diagonal, ``F`` (m,3) a vertex-manifold mesh whose faces
    are in the components ``labels`` (m,) (any integers), ``area`` (m,) the
    faces' areas, ``distance`` the weld distance; components with a
    ``protected`` (n,) vertex never go."""
    lab, k = numbered(labels)
    if k < 2:
        return None
    vc = vertex_labels(F, lab, V.shape[0])
    comp_area = np.bincount(lab, weights=area, minlength=k)
    points = _candidates(V, vc, comp_area, distance)
    if points.shape[0] < 2:
        return None
    pairs = coincident_pairs(V[points], distance)          # (rows of points)
    if not (vc[points[pairs[:, 0]]] != vc[points[pairs[:, 1]]]).any():
        return None
    shared = _shared_counts(pairs, vc[points], k)
    nverts = np.bincount(vc[vc >= 0], minlength=k)
    a, b, count = shared
    copy = count == nverts[a]
    same = np.abs(comp_area[a] - comp_area[b]) <= _SAME_AREA * comp_area[b]
    copy &= (comp_area[a] < comp_area[b]) & ~same | same & (a > b)
    gone = np.zeros(k, dtype=bool)
    gone[a[copy]] = True
    if protected is not None:
        gone[sorted_unique(vc[np.flatnonzero(protected & (vc >= 0))])] = False
    return gone[lab] if gone.any() else None


def stacked_copies(V, F, area, distance, protected=None):
    """(m,) bool mask of the faces of the input's pieces that lie on
    others face for face (see the module docstring), or None when there is
    none. A *piece* is a set of faces joined by shared vertex indices; a
    face lies on another when their corners coincide in turn (within the
    weld ``distance``; ``V`` in units of the bounding-box diagonal, ``area``
    (m,) the faces' areas). Of the pieces holding one place, the one of
    largest area stays (of equal ones the first); a piece goes when every
    face of it lies on a face of a piece that stays, and otherwise its faces
    that lie on one wound the same way go (duplicates: a copy with a few
    faces of its own, a fin or the faces over its original's holes, keeps
    just those, which the weld then joins to the original; faces wound the
    other way, where two closed parts touch, stay). Pieces with a
    ``protected`` (n,) vertex lose nothing. Inputs in more pieces than half
    their faces (soups) are left to the weld."""
    n, m = V.shape[0], F.shape[0]
    if m < 2:
        return None
    lab, k = face_components(F, n)
    if k < 2 or k > m // 2:
        return None
    vc = vertex_labels(F, lab, n)
    comp_area = np.bincount(lab, weights=area, minlength=k)
    points = _candidates(V, vc, comp_area, distance)
    if points.shape[0] < 6:
        return None
    pairs = coincident_pairs(V[points], distance)
    if pairs.shape[0] == 0:
        return None
    group = np.full(n, -1, dtype=np.int64)
    group[points] = points[connected_labels(points.shape[0], pairs)]
    faces = np.flatnonzero((group[F] >= 0).all(axis=1))
    corners = group[F[faces]]
    key = np.sort(corners, axis=1)
    fl = lab[faces]
    # larger first; areas within _SAME_AREA of each other (a copy moved by the weld distance
    # rounds its area differently) are equal, and the first piece of them stays
    size = np.floor(np.log(np.maximum(comp_area, np.finfo(float).tiny)) / _SAME_AREA)
    order = np.lexsort((fl, -size[fl], key[:, 2], key[:, 1], key[:, 0]))
    ks, fl, turn = key[order], fl[order], _winding(corners[order])
    first = np.concatenate([[True], (ks[1:] != ks[:-1]).any(axis=1)])
    place = np.cumsum(first) - 1
    keeper = fl[first][place]                      # the largest piece holding each place
    covered = np.bincount(fl, weights=fl != keeper, minlength=k)
    gone = covered == np.bincount(lab, minlength=k)
    drop = np.zeros(m, dtype=bool)
    drop[faces[order[(fl != keeper) & (turn == turn[first][place])]]] = True
    drop |= gone[lab]
    if protected is not None:
        drop &= ~_has_protected(vc, lab, protected, k)
    return drop if drop.any() else None


def doubled_quads(F, twin):
    r"""(m,) bool mask of the faces to drop from quads triangulated both ways,
    or None when there is none; ``twin`` is ``twin_table(F, n)``.

    A quad ``p a q b`` exported with both diagonals has the faces ``(a, b,
    p), (b, a, q)`` and ``(p, q, a), (q, p, b)``: a closed tetrahedron glued
    into the surface, each of its four rim edges shared by three or more
    faces. Pairing them edge by edge could take one triangulation on some rim
    edges and the other on the rest; the chain of disagreeing pairs was cut,
    both triangulations came loose, each dropped as a copy of the other, and
    the quad was a hole (a torus with 20 such quads: 5 holes). Here, of the
    two pairs of faces across an interior edge whose four other edges are all
    non-manifold and that stand on the same four vertices, the pair without
    the lower face index goes (the first one written stays, as of duplicates)::

        p ------- a        p ------- a
        |  \      |        |      /  |
        |    \    |   +    |    /    |
        |      \  |        |  /      |
        b ------- q        b ------- q

    (A tetrahedron on its own has no non-manifold edge; a quad with one of
    its rim edges on a border of the mesh has that edge in two faces only,
    and is left to the pairing.)
    """
    rims = row_sums(twin.reshape(-1, 3) == NON_MANIFOLD) == 2
    if not rims.any():
        return None
    # interior edges (h < twin[h]) between two faces whose other two edges are non-manifold
    h = np.flatnonzero((twin > np.arange(twin.size)) & np.repeat(rims, 3))
    t = twin[h]
    Fr = F.ravel()
    keep = rims[t // 3] & (Fr[h] != Fr[t])          # (and two corners across: not a duplicate)
    h, t = h[keep], t[keep]
    if h.size < 2:
        return None
    U, W = half_edge_ends(F, h)
    quads = np.sort(np.stack([U, W, Fr[h], Fr[t]], axis=1), axis=1)
    _, group, count = np.unique(quads, axis=0, return_inverse=True, return_counts=True)
    group = group.ravel()
    two = np.flatnonzero(count[group] == 2)
    if two.size == 0:
        return None
    low = np.minimum(h[two], t[two]) // 3
    order = two[np.lexsort((low, group[two]))]      # each quad's two diagonals, lower face first
    second = order[1::2]
    drop = np.zeros(F.shape[0], dtype=bool)
    drop[h[second] // 3] = True
    drop[t[second] // 3] = True
    return drop


def _winding(corners):
    """Of faces given by their corners' ids (k,3): 0 or 1, the parity of the
    permutation sorting them, so that two faces on the same three ids have
    the same winding exactly when their parities are equal."""
    a, b, c = corners.T
    return ((a > b).astype(np.int8) + (a > c) + (b > c)) & 1


def _has_protected(vc, lab, protected, k):
    """(m,) bool: the faces of the pieces (``lab``, ``k`` of them) holding a
    ``protected`` vertex (``vc``: each vertex's piece, -1 when unused)."""
    held = np.zeros(k, dtype=bool)
    held[vc[np.flatnonzero(protected & (vc >= 0))]] = True
    return held[lab]


def _candidates(V, vc, comp_area, distance):
    """The vertices that can be in a copy or under one: those of the
    components whose bounding box lies mostly inside another's of at least
    their area (:data:`BOX_COVER` on each axis, grown by the grid's reach: a
    copy's does, also with a fin of its own sticking out), and those of such
    containers inside the contained ones' boxes. Two overlapping scans of a
    million vertices each, a thousandth of the size apart, are then no
    pairing work at all."""
    used = np.flatnonzero(vc >= 0)
    k = comp_area.shape[0]
    lo = np.full((k, 3), np.inf)
    hi = np.full((k, 3), -np.inf)
    for axis in range(3):
        np.minimum.at(lo[:, axis], vc[used], V[used, axis])
        np.maximum.at(hi[:, axis], vc[used], V[used, axis])
    reach = 8.0 * distance
    # containers: the _CONTAINERS largest components (a copy is never larger than its original)
    big = np.argsort(-comp_area, kind="stable")[:_CONTAINERS]
    overlap = np.minimum(hi[:, None, :], hi[big][None, :, :]) - np.maximum(lo[:, None, :], lo[big][None, :, :])
    inside = (overlap >= BOX_COVER * (hi - lo)[:, None, :] - reach).all(axis=2)
    inside &= comp_area[:, None] <= comp_area[big][None, :] * (1 + _SAME_AREA)
    inside[big, np.arange(big.shape[0])] = False                    # not in itself
    contained = inside.any(axis=1)
    if not contained.any():
        return used[:0]
    holders = np.zeros(k, dtype=bool)
    holders[big[inside.any(axis=0)]] = True
    box_lo, box_hi = lo[contained].min(axis=0) - reach, hi[contained].max(axis=0) + reach
    near = ((V[used] >= box_lo) & (V[used] <= box_hi)).all(axis=1)
    return used[contained[vc[used]] | (holders[vc[used]] & near)]


def _shared_counts(pairs, vc, k):
    """Per ordered pair of components (A, B) sharing coincident vertices: how
    many vertices of A coincide with some vertex of B, as arrays (a, b, count).
    Coincident vertices (``pairs`` of rows of ``vc``, the points' components)
    are grouped; each group counts its vertices of A towards every other
    component it holds."""
    group = connected_labels(vc.shape[0], pairs)
    key, cnt = np.unique(group * np.int64(k) + vc, return_counts=True)
    g, c = np.divmod(key, k)
    # each (group, component) entry against every other entry of its group
    start = np.flatnonzero(np.concatenate([[True], g[1:] != g[:-1]]))
    size = np.diff(np.concatenate([start, [g.shape[0]]]))
    other, mine = ragged_ranges(np.repeat(start, size), np.repeat(size, size))
    keep = other != mine
    mine, other = mine[keep], other[keep]
    pair_key, inverse = np.unique(c[mine] * np.int64(k) + c[other], return_inverse=True)
    total = np.bincount(inverse, weights=cnt[mine]).astype(np.int64)
    a, b = np.divmod(pair_key, k)
    return a, b, total


def pillow_layers(V, F, labels, twin, distance, turned=None):
    """(m,) bool mask of the faces of the second layers of flat pillows (see
    the module docstring), or None. ``V`` in units of the bounding-box
    diagonal, ``labels`` the faces' components, ``twin`` their twin table,
    ``distance`` the weld distance, ``turned`` (m,) bool the faces the
    cleaning's orientation turned over (None: none). Of faces whose corners
    coincide in turn, the first one not turned stays: the layer that stays
    faces the way the input did (the orientation of a pillow, two equal
    layers, is a coin toss: the bunny twice came back inside out)."""
    m = F.shape[0]
    lab, k = numbered(labels)
    closed = np.ones(k, dtype=bool)
    closed[lab[np.flatnonzero(twin == BOUNDARY) // 3]] = False
    if not closed.any():
        return None
    a, b, c = (V[F[:, i]] for i in range(3))
    area = face_areas(V, F)
    volume = np.einsum("ij,ij->i", a, np.cross(b, c)) / 6.0
    comp_area = np.bincount(lab, weights=area, minlength=k)
    flat = closed & (np.abs(np.bincount(lab, weights=volume, minlength=k))
                     <= FLAT_VOLUME * comp_area ** 1.5) & (comp_area > 0)
    faces = np.flatnonzero(flat[lab])
    if faces.size == 0:
        return None
    points = sorted_unique(F[faces])
    pairs = coincident_pairs(V[points], distance)
    if pairs.shape[0] == 0:
        return None
    group = np.arange(V.shape[0])
    group[points] = points[connected_labels(points.shape[0], pairs)]
    key = np.sort(group[F[faces]], axis=1)
    first = np.zeros(faces.shape[0], dtype=bool) if turned is None else turned[faces]
    order = np.lexsort((first, *key.T[::-1]))
    ks = key[order]
    same = (ks[1:] == ks[:-1]).all(axis=1)
    again = np.concatenate([[False], same])
    # a pillow is two whole layers: every face of the component has its coincident twin
    # (a mesh squashed flat has faces that coincide here and there: not a pillow)
    paired = again | np.concatenate([same, [False]])
    whole = np.bincount(lab[faces[order]], weights=paired, minlength=k) \
        == np.bincount(lab[faces], minlength=k)
    again &= whole[lab[faces[order]]]
    if not again.any():
        return None
    drop = np.zeros(m, dtype=bool)
    drop[faces[order[again]]] = True        # (stable: among equal ones, the first face stays)
    return drop
