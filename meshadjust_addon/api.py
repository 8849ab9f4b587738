"""MeshAdjust's plain Python API: the workflow steps without any UI context.

The operators, the batch CLI and other people's scripts call these. Each
step is split into a pure-NumPy *compute* part (safe to run in a worker
thread, cancellable through ``progress``) and a Blender *commit* part that
creates or updates objects. Everything that can fail is checked before the
commit writes anything, so a failed or cancelled step changes nothing in the
scene (and :func:`.rollback.all_or_nothing` undoes a commit that fails
anyway).

    cage, report = simplify_object(obj, target_faces=1400, fit=True, bind=True)
    ...move cage vertices...
    result = refine_object(cage, output='EDITED')

Geometry is processed in the source object's local space; the cage is created
with the source's transform, and a cage moved as an object is mapped back
through both transforms, so object transforms are respected.

An edit is the difference between the cage's current shape and its *rest
shape* (the point attribute ``meshadjust_rest``, saved at bind time). Fit and
re-bind work on the rest shape and carry the edit over on top of the result,
so an artist's edit is never reset without being asked to.
"""

import time
from dataclasses import dataclass, field, fields, replace

import bpy
import numpy as np

from .. import core
from . import mesh_io, results, settings, staleness, store
from .rollback import all_or_nothing

CREASE = store.CREASE
#: samples per surface for the deviation shown after a simplify (enough for a
#: stable Hausdorff estimate in about a second on 250k triangles)
MEASURE_SAMPLES = 60_000
#: most levels the automatic choice picks
MAX_AUTO_LEVELS = 5
#: a target missed by more than this share makes the simplify report a warning
TARGET_TOLERANCE = 0.05
OUTPUT_NAMES = tuple(item[0] for item in settings.OUTPUTS)

_link_like = results.link_like   # kept for callers of the old private name


def _d(key):
    return field(default=settings.default(key))


@dataclass(frozen=True)
class SimplifyParams:
    """Everything :func:`simplify_object` needs besides the object.

    The defaults are those of ``settings.SETTINGS`` (the panel's and the
    operator's). The target is whichever of ``target_faces``, ``ratio`` and
    ``max_error_pct`` is given; with none, the default face count.
    ``levels=0`` picks the levels whose refined mesh comes closest to the
    source's face count (:func:`auto_levels`).
    """

    target_faces: int = None
    ratio: float = None
    max_error_pct: float = None      #: % of the bounding-box diagonal
    preserve_boundary: bool = _d("preserve_boundary")
    preserve_topology: bool = _d("preserve_topology")
    feature_angle_deg: float = _d("feature_angle_deg")
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
            feature_angle_deg=s.feature_angle_deg, weight_group=s.weight_group,
            lock_group=s.lock_group, fit=s.fit, bind=s.bind, levels=s.levels, scheme=s.scheme,
            hide_source=s.hide_source)

    def keywords(self):
        """The parameters as keyword arguments of :func:`simplify_object`."""
        return {f.name: getattr(self, f.name) for f in fields(self)}


def auto_levels(cage_faces, source_faces, *, max_levels=MAX_AUTO_LEVELS):
    """The subdivision levels (1..max_levels) whose refined face count,
    ``cage_faces * 4**levels``, is closest to ``source_faces``."""
    cage_faces = max(int(cage_faces), 1)
    counts = cage_faces * 4 ** np.arange(1, max_levels + 1)
    return int(np.argmin(np.abs(counts - int(source_faces)))) + 1


def _about(n):
    return f"{n / 1000:.0f}k" if n >= 10_000 else f"{n:,}"


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


@dataclass(frozen=True)
class Report:
    """What a step did, for the UI and logs. ``level`` is ``'INFO'`` or
    ``'WARNING'`` (something was not done, or not as asked: see
    ``warnings``)."""

    message: str
    faces_in: int = 0
    faces_out: int = 0
    deviation_pct: float = float("nan")
    seconds: float = 0.0
    level: str = 'INFO'
    warnings: tuple = ()
    cleaning: dict = field(default_factory=dict)   #: ``core.CleanReport.to_dict()`` of a simplify


