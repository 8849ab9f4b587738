"""PLY files checked before Blender's importer reads them.

Blender's PLY importer reads a file whose header's counts disagree with its
data on: it takes the next element's bytes for this one's, reads past the
end keeping what it could, or stops at the declared count and drops what
follows, and it turns NaN coordinates into 0. :func:`check` finds those
cases first and names the file and the counts:

    ply / format ascii|binary_little_endian|binary_big_endian 1.0 /
    element vertex N / property float x ... / element face M /
    property list uchar int vertex_indices / end_header / N records / M records
"""

import os
import re
import struct

import numpy as np

from .file_check import FileCheck, InputFileError
from .ply_ascii import record_problem

PLY_TYPES = {"char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2",
              "int16": "i2", "ushort": "u2", "uint16": "u2", "int": "i4", "int32": "i4",
              "uint": "u4", "uint32": "u4", "float": "f4", "float32": "f4", "double": "f8",
              "float64": "f8"}
#: the struct module's code of each NumPy type a list's count may have
_STRUCT_CODES = {"i1": "b", "u1": "B", "i2": "h", "u2": "H", "i4": "i", "u4": "I", "f4": "f",
                 "f8": "d"}
#: bytes of a blank line (and, after a binary file's data, of padding with 0)
_BLANK = (9, 10, 13, 32)


#: the most bytes read looking for a header's end (a scanner's thousands of comments fit)
_HEADER_LIMIT = 1 << 24
#: the line that ends a header
_END_HEADER = re.compile(rb"(?:\A|\n)(end_header)")
#: the largest element count Blender's importer reads (a C ``int``; beyond, it aborts)
_COUNT_LIMIT = 2**31 - 1


def _header_bytes(path):
    """The first bytes of a PLY file, up to and including its ``end_header``
    line (all of them when there is none within :data:`_HEADER_LIMIT`)."""
    head = b""
    with open(path, "rb") as fh:
        while len(head) < _HEADER_LIMIT:
            more = fh.read(1 << 16)
            head += more
            end = _header_end(head)
            if not more or (end >= 0 and head.find(b"\n", end) >= 0):
                break
    return head


def _header_end(head):
    """Where the ``end_header`` line starts in ``head``, or -1: a line that
    starts with the word, as Blender's importer finds it (a comment saying
    'see end_header below' had ended the header there, and with it every
    check: a file cut short came back with one warning)."""
    m = _END_HEADER.search(head)
    return m.start(1) if m else -1


def ply_header(path):
    """``(format, header length in bytes, [(element, count, [(type, name)])])``
    of a PLY file (a list property's type is ``("list", count type, item
    type)``), or None when it has no PLY header.

    Raises :class:`InputFileError` naming the line for a header Blender's
    importer would crash on or misread: an element line without a count it
    can read (``element vertex``: the importer aborted the process), a
    property before any element (``ELEMENT vertex 3`` then ``property``: it
    read freed memory, and crashed), a property of a type PLY has not, no
    ``end_header`` line (``vertex_indicesend_header``: the importer read the
    data as header lines and crashed, 14 of 500 mutated headers)."""
    head = _header_bytes(path)
    end = _header_end(head)
    if not head.startswith(b"ply"):
        return None                  # (Blender's importer says "Invalid PLY header")
    if end < 0:
        where = (f"in its first {len(head):,} bytes" if len(head) >= _HEADER_LIMIT else
                 "(found glued to the end of another line)" if b"end_header" in head else "")
        raise InputFileError(f"{os.path.basename(path)}: its header has no 'end_header' line"
                             f"{' ' + where if where else ''}: a damaged file (Blender's importer "
                             f"would read its data as header lines, and can crash on them)")
    nl = head.find(b"\n", end)
    length = nl + 1 if nl >= 0 else len(head)
    fmt, elements = None, []
    for k, line in enumerate(head[:end].decode("ascii", "replace").splitlines(), 1):
        parts = line.split()
        if parts[:1] == ["format"] and len(parts) > 1:
            fmt = parts[1]
        elif parts[:1] == ["element"]:
            if len(parts) != 3 or not parts[2].isdigit() or int(parts[2]) > _COUNT_LIMIT:
                raise _header_error(path, k, line, "is not 'element NAME COUNT' with a count of "
                                    f"0 to {_COUNT_LIMIT:,}")
            elements.append((parts[1], int(parts[2]), []))
        elif parts[:1] == ["property"]:
            if not elements:
                raise _header_error(path, k, line, "comes before any 'element' line (Blender's "
                                    "importer would crash on it)")
            kind = tuple(parts[1:4]) if parts[1:2] == ["list"] and len(parts) == 5 else \
                parts[1] if len(parts) == 3 else None
            if kind is None or not _known_type(kind):
                raise _header_error(path, k, line, "is not 'property TYPE NAME' or 'property "
                                    "list COUNT_TYPE ITEM_TYPE NAME' with PLY's types ("
                                    f"{', '.join(sorted(set(PLY_TYPES)))})")
            elements[-1][2].append((kind, parts[-1]))
    return fmt, length, elements


