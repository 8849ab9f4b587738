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

What Blender's importer would misread but the file means plainly is read
through a temporary copy (:func:`for_blender`): a binary file whose count
was left blank (0), or with bytes appended after its triangles, and an
ASCII file written in capitals (``VERTEX``: Blender found no face in it).
"""

import contextlib
import os
import re
import shutil
import struct
import tempfile

import numpy as np

from .ascii_words import BLANK, numbers, word_starts
from .file_check import FileCheck, InputFileError

#: a binary STL file: an 80-byte header and a little-endian uint32 triangle count, then
#: 50 bytes a triangle (normal, three corners: 12 float32, and a uint16)
STL_HEAD, STL_TRIANGLE = 84, 50
#: control bytes that never occur in a text file (tab, newlines and form feed do)
_CONTROL = frozenset(range(32)) - {9, 10, 12, 13}
#: the keywords that open and close a facet and a solid, as whole words
_KEYWORDS = re.compile(rb"(?<!\S)(facet|endfacet|endsolid)(?!\S)")
#: a ``solid`` or ``endsolid`` line's name, left out of the keywords' count (``endsolid scan
#: facet model`` had opened a facet never closed, ``endsolid vertex colours`` held a corner)
_SOLID_NAMES = re.compile(rb"^([ \t]*(?:end)?solid)(?![^ \t\r\n])[^\n]*", re.M)


def is_ascii(head):
    """Whether the first bytes of a file, ``head``, are text: no control
    bytes, in any 8-bit encoding (an ASCII STL's ``solid`` name may hold any
    character: ``solid Kugel_größe`` in UTF-8, or in Latin-1, which Blender
    reads too and which had been taken for a damaged binary file)."""
    return bool(head) and not _CONTROL & set(head)


def triangle_counts(path):
    """``(in_header, to_read)`` triangle counts of a binary STL file, None for
    an ASCII one (a size that is not ``84 + 50 * count``, and text).

    Blender's importer reads a file as binary only when its size is exactly
    ``84 + 50 * count`` and as ASCII otherwise, so a binary file with a wrong
    count came back as "no mesh with faces". Here a count of 0 with a size of
    whole triangles (an exporter that left the field blank) gives the
    triangles the size holds (``in_header`` 0, ``to_read`` k), and a file
    holding its header's triangles and then bytes that are no whole triangle
    (data appended) gives the header's count (the bytes after them are left
    out: :func:`for_blender`); any other disagreement raises
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
    if extra and count and size > STL_HEAD + STL_TRIANGLE * count:
        return count, count                      # its triangles, then bytes that are none
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


def _trailing_bytes(path, counts):
    """Bytes of a binary STL file after the ``counts[1]`` triangles it is read as."""
    return os.path.getsize(path) - STL_HEAD - STL_TRIANGLE * counts[1]


def _ascii_as_meant(path):
    """An ASCII STL file's bytes as Blender's importer should read them, or
    None when it reads the file itself as meant: its ``vertex`` keyword in
    lower case (``VERTEX``: the importer found no corner, and no face) and
    its solids' names without the keywords (``endsolid vertex colours``: it
    read a corner there, one face too many)."""
    with open(path, "rb") as fh:
        data = fh.read()
    clean = _SOLID_NAMES.sub(rb"\1", data.lower())
    same = all(data.count(word) == clean.count(word) for word in (b"vertex", b"facet"))
    return None if same else clean


@contextlib.contextmanager
def for_blender(path):
    """``path``, or a temporary copy of the same name that Blender's importer
    reads as the file means it (the file itself is never changed): a binary
    file with its blank triangle count written in and the bytes after its
    triangles left out (:func:`triangle_counts`); an ASCII file in lower case
    and its solids' names left out (:func:`_ascii_as_meant`)."""
    counts = triangle_counts(path)
    binary_fix = counts is not None and (counts[0] != counts[1] or _trailing_bytes(path, counts))
    text = _ascii_as_meant(path) if counts is None else None
    if not binary_fix and text is None:
        yield path
        return
    with tempfile.TemporaryDirectory(prefix="meshadjust-stl-") as folder:
        copy = os.path.join(folder, os.path.basename(path))
        if binary_fix:
            shutil.copyfile(path, copy)
            with open(copy, "r+b") as fh:
                fh.seek(80)
                fh.write(struct.pack("<I", counts[1]))
                fh.truncate(STL_HEAD + STL_TRIANGLE * counts[1])
        else:
            with open(copy, "wb") as dst:
                dst.write(text)
        yield copy