def _diag(V):
    return core.bbox_diagonal(V)


def user_cause(exc, what, obj_name):
    """A message for a failed step that names the object and the cause the
    user can act on, with the core's evidence after it."""
    text = str(exc)
    if "non-manifold" in text:
        cause = ("the cage has non-manifold vertices or edges (bowties, edges shared by more "
                 "than two faces), which subdivision cannot refine; clean the source "
                 "(Mesh > Clean Up) or simplify it with Keep topology off")
    elif isinstance(exc, core.TopologyMismatchError):
        cause = "the cage's topology no longer matches its binding"
    else:
        cause = text
        text = ""
    return f"{what} '{obj_name}' failed: {cause}" + (f" ({text})" if text else "")


def read_source(source):
    """The source's mesh as the artist made it (MeshAdjust's own shape keys
    muted): ``(MeshArrays, fingerprint)``."""
    with results.own_keys_muted(source):
        depsgraph = bpy.context.evaluated_depsgraph_get()
        arrays = mesh_io.read_object(source, depsgraph=depsgraph)
    return arrays, staleness.source_fingerprint(source) or ""


def prepare_simplify(source, params, *, depsgraph=None):
    """Read the source object into a :class:`SimplifyJob` (main thread)."""
    if source is None or source.type != 'MESH':
        raise core.InvalidMeshError("simplify: the active object is not a mesh")
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
        job.notes.append(f"triangulated {arrays.n_polygons:,} polygons for the core")
    n = arrays.V.shape[0]
    for group, attr in ((params.weight_group, "weights"), (params.lock_group, "locked")):
        if not group:
            continue
        if arrays.evaluated:
            raise core.InvalidArgumentError(
                f"simplify: vertex groups cannot be used together with modifiers or shape keys "
                f"on '{source.name}' (apply them first)")
        w = mesh_io.vertex_group_weights(source, group)
        if w.shape[0] != n:
            raise core.InvalidArgumentError(f"simplify: vertex group '{group}' does not match "
                                            f"the mesh")
        setattr(job, attr, w if attr == "weights" else w > 0.5)
    if job.weights is not None:
        job.weights = 1.0 + 9.0 * job.weights     # weight 1 -> 10x as important
    return job


