"""STL files checked before Blender's importer reads them.

Blender's STL importer reads a file as binary only when its size is exactly
``84 + 50 * count`` and as ASCII otherwise, turns NaN coordinates into 0 and
reads an ASCII file cut short up to where it ends, silently. :func:`check`
finds those cases first and names the file:

    binary:  80-byte header | uint32 count | count x (normal, 3 corners: 12 float32, uint16)
    ASCII:   solid NAME / facet normal ... / outer loop / vertex x y z (x3) / endloop /
             endfacet / ... / endsolid NAME

The ASCII scan counts keywords with ``bytes.count`` and reads the corners
with one regular expression: no Python loop over lines.
"""

import codecs
import contextlib
import os
import re
import shutil
import struct
import tempfile

import numpy as np

from .file_check import FileCheck, InputFileError

#: a binary STL file: an 80-byte header and a little-endian uint32 triangle count, then
#: 50 bytes a triangle (normal, three corners: 12 float32, and a uint16)
STL_HEAD, STL_TRIANGLE = 84, 50
#: control bytes that never occur in a text file (tab, newlines and form feed do)
_CONTROL = frozenset(range(32)) - {9, 10, 12, 13}
_VERTEX = re.compile(rb"\bvertex[ \t]+(\S+)[ \t]+(\S+)[ \t]+(\S+)")


def is_ascii(head):
    """Whether the first bytes of a file, ``head``, are text (UTF-8: an ASCII
    STL's ``solid`` name may hold any character, ``solid Kugel_größe``)."""
    if not head or _CONTROL & set(head):
        return False
    try:
        codecs.getincrementaldecoder("utf-8")().decode(head, final=False)
    except UnicodeDecodeError:
        return False
    return True


def triangle_counts(path):
    """``(in_header, by_size)`` triangle counts of a binary STL file, None for
    an ASCII one (a size that is not ``84 + 50 * count``, and text).

    Blender's importer reads a file as binary only when its size is exactly
    ``84 + 50 * count`` and as ASCII otherwise, so a binary file with a wrong
    count came back as "no mesh with faces". Here a count of 0 with a size of
    whole triangles (an exporter that left the field blank) gives the
    triangles the size holds (``in_header`` 0, ``by_size`` k: read a copy
    with k written in, :func:`with_count`); any other disagreement raises
    :class:`InputFileError` naming the file, the header's count and the
    count its size implies."""
    with open(path, "rb") as fh:
        head = fh.read(1024)
        size = os.fstat(fh.fileno()).st_size
    count = struct.unpack("<I", head[80:84])[0] if size >= STL_HEAD else None
    if count is not None and size == STL_HEAD + STL_TRIANGLE * count:
        return count, count                      # binary, as Blender's importer decides
    if is_ascii(head):
        return None
    name = os.path.basename(path)
    if count is None:
        raise InputFileError(f"{name}: {size:,} bytes, neither ASCII STL nor a binary STL file "
                             f"(at least {STL_HEAD} bytes of header and triangle count)")
    by_size, extra = divmod(size - STL_HEAD, STL_TRIANGLE)
    if extra:
        raise InputFileError(
            f"{name}: a binary STL file of {size:,} bytes, which is no whole number of triangles "
            f"({STL_HEAD} bytes of header and count, then {STL_TRIANGLE} a triangle; its header "
            f"says {count:,}): cut short or damaged")
    if count not in (by_size, 0):
        raise InputFileError(
            f"{name}: the header of this binary STL file says {count:,} triangles, but its size "
            f"({size:,} bytes) holds {by_size:,} ({STL_HEAD} bytes of header and count, then "
            f"{STL_TRIANGLE} a triangle): cut short, or a wrong count")
    return count, by_size


@contextlib.contextmanager
def with_count(path):
    """``path``, or when its binary STL header's triangle count is blank
    (:func:`triangle_counts`) a temporary copy of the same name with the
    count its size implies written in (the file itself is never changed)."""
    counts = triangle_counts(path)
    if counts is None or counts[0] == counts[1]:
        yield path
        return
    with tempfile.TemporaryDirectory(prefix="meshadjust-stl-") as folder:
        copy = os.path.join(folder, os.path.basename(path))
        shutil.copyfile(path, copy)
        with open(copy, "r+b") as fh:
            fh.seek(80)
            fh.write(struct.pack("<I", counts[1]))
        yield copy


def _nonfinite_error(path, bad):
    what = "facet" if bad == 1 else "facets"
    return InputFileError(f"{os.path.basename(path)}: {bad:,} {what} with a coordinate that is "
                          f"not a finite number (NaN or infinity; Blender's importer would read "
                          f"them as 0)")


def _check_binary(path, counts):
    rec = np.dtype([("normal", "<f4", 3), ("v", "<f4", (3, 3)), ("attr", "<u2")])
    v = np.fromfile(path, dtype=rec, count=counts[1], offset=STL_HEAD)["v"]
    bad = int((~np.isfinite(v).all(axis=(1, 2))).sum())
    if bad:
        raise _nonfinite_error(path, bad)
    notes = ()
    if counts[0] != counts[1]:
        notes = (f"the binary STL header's triangle count is 0 (left blank by its exporter?): "
                 f"read the {counts[1]:,} triangles its size holds",)
    return FileCheck(counts[1], notes)


def _ascii_body(data):
    """``(body, closed)`` of an ASCII STL file's bytes (lower case): what lies
    between its ``solid`` line and its last ``endsolid`` line (their names
    may hold any word), and whether that ``endsolid`` line ends the file."""
    start = data.find(b"\n") + 1 if b"\n" in data else len(data)
    tail = data.rstrip()
    last = tail.rfind(b"\n") + 1
    closed = last >= start and tail[last:].lstrip().startswith(b"endsolid")
    return data[start:last if closed else len(data)], closed


def _check_ascii(path):
    """An ASCII STL file: cut short inside a facet is an error ("ends inside
    facet 1,203 (file truncated?)"), after a whole facet without its
    ``endsolid`` a warning; a NaN or infinite corner an error."""
    with open(path, "rb") as fh:
        data = fh.read().lower()
    body, closed = _ascii_body(data)
    ends = body.count(b"endfacet")
    starts = body.count(b"facet") - ends
    name = os.path.basename(path)
    if starts > ends:
        raise InputFileError(f"{name}: ends inside facet {ends + 1:,} (file truncated?): an ASCII "
                             f"STL file's facets each end with 'endfacet', the last one does not")
    warnings = () if closed or not starts else (
        f"{name}: ends after facet {ends:,} without 'endsolid' (file truncated?): read the "
        f"{ends:,} whole facets",)
    try:
        V = np.array(_VERTEX.findall(body), dtype=np.float64).reshape(-1, 3)
    except ValueError:
        V = np.zeros((0, 3))                      # a bad number: Blender's importer says so
    finite = np.isfinite(V).all(axis=1)
    if V.shape[0] % 3 == 0 and not finite.all():
        raise _nonfinite_error(path, int((~finite.reshape(-1, 3).all(axis=1)).sum()))
    return FileCheck(ends, (), warnings)


def check(path):
    """What an STL file's own structure says (:class:`FileCheck`); raises
    :class:`InputFileError` for a file Blender would read wrong."""
    counts = triangle_counts(path)
    return _check_binary(path, counts) if counts is not None else _check_ascii(path)
