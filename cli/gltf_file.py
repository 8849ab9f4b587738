"""glTF files: checked before Blender's importer reads them, and their axes.

Blender's glTF importer decodes every accessor with ``np.frombuffer`` and
fails with a Python traceback ("ValueError: buffer is smaller than requested
size") when a buffer holds fewer bytes than the file's JSON says.
:func:`check` compares, before Blender, what each buffer holds (the ``.bin``
file beside a ``.gltf``, a GLB's BIN chunk, a ``data:`` URI) with the
``byteLength`` declared, and each buffer view and accessor with the bytes
they reach:

    GLB:  'glTF' | version 2 | length | JSON chunk (length, 'JSON') | BIN chunk (length, 'BIN\\0')
    accessor (count, type, component) -> bufferView (offset, length, stride)
                                      -> buffer (byteLength, uri)

glTF is Y-up; Blender's importer turns it Z-up (``(x, y, z)`` of the file
is ``(x, -z, y)`` in Blender). :data:`FROM_BLENDER` turns it back, so the
batch works in the file's own coordinates (and exports glTF without the
turn: ``export_yup=False``).
"""

import base64
import json
import os
import struct
import urllib.parse

import numpy as np

from .file_check import FileCheck, InputFileError
from .gltf_positions import INDEX_TYPES, indices_past_positions, nonfinite_positions

#: a file's ``(x, y, z)`` from Blender's: ``V_file = V_blender @ FROM_BLENDER``
FROM_BLENDER = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
_GLB_HEAD, _CHUNK_HEAD = 12, 8
_JSON_CHUNK, _BIN_CHUNK = 0x4E4F534A, 0x004E4942
_COMPONENT_BYTES = {5120: 1, 5121: 1, 5122: 2, 5123: 2, 5125: 4, 5126: 4}
_TYPE_COMPONENTS = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}


def _glb(path, name):
    """``(JSON document, BIN chunk or None)`` of a GLB file."""
    with open(path, "rb") as fh:
        data = fh.read()
    if len(data) < _GLB_HEAD + _CHUNK_HEAD or data[:4] != b"glTF":
        raise InputFileError(f"{name}: not a GLB file (no 'glTF' header)")
    length = struct.unpack_from("<I", data, 8)[0]
    if length != len(data):
        raise InputFileError(f"{name}: its GLB header says {length:,} bytes, the file has "
                             f"{len(data):,} (file truncated?)")
    chunks, pos = {}, _GLB_HEAD
    while pos + _CHUNK_HEAD <= len(data):
        size, kind = struct.unpack_from("<II", data, pos)
        if pos + _CHUNK_HEAD + size > len(data):
            raise InputFileError(f"{name}: a GLB chunk of {size:,} bytes at byte {pos:,} runs "
                                 f"past the end of the file ({len(data):,} bytes)")
        chunks.setdefault(kind, data[pos + _CHUNK_HEAD:pos + _CHUNK_HEAD + size])
        pos += _CHUNK_HEAD + size
    if _JSON_CHUNK not in chunks:
        raise InputFileError(f"{name}: a GLB file without its JSON chunk")
    doc = _json(chunks[_JSON_CHUNK], name)
    return doc, chunks.get(_BIN_CHUNK)


def _json(text, name):
    try:
        doc = json.loads(text)
    except (ValueError, UnicodeDecodeError) as exc:
        raise InputFileError(f"{name}: its glTF JSON does not parse ({exc})") from None
    if not isinstance(doc, dict):
        raise InputFileError(f"{name}: its glTF JSON is not an object")
    return doc


def _entries(doc, key, name):
    """The list of objects ``doc[key]`` (empty when absent)."""
    items = doc.get(key, [])
    if not isinstance(items, list) or not all(isinstance(x, dict) for x in items):
        raise InputFileError(f"{name}: its glTF '{key}' is not a list of objects")
    return items