def _header_error(path, lineno, line, problem):
    line = line.strip()
    line = line if len(line) <= 60 else line[:57] + "..."
    return InputFileError(f"{os.path.basename(path)}: header line {lineno}, '{line}', {problem}")


def ply_size_problem(path):
    """Why a PLY file does not hold what its header declares, in words that
    name the file and the counts (a file cut short, a count too large or too
    small), or None.

    Blender's importer reads such a file on: it takes the next element's
    bytes for this one's and fails with "Invalid face size, must be between 1
    and 255", reads past the end and keeps what it could with a warning per
    bad index, or stops at the declared counts and drops the rest silently.
    Checked here, before Blender: ASCII, a line per element, every one
    holding the values its properties give (:mod:`.ply_ascii`: numbers, whole
    ones in lists of integers, a list as long as its count), nothing but blank
    lines after the last; binary, the bytes of each fixed-size element and of
    each element with lists, its records counted at once while they have the
    first one's length (all triangles, all quads) and walked one by one from
    the first of another length, each face 1-255 corners long (Blender's
    importer reads no others, skipping those of 1 or 2), the first record a
    face (a count of 1-255, indices of declared vertices) or a triangle strip
    (indices of declared vertices or -1, which ends a strip);
    after the last element, nothing but padding (zero bytes, blanks)."""
    header = ply_header(path)
    if not header or not header[2]:
        return None
    fmt, length, elements = header
    data = np.memmap(path, dtype=np.uint8, mode="r") if os.path.getsize(path) \
        else np.zeros(0, np.uint8)
    said = (f"{os.path.basename(path)}: its header declares "
            f"{' and '.join(f'{n:,} {e}' for e, n, _ in elements)} elements")
    if fmt == "ascii":
        return _ascii_problem(data, length, elements, said)
    order = {"binary_little_endian": "<", "binary_big_endian": ">"}.get(fmt)
    if order is None or any(not _known_type(t) for _, _, props in elements for t, _ in props):
        return None
    return _binary_problem(path, data, order, length, elements, said)


def _ascii_problem(data, length, elements, said):
    """:func:`ply_size_problem` of an ASCII file (``said``: the message's
    start, naming the file and the declared counts)."""
    body = data[length:]
    ends = np.flatnonzero(body == 10)
    if body.size and body[-1] != 10:
        ends = np.append(ends, body.size)              # a last line without its newline
    need = sum(n for _, n, _ in elements)
    if ends.size < need:
        return (f"{said}, a line each ({need:,}), but the file has {ends.size:,} lines after "
                f"its header: cut short, or a wrong count in the header")
    starts = np.concatenate([[0], ends[:-1] + 1])
    rest = body[starts[need]:] if ends.size > need else body[:0]
    values = np.isin(rest, _BLANK, invert=True)
    header_lines = int(np.count_nonzero(data[:length] == 10))
    blank = _blank_lines(body, starts[:need], ends[:need]) if values.any() else ()
    if len(blank):
        more = f" (and {len(blank) - 1:,} more)" if len(blank) > 1 else ""
        return (f"{said}, a line each, but line {header_lines + blank[0] + 1:,} among them is "
                f"blank{more}: Blender's importer would take it for a record and misread the "
                f"rest; delete the blank lines")
    if values.any():
        more = np.unique(np.cumsum(rest == 10)[values]).size     # lines holding a value
        return (f"{said}, a line each ({need:,}), but {more:,} more lines with values follow "
                f"them: the file holds more than its header declares (a wrong count; Blender's "
                f"importer would drop them or misread them)")
    first = 0
    for element, count, props in elements:
        corners = next((n for t, n in props if isinstance(t, tuple) and element == "face"
                        and n in ("vertex_indices", "vertex_index")), None)
        bad = record_problem(body, starts, ends, first, count, props, corners) if count else None
        if bad:
            line = bytes(body[starts[bad[0]]:ends[bad[0]]]).decode("utf-8", "replace").strip()
            line = line if len(line) <= 60 else line[:57] + "..."
            why = ("" if "a face of" in bad[1] else
                   ": a wrong count in the header, or a damaged file (Blender's importer would "
                   "misread it)" if "values, not the" in bad[1] else
                   ": a damaged file, or one written by a tool that does not follow PLY "
                   "(Blender's importer would misread it)")
            return (f"{said}, but the {element} record on line {header_lines + bad[0] + 1:,} "
                    f"('{line}') {bad[1]}{why}")
        first += count
    return None


def _blank_lines(body, starts, ends):
    """Indices of the lines (``starts``, ``ends``: byte ranges of ``body``)
    that hold nothing but blanks."""
    filled = np.concatenate([[0], np.cumsum(np.isin(body, _BLANK, invert=True))])
    return np.flatnonzero(filled[ends] == filled[starts])


