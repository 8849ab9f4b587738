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


def _positions(doc, k, path, glb_bin, cache):
    """(count, 3) float32 of accessor ``k`` when it is one of floats read
    from a view, else None."""
    a = doc["accessors"][k]
    if a.get("componentType") != _FLOAT or a.get("type") != "VEC3" or "bufferView" not in a:
        return None
    view = doc["bufferViews"][a["bufferView"]]
    data = _buffer(doc, view["buffer"], path, glb_bin, cache)
    return np.ndarray((a["count"], 3), dtype="<f4", buffer=data,
                      offset=view.get("byteOffset", 0) + a.get("byteOffset", 0),
                      strides=(view.get("byteStride") or 12, 4))


def nonfinite_positions(doc, path, glb_bin):
    """``(mesh, primitive, vertices)`` of the first primitive whose POSITION
    holds a coordinate that is not a finite number, or None. ``glb_bin``:
    the GLB's BIN chunk (None for a ``.gltf``)."""
    cache, seen = {}, set()
    for i, mesh in enumerate(doc.get("meshes", [])):
        for j, prim in enumerate(mesh.get("primitives", [])):
            k = (prim.get("attributes") or {}).get("POSITION")
            if not isinstance(k, int) or isinstance(k, bool) or k in seen \
                    or not 0 <= k < len(doc.get("accessors", [])):
                continue            # (no such accessor: Blender's importer says so)
            seen.add(k)
            V = _positions(doc, k, path, glb_bin, cache)
            bad = 0 if V is None else int((~np.isfinite(V).all(axis=1)).sum())
            if bad:
                return i, j, bad
    return None
