"""How far apart two surfaces are: the Metro method, in pure NumPy.

Cignoni, Rocchini, Scopigno, *Metro: measuring error on simplified surfaces*
(Computer Graphics Forum 17(2), 1998). Each surface is sampled (area-weighted,
uniform on every triangle) and every sample, plus every vertex, is sent to the
exact closest point on the other surface (:func:`~.near_query.search_for`)::

    A --samples + vertices--> closest point on B  ->  d_AB (max, mean, rms)
    B --samples + vertices--> closest point on A  ->  d_BA (max, mean, rms)
    Hausdorff = max(max d_AB, max d_BA)

Maxima use the samples and the vertices (vertices catch spikes and corners);
means and RMS use only the area-weighted samples, so they estimate the surface
integrals without a bias towards densely meshed regions. The two-sided mean
and RMS are the larger of the two one-sided values (like the Hausdorff
distance), so the measure is symmetric. Errors are reported in mesh units and
as a percentage of the bounding-box diagonal of mesh A (the original).

Uniform sampling of a triangle uses the square-root trick (Osada et al. 2002):
with ``r1, r2`` uniform in [0,1) and ``s = sqrt(r1)``, the barycentric
coordinates ``(1 - s, s (1 - r2), s r2)`` are uniform over the triangle.
"""

from typing import NamedTuple

import math

import numpy as np

from .errors import InvalidArgumentError
from .mesh import (bbox_diagonal, check_mask, check_mesh, check_number, check_seed, check_units,
                   mean_edge_length, row_norms, scaled_area_normals, used_vertices)
from .near_query import NearQuery, cell_for_reach, search_for, search_kind
from .spatial import TriangleIndex
from .pages import plain_pages

__all__ = ["DistanceFrom", "SurfaceSamples", "SurfaceDistance", "percent", "sample_surface",
           "surface_distance"]

#: most samples drawn on a surface (1.2 GB of points and their faces; more was a MemoryError
#: of 74.5 GiB, or minutes of work, for a mistyped count)
MAX_SAMPLES = 50_000_000
#: default samples per surface: 2 per face of the larger mesh, clipped to this range (a
#: 1M-triangle comparison stays fast)
_DEFAULT_SAMPLES = (10_000, 200_000)
#: the reverse side's index (few queries on a large mesh) takes cells sized for the other
#: side's mean distance when they are at most this many of its mean edges wide: the 2M-face
#: torus against its 2,000-face cage, 60k samples, 3.4 -> 1.8-2.3 s (cells 1.4-2x the default, the
#: queries answered in the grid, not in a hierarchy built for them); wider, the default
#: (the bunny against a 50-face cage: cells of 32 edges, 1.2 -> 4.5 s)
_REACH_CELL_EDGES = 6.0


class SurfaceSamples(NamedTuple):
    """Points drawn on a triangle mesh: ``points`` (n,3) float64, ``face`` (n,) int64,
    ``bary`` (n,3) float64 (``points == bary @ V[F[face]]``)."""
    points: np.ndarray
    face: np.ndarray
    bary: np.ndarray


class SurfaceDistance(NamedTuple):
    """Two-sided distance between surfaces A and B, in mesh units.

    hausdorff : max(a_to_b_max, b_to_a_max).
    mean, rms : the larger of the one-sided area-weighted means / RMS.
    a_to_b_max, a_to_b_mean : from A's samples and vertices to B (B's to A likewise).
    diagonal : bounding-box diagonal of A's referenced vertices.
    a_to_b_rms, b_to_a_rms : one-sided RMS.
    n_samples : area-weighted samples drawn on each surface.
    """
    hausdorff: float
    mean: float
    rms: float
    a_to_b_max: float
    a_to_b_mean: float
    b_to_a_max: float
    b_to_a_mean: float
    diagonal: float
    a_to_b_rms: float = 0.0
    b_to_a_rms: float = 0.0
    n_samples: int = 0

    @property
    def hausdorff_pct(self):
        """Hausdorff distance in % of A's bounding-box diagonal."""
        return _pct(self.hausdorff, self.diagonal)

    @property
    def mean_pct(self):
        """Two-sided mean distance in % of A's bounding-box diagonal."""
        return _pct(self.mean, self.diagonal)

    @property
    def rms_pct(self):
        """Two-sided RMS distance in % of A's bounding-box diagonal."""
        return _pct(self.rms, self.diagonal)


#: :func:`percent` writes at most this many decimals (below, "under 0.000001%")
_PERCENT_DECIMALS = 6


