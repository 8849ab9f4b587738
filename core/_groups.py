"""Vectorised helpers for ragged groups (variable-length runs in flat arrays)
and for sorting and set membership of integer keys.

Shared by the spatial index and the binding: candidate lists per query are
stored flat, each query's entries contiguous, with a count per query. The
set helpers (:func:`sorted_unique`, :func:`member_of`) stand in for NumPy's
``np.unique`` / ``np.isin`` / ``np.union1d``, which NumPy 2.3+ answers with a
hash table, 10-75x slower on large arrays of keys.
"""

import numpy as np

from ._parallel import blocks, run_blocks

#: key ranges beyond which :func:`sort_keys` falls back on a stable argsort
_MAX_RANGES = 64
#: keys per block of :func:`sort_keys`' range labels on the worker threads
_LABEL_BLOCK = 1 << 16
#: :func:`member_of` takes a bool table over ``among``'s range when it is at most this
#: many times the two arrays' sizes (``np.isin``'s rule)
TABLE_SPAN = 6


def ragged_ranges(starts, counts):
    """Concatenated ``arange(starts[i], starts[i] + counts[i])`` and the
    group (``i``) of each entry.

    Examples
    --------
    >>> idx, owner = ragged_ranges(np.array([5, 0]), np.array([2, 3]))
    >>> idx.tolist(), owner.tolist()
    ([5, 6, 0, 1, 2], [0, 0, 1, 1, 1])
    """
    counts = np.asarray(counts, dtype=np.int64)
    owner = np.repeat(np.arange(counts.shape[0], dtype=np.int64), counts)
    offsets = np.cumsum(counts) - counts
    idx = np.arange(int(counts.sum()), dtype=np.int64) + np.repeat(starts - offsets, counts)
    return idx, owner


def ragged_entries(starts, counts):
    """The entries of :func:`ragged_ranges` without their owners (one
    ``repeat`` instead of two).

    Examples
    --------
    >>> ragged_entries(np.array([5, 0]), np.array([2, 3])).tolist()
    [5, 6, 0, 1, 2]
    """
    offsets = np.cumsum(counts) - counts
    return np.arange(int(offsets[-1] + counts[-1]) if counts.shape[0] else 0,
                     dtype=np.int64) + np.repeat(starts - offsets, counts)


#: :func:`distinct` marks a set in a boolean mask and scans its span when the span
#: is at most this many times the set's size
MASK_SPAN = 32


def distinct(values, seen, stamp=None):
    """The distinct values of the int array ``values``, ascending, as int64.

    Values spanning at most ``MASK_SPAN`` times their count (the large sets
    of an incremental deform or of the fold repair's test) are marked in
    the boolean scratch ``seen`` (longer than the largest value, all False
    between calls), the marks of the span read back in one sequential scan
    and cleared: 1.4-1.7x faster than the stamp for 80-200k values over
    1-2M. Sparser ones go through the int64 scratch ``stamp`` when given
    (each value's slot receives the position of one of its occurrences and
    exactly that occurrence is kept, O(len(values)) whatever their range,
    then sorted), else ``np.unique``. Not for two threads sharing a scratch.

    Examples
    --------
    >>> distinct(np.array([4, 2, 4, 3]), np.zeros(8, dtype=bool)).tolist()
    [2, 3, 4]
    """
    if values.shape[0] == 0:
        return values.astype(np.int64)
    lo, hi = int(values.min()), int(values.max()) + 1
    if hi - lo <= MASK_SPAN * values.shape[0]:
        seen[values] = True
        out = np.flatnonzero(seen[lo:hi])
        out += lo
        seen[out] = False
        return out
    if stamp is None:
        return sorted_unique(values).astype(np.int64, copy=False)
    pos = np.arange(values.shape[0], dtype=np.int64)
    stamp[values] = pos
    return np.sort(values[stamp[values] == pos]).astype(np.int64, copy=False)


def group_argmin(values, counts):
    """Index (into ``values``) of the first minimum of each contiguous group;
    every count must be > 0.

    Examples
    --------
    >>> group_argmin(np.array([3.0, 1.0, 1.0, 2.0, 0.5]), np.array([3, 2])).tolist()
    [1, 4]
    """
    starts = np.cumsum(counts) - counts
    mins = np.minimum.reduceat(values, starts)
    pos = np.flatnonzero(values == np.repeat(mins, counts))
    group = np.searchsorted(starts, pos, side="right") - 1
    first = np.ones(pos.shape[0], dtype=bool)
    first[1:] = group[1:] != group[:-1]
    return pos[first]


def stable_argsort(x):
    """``np.argsort(x, kind="stable")`` for non-negative integers ``x``
    (k,): the order of :func:`sort_keys` (the keys packed with their
    position and sorted by value, 3-4x faster: the faces around the
    vertices of a 1.1M-face scan, 3.3M keys, 22 against 97 ms).

    Examples
    --------
    >>> stable_argsort(np.array([2, 0, 2, 1, 0])).tolist()
    [1, 4, 3, 0, 2]
    """
    x = np.asarray(x)
    if x.size == 0:
        return np.zeros(0, dtype=np.int64)
    bound = int(x.max()) + 1
    if bound <= _RADIX_BOUND:
        return _radix_order(x)
    return sort_keys(x.astype(np.int64), bound)[0]


