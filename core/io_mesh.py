"""Mesh files without Blender: Wavefront OBJ and SMF (positions and faces).

SMF is the format of Garland and Heckbert's QSlim ("Simple Model Format"),
the seed format of quadric simplification; OBJ is its common superset::

    # a comment                       both formats
    v 0.5 -1.25 3                     a vertex: x y z (OBJ may add w or r g b)
    f 1 2 3                           a face: 1-based vertex indices
    f 1/1/1 2/2/2 3/3/3 4/4/4         OBJ: v/vt/vn, negative = relative
                                      (a polygon is fan-triangulated,
                                       v0 v1 v2, v0 v2 v3, ..., unless
                                       the fan folds: then ear-clipped,
                                       see :mod:`.triangulate`)

A line ending with a backslash continues on the next (``f 1 2 \\`` then
``3 4``), and a ``#`` after the numbers of a ``v`` or ``f`` line starts a
comment (``f 1 2 3 # a tri``), as the OBJ specification and Blender's
importer have them.

Every other keyword (SMF ``c``, ``n``, ``r``, ``t``, ``bind``, ``begin``,
``end``, ``set``...; OBJ ``vt``, ``vn``, ``o``, ``g``, ``usemtl``, ``l``...)
is counted and skipped: :func:`read_mesh` says how many of each. A line
that starts with no keyword (an ASCII letter, then letters, digits or ``_``,
16 at most: binary garbage, NUL bytes, a line cut short to ``1 2 3``) is
skipped as unreadable: :func:`read_mesh` says how many and where the first is.

Reading checks what a geometry core needs and names the line that breaks it
(``read_smf: scan.smf line 12: 'v 1 x 3' is not a number``): a coordinate that
is not a finite number, a face with fewer than 3 vertices or an index outside
the file's vertices. Writing is exact: floats are written with ``repr``, the
shortest text that reads back to the same float64, so ``write`` then ``read``
returns bit-identical arrays.

A file is read in bulk: its lines classified and its numbers converted at
once (a 1.1M-face OBJ in about half a second); only a file with something
unusual or wrong is read again line by line, which names the line.
"""

import os
import re
import string
import warnings
from collections import Counter
from typing import NamedTuple

import numpy as np

from ._groups import member_of
from .errors import InvalidArgumentError, InvalidMeshError
from .mesh import check_mesh
from .pages import plain_pages
from .triangulate import triangulate_polygons

#: the extensions :func:`read_mesh` and :func:`write_mesh` understand
MESH_EXTENSIONS = (".obj", ".smf")


class MeshFile(NamedTuple):
    """What :func:`read_mesh` read.

    Attributes
    ----------
    V : (n,3) float64, vertex positions.
    F : (m,3) int64, triangles, 0-based, in the file's order; a polygon of k
        vertices gives k-2 (a fan from its first vertex, ear-clipped where
        the fan folds: :func:`.triangulate.triangulate_polygons`).
    n_polygons : int, faces in the file (before triangulation).
    skipped : dict str -> int, lines of each other keyword, skipped.
    n_unreadable : int, lines starting with no keyword, skipped.
    first_unreadable : int, the first of them (1-based line number; 0: none).
    """

    V: np.ndarray
    F: np.ndarray
    n_polygons: int
    skipped: dict
    n_unreadable: int = 0
    first_unreadable: int = 0


def _line_text(path, lineno):
    """Line ``lineno`` (1-based) of ``path``, stripped and shortened."""
    with open(path, "r", encoding="utf-8", errors="replace") as fh:
        for k, line in enumerate(fh, 1):
            if k == lineno:
                text = line.strip()
                return text if len(text) <= 80 else text[:77] + "..."
    return ""


def _line_error(fn, path, lineno, problem):
    return InvalidMeshError(f"{fn}: {path} line {lineno}: '{_line_text(path, lineno)}' {problem}")


