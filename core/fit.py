"""Fit cage positions so that their subdivision surface matches a dense mesh.

Subdivision is linear in the cage positions, ``Vf = S Vc``, so fitting is a
least-squares problem on ``Vc`` once correspondences are fixed. We alternate
(an ICP in the spirit of Lee, Moreton & Hoppe, "Displaced subdivision
surfaces", 2000, and Hoppe et al., "Piecewise smooth surface reconstruction",
1994)::

    X = V_cage
    repeat `iterations` times (each step Anderson-accelerated, below):
        Vf = S X
        q_i      = closest point of fine vertex i on the dense surface    (fine -> dense)
        (f_s, b_s) = closest point of dense sample s on the fine surface  (dense -> fine, so
                                                                           thin parts are seen)
        minimise   sum_i a_i    |(S X)_i - q_i|^2_{M_i}        a_i: fine vertex areas, sum 1
                 + sum_s 1/n_s  |(B S X)_s - p_s|^2_{M_s}      B: barycentric rows (f_s, b_s)
                 + smoothness / n_cage |L (X - V_cage)|^2      L: cage Laplacian (rows sum 0)
                   with |d|^2_M = (d.n)^2 + point_to_point |d|^2, n the dense surface's
                   (interpolated vertex) normal at q_i / p_s (point-to-plane, Chen & Medioni 1992, which
                   converges in a few steps, plus a little point-to-point to hold the
                   tangential drift)
        by conjugate gradients on the normal equations, the matrix applied with
        S.apply / S.apply_transpose (never formed).

The alternation converges linearly (the point-to-point term holds each step's
tangential slide), so each step is *Anderson-accelerated* (Walker & Ni, 2011;
for ICP, Pavlov et al., 2018): of the last ``ANDERSON_DEPTH + 1`` cages ``X_k``
and their solves ``G_k``, the combination of the solves whose residuals
``G_k - X_k`` combine to the least residual; taken when its correspondences are
closer than the last ones, else the plain solve (and the history restarts).

Both data terms are mean squared distances and the Laplacian is normalised
(``L X = X - weighted mean of neighbours``), so ``smoothness`` is unit-free.
Regularising the *change* of the cage (not the cage itself) keeps the cage's
shape without shrinking it, which is the point: QEM cages sit inside convex
regions ("QSlim reduces the size of objects") and the fit moves them back out.
"""

from typing import NamedTuple

import numpy as np

from .cg import conjugate_gradient
from .clean import CleanedInput, clean_mesh
from .errors import InvalidArgumentError, InvalidMeshError
from .mesh import (barycentric_gather, barycentric_scatter, bbox_diagonal, bounding_box,
                   check_mesh, check_number, check_seed, check_units, cross_rows, face_areas,
                   shown, squared_edges, stops, vertex_normals)
from .metrics import MAX_SAMPLES, sample_surface
from .mirror import axis_index, mirror_partners, symmetrize
from ._parallel import run_each
from .near_query import NEEDLE_CELL_FACTOR, needle_grid, search_for
from .spatial import TriangleIndex
from .subdivide import MAX_BOUND_FINE_FACES, cage_operator, check_subdivision_args
from .topology import check_not_soup, edge_map
from .pages import plain_pages

_LAPLACIANS = ("uniform", "cotangent")

#: a ``smoothness`` above this is taken as this: the smoothness term then outweighs the data
#: terms (weights summing to about 1) by more than float64's precision, so the cage stays
#: where it is to rounding, as for any larger value (at 1e200 the solver's sums overflowed)
_SMOOTHNESS_CAP = 1e16

#: most levels a fit is worth evaluating its cage at (the add-on's and the batch's fits
#: take at most these, whatever levels the binding or the refined mesh has): the fit
#: undoes the shrinkage of simplification, which two levels already show. The bunny to
#: 1,400 faces, butterfly, its subdivision at three levels after the fit: fitted at
#: three levels 0.5% closer to the bunny in the mean and 5% farther in Hausdorff
#: distance than fitted at two, in 3.6x the time (6.31 against 1.75 s; 2026-12-06)
MAX_FIT_LEVELS = 2

#: solves an accelerated step of the fit combines besides the last (Anderson's depth;
#: 0: plain alternation). Six steps at depth 3 fit closer than eight plain ones on 14 of
#: 16 fits (the shared meshes to 2,000-face cages, both schemes; the other two 0.03% and
#: 0.08% farther) in 73-78% of the time; depth 5 gave the same distances to 0.1%
ANDERSON_DEPTH = 3