def _nonfinite_error(path, bad):
    what = "facet" if bad == 1 else "facets"
    return InputFileError(f"{os.path.basename(path)}: {bad:,} {what} with a coordinate that is "
                          f"not a finite number (NaN or infinity, or beyond a float's range; "
                          f"Blender's importer would read them as 0)")


def _check_binary(path, counts):
    rec = np.dtype([("normal", "<f4", 3), ("v", "<f4", (3, 3)), ("attr", "<u2")])
    v = np.fromfile(path, dtype=rec, count=counts[1], offset=STL_HEAD)["v"]
    bad = int((~np.isfinite(v).all(axis=(1, 2))).sum())
    if bad:
        raise _nonfinite_error(path, bad)
    notes, warnings = (), ()
    if counts[0] != counts[1]:
        notes = (f"the binary STL header's triangle count is 0 (left blank by its exporter?): "
                 f"read the {counts[1]:,} triangles its size holds",)
    if trailing := _trailing_bytes(path, counts):
        warnings = (f"{os.path.basename(path)}: {trailing:,} bytes follow the {counts[1]:,} "
                    f"triangles its header declares, no whole triangle (data appended to the "
                    f"file?): read those {counts[1]:,} triangles",)
    return FileCheck(counts[1], notes, warnings)


def _ascii_keywords(data):
    """``(facets opened, facets closed, closed)`` of an ASCII STL file's bytes
    (lower case) after its first (``solid``) line: the ``facet`` and
    ``endfacet`` keywords counted as whole words (a solid's name may hold
    them inside a word: ``solid faceted_body`` in a file of several solids
    was a facet never closed), and whether an ``endsolid`` follows the last
    facet (what follows it, NUL padding or an exporter's junk, is no facet:
    the file was not cut short)."""
    start = data.find(b"\n") + 1 if b"\n" in data else len(data)
    ends = data.count(b"endfacet", start)
    starts = data.count(b"facet", start) - ends
    closed = data.rfind(b"endsolid") > max(data.rfind(b"endfacet"), start - 1)
    if starts == ends and closed:
        return starts, ends, closed          # (byte counts: 20x faster than the words)
    words = _KEYWORDS.findall(data, start)
    closed = bool(words) and words[-1] == b"endsolid"
    return words.count(b"facet"), words.count(b"endfacet"), closed


def _check_ascii(path):
    """An ASCII STL file: cut short inside a facet is an error ("ends inside
    facet 1,203 (file truncated?)"), after a whole facet without its
    ``endsolid`` a warning; a corner that is not three numbers, a facet of
    fewer than 3 corners and a NaN or infinite corner are errors naming the
    line (:func:`_corners`)."""
    with open(path, "rb") as fh:
        data = _SOLID_NAMES.sub(rb"\1", fh.read().lower())
    starts, ends, closed = _ascii_keywords(data)
    name = os.path.basename(path)
    if starts > ends:
        raise InputFileError(f"{name}: ends inside facet {ends + 1:,} (file truncated?): an ASCII "
                             f"STL file's facets each end with 'endfacet', the last one does not")
    warnings = () if closed or not starts else (
        f"{name}: ends after facet {ends:,} without 'endsolid' (file truncated?): read the "
        f"{ends:,} whole facets",)
    V, facet = _corners(path, data)
    with np.errstate(invalid="ignore"):       # (Blender reads float32: 1e39 became 0)
        finite = (np.abs(V) <= np.finfo(np.float32).max).all(axis=1)
    if not finite.all():
        bad = np.sort(facet[~finite])          # (not np.unique: a hash table on NumPy 2.3+)
        raise _nonfinite_error(path, int(np.count_nonzero(np.diff(bad))) + 1)
    return FileCheck(ends, (), warnings)


def _keyword_at(b, word):
    """Byte offsets in ``b`` (uint8) where ``word`` starts as a whole word
    (blanks or the file's ends on both sides)."""
    at = np.flatnonzero(b[:max(b.size - len(word) + 1, 0)] == word[0])
    for k in range(1, len(word)):
        at = at[b[at + k] == word[k]]
    before = (at == 0) | BLANK[b[np.maximum(at - 1, 0)]]
    end = at + len(word)
    after = (end >= b.size) | BLANK[b[np.minimum(end, b.size - 1)]]
    return at[before & after]


