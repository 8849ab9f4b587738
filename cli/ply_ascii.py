"""The records of an ASCII PLY file, every one checked before Blender reads them.

Blender's PLY importer reads an ASCII record that holds a word which is no
number (``0.5 abc 0.5``, a decimal comma ``0,5``) as 0, one with too few
values from what follows, and drops a face with an index ``1.5`` with a
bare count: the file came back "ok" with vertices moved to 0 (a comma file:
every vertex on an axis). :func:`record_problem` finds the first such
record, the numbers of a block of lines converted at once::

    for each element, a block of lines at a time:
        values = every word as a number          (a word that is none: that line)
        words per line == the values its properties give (a list's count read)
        whole numbers in a list of an integer type (a face's indices), written
        as integers (``12.0`` and ``0.42e2``, which Blender reads otherwise: no
        faces, or scrambled ones) within 32 bits (2147483648 was vertex 0)
"""

import numpy as np

from .ascii_words import BLANK, numbers, word_starts

#: property types that hold whole numbers
INTEGER_TYPES = {"char", "int8", "uchar", "uint8", "short", "int16", "ushort", "uint16", "int",
                 "int32", "uint", "uint32"}
#: lines whose numbers are converted at once
_BLOCK = 1 << 16

#: the integers a list's count and items may hold (Blender's importer reads them in 32 bits)
INTEGER_LIMIT = 2 ** 31

#: bytes an integer's word is made of
_INTEGER_BYTES = np.zeros(256, dtype=bool)
_INTEGER_BYTES[list(b"0123456789+-")] = True


def _whole(x):
    return bool(np.isfinite(x) and x == np.floor(x))


def _integer(word, value):
    """Whether ``word`` (bytes; its number ``value``) is written as an
    integer within :data:`INTEGER_LIMIT`."""
    return bool(_INTEGER_BYTES[np.frombuffer(word, dtype=np.uint8)].all()) and \
        _whole(value) and abs(value) < INTEGER_LIMIT


def describe(words, props, corners=None):
    """What is wrong with one record (its ``words``, bytes) of an element of
    ``props`` (``[(type, name)]``, a list's type ``("list", count type,
    item type)``), in words, or None; ``corners``: the name of a face's list
    of corners, whose length Blender's importer takes from 1 to 255."""
    if not words and props:
        return "is blank"
    values = []
    for w in words:
        got = numbers(w)
        if got is None or got.size != 1:
            comma = " (a decimal comma? PLY's numbers take a point)" if b"," in w else ""
            return f"holds '{w.decode('ascii', 'replace')}', which is not a number{comma}"
        values.append(float(got[0]))
    at, want = 0, 0
    for t, name in props:
        if isinstance(t, tuple):
            if at < len(values) and not (_integer(words[at], values[at]) and values[at] >= 0):
                return (f"holds '{words[at].decode()}' as the length of its {name} list, which "
                        f"is no count")
            n = int(values[at]) if at < len(values) else 0
            if name == corners and at < len(values) and not 1 <= n <= 255:
                return (f"is a face of {n:,} corners, and Blender's PLY importer reads faces of "
                        f"at most 255: triangulate the file's polygons first (e.g. save it as "
                        f"OBJ)" if n > 255 else f"is a face of {n} corners: a damaged file")
            items = values[at + 1:at + 1 + n]
            bad = [k for k, v in enumerate(items) if not _integer(words[at + 1 + k], v)] \
                if t[2] in INTEGER_TYPES else []
            if bad:
                return (f"holds '{words[at + 1 + bad[0]].decode()}' in its {name} list, whose "
                        f"items are 32-bit integers ({t[2]}) written in digits")
            at, want = at + 1 + n, want + 1 + n
        else:               # (a scalar's type is not checked: Blender reads 0.5 as 0.5 there)
            at, want = at + 1, want + 1
    if len(values) != want:
        return f"holds {len(values)} values, not the {want} its properties give"
    return None