#: most fitting iterations (and a hundred times that, conjugate-gradient steps) taken:
#: more is a mistake (iterations=10**12 ran on and on)
MAX_ITERATIONS = 10_000

#: the dense surface's index has cells at least this many median fine edges wide: the
#: fine vertices it answers lie a fraction of a fine edge from the dense surface, often
#: many dense triangles away, and balls crossing many small cells cost more than larger
#: cells' extra triangles (a 1M-face scan, 2,000-face cage: queries 2.6x faster)
_DENSE_CELL_EDGES = 1.0

#: ... but no wider than this share of the dense mesh's diagonal: a cage far larger
#: than the scan (30x the bunny's size) made the whole scan one cell, and every query a
#: scan of all its triangles (a 500-face cage on the 69k-face bunny: 37 s, now 3.5 s)
_DENSE_CELL_MAX_SHARE = 1 / 8

#: the cotangent Laplacian takes a cage angle's sine to be at least this (a flat face)
_FLAT_ANGLE_SIN = 1e-12


class FitResult(NamedTuple):
    """Fitted cage and the distance record of :func:`fit_cage`."""

    V: np.ndarray               #: (n_cage,3) float64 fitted cage positions
    mean_distance: np.ndarray   #: (k+1,) two-sided mean distance, at the start and after each step kept
    fine_to_dense: np.ndarray   #: (k+1,) area-weighted mean distance fine surface -> dense
    dense_to_fine: np.ndarray   #: (k+1,) mean distance dense samples -> fine surface
    cg_iterations: np.ndarray   #: (k,) CG iterations of each step kept
    diagonal: float             #: bounding-box diagonal of the dense mesh
    cancelled: bool = False     #: True when ``progress`` asked to stop (V is then the last iterate)


