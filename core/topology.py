"""Edge maps, manifoldness, boundary loops, components and Euler characteristic.

Conventions (every other module relies on them)
-----------------------------------------------
* Face-edge ``c`` of face ``f`` is the edge *opposite* corner ``c``:
  ``(F[f, (c+1)%3], F[f, (c+2)%3])``.
* Unique edges ``E`` (e,2) are sorted rows ``E[k] = (lo, hi)``, ``lo < hi``, in
  lexicographic order of ``(lo, hi)`` (the order of the key ``lo*n + hi``).
  ``face_edge[f, c]`` is the index into ``E`` of face-edge ``c`` of face ``f``.
* Edge ``k`` is a boundary edge when ``edge_face_count[k] == 1``, interior
  when it is 2 and non-manifold when it is more than 2.
"""

from typing import NamedTuple

import numpy as np

from ._groups import sorted_unique
from .errors import InvalidArgumentError, InvalidMeshError
from .mesh import check_count, check_faces, shown

#: most vertices a mesh's topology is built for (its per-vertex arrays: 2^32)
MAX_VERTICES = 2 ** 32


class EdgeMap(NamedTuple):
    """Unique edges of a triangle mesh and how faces use them."""

    E: np.ndarray                #: (e,2) int64, sorted rows, lexicographic order
    face_edge: np.ndarray        #: (m,3) int64, edge opposite corner c of face f
    edge_face_count: np.ndarray  #: (e,) int64, number of faces using each edge


def edge_keys(a, b, n_vertices):
    """One int64 key per undirected edge ``(a[i], b[i])`` of a mesh with
    ``n_vertices`` vertices: ``min * n + max`` (the same for both
    directions; sorting the keys sorts the edges by (lower, higher) end)."""
    return np.minimum(a, b) * np.int64(max(n_vertices, 1)) + np.maximum(a, b)


def edge_map(F, n_vertices):
    """Unique edges of ``F`` and the face-to-edge map.

    Parameters
    ----------
    F : (m,3) int array_like, each index in ``[0, n_vertices)``
    n_vertices : int >= 0

    Returns
    -------
    EdgeMap

    Raises
    ------
    InvalidMeshError
        ``F`` not (m,3) integers, or an index outside ``[0, n_vertices)``.
    InvalidArgumentError
        ``n_vertices`` not an integer >= 0.

    Examples
    --------
    >>> em = edge_map(np.array([[0, 1, 2]]), 3)
    >>> em.E.tolist(), em.face_edge.tolist()
    ([[0, 1], [0, 2], [1, 2]], [[2, 1, 0]])
    """
    F, n = _checked("edge_map", F, n_vertices)
    return _edge_map(F, n)


def _checked(where, F, n_vertices):
    """``F`` (int64, not copied when it already is) and ``n_vertices`` checked
    for the public function ``where`` (:func:`~.mesh.check_faces`)."""
    n = check_count(n_vertices, where=where, name="n_vertices")
    if n > MAX_VERTICES:   # (10**12 asked for 7 TiB; 10**30 overflowed the edge keys)
        raise InvalidArgumentError(
            f"{where}: n_vertices must be at most {MAX_VERTICES:,} (2^32), got {shown(n_vertices)}")
    return check_faces(F, n, where=where, copy=False), n