def _binary_problem(path, data, order, length, elements, said):
    """:func:`ply_size_problem` of a binary file."""
    size = data.size
    pos = length
    n_vertices = {e: n for e, n, _ in elements}.get("vertex", 2**63 - 1)
    for element, count, props in elements:
        got, end, bad_first = _records(path, order, props, pos, count, size, n_vertices,
                                       element)
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
    if np.isin(data[pos:], _BLANK + (0,), invert=True).any():
        return (f"{said}, but {size - pos:,} bytes follow them (the file is {size:,} bytes, its "
                f"elements end at byte {pos:,}): the file holds more than its header declares "
                f"(a wrong count, or data appended; Blender's importer would drop them)")
    return None


def _known_type(t):
    return t in PLY_TYPES or (isinstance(t, tuple) and t[1] in PLY_TYPES and t[2] in PLY_TYPES)


def _records(path, order, props, pos, count, size, n_vertices, element):
    """``(whole records in the file, end byte, what is wrong)`` of a binary
    PLY element of ``count`` records at byte ``pos`` (see
    :func:`ply_size_problem`; ``n_vertices``: the vertices declared,
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
    if not _valid_first(element, c0, first, n_vertices):
        many = element == "face" and c0 > 255 and first.size == c0 \
            and _valid_first(element, 3, first, n_vertices)
        return 0, pos, "too many corners" if many else True
    rec = before + itemsize[ct] + c0 * itemsize[it] + after
    fits = min(count, (size - pos) // rec)
    counts = np.frombuffer(data, offset=pos, count=fits, dtype=np.dtype(
        {"names": ["c"], "formats": [order + PLY_TYPES[ct]], "offsets": [before],
         "itemsize": rec}))["c"]
    same = counts == c0
    run = fits if same.all() else int(np.argmin(same))   # records of the first one's length
    if run == count:
        return count, pos + count * rec, False
    return _walk(data, order, props, pos + run * rec, run, count, element)


def _walk(data, order, props, pos, done, count, element):
    """:func:`_records` of the records ``done`` to ``count`` of an element,
    the first at byte ``pos``, read one by one (each list's count read, its
    items skipped): ``(whole records, end byte, what is wrong)``, what is
    wrong ``(record, byte, items)`` of the first face whose corners Blender's
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


def count_nonfinite(path):
    """Vertices with a coordinate that is NaN or infinite, read from the file
    itself (Blender's importer turns those into 0); None when the layout is
    not one read here (list properties on the vertices, a file cut short).
    The vertex element may come after others (a file whose faces come first
    had its NaN read as 0, status ok): ASCII, after their lines; binary,
    after their bytes (:func:`_records`)."""
    header = ply_header(path)
    if not header:
        return None
    fmt, length, elements = header
    at = next((k for k, (e, _, _) in enumerate(elements) if e == "vertex"), None)
    if at is None:
        return None
    _, n, props = elements[at]
    names = [p for _, p in props]
    if any(t not in PLY_TYPES for t, _ in props) or not {"x", "y", "z"} <= set(names) \
            or len(set(names)) < len(names):
        return None
    if fmt == "ascii":
        with open(path, "rb") as fh:
            fh.seek(length)
            text = fh.read()
        skip = sum(count for _, count, _ in elements[:at])   # the lines of the elements before
        try:
            lines = text.split(b"\n", skip + n)[skip:skip + n]
            table = np.array(b" ".join(lines).split(), dtype=np.float64).reshape(n, len(props))
        except ValueError:
            return None
        cols = [k for k, (_, name) in enumerate(props) if name in ("x", "y", "z")]
        return int((~np.isfinite(table[:, cols]).all(axis=1)).sum())
    order = {"binary_little_endian": "<", "binary_big_endian": ">"}.get(fmt)
    if order is None:
        return None
    size, pos = os.path.getsize(path), length
    for element, count, before in elements[:at]:
        got, pos, bad = _records(path, order, before, pos, count, size, n, element)
        if bad or got < count:
            return None         # (ply_size_problem says what is wrong)
    rec = np.dtype([(name, order + PLY_TYPES[t]) for t, name in props])
    if pos + n * rec.itemsize > size:
        return None     # (cut short, or a count of 10^11: 1 TiB allocated); ply_size_problem says
    table = np.fromfile(path, dtype=rec, count=n, offset=pos)
    with np.errstate(invalid="ignore"):          # (NaN in a byte-swapped float32: a warning)
        xyz = np.stack([table[c].astype(np.float64) for c in ("x", "y", "z")], axis=1)
    return int((~np.isfinite(xyz).all(axis=1)).sum())


def check(path):
    """What a PLY file's own structure says (:class:`FileCheck`: the faces
    its header declares); raises :class:`InputFileError` for a file Blender
    would read wrong (:func:`count_nonfinite`, :func:`ply_size_problem`)."""
    bad = count_nonfinite(path)
    if bad:
        raise InputFileError(f"{os.path.basename(path)}: {bad:,} "
                             f"{'vertex' if bad == 1 else 'vertices'} with a coordinate that is "
                             f"not a finite number (NaN or infinity; Blender's importer would "
                             f"read them as 0)")
    problem = ply_size_problem(path)
    if problem:
        raise InputFileError(problem)
    header = ply_header(path)
    return FileCheck({e: n for e, n, _ in header[2]}.get("face") if header else None)
