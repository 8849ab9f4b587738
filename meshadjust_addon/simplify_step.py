"""The Simplify step: a dense mesh into a cage (the compute / commit split).

``prepare_simplify`` reads the source (main thread), ``compute_simplify``
runs the core's simplify, measure, fit and bind (pure NumPy, any thread,
cancellable), ``commit_simplify`` creates the cage and the bound copy. A fit
or bind that fails after the simplify succeeded keeps the cage and says why.
"""

import time
from dataclasses import dataclass, field, fields, replace

import bpy
import numpy as np

from .. import core
from . import cage_steps, mesh_io, names, results, settings, store
from .cage_steps import (CageJob, auto_levels, edit_levels, fit_levels, read_source,
                         transform_problem)
from .report import Report, fit_change, user_cause
from .rollback import all_or_nothing

CREASE = store.CREASE
#: samples per surface for the deviation shown after a simplify (enough for a
#: stable Hausdorff estimate in about a second on 250k triangles)
MEASURE_SAMPLES = 60_000
#: a target missed by more than this share makes the simplify report a warning
TARGET_TOLERANCE = 0.05


def _diag(V):
    return core.bbox_diagonal(V)


def _d(key):
    return field(default=settings.default(key))


@dataclass(frozen=True)
class SimplifyParams:
    """Everything :func:`simplify_object` needs besides the object.

    The defaults are those of ``settings.SETTINGS`` (the panel's and the
    operator's). The target is whichever of ``target_faces``, ``ratio`` and
    ``max_error_pct`` is given; with several, the run stops at whichever is
    reached first (``core.simplify``: of two face counts, the larger); with
    none, the default face count.
    ``levels=0`` binds at the levels whose refined mesh comes closest to the
    source's face count, at most two (:func:`edit_levels`; Refine makes the
    refined mesh at the closest, :func:`refine_levels`).
    """

    target_faces: int = None
    ratio: float = None
    max_error_pct: float = None      #: % of the bounding-box diagonal
    preserve_boundary: bool = _d("preserve_boundary")
    preserve_topology: bool = _d("preserve_topology")
    close_pinholes: bool = _d("close_pinholes")
    feature_angle_deg: float = _d("feature_angle_deg")
    max_dihedral_deg: float = _d("max_dihedral_deg")   #: 180: off
    use_symmetry: bool = _d("use_symmetry")
    symmetry_axis: str = _d("symmetry_axis")   #: 'X', 'Y' or 'Z' (the object's local axes)
    weight_group: str = _d("weight_group")
    lock_group: str = _d("lock_group")
    fit: bool = _d("fit")
    bind: bool = _d("bind")
    levels: int = _d("levels")
    scheme: str = _d("scheme")
    hide_source: bool = _d("hide_source")
    measure: bool = True

    @classmethod
    def from_settings(cls, s):
        """The parameters held by ``s``: an operator or the scene settings
        (anything with the properties of ``settings.SIMPLIFY``)."""
        return cls(
            target_faces=s.target_faces if s.target_mode == 'FACES' else None,
            ratio=s.ratio if s.target_mode == 'RATIO' else None,
            max_error_pct=s.max_error_pct if s.target_mode == 'ERROR' else None,
            preserve_boundary=s.preserve_boundary, preserve_topology=s.preserve_topology,
            close_pinholes=s.close_pinholes, feature_angle_deg=s.feature_angle_deg,
            max_dihedral_deg=s.max_dihedral_deg, use_symmetry=s.use_symmetry,
            symmetry_axis=s.symmetry_axis, weight_group=s.weight_group,
            lock_group=s.lock_group, fit=s.fit, bind=s.bind, levels=s.levels, scheme=s.scheme,
            hide_source=s.hide_source)

    @property
    def symmetry(self):
        """The core's ``symmetry`` argument: the axis, or None."""
        return self.symmetry_axis if self.use_symmetry else None

    def keywords(self):
        """The parameters as keyword arguments of :func:`simplify_object`."""
        return {f.name: getattr(self, f.name) for f in fields(self)}