@plain_pages
def fit_cage(V_dense, F_dense, V_cage, F_cage, *, levels=2, scheme="butterfly", creases=None,
             iterations=6, smoothness=0.05, point_to_point=0.1, laplacian="uniform",
             samples=None, seed=0, symmetry=None,
             cg_rtol=1e-6, cg_max_iterations=300, progress=None, clean=True):
    """Cage positions whose subdivision surface best matches a dense surface.

    Parameters
    ----------
    V_dense, F_dense : (n,3) float, (m,3) int
        The dense surface to match, cleaned first as ``simplify`` to the
        cage's face count cleans it (:func:`core.clean.clean_mesh` with that
        ``face_budget``: any mesh as scans arrive; the specks too small for
        one face of the cage are debris, as a simplify to it drops them, and
        do not pull the fit).
    V_cage, F_cage : (n_c,3) float, (m_c,3) int
        Starting cage (e.g. :func:`~.simplify.simplify`'s output); its
        topology is kept, only positions change.
    levels, scheme, creases
        Subdivision used to evaluate the cage (as in :func:`~.binding.bind`).
    iterations : int
        Correspondence / solve alternations (>= 0; 0 returns the input),
        each Anderson-accelerated (the module's docstring: six fit closer
        than eight plain ones did, in three quarters of their time). A
        step that would increase the mean distance (its correspondences
        slide, e.g. an open patch drifting off the scan) is undone and the
        fit stops there, so ``k <= iterations`` steps are kept and the
        distance record never rises: the cage returned is never farther
        than the one given. A fit that reaches its fixed point (a solve
        gives the cage back unchanged) stops there, its records filled in as
        the remaining iterations would have repeated them.
    smoothness : float
        Weight (>= 0, unit-free) of the Laplacian of the cage's displacement,
        relative to the mean-squared-distance data terms.
    point_to_point : float
        Weight (>= 0) of the full point-to-point distance added to the
        point-to-plane one in both data terms.
    laplacian : {"uniform", "cotangent"}
        Laplacian weights on the cage (cotangent weights from the input cage).
    samples : int, optional
        Number of area-weighted samples of the dense surface for the
        dense -> fine term (default: twice the number of fine vertices,
        between 5,000 and 200,000).
    seed : int
        Seed of the surface sampling.
    symmetry : {None, 'X', 'Y', 'Z'}
        Keep a mirror-symmetric cage (``simplify(..., symmetry=...)``)
        symmetric about the plane through the origin normal to this axis:
        each solve runs on the symmetric positions only (conjugate gradients
        on the projected system ``P A P``, ``P`` averaging every vertex with
        its partner's mirror image, :func:`core.mirror.symmetrize`), so the
        fit settles between the two sides of a nearly symmetric scan;
        partners are exact mirror images, plane vertices exactly on it.
    cg_rtol, cg_max_iterations
        Stopping rule of each conjugate-gradient solve.
    progress : callable, optional
        Called with the fraction done (0..1) after each iteration; returning
        False stops the fit (``FitResult.cancelled``; the distance records
        then end at the last completed iteration).
    clean : bool
        Clean the dense mesh first (the default). False takes it as it is:
        for a mesh already clean, such as ``simplify``'s
        :attr:`~.simplify.SimplifyResult.cleaned` (``fit_cage(*r.cleaned,
        r.V, r.F, clean=False)``: the surface the collapse saw, not cleaned
        twice). Seams left unwelded then split the normals, and double-sided
        sheets cancel theirs.

    Returns
    -------
    FitResult

    Raises
    ------
    InvalidMeshError
        A mesh is malformed or has no faces.
    InvalidArgumentError
        A parameter is out of range; with ``symmetry``, a cage vertex without
        a mirror partner.

    Examples
    --------
    >>> r = fit_cage(V, F, cage.V, cage.F, levels=2)                  # doctest: +SKIP
    >>> r.mean_distance[-1] < r.mean_distance[0]                      # doctest: +SKIP
    True
    """
    cg_rtol, cg_max_iterations = _check_solver(cg_rtol, cg_max_iterations, progress)
    check_subdivision_args(levels, scheme, "fit_cage")
    pb = _set_up(V_dense, F_dense, V_cage, F_cage, levels=levels, scheme=scheme, creases=creases,
                 smoothness=smoothness, point_to_point=point_to_point, laplacian=laplacian,
                 samples=samples, seed=seed, symmetry=symmetry, iterations=iterations,
                 clean=clean)
    X, m = pb.X0, _match(pb, pb.X0)
    f2d, d2f, cg_its = [m.fine_to_dense], [m.dense_to_fine], []
    cancelled, matched_at = False, None     # (the reach m was matched with)
    anderson = _Anderson(ANDERSON_DEPTH, pb.sym)
    for it in range(int(iterations)):
        X_new, n_cg = _solve(pb, m, X, cg_rtol, cg_max_iterations)
        if progress is not None and stops(progress((it + 1) / (int(iterations) + 1))):
            X, cancelled = X_new, True
            cg_its.append(n_cg)
            break
        if _fixed_point(X, X_new, matched_at, m):
            left = int(iterations) - it      # (each would repeat this one, bit for bit)
            f2d += [m.fine_to_dense] * left
            d2f += [m.dense_to_fine] * left
            cg_its += [n_cg] * left
            break
        X_new, m_new = anderson.step(pb, X, X_new, m)
        if not m_new.mean <= m.mean:   # a step away from the surface (or NaN): undone, and
            break                      # the next would be the same (same correspondences)
        X, m, matched_at = X_new, m_new, m.reach
        f2d.append(m.fine_to_dense)
        d2f.append(m.dense_to_fine)
        cg_its.append(n_cg)
    f2d = np.array(f2d)
    d2f = np.array(d2f)
    # (no step kept: the cage as given, not moved there and back through the working origin)
    V = pb.start if X is pb.X0 else X + pb.centre
    return FitResult(V, 0.5 * (f2d + d2f), f2d, d2f, np.array(cg_its, dtype=np.int64),
                     bbox_diagonal(pb.V_dense), cancelled)


def _dense_index(V, F, fine_edge):
    """The index of the dense surface ``(V, F)`` the fine vertices (median edge
    ``fine_edge``) are matched on, every iteration: cells at least
    ``_DENSE_CELL_EDGES`` fine edges wide (at most ``_DENSE_CELL_MAX_SHARE`` of
    the diagonal), or for a mesh of needles (a CAD part's fans and strips,
    :func:`~.near_query.needle_grid`) cells of
    :data:`~.near_query.NEEDLE_CELL_FACTOR` of its triangles' extents: wide
    cells there hold hundreds of needles each, all bounded for every query
    (a 10k-face CAD cylinder's fine vertices 0.27 -> 0.07 s a match, a 40k-face
    one's 0.63 -> 0.19, for a second build of 0.18 and 0.36 s)."""
    index = TriangleIndex(V, F, min_cell=min(_DENSE_CELL_EDGES * fine_edge,
                                             _DENSE_CELL_MAX_SHARE * bbox_diagonal(V)))
    if needle_grid(index.tables):
        index = TriangleIndex(V, F, cell_factor=NEEDLE_CELL_FACTOR)
    return index


