"""Input checking and small whole-mesh measures shared by every algorithm.

A mesh is ``V`` (n,3) float64 coordinates and ``F`` (m,3) int64 vertex
indices. Core functions call :func:`check_mesh` first: it returns fresh,
contiguous float64/int64 arrays (so the caller's arrays are never modified)
or raises :class:`~.errors.InvalidMeshError` naming the problem and an example.
"""

import numpy as np

from ._groups import member_of
from ._parallel import blocks, run_blocks
from .errors import InvalidArgumentError, InvalidMeshError

#: triangles per block of :func:`area_normals_t` (its temporaries stay small and are
#: reused: 2M faces at once made four fresh (3, m) float64 arrays, which this machine
#: pays for dearly the first time they are touched)
NORMALS_BLOCK = 1 << 14
#: triangles per block of :func:`normal_dots` (its nine gathered coordinate rows and
#: products, 64 kB each, stay in the core's cache: 52k faces, the fold test around
#: 5 moved cage vertices' rows of the bunny x16, 1.5 ms in blocks of 8k or 16k, 1.6 of
#: 4k, 1.7 all at once; 2.2 with the (k,3) gathers it had before)
DOTS_BLOCK = 1 << 13
#: a face is flat (its corners collinear, up to the rounding of their coordinates) when
#: twice its area is at most this times its longest edge times the largest coordinate
#: magnitude: the error of a cross product of edges between rounded coordinates is a few
#: eps of that product (:func:`has_area`)
FLAT_FACE = 64 * float(np.finfo(np.float64).eps)


def _as_array(x, name, shape, where, error=InvalidMeshError):
    """``np.asarray(x)``; a ragged list (rows of different lengths) raises
    ``error`` naming ``name`` instead of NumPy's error."""
    try:
        return np.asarray(x)
    except ValueError as exc:
        raise error(f"{where}: {name} must be {shape}, got rows of different "
                    f"lengths ({exc})") from None


def check_mesh(V, F, *, where, allow_empty=True, copy=True, names=("V", "F")):
    """Validate and copy a triangle mesh.

    Parameters
    ----------
    V : array_like, (n, 3) float
        Vertex positions. Must be finite.
    F : array_like, (m, 3) int
        Triangle vertex indices, each in ``[0, n)``.
    where : str
        Name of the calling function, used as the message prefix.
    allow_empty : bool
        If False, a mesh with no faces raises.
    copy : bool
        If False, arrays that already are C-contiguous float64 / int64 come
        back as they are (for functions that only read them).
    names : (str, str)
        The arguments the messages name (``("V_cage", "F_cage")`` for a
        function taking two meshes: "F_cage has no faces", not "the mesh").

    Returns
    -------
    V : (n, 3) float64 ndarray, a new C-contiguous copy (with ``copy``).
    F : (m, 3) int64 ndarray, a new C-contiguous copy (with ``copy``).

    Raises
    ------
    InvalidMeshError
        Wrong shapes or dtypes, NaN/inf coordinates, out-of-range indices.

    Examples
    --------
    >>> V, F = check_mesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]], where="demo")
    >>> V.dtype, F.dtype
    (dtype('float64'), dtype('int64'))
    """
    V = _as_array(V, names[0], "(n,3) floats", where)     # ragged lists first, V's then F's
    F = _as_array(F, names[1], "(m,3) integers", where)
    V = check_vertices(V, where=where, name=names[0], copy=copy, faces=F)
    return V, check_faces(F, V.shape[0], where=where, allow_empty=allow_empty, copy=copy,
                          name=names[1])


def _converted(x, dtype, copy):
    """``x`` as a C-contiguous ``dtype`` array: always a new one with ``copy``,
    else only when it is not one already."""
    return np.array(x, dtype=dtype, order="C") if copy else np.asarray(x, dtype=dtype, order="C")


def check_vertices(V, *, where, name="V", copy=True, faces=None):
    """Vertex positions ``V`` (n,3) as float64, checked as :func:`check_mesh`
    checks them (shape, numbers, finite); ``name`` is the argument named in
    the message, which says how many of the non-finite vertices the
    ``faces`` (when given) use. Raises :class:`InvalidMeshError`."""
    V_in = _as_array(V, name, "(n,3) floats", where)
    if V_in.size == 0 and V_in.ndim <= 1:
        V_in = V_in.reshape(0, 3)
    if V_in.ndim != 2 or V_in.shape[1] != 3 or not (
            np.issubdtype(V_in.dtype, np.floating) or np.issubdtype(V_in.dtype, np.integer)):
        raise InvalidMeshError(f"{where}: {name} must be (n,3) floats, got {V_in.shape} {V_in.dtype}")
    V_out = _converted(V_in, np.float64, copy)
    if not np.isfinite(V_out).all():
        rows = np.flatnonzero(~np.isfinite(V_out).all(axis=1))
        of = "" if name == "V" else f" of {name}"
        raise InvalidMeshError(
            f"{where}: {rows.size} vertices{of} have NaN or infinite coordinates"
            f"{_used_by_faces(rows, faces)}, e.g. vertex {rows[0]} = {V_out[rows[0]].tolist()}"
        )
    return V_out