def percent(share):
    """``share`` (a fraction of a size, e.g. a distance over the diagonal) as
    a percentage a reader can use: two decimals, or two significant digits
    below 0.1% ("0.30%", "0.035%", "0.00080%": a CAD part's cage 8e-6 of its
    size off read "0.00%"), "0%" for none, "under 0.000001%" below that.

    >>> percent(0.0065), percent(3.5e-4), percent(8e-6)
    ('0.65%', '0.035%', '0.00080%')
    """
    value = 100.0 * share
    if value == 0:
        return "0%"
    if not math.isfinite(value):
        return f"{value}%"
    decimals = max(2, 1 - math.floor(math.log10(abs(value))))
    if decimals > _PERCENT_DECIMALS:
        return f"under {10.0 ** -_PERCENT_DECIMALS:.{_PERCENT_DECIMALS}f}%"
    return f"{value:.{decimals}f}%"


def _pct(value, diagonal):
    if diagonal > 0:
        return 100.0 * value / diagonal
    return 0.0 if value == 0 else float("inf")


def _sample(V, F, n, rng):
    """Area-weighted uniform samples on a checked mesh (faces uniformly if zero area)."""
    # (areas in power-of-two units: the same draws; beyond 1e154 they overflowed and every
    # sample fell on one face, below 1e-160 they were all zero)
    area = row_norms(scaled_area_normals(V, F)[0])
    cum = np.cumsum(area)
    total = float(cum[-1])
    if total > 0:
        face = np.searchsorted(cum, rng.random(n) * total, side="right")
        face = np.minimum(face, F.shape[0] - 1)
    else:
        face = rng.integers(0, F.shape[0], size=n)
    r = rng.random((n, 2))
    s = np.sqrt(r[:, 0])
    bary = np.stack([1.0 - s, s * (1.0 - r[:, 1]), s * r[:, 1]], axis=1)
    T = V[F[face]]
    points = np.einsum("ij,ijk->ik", bary, T)
    return SurfaceSamples(points, face.astype(np.int64), bary)


@plain_pages
def sample_surface(V, F, n_samples, *, seed=0):
    """Draw points uniformly (area-weighted) on a triangle mesh.

    Parameters
    ----------
    V : (n, 3) array_like of float
    F : (m, 3) array_like of int, m >= 1.
    n_samples : int >= 0
    seed : int or None
        Seed of ``numpy.random.default_rng``; the same seed gives the same samples.

    Returns
    -------
    SurfaceSamples
        ``points`` (n_samples,3), ``face`` (n_samples,) int64, ``bary`` (n_samples,3).
        A face is chosen with probability proportional to its area (uniformly when
        the whole mesh has zero area), then a point uniformly inside it.

    Raises
    ------
    InvalidMeshError
        Bad mesh or no faces.
    InvalidArgumentError
        ``n_samples`` not an integer >= 0.

    Examples
    --------
    >>> s = sample_surface([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]], 4, seed=1)
    >>> s.points.shape, bool((s.bary >= 0).all())
    ((4, 3), True)
    """
    V, F = check_mesh(V, F, where="sample_surface", allow_empty=False)
    n = check_number(n_samples, where="sample_surface", name="n_samples", lo=0, hi=MAX_SAMPLES,
                     integer=True)
    return _sample(V, F, n, np.random.default_rng(check_seed(seed, where="sample_surface")))


def _checked_shared(shared, m_a, m_b):
    """``(on_a, on_b)`` of :meth:`DistanceFrom.to`'s ``shared`` as (m_a,) and
    (m_b,) booleans ((None, None) for None), or
    :class:`~.errors.InvalidArgumentError` naming what is wrong."""
    if shared is None:
        return None, None
    if not isinstance(shared, (tuple, list)) or len(shared) != 2:
        raise InvalidArgumentError(f"surface_distance: shared must be a pair (on_a, on_b) of face "
                                   f"masks, got {type(shared).__name__}")
    return (check_mask(shared[0], m_a, where="surface_distance", name="shared[0]",
                       per="face of mesh a"),
            check_mask(shared[1], m_b, where="surface_distance", name="shared[1]",
                       per="face of mesh b"))


class _Side(NamedTuple):
    """What one side of :meth:`DistanceFrom.to` searches: sample points,
    vertex indices, and the counts of all its samples and vertices (those
    left out on shared faces count as distance 0)."""

    points: np.ndarray
    vertices: np.ndarray
    counts: tuple