class _Anderson:
    """The fit's Anderson acceleration (module docstring): the last cages and
    their solves, flat, at most ``depth + 1`` of each; ``sym`` the fit's
    symmetric projection (None: none), which an accelerated cage goes
    through again (a combination of mirror-symmetric cages is one, but not
    to the last bit)."""

    def __init__(self, depth, sym=None):
        self.depth, self.sym, self.cages, self.solves = int(depth), sym, [], []

    def step(self, pb, X, G, m):
        """``(X_next, its matches)`` after the solve ``G`` of the cage ``X``
        (matched as ``m``): the accelerated cage when its matches are closer
        than ``m``, else the plain solve ``G`` and its matches (the history
        then restarts from this step)."""
        if self.depth <= 0:
            return G, _match(pb, G, reach=m.reach)
        self.cages = (self.cages + [X.ravel()])[-(self.depth + 1):]
        self.solves = (self.solves + [G.ravel()])[-(self.depth + 1):]
        if len(self.cages) > 1 and np.isfinite(self.solves[-1]).all():   # (NaN: plain, undone)
            X_acc = self._combined().reshape(X.shape)
            X_acc = X_acc if self.sym is None else self.sym(X_acc)
            m_acc = _match(pb, X_acc, reach=m.reach)
            if m_acc.mean <= m.mean:
                return X_acc, m_acc
            self.cages, self.solves = self.cages[-1:], self.solves[-1:]
        return G, _match(pb, G, reach=m.reach)

    def _combined(self):
        """The solves' combination ``G_k - dG gamma``, ``gamma`` the least
        squares fit of the last residual ``G_k - X_k`` by the residuals'
        differences ``dF`` (flat (3 n_c,))."""
        F = np.stack([g - x for g, x in zip(self.solves, self.cages)], axis=1)
        G = np.stack(self.solves, axis=1)
        gamma = np.linalg.lstsq(np.diff(F, axis=1), F[:, -1], rcond=None)[0]
        return G[:, -1] - np.diff(G, axis=1) @ gamma


def _fixed_point(X, X_new, matched_at, m):
    """Whether the fit has reached a fixed point: the solve gave ``X`` back
    bit for bit (``X_new``; a fit that has converged, as on a CAD part whose
    faces the cage's subdivision already lies on: its solves take no
    conjugate-gradient step), and the correspondences ``m`` of ``X`` were
    matched with the reach they give the next match (``matched_at``): that
    match would then find ``m`` again, and every later iteration repeat this
    one (the same solve, the same cage). A 10k-face CAD cylinder's fit to a
    2,000-face cage took 9 matches of 0.5 s each, the last 7 of them
    repeats."""
    return matched_at is not None and matched_at == m.reach and X_new.tobytes() == X.tobytes()


class _Problem(NamedTuple):
    """What every iteration of the fit reads (built once by :func:`_set_up`;
    positions relative to ``centre``)."""

    op: object              #: the cage's SubdivisionOperator
    V_dense: np.ndarray     #: (n,3) the cleaned dense surface
    F_dense: np.ndarray     #: (m,3)
    N_dense: np.ndarray     #: (n,3) its vertex normals
    dense_index: object     #: TriangleIndex of the dense surface
    P: np.ndarray           #: (n_s,3) area-weighted samples of the dense surface
    N_samples: np.ndarray   #: (n_s,3) the dense normals there
    X0: np.ndarray          #: (n_c,3) the starting cage (its Laplacian is the reference)
    laplacian: tuple        #: (rows, cols, weights) of the cage Laplacian L
    lam: float              #: weight of |L (X - X0)|^2 (smoothness / n_c)
    mu: float               #: point-to-point weight
    sym: object             #: the symmetric projection, or None
    centre: np.ndarray      #: (3,) the working origin (dense bounding-box centre)
    start: np.ndarray       #: (n_c,3) the starting cage as given (symmetrized with a symmetry)