def check_finite_rows(X, *, where, what):
    """Raise :class:`InvalidArgumentError` when a row of ``X`` (k,d) holds NaN
    or an infinite value, saying how many rows of ``what`` (e.g. "query
    points") do and giving the first, with its values. (The whole array is
    tested first: a reduction along rows of three is 15x slower, 14 ms for
    a million points, once per block of a bind's queries.)"""
    if np.isfinite(X).all():
        return
    bad = ~np.isfinite(X).all(axis=1)
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        raise InvalidArgumentError(
            f"{where}: {int(bad.sum())} {what} have NaN or infinite values, "
            f"e.g. row {k} = {X[k].tolist()}")


#: the units :func:`check_units` accepts: coordinates up to ``UNITS[1]`` in absolute
#: value, a size (bounding-box diagonal) from ``UNITS[0]``. ``fit_cage``, ``bind``,
#: ``deform`` and ``surface_distance`` compute in the mesh's own units, and their
#: searches near a surface bound squared distances in float32 (normal from 1.2e-38 to
#: 3.4e38): from coordinates of 1e19 these overflowed (warnings; ``bind`` failed at
#: 1e78 and its ``deform`` was 10% of the size off at 1e80) and below sizes of 1e-20
#: they went subnormal (``fit_cage`` 10-100x slower). ``simplify`` scales the mesh to a
#: unit size first and takes any units.
UNITS = (1e-15, 1e15)


#: the reach of the exact closest-point searches (``TriangleIndex``): their kernel
#: multiplies squared lengths, so coordinates whose fourth powers stay finite (at 1e100
#: it overflowed, at 1e300 it failed with an IndexError)
SEARCH_REACH = 1e60


def check_points(P, *, where, name="P", what="query points"):
    """Query points ``P`` as a (q,3) float64 array, or
    :class:`InvalidArgumentError` naming ``name``: not (q,3) real numbers
    (strings, complex numbers and ragged lists had gone through to NumPy's
    own errors or lost their imaginary part), NaN or infinite values
    (:func:`check_finite_rows`, ``what``), or coordinates beyond
    :data:`SEARCH_REACH` (at 1e154 a search answered with the wrong face
    and an infinite distance)."""
    P_in = _as_array(P, name, "(q,3) floats", where, InvalidArgumentError)
    if P_in.ndim != 2 or P_in.shape[1] != 3 or P_in.dtype.kind not in "fiu":
        raise InvalidArgumentError(
            f"{where}: {name} must be (q,3) floats, got {P_in.shape} {P_in.dtype}")
    P_out = np.ascontiguousarray(P_in, dtype=np.float64)
    check_finite_rows(P_out, where=where, what=what)
    reach = float(np.abs(P_out).max()) if P_out.size else 0.0
    if reach > SEARCH_REACH:
        raise InvalidArgumentError(
            f"{where}: {name} reaches {reach:.3g} in its coordinates; the closest-point "
            f"searches take coordinates up to {SEARCH_REACH:g}")
    return P_out


def check_reach(V, *, where, name):
    """Raise :class:`InvalidMeshError` when the finite positions ``V`` reach
    beyond :data:`SEARCH_REACH`."""
    reach = float(np.abs(V).max()) if V.size else 0.0
    if reach > SEARCH_REACH:
        raise InvalidMeshError(
            f"{where}: {name} reaches {reach:.3g} in its coordinates; its closest-point searches "
            f"take coordinates up to {SEARCH_REACH:g}: scale the mesh first")


def check_units(V, *, where, name):
    """Raise :class:`InvalidMeshError` when the finite (n,3) positions ``V``
    reach beyond ``UNITS[1]`` in absolute value or span less than
    ``UNITS[0]`` (a single point spans 0 and passes: other checks name it);
    ``name`` is the argument named in the message."""
    lo, hi = bounding_box(V)
    reach = float(np.maximum(np.abs(lo), np.abs(hi)).max())
    size = diagonal_length(lo, hi)
    if reach > UNITS[1]:
        found = f"reaches {reach:.3g} in its coordinates"
    elif 0.0 < size < UNITS[0]:
        found = f"is {size:.3g} across"
    else:
        return
    raise InvalidMeshError(
        f"{where}: {name} {found}; {where} computes in the mesh's own units and takes "
        f"coordinates up to {UNITS[1]:g} and sizes from {UNITS[0]:g}: scale the mesh into that "
        f"range (e.g. to metres or millimetres) first (simplify takes any units)")


