"""Vectorised helpers for ragged groups (variable-length runs in flat arrays).

Shared by the spatial index and the binding: candidate lists per query are
stored flat, each query's entries contiguous, with a count per query.
"""

import numpy as np


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
