"""Input cleaning and the half-edge twin table used by :mod:`.simplify`.

Half-edge convention: half-edge ``h = 3 f + c`` is the edge of face ``f``
opposite corner ``c``, from ``F[f, (c+1)%3]`` to ``F[f, (c+2)%3]`` (the same
numbering as ``core.topology``'s face-edge ``c``). ``twin[h]`` is the other
half-edge on the same undirected edge (whatever its direction, so meshes
with inconsistent orientation work too), ``-1`` on a boundary edge and
``-2`` on a non-manifold edge (used by more than two faces).
"""

from typing import NamedTuple

import numpy as np

from .topology import connected_labels

BOUNDARY = -1
NON_MANIFOLD = -2


class CleanMesh(NamedTuple):
    """A mesh with duplicate/degenerate faces and unreferenced vertices removed."""

    V: np.ndarray                 #: (n,3) float64 referenced vertices
    F: np.ndarray                 #: (m,3) int64
    vertex_to_clean: np.ndarray   #: (n_in,) int64, index in V of each input vertex, -1 if dropped
    clean_to_vertex: np.ndarray   #: (n,) int64, input index of each kept vertex
    n_degenerate_faces: int       #: faces with a repeated vertex index
    n_duplicate_faces: int        #: faces with the vertex set of an earlier face
    n_unreferenced_vertices: int  #: vertices no kept face uses


def clean_mesh(V, F):
    """Drop degenerate and duplicate faces and unreferenced vertices.

    Parameters
    ----------
    V : (n,3) float64, F : (m,3) int64 (already checked by ``check_mesh``).

    Returns
    -------
    CleanMesh
    """
    n_in = V.shape[0]
    m_in = F.shape[0]
    degenerate = (F[:, 0] == F[:, 1]) | (F[:, 1] == F[:, 2]) | (F[:, 0] == F[:, 2])
    F = F[~degenerate]
    n_dup = 0
    if F.shape[0]:
        Fs = np.sort(F, axis=1)
        nn = np.int64(max(n_in, 1))
        key = (Fs[:, 0] * nn + Fs[:, 1]) * nn + Fs[:, 2]
        _, first = np.unique(key, return_index=True)
        keep = np.zeros(F.shape[0], dtype=bool)
        keep[first] = True
        n_dup = int(F.shape[0] - first.size)
        F = F[keep]  # boolean mask keeps the original face order
    used = np.zeros(n_in, dtype=bool)
    used[F.ravel()] = True
    clean_to_vertex = np.flatnonzero(used)
    vertex_to_clean = np.full(n_in, -1, dtype=np.int64)
    vertex_to_clean[clean_to_vertex] = np.arange(clean_to_vertex.size)
    return CleanMesh(V[clean_to_vertex], vertex_to_clean[F], vertex_to_clean, clean_to_vertex,
                     int(degenerate.sum()), n_dup, int(n_in - clean_to_vertex.size))


def half_edge_ends(F):
    """Endpoints ``(U, W)`` of every half-edge, each (3m,) int64."""
    return F[:, [1, 2, 0]].ravel(), F[:, [2, 0, 1]].ravel()


def twin_table(F, n_vertices):
    """Twin of every half-edge (see the module docstring), (3m,) int64.

    One sort of the undirected edge keys; edges used once are boundary
    (``-1``), twice are paired, more than twice non-manifold (``-2``).
    """
    U, W = half_edge_ends(F)
    nn = np.int64(max(n_vertices, 1))
    key = np.minimum(U, W) * nn + np.maximum(U, W)
    order = np.argsort(key, kind="stable")
    ks = key[order]
    size = ks.size
    twin = np.full(size, BOUNDARY, dtype=np.int64)
    if size == 0:
        return twin
    start = np.flatnonzero(np.concatenate([[True], ks[1:] != ks[:-1]]))
    count = np.diff(np.concatenate([start, [size]]))
    pair = start[count == 2]
    h0, h1 = order[pair], order[pair + 1]
    twin[h0] = h1
    twin[h1] = h0
    multi = np.repeat(count > 2, count)
    twin[order[multi]] = NON_MANIFOLD
    return twin


def non_manifold_vertices(F, n_vertices, twin):
    """Boolean mask of vertices on a non-manifold edge or whose faces form
    more than one fan (bow-tie vertices), (n,) bool."""
    U, W = half_edge_ends(F)
    bad = np.zeros(n_vertices, dtype=bool)
    nm = twin == NON_MANIFOLD
    bad[U[nm]] = True
    bad[W[nm]] = True
    # fans: join the corners of the same vertex across manifold interior edges
    h = np.flatnonzero(twin > np.arange(twin.size))
    t = twin[h]
    f_h, f_t = h - h % 3, t - t % 3
    Fr = F.ravel()

    def corner(face_base, vertex):
        # the corner of face (3*f) holding vertex
        c = np.where(Fr[face_base] == vertex, 0, np.where(Fr[face_base + 1] == vertex, 1, 2))
        return face_base + c

    u, w = U[h], W[h]
    pairs = np.concatenate([np.stack([corner(f_h, u), corner(f_t, u)], axis=1),
                            np.stack([corner(f_h, w), corner(f_t, w)], axis=1)])
    labels = connected_labels(Fr.size, pairs)
    roots = labels == np.arange(Fr.size)
    fans = np.bincount(Fr[roots], minlength=n_vertices)
    bad |= fans > 1
    return bad