def _held(buffer, i, path, name, bin_length):
    """Bytes buffer ``i`` holds: its GLB BIN chunk, ``data:`` URI or file."""
    uri = buffer.get("uri")
    if uri is not None and not isinstance(uri, str):
        raise InputFileError(f"{name}: buffer {i}'s uri is not a string")
    if uri is None:
        if bin_length is None:
            raise InputFileError(f"{name}: buffer {i} has no uri and the file no BIN chunk")
        return bin_length, "the GLB's BIN chunk"
    if uri.startswith("data:"):
        try:
            return len(base64.b64decode(uri.partition(",")[2], validate=False)), "its data: URI"
        except ValueError:
            raise InputFileError(f"{name}: buffer {i}'s data: URI is not base64") from None
    file = os.path.join(os.path.dirname(path), urllib.parse.unquote(uri))
    if not os.path.isfile(file):
        raise InputFileError(f"{name}: buffer {i}'s file {uri} is missing (looked for {file})")
    return os.path.getsize(file), uri


def _key(v):
    """``v`` when it can be a key of a table (a number or a string), else
    None (a list or an object where the JSON has a number failed with
    "TypeError: unhashable type: 'list'")."""
    return v if isinstance(v, (int, float, str)) and not isinstance(v, bool) else None


def _number(obj, key, default=0):
    v = obj.get(key, default) if isinstance(obj, dict) else None
    return v if isinstance(v, int) and not isinstance(v, bool) and v >= 0 else None


def _check_buffers(doc, path, name, bin_length):
    """Each buffer holds its ``byteLength``; each view lies in its buffer."""
    buffers = _entries(doc, "buffers", name)
    for i, b in enumerate(buffers):
        held, where = _held(b, i, path, name, bin_length)
        need = _number(b, "byteLength", None)
        if need is not None and held < need:
            raise InputFileError(f"{name}: buffer {i} ({where}) holds {held:,} bytes, the file "
                                 f"says {need:,} (file truncated?)")
    for j, v in enumerate(_entries(doc, "bufferViews", name)):
        k, off, length = _number(v, "buffer", None), _number(v, "byteOffset"), \
            _number(v, "byteLength", None)
        if None in (k, off, length) or k >= len(buffers):
            raise InputFileError(f"{name}: bufferView {j} names no valid buffer, offset or length")
        size = _number(buffers[k], "byteLength", None) or 0
        if off + length > size:
            raise InputFileError(f"{name}: bufferView {j} reaches byte {off + length:,} of buffer "
                                 f"{k}, which holds {size:,}")


def _check_accessors(doc, name):
    """Each accessor's elements lie in its buffer view, apart (a byteStride
    at least their size: 4 bytes for VEC3 floats had overlapping positions
    read, "ok"), and so do its ``sparse`` indices and values (a count past
    their views was Blender's "ValueError: buffer is smaller than requested
    size")."""
    views = _entries(doc, "bufferViews", name)
    for i, a in enumerate(_entries(doc, "accessors", name)):
        width = _COMPONENT_BYTES.get(_key(a.get("componentType")), 0) * \
            _TYPE_COMPONENTS.get(_key(a.get("type")), 0)
        count = _number(a, "count", None)
        if "bufferView" in a:                     # (else all zeros, or sparse only)
            _check_reach(views, a, count, width, f"accessor {i}", name, strided=True)
        sparse = a.get("sparse")
        if sparse is None:
            continue
        n = _number(sparse, "count", None) if isinstance(sparse, dict) else None
        at, values = (sparse.get(k) if isinstance(sparse, dict) else None
                      for k in ("indices", "values"))
        if n is None or not isinstance(at, dict) or not isinstance(values, dict) \
                or _key(at.get("componentType")) not in INDEX_TYPES \
                or (count is not None and n > count):
            raise InputFileError(f"{name}: accessor {i}'s sparse substitution names no valid "
                                 f"count, indices or values")
        _check_reach(views, at, n, _COMPONENT_BYTES[at["componentType"]],
                     f"accessor {i}'s sparse indices", name)
        _check_reach(views, values, n, width, f"accessor {i}'s sparse values", name)


def _check_reach(views, a, count, width, what, name, strided=False):
    """The ``count`` elements of ``width`` bytes that ``a`` (an accessor,
    or its sparse indices or values: tightly packed) reads from its view lie
    inside it, and apart."""
    j, off = _number(a, "bufferView", None), _number(a, "byteOffset")
    if None in (j, off, count) or j >= len(views) or not width:
        raise InputFileError(f"{name}: {what} names no valid bufferView, count or type")
    stride = (_number(views[j], "byteStride") or width) if strided else width
    if stride < width:
        raise InputFileError(f"{name}: bufferView {j} has a byteStride of {stride} bytes, less "
                             f"than the {width} of each element of {what}: they would overlap "
                             f"(glTF needs at least their size)")
    need = off + (stride * (count - 1) + width if count else 0)
    if need > views[j]["byteLength"]:
        raise InputFileError(f"{name}: {what} reads {need:,} bytes of bufferView {j}, which "
                             f"holds {views[j]['byteLength']:,} (a wrong count or offset)")