def _used_by_faces(rows, faces):
    """How many of the vertices ``rows`` the ``faces`` use, as the end of a
    sentence (``", none of them used by a face (...)"``); "" when ``faces``
    is not an (m,3) integer array (its own check names that)."""
    F = faces if isinstance(faces, np.ndarray) else None
    if F is None or F.ndim != 2 or F.shape[1] != 3 or not np.issubdtype(F.dtype, np.integer):
        return ""
    used = int(np.count_nonzero(member_of(rows, F)))
    if used == 0:
        return (", none of them used by a face (a scan's leftover points: keep only the "
                "vertices the faces use)")
    return f", {used:,} of them used by faces"


def check_faces(F, n_vertices, *, where, allow_empty=True, copy=True, name="F"):
    """Triangles ``F`` (m,3) as int64, checked as :func:`check_mesh` checks
    them: integers, each in ``[0, n_vertices)`` (``n_vertices`` None: only
    ``>= 0``). Raises :class:`InvalidMeshError` naming the first bad face
    (and ``name``, the argument, where it is not plain ``F``).

    Examples
    --------
    >>> check_faces([[0, 1, 2]], 3, where="demo").tolist()
    [[0, 1, 2]]
    """
    F_in = _as_array(F, name, "(m,3) integers", where)
    of, face = ("", "face") if name == "F" else (f" of {name}", f"{name}'s face")
    if F_in.size == 0 and F_in.ndim <= 1:
        F_in = F_in.reshape(0, 3).astype(np.int64)
    if F_in.ndim != 2 or F_in.shape[1] != 3 or not np.issubdtype(F_in.dtype, np.integer):
        raise InvalidMeshError(f"{where}: {name} must be (m,3) integers, got {F_in.shape} "
                               f"{F_in.dtype}")
    if F_in.dtype.kind == "u" and F_in.size and int(F_in.max()) > np.iinfo(np.int64).max:
        # (as int64 it wrapped to a negative index, and the message showed -1)
        f = int(np.flatnonzero((F_in > np.iinfo(np.int64).max).any(axis=1))[0])
        raise InvalidMeshError(f"{where}: {face} {f} = {F_in[f].tolist()} indexes a vertex beyond "
                               f"any mesh (more than 2^63)")
    F_out = _converted(F_in, np.int64, copy)
    if F_out.size:
        n = n_vertices
        if F_out.min() < 0 or (n is not None and F_out.max() >= n):
            out = (F_out < 0) if n is None else (F_out < 0) | (F_out >= n)
            f = int(np.flatnonzero(out.any(axis=1))[0])
            span = "have negative indices" if n is None else f"index vertices outside [0, {n})"
            raise InvalidMeshError(
                f"{where}: {int(out.any(axis=1).sum())} faces{of} {span}, "
                f"e.g. face {f} = {F_out[f].tolist()}"
            )
    elif not allow_empty:
        raise InvalidMeshError(f"{where}: {'the mesh' if name == 'F' else name} has no faces")
    return F_out


def shown(value, limit=60):
    """``value`` as an error message shows what was given: its ``repr``, or
    for an array or a long sequence its kind and shape (a face array given
    as a count had printed all of its rows into the message)."""
    if isinstance(value, np.ndarray) and value.ndim:
        return f"an array of shape {value.shape} ({value.dtype})"
    text = repr(value)
    if len(text) <= limit:
        return text
    if isinstance(value, (list, tuple)):
        return f"a {type(value).__name__} of {len(value)} items"
    return text[:limit - 4] + " ..."


def check_count(value, *, where, name):
    """``value`` as an int, or :class:`InvalidArgumentError` naming ``name``
    when it is not an integer >= 0 (a bool is not one)."""
    if isinstance(value, (bool, np.bool_, np.timedelta64)) \
            or not isinstance(value, (int, np.integer)) or value < 0:
        raise InvalidArgumentError(f"{where}: {name} must be an integer >= 0, got {shown(value)}")
    return int(value)


def check_number(value, *, where, name, lo=None, hi=None, open_lo=False, open_hi=False,
                 integer=False):
    """``value`` as a float (an int with ``integer``), or
    :class:`InvalidArgumentError` naming ``name`` and the range it takes:
    a real number (not a bool, a string, a list or a complex), finite, within
    ``lo`` .. ``hi`` (each end open as asked, None: unbounded), an integer
    with ``integer`` (3.0 is one, 2.5 is not)."""
    kind = "an integer" if integer else "a number"
    if lo is not None and hi is not None:
        takes = f"{kind} in {'(' if open_lo else '['}{lo:g}, {hi:g}{')' if open_hi else ']'}"
    elif lo is not None:
        takes = f"{kind} {'>' if open_lo else '>='} {lo:g}"
    elif hi is not None:
        takes = f"{kind} {'<' if open_hi else '<='} {hi:g}"
    else:
        takes = f"a finite {kind[2:]}"
    # integers are taken as they are (a float of 2**63 - 1 is 2**63, and np.isfinite
    # refused Python integers from 2**64 with a TypeError)
    whole = isinstance(value, (int, np.integer)) and not isinstance(
        value, (bool, np.bool_, np.timedelta64))          # (NumPy counts a timedelta64 as one)
    ok = whole or (isinstance(value, (float, np.floating)) and bool(np.isfinite(value)))
    if ok and integer and not whole:
        ok = float(value).is_integer()
    if ok and lo is not None:
        ok = value > lo if open_lo else value >= lo
    if ok and hi is not None:
        ok = value < hi if open_hi else value <= hi
    if not ok:
        raise InvalidArgumentError(f"{where}: {name} must be {takes}, got {shown(value)}")
    return int(value) if integer else float(value)