def compute_simplify(job, *, progress=None):
    """Run the core on a :class:`SimplifyJob` (pure NumPy, any thread).

    ``progress(fraction)`` returning False cancels; ``job.cancelled`` says so.
    Measure, fit and bind take the last 30% of the bar. A fit or bind that
    fails with the core's error is recorded (``fit_error``, ``bind_error``)
    and the cage is kept: nothing computed is thrown away.
    """
    p = job.params
    t0 = time.perf_counter()
    max_error = None
    if p.max_error_pct is not None:
        max_error = p.max_error_pct / 100.0 * _diag(job.V)

    def simplify_progress(f):
        return True if progress is None else progress(0.7 * f)

    def cancelled_at(f):
        if progress is not None and progress(f) is False:
            job.cancelled = True
        return job.cancelled

    res = core.simplify(job.V, job.F, target_faces=p.target_faces, ratio=p.ratio,
                        max_error=max_error, preserve_boundary=p.preserve_boundary,
                        preserve_topology=p.preserve_topology,
                        feature_angle_deg=None if p.feature_angle_deg >= 180.0
                        else p.feature_angle_deg,
                        vertex_weights=job.weights, locked=job.locked,
                        progress=simplify_progress)
    job.result = res
    if res.stopped_because == "cancelled":
        job.cancelled = True
        return job
    job.V_cage = res.V
    job.levels = p.levels or auto_levels(res.F.shape[0], job.F.shape[0])
    if p.measure:
        # the deviation of the cage QEM produced (the classic measure of a
        # simplification), before any fitting moves it
        if cancelled_at(0.72):
            return job
        job.distance = core.surface_distance(job.V, job.F, res.V, res.F, samples=MEASURE_SAMPLES)
    creases = res.feature_edges if len(res.feature_edges) else None
    if p.fit and res.F.shape[0] >= 4:
        if cancelled_at(0.8):
            return job
        fit_progress = None if progress is None else (lambda f: progress(0.8 + 0.12 * f))
        try:
            fit = core.fit_cage(job.V, job.F, res.V, res.F, levels=job.levels, scheme=p.scheme,
                                creases=creases, progress=fit_progress)
        except core.MeshAdjustError as exc:
            job.fit_error = user_cause(exc, "fitting", f"{job.source_name}_cage")
        else:
            if fit.cancelled:
                job.cancelled = True
                return job
            job.fit = fit
            job.V_cage = fit.V
    # the cage as its mesh will hold it (float32), so the binding is the one a
    # re-bind of the unedited cage makes
    job.V_cage = job.V_cage.astype(np.float32).astype(np.float64)
    if p.bind:
        if cancelled_at(0.93):
            return job
        try:
            job.binding = core.bind(job.V, job.F, job.V_cage, res.F, levels=job.levels,
                                    scheme=p.scheme, creases=creases)
        except core.MeshAdjustError as exc:
            job.bind_error = user_cause(exc, f"binding '{job.source_name}' to",
                                        f"{job.source_name}_cage")
        if cancelled_at(0.99):
            return job
    job.seconds = time.perf_counter() - t0
    if progress is not None:
        progress(1.0)
    return job


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
    if res.stopped_because not in ("topology_floor", "no_valid_collapse") and not missed:
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
    with all_or_nothing():
        name = f"{source.name}_cage"
        mesh = mesh_io.new_mesh(name, job.V_cage, res.F)
        n_creases = mesh_io.set_edge_flags(mesh, res.feature_edges, CREASE)
        if n_creases:
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
        faces_in = job.F.shape[0]
        dev = float("nan")
        msg = f"{faces_in:,} -> {res.F.shape[0]:,} faces"
        if job.distance is not None:
            dev = 100.0 * job.distance.hausdorff / max(_diag(job.V), 1e-300)
            msg += (f", max deviation {dev:.2f}% of size (mean "
                    f"{100.0 * job.distance.mean / max(_diag(job.V), 1e-300):.3f}%)")
        msg += f", {job.seconds:.1f} s"
        warnings = []
        target_note, missed = _target_note(job)
        if target_note:
            msg += f"; {target_note}"
            if missed:
                warnings.append(target_note)
        notes = _cleaning_notes(res) + job.notes
        if job.fit is not None:
            d = job.fit.mean_distance
            msg += (f"; fitted: mean distance of the refined cage "
                    f"{100 * d[0] / job.fit.diagonal:.3f}% -> {100 * d[-1] / job.fit.diagonal:.3f}%")
        if job.fit_error:
            warnings.append(f"{job.fit_error}; the cage is kept unfitted")
        if job.binding is not None:
            bjob = CageJob(cage.name, job.V, job.F, job.V_cage, res.F,
                           res.feature_edges if len(res.feature_edges) else None, job.levels,
                           p.scheme, binding=job.binding, V_now=job.V_cage, V_edited=job.V,
                           source_fingerprint=job.source_fingerprint)
            commit_bind(cage, bjob)
            auto = ", automatic: closest to the source's faces" if not p.levels else ""
            msg += f"; bound '{source.name}' (levels {job.levels}{auto}, {p.scheme})"
        elif job.bind_error:
            warnings.append(f"{job.bind_error}; the cage is kept, not bound")
        if notes:
            msg += "; " + "; ".join(notes)
        if warnings:
            msg += "; WARNING: " + "; ".join(warnings)
        # the source's own state last: a failure above leaves it as it was
        source.meshadjust.role = 'SOURCE'
        source.meshadjust.cage = cage
        if p.hide_source:
            source.hide_set(True)
        cs.last_report = msg
    cleaning = res.cleaning.to_dict() if getattr(res, "cleaning", None) is not None else {}
    return cage, Report(msg, faces_in, res.F.shape[0], dev, job.seconds,
                        'WARNING' if warnings else 'INFO', tuple(warnings), cleaning)


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