def _check_nodes(doc, name):
    """The node hierarchy is a forest (no node its own ancestor, none the
    child of two: Blender's importer failed with a RecursionError or an
    AssertionError), and the default scene and the scenes' nodes exist
    (an IndexError)."""
    nodes = _entries(doc, "nodes", name)
    parent = np.full(len(nodes), -1, dtype=np.int64)
    for i, node in enumerate(nodes):
        children = node.get("children", [])
        if not _node_indices(children, len(nodes)):
            raise InputFileError(f"{name}: node {i}'s children are not node indices")
        for c in children:
            if parent[c] >= 0 or c == i:
                raise InputFileError(f"{name}: node {c} is the child of "
                                     f"{'itself' if c == i else 'two nodes'}: a node hierarchy "
                                     f"must be a tree")
            parent[c] = i
    up = parent.copy()                      # each node's ancestor 2^k steps up, k = 0, 1, ...
    for _ in range(len(nodes).bit_length()):
        up = np.where(up >= 0, up[up], -1)
    if (up >= 0).any():                     # (more steps up than there are nodes: a cycle)
        raise InputFileError(f"{name}: node {int(np.flatnonzero(up >= 0)[0])} is its own "
                             f"ancestor: a node hierarchy must be a tree")
    scenes = _entries(doc, "scenes", name)
    if "scene" in doc and not (_number(doc, "scene", None) is not None
                               and doc["scene"] < len(scenes)):
        raise InputFileError(f"{name}: its default scene {doc['scene']!r} is not one of its "
                             f"{len(scenes)} scenes")
    for k, scene in enumerate(scenes):
        if not _node_indices(scene.get("nodes", []), len(nodes)):
            raise InputFileError(f"{name}: scene {k}'s nodes are not node indices")


def _node_indices(value, n):
    """Whether ``value`` is a list of indices of the ``n`` nodes."""
    return isinstance(value, list) and all(
        isinstance(c, int) and not isinstance(c, bool) and 0 <= c < n for c in value)


#: per primitive mode, its name and whether a count of corners makes whole triangles
_MODES = {4: ("TRIANGLES", lambda n: n % 3 == 0), 5: ("TRIANGLE_STRIP", lambda n: n == 0 or n >= 3),
          6: ("TRIANGLE_FAN", lambda n: n == 0 or n >= 3)}


def _check_primitives(doc, name):
    """Each triangle primitive's corners (its indices, else its positions)
    make whole triangles: Blender's importer read 17,411 indices of a
    TRIANGLES primitive (not a multiple of 3) as 5,803 faces, some of them
    polygons, and the file came back "ok"."""
    accessors = _entries(doc, "accessors", name)
    for i, mesh in enumerate(_entries(doc, "meshes", name)):
        for j, prim in enumerate(_entries(mesh, "primitives", name)):
            mode = _key(prim.get("mode", 4))
            attributes = prim.get("attributes")
            which = prim.get("indices", attributes.get("POSITION") if isinstance(attributes, dict)
                             else None)
            if mode not in _MODES or not isinstance(which, int) or isinstance(which, bool) \
                    or not 0 <= which < len(accessors):
                continue
            if "indices" in prim and \
                    _key(accessors[which].get("componentType")) not in INDEX_TYPES:
                raise InputFileError(f"{name}: mesh {i} primitive {j}'s indices are not unsigned "
                                     f"integers (glTF's UNSIGNED_BYTE, SHORT or INT)")
            n = _number(accessors[which], "count", None)
            what, whole = _MODES[mode]
            if n is not None and not whole(n):
                kind = "indices" if "indices" in prim else "vertices (it has no indices)"
                raise InputFileError(f"{name}: mesh {i} primitive {j} is {what} of {n:,} {kind}, "
                                     f"which make no whole triangles (cut short, or a wrong count)")


#: how far a node matrix's rotation part may be from orthogonal and still be a rotation
_SHEAR_TOLERANCE = 1e-4