def _parsed(fn, path, rows, lines, dtype, problem, too_large=None):
    """The strings ``rows`` as one ``dtype`` array; the first line whose
    strings do not parse is named with ``problem``, or ``too_large`` when a
    number does not fit ``dtype`` (an integer beyond 64 bits). Digits are
    ASCII ones: Python's numbers take any script's (``v ١ ٢ ٣`` had read as
    1, 2, 3)."""
    if not "".join(map("".join, rows)).isascii():
        for row, lineno in zip(rows, lines):
            if not "".join(row).isascii():
                raise _line_error(fn, path, lineno, problem)
    try:
        return np.array(rows, dtype=dtype)
    except (ValueError, OverflowError):
        for row, lineno in zip(rows, lines):
            try:
                np.array(row, dtype=dtype)
            except ValueError:
                raise _line_error(fn, path, lineno, problem) from None
            except OverflowError:
                raise _line_error(fn, path, lineno, too_large or problem) from None
        raise


def _missing_vertex(n):
    """The problem of a face line indexing past the file's ``n`` vertices."""
    return f"refers to a missing vertex (the file has {n:,})"


def _vertices(fn, path, rows, lines):
    """(n,3) float64 from the coordinate strings of the ``v`` lines."""
    if not rows:
        return np.zeros((0, 3), dtype=np.float64)
    return _parsed(fn, path, rows, lines, np.float64, "is not a number")


def _check_finite(fn, path, V, lines, F):
    """Raise when a ``v`` line (``lines``: their numbers) has a coordinate
    that is not a finite number, naming the first one a face (``F``, 0-based)
    uses, else the first, and saying how many there are and whether faces
    use them (a scan's leftover points are used by none)."""
    if np.isfinite(V).all():              # (15x faster than the test along rows)
        return
    bad = np.flatnonzero(~np.isfinite(V).all(axis=1))
    used = member_of(bad, F)
    k = bad[np.argmax(used)] if used.any() else bad[0]
    some = f"one of {bad.size:,} such vertices, " if bad.size > 1 else ""
    if not used.any():
        how = (f" ({some}none used by a face: a scan's leftover points; delete the vertices "
               f"no face uses)")
    else:
        how = f" ({some}{used.sum():,} used by faces)" if some else ""
    raise _line_error(fn, path, lines[k], f"has a coordinate that is not a finite number{how}")


def _read(path, fn, obj):
    """Parse an OBJ (``obj=True``) or SMF file into a :class:`MeshFile`:
    :func:`_read_bulk`, or line by line (:func:`_read_lines`) when that finds
    anything it does not read the same way (the line reader then names the
    line)."""
    with open(path, "rb") as fh:
        data = fh.read()
    bulk = _read_bulk(data, obj)
    return bulk if bulk is not None else _read_lines(path, fn, obj)


#: bytes that separate the words of a line (str.split's ASCII whitespace)
_SPACES = np.array([9, 10, 11, 12, 13, 28, 29, 30, 31, 32], dtype=np.uint8)
#: per byte value, whether it separates words (a table: twice as fast as np.isin)
_IS_SPACE = np.zeros(256, dtype=bool)
_IS_SPACE[_SPACES] = True
#: the longest keyword (a longer first word makes an unreadable line)
_KEY_BYTES = 16
#: a keyword, as the line reader checks a line's first word
_KEYWORD = re.compile(rf"[A-Za-z][A-Za-z0-9_]{{0,{_KEY_BYTES - 1}}}")
#: per byte value, whether it may start a keyword / continue one
_KEY_FIRST = np.zeros(256, dtype=bool)
_KEY_FIRST[list(string.ascii_letters.encode())] = True
_KEY_NEXT = _KEY_FIRST.copy()
_KEY_NEXT[list((string.digits + "_").encode())] = True
#: lines whose first words :func:`_keywords` reads at once (its memory: ~300 bytes a line)
_KEY_BLOCK = 1 << 16


class _Skipped(NamedTuple):
    """The lines of a file that are neither ``v``, ``f``, comments nor blank."""

    keys: dict              #: keyword -> lines
    n_unreadable: int       #: lines starting with no keyword
    first_unreadable: int   #: the first of them (1-based; 0: none)


