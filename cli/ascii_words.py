"""The words and numbers of an ASCII mesh file's records, a block of lines at a time
(the PLY and STL checks read them so before Blender's importers do)."""

import warnings

import numpy as np

#: bytes that separate words (as NumPy's number parser skips them)
BLANK = np.zeros(256, dtype=bool)
BLANK[[9, 10, 11, 12, 13, 32]] = True


def numbers(text):
    """The numbers of ``text`` (bytes of whitespace-separated words), or
    None when a word is no number."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")              # (NumPy 1.x: a warning, 2.x: an error)
        try:
            return np.fromstring(text, dtype=np.float64, sep=" ")
        except (ValueError, DeprecationWarning):
            return None


def word_starts(b):
    """Positions in ``b`` ((k,) uint8, a file's bytes) where a word begins."""
    blank = BLANK[b]
    first = ~blank
    first[1:] &= blank[:-1]
    return np.flatnonzero(first)