def _set_up(V_dense, F_dense, V_cage, F_cage, *, levels, scheme, creases, smoothness,
            point_to_point, laplacian, samples, seed, symmetry, iterations, clean=True):
    """Check the arguments and build the :class:`_Problem`: the dense surface
    cleaned as ``simplify`` to the cage's face count saw it (welded, so vertex
    normals cross seams; without double-sided sheets, whose normals cancel,
    or debris; with ``clean`` False, as given), everything
    moved to the dense bounding-box centre (the result then does not depend
    on where the mesh sits; the CG stopping rule is relative), its samples
    and index, and the cage's operator and Laplacian."""
    V_dense, F_dense = check_mesh(V_dense, F_dense, where="fit_cage",
                                  names=("V_dense", "F_dense"), allow_empty=False)
    V_cage, F_cage = check_mesh(V_cage, F_cage, where="fit_cage", names=("V_cage", "F_cage"),
                                allow_empty=False)
    check_subdivision_args(levels, scheme, "fit_cage", F_cage.shape[0],
                           max_faces=MAX_BOUND_FINE_FACES)
    check_units(V_dense, where="fit_cage", name="V_dense")
    check_units(V_cage, where="fit_cage", name="V_cage")
    if not isinstance(clean, (bool, np.bool_)):
        raise InvalidArgumentError(f"fit_cage: clean must be True or False, not {clean!r}")
    dense = clean_mesh(V_dense, F_dense, face_budget=F_cage.shape[0]) if clean \
        else CleanedInput(V_dense, F_dense)
    if clean and dense.F.shape[0] == 0:       # (check_mesh refused a mesh without faces)
        raise InvalidMeshError(f"fit_cage: nothing of the dense mesh is left after cleaning "
                               f"({dense.report.summary()})")
    check_not_soup(F_cage, V_cage.shape[0], dense.F, dense.V.shape[0], "fit_cage")
    iterations, smoothness, point_to_point = _check_weights(iterations, smoothness,
                                                            point_to_point, laplacian)
    centre = 0.5 * np.add(*bounding_box(dense.V))
    sym = None
    if symmetry is not None:
        k, sym = _symmetric_projection(V_cage, symmetry)
        centre[k] = 0.0          # the mirror plane through the working origin: sym stays linear
        V_cage = sym(V_cage)
    start = V_cage
    V_dense, V_cage = dense.V - centre, V_cage - centre
    op = cage_operator(F_cage, V_cage.shape[0], where="fit_cage", levels=levels, scheme=scheme,
                       creases=creases)
    if samples is None:
        samples = int(np.clip(2 * op.n_fine, 5000, 200000))
    samples = check_number(samples, where="fit_cage", name="samples", lo=1, hi=MAX_SAMPLES,
                           integer=True)
    sampled = sample_surface(V_dense, dense.F, samples, seed=check_seed(seed, where="fit_cage"))
    index = _dense_index(V_dense, dense.F, _typical_edge(op.apply(V_cage), op.F_fine))
    N_dense = vertex_normals(V_dense, dense.F)
    return _Problem(op, V_dense, dense.F, N_dense, index,
                    np.asarray(sampled.points, dtype=np.float64),
                    _interpolate(N_dense, dense.F, sampled.face, sampled.bary), V_cage,
                    _laplacian(V_cage, F_cage, laplacian),
                    min(float(smoothness), _SMOOTHNESS_CAP) / V_cage.shape[0],
                    float(point_to_point), sym, centre, start)


def _check_weights(iterations, smoothness, point_to_point, laplacian):
    """The settings as numbers, checked (:class:`~.errors.InvalidArgumentError`
    for a setting of the wrong kind or out of range: an infinite smoothness
    returned the cage unfitted, a string one a TypeError deep inside)."""
    if laplacian not in _LAPLACIANS:
        raise InvalidArgumentError(
            f"fit_cage: laplacian must be one of {_LAPLACIANS}, got {shown(laplacian)}")
    return (check_number(iterations, where="fit_cage", name="iterations", lo=0,
                         hi=MAX_ITERATIONS, integer=True),
            check_number(smoothness, where="fit_cage", name="smoothness", lo=0),
            check_number(point_to_point, where="fit_cage", name="point_to_point", lo=0))


