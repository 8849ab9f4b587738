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


def _positions(doc, k, path, glb_bin, cache):
    """(count, 3) float32 of accessor ``k`` when it is one of floats read
    from a view, else None (also when a field is not what glTF says: the
    checks before, or Blender's importer, name that)."""
    a = doc["accessors"][k]
    if not isinstance(a, dict) or a.get("componentType") != _FLOAT or a.get("type") != "VEC3":
        return None
    j, count, off = _count(a.get("bufferView")), _count(a.get("count")), \
        _count(a.get("byteOffset", 0))
    views = doc.get("bufferViews")
    if None in (j, count, off) or not isinstance(views, list) or j >= len(views) \
            or not isinstance(views[j], dict):
        return None
    view = views[j]
    i, start = _count(view.get("buffer")), _count(view.get("byteOffset", 0))
    stride = _count(view.get("byteStride", 12)) or 12
    buffers = doc.get("buffers")
    if None in (i, start) or not isinstance(buffers, list) or i >= len(buffers) \
            or not isinstance(buffers[i], dict) or not isinstance(buffers[i].get("uri", ""), str):
        return None
    data = _buffer(doc, i, path, glb_bin, cache)
    if data is None or start + off + (stride * (count - 1) + 12 if count else 0) > len(data):
        return None
    return np.ndarray((count, 3), dtype="<f4", buffer=data, offset=start + off,
                      strides=(stride, 4))


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