def check_seed(seed, *, where):
    """``seed`` for ``np.random.default_rng``: None, an integer >= 0 or a
    ``np.random.Generator`` (which the call advances), else
    :class:`InvalidArgumentError` (NumPy's own TypeError named none of it)."""
    if seed is None or isinstance(seed, np.random.Generator):
        return seed
    return check_number(seed, where=where, name="seed", lo=0, integer=True)


def check_flag(value, *, where, name):
    """``value`` as a bool, or :class:`InvalidArgumentError` naming ``name``
    when it is not True or False (NumPy's booleans too; 0, 1, "no" and None
    are not flags)."""
    if not isinstance(value, (bool, np.bool_)):
        raise InvalidArgumentError(f"{where}: {name} must be True or False, got {shown(value)}")
    return bool(value)


def stops(answer):
    """Whether a ``progress`` callback's ``answer`` asks to cancel: False,
    NumPy's False too (``np.False_ is False`` is not true, so a callback
    returning a comparison's result never cancelled)."""
    return answer is False or (isinstance(answer, np.bool_) and not answer)


def check_vertex_mask(mask, n, *, where, name):
    """A per-vertex flag array (n,) as booleans (:func:`check_mask`)."""
    return check_mask(mask, n, where=where, name=name, per="vertex")


def check_mask(mask, n, *, where, name, per):
    """A flag array (n,) as booleans, one ``per`` item (e.g. "vertex"), or
    :class:`InvalidArgumentError` naming ``name`` and the length ``n`` it
    needs (booleans or integers accepted: nonzero is True)."""
    a = _as_array(mask, name, f"({n},) booleans", where, InvalidArgumentError)
    if a.shape != (n,) or not (a.dtype == bool or np.issubdtype(a.dtype, np.integer)):
        raise InvalidArgumentError(f"{where}: {name} must be ({n},) booleans (one per {per}), "
                                   f"got {a.shape} {a.dtype}")
    return a.astype(bool)


def check_vertex_indices(index, n, *, where, name):
    """A per-vertex array of vertex indices (n,) as int64, each in ``[0, n)``,
    or :class:`InvalidArgumentError` naming ``name`` and the first vertex
    whose entry is out of range."""
    a = _as_array(index, name, f"({n},) integers", where, InvalidArgumentError)
    if a.shape != (n,) or not np.issubdtype(a.dtype, np.integer):
        raise InvalidArgumentError(f"{where}: {name} must be ({n},) vertex indices (one per vertex), "
                                   f"got {a.shape} {a.dtype}")
    a = a.astype(np.int64)
    bad = (a < 0) | (a >= n)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise InvalidArgumentError(f"{where}: {name} must hold vertex indices in [0, {n}), got "
                                   f"{int(bad.sum())} outside, e.g. {name}[{i}] = {a[i]}")
    return a


#: rows per block of :func:`bounding_box`
_BOX_BLOCK = 1 << 15


def bounding_box(V):
    """Corners ``(lo, hi)`` of the axis-aligned bounding box of ``V`` (n,3),
    each (3,) float64 (zeros if empty)."""
    V = np.asarray(V, dtype=np.float64)
    if V.shape[0] == 0:
        return np.zeros(3), np.zeros(3)
    # row reductions of transposed blocks, the block in cache: V.min(axis=0) took 4x the
    # time of a transposed copy's rows, which took 3.5x that of the blocks' (1M vertices)
    lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
    cols = np.empty((3, min(V.shape[0], _BOX_BLOCK)))
    for s in range(0, V.shape[0], _BOX_BLOCK):
        block = cols[:, :min(V.shape[0] - s, _BOX_BLOCK)]
        block[...] = V[s:s + _BOX_BLOCK].T
        np.minimum(lo, block.min(axis=1), out=lo)
        np.maximum(hi, block.max(axis=1), out=hi)
    return lo, hi


def bbox_diagonal(V):
    """Length of the axis-aligned bounding-box diagonal of ``V`` (0 if empty).

    Every tolerance in ``core`` is expressed relative to this length, so that
    results do not depend on the mesh's units. ``V`` is checked as
    :func:`check_vertices` checks it (a NaN gave inf, an (n,2) array a number).
    """
    return diagonal_length(*bounding_box(check_vertices(V, where="bbox_diagonal", copy=False)))


