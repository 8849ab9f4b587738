"""The records of a binary PLY file, walked before Blender's importer reads them.

Blender's PLY importer takes a binary element's records on trust: a count in
the header that is wrong makes it read the next element's bytes for this
one's, or past the end of the file. :func:`binary_problem` checks that the
file holds what its header declares, element after element::

    pos = the header's end
    for each element:
        no list property:  count x the record's size
        one list property: the first record checked (a face of 1-255 corners on
                           declared vertices, a strip of declared vertices and -1);
                           the records of its length counted at once, then from
                           the first of another length walked one by one
        several lists:     walked one by one (each list's count read, its items skipped)
        pos = the element's end (the file ends first: cut short, or a wrong count)
    after the last element: nothing but padding (zero bytes, blanks)

:func:`element_records` is that walk for one element (the NaN check of
:mod:`.ply_file` also finds the vertex element after others with it).
"""

import os
import struct

import numpy as np

#: PLY's property types and the NumPy type of each (a binary record's bytes)
PLY_TYPES = {"char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2",
              "int16": "i2", "ushort": "u2", "uint16": "u2", "int": "i4", "int32": "i4",
              "uint": "u4", "uint32": "u4", "float": "f4", "float32": "f4", "double": "f8",
              "float64": "f8"}
#: the struct module's code of each NumPy type a list's count may have
_STRUCT_CODES = {"i1": "b", "u1": "B", "i2": "h", "u2": "H", "i4": "i", "u4": "I", "f4": "f",
                 "f8": "d"}
#: bytes that may follow a binary file's last element (padding: zeros, blanks)
PADDING = (9, 10, 13, 32, 0)


def binary_problem(path, data, order, length, elements, said):
    """:func:`.ply_file.ply_size_problem` of a binary file (``data``: its
    bytes, ``order``: ``"<"`` or ``">"``, ``length``: its header's,
    ``elements``: as :func:`.ply_file.ply_header` gives them, ``said``: the
    message's start, naming the file and the declared counts)."""
    size = data.size
    pos = length
    n_vertices = {e: n for e, n, _ in elements}.get("vertex", 2**63 - 1)
    for element, count, props in elements:
        got, end, bad_first = element_records(path, order, props, pos, count, size,
                                              n_vertices, element)
        if isinstance(bad_first, tuple):
            k, at, n = bad_first
            if element == "face" and n > 255:
                return (f"{os.path.basename(path)}: its face {k + 1:,} (at byte {at:,}) has "
                        f"{n:,} corners, and Blender's PLY importer reads faces of at most 255: "
                        f"triangulate the file's polygons first (e.g. save it as OBJ), unless "
                        f"the file is damaged there")
            return (f"{said}, but {element} record {k + 1:,} (at byte {at:,}) holds a list of "
                    f"{n:g} items: the file is damaged there, or a count in the header is wrong")
        if bad_first == "too many corners":
            return (f"{os.path.basename(path)}: its first face (at byte {pos:,}) has more than "
                    f"255 corners, and Blender's PLY importer reads faces of at most 255: "
                    f"triangulate the file's polygons first (e.g. save it as OBJ)")
        if bad_first:
            return (f"{said}, but the first {element} record (at byte {pos:,}) holds no valid "
                    f"{element}: the data before it is not the size the header's counts give "
                    f"(a wrong count), or the file is damaged")
        if got < count:
            return (f"{said}, but the file ends ({size:,} bytes) after {got:,} of the {count:,} "
                    f"{element} elements: cut short, or a wrong count in the header")
        pos = end
    if np.isin(data[pos:], PADDING, invert=True).any():
        return (f"{said}, but {size - pos:,} bytes follow them (the file is {size:,} bytes, its "
                f"elements end at byte {pos:,}): the file holds more than its header declares "
                f"(a wrong count, or data appended; Blender's importer would drop them)")
    return None