@dataclass
class SimplifyJob:
    """The compute half of a simplify: inputs read from Blender, then results."""

    source_name: str
    params: SimplifyParams
    V: np.ndarray
    F: np.ndarray
    weights: np.ndarray = None
    locked: np.ndarray = None
    notes: list = field(default_factory=list)
    source_fingerprint: str = ""
    result: object = None            #: core.SimplifyResult
    V_cage: np.ndarray = None        #: fitted (or plain) cage positions
    levels: int = 0                  #: the binding's levels (``params.levels`` resolved)
    distance: object = None          #: core.SurfaceDistance of QEM's cage to the source
    fit: object = None               #: core.FitResult when the cage was fitted
    binding: object = None           #: core.Binding when the source was bound
    fit_error: str = ""              #: why the fit failed (the cage is kept unfitted)
    bind_error: str = ""             #: why the bind failed (the cage is kept unbound)
    seconds: float = 0.0
    cancelled: bool = False


def source_problem(source):
    """Why ``source`` (a mesh object) cannot be simplified into a cage, in
    words that say what to do, or None: its transform
    (:func:`~.cage_steps.transform_problem`), or linked from a library (the
    link to its cage could not be saved), or a result another cage rewrites."""
    if source.library is not None:
        return (f"'{source.name}' is linked from a library: its link to a cage would not be "
                f"saved; make it local first (Object > Relations > Make Local)")
    cage = source.meshadjust.cage
    if cage is not None and source in (cage.meshadjust.edited, cage.meshadjust.refined):
        what = "edited original" if source == cage.meshadjust.edited else "refined mesh"
        return (f"'{source.name}' is the {what} of '{cage.name}', which the cage rewrites: "
                f"simplify a copy of it (Shift+D), or its source")
    return transform_problem(source)


def prepare_simplify(source, params, *, depsgraph=None):
    """Read the source object into a :class:`SimplifyJob` (main thread)."""
    if source is None or source.type != 'MESH':
        raise core.InvalidMeshError("simplify: the active object is not a mesh")
    why = source_problem(source)
    if why:
        raise core.MeshAdjustError(f"simplify: {why}")
    params = replace(params, levels=settings.checked("levels", params.levels, "simplify"),
                     scheme=settings.checked("scheme", params.scheme, "simplify"))
    if depsgraph is None:
        arrays, fp = read_source(source)
    else:
        arrays, fp = mesh_io.read_object(source, depsgraph=depsgraph), ""
    if arrays.F.shape[0] == 0:
        raise core.InvalidMeshError(f"simplify: '{source.name}' has no faces")
    if params.target_faces is None and params.ratio is None and params.max_error_pct is None:
        params = replace(params, target_faces=settings.default("target_faces"))
    job = SimplifyJob(source.name, params, arrays.V, arrays.F, source_fingerprint=fp)
    if arrays.evaluated:
        job.notes.append("used the evaluated mesh (modifiers and shape keys applied)")
    if arrays.triangulated:
        job.notes.append(f"triangulated {arrays.n_split:,} of {arrays.n_polygons:,} polygons "
                         f"(quads and n-gons) for the core")
    n = arrays.V.shape[0]
    for group, attr in ((params.weight_group, "weights"), (params.lock_group, "locked")):
        if not group:
            continue
        # (modifiers and shape keys that only move the vertices, an Armature's, keep the
        # groups' vertices: a rig need not be applied)
        w = mesh_io.vertex_group_weights(source, group)
        if w.shape[0] != n:
            raise core.InvalidArgumentError(
                f"simplify: vertex group '{group}' cannot be used with the modifiers on "
                f"'{source.name}': they make {n:,} vertices of its {w.shape[0]:,} (apply them "
                f"first, or turn those that add or remove vertices off)")
        setattr(job, attr, w if attr == "weights" else w > 0.5)
    if job.weights is not None:
        job.weights = 1.0 + 9.0 * job.weights     # weight 1 -> 10x as important
    return job