def used_vertices(F, n):
    """(k,) int64 the vertices ``0..n-1`` the faces ``F`` use, ascending:
    ``np.unique(F)`` by a count (a 278k-face mesh: 2 ms against 111 ms)."""
    return np.flatnonzero(np.bincount(np.asarray(F).ravel(), minlength=n))


def surface_diagonal(V, F):
    """:func:`bbox_diagonal` of the vertices of ``V`` the faces ``F`` use:
    the size a deviation or a max-error percentage is of (a scan's stray
    loose vertex 50 sizes away does not make it 50 times larger)."""
    V = check_vertices(V, where="surface_diagonal", copy=False)
    F = check_faces(F, V.shape[0], where="surface_diagonal", copy=False)
    return bbox_diagonal(V[used_vertices(F, V.shape[0])]) if F.size else bbox_diagonal(V)


def diagonal_length(lo, hi):
    """Length of the box diagonal from corner ``lo`` to ``hi`` (each (3,)),
    scaled so that coordinates near the float limits (1e200) do not overflow."""
    d = np.abs(np.asarray(hi, dtype=np.float64) - lo)
    s = float(d.max()) if d.size else 0.0
    if not s > 0 or not np.isfinite(s):
        return s if np.isfinite(s) else float("inf")
    return s * float(np.sqrt(np.sum((d / s) ** 2)))


def row_sums(X):
    """The sums of the rows of ``X`` (k,3), (k,): ``X.sum(axis=1)`` (the same
    bits: NumPy adds a row's three left to right; a bool array counts its
    True) about 10x faster than NumPy's reduction along rows of three (0.9 ms
    for 65k rows, against 0.09 for the three columns added)."""
    first = X[:, 0].astype(np.intp) if X.dtype == bool else X[:, 0]
    return first + X[:, 1] + X[:, 2]


def row_norms(X):
    """The Euclidean lengths of the rows of ``X`` (k,3), (k,): the bits of
    ``np.linalg.norm(X, axis=1)`` (the squares summed left to right, as its
    reduction does) without its reduction along rows of three (see
    :func:`row_sums`)."""
    return np.sqrt(X[:, 0] * X[:, 0] + X[:, 1] * X[:, 1] + X[:, 2] * X[:, 2])


def lengths(X):
    """:func:`row_norms` of ``X`` (k,3) at any scale: its rows divided by the
    power of two above their largest coordinate first when that is beyond
    ``2**SAFE_EXPONENT`` (or below its inverse), and the lengths multiplied
    back (exact: the same bits where the squares neither overflow nor
    underflow; at 1e200 they were infinite, with NumPy's overflow warning)."""
    scale = safe_scale(float(np.abs(X).max()) if X.size else 0.0)
    return row_norms(X) if scale == 1.0 else row_norms(X / scale) * scale


def any_in_rows(B):
    """``B.any(axis=1)`` of a bool (k,3) array, by its columns (see :func:`row_sums`)."""
    return B[:, 0] | B[:, 1] | B[:, 2]


def all_in_rows(B):
    """``B.all(axis=1)`` of a bool (k,3) array, by its columns (see :func:`row_sums`)."""
    return B[:, 0] & B[:, 1] & B[:, 2]


def dot_columns(a, b):
    """Dot products of the columns of two (3, k) arrays, (k,) (coordinates
    first: each row a contiguous coordinate)."""
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def cross_rows(a, b, out=None):
    """Cross products of the rows of two (k, 3) arrays, (k, 3) (into ``out``
    when given): the products and differences of ``np.cross``, so the same
    bits, without its temporaries (4-8x faster on large arrays)."""
    if out is None:
        out = np.empty(np.broadcast_shapes(a.shape, b.shape), dtype=np.result_type(a, b))
    for c, i, j in ((0, 1, 2), (1, 2, 0), (2, 0, 1)):
        np.multiply(a[:, i], b[:, j], out=out[:, c])
        out[:, c] -= a[:, j] * b[:, i]
    return out


def cross_columns(a, b):
    """Cross products of the columns of two (3, k) arrays, (3, k): the
    products and differences of ``np.cross`` on rows, so the same bits."""
    out = np.empty(np.broadcast_shapes(a.shape, b.shape), dtype=np.result_type(a, b))
    np.subtract(a[1] * b[2], a[2] * b[1], out=out[0])
    np.subtract(a[2] * b[0], a[0] * b[2], out=out[1])
    np.subtract(a[0] * b[1], a[1] * b[0], out=out[2])
    return out