def _unshared(samples, F, used, shared):
    """The :class:`_Side` of a mesh's ``samples`` (SurfaceSamples) and
    ``used`` vertices, without those on its ``shared`` faces alone (None:
    every one)."""
    counts = (samples.points.shape[0], used.shape[0])
    if shared is None:
        return _Side(samples.points, used, counts)
    on_other = np.zeros(int(F.max()) + 1, dtype=bool)        # (F has faces: checked)
    on_other[F[~shared].ravel()] = True
    return _Side(samples.points[~shared[samples.face]], used[on_other[used]], counts)


def _one_side(index, P_samples, P_vertices, counts=None):
    """(max, mean, rms) of the distances of ``P_samples`` and ``P_vertices``
    to ``index``; ``counts``: the samples' and vertices' counts the means
    are over (more than given: the others at distance 0; None: as given)."""
    n_s, n_v = counts if counts is not None else (P_samples.shape[0], P_vertices.shape[0])
    d_s = index.closest(P_samples).distance if P_samples.shape[0] else np.zeros(0)
    d_v = index.closest(P_vertices).distance if P_vertices.shape[0] else np.zeros(0)
    dmax = float(max(d_s.max(initial=0.0), d_v.max(initial=0.0)))
    if n_s:                    # (np.mean's sum and division: the same bits)
        mean = float(np.sum(d_s) / n_s)
        rms = float(np.sqrt(np.sum(d_s * d_s) / n_s))
    else:                      # no samples asked for: fall back to the vertices
        mean = float(np.sum(d_v) / n_v)
        rms = float(np.sqrt(np.sum(d_v * d_v) / n_v))
    return dmax, mean, rms


@plain_pages
def surface_distance(V_a, F_a, V_b, F_b, *, samples=None, seed=0):
    """Two-sided Hausdorff, mean and RMS distance between two triangle meshes (Metro).

    Parameters
    ----------
    V_a, F_a : the first mesh (the original; its diagonal scales the percentages).
    V_b, F_b : the second mesh (e.g. the simplified one).
    samples : int >= 0 or None
        Area-weighted samples drawn on *each* surface, in addition to its vertices.
        None: 2 per face of the larger mesh, clipped to [10,000, 200,000].
    seed : int or None
        Sampling seed (both surfaces use it, so swapping A and B swaps the one-sided
        results exactly).

    Returns
    -------
    SurfaceDistance
        ``hausdorff, mean, rms, a_to_b_max, a_to_b_mean, b_to_a_max, b_to_a_mean,
        diagonal, a_to_b_rms, b_to_a_rms, n_samples``; properties ``hausdorff_pct``,
        ``mean_pct``, ``rms_pct`` (% of A's bounding-box diagonal).

    Raises
    ------
    InvalidMeshError
        A mesh is malformed or has no faces.
    InvalidArgumentError
        ``samples`` not an integer >= 0.

    Examples
    --------
    >>> V = [[0, 0, 0], [1, 0, 0], [0, 1, 0]]
    >>> d = surface_distance(V, [[0, 1, 2]], [[0, 0, 1], [1, 0, 1], [0, 1, 1]], [[0, 1, 2]])
    >>> round(d.hausdorff, 12), round(d.mean, 12)
    (1.0, 1.0)
    """
    return DistanceFrom(V_a, F_a).to(V_b, F_b, samples=samples, seed=seed)