def _auto_note(levels, cage_faces, source_faces):
    """What the report says of levels chosen automatically: the bind's, and
    Refine's when they differ (:func:`edit_levels`)."""
    closest = auto_levels(cage_faces, source_faces)
    if closest == levels:
        return ", automatic: closest to the source's faces"
    return f", automatic: refined at {closest}, closest to the source's faces"


def compute_simplify(job, *, progress=None):
    """Run the core on a :class:`SimplifyJob` (pure NumPy, any thread).

    ``progress(fraction)`` returning False cancels; ``job.cancelled`` says so.
    Simplify takes the first 70% of the bar; measure, fit and bind the rest
    (the bind reports from inside its searches: at five levels on a
    1M-vertex scan it is the longest step, and Esc there stops it). A fit or
    bind that fails with the core's error is recorded (``fit_error``,
    ``bind_error``) and the cage is kept: nothing computed is thrown away.
    """
    p = job.params
    t0 = time.perf_counter()

    def cancelled_at(f):
        if progress is not None and progress(f) is False:
            job.cancelled = True
        return job.cancelled

    res = _simplify_cage(job, progress)
    job.result = res
    if res.stopped_because == "cancelled":
        job.cancelled = True
        return job
    job.V_cage = res.V
    job.levels = p.levels or edit_levels(res.F.shape[0], job.F.shape[0])
    if p.measure and res.n_input_pieces is None:
        # the deviation of the cage QEM produced (the classic measure of a
        # simplification), before any fitting moves it (not of a soup's pieces,
        # which the report names: measuring those overlapping faces took 28 s)
        if cancelled_at(0.72):
            return job
        job.distance = res.deviation(job.V, job.F, samples=MEASURE_SAMPLES)
    creases = res.feature_edges if len(res.feature_edges) else None
    if p.fit and res.F.shape[0] >= 4:
        if cancelled_at(0.8) or not _fit_cage(job, res, creases, progress):
            return job
    # the cage as its mesh will hold it (float32), so the binding is the one a
    # re-bind of the unedited cage makes
    job.V_cage = job.V_cage.astype(np.float32).astype(np.float64)
    if p.bind:
        if cancelled_at(0.93) or not _bind_cage(job, res, creases, progress) \
                or cancelled_at(0.99):
            return job
    job.seconds = time.perf_counter() - t0
    if progress is not None:
        progress(1.0)
    return job


def _simplify_cage(job, progress):
    """``core.simplify`` with the job's settings (the first 70% of the bar)."""
    p = job.params
    max_error = None
    if p.max_error_pct is not None:
        # the size of the surface (the report's "of size"): a stray loose vertex of a scan
        # 50 units away made the bound 25 times what was asked
        max_error = p.max_error_pct / 100.0 * core.surface_diagonal(job.V, job.F)
    return core.simplify(job.V, job.F, target_faces=p.target_faces, ratio=p.ratio,
                         max_error=max_error, preserve_boundary=p.preserve_boundary,
                         preserve_topology=p.preserve_topology, close_pinholes=p.close_pinholes,
                         feature_angle_deg=None if p.feature_angle_deg >= 180.0
                         else p.feature_angle_deg,
                         max_dihedral_deg=None if p.max_dihedral_deg >= 180.0
                         else p.max_dihedral_deg,
                         vertex_weights=job.weights, locked=job.locked, symmetry=p.symmetry,
                         progress=None if progress is None else (lambda f: progress(0.7 * f)))


