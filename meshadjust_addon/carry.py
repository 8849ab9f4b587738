"""What a subdivided mesh keeps of the mesh it was subdivided from.

Subdivide (``api.subdivide_object``) builds a new mesh from positions and
triangles; without this module it lost every UV map, colour attribute,
vertex group, sharp edge and attribute of the artist's (in place too). Each
fine element takes its values from where it lies in its coarse triangle, as
the core's numbering says (``core.subdivide``: fine face ``g`` lies in coarse
triangle ``g // 4**levels``; :meth:`core.SubdivisionOperator.fine_vertex_parent`
gives each fine vertex's barycentric coordinates in a coarse triangle):

* **corner** values (UV maps, corner colours) are interpolated linearly from
  the three corners of the fine face's own coarse triangle, so a UV seam
  stays a seam;
* **point** values (point colours, vertex groups) linearly from the coarse
  triangle's vertices (a coarse vertex keeps its value bit for bit);
* **face** values (material index, smooth shading) are the coarse polygon's;
* **edge** values (sharp edges, seams) go to the fine edges along the coarse
  edge, the other fine edges get none;
* hidden parts stay hidden (the ``.hide_*`` flags, carried as the others);
* a cage's rest shape goes through the subdivision as its positions do, and
  its crease flags as its sharp edges, so its edit is kept.

Integer, boolean and other discrete values take the nearest coarse corner's
value instead of an interpolation. Custom split normals are not carried (the
subdivided surface has normals of its own): the report says so.
"""

from typing import NamedTuple

import numpy as np

from . import mesh_io

_TYPES = mesh_io.ATTRIBUTE_FIELDS

#: attributes the new mesh has of its own or that are not the artist's data
_SKIP = {"position", "custom_normal"}
#: Blender's internal attributes ("." names) that are the artist's: hidden parts, seams (4.2)
_INTERNAL = {".hide_vert", ".hide_edge", ".hide_poly", ".uv_seam"}


#: a cage's rest shape (source space): subdivided as its positions are, so its edit is kept
_REST = "meshadjust_rest"
#: a cage's crease flags: carried as its sharp edges are
_CREASE = "meshadjust_crease"


def _carried(attr):
    """Whether ``attr`` is an attribute of the artist's (or a cage's crease
    flags) that this module carries by interpolation; MeshAdjust's others
    (a binding's, per dense vertex) are left out."""
    name = attr.name
    return ((name in _INTERNAL or name == _CREASE or not name.startswith((".", "meshadjust_")))
            and name not in _SKIP and attr.data_type in _TYPES
            and attr.domain in ('POINT', 'CORNER', 'FACE', 'EDGE'))


def _carry_rest(src, dst, op):
    """A cage's rest shape (point attribute ``meshadjust_rest``, in its
    source's space) through the subdivision operator ``op``, as its positions
    went: the edit (positions minus rest) stays an edit of the finer cage (a
    cage subdivided in place lost it, and the Bind that followed made its
    edited shape the rest: the edited original went back to the scan)."""
    rest = src.attributes.get(_REST)
    if rest is None or rest.domain != 'POINT' or rest.data_type != 'FLOAT_VECTOR' \
            or len(rest.data) != op.n_coarse:
        return
    out = dst.attributes.new(_REST, 'FLOAT_VECTOR', 'POINT')
    mesh_io.write_attribute(out, op.apply(mesh_io.read_attribute(rest).astype(np.float64)))


def _mix(values, idx, weights, interpolate):
    """Per row ``r``: ``sum_j weights[r, j] * values[idx[r, j]]`` (or the
    value of the largest weight, for discrete values)."""
    if not interpolate:
        return values[idx[np.arange(idx.shape[0]), np.argmax(weights, axis=1)]]
    out = np.zeros((idx.shape[0], values.shape[1]))
    for j in range(idx.shape[1]):
        out += weights[:, j, None] * values[idx[:, j]]
    return out