class DistanceFrom:
    """:func:`surface_distance` from one mesh ``A`` to many: what depends on
    ``A`` alone (its checks, used vertices and diagonal, its samples for each
    count and seed, its closest-point search of each kind) is made once and
    kept. ``simplify(max_error=...)`` measures each step's cage against the
    cleaned input: the 1.1M-face bunny x16's index took 1.35 s of each of
    its six measures at 0.5%. The results are :func:`surface_distance`'s, bit
    for bit (it is ``DistanceFrom(V_a, F_a).to(V_b, F_b)``).

    Parameters
    ----------
    V_a, F_a : the mesh measured from (the original; its diagonal scales the
        percentages). Kept by reference as checked: not to be changed while
        in use.

    Raises
    ------
    InvalidMeshError
        The mesh is malformed or has no faces.

    Examples
    --------
    >>> a = DistanceFrom([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]])
    >>> round(a.to([[0, 0, 1], [1, 0, 1], [0, 1, 1]], [[0, 1, 2]]).hausdorff, 12)
    1.0
    """

    def __init__(self, V_a, F_a):
        self.V, self.F = check_mesh(V_a, F_a, where="surface_distance (mesh a)", allow_empty=False)
        self._used = used_vertices(self.F, self.V.shape[0])
        # (the faces' vertices: a loose vertex at 1e20 beside a scan refused the add-on's
        # report of its simplify, which left it out)
        on_faces = self.V[self._used]
        check_units(on_faces, where="surface_distance", name="mesh a")
        self.diagonal = bbox_diagonal(on_faces)
        self._samples = {}                  # (count, seed) -> SurfaceSamples
        self._searches = {}                 # kind -> search

    def to(self, V_b, F_b, *, samples=None, seed=0, shared=None):
        """:func:`surface_distance` from ``A`` to the mesh ``V_b``, ``F_b``
        (same parameters, same result).

        ``shared``: ``(on_a, on_b)``, (m_a,) and (m_b,) bool, the faces of
        each mesh that are faces of the other too (the same three corner
        positions, bit for bit), or None. Their samples, and the vertices on
        them alone, lie on the other surface: they count as distance 0 and
        are not searched (a cage that keeps most of its input, measured in
        the time of what changed: the bunny jittered by 1% of its size, to
        ``max_error`` 0.5%, 21.5 -> 2.9-3.3 s). The maxima are those of the
        search of every sample (whose distance there is 0, or a rounding
        step of it), the means and RMS to rounding. The masks are the
        caller's word: a face called shared that is not is measured as 0."""
        V_b, F_b = check_mesh(V_b, F_b, where="surface_distance (mesh b)", allow_empty=False)
        used_b = used_vertices(F_b, V_b.shape[0])
        check_units(V_b[used_b], where="surface_distance", name="mesh b")
        if samples is None:
            n = int(np.clip(2 * max(self.F.shape[0], F_b.shape[0]), *_DEFAULT_SAMPLES))
        else:
            n = check_number(samples, where="surface_distance", name="samples", lo=0,
                             hi=MAX_SAMPLES, integer=True)
        seed = check_seed(seed, where="surface_distance")
        s_a = self._sampled(n, seed)
        s_b = _sample(V_b, F_b, n, np.random.default_rng(seed))
        on_a, on_b = _checked_shared(shared, self.F.shape[0], F_b.shape[0])
        a_side = _unshared(s_a, self.F, self._used, on_a)
        b_side = _unshared(s_b, F_b, used_b, on_b)
        ab_max, ab_mean, ab_rms = _one_side(
            search_for(V_b, F_b, a_side.points.shape[0] + a_side.vertices.shape[0]),
            a_side.points, self.V[a_side.vertices], a_side.counts)
        ba_max, ba_mean, ba_rms = _one_side(
            self._search(b_side.points.shape[0] + b_side.vertices.shape[0], ab_mean),
            b_side.points, V_b[b_side.vertices], b_side.counts)
        return SurfaceDistance(
            hausdorff=max(ab_max, ba_max), mean=max(ab_mean, ba_mean), rms=max(ab_rms, ba_rms),
            a_to_b_max=ab_max, a_to_b_mean=ab_mean, b_to_a_max=ba_max, b_to_a_mean=ba_mean,
            diagonal=self.diagonal, a_to_b_rms=ab_rms, b_to_a_rms=ba_rms, n_samples=n)

    def _sampled(self, n, seed):
        """``A``'s ``n`` samples drawn with ``seed`` (kept)."""
        if (n, seed) not in self._samples:
            self._samples[(n, seed)] = _sample(self.V, self.F, n, np.random.default_rng(seed))
        return self._samples[(n, seed)]

    def _search(self, n_queries, reach):
        """``A``'s closest-point search for ``n_queries`` points (kept per
        kind, as :func:`~.near_query.search_for` makes it: a
        :class:`~.near_query.NearQuery` told the first call's count, which
        sizes a mesh of needles' cells); a :class:`~.spatial.TriangleIndex`
        (fewer queries than faces) with cells for queries ``reach`` away (the
        other side's mean distance) when that is within ``_REACH_CELL_EDGES``
        of ``A``'s mean edges (the same distances either way)."""
        kind = search_kind(self.F.shape[0], n_queries)
        if kind is NearQuery and kind not in self._searches:
            self._searches[kind] = NearQuery(self.V, self.F, queries=n_queries)
        elif kind not in self._searches:
            cell = cell_for_reach(reach)
            if cell and cell > _REACH_CELL_EDGES * mean_edge_length(self.V, self.F, 65536):
                cell = None
            self._searches[kind] = TriangleIndex(self.V, self.F, min_cell=cell)
        return self._searches[kind]