#: keys below this take NumPy's radix sort of 16-bit keys (:func:`_radix_order`)
_RADIX_BOUND = 1 << 16


def _radix_order(key):
    """``np.argsort(key, kind="stable")`` for keys below ``_RADIX_BOUND``:
    NumPy's radix sort of them as 16-bit keys (4-10x the packed sort; 10x a
    stable sort of int64)."""
    return np.argsort(key.astype(np.uint16), kind="stable")


def sort_keys(key, bound):
    """``order = np.argsort(key, kind="stable")`` and ``key[order]`` for keys
    in ``[0, bound)``: below ``_RADIX_BOUND`` by NumPy's radix sort, else
    from plain sorts of ``key << bits | index`` (unique values: far faster
    than a stable argsort, and the same result).

    Keys too wide to pack with their index are sorted range by range: the
    ranges of ``2**(63 - bits)`` keys, each packed relative to its start.
    ``key`` (int64) is overwritten.
    """
    size = key.size
    bits = max(int(size - 1).bit_length(), 1)
    if bound <= _RADIX_BOUND:
        order = _radix_order(key)
        return order, key.take(order)
    if bound <= 1 << (63 - bits):
        return _packed_sort(key, bits)
    width = 63 - bits
    n_ranges = int((bound - 1) >> width) + 1
    if n_ranges > _MAX_RANGES:
        order = np.argsort(key, kind="stable")
        return order, key[order]
    spans = blocks(size, _LABEL_BLOCK)
    in_range = np.empty(size, dtype=np.uint16)

    def label(a, b):
        np.right_shift(key[a:b], width, out=in_range[a:b], casting="unsafe")

    run_blocks(label, spans)
    starts = np.concatenate([[0], np.cumsum(np.bincount(in_range, minlength=n_ranges))])
    order = np.empty(size, dtype=np.int64)
    ks = np.empty(size, dtype=np.int64)

    def one(r):
        sel = np.flatnonzero(in_range == r)
        k = key.take(sel)
        k -= np.int64(r << width)
        k <<= bits
        k |= sel
        k.sort()
        a, b = starts[r], starts[r + 1]
        np.bitwise_and(k, np.int64((1 << bits) - 1), out=order[a:b])
        np.right_shift(k, bits, out=ks[a:b])
        ks[a:b] += np.int64(r << width)

    for r in range(n_ranges):      # in this thread: a worker's arena would keep their memory
        one(r)
    return order, ks


def _packed_sort(key, bits):
    """:func:`sort_keys` when ``key << bits`` fits in 63 bits (in place)."""
    key <<= bits
    key |= np.arange(key.size, dtype=np.int64)
    key.sort()
    order = key & np.int64((1 << bits) - 1)
    key >>= bits
    return order, key


def sorted_unique(x):
    """``np.unique(x)`` (the distinct values of ``x`` flattened, ascending;
    the same array) for integer and bool arrays by one sort, as NumPy 1.x
    finds them: NumPy 2.3+ finds them with a hash table, 2M int64 of
    many distinct values 1.36 s against 0.018 (a five-level refined bind
    spent 1.5 of its 3.9 s there). Other dtypes go to ``np.unique``.

    Examples
    --------
    >>> sorted_unique(np.array([[3, 1], [3, 2]])).tolist()
    [1, 2, 3]
    """
    x = np.asarray(x)
    if x.dtype.kind not in "biu":
        return np.unique(x)
    a = np.sort(x, axis=None)
    if a.size < 2:
        return a
    keep = np.empty(a.size, dtype=bool)
    keep[0] = True
    np.not_equal(a[1:], a[:-1], out=keep[1:])
    return a[keep]


def member_of(values, among):
    """``np.isin(values, among)`` for integer arrays: a bool array shaped as
    ``values``, True where the value is one of ``among``'s. Over a range at
    most ``TABLE_SPAN`` times the two sizes, a bool table of ``among``'s
    values, as ``np.isin`` does; wider, ``among`` sorted
    (:func:`sorted_unique`) and ``values`` found in it in ascending order
    (a binary search for each in random order is 4x slower): NumPy 2.3+'s
    ``np.isin`` of keys over a wide range finds ``among``'s values with a
    hash table (1M edge keys against 1M: 524 ms, these 43; NumPy 1.26's
    52; ``np.union1d`` 1.5 s against 21 ms, which :func:`sorted_unique` of
    the two arrays replaces).

    Examples
    --------
    >>> member_of(np.array([3, 9, 4]), np.array([[4, 5], [3, 3]])).tolist()
    [True, False, True]
    """
    values = np.asarray(values)
    among = np.asarray(among).ravel()
    out = np.zeros(values.shape, dtype=bool)
    if among.size == 0 or values.size == 0:
        return out
    lo, hi = int(among.min()), int(among.max())
    if hi - lo <= TABLE_SPAN * (values.size + among.size):
        table = np.zeros(hi - lo + 1, dtype=bool)
        table[among - lo] = True
        inside = (values >= lo) & (values <= hi)
        out[inside] = table[values[inside] - lo]
        return out
    known = sorted_unique(among)
    flat = values.ravel()
    order = np.argsort(flat)
    q = flat[order]
    at = np.searchsorted(known, q)
    np.minimum(at, known.size - 1, out=at)
    out.ravel()[order] = known[at] == q
    return out
