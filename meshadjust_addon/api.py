"""MeshAdjust's plain Python API: the workflow steps without any UI context.

The operators, the batch CLI and other people's scripts call these. Each
step is split into a pure-NumPy *compute* part (safe to run in a worker
thread, cancellable through ``progress``) and a Blender *commit* part that
creates or updates objects; a failed or cancelled compute changes nothing in
the scene.

    cage, report = simplify_object(obj, target_faces=1400, fit=True, bind=True)
    ...move cage vertices...
    result = refine_object(cage, output='EDITED')

Geometry is processed in the source object's local space; the cage is created
with the source's transform, and a cage moved as an object is mapped back
through both transforms, so object transforms are respected.
"""

import time
from dataclasses import dataclass, field

import bpy
import numpy as np

from .. import core
from . import mesh_io, store

CREASE = store.CREASE
#: samples per surface for the deviation shown after a simplify (enough for a
#: stable Hausdorff estimate in about a second on 250k triangles)
MEASURE_SAMPLES = 60_000


@dataclass(frozen=True)
class SimplifyParams:
    """Everything :func:`simplify_object` needs besides the object."""

    target_faces: int = None
    ratio: float = None
    max_error_pct: float = None      #: % of the bounding-box diagonal
    preserve_boundary: bool = True
    preserve_topology: bool = True
    feature_angle_deg: float = 60.0
    weight_group: str = ""
    lock_group: str = ""
    fit: bool = True
    bind: bool = True
    levels: int = 2
    scheme: str = "butterfly"
    hide_source: bool = False
    measure: bool = True


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
    result: object = None            #: core.SimplifyResult
    V_cage: np.ndarray = None        #: fitted (or plain) cage positions
    distance: object = None          #: core.SurfaceDistance of QEM's cage to the source
    fit: object = None               #: core.FitResult when the cage was fitted
    seconds: float = 0.0
    cancelled: bool = False


@dataclass(frozen=True)
class Report:
    """What a step did, for the UI and logs."""

    message: str
    faces_in: int = 0
    faces_out: int = 0
    deviation_pct: float = float("nan")
    seconds: float = 0.0


def _diag(V):
    return core.bbox_diagonal(V)