def _corners(path, data):
    """``(V, facet)``: the corners of an ASCII STL file's bytes ``data``
    (lower case), (n,3) float64, and the facet (0-based) of each. Raises
    :class:`InputFileError` naming the line of a ``vertex`` not followed by
    three numbers (Blender's importer read '1.0 abc 2.0' and '1.0 2.0' on,
    as 0 or the next line's word: the file came back "ok") and the facet of
    other than 3 corners (fewer: dropped as degenerate, with a warning that
    did not say why; more: read as a face too many, "read 321 faces from the
    file's 320")."""
    b = np.frombuffer(data, dtype=np.uint8)
    first_line = data.find(b"\n") + 1 if b"\n" in data else len(data)
    at = _keyword_at(b, b"vertex")
    at = at[at >= first_line]                      # (the solid's name may hold the word)
    nl = np.append(np.flatnonzero(b == 10), b.size)
    stop = nl[np.searchsorted(nl, at)]              # each vertex line's end
    if at.size == 0:
        return np.zeros((0, 3)), np.zeros(0, dtype=np.int64)
    rest = b"\n".join([data[i:j] for i, j in zip((at + 6).tolist(), stop.tolist())]) + b"\n"
    V = _three_numbers(rest, at.size)
    if V is None:
        _raise_bad_vertex(path, data, at, stop)
    facet = np.searchsorted(_keyword_at(b, b"endfacet"), at)
    corners = np.bincount(facet)
    odd = np.flatnonzero(corners[:facet.max() + 1 if facet.size else 0] != 3)
    if odd.size:
        k = int(odd[0])
        line = data.count(b"\n", 0, int(at[facet == k][0])) + 1 if corners[k] else None
        where = f" (line {line:,})" if line else ""
        raise InputFileError(
            f"{os.path.basename(path)}: facet {k + 1:,}{where} has {corners[k]} "
            f"{'vertex' if corners[k] == 1 else 'vertices'}, not 3: a damaged file (Blender's "
            f"importer would " + ("drop it as a degenerate triangle)" if corners[k] < 3 else
                                  "read it as more than one face)"))
    return V, facet


def _three_numbers(rest, n):
    """(n,3) float64 of ``rest`` (a line of three numbers for each of ``n``
    vertices), or None when a line holds other than three numbers."""
    values = numbers(rest)
    if values is None:
        return None
    r = np.frombuffer(rest, dtype=np.uint8)
    words = np.bincount(np.searchsorted(np.flatnonzero(r == 10), word_starts(r)), minlength=n)
    if values.size != 3 * n or (words != 3).any():
        return None
    return values.reshape(n, 3)


def _raise_bad_vertex(path, data, at, stop):
    """Raise :class:`InputFileError` naming the first ``vertex`` line (at
    byte offsets ``at`` to ``stop``) that is not three numbers."""
    for a, e in zip(at.tolist(), stop.tolist()):
        words = data[a + 6:e].split()
        bad = next((w for w in words[:3] if _three_numbers(w + b" 0 0\n", 1) is None), None)
        if bad is None and len(words) == 3:
            continue
        text = data[a:e].decode("utf-8", "replace").strip()
        text = text if len(text) <= 60 else text[:57] + "..."
        why = (f"holds '{bad.decode('utf-8', 'replace')}', which is not a number" +
               (" (a decimal comma? STL's numbers take a point)" if b"," in bad else "")
               if bad is not None else f"has {len(words)} numbers, not the 3 of a corner")
        line = data.count(b"\n", 0, a) + 1
        raise InputFileError(f"{os.path.basename(path)}: line {line:,}, '{text}', {why} "
                             f"(Blender's importer would misread it)")
    raise InputFileError(f"{os.path.basename(path)}: a 'vertex' line is not three numbers")


def check(path):
    """What an STL file's own structure says (:class:`FileCheck`); raises
    :class:`InputFileError` for a file Blender would read wrong."""
    counts = triangle_counts(path)
    return _check_binary(path, counts) if counts is not None else _check_ascii(path)