def area_normals_t(PT, T, out=None):
    """Area normals (3,k) of the triangles ``T`` (3,k) (corner index rows,
    or a sequence of three index arrays) over positions ``PT`` (3,n) (the
    operations of ``np.cross``), ``NORMALS_BLOCK`` triangles at a time on the
    worker threads, into ``out`` when given (any float dtype: e.g. float32
    for half the bytes)."""
    k = T[0].shape[0]
    if k <= NORMALS_BLOCK and out is None:
        return _area_normals_block(PT, T[0], T[1], T[2])
    out = np.empty((3, k)) if out is None else out

    def block(s, e):
        out[:, s:e] = _area_normals_block(PT, T[0][s:e], T[1][s:e], T[2][s:e])
    run_blocks(block, blocks(k, NORMALS_BLOCK))
    return out


def _area_normals_block(PT, i0, i1, i2):
    """:func:`area_normals_t` of one block (corner index arrays i0, i1, i2)."""
    a = np.take(PT, i0, axis=1)
    e1 = np.take(PT, i1, axis=1)
    e1 -= a
    e2 = np.take(PT, i2, axis=1)
    e2 -= a
    return cross_columns(e1, e2)


def area_normals_rows(X, T):
    """:func:`area_normals_t` over positions ``X`` (n,3), as rows (k,3) (the
    same values)."""
    a, e1, e2 = _corner_edges(X, T)
    return cross_rows(e1, e2, out=a)


def normal_dots(X, T, reference):
    """``reference . n`` (k,) for the triangles ``T`` (3,k) over positions
    ``X`` (n,3), ``n`` their area normal, ``reference`` (3,k) (rows of
    directions): the products and sums of :func:`area_normals_rows` then
    :func:`dot_columns` in the same order (the same bits), without the
    normals' (k,3) array. ``DOTS_BLOCK`` triangles at a time, each corner's
    coordinates gathered one at a time from the flat positions (nine gathers
    of single floats into contiguous rows: the arithmetic then reads
    contiguous rows, not the columns of (k,3) arrays). Negative: the face
    points away from its reference."""
    flat = np.ascontiguousarray(X).reshape(-1)
    k = T.shape[1]
    out = np.empty(k, dtype=np.result_type(flat, reference))
    for s in range(0, k, DOTS_BLOCK):
        _normal_dots_block(flat, T[:, s:s + DOTS_BLOCK], reference[:, s:s + DOTS_BLOCK],
                           out[s:s + DOTS_BLOCK])
    return out


def _normal_dots_block(flat, T, reference, out):
    """:func:`normal_dots` of one block into ``out``, over the positions
    ``flat`` (3n,) (C order: vertex ``v``'s coordinate ``d`` at ``3 v + d``)."""
    at = np.multiply(T, 3, dtype=np.int64)
    k = at.shape[1]
    e1, e2 = np.empty((3, k), dtype=flat.dtype), np.empty((3, k), dtype=flat.dtype)
    a = np.empty(k, dtype=flat.dtype)
    for d in range(3):
        coordinate = flat[d:]       # (the indices are the faces' corners: in range, so
        np.take(coordinate, at[0], out=a, mode="wrap")  # "wrap", half the time of "raise")
        np.take(coordinate, at[1], out=e1[d], mode="wrap")
        e1[d] -= a
        np.take(coordinate, at[2], out=e2[d], mode="wrap")
        e2[d] -= a
    t, term = np.empty_like(a), np.empty_like(out)
    for c, i, j in ((0, 1, 2), (1, 2, 0), (2, 0, 1)):   # the cross product's row c, as np.cross
        np.multiply(e1[i], e2[j], out=a)
        np.multiply(e1[j], e2[i], out=t)
        a -= t
        np.multiply(reference[c], a, out=term if c else out)
        if c:
            out += term


def _corner_edges(X, T):
    """The first corner ``a`` and the edges ``b - a``, ``c - a`` (each (k,3),
    new arrays) of the triangles ``T`` (3,k) over positions ``X`` (n,3)."""
    a = np.take(X, T[0], axis=0)
    e1 = np.take(X, T[1], axis=0)
    e1 -= a
    e2 = np.take(X, T[2], axis=0)
    e2 -= a
    return a, e1, e2


def unit_rows(X):
    """The rows of ``X`` (k,3) normalised, a new array (zero rows stay zero)."""
    length = row_norms(X)
    return np.divide(X, length[:, None], out=np.zeros_like(X), where=length[:, None] > 0)


#: coordinates whose largest is within 2**-SAFE_EXPONENT .. 2**SAFE_EXPONENT
#: multiply (twice, in area normals) without overflow or underflow
SAFE_EXPONENT = 250


def power_of_two_scale(V, F):
    """A power of two to divide the coordinates of the faces ``F`` by before
    multiplying them: the one just above their largest, or 1.0 when they are
    safe as they are (:data:`SAFE_EXPONENT`; none; all zero). Dividing by it
    is exact, so the products of the scaled coordinates neither overflow (at
    1e200 area normals did, and ``inf - inf`` gave NaN) nor underflow (at
    1e-200 they were zero), and give the same bits where neither happened."""
    if F.size == 0:
        return 1.0
    A = np.abs(V)
    return safe_scale(float(np.maximum(np.maximum(A[:, 0], A[:, 1]), A[:, 2])[F].max()))


