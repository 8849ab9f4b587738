"""Quadric edge-collapse simplification in vectorised batches.

Garland & Heckbert, "Surface simplification using quadric error metrics"
(SIGGRAPH 1997) and Garland's thesis (1999) for the quadrics, boundary
constraint planes and the compactness term; Dey, Edelsbrunner, Guha and
Nekhayev, "Topology preserving edge contraction" (1999) for the link
condition. Instead of a sequential heap, collapses are applied in batches
of independent edges, each batch checked on the mesh as it is::

    clean the input; freeze non-manifold edges and vertices
    Q[v] = sum of area-weighted face planes (+ boundary and crease planes)
    repeat (one pass):
        cost the edges around vertices moved by the last pass (cached
        otherwise): Q = Q[a] + Q[b], x = argmin Q (3x3 solve), err = Q(x)
        pool = the cheapest edges (a bounded share: never much costlier
               than the cheapest remaining ones), split into cost bands
        repeat (rounds):
            pick pool edges whose priority (band, then a fixed hash) is the
            smallest within two rings, so their stars -- the faces around
            both endpoints -- are disjoint
            check each on the current mesh: link condition, no flipped or
            near-degenerate face, no face turned > 90 deg from the summed
            input normals it stands for; add the compactness penalty and a
            Hausdorff-aware one (distance of the merged vertices' witnesses,
            the input points they stood for that lay farthest from the
            surface, to the new faces)
            accept those still within the pool's cost bound, lock their stars
        apply every accepted collapse with one remap (b -> a, V[a] = x,
        Q[a] += Q[b]); glue the half-edge twins of the removed faces
    until the target, the error bound, or no valid collapse
    move the unlocked cage vertices towards the input surface, both ways, and
    its borders onto the input's (``core._relocate``)

The mesh is kept as faces plus a half-edge twin table (``core._clean``), which
collapses update locally: no sort after the first one.

Units: the mesh is moved to its bounding-box centre and scaled to a unit
diagonal before anything else, so the result does not depend on the units.
"""

from dataclasses import dataclass

import numpy as np

from ._clean import BOUNDARY, clean_with_twins, non_manifold_vertices, spatial_order
from ._collapse import State, _ends, run
from ._relax import close_triangular_holes, drop_stuck_components
from ._relocate import relocate, segment_triangles
from .errors import InvalidArgumentError
from .mesh import bounding_box, check_mesh
from .quadrics import _accumulate_T, _vertex_face_quadrics, edge_constraint_quadrics
from .spatial import TriangleIndex

_WHERE = "simplify"


@dataclass(frozen=True)
class Tuning:
    """Every constant of the algorithm in one place (all unit-free)."""

    area_power: float = 0.5          #: face plane weight = area^p * mean area^(1-p)
    boundary_weight: float = 100.0   #: boundary plane weight, times the edge length squared
    feature_weight: float = 3.0      #: crease plane weight, times the edge length squared
    pool_share: float = 0.2          #: at most this share of the candidate edges per pass
    pool_goal_factor: float = 1.5    #: ... and at most this many times the collapses still needed
    max_rounds: int = 4              #: selection rounds per pass
    bands: int = 8                   #: cost bands of the pool (random order inside a band)
    flip_cos: float = 0.0            #: reject if a face normal turns by more than acos(flip_cos)
    #: ... or ends farther than acos(ref_cos) from the summed normals of the input it
    #: stands for (-1: off; 0, i.e. 90 degrees, keeps rough scans collapsing; stricter stalls them)
    ref_cos: float = 0.0
    gamma_hard: float = 0.02         #: reject new triangles less compact than this (and than before)
    gamma_soft: float = 0.3          #: penalise new triangles less compact than this
    compact_weight: float = 1e-5     #: penalty scale: star area * edge length^2 * (1 - g/g_soft)^2
    #: Hausdorff-aware penalty: weight * merged area * (distance of the farther merged
    #: vertex's witness -- its input point farthest from the surface so far -- to the new faces)^2
    haus_weight: float = 0.45
    haus_phase: float = 4.0          #: ... only once the mesh has at most this many times the target faces
    relocate_iters: int = 2          #: final relocation rounds towards the input (0: off)
    #: inputs up to this many faces also get the backward pull (cage towards the input
    #: surface, which needs an index of the whole input) ...
    relocate_back_max_faces: int = 50000
    relocate_back: float = 0.3       #: ... with this weight (cage area against the input points)
    relocate_back_iters: int = 4     #: ... and this many rounds
    relocate_border_weight: float = 1.0  #: weight of each input border point (a surface sample: 1)
    relocate_samples: int = 20000    #: input vertices as relocation targets: this many ...
    relocate_per_vertex: int = 4     #: ... or this many per cage vertex, whichever is more
    relocate_reg: float = 1.0        #: pull of each vertex to its place, relative to its samples
    relocate_max_faces: int = 200000  #: ... only for cages up to this size
    relocate_max_share: float = 0.5  #: ... and at most this share of the input's faces
    #: preserve_topology=False removes stuck components up to this size (share of the diagonal)
    relax_max_size: float = 0.25
    snap_bits: int = 32              #: coordinates snapped to 2^-snap_bits of the diagonal
    max_passes: int = 100000