def _check_solver(cg_rtol, cg_max_iterations, progress):
    """The conjugate-gradient settings, checked, and ``progress`` callable or
    None (it was first called after a whole iteration)."""
    if progress is not None and not callable(progress):
        raise InvalidArgumentError(
            f"fit_cage: progress must be callable or None, got {type(progress).__name__}")
    return (check_number(cg_rtol, where="fit_cage", name="cg_rtol", lo=0, hi=1, open_lo=True,
                         open_hi=True),
            check_number(cg_max_iterations, where="fit_cage", name="cg_max_iterations", lo=1,
                         hi=MAX_ITERATIONS * 100, integer=True))


class _Matches(NamedTuple):
    """One iteration's correspondences (:func:`_match`) and its distances."""

    area: np.ndarray     #: (n_fine,) the fine vertices' area shares (sum 1)
    near: object         #: ClosestPoints of the fine vertices on the dense surface
    hit: object          #: ClosestPoints of the dense samples on the fine surface

    @property
    def fine_to_dense(self):
        """Area-weighted mean distance of the fine vertices to the dense surface."""
        return float(np.dot(self.area, self.near.distance))

    @property
    def dense_to_fine(self):
        """Mean distance of the dense samples to the fine surface."""
        return float(np.mean(self.hit.distance))

    @property
    def mean(self):
        """The two-sided mean distance (``FitResult.mean_distance``)."""
        return 0.5 * (self.fine_to_dense + self.dense_to_fine)

    @property
    def reach(self):
        """The dense samples' median distance to the fine surface: the next
        iteration's search over the fine surface takes cells at least
        :func:`~.near_query.cell_for_reach` of it wide. Its cells are set
        by the fine triangles, and where they are far smaller than the gaps
        (a gravel scan's pebbles, each a tetrahedron of the cage and a
        small blob of the fine surface inside it) most samples lay beyond
        the cells around their own (the search's slow path; the answers are
        the same, exact, either way)."""
        return float(np.median(self.hit.distance))


def _match(pb, X, reach=None):
    """The correspondences of the cage ``X``: each fine vertex's closest
    point on the dense surface (weighted by its area share) and each dense
    sample's closest point on the fine surface (``reach``: the samples'
    typical distance from it, when known, :attr:`_Matches.reach`)."""
    Vf = pb.op.apply(X)
    Ff = pb.op.F_fine
    area = _vertex_areas(Vf, Ff, pb.op.n_fine)
    total = area.sum()
    area = area / total if total > 0 else np.full(pb.op.n_fine, 1.0 / pb.op.n_fine)
    # the two searches do not depend on each other, and each answers its points on one
    # thread: side by side on the worker threads (each point's answer is its own)
    to_dense, hit = run_each(lambda search: search(), [
        lambda: pb.dense_index.closest(Vf),
        lambda: search_for(Vf, Ff, pb.P.shape[0], reach=reach).closest(pb.P)])
    return _Matches(area, to_dense, hit)


def _metric(mu, N, Y):
    """``(mu I + n n^T) y`` per row: point-to-plane plus a little point-to-point."""
    return mu * Y + N * np.einsum("ij,ij->i", N, Y)[:, None]


def _solve(pb, m, X, cg_rtol, cg_max_iterations):
    """Minimise the module docstring's energy for the correspondences ``m``
    by conjugate gradients from ``X`` (preconditioned by the inverses of
    the lumped 3x3 blocks, :func:`_inverse_blocks`; on the symmetric
    positions when the fit keeps a symmetry): (the new cage, CG iterations)."""
    n_c = pb.X0.shape[0]
    rows, cols, w = pb.laplacian
    A, rhs, blocks = _normal_equations(pb, m)
    inv = _inverse_blocks(blocks, pb.lam * _lt_l_diagonal(rows, cols, w, n_c))
    precondition = lambda r: np.einsum("nij,nj->ni", inv, r.reshape(n_c, 3)).ravel()  # noqa: E731
    if pb.sym is not None:
        A, rhs, precondition = _restricted(pb.sym, A, rhs, precondition, n_c)
    sol = conjugate_gradient(A, rhs.ravel(), X0=X.ravel(), rtol=cg_rtol,
                             max_iterations=cg_max_iterations, preconditioner=precondition)
    X = sol.X.reshape(n_c, 3)
    return (X if pb.sym is None else pb.sym(X)), sol.iterations


