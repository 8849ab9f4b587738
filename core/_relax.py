"""Topology changes that ``simplify(..., preserve_topology=False)`` allows
once the link condition has stopped every collapse (private).

All keep the mesh a clean manifold:

* a hole bounded by three edges is closed with one triangle (the rim's
  half-edges get the new face's as twins), so its rim can collapse further;
* a component that cannot lose another face (a tetrahedron, a lone
  triangle) is removed, smallest first, while faces are still needed;
* a longer hole is capped with a fan of triangles from one rim vertex,
  shortest first (``close_smallest_hole``).

They work on a compact :class:`core._collapse.State` and leave it compact.
"""

import numpy as np

from ._groups import sorted_unique
from ._clean import BOUNDARY, edge_representatives, face_keys, half_edge_ends
from ._collapse import append_faces, compact, survivors
from .mesh import flat_faces
from .topology import connected_labels, edge_keys, face_components, vertex_labels


def _border(st):
    """The border half-edges of the state and their ends ``u -> w`` (the
    direction their face runs along the border)."""
    hb = np.flatnonzero(st.twin == BOUNDARY)
    u, w = half_edge_ends(st.F, hb)
    return hb, u, w


def close_triangular_holes(st):
    """Cap every boundary loop of exactly three edges whose triangle is not
    already a face and has an area. Returns the number of caps."""
    F, twin = st.F, st.twin
    n = st.V.shape[0]
    hb, u, w = _border(st)
    if hb.size < 3:
        return 0
    deg = np.bincount(u, minlength=n) + np.bincount(w, minlength=n)
    nsum = np.bincount(u, weights=w, minlength=n) + np.bincount(w, weights=u, minlength=n)
    nsum = np.rint(nsum).astype(np.int64)         # sum of each rim vertex's two rim neighbours
    z = nsum[u] - w                                # u's other rim neighbour
    loop = (deg[u] == 2) & (deg[w] == 2) & (z == nsum[w] - u)
    z = np.where(loop, z, 0)
    loop &= (deg[z] == 2) & (nsum[z] == u + w) & (z != u) & (z != w)
    if not loop.any():
        return 0
    hb, u, w, z = hb[loop], u[loop], w[loop], z[loop]
    # one cap per loop (each loop was found from its three edges) ...
    keys = face_keys(np.concatenate([np.stack([u, w, z], axis=1), F]), n)
    key, fkey = keys[:u.size], np.sort(keys[u.size:])
    _, first = np.unique(key, return_index=True)
    hb, u, w, z, key = hb[first], u[first], w[first], z[first], key[first]
    # ... unless that triangle is already a face (a lone triangle, or a cap would double a face)
    pos = np.minimum(np.searchsorted(fkey, key), fkey.size - 1)
    new = fkey[pos] != key
    hb, u, w, z = hb[new], u[new], w[new], z[new]
    # ... or has no area (two corners are copies of a split bow-tie vertex, or the three
    # lie on a line: locked, no collapse would remove it)
    keep = ~flat_faces(st.V, np.stack([w, u, z], axis=1))
    hb, u, w, z = hb[keep], u[keep], w[keep], z[keep]
    k = hb.size
    if k == 0:
        return 0
    # rim half-edges by undirected key, to pair the caps' sides with them
    hall = np.flatnonzero(twin == BOUNDARY)
    ua, wa = half_edge_ends(F, hall)
    ekey = edge_keys(ua, wa, n)
    order = np.argsort(ekey)
    ekey, hall = ekey[order], hall[order]

    def rim(a, b):
        q = edge_keys(a, b, n)
        return hall[np.searchsorted(ekey, q)]

    m = F.shape[0]
    caps = np.stack([w, u, z], axis=1)            # opposite direction to the rim: w -> u, u -> z, z -> w
    hc = 3 * (m + np.arange(k, dtype=np.int64))
    pairs = [(hc + 0, rim(u, z)), (hc + 1, rim(z, w)), (hc + 2, hb)]  # edge c is opposite corner c
    _add_caps(st, caps, hb, pairs)
    return k