def record_problem(body, starts, ends, first, count, props, corners=None):
    """``(line, problem)`` of the first bad record of an element of
    ``count`` records from line ``first`` of ``body`` (bytes; ``starts``,
    ``ends``: each line's byte range; the line 0-based in ``body``) whose
    properties are ``props`` (``corners``: see :func:`describe`), or None
    (see the module's docstring)."""
    for s in range(first, first + count, _BLOCK):
        e = min(s + _BLOCK, first + count)
        k = _first_bad_line(body, starts[s:e], ends[s:e], props, corners)
        if k is not None:
            line = s + k
            return line, describe(bytes(body[starts[line]:ends[line]]).split(), props, corners)
    return None


def _first_bad_line(body, starts, ends, props, corners):
    """Index (in ``starts``) of the first line whose record :func:`describe`
    finds wrong, or None."""
    seg = np.asarray(body[starts[0]:ends[-1]])
    rel_ends = ends - starts[0]
    values = numbers(seg.tobytes())
    words = np.bincount(np.searchsorted(rel_ends, word_starts(seg), side="right"),
                        minlength=starts.size)[:starts.size]
    if values is None or values.size != words.sum():
        return _first_described(body, starts, ends, props, corners)
    offset = np.cumsum(words) - words
    bad = _wrong_records(values, offset, words, props, corners, _integer_words(seg))
    if bad is None:
        return _first_described(body, starts, ends, props, corners)
    hits = np.flatnonzero(bad)
    return int(hits[0]) if hits.size else None


def _first_described(body, starts, ends, props, corners):
    """The first line :func:`describe` finds wrong (a line at a time)."""
    for k in range(starts.size):
        if describe(bytes(body[starts[k]:ends[k]]).split(), props, corners):
            return k
    return None


def _integer_words(seg):
    """Per word of ``seg`` ((k,) uint8), whether it is written as an integer
    (digits and signs only)."""
    blank = BLANK[seg]
    first = ~blank
    first[1:] &= blank[:-1]
    word = np.cumsum(first) - 1
    other = ~blank & ~_INTEGER_BYTES[seg]
    return np.bincount(word[other], minlength=int(first.sum())) == 0


def _wrong_records(values, offset, words, props, corners, integer_words):
    """Per record (its words ``values[offset:offset + words]``), whether its
    value count, a list's count or an item of a list of integers is wrong
    (``integer_words``: per word, whether it is written as an integer); None
    when a list's count cannot be read (the line by line check then finds it)."""
    literal = np.append(integer_words & (np.abs(values) < INTEGER_LIMIT), True)
    at = offset.copy()
    padded = np.append(values, 0.0)              # (records of no words read a 0 past the end)
    bad = np.zeros(words.size, dtype=bool)
    integer = np.zeros(values.size + 1, dtype=np.int64)     # +1 / -1 where int items start / end
    end = offset + words
    for t, name in props:
        inside = at < end
        if isinstance(t, tuple):
            c = np.where(inside, padded[np.minimum(at, values.size)], 0.0)
            if not np.isfinite(c).all():
                return None
            bad |= (c != np.floor(c)) | (c < 0) | ~literal[np.minimum(at, values.size)]
            if name == corners:
                bad |= inside & ((c < 1) | (c > 255))
            n = np.where(bad, 0, c).astype(np.int64)
            if t[2] in INTEGER_TYPES:
                lo, hi = np.minimum(at + 1, end), np.minimum(at + 1 + n, end)
                np.add.at(integer, lo, 1)
                np.add.at(integer, hi, -1)
            at = at + 1 + n
        else:
            at = at + 1
    bad |= at != end
    check = np.cumsum(integer[:-1]) > 0
    wrong = check & ~(np.isfinite(values) & (values == np.floor(values)) & literal[:-1])
    if wrong.any():
        bad[np.searchsorted(offset, np.flatnonzero(wrong), side="right") - 1] = True
    return bad