def _normal_equations(pb, m):
    """The normal equations of the module docstring's energy for the
    correspondences ``m``: the map ``A`` (flat (3 n_c,) -> (3 n_c,)), the
    right-hand side (n_c,3), and the lumped 3x3 blocks (n_c,3,3) of the
    data terms (each block row of ``A``'s data part summed: ``S 1 = 1`` and
    ``B 1 = 1``, so ``sum_i S_ij a_i M_i`` and the samples' alike; the
    Laplacian's rows sum to 0)."""
    op, n_c, ws = pb.op, pb.X0.shape[0], 1.0 / pb.P.shape[0]
    rows, cols, w = pb.laplacian
    N_near = _interpolate(pb.N_dense, pb.F_dense, m.near.face, m.near.bary)
    corners = op.F_fine[np.asarray(m.hit.face, dtype=np.int64)]
    bary = np.asarray(m.hit.bary, dtype=np.float64)

    def B_t(Z):
        return barycentric_scatter(Z, corners, bary, op.n_fine)

    def A(x):
        Xc = x.reshape(n_c, 3)
        Y = op.apply(Xc)
        G = m.area[:, None] * _metric(pb.mu, N_near, Y) \
            + B_t(ws * _metric(pb.mu, pb.N_samples, barycentric_gather(Y, corners, bary)))
        return (op.apply_transpose(G) + pb.lam * _lt_l(rows, cols, w, n_c, Xc)).ravel()

    rhs = (op.apply_transpose(m.area[:, None] * _metric(pb.mu, N_near, m.near.point)
                              + B_t(ws * _metric(pb.mu, pb.N_samples, pb.P)))
           + pb.lam * _lt_l(rows, cols, w, n_c, pb.X0))
    blocks = op.apply_transpose(_metric_blocks(pb.mu, N_near, m.area)
                                + B_t(_metric_blocks(pb.mu, pb.N_samples, ws)))
    return A, rhs, blocks.reshape(n_c, 3, 3)


def _metric_blocks(mu, N, weight):
    """(k, 9) rows of the 3x3 metrics ``weight (mu I + n n^T)`` (``weight``
    (k,) or a number)."""
    M = N[:, :, None] * N[:, None, :]
    M[:, [0, 1, 2], [0, 1, 2]] += mu
    M *= np.reshape(weight, (-1, 1, 1))
    return M.reshape(-1, 9)


def _inverse_blocks(blocks, diagonal):
    """The inverses (n,3,3) of the lumped blocks ``blocks`` (n,3,3, symmetric)
    plus ``diagonal`` (n,) times the identity, each first raised, where
    needed, so that its Gershgorin bound (:func:`_gershgorin_lowest`) is at
    least 1e-3 of the largest mean diagonal: a vertex no sample sees, or a
    butterfly stencil's negative weights, leave a block singular, indefinite
    or nearly so (raised to its exact smallest eigenvalue instead, the
    butterfly fits of the shared meshes took up to 50% more steps than with
    the isotropic diagonal, fandisk's 287 against 210; with this bound 130).

    The isotropic lumped diagonal (``1 + mu`` in every direction) took the
    point-to-plane metric's weak tangential directions (``mu``) for strong
    ones: a gravel scan's fit (2,000 pebbles, each a tetrahedron of the
    cage) took 45-65 conjugate-gradient steps a solve, 27-39 with these
    blocks; the shared meshes' fits about a third fewer too (the fits'
    distances the same to 1e-6)."""
    B = blocks + diagonal[:, None, None] * np.eye(3)
    floor = 1e-3 * max(float(np.einsum("nii->n", B).max()) / 3.0, 1e-300)
    B += np.maximum(floor - _gershgorin_lowest(B), 0.0)[:, None, None] * np.eye(3)
    return np.linalg.inv(B)


def _gershgorin_lowest(B):
    """A lower bound (n,) of the eigenvalues of each block of ``B`` (n,3,3):
    the smallest diagonal entry less the rest of its row's magnitudes."""
    d = np.einsum("nii->ni", B)
    return (d - (np.abs(B).sum(axis=2) - np.abs(d))).min(axis=1)


def _symmetric_projection(V_cage, symmetry):
    """``(axis, P)``: the axis index and the projection ``P`` of an (n,3)
    array onto positions mirror-symmetric about the plane through the
    origin normal to that axis (each vertex averaged with its partner's
    mirror image; symmetric and idempotent)."""
    k = axis_index(symmetry, "fit_cage")
    partner = mirror_partners(V_cage, symmetry, where="fit_cage")
    return k, lambda X: symmetrize(X, partner, k)