def _cage_in_source_space(cage, source):
    """Cage positions in the source's local space (object transforms respected)."""
    if cage.mode == 'EDIT':
        cage.update_from_editmode()
    V = mesh_io.read_positions(cage.data)
    M = np.array(source.matrix_world.inverted() @ cage.matrix_world)
    return V @ M[:3, :3].T + M[:3, 3]


def _source_to_cage(cage, source, V):
    M = np.array(cage.matrix_world.inverted() @ source.matrix_world)
    return V @ M[:3, :3].T + M[:3, 3]


def _edited_copy(source, cage):
    """The edited-original object of ``cage`` (created once)."""
    return results.edited_copy(source, cage, len(source.data.vertices))[0]


@dataclass
class CageJob:
    """The compute half of a bind or a fit: source and cage read from Blender.

    ``V_cage`` is the shape bound or fitted (the rest shape); ``V_now`` the
    cage as the artist left it, so ``V_now - V_cage`` is the edit, carried
    over onto the result."""

    cage_name: str
    V: np.ndarray                #: source positions (its local space)
    F: np.ndarray                #: source triangles
    V_cage: np.ndarray           #: cage rest positions in the source's space
    F_cage: np.ndarray
    creases: object
    levels: int
    scheme: str
    from_rest: bool = False      #: V_cage is the saved rest shape
    rebind: bool = False         #: a fit also re-binds (the cage was bound)
    binding: object = None       #: core.Binding, after compute_bind
    fit: object = None           #: core.FitResult, after compute_fit
    cancelled: bool = False
    V_now: np.ndarray = None     #: the cage's current positions (source space)
    V_edited: np.ndarray = None  #: the edited original's positions, after compute_bind
    source_fingerprint: str = ""
    old_levels: int = 0          #: the binding's levels and scheme before (0: unbound)
    old_scheme: str = ""
    note: str = ""               #: what the commit re-made, for the report

    @property
    def n_moved(self):
        """Cage vertices the edit moves (beyond float32 rounding)."""
        if self.V_now is None or self.V_now.shape != self.V_cage.shape:
            return 0
        tol = 1e-6 * max(_diag(self.V_cage), 1e-300)
        return int(np.count_nonzero(np.abs(self.V_now - self.V_cage).max(axis=1) > tol))


def _rest_of(cage, n):
    """The cage's saved rest shape (source space) when it has one for ``n``
    vertices, else None."""
    if cage.data.attributes.get(store.REST) is None and not cage.data.is_editmode:
        return None
    try:
        V_rest = store.load_rest(cage)
    except core.MeshAdjustError:
        return None
    return V_rest if V_rest.shape[0] == n else None


def prepare_cage_job(cage, *, levels=None, scheme=None, from_rest=False, keep_edit=False):
    """Read what a bind or a fit of ``cage`` needs (main thread).

    ``levels`` / ``scheme`` None (or 0 / ``'BOUND'``) keep the cage's. With
    ``keep_edit`` (or the older name ``from_rest``), the cage's saved rest
    shape is bound or fitted and the edit (current - rest) carried over; a
    cage without a rest shape counts as unedited."""
    cs = cage.meshadjust
    source = cs.source
    if source is None:
        raise core.MeshAdjustError(f"'{cage.name}' is not a MeshAdjust cage (no source linked)")
    V_now = _cage_in_source_space(cage, source)
    V_rest = _rest_of(cage, V_now.shape[0]) if (keep_edit or from_rest) else None
    F_cage, _, creases = store.cage_topology(cage)
    src, fp = read_source(source)
    if levels in (None, 0):
        levels = cs.levels or auto_levels(F_cage.shape[0], src.F.shape[0])
    if scheme in (None, 'BOUND'):
        scheme = cs.scheme
    bound = cs.edited is not None
    return CageJob(cage.name, src.V, src.F, V_now if V_rest is None else V_rest, F_cage, creases,
                   levels, scheme, V_rest is not None, V_now=V_now, source_fingerprint=fp,
                   old_levels=cs.levels if bound else 0, old_scheme=cs.scheme if bound else "")