def _fit_cage(job, res, creases, progress):
    """Fit the cage (80-92% of the bar) into ``job.fit`` / ``job.V_cage``, or
    record the core's error in ``job.fit_error``; False when cancelled."""
    p = job.params
    try:
        # (to the surface the collapse saw, as simplify cleaned it: not cleaned again)
        fit = core.fit_cage(*res.cleaned, res.V, res.F, levels=fit_levels(job.levels),
                            scheme=p.scheme, creases=creases, symmetry=p.symmetry,
                            progress=None if progress is None
                            else (lambda f: progress(0.8 + 0.12 * f)), clean=False)
    except core.MeshAdjustError as exc:
        job.fit_error = user_cause(exc, "fitting", f"{job.source_name}_cage")
        return True
    if fit.cancelled:
        job.cancelled = True
        return False
    job.fit = fit
    job.V_cage = fit.V
    return True


def _bind_cage(job, res, creases, progress):
    """Bind the source to the cage (93-99% of the bar) into ``job.binding``,
    or record the core's error in ``job.bind_error``; False when cancelled."""
    p = job.params
    try:
        job.binding = core.bind(job.V, job.F, job.V_cage, res.F, levels=job.levels,
                                scheme=p.scheme, creases=creases,
                                progress=None if progress is None
                                else (lambda f: progress(0.93 + 0.06 * f)))
    except core.CancelledError:
        job.cancelled = True
        return False
    except core.MeshAdjustError as exc:
        job.bind_error = user_cause(exc, f"binding '{job.source_name}' to",
                                    f"{job.source_name}_cage")
    return True


def _cleaning_notes(res):
    """What the core's cleaning of the input did (``core.CleanReport``)."""
    cleaning = getattr(res, "cleaning", None)
    summary = cleaning.summary() if cleaning is not None else ""
    return [f"cleaned the input: {summary}"] if summary else []


def _target_note(job):
    """``(sentence, missed)``: why the cage stopped short of its target, when
    it did (the core's own sentence, e.g. "stopped at 216 faces of 205 asked:
    the topology floor (23 border loops, 1 component kept)"), and whether it
    missed the target by more than ``TARGET_TOLERANCE``."""
    res, p = job.result, job.params
    m = res.F.shape[0]
    target = getattr(res, "target", None)
    if target is None and (p.target_faces is not None or p.ratio is not None):
        target = p.target_faces
        if p.ratio is not None:
            target = max(target or 0, int(round(p.ratio * job.F.shape[0])))
    missed = target is not None and m > target * (1.0 + TARGET_TOLERANCE)
    short = res.stopped_because in ("topology_floor", "no_valid_collapse", "max_dihedral")
    under = getattr(res, "under_note", "")
    if under and not short and not missed:
        # fewer than asked: a mirrored cage's step, or an input smaller than the target (a
        # 320-face mesh asked for 1,000 came back "320 -> 320 faces" as done)
        return f"{m:,} faces{under}", m >= getattr(res, "n_clean_faces", m + 1)
    if not short and not missed:
        return "", False
    message = getattr(res, "message", "")
    head = message.split("; ")[0] if message else (
        f"stopped at {m:,} faces" + (f" of {target:,} asked" if target is not None else ""))
    return head, missed


def commit_simplify(source, job):
    """Create the cage object (and the bound copy) from a computed job.

    Returns ``(cage, Report)``; the report is a warning when the fit or the
    bind failed (the cage is kept and says so) or the target was missed by
    more than 5%."""
    res = job.result
    p = job.params
    with all_or_nothing() as rb:
        rb.keep_object(source)
        cage = _new_cage(source, job)
        msg, dev, warnings = _summary(job)
        if job.binding is not None:
            bjob = CageJob(cage.name, job.V, job.F, job.V_cage, res.F,
                           res.feature_edges if len(res.feature_edges) else None, job.levels,
                           p.scheme, binding=job.binding, V_now=job.V_cage, V_edited=job.V,
                           source_fingerprint=job.source_fingerprint)
            cage_steps.commit_bind(cage, bjob)
            auto = "" if p.levels else _auto_note(job.levels, res.F.shape[0], job.F.shape[0])
            msg += f"; bound '{source.name}' (levels {job.levels}{auto}, {p.scheme})"
        elif job.bind_error:
            warnings.append(f"{job.bind_error}; the cage is kept, not bound")
        notes = _cleaning_notes(res) + job.notes
        if notes:
            msg += "; " + "; ".join(notes)
        if warnings:
            msg += "; WARNING: " + "; ".join(warnings)
        # the source's own state last: a failure above leaves it as it was
        source.meshadjust.role = 'SOURCE'
        source.meshadjust.cage = cage
        if p.hide_source:
            source.hide_set(True)
        cage.meshadjust.last_report = msg
    cleaning = res.cleaning.to_dict() if getattr(res, "cleaning", None) is not None else {}
    return cage, Report(msg, job.F.shape[0], res.F.shape[0], dev, job.seconds,
                        'WARNING' if warnings else 'INFO', tuple(warnings), cleaning)