TUNING = Tuning()



@dataclass(frozen=True)
class SimplifyResult:
    """What :func:`simplify` returns.

    Attributes
    ----------
    V : (n,3) float64, the cage's vertices.
    F : (m,3) int64, the cage's faces.
    vertex_map : (n_input,) int64, the cage vertex each input vertex was merged
        into (``-1`` for input vertices no face used, and for those of
        components removed with ``preserve_topology=False``).
    max_error : float, largest error of an accepted collapse, as a distance in
        mesh units (``sqrt(quadric error / quadric area)``, see ``core.quadrics``);
        the final relocation only moves vertices closer to the input and is
        not counted in it.
    stopped_because : str, ``"target"``, ``"max_error"``, ``"no_valid_collapse"``
        or ``"cancelled"``.
    feature_edges : (k,2) int64, cage edges (sorted rows) that descend from the
        input's sharp edges (dihedral angle above ``feature_angle_deg``):
        pass them as ``creases`` to subdivision.
    n_degenerate_faces, n_duplicate_faces, n_unreferenced_vertices : int,
        what cleaning dropped from the input.
    n_frozen_vertices : int, vertices on non-manifold edges or with several
        fans, kept in place.
    n_passes : int, batches applied.
    """

    V: np.ndarray
    F: np.ndarray
    vertex_map: np.ndarray
    max_error: float
    stopped_because: str
    feature_edges: np.ndarray
    n_degenerate_faces: int = 0
    n_duplicate_faces: int = 0
    n_unreferenced_vertices: int = 0
    n_frozen_vertices: int = 0
    n_passes: int = 0


def _check_args(n, target_faces, ratio, max_error, feature_angle_deg, vertex_weights, locked, progress):
    if target_faces is None and ratio is None and max_error is None:
        raise InvalidArgumentError(
            f"{_WHERE}: give at least one of target_faces, ratio or max_error, e.g. ratio=0.1")
    if target_faces is not None:
        if isinstance(target_faces, bool) or not isinstance(target_faces, (int, np.integer)):
            raise InvalidArgumentError(
                f"{_WHERE}: target_faces must be an integer >= 0, got {target_faces!r}")
        if target_faces < 0:
            raise InvalidArgumentError(f"{_WHERE}: target_faces must be >= 0, got {target_faces}")
    if ratio is not None:
        r = float(ratio)
        if not (0.0 < r <= 1.0):
            raise InvalidArgumentError(f"{_WHERE}: ratio must be in (0, 1], got {ratio!r}")
    if max_error is not None:
        e = float(max_error)
        if not (e >= 0.0) or not np.isfinite(e):
            raise InvalidArgumentError(
                f"{_WHERE}: max_error must be a finite distance >= 0, got {max_error!r}")
    if feature_angle_deg is not None:
        a = float(feature_angle_deg)
        if not (0.0 < a <= 180.0):
            raise InvalidArgumentError(
                f"{_WHERE}: feature_angle_deg must be in (0, 180] or None, got {feature_angle_deg!r}")
    w = None
    if vertex_weights is not None:
        w = np.asarray(vertex_weights)
        if w.shape != (n,) or not (np.issubdtype(w.dtype, np.floating) or np.issubdtype(w.dtype, np.integer)):
            raise InvalidArgumentError(
                f"{_WHERE}: vertex_weights must be ({n},) numbers, got {w.shape} {w.dtype}")
        w = w.astype(np.float64)
        bad = ~np.isfinite(w) | (w < 0)
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            raise InvalidArgumentError(
                f"{_WHERE}: vertex_weights must be finite and >= 0, e.g. vertex {i} has {w[i]}")
    lk = None
    if locked is not None:
        lk = np.asarray(locked)
        if lk.shape != (n,) or not (lk.dtype == bool or np.issubdtype(lk.dtype, np.integer)):
            raise InvalidArgumentError(
                f"{_WHERE}: locked must be ({n},) booleans, got {lk.shape} {lk.dtype}")
        lk = lk.astype(bool)
    if progress is not None and not callable(progress):
        raise InvalidArgumentError(f"{_WHERE}: progress must be callable or None, got {type(progress)}")
    return w, lk