def compute_bind(job, *, progress=None):
    """Bind the source to the cage's rest shape and deform it by the edit
    (pure NumPy, any thread). ``progress`` is only asked whether to go on,
    at the end."""
    if progress is not None and progress(0.0) is False:
        job.cancelled = True
        return job
    job.binding = core.bind(job.V, job.F, job.V_cage, job.F_cage, levels=job.levels,
                            scheme=job.scheme, creases=job.creases)
    if progress is not None and progress(0.9) is False:
        job.cancelled = True
        return job
    if job.V_now is not None and job.n_moved:
        job.V_edited = core.deform(job.binding, job.V_now)
    else:
        job.V_edited = job.V
    if progress is not None and progress(1.0) is False:
        job.cancelled = True
    return job


def commit_bind(cage, job):
    """Write a computed binding: the edited-original copy (created on first
    use, re-made when the source's vertex count changed), deformed by the
    edit; its binding attributes and fingerprints; the cage's rest shape;
    the other results that exist, updated. Returns the edited-original
    object (``job.notes`` gets what was re-made)."""
    cs = cage.meshadjust
    source = cs.source
    with all_or_nothing() as rb:
        if cs.edited is not None:
            rb.keep(cs.edited.data)
        rb.keep(cage.data)
        edited, note = results.edited_copy(source, cage, job.V.shape[0])
        job.note = note
        mesh_io.write_positions(edited.data, job.V_edited if job.V_edited is not None else job.V)
        store.save_binding(edited, job.binding)
        store.save_rest(cage, job.V_cage)
        st = edited.meshadjust
        key = staleness.topology_key(cage)
        st.cage_counts = (key[0], key[2])
        st.cage_edges = key[1]
        st.cage_topology = key[3]
        st.source_fingerprint = job.source_fingerprint
        st.dense_faces = job.F.shape[0]
        cs.levels = job.levels
        cs.scheme = job.scheme
        cs.fingerprint = job.binding.fingerprint
        V_now = job.V_now if job.V_now is not None else job.V_cage
        if cs.refined is not None:
            results.write_refined(cage, source, *core.refine(job.binding, V_now))
        if results.shape_key_of(source, cage) is not None:
            _write_key(source, cage, edited, job.binding, job.V_edited, V_rest=job.V_cage)
        staleness.touched(cage)
        staleness.touched(source)
    return edited


def bind_object(cage, *, levels=None, scheme=None, from_rest=False, keep_edit=None):
    """(Re-)bind the cage's source to the cage (the synchronous path).

    ``keep_edit`` (default: the setting's, True; ``from_rest`` is its older
    name): the rest shape saved at the last bind is bound again and the edit
    kept on top; False: the cage's current shape becomes the rest shape.
    Returns the edited-original object.
    """
    if keep_edit is None:
        keep_edit = settings.default("keep_edit") or from_rest
    job = prepare_cage_job(cage, levels=levels, scheme=scheme, keep_edit=keep_edit)
    return commit_bind(cage, compute_bind(job))


def prepare_fit(cage, *, rebind=True, levels=None, scheme=None):
    """A fit job: the rest shape is fitted and the edit carried over (a cage
    that was never bound is its own rest shape)."""
    job = prepare_cage_job(cage, levels=levels, scheme=scheme, keep_edit=True)
    job.rebind = rebind and cage.meshadjust.edited is not None
    return job