def _add_caps(st, caps, rim_h, pairs):
    """Append the faces ``caps`` (k,3), each descending from the face of the
    rim half-edge ``rim_h[i]``, and glue the half-edge ``pairs`` (lists of
    (a, b) arrays) as twins; their vertices are no longer on a border."""
    append_faces(st, caps, st.forig[rim_h // 3])
    for a, b in pairs:
        st.twin[a] = b
        st.twin[b] = a
    st.is_bnd[caps.ravel()] = False
    # the rims' edges were invalid (both ends on a border): cost everything afresh
    st.c_cost[:] = 0.0
    st.c_stale[:] = True




def _list_order(succ):
    """Order of the nodes of one linked list (``succ[i]``: the next node,
    ``-1`` at the end), first to last, by pointer jumping (Wyllie)."""
    dist = (succ >= 0).astype(np.int64)          # distance to the end
    ptr = succ.copy()
    while (ptr >= 0).any():
        ok = ptr >= 0
        nxt = np.where(ok, ptr, 0)
        dist = np.where(ok, dist + dist[nxt], dist)
        ptr = np.where(ok, ptr[nxt], -1)
    return np.argsort(-dist, kind="stable")


def close_smallest_hole(st, tun):
    """Cap the shortest boundary loop of more than three edges with a fan of
    triangles from one of its vertices, so that it can collapse further.
    Apexes are tried along the rim (``tun.cap_apex_tries``, evenly spaced)
    until none of the fan's chords is already an edge (a chord that exists
    would be a third face on it) and each of its triangles has an area
    (:func:`_flat_fan`), and loops in order of length (``tun.cap_hole_tries``).
    Returns the number of faces added (0: no loop could be closed)."""
    F, twin = st.F, st.twin
    n = st.V.shape[0]
    hb, u, w = _border(st)
    if hb.size < 4:
        return 0
    out = np.full(n, -1, dtype=np.int64)
    out[u] = np.arange(hb.size)                   # the border half-edge leaving each rim vertex
    nxt = out[w]
    loop = connected_labels(hb.size, np.stack([np.arange(hb.size), nxt], axis=1))
    length = np.bincount(loop, minlength=hb.size)
    roots = np.flatnonzero((loop == np.arange(hb.size)) & (length > 3))
    if roots.size == 0:
        return 0
    hi = edge_representatives(twin, boundary=False)
    ea, eb = half_edge_ends(F, np.concatenate([hi, hb]))
    edges = np.sort(edge_keys(ea, eb, n))
    for root in roots[np.argsort(length[roots], kind="stable")][:tun.cap_hole_tries]:
        members = np.flatnonzero(loop == root)
        local = np.full(hb.size, -1, dtype=np.int64)
        local[members] = np.arange(members.size)
        succ = local[nxt[members]]
        succ[succ == 0] = -1                      # cut the loop before its first member
        ring = members[_list_order(succ)]         # rim half-edges in order: v_i -> v_{i+1}
        k = ring.size
        shifts = np.linspace(0, k, tun.cap_apex_tries, endpoint=False).astype(np.int64)
        for shift in sorted_unique(shifts):
            r = np.roll(ring, -shift)
            v = u[r]                              # v_0 (the apex) .. v_{k-1}
            q = edge_keys(v[0], v[2:k - 1], n)
            pos = np.minimum(np.searchsorted(edges, q), edges.size - 1)
            if (edges[pos] == q).any() or _flat_fan(st, v):
                continue
            _fan(st, v, hb[r])
            return k - 2
    return 0


def _flat_fan(st, v):
    """Whether a triangle of the fan :func:`_fan` makes of the loop ``v`` has
    no area (two of its corners copies of a split bow-tie vertex, or the three
    on a line): where its corners are locked, no collapse removes it, and the
    cage kept a face of no area (an icosphere with 8% of its faces removed,
    every vertex locked, ``preserve_topology=False``: 4 of them)."""
    i = np.arange(1, v.size - 1)
    return bool(flat_faces(st.V, np.stack([np.full(i.size, v[0]), v[i + 1], v[i]], axis=1)).any())


def _fan(st, v, rim_h):
    """Cap the loop ``v`` (rim vertices in order, the border half-edge
    ``rim_h[i]`` running v_i -> v_{i+1}) with triangles (v_0, v_{i+1}, v_i),
    i = 1 .. k-2, glued to the rim and to each other."""
    k = v.size
    i = np.arange(1, k - 1)
    caps = np.stack([np.full(k - 2, v[0]), v[i + 1], v[i]], axis=1)
    hc = 3 * (st.F.shape[0] + np.arange(k - 2, dtype=np.int64))
    # corner 0 faces rim i; corner 1 the chord to v_i (rim 0 for the first);
    # corner 2 the chord to v_{i+1} (rim k-1 for the last)
    pairs = [(hc + 0, rim_h[i]), (hc[1:] + 1, hc[:-1] + 2),
             (hc[:1] + 1, rim_h[:1]), (hc[-1:] + 2, rim_h[-1:])]
    _add_caps(st, caps, rim_h[i], pairs)


def drop_stuck_components(st, need, max_size):
    """Remove components of at most four faces (they cannot collapse further),
    smallest bounding box first, until ``need`` faces are gone; only those
    whose bounding-box diagonal is at most ``max_size`` (working units), that
    have no locked vertex and are not the largest component. Returns the
    number of faces removed."""
    F = st.F
    n, m = st.V.shape[0], F.shape[0]
    if m == 0 or need <= 0:
        return 0
    comp, k = face_components(F, n)
    size = np.bincount(comp, minlength=k)
    vcomp = vertex_labels(F, comp, n)
    used = vcomp >= 0
    lo = np.full((k, 3), np.inf)
    hi = np.full((k, 3), -np.inf)
    np.minimum.at(lo, vcomp[used], st.V[used])
    np.maximum.at(hi, vcomp[used], st.V[used])
    diag = np.linalg.norm(hi - lo, axis=1)
    locked = np.bincount(vcomp[used], weights=st.locked[used], minlength=k) > 0
    ok = (size <= 4) & ~locked & (diag <= max_size)
    ok[np.argmax(diag)] = False
    cand = np.flatnonzero(ok)
    if cand.size == 0:
        return 0
    cand = cand[np.argsort(diag[cand], kind="stable")]
    take = np.cumsum(size[cand]) - size[cand] < need
    drop = np.zeros(k, dtype=bool)
    drop[cand[take]] = True
    st.alive = ~drop[comp]
    dead_v = used & drop[np.maximum(vcomp, 0)]
    st.dead_v = dead_v
    cur = survivors(st)
    st.cur_of_clean = np.where((cur >= 0) & ~dead_v[np.maximum(cur, 0)], cur, -1)
    st.parent = np.arange(n, dtype=np.int64)
    st.m_live = int(st.alive.sum())
    removed = m - st.m_live
    compact(st)
    return removed