class _Lines(NamedTuple):
    """The lines of a file's bytes: where each starts and ends (its newline
    excluded) and whether each byte separates words."""

    b: np.ndarray        #: (size,) uint8, the bytes
    space: np.ndarray    #: (size,) bool
    starts: np.ndarray   #: (k,) int64
    ends: np.ndarray     #: (k,) int64

    @classmethod
    def of(cls, b):
        nl = np.flatnonzero(b == 10)
        starts = np.concatenate([[0], nl + 1])
        ends = np.concatenate([nl, [b.size]])
        if starts[-1] == b.size:                  # (after the last newline: no line)
            starts, ends = starts[:-1], ends[:-1]
        return cls(b, _IS_SPACE[b], starts, ends)

    def words(self):
        """(k,) the number of words on each line (each word's first byte
        found, then its line: np.add.reduceat over the bytes is 5x slower)."""
        first = ~self.space
        first[1:] &= self.space[:-1]
        line = np.searchsorted(self.ends, np.flatnonzero(first), side="right")
        return np.bincount(line, minlength=self.starts.size)[:self.starts.size]

    def second(self):
        """(k,) the second byte of each line (a newline for a line of one byte)."""
        at = np.minimum(self.starts + 1, self.b.size - 1)
        return np.where(self.starts + 1 < self.ends, self.b[at], 10)


def _body(lines, which):
    """The bytes of the lines ``which`` (a mask), each without its first
    byte (its keyword) and ending with a newline, and each line's word count."""
    b = lines.b
    take = np.repeat(which, lines.ends - lines.starts + 1)[:b.size]
    take[lines.starts[which]] = False
    body = b[take].tobytes()
    if not body.endswith(b"\n"):
        body += b"\n"
    return body