def compute_fit(job, *, progress=None):
    """Fit the cage's rest shape to the source (pure NumPy, any thread;
    cancellable); with ``job.rebind``, bind the fitted rest shape and deform
    by the edit too."""
    fit_progress = progress
    if job.rebind and progress is not None:
        fit_progress = lambda f: progress(0.8 * f)   # noqa: E731
    job.fit = core.fit_cage(job.V, job.F, job.V_cage, job.F_cage, levels=job.levels,
                            scheme=job.scheme, creases=job.creases, progress=fit_progress)
    job.cancelled = job.fit.cancelled
    if job.cancelled:
        return job
    edit = None if job.V_now is None else job.V_now - job.V_cage
    job.V_cage = job.fit.V
    job.V_now = job.fit.V if edit is None else job.fit.V + edit
    if job.rebind:
        compute_bind(job, progress=None if progress is None else (lambda f: progress(0.8 + 0.2 * f)))
    return job


def commit_fit(cage, job):
    """Move the cage to the fitted rest shape plus the edit (and write the
    new binding when the job re-bound). Returns the core's ``FitResult``."""
    source = cage.meshadjust.source
    if cage.mode == 'EDIT':
        raise core.MeshAdjustError(f"leave Edit Mode on '{cage.name}' to fit it")
    with all_or_nothing() as rb:
        rb.keep(cage.data)
        mesh_io.write_positions(cage.data, _source_to_cage(cage, source, job.V_now))
        if job.binding is not None:
            commit_bind(cage, job)
        staleness.touched(cage)
    return job.fit


def fit_cage_object(cage, *, levels=None, scheme=None, rebind=settings.default("rebind")):
    """Fit the cage (the synchronous path): its rest shape moves so its
    subdivision matches the source, the edit stays on top. Returns the
    core's ``FitResult``."""
    job = prepare_fit(cage, rebind=rebind, levels=levels, scheme=scheme)
    return commit_fit(cage, compute_fit(job))


_rest_dense = {}   #: edited session_uid -> (binding id, dense positions of the rest shape)


def _write_key(source, cage, edited, binding, V_edited, *, V_rest=None):
    """The shape-key output: relative to the mesh that was bound."""
    V_bound = None
    if not results.only_own_keys_and_no_modifiers(source):
        hit = _rest_dense.get(edited.session_uid)
        if hit is None or hit[0] != id(binding):
            if V_rest is None:
                V_rest = store.load_rest(cage)
            hit = (id(binding), core.deform(binding, V_rest))
            _rest_dense[edited.session_uid] = hit
        V_bound = hit[1]
    return results.write_shape_key(source, cage, V_edited, V_bound)


