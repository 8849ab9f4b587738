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

import numpy as np

from .file_check import FileCheck, InputFileError
from .ply_ascii import record_problem
from .ply_binary import PLY_TYPES, binary_problem, element_records

#: bytes of a blank line
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
        return None                  # (check names it: Blender's importer could crash on it)
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


def ply_size_problem(path, header=None):
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
    after the last element, nothing but padding (zero bytes, blanks).
    ``header``: the file's :func:`ply_header` when the caller has read it."""
    header = header or ply_header(path)
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
    return binary_problem(path, data, order, length, elements, said)


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
        lines = np.cumsum(rest == 10)[values]                    # (ascending: no np.unique,
        more = int(np.count_nonzero(np.diff(lines))) + 1           # a hash on NumPy 2.3+)
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


def _known_type(t):
    return t in PLY_TYPES or (isinstance(t, tuple) and t[1] in PLY_TYPES and t[2] in PLY_TYPES)


def count_nonfinite(path, header=None):
    """Vertices with a coordinate that is NaN or infinite, or beyond a
    float's range in a ``float`` property (1e39: Blender's importer stores
    those as 0), read from the file itself; None when the layout is not one
    read here (a binary file with list properties on the vertices, x, y or
    z after such a list, a file cut short). The vertex element may come
    after others (a file whose faces come first had its NaN read as 0,
    status ok): ASCII, after their lines; binary, after their bytes
    (:func:`.ply_binary.element_records`). An ASCII vertex with a list (a
    scanner's per-vertex extras) is read up to the list (it had not been
    read at all: its NaN came back "ok"). ``header``: as for
    :func:`ply_size_problem`."""
    header = header or ply_header(path)
    if not header:
        return None
    fmt, length, elements = header
    at = next((k for k, (e, _, _) in enumerate(elements) if e == "vertex"), None)
    if at is None:
        return None
    _, n, props = elements[at]
    names = [p for _, p in props]
    if not {"x", "y", "z"} <= set(names) or len(set(names)) < len(names):
        return None                    # (check names a coordinate declared twice)
    scalars = next((k for k, (t, _) in enumerate(props) if t not in PLY_TYPES), len(props))
    cols = [k for k, (_, name) in enumerate(props) if name in ("x", "y", "z")]
    if max(cols) >= scalars:
        return None
    if fmt == "ascii":
        table = _ascii_columns(path, length, sum(count for _, count, _ in elements[:at]), n,
                               scalars, len(props))
        if table is None:
            return None
        xyz = table[:, cols]
        single = np.array([PLY_TYPES[props[k][0]] == "f4" for k in cols])
        with np.errstate(invalid="ignore"):
            beyond = single & (np.abs(xyz) > np.finfo(np.float32).max)
        return int((~np.isfinite(xyz).all(axis=1) | beyond.any(axis=1)).sum())
    if scalars < len(props):
        return None
    order = {"binary_little_endian": "<", "binary_big_endian": ">"}.get(fmt)
    if order is None:
        return None
    size, pos = os.path.getsize(path), length
    for element, count, before in elements[:at]:
        got, pos, bad = element_records(path, order, before, pos, count, size, n, element)
        if bad or got < count:
            return None         # (ply_size_problem says what is wrong)
    rec = np.dtype([(name, order + PLY_TYPES[t]) for t, name in props])
    if pos + n * rec.itemsize > size:
        return None     # (cut short, or a count of 10^11: 1 TiB allocated); ply_size_problem says
    table = np.fromfile(path, dtype=rec, count=n, offset=pos)
    with np.errstate(invalid="ignore"):          # (NaN in a byte-swapped float32: a warning)
        xyz = np.stack([table[c].astype(np.float64) for c in ("x", "y", "z")], axis=1)
    return int((~np.isfinite(xyz).all(axis=1)).sum())


def _ascii_columns(path, length, skip, n, scalars, width):
    """The first ``scalars`` numbers of each of the ``n`` vertex lines of an
    ASCII PLY file (header ``length`` bytes, ``skip`` lines of other
    elements before them; ``width`` properties, all scalars when ``scalars``
    is ``width``), (n, scalars) float64, or None when they cannot be read."""
    with open(path, "rb") as fh:
        fh.seek(length)
        text = fh.read()
    lines = text.split(b"\n", skip + n)[skip:skip + n]
    try:
        if scalars == width:
            return np.array(b" ".join(lines).split(), dtype=np.float64).reshape(n, width)
        words = rb"^[ \t\r]*" + rb"[ \t]+".join([rb"(\S+)"] * scalars)
        first = re.findall(words, b"\n".join(lines), re.M)     # (a word per scalar, each line)
        return np.array(first, dtype=np.float64).reshape(n, scalars)
    except ValueError:
        return None


def _twice(path, header):
    """A message for a vertex coordinate (x, y or z) the file's
    :func:`ply_header` declares twice (which one Blender's importer takes is
    not said), or None."""
    vertex = next((props for e, _, props in header[2] if e == "vertex"), []) if header else []
    names = [name for _, name in vertex]
    twice = [c for c in ("x", "y", "z") if names.count(c) > 1]
    return (f"{os.path.basename(path)}: its header declares the vertices' property "
            f"'{twice[0]}' {names.count(twice[0])} times: which one is the coordinate is not "
            f"clear (a damaged header)") if twice else None


def check(path):
    """What a PLY file's own structure says (:class:`FileCheck`: the faces
    its header declares); raises :class:`InputFileError` for a file Blender
    would read wrong (:func:`count_nonfinite`, :func:`ply_size_problem`);
    the header read once for them all."""
    header = ply_header(path)
    twice = _twice(path, header)
    if twice:
        raise InputFileError(twice)
    bad = count_nonfinite(path, header)
    if bad:
        raise InputFileError(f"{os.path.basename(path)}: {bad:,} "
                             f"{'vertex' if bad == 1 else 'vertices'} with a coordinate that is "
                             f"not a finite number (NaN or infinity, or beyond a float's range; "
                             f"Blender's importer would read them as 0)")
    problem = ply_size_problem(path, header)
    if problem:
        raise InputFileError(problem)
    if header is None:
        raise InputFileError(_not_ply(path))
    counts = {e: n for e, n, _ in header[2]}
    # (a file's triangle strips are faces too, how many only their records say: with a face
    # element beside them, the faces read had been compared with the face records alone)
    return FileCheck(None if "tristrips" in counts else counts.get("face"))


def _not_ply(path):
    """Why a ``.ply`` file without PLY's first word is none: its first bytes
    said (a file of zero bytes, a copy cut short on a file system that
    reserves its space, crashed Blender's importer: the worker died, SIGABRT,
    and the batch could only say so)."""
    with open(path, "rb") as fh:
        first = fh.read(64)
    name = os.path.basename(path)
    if not first:
        return f"{name}: the file is empty"
    if not first.strip(b"\0"):
        return (f"{name}: not a PLY file: its first bytes are zeros (a copy cut short, or a "
                f"file never written)")
    return f"{name}: not a PLY file: it does not begin with 'ply'"