def safe_scale(largest):
    """The power of two just above ``largest`` (a magnitude >= 0), or 1.0
    when it lies within ``2**-SAFE_EXPONENT .. 2**SAFE_EXPONENT`` or is 0:
    what to divide numbers of that magnitude by, exactly, before
    multiplying them."""
    exponent = int(np.frexp(largest)[1])
    if largest == 0 or abs(exponent) < SAFE_EXPONENT:
        return 1.0
    return float(np.ldexp(1.0, exponent))


def scaled_area_normals(V, F):
    """The area normals (m,3) of ``F`` over ``V / s`` and ``s``
    (:func:`power_of_two_scale`): the true normals are ``s * s`` times them."""
    s = power_of_two_scale(V, F)
    return area_normals_rows(V / s if s != 1.0 else V, F.T), s


def face_normals(V, F, *, normalize=True):
    """Per-face normals, (m,3) float64; unnormalised normals have length
    twice the face area (infinite where that is beyond the floats).
    Degenerate faces get a zero normal; unit normals are found at any scale.

    Raises :class:`InvalidMeshError` for a malformed mesh (:func:`check_mesh`).
    Inside ``core``, on checked arrays, :func:`area_normals_rows` of ``F.T``
    is the same without the check."""
    V, F = check_mesh(V, F, where="face_normals", copy=False)
    normalize = check_flag(normalize, where="face_normals", name="normalize")
    N, s = scaled_area_normals(V, F)
    if normalize:
        return unit_rows(N)
    with np.errstate(over="ignore"):
        return N * s * s if s != 1.0 else N     # twice: 0 * (s * s) was NaN at inf


def turned_faces(V_rest, V_new, F):
    """The faces (ascending, int64) of ``F`` whose normal on ``V_new`` turned by
    more than 90 degrees from their normal on ``V_rest`` (negative dot product
    of the area normals): the faces an edit folded over. Faces degenerate at
    rest (no normal) are never counted.

    Raises :class:`InvalidMeshError` for a malformed mesh (:func:`check_mesh`)
    or a ``V_new`` not of the shape of ``V_rest``.

    Examples
    --------
    >>> V = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]])
    >>> mirrored = V * [-1, 1, 1]
    >>> turned_faces(V, V, [[0, 1, 2]]).tolist(), turned_faces(V, mirrored, [[0, 1, 2]]).tolist()
    ([], [0])
    """
    where = "turned_faces"
    V_rest, F = check_mesh(V_rest, F, where=where, copy=False)
    V_new = check_vertices(V_new, where=where, name="V_new", copy=False)
    if V_new.shape != V_rest.shape:
        raise InvalidMeshError(f"{where}: V_new must have the shape of V_rest {V_rest.shape}, "
                               f"got {V_new.shape}")
    # each in its own power-of-two units (exact: the same signs; beyond 1e154 the products
    # overflowed, inf - inf was NaN and a folded face went uncounted)
    rest, _ = scaled_area_normals(V_rest, F)
    scale = power_of_two_scale(V_new, F)
    return np.flatnonzero(normal_dots(V_new / scale if scale != 1.0 else V_new, F.T,
                                      rest.T) < 0)


def squared_edges(V, F):
    """Squared lengths of the three edges of each face (corner k to corner
    k+1), (m,3)."""
    E = V[F[:, [1, 2, 0]]] - V[F]
    return np.einsum("ijk,ijk->ij", E, E)