def _new_cage(source, job):
    """The cage object: its mesh (the job's cage positions, the feature edges
    marked as creases and sharp), placed and linked like ``source``, its
    MeshAdjust settings (role, source, levels, scheme, symmetry)."""
    res, p = job.result, job.params
    name = names.suffixed(source.name, "_cage")
    mesh = mesh_io.new_mesh(name, job.V_cage, res.F)
    if mesh_io.set_edge_flags(mesh, res.feature_edges, CREASE):
        sharp = (mesh.attributes.get("sharp_edge")
                 or mesh.attributes.new("sharp_edge", 'BOOLEAN', 'EDGE'))
        flags = np.zeros(len(mesh.edges), dtype=bool)
        mesh.attributes[CREASE].data.foreach_get("value", flags)
        sharp.data.foreach_set("value", flags)
    cage = bpy.data.objects.new(name, mesh)
    cage.matrix_world = source.matrix_world.copy()
    results.link_like(cage, source)
    cage.show_wire = True
    cs = cage.meshadjust
    cs.role = 'CAGE'
    cs.source = source
    cs.levels = job.levels
    cs.scheme = p.scheme
    cs.symmetry = p.symmetry or 'NONE'
    return cage


def _summary(job):
    """``(message, deviation %, warnings)`` of a simplify: the face counts,
    the cage's deviation from the source, the symmetry, the time, a target
    missed, the fit's distances or its failure."""
    res, p = job.result, job.params
    dev = float("nan")
    msg = f"{job.F.shape[0]:,} -> {res.F.shape[0]:,} faces"
    if job.distance is not None:
        size = max(job.distance.diagonal, 1e-300)      # (of what the cage stands for)
        dev = 100.0 * job.distance.hausdorff / size
        msg += (f", max deviation {core.percent(job.distance.hausdorff / size)} of size "
                f"(mean {core.percent(job.distance.mean / size)})")
    if p.symmetry:
        msg += f", mirror-symmetric in {p.symmetry}"
    msg += f", {job.seconds:.1f} s"
    warnings = []
    target_note, missed = _target_note(job)
    if target_note:
        msg += f"; {target_note}"
        if missed:
            warnings.append(target_note)
    if job.fit is not None:
        msg += f"; fitted: mean distance of the refined cage {fit_change(job.fit)}"
        if fit_levels(job.levels) < job.levels:
            msg += f" (at {fit_levels(job.levels)} levels)"
    if job.fit_error:
        warnings.append(f"{job.fit_error}; the cage is kept unfitted")
    for note in (getattr(res, "sliver_note", ""), getattr(res, "asymmetry_note", ""),
                 getattr(res, "pieces_note", "")):
        if note:
            warnings.append(note)
    return msg, dev, warnings


def simplify_object(source, *, progress=None, **kwargs):
    """Simplify ``source`` into a new cage object (the synchronous path).

    Keyword arguments are those of :class:`SimplifyParams`. Returns
    ``(cage, Report)``; ``(None, Report)`` when cancelled (nothing created).
    """
    job = prepare_simplify(source, SimplifyParams(**kwargs))
    compute_simplify(job, progress=progress)
    if job.cancelled:
        return None, Report("cancelled: nothing was changed")
    return commit_simplify(source, job)
