"""The vertex positions of a glTF file, read before Blender's importer reads
them: a NaN or infinite coordinate, which the importer turns into 0 without
a word (a sphere with a NaN came back "ok", its vertex pulled to the
origin's plane), is refused naming the mesh and the primitive.

    primitive.attributes.POSITION -> accessor (FLOAT VEC3, count, byteOffset)
        -> bufferView (buffer, byteOffset, byteStride) -> buffer bytes

Only what :mod:`.gltf_file` has checked is read here (every view inside its
buffer, every accessor inside its view); an accessor of integers (quantized
positions) is finite by its type, one without a bufferView all zeros.
"""

import base64
import os
import urllib.parse

import numpy as np

_FLOAT = 5126


def _buffer(doc, i, path, glb_bin, cache):
    """The bytes of buffer ``i``: the GLB's BIN chunk, its ``data:`` URI or
    its file (read once, kept in ``cache``)."""
    if i not in cache:
        uri = doc["buffers"][i].get("uri")
        if uri is None:
            cache[i] = glb_bin
        elif uri.startswith("data:"):
            cache[i] = base64.b64decode(uri.partition(",")[2], validate=False)
        else:
            with open(os.path.join(os.path.dirname(path), urllib.parse.unquote(uri)), "rb") as fh:
                cache[i] = fh.read()
    return cache[i]


def _count(v):
    """``v`` when it is a count or an index (an int >= 0, not a bool), else None."""
    return v if isinstance(v, int) and not isinstance(v, bool) and v >= 0 else None


#: the NumPy type of each glTF component type an index may have (UNSIGNED_BYTE, _SHORT, _INT)
INDEX_TYPES = {5121: "<u1", 5123: "<u2", 5125: "<u4"}


def _view_items(doc, a, count, dtype, width, path, glb_bin, cache):
    """(count, width) of ``dtype`` that ``a`` (an accessor, or its sparse
    indices or values) reads from its bufferView at its byteOffset (the
    view's byteStride, or tightly packed), or None when a field is not what
    glTF says or the bytes are not there."""
    j, off = _count(a.get("bufferView")), _count(a.get("byteOffset", 0))
    views = doc.get("bufferViews")
    if None in (j, count, off) or not isinstance(views, list) or j >= len(views) \
            or not isinstance(views[j], dict):
        return None
    view = views[j]
    size = np.dtype(dtype).itemsize
    i, start = _count(view.get("buffer")), _count(view.get("byteOffset", 0))
    stride = _count(view.get("byteStride", size * width)) or size * width
    buffers = doc.get("buffers")
    if None in (i, start) or not isinstance(buffers, list) or i >= len(buffers) \
            or not isinstance(buffers[i], dict) or not isinstance(buffers[i].get("uri", ""), str):
        return None
    data = _buffer(doc, i, path, glb_bin, cache)
    if data is None or start + off + (stride * (count - 1) + size * width if count else 0) \
            > len(data):
        return None
    return np.ndarray((count, width), dtype=dtype, buffer=data, offset=start + off,
                      strides=(stride, size))


def _positions(doc, k, path, glb_bin, cache):
    """(count, 3) float32 of accessor ``k`` when it is one of floats, else
    None (also when a field is not what glTF says: the checks before, or
    Blender's importer, name that): its view's values (zeros without one),
    with its ``sparse`` values put in (a NaN there had come back "ok")."""
    a = doc["accessors"][k]
    if not isinstance(a, dict) or a.get("componentType") != _FLOAT or a.get("type") != "VEC3":
        return None
    count = _count(a.get("count"))
    if count is None:
        return None
    if a.get("bufferView") is None:
        V = np.zeros((count, 3), dtype="<f4")
    else:
        V = _view_items(doc, a, count, "<f4", 3, path, glb_bin, cache)
    sparse = a.get("sparse")
    if V is None or not isinstance(sparse, dict):
        return V
    n = _count(sparse.get("count"))
    at, values = sparse.get("indices"), sparse.get("values")
    if n is None or not isinstance(at, dict) or not isinstance(values, dict) \
            or at.get("componentType") not in INDEX_TYPES:
        return V
    at = _view_items(doc, at, n, INDEX_TYPES[at["componentType"]], 1, path, glb_bin, cache)
    values = _view_items(doc, values, n, "<f4", 3, path, glb_bin, cache)
    if at is None or values is None or (n and int(at.max()) >= count):
        return V
    V = V.copy()
    V[at.ravel().astype(np.int64)] = values
    return V


def nonfinite_positions(doc, path, glb_bin):
    """``(mesh, primitive, vertices)`` of the first primitive whose POSITION
    holds a coordinate that is not a finite number, or None. ``glb_bin``:
    the GLB's BIN chunk (None for a ``.gltf``)."""
    cache, seen = {}, set()
    accessors = doc.get("accessors")
    for i, mesh in enumerate(doc.get("meshes", [])):
        for j, prim in enumerate(mesh.get("primitives", [])):
            attributes = prim.get("attributes")
            k = _count(attributes.get("POSITION")) if isinstance(attributes, dict) else None
            if k is None or k in seen or not isinstance(accessors, list) or k >= len(accessors):
                continue            # (no such accessor: Blender's importer says so)
            seen.add(k)
            V = _positions(doc, k, path, glb_bin, cache)
            bad = 0 if V is None else int((~np.isfinite(V).all(axis=1)).sum())
            if bad:
                return i, j, bad
    return None


def indices_past_positions(doc, path, glb_bin):
    """``(mesh, primitive, largest index, vertices)`` of the first primitive
    whose indices name a vertex its POSITION does not have (Blender's
    importer failed with an IndexError), or None."""
    accessors, cache = doc.get("accessors"), {}
    for i, mesh in enumerate(doc.get("meshes", [])):
        for j, prim in enumerate(mesh.get("primitives", [])):
            attributes = prim.get("attributes")
            k = _count(attributes.get("POSITION")) if isinstance(attributes, dict) else None
            q = _count(prim.get("indices"))
            if None in (k, q) or not isinstance(accessors, list) or max(k, q) >= len(accessors):
                continue
            a, n = accessors[q], _count(accessors[k].get("count"))
            if not isinstance(a, dict) or a.get("componentType") not in INDEX_TYPES or \
                    a.get("bufferView") is None or n is None:
                continue
            index = _view_items(doc, a, _count(a.get("count")), INDEX_TYPES[a["componentType"]],
                                1, path, glb_bin, cache)
            if index is not None and index.size and int(index.max()) >= n:
                return i, j, int(index.max()), n
    return None