def fine_corner_weights(F, op):
    """Where each fine corner lies in its fine face's own coarse triangle.

    Returns ``(tri, W)``: ``tri`` (m_fine*3,) int64, the coarse triangle of
    each fine corner (row ``3*g + k`` is corner ``k`` of fine face ``g``), and
    ``W`` (m_fine*3, 3) float64, its barycentric weights on that triangle's
    corners (rows sum to 1)."""
    F = np.asarray(F, dtype=np.int64)
    face, bary = op.fine_vertex_parent()
    fine_v = op.F_fine.ravel()
    tri = np.repeat(np.arange(op.F_fine.shape[0], dtype=np.int64) // 4 ** op.levels, 3)
    ids = F[face[fine_v]]                         # the coarse corners the weights are on
    own = F[tri]
    # (a fine vertex on a coarse edge may have its weights in the neighbour triangle:
    # they are on the edge's two vertices only, which the own triangle has too)
    W = np.einsum("ci,cij->cj", bary[fine_v], ids[:, :, None] == own[:, None, :])
    return tri, W


def _vertex_weights(F, op):
    """``(idx, W)``: each fine vertex's coarse vertices and weights (a coarse
    vertex, also an isolated one, is its own: weight 1)."""
    face, bary = op.fine_vertex_parent()
    idx = np.asarray(F, dtype=np.int64)[np.maximum(face, 0)]
    n0 = op.n_coarse
    idx[:n0] = np.arange(n0)[:, None]
    W = bary.copy()
    W[:n0] = [1.0, 0.0, 0.0]
    return idx, W


def _edge_parents(src, dst, F, op):
    """For each edge of ``dst`` the edge of ``src`` it lies along, or -1: a
    fine edge lies along coarse edge ``(p, q)`` when its two ends have
    weights on ``p`` and ``q`` only."""
    idx, W = _vertex_weights(F, op)
    support = np.where(W > 0, idx, -1)             # (n_fine, 3) coarse vertices, -1: none
    ev = np.empty(2 * len(dst.edges), np.int32)
    dst.edges.foreach_get("vertices", ev)
    ev = ev.reshape(-1, 2)
    ids = np.sort(np.concatenate([support[ev[:, 0]], support[ev[:, 1]]], axis=1), axis=1)
    new = (ids >= 0) & np.concatenate([np.ones((ids.shape[0], 1), bool),
                                       ids[:, 1:] != ids[:, :-1]], axis=1)
    hi = ids[:, -1]
    lo = np.where(ids >= 0, ids, hi[:, None]).min(axis=1)
    n = max(len(src.vertices), 1)
    sv = np.empty(2 * len(src.edges), np.int32)
    src.edges.foreach_get("vertices", sv)
    sv = sv.reshape(-1, 2).astype(np.int64)
    skey = np.minimum(sv[:, 0], sv[:, 1]) * n + np.maximum(sv[:, 0], sv[:, 1])
    order = np.argsort(skey)
    found = np.full(ev.shape[0], -1, dtype=np.int64)
    if not len(skey):
        return found
    key = lo * n + hi
    at = np.minimum(np.searchsorted(skey[order], key), len(skey) - 1)
    hit = (new.sum(axis=1) == 2) & (skey[order][at] == key)
    found[hit] = order[at][hit]
    return found


def _loose_edges(src, dst):
    """Add to ``dst`` the edges of ``src`` that no face uses (their vertices
    keep their indices through a subdivision); returns how many."""
    loose = np.empty(len(src.edges), dtype=bool)
    src.edges.foreach_get("is_loose", loose)
    if not loose.any():
        return 0
    sv = np.empty(2 * len(src.edges), np.int32)
    src.edges.foreach_get("vertices", sv)
    E = sv.reshape(-1, 2)[loose]
    n_e = len(dst.edges)
    dst.edges.add(E.shape[0])
    ev = np.empty(2 * len(dst.edges), np.int32)
    dst.edges.foreach_get("vertices", ev)
    ev[2 * n_e:] = E.ravel()
    dst.edges.foreach_set("vertices", ev)
    dst.update()
    return E.shape[0]


def carry(src, src_obj, dst, F, op):
    """Give the new mesh ``dst``, the subdivision ``op`` of the triangles
    ``F`` of ``src`` (read with :func:`~.mesh_io.read_triangles`), the
    artist's data of ``src`` (the mesh of ``src_obj``, or what it shows):
    its loose edges, attributes of every domain, UV maps and colours with
    their active and render choices. Returns ``(groups, notes)``: the vertex
    groups for :func:`put_groups`, and the sentences of what was not carried
    (for the report)."""
    _loose_edges(src, dst)
    tri_loops = _triangle_loops(src, F.shape[0])
    tri_poly = mesh_io.triangle_polygons(src)
    vidx = vW = None
    corner = edge = None
    for attr in [a for a in src.attributes if _carried(a)]:
        values = mesh_io.read_attribute(attr)
        interpolate = _TYPES[attr.data_type][3]
        if attr.domain == 'POINT':
            if vidx is None:
                vidx, vW = _vertex_weights(F, op)
            out = _mix(values, vidx, vW, interpolate)
        elif attr.domain == 'CORNER':
            if corner is None:
                corner = fine_corner_weights(F, op)
            tri, W = corner
            out = _mix(values, tri_loops[tri], W, interpolate)
        elif attr.domain == 'FACE':
            out = values[tri_poly[np.arange(len(dst.polygons)) // 4 ** op.levels]]
        else:
            if edge is None:
                edge = _edge_parents(src, dst, F, op)
            out = np.zeros((len(dst.edges), values.shape[1]), dtype=values.dtype)
            out[edge >= 0] = values[edge[edge >= 0]]
        new = dst.attributes.get(attr.name)
        if new is None or new.domain != attr.domain or new.data_type != attr.data_type:
            if new is not None:
                dst.attributes.remove(new)
            new = dst.attributes.new(attr.name, attr.data_type, attr.domain)
        mesh_io.write_attribute(new, out)
    _carry_rest(src, dst, op)
    _choices(src, dst)
    notes = []
    left = sorted(a.name for a in src.attributes if not a.name.startswith((".", "meshadjust_"))
                  and a.name not in _SKIP and not _carried(a))
    if left:
        notes.append(f"attribute{'s' if len(left) > 1 else ''} "
                     f"{', '.join(repr(n) for n in left)} not carried (of a kind Subdivide "
                     f"cannot interpolate)")
    if src.has_custom_normals:
        notes.append("its custom split normals are not carried (the subdivided surface has "
                     "normals of its own)")
    return _fine_groups(src, src_obj, F, op), notes


def _triangle_loops(mesh, m):
    """(m,3) int64: the corner (loop) of each corner of each triangle
    :func:`~.mesh_io.read_triangles` gives."""
    if len(mesh.loops) == 3 * len(mesh.polygons):
        return np.arange(3 * m, dtype=np.int64).reshape(-1, 3)
    mesh.calc_loop_triangles()
    buf = np.empty(3 * len(mesh.loop_triangles), dtype=np.int32)
    mesh.loop_triangles.foreach_get("loops", buf)
    return buf.reshape(-1, 3).astype(np.int64)


def _choices(src, dst):
    """The active and render UV maps and colour attributes of ``src`` on ``dst``."""
    for uv in src.uv_layers:
        new = dst.uv_layers.get(uv.name)
        if new is not None:
            if uv.active:
                dst.uv_layers.active = new
            new.active_render = uv.active_render
    colors = src.color_attributes
    for what in ("active_color_name", "default_color_name"):
        name = getattr(colors, what, "")
        if name and name in dst.color_attributes:
            setattr(dst.color_attributes, what, name)


class Groups(NamedTuple):
    """Vertex groups carried to a fine mesh, to put on its object
    (:func:`put_groups`, once the object has the mesh: Blender keeps the
    group names on the mesh)."""

    names: list
    locks: list
    active: int
    weights: np.ndarray   #: (n_fine, groups) float32
    member: np.ndarray    #: (n_fine, groups) bool


def _fine_groups(src, src_obj, F, op):
    """The vertex groups of ``src_obj`` (weights read from ``src``) at the
    fine vertices of ``op``, interpolated like point values (a fine vertex
    none of whose coarse vertices is in a group stays out of it); None when
    it has none."""
    if src_obj is None or not len(src_obj.vertex_groups):
        return None
    names = [g.name for g in src_obj.vertex_groups]
    weights = np.zeros((len(src.vertices), len(names)), dtype=np.float32)
    member = np.zeros(weights.shape, dtype=bool)
    for v in src.vertices:                      # (no bulk read of vertex groups in the API)
        for g in v.groups:
            if g.group < len(names):
                weights[v.index, g.group] = g.weight
                member[v.index, g.group] = True
    idx, W = _vertex_weights(F, op)
    fine_w = _mix(weights, idx, W, True).astype(np.float32)
    fine_in = _mix(member.astype(np.float64), idx, W, True) > 0
    return Groups(names, [g.lock_weight for g in src_obj.vertex_groups],
                  src_obj.vertex_groups.active_index, fine_w, fine_in)


def put_groups(obj, groups):
    """Give ``obj`` (with the fine mesh) the carried vertex ``groups``."""
    if groups is None:
        return
    obj.vertex_groups.clear()
    for k, name in enumerate(groups.names):
        group = obj.vertex_groups.new(name=name)
        group.lock_weight = groups.locks[k]
        rows = np.flatnonzero(groups.member[:, k])
        # one add() per distinct weight (the API has no bulk write of weights)
        values, inverse = np.unique(groups.weights[rows, k], return_inverse=True)
        inverse = inverse.ravel()
        order = np.argsort(inverse, kind="stable")
        bounds = np.cumsum(np.bincount(inverse, minlength=values.size))[:-1]
        for value, members in zip(values.tolist(), np.split(rows[order], bounds)):
            group.add(members.tolist(), value, 'REPLACE')
    obj.vertex_groups.active_index = groups.active