def element_records(path, order, props, pos, count, size, n_vertices, element):
    """``(whole records in the file, end byte, what is wrong)`` of a binary
    PLY element of ``count`` records at byte ``pos`` (see
    :func:`.ply_file.ply_size_problem`; ``n_vertices``: the vertices declared,
    bounding a face's indices; ``element``: its name, whose first record
    :func:`_valid_first` checks). What is wrong: False, True (the first
    record is none), ``"too many corners"`` (the first face has more than
    255) or, from :func:`_walk`, ``(record, byte, items)`` of a later record
    whose list no reader takes. Records of the first one's length are
    counted at once; from the first of another length on they are walked
    one by one (mixed lengths had been taken on trust: a file of quads and
    triangles cut 5 bytes short, or with bytes after it, came back "ok",
    its last face read from past the end)."""
    itemsize = {t: np.dtype(PLY_TYPES[t]).itemsize for t in PLY_TYPES}
    lists = [k for k, (t, _) in enumerate(props) if isinstance(t, tuple)]
    if not lists:
        rec = sum(itemsize[t] for t, _ in props)
        return (min(count, (size - pos) // rec) if rec else count), pos + count * rec, False
    if count == 0:
        return 0, pos, False
    data = np.memmap(path, dtype=np.uint8, mode="r")
    if len(lists) > 1:
        return _walk(data, order, props, pos, 0, count, element)
    k = lists[0]
    before = sum(itemsize[t] for t, _ in props[:k])
    after = sum(itemsize[t] for t, _ in props[k + 1:])
    _, ct, it = props[k][0]
    at = pos + before + itemsize[ct]                    # the first record's indices
    if at > size:
        return 0, pos, False
    c0 = int(np.frombuffer(data, dtype=order + PLY_TYPES[ct], count=1, offset=at - itemsize[ct])[0])
    first = np.frombuffer(data, dtype=order + PLY_TYPES[it], offset=at,
                          count=max(0, min(c0, (size - at) // itemsize[it])))
    rec = before + itemsize[ct] + c0 * itemsize[it] + after
    fits = min(count, (size - pos) // rec) if rec > 0 else 0
    counts = np.frombuffer(data, offset=pos, count=fits, dtype=np.dtype(
        {"names": ["c"], "formats": [order + PLY_TYPES[ct]], "offsets": [before],
         "itemsize": rec}))["c"] if fits else np.zeros(0, dtype=np.int64)
    same = counts == c0
    if not _valid_first(element, c0, first, n_vertices):
        many = element == "face" and c0 > 255 and first.size == c0 \
            and _valid_first(element, 3, first, n_vertices)
        # (records all of its length, ending where the file's data ends: the layout holds and
        # the first face has only a bad index, which Blender drops with a warning, as a later
        # one; it had been read as a wrong count)
        whole = 1 <= c0 <= (255 if element == "face" else c0) and fits == count \
            and same.all() and not np.isin(data[pos + count * rec:], PADDING, invert=True).any()
        if not whole:
            return 0, pos, "too many corners" if many else True
    run = fits if same.all() else int(np.argmin(same))   # records of the first one's length
    if run == count:
        return count, pos + count * rec, False
    return _walk(data, order, props, pos + run * rec, run, count, element)


def _walk(data, order, props, pos, done, count, element):
    """:func:`element_records` of the records ``done`` to ``count`` of an
    element, the first at byte ``pos``, read one by one (each list's count
    read, its items skipped): ``(whole records, end byte, what is wrong)``,
    what is wrong ``(record, byte, items)`` of the first face whose corners Blender's
    importer refuses (fewer than 1 or more than 255) or list whose count is
    negative, else False."""
    plan, fixed = [], 0          # (bytes before, count reader, item bytes, corners?) per list
    for t, name in props:
        if isinstance(t, tuple):
            reader = struct.Struct(order + _STRUCT_CODES[PLY_TYPES[t[1]]])
            corners = element == "face" and name in ("vertex_indices", "vertex_index")
            plan.append((fixed, reader, np.dtype(PLY_TYPES[t[2]]).itemsize, corners))
            fixed = 0
        else:
            fixed += np.dtype(PLY_TYPES[t]).itemsize
    size, buf = data.size, memoryview(data)
    for k in range(done, count):
        start = pos
        for skip, reader, item, corners in plan:
            pos += skip
            if pos + reader.size > size:
                return k, size, False
            n = reader.unpack_from(buf, pos)[0]
            if n < 0 or n != int(n) or (corners and not 1 <= n <= 255):
                return k, start, (k, start, n)
            pos += reader.size + int(n) * item
        pos += fixed
        if pos > size:
            return k, size, False
    return count, pos, False


def _valid_first(element, count, items, n_vertices):
    """Whether the first record of a list ``element`` (its ``count`` and
    ``items`` read) can be one: a face of 1-255 corners (Blender's importer
    reads no more) on declared vertices, a triangle strip of declared
    vertices and -1 (the end of a strip: a file's whole strip set is often
    one record of thousands), anything for another element (its items'
    meaning unknown)."""
    if element == "face":
        return 1 <= count <= 255 and not (items.size and (items.min() < 0 or
                                                          items.max() >= n_vertices))
    if element == "tristrips":
        return count >= 1 and not (items.size and (items.min() < -1 or
                                                   items.max() >= n_vertices))
    return count >= 0