def _numbers(body, dtype, n_lines):
    """The numbers of ``body`` (whitespace separated) and the count on each
    of its ``n_lines`` lines; None when a word is not a number of ``dtype``
    (or a line lost its newline: a last line of just its keyword)."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")              # (NumPy 1.x: a warning, 2.x: an error)
        try:
            values = np.fromstring(body, dtype=dtype, sep=" ")
        except (ValueError, DeprecationWarning):
            return None
    lines = _Lines.of(np.frombuffer(body, dtype=np.uint8))
    words = lines.words()
    return (values, words) if values.size == words.sum() and words.size == n_lines else None


def _keywords(lines, other):
    """The :class:`_Skipped` of the lines ``other`` (a mask), read a block of
    ``_KEY_BLOCK`` lines at a time (a bounded memory); None when a first
    word has a byte outside ASCII before it is known to be no keyword (the
    line reader's text may split it there: a no-break space)."""
    rows = np.flatnonzero(other)
    words, bad = Counter(), []
    for s in range(0, rows.size, _KEY_BLOCK):
        got = _key_block(lines, rows[s:s + _KEY_BLOCK])
        if got is None:
            return None
        keys, counts = np.unique(got[0], return_counts=True)
        words.update(dict(zip(keys.tolist(), counts.tolist())))
        bad.append(got[1])
    bad = np.concatenate(bad) if bad else rows
    keys = {k.decode("ascii"): n for k, n in sorted(words.items())}      # (in keyword order)
    return _Skipped(keys, bad.size, int(bad[0]) + 1 if bad.size else 0)


def _key_block(lines, rows):
    """``(keywords, unreadable)`` of the lines ``rows`` (indices): the
    keywords of those starting with one (``S16``, one per line) and the
    indices of the others; None (see :func:`_keywords`).

    Each line's first ``_KEY_BYTES + 1`` bytes are read as a row (spaces
    past its end): a keyword's bytes, then a separator."""
    w = _KEY_BYTES + 1
    at = lines.starts[rows][:, None] + np.arange(w)
    inside = at < lines.ends[rows][:, None]
    window = np.where(inside, lines.b[np.minimum(at, lines.b.size - 1)], 32)
    ok = np.concatenate([_KEY_FIRST[window[:, :1]], _KEY_NEXT[window[:, 1:]]], axis=1)
    length = np.where(ok.all(axis=1), w, np.argmin(ok, axis=1))    # (w: no separator)
    stop = window[np.arange(rows.size), np.minimum(length, w - 1)]
    if ((stop >= 0x80) & (length < w)).any():
        return None
    key = (length > 0) & (length < w) & _IS_SPACE[stop]
    window[np.arange(w) >= length[:, None]] = 0
    return np.ascontiguousarray(window[key, :_KEY_BYTES]).view(f"S{_KEY_BYTES}").ravel(), rows[~key]


def _read_bulk(data, obj):
    """The :class:`MeshFile` of a file's bytes ``data`` read in bulk (every
    line classified and every number converted at once, no loop over lines:
    a 1.1M-face OBJ in well under a second instead of 4 s), or None when the
    file has anything the line reader would read otherwise or refuse: a
    line starting with a space, a ``v`` or ``f`` line with too few words or
    a word that is not a number, an ``_``, a 0 or out-of-range index, a
    coordinate that is not finite, a NUL in a ``v`` or ``f`` line, a byte
    outside ASCII in a first word that may yet be a keyword, no ``v`` or
    ``f`` line, a line continued with a backslash, a comment after a ``v``
    or ``f`` line's numbers."""
    if data.startswith(b"\xef\xbb\xbf"):
        data = data[3:]
    if data.count(b"\r") != data.count(b"\r\n"):
        return None        # (a lone CR ends a line in text mode)
    if b"\\\n" in data or b"\\\r\n" in data:
        return None        # (a line continued on the next: the line reader joins them)
    lines = _Lines.of(np.frombuffer(data, dtype=np.uint8))
    if lines.starts.size == 0:
        return None
    empty = lines.starts == lines.ends
    first = np.where(empty, 10, lines.b[np.minimum(lines.starts, lines.b.size - 1)])
    keyword_ends = _IS_SPACE[lines.second()]
    is_v = (first == ord("v")) & keyword_ends
    is_f = (first == ord("f")) & keyword_ends
    lead = _IS_SPACE[first] & ~empty
    if lead.any() and (lines.words()[lead] > 0).any():
        return None                                 # (a line starting with a space)
    other = ~(is_v | is_f | empty | lead | (first == ord("#")))
    skipped = _keywords(lines, other)
    if skipped is None or not is_v.any():
        return None
    vb = _body(lines, is_v)
    if b"_" in vb or b"\x00" in vb or b"#" in vb or not vb.isascii():
        return None        # (text mode splits words at Unicode spaces too)
    got = _numbers(vb, np.float64, int(np.count_nonzero(is_v)))
    if got is None or (got[1] < 3).any():
        return None
    values, words = got
    V = values[(np.cumsum(words) - words)[:, None] + np.arange(3)]
    if not np.isfinite(V).all():
        return None
    if not is_f.any():
        return MeshFile(V, np.zeros((0, 3), dtype=np.int64), 0, *skipped)
    F = _faces(lines, is_v, is_f, obj, V)
    return None if F is None else MeshFile(V, F, int(np.count_nonzero(is_f)), *skipped)


def _faces(lines, is_v, is_f, obj, V):
    """(m,3) int64 0-based triangles of the ``f`` lines over the vertices
    ``V`` (polygons triangulated by :func:`triangulate_polygons`, in the file's
    order; OBJ: ``v/vt/vn`` read as ``v``, negative indices relative to the
    vertices before the line), or None (see :func:`_read_bulk`)."""
    n = V.shape[0]
    fb = _body(lines, is_f)
    if b"_" in fb or b"\x00" in fb or b"#" in fb or (not obj and b"/" in fb) or not fb.isascii():
        return None        # (text mode splits words at Unicode spaces too)
    if obj and b"/" in fb:
        fb = _cut_slashes(fb)
        if fb is None:
            return None
    got = _numbers(fb, np.int64, int(np.count_nonzero(is_f)))
    if got is None or (got[1] < 3).any():
        return None
    values, words = got
    tris = words - 2
    line = np.repeat(np.arange(words.size), tris)
    j = np.arange(line.size) - np.repeat(np.cumsum(tris) - tris, tris)
    start = (np.cumsum(words) - words)[line]
    R = values[np.stack([start, start + j + 1, start + j + 2], axis=1)]
    if obj:
        base = (np.cumsum(is_v) - is_v)[is_f][line]
        F = np.where(R > 0, R - 1, base[:, None] + R)
    else:
        F = R - 1
    if (R == 0).any() or (F < 0).any() or (F >= n).any():
        return None
    return triangulate_polygons(V, F, words)


def _cut_slashes(fb):
    """The ``f`` lines' body ``fb`` (ASCII bytes) with each word cut at its
    first ``/`` (``v/vt/vn`` read as ``v``), or None when a word starts with
    ``/`` (no vertex index: the line reader names the line) or a control byte
    that separates no words (0x00-0x08, 0x0e-0x1b) stands where a word may end.

    Vectorised over the bytes (a regex pass took 2-4 s on a 2M-face file): the
    "events" are the separators and slashes; the bytes from a slash up to the
    next event are cut, the rest kept::

        b" 12/5/7 3//9 4"  ->  b" 12 3 4"
    """
    z = np.frombuffer(fb, dtype=np.uint8)
    E = np.flatnonzero((z <= 32) | (z == 47))        # (separators, slashes, other controls)
    at = z[E]
    slash = at == 47
    if not (_IS_SPACE[at] | slash).all():
        return None
    after_space = np.concatenate([[E[0] == 0], ~slash[:-1] & (np.diff(E) == 1)])
    if (slash & after_space).any():
        return None
    keep = np.repeat(~slash, np.diff(E, append=z.size))   # (each event's byte to the next)
    return fb[:E[0]] + z[E[0]:][keep].tobytes()


def _read_lines(path, fn, obj):
    """Parse an OBJ (``obj=True``) or SMF file line by line (naming the
    first line it cannot read)."""
    lines = _split_lines(path, fn, obj)
    n_other = sum(lines.skipped.values()) + len(lines.unreadable)
    if not lines.v_lines and not lines.tri_lines and not lines.poly and n_other:
        raise InvalidMeshError(
            f"{fn}: {path} has no 'v' or 'f' line ({n_other:,} other "
            f"lines): not {'an OBJ' if obj else 'an SMF'} file, or an empty one")
    V = _vertices(fn, path, lines.v_rows, lines.v_lines)
    F, sizes = _line_faces(fn, path, lines, V.shape[0], obj)
    _check_finite(fn, path, V, lines.v_lines, F)
    F = triangulate_polygons(V, F, sizes)
    return MeshFile(V, F, len(lines.tri_lines) + len(lines.poly), lines.skipped,
                    len(lines.unreadable), lines.unreadable[0] if lines.unreadable else 0)


class _SplitLines(NamedTuple):
    """A file's lines as :func:`_split_lines` sorts them (strings, not yet numbers)."""

    v_rows: list       #: per ``v`` line, its 3 coordinate strings
    v_lines: list      #: their line numbers
    tri_rows: list     #: per triangle line, its 3 index strings (``v/vt/vn`` cut to ``v``)
    tri_lines: list    #: their line numbers
    tri_base: list     #: the vertices read before each
    poly: list         #: per polygon line: (line number, index strings, vertices before)
    skipped: dict      #: other keyword -> lines
    unreadable: list   #: the numbers of the lines starting with no keyword


def _joined_lines(fh):
    """``(line number, text)`` of each line of the text file ``fh``, a line
    ending with a backslash joined with the next (OBJ's line continuation,
    as Blender's importer reads it: ``f 1 2 \\`` then ``3 4``); a joined line
    has the number of its first line."""
    held, first = "", 0
    for lineno, line in enumerate(fh, 1):
        text = line.rstrip("\r\n")
        if text.endswith("\\"):
            held, first = held + text[:-1] + " ", first or lineno
            continue
        yield (first or lineno), held + line
        held, first = "", 0
    if first:
        yield first, held


def _split_lines(path, fn, obj):
    """The :class:`_SplitLines` of the file (raises at a ``v`` or ``f`` line
    with too few words or an ``_``). A ``#`` ends a ``v`` or ``f`` line (a
    comment after the numbers: ``f 1 2 3 # a tri``)."""
    out = _SplitLines([], [], [], [], [], [], {}, [])
    with open(path, "r", encoding="utf-8-sig", errors="replace") as fh:
        for lineno, line in _joined_lines(fh):
            parts = line.split()
            if not parts:
                continue
            key = parts[0]
            if key in ("v", "f"):
                line = line.partition("#")[0]
                parts = line.split()
            if key in ("v", "f") and "_" in line:      # (Python's int() and float() read 1_0 as 10)
                raise _line_error(fn, path, lineno, "is not a number" if key == "v" else
                                  "has an index that is not an integer")
            if key == "v":
                if len(parts) < 4:
                    raise _line_error(fn, path, lineno, "needs 3 coordinates")
                out.v_rows.append(parts[1:4])
                out.v_lines.append(lineno)
            elif key == "f":
                idx = [t.partition("/")[0] for t in parts[1:]] if obj else parts[1:]
                if len(idx) < 3:
                    raise _line_error(fn, path, lineno, "needs at least 3 vertices")
                if len(idx) == 3:
                    out.tri_rows.append(idx)
                    out.tri_lines.append(lineno)
                    out.tri_base.append(len(out.v_rows))
                else:
                    out.poly.append((lineno, idx, len(out.v_rows)))
            elif _KEYWORD.fullmatch(key):
                out.skipped[key] = out.skipped.get(key, 0) + 1
            elif not key.startswith("#"):
                out.unreadable.append(lineno)
    return out


def _line_faces(fn, path, lines, n, obj):
    """``(F, sizes)``: (m,3) int64 0-based triangles of the :class:`_SplitLines`
    ``lines`` over ``n`` vertices (polygons fan-triangulated after the
    triangles, then sorted back by line so the faces keep the file's order;
    OBJ's negative indices resolved) and the number of vertices of each face
    line, in order. Raises at the first line with a bad index."""
    rows, at, base = list(lines.tri_rows), list(lines.tri_lines), list(lines.tri_base)
    for lineno, idx, before in lines.poly:
        for k in range(1, len(idx) - 1):
            rows.append([idx[0], idx[k], idx[k + 1]])
            at.append(lineno)
            base.append(before)
    if not rows:
        return np.zeros((0, 3), dtype=np.int64), np.zeros(0, dtype=np.int64)
    R = _parsed(fn, path, rows, at, np.int64,    # the file's indices
                "has an index that is not an integer", _missing_vertex(n))
    at, base = np.array(at, dtype=np.int64), np.array(base, dtype=np.int64)
    if lines.poly:
        order = np.argsort(at, kind="stable")
        R, at, base = R[order], at[order], base[order]
    # OBJ's negative indices: relative to the vertices read before the line
    F = np.where(R > 0, R - 1, base[:, None] + R) if obj else R - 1
    bad = np.flatnonzero((R == 0).any(axis=1) | (F < 0).any(axis=1) | (F >= n).any(axis=1))
    if bad.size:
        k = bad[0]
        problem = ("has vertex index 0 (indices are 1-based)" if (R[k] == 0).any() else
                   _missing_vertex(n))
        raise _line_error(fn, path, int(at[k]), problem)
    return F, np.unique(at, return_counts=True)[1] + 2


def read_smf(path):
    """Read an SMF file.

    Parameters
    ----------
    path : str or os.PathLike

    Returns
    -------
    V : (n,3) float64
    F : (m,3) int64, 0-based; polygons triangulated (see :class:`MeshFile`).

    Raises
    ------
    InvalidMeshError
        A bad line, named with its number: a coordinate that is not a finite
        number, fewer than 3 coordinates or vertices, an index outside the
        file's vertices.
    InvalidArgumentError
        ``path`` is not a file name (:func:`file_name`).
    OSError
        The file cannot be read (Python's own: ``FileNotFoundError``, ...).

    Examples
    --------
    >>> core.write_smf("tet.smf", V, F)
    >>> V2, F2 = core.read_smf("tet.smf")     # V2 == V bit for bit
    """
    m = _read(file_name(path, "read_smf"), "read_smf", obj=False)
    return m.V, m.F


def read_obj(path):
    """Read a Wavefront OBJ file (positions and faces only).

    Texture and normal indices (``v/vt/vn``) are ignored, negative (relative)
    indices resolved, polygons triangulated (see :class:`MeshFile`).

    Returns
    -------
    V : (n,3) float64
    F : (m,3) int64, 0-based.

    Raises
    ------
    InvalidMeshError
        A bad line, named with its number (see :func:`read_smf`).
    """
    m = _read(file_name(path, "read_obj"), "read_obj", obj=True)
    return m.V, m.F


def file_name(path, fn):
    """``path`` (a str, bytes or os.PathLike) as a str, or
    :class:`InvalidArgumentError` naming ``fn`` (None or a number had been
    Python's TypeError). A file that cannot be opened stays Python's own
    ``OSError`` (``FileNotFoundError``, ``IsADirectoryError``, ...), which
    names it."""
    try:
        return os.fsdecode(path)
    except TypeError:
        raise InvalidArgumentError(f"{fn}: path must be a file name (str or os.PathLike), got "
                                   f"{type(path).__name__}") from None


def _extension(fn, path):
    ext = os.path.splitext(path)[1].lower()
    if ext not in MESH_EXTENSIONS:
        raise InvalidArgumentError(f"{fn}: {path}: unsupported extension "
                                   f"'{ext or '(none)'}' (use {' or '.join(MESH_EXTENSIONS)})")
    return ext


@plain_pages
def read_mesh(path):
    """Read an OBJ or SMF file, chosen by its extension.

    Returns
    -------
    MeshFile
        ``V`` (n,3) float64, ``F`` (m,3) int64, ``n_polygons`` (faces in the
        file) and ``skipped`` (lines of other keywords, per keyword).

    Raises
    ------
    InvalidArgumentError
        An extension other than ``.obj`` / ``.smf``.
    InvalidMeshError
        A bad line (see :func:`read_smf`).

    Examples
    --------
    >>> m = core.read_mesh("scan.smf")
    >>> m.V.shape, m.F.shape, m.skipped            # ((n, 3), (m, 3), {'c': 120})
    """
    path = file_name(path, "read_mesh")
    ext = _extension("read_mesh", path)
    return _read(path, "read_obj" if ext == ".obj" else "read_smf", obj=ext == ".obj")


def _write(path, V, F, fn):
    # checked as every function checks a mesh: NaN was written out (and then not read back),
    # strings, booleans and complex numbers were taken
    V, F = check_mesh(V, F, where=fn, copy=False)
    with open(path, "w", encoding="utf-8") as fh:
        fh.write(f"# written by MeshAdjust: {V.shape[0]} vertices, {F.shape[0]} triangles\n")
        # %r: repr, the shortest text that reads back to the same float64; a block of
        # rows formatted at once (one % over a repeated line: no loop over vertices)
        _write_rows(fh, "v %r %r %r\n", V)
        _write_rows(fh, "f %d %d %d\n", F.astype(np.int64) + 1)


#: rows formatted at once by :func:`_write_rows`
_WRITE_BLOCK = 1 << 16


def _write_rows(fh, line, X):
    """Write the rows of ``X`` (k,3), each as ``line % row``, a block of
    ``_WRITE_BLOCK`` rows at a time."""
    for s in range(0, X.shape[0], _WRITE_BLOCK):
        block = X[s:s + _WRITE_BLOCK]
        fh.write((line * block.shape[0]) % tuple(block.ravel().tolist()))


def write_smf(path, V, F):
    """Write positions and triangles to an SMF file, exactly.

    Parameters
    ----------
    path : str or os.PathLike
    V : (n,3) float array_like
    F : (m,3) int array_like, 0-based (written 1-based).

    Raises
    ------
    InvalidMeshError
        Wrong shapes or indices outside ``V``.
    """
    _write(file_name(path, "write_smf"), V, F, "write_smf")


def write_obj(path, V, F):
    """Write positions and triangles to an OBJ file, exactly (see
    :func:`write_smf`; the text is the same)."""
    _write(file_name(path, "write_obj"), V, F, "write_obj")


@plain_pages
def write_mesh(path, V, F):
    """Write an OBJ or SMF file, chosen by the extension of ``path``.

    Raises
    ------
    InvalidArgumentError
        An extension other than ``.obj`` / ``.smf``.
    InvalidMeshError
        Wrong shapes or indices outside ``V``.
    """
    path = file_name(path, "write_mesh")
    ext = _extension("write_mesh", path)
    _write(path, V, F, "write_obj" if ext == ".obj" else "write_smf")