def mean_edge_length(V, F, samples=None):
    """Mean length of the edges of the triangles ``F`` over ``V`` (each edge
    counted once per face side; 0.0 without faces), over at most about
    ``samples`` faces taken evenly by index when given (the 2M faces of a
    cage at five levels: 0.9 s for all of them, one thread, where 65k give
    the mean to a fraction of a percent).

    Examples
    --------
    >>> mean_edge_length(np.array([[0., 0, 0], [3, 0, 0], [0, 4, 0]]), np.array([[0, 1, 2]]))
    4.0
    """
    if F.shape[0] == 0:
        return 0.0
    step = 1 if samples is None else max(1, F.shape[0] // max(1, int(samples)))
    return float(np.sqrt(squared_edges(V, F[::step])).mean())


def face_areas(V, F):
    """Per-face areas, (m,) float64 (infinite where beyond the floats, never
    NaN).

    Raises :class:`InvalidMeshError` for a malformed mesh (:func:`check_mesh`)."""
    V, F = check_mesh(V, F, where="face_areas", copy=False)
    N, s = scaled_area_normals(V, F)
    with np.errstate(over="ignore"):
        return 0.5 * row_norms(N) * s * s


def vertex_normals(V, F):
    """Area-weighted, normalised per-vertex normals, (n,3) float64.

    Vertices in no face (or only degenerate faces) get a zero normal; found
    at any scale (:func:`power_of_two_scale`).
    Raises :class:`InvalidMeshError` for a malformed mesh (:func:`check_mesh`).
    """
    V, F = check_mesh(V, F, where="vertex_normals", copy=False)
    n = V.shape[0]
    N, _ = scaled_area_normals(V, F)
    out = np.empty((n, 3))
    for k in range(3):
        out[:, k] = (np.bincount(F[:, 0], N[:, k], n) + np.bincount(F[:, 1], N[:, k], n)
                     + np.bincount(F[:, 2], N[:, k], n))
    return unit_rows(out)


def enclosed_volume(V, F):
    """Signed volume enclosed by a closed, consistently oriented mesh
    (divergence theorem; positive for outward-facing normals).

    Raises :class:`InvalidMeshError` for a malformed mesh (:func:`check_mesh`)."""
    V, F = check_mesh(V, F, where="enclosed_volume", copy=False)
    if F.shape[0] == 0:
        return 0.0
    scale = power_of_two_scale(V, F)          # at 1e150 the products overflowed
    a, b, c = (V[F[:, k]] / scale for k in range(3))
    volume = np.einsum("ij,ij->i", a, cross_rows(b, c)).sum() / 6.0
    with np.errstate(over="ignore"):
        return float(volume * scale * scale * scale)


def has_area(V, F):
    """Whether some face of ``F`` (checked arrays) has an area: more than
    rounding leaves of three collinear corners (:data:`FLAT_FACE`; an exact
    zero test misses collinear corners whose coordinates were rounded).
    Unit-free (coordinates over the box diagonal: no overflow at 1e200);
    ``NORMALS_BLOCK`` faces at a time, stopping at the first block with one
    (an ordinary mesh stops at its first)."""
    lo, hi = bounding_box(V)
    d = diagonal_length(lo, hi)
    if d == 0 or F.shape[0] == 0:            # every corner at one point
        return False
    if not np.isfinite(d):                   # a box beyond the floats: not measured here
        return True
    size = max(float(np.abs(np.concatenate([lo, hi])).max()) / d, 1.0)
    for s in range(0, F.shape[0], NORMALS_BLOCK):
        _, e1, e2 = _corner_edges(V, F[s:s + NORMALS_BLOCK].T)
        e1 /= d
        e2 /= d
        e3 = e2 - e1
        longest2 = np.maximum(np.maximum(np.einsum("ij,ij->i", e1, e1), np.einsum("ij,ij->i", e2, e2)),
                              np.einsum("ij,ij->i", e3, e3))
        twice = np.linalg.norm(cross_rows(e1, e2), axis=1)
        if (twice > FLAT_FACE * size * np.sqrt(longest2)).any():
            return True
    return False


def flat_faces(V, F):
    """(k,) bool per face of ``F`` (k,3): no area, its corners collinear up to
    the rounding of their coordinates (twice its area at most ``FLAT_FACE``
    times its longest edge times its largest coordinate magnitude, as
    :func:`has_area` tells; each face scaled by that magnitude first, so no
    product overflows at 1e200)."""
    P = V[F]                                               # (k,3,3)
    size = np.abs(P).max(axis=(1, 2), initial=0.0)
    P /= np.where(size > 0, size, 1.0)[:, None, None]
    e1, e2 = P[:, 1] - P[:, 0], P[:, 2] - P[:, 0]
    longest = np.sqrt(np.maximum(np.maximum((e1 * e1).sum(axis=1), (e2 * e2).sum(axis=1)),
                                 ((e2 - e1) ** 2).sum(axis=1)))
    return np.linalg.norm(cross_rows(e1, e2), axis=1) <= FLAT_FACE * longest


def barycentric_gather(X, corners, bary):
    """Points blended from the rows of ``X`` (n,d): ``sum_j bary[i, j] *
    X[corners[i, j]]``, (s,d). ``corners`` and ``bary`` are (s,3) (a
    transposed (3,s) array works as well: each column is read once)."""
    out = bary[:, 0:1] * np.take(X, corners[:, 0], axis=0)
    out += bary[:, 1:2] * np.take(X, corners[:, 1], axis=0)
    out += bary[:, 2:3] * np.take(X, corners[:, 2], axis=0)
    return out


def barycentric_scatter(R, corners, bary, n):
    """The adjoint of :func:`barycentric_gather`: every row of ``R`` (s,d)
    spread onto its three corners with its weights, (n,d) sums (one
    ``bincount`` per column)."""
    flat = np.ascontiguousarray(corners.T).ravel()
    w = np.ascontiguousarray(bary.T)
    out = np.empty((n, R.shape[1]))
    for k in range(R.shape[1]):
        out[:, k] = np.bincount(flat, weights=(w * R[:, k]).ravel(), minlength=n)
    return out