def _restricted(P, A, rhs, precondition, n):
    """``P A P``, ``P rhs`` and ``P M P`` for conjugate gradients on the
    range of the projection ``P`` (symmetric and idempotent)."""
    def flat(f):
        return lambda x: P(f(P(x.reshape(n, 3)).ravel()).reshape(n, 3)).ravel()
    return flat(A), P(rhs.reshape(n, 3)), flat(precondition)


def _interpolate(N, F, face, bary):
    """Unit normals blended from vertex normals ``N`` at barycentric points
    (continuous across edges and vertices, unlike face normals); a zero blend
    stays zero (that point then only has the point-to-point term)."""
    corners = F[np.asarray(face, dtype=np.int64)]
    out = barycentric_gather(N, corners, np.asarray(bary, dtype=np.float64))
    length = np.linalg.norm(out, axis=1)
    return np.divide(out, length[:, None], out=np.zeros_like(out), where=length[:, None] > 1e-12)


def _typical_edge(V, F):
    """Median length of the edges of the triangles ``F`` (each counted once
    per face side); the smallest positive float for a mesh of points. (The
    mean was set by a scan's spike: a vertex 1,000 diagonals off, its cage
    faces' long fine edges made the dense index's cells 13x wider, and the
    bunny's fit took 182 s.)"""
    return max(float(np.median(np.sqrt(squared_edges(V, F)))), np.finfo(float).tiny)


def _vertex_areas(V, F, n):
    """One third of the area of the faces around each vertex, (n,)."""
    A3 = face_areas(V, F) / 3.0
    return np.bincount(F[:, 0], A3, n) + np.bincount(F[:, 1], A3, n) + np.bincount(F[:, 2], A3, n)


def _laplacian(V, F, kind):
    """Triplets of the normalised Laplacian ``(L X)_i = X_i - sum_j w_ij X_j``
    with ``sum_j w_ij = 1`` (uniform or clamped-positive cotangent weights)."""
    n = V.shape[0]
    em = edge_map(F, n)
    E = em.E
    if kind == "uniform":
        w = np.ones(E.shape[0])
    else:
        # cotangent of the angle at corner c, accumulated on the opposite edge; a flat
        # angle's |cross| is floored relative to |u| |v| (cotangents within 1e12: an
        # absolute floor made them overflow from cages 1e4 wide), 1e-300 for a point
        w = np.zeros(E.shape[0])
        for c in range(3):
            p = V[F[:, c]]
            u = V[F[:, (c + 1) % 3]] - p
            v = V[F[:, (c + 2) % 3]] - p
            cr = np.linalg.norm(cross_rows(u, v), axis=1)
            floor = _FLAT_ANGLE_SIN * np.linalg.norm(u, axis=1) * np.linalg.norm(v, axis=1)
            cot = np.einsum("ij,ij->i", u, v) / np.maximum(np.maximum(cr, floor), 1e-300)
            w += np.bincount(em.face_edge[:, c], 0.5 * cot, E.shape[0])
        # clamp: negative cotangent weights (obtuse cages) would make the
        # normalised rows unstable; a tiny positive floor keeps every neighbour
        w = np.maximum(w, 1e-3 * max(float(np.median(np.abs(w))), 1e-300))
    rows = np.concatenate([E[:, 0], E[:, 1]])
    cols = np.concatenate([E[:, 1], E[:, 0]])
    ww = np.concatenate([w, w])
    total = np.bincount(rows, ww, n)
    has = total > 0
    ww = ww / np.where(has, total, 1.0)[rows]
    diag_rows = np.arange(n, dtype=np.int64)
    return (np.concatenate([diag_rows, rows]), np.concatenate([diag_rows, cols]),
            np.concatenate([has.astype(np.float64), -ww]))


def _sparse_apply(rows, cols, w, n, X):
    out = np.empty((n, X.shape[1]))
    for k in range(X.shape[1]):
        out[:, k] = np.bincount(rows, w * X[cols, k], n)
    return out


def _lt_l(rows, cols, w, n, X):
    """``L^T L X`` from the triplets of ``L``."""
    return _sparse_apply(cols, rows, w, n, _sparse_apply(rows, cols, w, n, X))


def _lt_l_diagonal(rows, cols, w, n):
    """Diagonal of ``L^T L``: column sums of squared entries."""
    return np.bincount(cols, w * w, n)