def _initial_quadrics(V, F, twin, U, W, preserve_boundary, feature_angle_deg, tun):
    """Vertex quadrics (n,11) with boundary and crease planes, the crease
    flags per half-edge, and the unnormalised face normals (m,3) (as
    ``face_normals(V, F, normalize=False)``). The quadrics are the transposed
    view of an (11,n) C-contiguous array (``State`` keeps that layout)."""
    n = V.shape[0]
    QT, Nf, Nraw = _vertex_face_quadrics(V, F, n, tun.area_power)  # (11, n)
    feat = np.zeros(twin.size, dtype=bool)
    items, ends = [], []
    if preserve_boundary:
        hb = np.flatnonzero(twin == BOUNDARY)
        E = np.stack([U[hb], W[hb]], axis=1)
        L2 = np.einsum("ij,ij->i", V[E[:, 1]] - V[E[:, 0]], V[E[:, 1]] - V[E[:, 0]])
        items.append(edge_constraint_quadrics(V, E, Nf[hb // 3], tun.boundary_weight * L2))
        ends.append(E)
    if feature_angle_deg is not None:
        hi = np.flatnonzero(twin > np.arange(twin.size, dtype=np.int64))
        t = twin[hi]
        cosang = np.einsum("ij,ij->i", np.take(Nf, hi // 3, axis=0), np.take(Nf, t // 3, axis=0))
        # faces that disagree on the edge's direction have opposite normal conventions
        np.negative(cosang, out=cosang, where=U[hi] != W[t])
        sharp = np.flatnonzero(cosang < np.cos(np.radians(feature_angle_deg)))
        hs, ts = hi[sharp], t[sharp]
        feat[hs] = True
        feat[ts] = True
        E = np.stack([U[hs], W[hs]], axis=1)
        L2 = np.einsum("ij,ij->i", V[E[:, 1]] - V[E[:, 0]], V[E[:, 1]] - V[E[:, 0]])
        for side in (hs, ts):
            items.append(edge_constraint_quadrics(V, E, Nf[side // 3], tun.feature_weight * L2))
            ends.append(E)
    if items:
        Qc = np.concatenate(items)
        Ec = np.concatenate(ends)
        Qc[:, 10] = 0.0  # constraint planes do not count as surface area
        # only the vertices on constraint edges change (adding 0.0 elsewhere is exact)
        vc, local = np.unique(Ec, return_inverse=True)
        QT[:, vc] += _accumulate_T(Qc, local.reshape(Ec.shape).T.ravel(), vc.size, 2)
    return QT.T, feat, Nraw  # (n,11) view of the coefficient-major array the engine uses


def _normal_sums(F, N, n):
    """Sum of the face normals ``N`` (m,3) around each vertex, (n,3) float64
    (each bin adds its faces in face order)."""
    if F.shape[0] == 0:
        return np.zeros((n, 3))
    Fr = F.ravel()
    w = np.empty(Fr.size)
    out = np.empty((n, 3))
    for k in range(3):
        w.reshape(-1, 3)[:] = N[:, k, None]  # np.repeat(N[:, k], 3) without a new array
        out[:, k] = np.bincount(Fr, weights=w, minlength=n)
    return out


def _relocate_cage(mesh, Vn, creases, Eb_in, surface, tun):
    """Move the unlocked cage vertices towards the input (see ``core._relocate``):
    the input's crease vertices ``creases`` join the surface samples, its
    border edges ``Eb_in`` (k,2) are tied to the cage's, and ``surface`` (the
    input faces, or None) turns on the backward pull. Borders, creases and
    corners move too, towards the input's (pinning them measured worse: their
    collapse positions are often off the input)."""
    Fm = mesh.F
    movable = ~mesh.locked
    samples = max(tun.relocate_samples, tun.relocate_per_vertex * mesh.V.shape[0])
    step = max(1, int(np.ceil(Vn.shape[0] / samples)))
    P = np.concatenate([Vn[::step], Vn[creases[::step]]])
    border = None
    if Eb_in.shape[0]:
        hb = np.flatnonzero(mesh.twin == BOUNDARY)
        Eb = np.stack(_ends(Fm, hb), axis=1)
        C = Vn[np.unique(Eb_in)[::step]]
        border = (C, Eb, TriangleIndex(Vn, segment_triangles(Eb_in)), tun.relocate_border_weight)
    Nkeep = mesh.Nref[Fm].sum(axis=1) if tun.ref_cos > -1.0 else None
    back = dict(surface=TriangleIndex(Vn, surface), back=tun.relocate_back,
                iters=tun.relocate_back_iters) if surface is not None else dict(iters=tun.relocate_iters)
    Vnew = relocate(mesh.V, Fm, P, movable, reg=tun.relocate_reg, N_keep=Nkeep, border=border,
                    min_compact=tun.gamma_hard, **back)
    mesh.moved |= np.any(Vnew != mesh.V, axis=1)
    mesh.V = Vnew


def simplify(V, F, *, target_faces=None, ratio=None, max_error=None, preserve_boundary=True,
             preserve_topology=True, feature_angle_deg=60.0, vertex_weights=None, locked=None,
             progress=None):
    """Simplify a triangle mesh to a coarse, clean manifold cage (QEM).

    Parameters
    ----------
    V : (n,3) float array_like
    F : (m,3) int array_like
    target_faces : int >= 0, optional
        Stop once the cage has at most this many faces.
    ratio : float in (0, 1], optional
        Target as a share of the (cleaned) input's faces, ``round(ratio * m)``.
    max_error : float >= 0, optional
        Never accept a collapse whose error exceeds this distance, in the
        mesh's units. The error of a collapse is ``sqrt(E / W)``: ``E`` the
        quadric error of the merged vertex (area-weighted squared distances to
        the planes of the input faces it stands for) and ``W`` their total
        area, i.e. the RMS distance of the new vertex to those planes.
        At least one of ``target_faces``, ``ratio``, ``max_error`` is needed;
        the run stops at whichever is reached first.
    preserve_boundary : bool
        Add heavy constraint planes on open borders so they keep their shape;
        an interior edge with one boundary endpoint collapses onto it.
    preserve_topology : bool
        Enforce the link condition: genus, boundary loops and components
        kept, never a non-manifold edge or vertex. With ``False``, once the
        link condition stops every collapse before the target, holes bounded
        by three edges are closed with a triangle and components that cannot
        shrink any further (a tetrahedron, a lone triangle; at most a quarter
        of the mesh's size and no larger than ``max_error`` when it is given;
        never the largest component or one with locked vertices) are
        removed, smallest first, and simplification goes on. The output is still a
        clean manifold; input vertices of removed components map to ``-1``.
    feature_angle_deg : float in (0, 180] or None
        Edges whose faces meet at more than this angle get constraint planes
        (creases and corners survive) and are reported in ``feature_edges``.
    vertex_weights : (n,) float >= 0, optional
        Importance of each input vertex: scales its quadric.
    locked : (n,) bool, optional
        Locked vertices are never moved or removed.
    progress : callable(float) -> bool or None, optional
        Called after every pass with the fraction done (0..1); returning
        ``False`` stops cleanly with ``stopped_because == "cancelled"``.

    Returns
    -------
    SimplifyResult

    Raises
    ------
    InvalidMeshError
        NaN/inf coordinates, indices out of range, wrong shapes or dtypes.
    InvalidArgumentError
        No target given, ``target_faces < 0``, ``ratio`` outside (0, 1],
        negative ``max_error``, badly shaped weights or lock mask.

    Examples
    --------
    >>> from tests.mesh_factory import icosphere
    >>> V, F = icosphere(3)
    >>> r = simplify(V, F, target_faces=100)
    >>> r.F.shape[0] <= 100, r.stopped_because
    (True, 'target')
    """
    tun = TUNING
    V, F = check_mesh(V, F, where=_WHERE)
    n_in = V.shape[0]
    weights, lk = _check_args(n_in, target_faces, ratio, max_error, feature_angle_deg, vertex_weights,
                              locked, progress)
    clean, twin, U, W = clean_with_twins(V, F)
    # working order: neighbours near each other in memory; to_input[i] is the
    # input vertex of working vertex i
    lo, hi = bounding_box(clean.V)
    Vc, Fc, twin, U, W, order, forder = spatial_order(clean.V, clean.F, twin, box=(lo, hi))
    to_input = clean.clean_to_vertex[order]
    dropped = {k: getattr(clean, k) for k in ("n_degenerate_faces", "n_duplicate_faces",
                                              "n_unreferenced_vertices")}
    del order, clean  # the reordered copies replace the cleaned mesh
    n, m0 = Vc.shape[0], Fc.shape[0]

    target = None
    if target_faces is not None:
        target = int(target_faces)
    if ratio is not None:
        t = int(round(float(ratio) * m0))
        target = t if target is None else max(target, t)

    frozen = non_manifold_vertices(Fc, n, twin, ends=(U, W)) if m0 else np.zeros(n, dtype=bool)
    lock = frozen.copy()
    if lk is not None:
        lock |= lk[to_input]

    # unit-free working coordinates: centred, unit diagonal, snapped to a grid
    centre = 0.5 * (lo + hi)
    scale = float(np.linalg.norm(hi - lo)) or 1.0
    grid = float(2 ** tun.snap_bits)
    Vn = Vc - centre
    Vn /= scale
    Vn *= grid
    np.round(Vn, out=Vn)
    Vn /= grid

    Q, feat, Nf = _initial_quadrics(Vn, Fc, twin, U, W, preserve_boundary, feature_angle_deg, tun)
    # for the final relocation: the input's border edges and crease vertices, and its
    # faces when small enough for the backward pull (the engine rewrites Fc)
    hb = np.flatnonzero(twin == BOUNDARY)
    Eb_in = np.stack([U[hb], W[hb]], axis=1)
    creases = np.unique(np.concatenate([U[feat], W[feat]]))
    Fin = Fc.copy() if m0 <= tun.relocate_back_max_faces else None
    del U, W  # (3m,) each: not needed past the set-up
    if weights is not None:
        Q *= weights[to_input][:, None]
    Nref = _normal_sums(Fc, Nf, n)
    del Nf
    mesh = State(Vn, Fc, twin, Q, lock, feat, Nref, forig=forder)  # Fc is spatial_order's own array
    max_err_n = None if max_error is None else float(max_error) / scale

    stopped = "target"
    passes = 0
    if target is None or m0 > target:
        stopped, passes = run(mesh, target, max_err_n, preserve_boundary, progress, m0, tun)
        while not preserve_topology and stopped == "no_valid_collapse":
            # the link condition stopped every collapse: close 3-edge holes, drop
            # components that cannot shrink, and go on
            need = mesh.F.shape[0] - target if target is not None else mesh.F.shape[0]
            changed = close_triangular_holes(mesh)
            if not changed:
                size = tun.relax_max_size if max_err_n is None else min(tun.relax_max_size, max_err_n)
                changed = drop_stuck_components(mesh, need, size)
            if not changed:
                break
            stopped, more = run(mesh, target, max_err_n, preserve_boundary, progress, m0, tun)
            passes += more
    worst = mesh.worst
    if (tun.relocate_iters > 0 and passes > 0 and stopped != "cancelled"
            and mesh.F.shape[0] <= min(tun.relocate_max_faces, tun.relocate_max_share * m0)):
        _relocate_cage(mesh, Vn, creases, Eb_in, Fin, tun)

    # back to the caller's units; vertices never moved keep their exact input position
    Vout = mesh.V * scale + centre
    still = ~mesh.moved
    Vout[still] = Vc[mesh.orig[still]]
    # back to the input's order: cage vertices in the order of the input vertices
    # they keep, faces in the order of the input faces they descend from
    vorder = np.argsort(to_input[mesh.orig])  # (distinct keys)
    new_v = np.empty(vorder.size, dtype=np.int64)
    new_v[vorder] = np.arange(vorder.size, dtype=np.int64)
    cur = mesh.cur_of_clean
    vertex_map = np.full(n_in, -1, dtype=np.int64)
    vertex_map[to_input] = np.where(cur >= 0, new_v[np.maximum(cur, 0)], -1)
    hf = np.flatnonzero(mesh.feat)
    tf = mesh.twin[hf]
    hf = hf[(tf > hf) | (tf == BOUNDARY)]  # one half-edge per feature edge
    a, b = (new_v[e] for e in _ends(mesh.F, hf))
    fe = np.stack([np.minimum(a, b), np.maximum(a, b)], axis=1)
    fe = fe[np.lexsort((fe[:, 1], fe[:, 0]))]
    Fo = new_v[mesh.F[np.argsort(mesh.forig, kind="stable")]]
    return SimplifyResult(
        V=Vout[vorder], F=Fo, vertex_map=vertex_map, max_error=float(worst * scale),
        stopped_because=stopped, feature_edges=fe.astype(np.int64),
        **dropped, n_frozen_vertices=int(frozen.sum()),
        n_passes=passes)