def _check_node_matrices(doc, name):
    """Each node ``matrix`` is a translation, rotation and scale, as glTF
    requires: Blender's importer splits a matrix into those three and drops
    what else it holds (a shear), so a mesh under a sheared matrix came back
    in another shape, "ok" (a sphere whose matrix had determinant -2.3:
    volume 9.48 for 2.63, vertices up to 1.04 off)."""
    for i, node in enumerate(_entries(doc, "nodes", name)):
        m = node.get("matrix")
        if m is None:
            continue
        try:
            M = np.array(m, dtype=np.float64).reshape(4, 4).T        # (column-major)
        except (TypeError, ValueError):
            raise InputFileError(f"{name}: node {i}'s matrix is not 16 numbers") from None
        A = M[:3, :3]
        lengths = np.linalg.norm(A, axis=0)
        if not np.isfinite(M).all():
            raise InputFileError(f"{name}: node {i}'s matrix holds a number that is not finite")
        if (lengths == 0).any():
            continue                          # (a zero scale: flat, as Blender reads it too)
        R = A / lengths
        cosines = np.abs((R.T @ R)[np.triu_indices(3, 1)])
        if cosines.max() > _SHEAR_TOLERANCE:
            apart = np.degrees(np.arccos(min(cosines.max(), 1.0)))
            raise InputFileError(
                f"{name}: node {i}'s matrix shears: two of its axes are {apart:.1f} degrees apart, "
                f"not 90 (glTF allows translation, rotation and scale only, and Blender's importer "
                f"drops the shear: the mesh would come back in another shape)")


def _expected_faces(doc):
    """Triangles of the meshes the file's scene shows (each node's mesh,
    instances counted each time), as its primitives' counts make them; None
    when the scene is not one read here. Blender's importer drops
    degenerate triangles without a word (a primitive whose indices are all
    0: 160 of 320 triangles came back "ok")."""
    try:
        accessors, meshes, nodes = (doc.get(k, []) for k in ("accessors", "meshes", "nodes"))
        per_mesh = []
        for mesh in meshes:
            n = 0
            for prim in mesh.get("primitives", []):
                mode = _key(prim.get("mode", 4))
                which = prim["indices"] if "indices" in prim else prim["attributes"]["POSITION"]
                count = accessors[which]["count"] if mode in _MODES else 0
                n += count // 3 if mode == 4 else max(count - 2, 0) if mode in _MODES else 0
            per_mesh.append(n)
        roots = doc["scenes"][doc.get("scene", 0)].get("nodes", [])
        total, seen, todo = 0, set(), list(roots)
        while todo:
            k = todo.pop()
            if k in seen:
                continue
            seen.add(k)
            total += per_mesh[nodes[k]["mesh"]] if "mesh" in nodes[k] else 0
            todo.extend(nodes[k].get("children", []))
        return total
    except (KeyError, IndexError, TypeError, AttributeError):
        return None


def check(path):
    """What a glTF or GLB file's own structure says (:class:`FileCheck`);
    raises :class:`InputFileError` naming the file when a buffer holds less
    than its JSON declares or a view or accessor reaches past it."""
    name = os.path.basename(path)
    if path.lower().endswith(".glb"):
        doc, glb_bin = _glb(path, name)
    else:
        with open(path, "rb") as fh:
            doc, glb_bin = _json(fh.read(), name), None
    _check_buffers(doc, path, name, None if glb_bin is None else len(glb_bin))
    _check_accessors(doc, name)
    _check_nodes(doc, name)
    _check_primitives(doc, name)
    _check_node_matrices(doc, name)
    past = indices_past_positions(doc, path, glb_bin)
    if past:
        mesh, prim, index, n = past
        raise InputFileError(f"{name}: mesh {mesh} primitive {prim} has an index {index:,}, past "
                             f"its {n:,} vertices (a damaged file)")
    bad = nonfinite_positions(doc, path, glb_bin)
    if bad:
        mesh, prim, n = bad
        raise InputFileError(f"{name}: mesh {mesh} primitive {prim} has {n:,} "
                             f"{'vertex' if n == 1 else 'vertices'} with a coordinate that is not "
                             f"a finite number (NaN or infinity; Blender's importer would read "
                             f"them as 0)")
    return FileCheck(_expected_faces(doc))