def refine_object(cage, *, output='EDITED', levels=None, scheme=None):
    """Update the results of an edited cage; returns a :class:`Report`.

    ``output``: ``'EDITED'`` (the bound copy of the source, deformed; same
    topology, UVs and attributes), ``'SHAPE_KEY'`` (the edit as a shape key
    of the source named after the cage), ``'REFINED'`` (the subdivided cage
    with the source's detail) or ``'BOTH'`` (edited and refined). Results
    are created once and updated in place afterwards. Other ``levels`` /
    ``scheme`` than the binding's re-bind from the rest shape, keeping the
    edit (and the report says so). A source changed since the bind makes the
    report a warning.
    """
    if output not in OUTPUT_NAMES:
        raise core.InvalidArgumentError(f"refine: output must be one of {OUTPUT_NAMES}, "
                                        f"got {output!r}")
    t0 = time.perf_counter()
    cs = cage.meshadjust
    source = cs.source
    if source is None:
        raise core.MeshAdjustError(f"'{cage.name}' is not a MeshAdjust cage (no source linked)")
    edited = cs.edited
    if edited is None:
        raise core.MeshAdjustError(f"'{cage.name}' is not bound yet: bind it first")
    if scheme == 'BOUND':
        scheme = None
    parts, warnings = [], []
    with all_or_nothing() as rb:
        if (levels and levels != cs.levels) or (scheme is not None and scheme != cs.scheme):
            job = prepare_cage_job(cage, levels=levels, scheme=scheme, keep_edit=True)
            commit_bind(cage, compute_bind(job))
            parts.append(f"re-bound from the rest shape ({job.old_scheme} x{job.old_levels} -> "
                         f"{job.scheme} x{job.levels}), the edit kept")
        binding = store.load_binding(edited, cage)
        V_cage = _cage_in_source_space(cage, source)
        if output == 'SHAPE_KEY':
            why = results.shape_key_unavailable(source, binding.n_dense)
            if why:
                raise core.MeshAdjustError(f"Refine: {why}")
        V_edited = None
        if output in ('EDITED', 'BOTH', 'SHAPE_KEY'):
            V_edited = core.deform(binding, V_cage)
        if output in ('EDITED', 'BOTH'):
            rb.keep(edited.data)
            mesh_io.write_positions(edited.data, V_edited)
            parts.append(f"'{edited.name}' deformed ({binding.n_dense:,} vertices)")
        if output == 'SHAPE_KEY':
            rb.keep(source.data)
            key = _write_key(source, cage, edited, binding, V_edited)
            parts.append(f"shape key '{key.name}' of '{source.name}' updated "
                         f"({binding.n_dense:,} vertices)")
        if output in ('REFINED', 'BOTH'):
            Vr, Fr = core.refine(binding, V_cage)
            refined = results.write_refined(cage, source, Vr, Fr)
            about = edited.meshadjust.dense_faces
            parts.append(f"'{refined.name}' refined: {Fr.shape[0]:,} faces, {binding.scheme} x"
                         f"{binding.levels}" + (f", about the source's {_about(about)}"
                                                if about else ""))
    stale = staleness.source_change(source, edited.meshadjust.source_fingerprint, fresh=True)
    if stale:
        warnings.append(f"{stale}: the result uses the mesh that was bound; re-bind to use the "
                        f"new one")
    dt = time.perf_counter() - t0
    msg = "; ".join(parts) + f", {dt:.2f} s"
    if warnings:
        msg += "; WARNING: " + "; ".join(warnings)
    cs.last_report = msg
    return Report(msg, seconds=dt, level='WARNING' if warnings else 'INFO',
                  warnings=tuple(warnings))


def subdivide_object(obj, *, levels=1, scheme="butterfly", in_place=False):
    """Butterfly or Loop subdivision of any mesh object (creases: the edges
    marked sharp). Returns ``(object, Report)``: a new object beside ``obj``,
    or ``obj`` itself when ``in_place``."""
    t0 = time.perf_counter()
    arrays = mesh_io.read_object(obj)
    # sharp edges index the mesh data: they only apply when it was used as is
    creases = (np.zeros((0, 2), np.int64) if arrays.evaluated
               else mesh_io.get_edge_flags(obj.data, "sharp_edge"))
    Vf, Ff = core.subdivide(arrays.V, arrays.F, levels=levels, scheme=scheme,
                            creases=creases if creases.shape[0] else None)
    name = f"{obj.name}_{scheme}{levels}"
    with all_or_nothing():
        mesh = mesh_io.new_mesh(name, Vf, Ff)
        if in_place:
            old = obj.data
            obj.data = mesh
            if old.users == 0:
                bpy.data.meshes.remove(old)
            out = obj
        else:
            out = bpy.data.objects.new(name, mesh)
            out.matrix_world = obj.matrix_world.copy()
            results.link_like(out, obj)
    dt = time.perf_counter() - t0
    msg = f"{arrays.F.shape[0]:,} -> {Ff.shape[0]:,} faces ({scheme}, {levels} level"
    msg += "s" if levels != 1 else ""
    msg += f"), {dt:.2f} s"
    if arrays.triangulated:
        msg += f"; triangulated {arrays.n_polygons:,} polygons first"
    if arrays.evaluated:
        msg += "; used the evaluated mesh (modifiers and shape keys applied)"
    return out, Report(msg, arrays.F.shape[0], Ff.shape[0], seconds=dt)