def _edge_map(F, n_vertices):
    """:func:`edge_map` of a checked ``F`` (m,3) int64."""
    m = F.shape[0]
    half = F[:, [1, 2, 2, 0, 0, 1]].reshape(-1, 2)
    key = edge_keys(half[:, 0], half[:, 1], n_vertices)
    uniq, inverse, counts = np.unique(key, return_inverse=True, return_counts=True)
    n = np.int64(max(n_vertices, 1))
    E = np.stack([uniq // n, uniq % n], axis=1)
    return EdgeMap(E, inverse.reshape(m, 3).astype(np.int64), counts.astype(np.int64))


def edge_faces(em):
    """For each edge, up to two incident faces and the local corner opposite it.

    Returns
    -------
    faces : (e,2) int64, ``-1`` where missing (boundary edges have one face).
        For non-manifold edges only the first two faces are listed.
    corners : (e,2) int64, the corner of that face opposite the edge, ``-1``
        where missing.
    """
    m = em.face_edge.shape[0]
    e = em.E.shape[0]
    flat = em.face_edge.ravel()
    order = np.argsort(flat, kind="stable")
    sorted_edges = flat[order]
    first = np.searchsorted(sorted_edges, np.arange(e))
    faces = np.full((e, 2), -1, dtype=np.int64)
    corners = np.full((e, 2), -1, dtype=np.int64)
    if m == 0:
        return faces, corners
    faces[:, 0] = order[first] // 3
    corners[:, 0] = order[first] % 3
    has2 = em.edge_face_count >= 2
    second = order[first[has2] + 1]
    faces[has2, 1] = second // 3
    corners[has2, 1] = second % 3
    return faces, corners


def connected_labels(n_nodes, pairs):
    """Connected-component labels of an undirected graph, vectorised.

    Hooking with pointer jumping, on a graph that contracts as it goes: each
    round hooks the larger root of every pair that still joins two trees
    under the smaller one, jumps the hooked roots to their new roots and
    drops the pairs now inside one tree; the loop runs over rounds, never
    over nodes. A root paired with several smaller ones is hooked below the
    smallest of them, so a star takes two rounds whatever its centre. A
    node only ever points at a smaller one of its component,
    so the component's smallest node is its root, whichever of several
    hooks on one root lands.

    Parameters
    ----------
    n_nodes : int
    pairs : (k,2) int64 ndarray, the graph's edges.

    Returns
    -------
    labels : (n_nodes,) int64, each node's component's smallest node index.
    """
    pairs = np.asarray(pairs).reshape(-1, 2)
    dtype = np.int32 if n_nodes < 2 ** 31 else np.int64    # half the memory traffic
    parent = np.arange(n_nodes, dtype=dtype)
    ra, rb = pairs[:, 0].astype(dtype), pairs[:, 1].astype(dtype)
    hooked, rounds = None, []    # the nodes each round hooked (pointing at its roots)
    while True:
        keep = ra != rb
        k = int(np.count_nonzero(keep))
        if k == 0:
            break
        if k < ra.size:
            ra, rb = ra[keep], rb[keep]
        lo = np.minimum(ra, rb)
        hi = np.maximum(ra, rb)
        parent[hi] = lo                  # roots hooked below smaller roots, each below the
        lost = parent[hi] > lo           # smallest of its pairs (the last write alone hooked
        if lost.any():                   # one leaf a round of a star centred on its largest
            np.minimum.at(parent, hi[lost], lo[lost])    # node: 40k copies of a triangle, 4.8 s)
        if hooked is None:               # (the first round hooks most nodes)
            _jump_all(parent)
            rounds.append(np.flatnonzero(parent != np.arange(n_nodes, dtype=dtype)))
            hooked = np.zeros(n_nodes, dtype=bool)
        else:                            # the hooked roots, once each, in order
            hooked[hi] = True
            nodes = np.flatnonzero(hooked)
            hooked[nodes] = False
            _jump(parent, nodes.astype(dtype))
            rounds.append(nodes)
        ra, rb = parent[ra], parent[rb]  # roots again
    # a round's nodes point at roots of that round, whose later rounds (done first) are final
    for nodes in reversed(rounds):
        parent[nodes] = parent[parent[nodes]]
    return parent.astype(np.int64)


def _jump(parent, nodes):
    """Pointer jumping on ``nodes`` (in place) until each points at a root
    (pointers double when every node on their paths is among them)."""
    while nodes.size:
        p = parent[nodes]
        gp = parent[p]
        moving = gp != p
        nodes = nodes[moving]
        parent[nodes] = gp[moving]


def _jump_all(parent):
    """Pointer jumping on every node (in place) until each points at a root."""
    gp = parent[parent]
    nodes = np.flatnonzero(gp != parent).astype(parent.dtype)
    parent[nodes] = gp[nodes]
    _jump(parent, nodes)


def face_components(F, n_vertices):
    """Label of each face's connected component (faces joined through
    shared vertices), numbered in the order of their smallest vertex, and
    the number of components. The graph is over the used vertices only (a
    scan's unreferenced vertices cost nothing), joined along two edges of
    every face."""
    F = np.asarray(F, dtype=np.int64)
    if F.shape[0] == 0:
        return np.zeros(0, dtype=np.int64), 0
    used = np.zeros(n_vertices, dtype=bool)
    used[F.ravel()] = True
    at = np.cumsum(used) - 1
    Fu = at[F]
    roots = connected_labels(int(at[-1]) + 1, np.concatenate([Fu[:, :2], Fu[:, 1:]]))
    return numbered(roots[Fu[:, 0]])


#: a cage with more separate pieces than this share of its faces, and at least
#: ``SOUP_MIN_PIECES`` of them, is a triangle soup (:func:`is_soup`)
SOUP_PIECES_SHARE = 0.5
SOUP_MIN_PIECES = 32


def is_soup(pieces, faces):
    """Whether a mesh of ``faces`` faces in ``pieces`` separate pieces is a
    triangle soup (more pieces than ``SOUP_PIECES_SHARE`` of its faces, at
    least ``SOUP_MIN_PIECES``)."""
    return pieces >= SOUP_MIN_PIECES and pieces > SOUP_PIECES_SHARE * faces


def soup_pieces(F_cage, n_cage, F_source, n_source, cage_pieces=None):
    """The separate pieces of the source mesh ``F_source`` when it and the
    cage ``F_cage`` standing for it are triangle soups (:func:`is_soup`),
    else None (``cage_pieces``: the cage's count, when known). The source is
    counted only when the cage is one (its pieces cost 0.12 s at 1M faces):
    a cage in pieces at their floor can come from a source that is not (the
    beetle beside a copy of itself 1e-4 of its size off: 36 pieces for 44
    faces, from 36 pieces of 2,291 faces, which no weld joins)."""
    if cage_pieces is None:
        cage_pieces = face_components(F_cage, n_cage)[1]
    if not is_soup(cage_pieces, np.asarray(F_cage).shape[0]):
        return None
    pieces = face_components(F_source, n_source)[1]
    return pieces if is_soup(pieces, np.asarray(F_source).shape[0]) else None


def check_not_soup(F_cage, n_cage, F_dense, n_dense, where):
    """Raise :class:`~.errors.InvalidMeshError` when the cage ``F_cage`` and
    the dense mesh ``F_dense`` it stands for are triangle soups
    (:func:`soup_pieces`), as ``simplify`` returns for a source whose faces
    no weld joins (its topology floor: every face its own piece). Nothing
    can be fitted to or bound through such a cage, and the closest-point
    searches over its heavily overlapping subdivision grow with the square
    of its size (spot as a soup jittered by 30% of its size: 162 s to fit a
    5,856-face "cage")."""
    _, pieces = face_components(F_cage, n_cage)
    if soup_pieces(F_cage, n_cage, F_dense, n_dense, pieces) is None:
        return
    m = np.asarray(F_cage).shape[0]
    raise InvalidMeshError(
        f"{where}: the cage is {pieces:,} separate pieces for its {m:,} faces, a triangle "
        f"soup: its source's faces are not joined by their edges (not welded, or meeting "
        f"only at bow-tie vertices), and a soup has no surface to subdivide; weld the "
        f"source first (Merge by Distance in Blender, or simplify with a larger "
        f"weld_distance) and make the cage again")


def numbered(labels):
    """The labels ``labels`` (any integers >= 0) as 0 .. k-1 in their order,
    and k: from a mask of the labels present, not a sort of them."""
    labels = np.asarray(labels, dtype=np.int64)
    if labels.size == 0:
        return labels, 0
    present = np.zeros(int(labels.max()) + 1, dtype=bool)
    present[labels] = True
    return (np.cumsum(present) - 1)[labels], int(np.count_nonzero(present))


def vertex_labels(F, face_labels, n_vertices):
    """The label of each vertex from the faces' ``face_labels`` (m,) (one
    label per connected piece: any face of it will do), -1 for vertices no
    face uses; (n_vertices,) int64."""
    out = np.full(n_vertices, -1, dtype=np.int64)
    out[np.asarray(F).ravel()] = np.repeat(face_labels, 3)
    return out


def boundary_loops_count(F, n_vertices, em=None):
    """Number of boundary loops (connected chains of boundary edges)."""
    em = _edge_map(np.asarray(F, dtype=np.int64), n_vertices) if em is None else em
    B = em.E[em.edge_face_count == 1]
    if B.shape[0] == 0:
        return 0
    used = sorted_unique(B)
    relabel = np.searchsorted(used, B)
    labels = connected_labels(used.shape[0], relabel)
    return int(sorted_unique(labels).shape[0])


def border_vertex_count(F, n_vertices, em=None):
    """Number of vertices on boundary edges (edges of one face)."""
    em = _edge_map(np.asarray(F, dtype=np.int64), n_vertices) if em is None else em
    return int(sorted_unique(em.E[em.edge_face_count == 1]).shape[0])


class ManifoldReport(NamedTuple):
    """What is wrong with a triangle mesh's topology, as index arrays."""

    non_manifold_edges: np.ndarray     #: (k,2) edges used by more than two faces
    non_manifold_vertices: np.ndarray  #: (j,) vertices whose faces form more than one fan
    inconsistent_edges: np.ndarray     #: (i,2) interior edges whose two faces disagree on orientation
    degenerate_faces: np.ndarray       #: (d,) faces with a repeated vertex index
    duplicate_faces: np.ndarray        #: (u,) faces with the same vertex set as an earlier face

    @property
    def is_manifold(self):
        return (self.non_manifold_edges.shape[0] == 0 and self.non_manifold_vertices.shape[0] == 0
                and self.degenerate_faces.shape[0] == 0 and self.duplicate_faces.shape[0] == 0)

    @property
    def is_oriented_manifold(self):
        return self.is_manifold and self.inconsistent_edges.shape[0] == 0


def manifold_report(F, n_vertices):
    """Check a triangle mesh for non-manifold edges and vertices, orientation
    flips, degenerate and duplicate faces.

    A vertex is manifold when its incident faces form a single fan, i.e. are
    connected to each other through manifold edges around the vertex (a disk,
    or a half-disk on the boundary). Isolated vertices are fine.

    Raises
    ------
    InvalidMeshError
        ``F`` not (m,3) integers, or an index outside ``[0, n_vertices)``.
    InvalidArgumentError
        ``n_vertices`` not an integer >= 0.
    """
    return _manifold_report(*_checked("manifold_report", F, n_vertices))


def _manifold_report(F, n_vertices):
    """:func:`manifold_report` of a checked ``F`` (m,3) int64."""
    m = F.shape[0]
    empty2 = np.zeros((0, 2), dtype=np.int64)
    empty1 = np.zeros(0, dtype=np.int64)
    if m == 0:
        return ManifoldReport(empty2, empty1, empty2, empty1, empty1)
    degenerate = np.flatnonzero((F[:, 0] == F[:, 1]) | (F[:, 1] == F[:, 2]) | (F[:, 0] == F[:, 2]))
    Fs = np.sort(F, axis=1)
    n = np.int64(max(n_vertices, 1))
    fkey = (Fs[:, 0] * n + Fs[:, 1]) * n + Fs[:, 2]
    _, first_idx = np.unique(fkey, return_index=True)
    dup_mask = np.ones(m, dtype=bool)
    dup_mask[first_idx] = False
    duplicates = np.flatnonzero(dup_mask)

    em = _edge_map(F, n_vertices)
    nm_edges = em.E[em.edge_face_count > 2]

    faces, corners = edge_faces(em)
    interior = np.flatnonzero(em.edge_face_count == 2)
    f0, f1 = faces[interior, 0], faces[interior, 1]
    c0, c1 = corners[interior, 0], corners[interior, 1]
    # directed edge (F[f,c+1] -> F[f,c+2]) in each face; consistent faces traverse it oppositely
    start0 = F[f0, (c0 + 1) % 3]
    start1 = F[f1, (c1 + 1) % 3]
    inconsistent = em.E[interior[start0 == start1]]

    # fans: corners of the same vertex joined across interior manifold edges
    # corner id = 3*f + c; the shared vertices of edge (a,b) are a and b
    a, b = em.E[interior, 0], em.E[interior, 1]

    def corner_of(face, vertex):
        local = np.argmax(F[face] == vertex[:, None], axis=1)
        return 3 * face + local

    pairs = np.concatenate([
        np.stack([corner_of(f0, a), corner_of(f1, a)], axis=1),
        np.stack([corner_of(f0, b), corner_of(f1, b)], axis=1),
    ])
    valid = np.ones(3 * m, dtype=bool)
    valid[3 * degenerate[:, None] + np.arange(3)] = False
    labels = connected_labels(3 * m, pairs)
    vert_of_corner = F.ravel()
    keep = valid
    vk = vert_of_corner[keep]
    lk = labels[keep]
    key = sorted_unique(vk * np.int64(3 * m) + lk)
    fans_per_vertex = np.bincount(key // np.int64(3 * m), minlength=n_vertices)
    nm_vertices = np.flatnonzero(fans_per_vertex > 1)
    # vertices on a non-manifold edge are reported there, not here twice
    return ManifoldReport(nm_edges, nm_vertices, inconsistent, degenerate, duplicates)


def euler_characteristic(F, n_vertices=None):
    """V - E + F counting only the vertices referenced by ``F``.

    ``n_vertices`` (optional) is checked: every index of ``F`` below it.
    Raises :class:`InvalidMeshError` for a malformed ``F`` (see :func:`edge_map`).
    """
    if n_vertices is None:
        F = check_faces(F, None, where="euler_characteristic", copy=False)
    else:
        F, _ = _checked("euler_characteristic", F, n_vertices)
    return _euler(F)


def _euler(F):
    """:func:`euler_characteristic` of a checked ``F`` (m,3) int64 (over its
    used vertices, renumbered: the edge keys stay small whatever the indices)."""
    if F.shape[0] == 0:
        return 0
    used, Fu = np.unique(F, return_inverse=True)
    em = _edge_map(Fu.reshape(-1, 3), used.shape[0])
    return int(used.shape[0] - em.E.shape[0] + F.shape[0])


class TopologySummary(NamedTuple):
    """Topological invariants a cage must share with its source."""

    euler: int
    components: int
    boundary_loops: int
    boundary_edges: int
    non_manifold_edges: int
    non_manifold_vertices: int


def topology_summary(F, n_vertices):
    """Euler characteristic, components, boundary loops and defects of a mesh.

    Raises :class:`InvalidMeshError` / :class:`InvalidArgumentError` for a
    malformed ``F`` or ``n_vertices`` (see :func:`edge_map`)."""
    F, n_vertices = _checked("topology_summary", F, n_vertices)
    em = _edge_map(F, n_vertices)
    rep = _manifold_report(F, n_vertices)
    _, n_comp = face_components(F, n_vertices)
    return TopologySummary(
        euler=_euler(F),
        components=n_comp,
        boundary_loops=boundary_loops_count(F, n_vertices, em),
        boundary_edges=int((em.edge_face_count == 1).sum()),
        non_manifold_edges=int(rep.non_manifold_edges.shape[0]),
        non_manifold_vertices=int(rep.non_manifold_vertices.shape[0]),
    )


def collapsible_edges(F, n_vertices, em=None):
    """Edges of a manifold mesh whose collapse keeps its topology (the link
    condition of Dey et al., 1999, as ``simplify`` enforces it).

    Edge ``(a, b)`` passes when the vertices adjacent to both ``a`` and ``b``
    are exactly its opposite vertices (two inside, one on a border), an inside
    edge does not join two border vertices (that would pinch the surface), a
    border edge's loop has more than three edges, and its component is not a
    tetrahedron.

    Returns
    -------
    em : EdgeMap, the edges tested (``em.E``).
    ok : (e,) bool, edge ``k`` can collapse.
    """
    F = np.asarray(F, dtype=np.int64)
    em = _edge_map(F, n_vertices) if em is None else em
    E, count = em.E, em.edge_face_count
    e = E.shape[0]
    if e == 0:
        return em, np.zeros(0, dtype=bool)
    key = edge_keys(E[:, 0], E[:, 1], n_vertices)     # sorted (edge_map's order)
    # adjacency lists: both directions of every edge, grouped by vertex
    src = np.concatenate([E[:, 0], E[:, 1]])
    dst = np.concatenate([E[:, 1], E[:, 0]])
    order = np.argsort(src, kind="stable")
    src, dst = src[order], dst[order]
    start = np.searchsorted(src, np.arange(n_vertices))
    valence = np.bincount(src, minlength=n_vertices)
    # for every edge (a, b) and every neighbour c of a: is (b, c) an edge?
    a, b = E[:, 0], E[:, 1]
    reps = valence[a]
    owner = np.repeat(np.arange(e), reps)
    c = dst[np.repeat(start[a] - np.cumsum(reps) + reps, reps) + np.arange(int(reps.sum()))]
    bb = b[owner]
    q = edge_keys(bb, c, n_vertices)
    pos = np.minimum(np.searchsorted(key, q), e - 1)
    common = np.bincount(owner, weights=(key[pos] == q) & (c != bb), minlength=e)
    border = count == 1
    on_border = np.zeros(n_vertices, dtype=bool)
    on_border[E[border].ravel()] = True
    ok = np.where(border, common == 1, (common == 2) & ~(on_border[a] & on_border[b]))
    if border.any():
        # border loops of three edges would close up
        B = E[border]
        used, rel = np.unique(B, return_inverse=True)
        loop = connected_labels(used.size, rel.reshape(-1, 2))
        loop_edges = np.bincount(loop[rel.reshape(-1, 2)[:, 0]], minlength=used.size)
        ok[np.flatnonzero(border)[loop_edges[loop[rel.reshape(-1, 2)[:, 0]]] <= 3]] = False
    comp, k = face_components(F, n_vertices)
    faces_per_comp = np.bincount(comp, minlength=k)
    tetra = faces_per_comp[comp] <= 4
    ok[sorted_unique(em.face_edge[tetra].ravel())] = False
    return em, ok