def prepare_simplify(source, params, *, depsgraph=None):
    """Read the source object into a :class:`SimplifyJob` (main thread)."""
    if source is None or source.type != 'MESH':
        raise core.InvalidMeshError("simplify: the active object is not a mesh")
    arrays = mesh_io.read_object(source, depsgraph=depsgraph)
    if arrays.F.shape[0] == 0:
        raise core.InvalidMeshError(f"simplify: '{source.name}' has no faces")
    job = SimplifyJob(source.name, params, arrays.V, arrays.F)
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
    Fit and measurement take the last 30% of the bar.
    """
    p = job.params
    t0 = time.perf_counter()
    max_error = None
    if p.max_error_pct is not None:
        max_error = p.max_error_pct / 100.0 * _diag(job.V)

    def simplify_progress(f):
        return True if progress is None else progress(0.7 * f)

    res = core.simplify(job.V, job.F, target_faces=p.target_faces, ratio=p.ratio,
                        max_error=max_error, preserve_boundary=p.preserve_boundary,
                        preserve_topology=p.preserve_topology,
                        feature_angle_deg=p.feature_angle_deg, vertex_weights=job.weights,
                        locked=job.locked, progress=simplify_progress)
    job.result = res
    if res.stopped_because == "cancelled":
        job.cancelled = True
        return job
    job.V_cage = res.V
    if p.measure:
        # the deviation of the cage QEM produced (the classic measure of a
        # simplification), before any fitting moves it
        if progress is not None and progress(0.72) is False:
            job.cancelled = True
            return job
        job.distance = core.surface_distance(job.V, job.F, res.V, res.F, samples=MEASURE_SAMPLES)
    creases = res.feature_edges if len(res.feature_edges) else None
    if p.fit and res.F.shape[0] >= 4:
        if progress is not None and progress(0.8) is False:
            job.cancelled = True
            return job
        fit_progress = None if progress is None else (lambda f: progress(0.8 + 0.18 * f))
        job.fit = core.fit_cage(job.V, job.F, res.V, res.F, levels=p.levels, scheme=p.scheme,
                                creases=creases, progress=fit_progress)
        if job.fit.cancelled:
            job.cancelled = True
            return job
        job.V_cage = job.fit.V
    job.seconds = time.perf_counter() - t0
    if progress is not None:
        progress(1.0)
    return job


def _link_like(obj, like):
    """Link ``obj`` into the collections of ``like`` (or the scene's)."""
    cols = list(like.users_collection) if like is not None else []
    if not cols:
        cols = [bpy.context.scene.collection]
    for col in cols:
        col.objects.link(obj)


def commit_simplify(source, job):
    """Create the cage object (and the bound copy) from a computed job."""
    res = job.result
    p = job.params
    name = f"{source.name}_cage"
    mesh = mesh_io.new_mesh(name, job.V_cage, res.F)
    n_creases = mesh_io.set_edge_flags(mesh, res.feature_edges, CREASE)
    if n_creases:
        sharp = mesh.attributes.get("sharp_edge") or mesh.attributes.new("sharp_edge", 'BOOLEAN',
                                                                         'EDGE')
        flags = np.zeros(len(mesh.edges), dtype=bool)
        mesh.attributes[CREASE].data.foreach_get("value", flags)
        sharp.data.foreach_set("value", flags)
    cage = bpy.data.objects.new(name, mesh)
    cage.matrix_world = source.matrix_world.copy()
    _link_like(cage, source)
    cage.show_wire = True
    cs = cage.meshadjust
    cs.role = 'CAGE'
    cs.source = source
    cs.levels = p.levels
    cs.scheme = p.scheme
    source.meshadjust.role = 'SOURCE'
    source.meshadjust.cage = cage
    faces_in = job.F.shape[0]
    dev = float("nan")
    msg = f"{faces_in:,} -> {res.F.shape[0]:,} faces"
    if job.distance is not None:
        dev = 100.0 * job.distance.hausdorff / max(_diag(job.V), 1e-300)
        msg += (f", max deviation {dev:.2f}% of size (mean "
                f"{100.0 * job.distance.mean / max(_diag(job.V), 1e-300):.3f}%)")
    msg += f", {job.seconds:.1f} s"
    if job.fit is not None:
        d = job.fit.mean_distance
        msg += (f"; fitted: mean distance of the refined cage {100 * d[0] / job.fit.diagonal:.3f}%"
                f" -> {100 * d[-1] / job.fit.diagonal:.3f}%")
    if job.notes:
        msg += "; " + "; ".join(job.notes)
    if p.bind:
        bind_object(cage)
        msg += f"; bound '{source.name}' (levels {p.levels}, {p.scheme})"
    if p.hide_source:
        source.hide_set(True)
    cs.last_report = msg
    return cage, Report(msg, faces_in, res.F.shape[0], dev, job.seconds)


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


def _edited_copy(source, cage):
    """The edited-original object of ``cage``: a copy of the source's
    (evaluated) mesh with its UVs and attributes, created once."""
    edited = cage.meshadjust.edited
    if edited is not None and edited.name in bpy.data.objects:
        return edited
    depsgraph = bpy.context.evaluated_depsgraph_get()
    mesh = bpy.data.meshes.new_from_object(source.evaluated_get(depsgraph))
    mesh.name = f"{source.name}_edited"
    edited = bpy.data.objects.new(f"{source.name}_edited", mesh)
    edited.matrix_world = source.matrix_world.copy()
    _link_like(edited, source)
    for slot, src_slot in enumerate(source.material_slots[:len(edited.material_slots)]):
        edited.material_slots[slot].material = src_slot.material
    st = edited.meshadjust
    st.role = 'EDITED'
    st.source = source
    st.cage = cage
    cage.meshadjust.edited = edited
    return edited


@dataclass
class CageJob:
    """The compute half of a bind or a fit: source and cage read from Blender."""

    cage_name: str
    V: np.ndarray                #: source positions (its local space)
    F: np.ndarray                #: source triangles
    V_cage: np.ndarray           #: cage positions in the source's space
    F_cage: np.ndarray
    creases: object
    levels: int
    scheme: str
    from_rest: bool = False
    rebind: bool = False         #: a fit also re-binds (the cage was bound)
    binding: object = None       #: core.Binding, after compute_bind
    fit: object = None           #: core.FitResult, after compute_fit
    cancelled: bool = False


def prepare_cage_job(cage, *, levels=None, scheme=None, from_rest=False):
    """Read what a bind or a fit of ``cage`` needs (main thread).

    ``from_rest`` takes the cage's shape at the last bind instead of its
    current one (to change levels or scheme without losing an edit)."""
    cs = cage.meshadjust
    source = cs.source
    if source is None:
        raise core.MeshAdjustError(f"'{cage.name}' is not a MeshAdjust cage (no source linked)")
    V_cage = store.load_rest(cage) if from_rest else _cage_in_source_space(cage, source)
    F_cage, _, creases = store.cage_topology(cage)
    depsgraph = bpy.context.evaluated_depsgraph_get()
    src = mesh_io.read_object(source, depsgraph=depsgraph)
    return CageJob(cage.name, src.V, src.F, V_cage, F_cage, creases,
                   cs.levels if levels is None else levels,
                   cs.scheme if scheme is None else scheme, from_rest)


def compute_bind(job, *, progress=None):
    """Bind the source to the cage's subdivision surface (pure NumPy, any
    thread). ``progress`` is only asked whether to go on, at the end."""
    job.binding = core.bind(job.V, job.F, job.V_cage, job.F_cage, levels=job.levels,
                            scheme=job.scheme, creases=job.creases)
    if progress is not None and progress(1.0) is False:
        job.cancelled = True
    return job


def commit_bind(cage, job):
    """Write a computed binding: the edited-original copy (created on first
    use, its vertices reset to the source's), its binding attributes and the
    cage's rest shape. Returns the edited-original object."""
    cs = cage.meshadjust
    edited = _edited_copy(cs.source, cage)
    if job.V.shape[0] != len(edited.data.vertices):
        raise core.TopologyMismatchError(
            f"'{cs.source.name}' now has {job.V.shape[0]} vertices, its edited copy "
            f"{len(edited.data.vertices)}: delete '{edited.name}' and bind again")
    mesh_io.write_positions(edited.data, job.V)
    store.save_binding(edited, job.binding)
    if not job.from_rest:
        store.save_rest(cage, job.V_cage)
    cs.levels = job.levels
    cs.scheme = job.scheme
    cs.fingerprint = job.binding.fingerprint
    return edited


def bind_object(cage, *, levels=None, scheme=None, from_rest=False):
    """(Re-)bind the cage's source to the cage (the synchronous path).

    The cage's current shape becomes the rest shape (or, with ``from_rest``,
    the shape of the last bind is used again). Returns the edited-original
    object.
    """
    job = prepare_cage_job(cage, levels=levels, scheme=scheme, from_rest=from_rest)
    return commit_bind(cage, compute_bind(job))


def compute_fit(job, *, progress=None):
    """Fit the cage to the source (pure NumPy, any thread; cancellable)."""
    job.fit = core.fit_cage(job.V, job.F, job.V_cage, job.F_cage, levels=job.levels,
                            scheme=job.scheme, creases=job.creases, progress=progress)
    job.cancelled = job.fit.cancelled
    return job


def commit_fit(cage, job):
    """Move the cage's vertices to the fitted positions."""
    source = cage.meshadjust.source
    M = np.array(cage.matrix_world.inverted() @ source.matrix_world)
    if cage.mode == 'EDIT':
        raise core.MeshAdjustError(f"leave Edit Mode on '{cage.name}' to fit it")
    mesh_io.write_positions(cage.data, job.fit.V @ M[:3, :3].T + M[:3, 3])
    return job.fit


def fit_cage_object(cage, *, levels=None, scheme=None):
    """Move the cage's vertices so its subdivision matches its source (the
    synchronous path). Returns the core's ``FitResult``."""
    job = prepare_cage_job(cage, levels=levels, scheme=scheme)
    return commit_fit(cage, compute_fit(job))


def refine_object(cage, *, output='EDITED', levels=None, scheme=None):
    """Update the results of an edited cage; returns a :class:`Report`.

    ``output``: ``'EDITED'`` (the bound copy of the source, deformed; same
    topology, UVs and attributes), ``'REFINED'`` (the subdivided cage with the
    source's detail) or ``'BOTH'``. Result objects are created once and
    updated in place afterwards.
    """
    t0 = time.perf_counter()
    cs = cage.meshadjust
    source = cs.source
    if source is None:
        raise core.MeshAdjustError(f"'{cage.name}' is not a MeshAdjust cage (no source linked)")
    edited = cs.edited
    if edited is None:
        raise core.MeshAdjustError(f"'{cage.name}' is not bound yet: bind it first")
    if (levels is not None and levels != cs.levels) or (scheme is not None and scheme != cs.scheme):
        bind_object(cage, levels=levels, scheme=scheme, from_rest=True)
    binding = store.load_binding(edited, cage)
    V_cage = _cage_in_source_space(cage, source)
    parts = []
    if output in ('EDITED', 'BOTH'):
        mesh_io.write_positions(edited.data, core.deform(binding, V_cage))
        parts.append(f"'{edited.name}' deformed ({binding.n_dense:,} vertices)")
    if output in ('REFINED', 'BOTH'):
        Vr, Fr = core.refine(binding, V_cage)
        refined = cs.refined
        if refined is not None and len(refined.data.vertices) == Vr.shape[0] \
                and len(refined.data.polygons) == Fr.shape[0]:
            mesh_io.write_positions(refined.data, Vr)
        else:
            name = f"{source.name}_refined"
            mesh = mesh_io.new_mesh(name, Vr, Fr)
            if refined is None:
                refined = bpy.data.objects.new(name, mesh)
                refined.matrix_world = source.matrix_world.copy()
                _link_like(refined, source)
                refined.meshadjust.role = 'REFINED'
                refined.meshadjust.source = source
                refined.meshadjust.cage = cage
                cs.refined = refined
            else:
                old = refined.data
                refined.data = mesh
                if old.users == 0:
                    bpy.data.meshes.remove(old)
        parts.append(f"'{refined.name}' refined ({Fr.shape[0]:,} faces, {binding.scheme} x"
                     f"{binding.levels})")
    dt = time.perf_counter() - t0
    msg = "; ".join(parts) + f", {dt:.2f} s"
    cs.last_report = msg
    return Report(msg, seconds=dt)


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
        _link_like(out, obj)
    dt = time.perf_counter() - t0
    msg = f"{arrays.F.shape[0]:,} -> {Ff.shape[0]:,} faces ({scheme}, {levels} level"
    msg += "s" if levels != 1 else ""
    msg += f"), {dt:.2f} s"
    if arrays.triangulated:
        msg += f"; triangulated {arrays.n_polygons:,} polygons first"
    if arrays.evaluated:
        msg += "; used the evaluated mesh (modifiers and shape keys applied)"
    return out, Report(msg, arrays.F.shape[0], Ff.shape[0], seconds=dt)
