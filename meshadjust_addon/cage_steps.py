"""Steps on a cage: bind and fit (the compute / commit split; Refine is
:mod:`.refine_step`).

An edit is the difference between the cage's current shape and its *rest
shape* (the point attribute ``meshadjust_rest``, saved at bind time). Fit and
re-bind work on the rest shape and carry the edit over on top of the result,
so an artist's edit is never reset without being asked to. Everything that
can fail is computed or checked before a commit writes anything; the commits
run inside :func:`.rollback.all_or_nothing`.
"""

from dataclasses import dataclass, replace

import bpy
import numpy as np

from .. import core
from . import mesh_io, results, rollback, settings, staleness, store
from .rollback import all_or_nothing

#: most levels the automatic choice picks
MAX_AUTO_LEVELS = 5
#: most levels Auto binds the edit at (the refined mesh still takes the levels
#: closest to the source's face count, :func:`refine_levels`): the edited
#: original follows the cage as it does at five levels (the folds are measured
#: at two) and a 1M-vertex scan on a 2,000-face cage binds 10x faster and
#: updates live 2x faster (0.80 against 8.52 s, 16 against 36 ms; 2026-12-06)
MAX_EDIT_LEVELS = 2
OUTPUT_NAMES = tuple(item[0] for item in settings.OUTPUTS)
#: cage faces a report names (then "...")
_LISTED_FACES = 5


def fit_levels(levels):
    """The levels a fit uses for a binding of ``levels``."""
    return min(int(levels), core.MAX_FIT_LEVELS)


def auto_levels(cage_faces, source_faces, *, max_levels=MAX_AUTO_LEVELS):
    """The subdivision levels (1..max_levels) whose refined face count,
    ``cage_faces * 4**levels``, is closest to ``source_faces``."""
    cage_faces = max(int(cage_faces), 1)
    counts = cage_faces * 4 ** np.arange(1, max_levels + 1)
    return int(np.argmin(np.abs(counts - int(source_faces)))) + 1


def edit_levels(cage_faces, source_faces):
    """The levels Auto binds the edit at: :func:`auto_levels`, at most
    :data:`MAX_EDIT_LEVELS`."""
    return min(auto_levels(cage_faces, source_faces), MAX_EDIT_LEVELS)


def refine_levels(binding_levels, cage_faces, source_faces):
    """The levels Refine makes the refined mesh at when none are asked for:
    those closest to the source's face count (:func:`auto_levels`), or the
    binding's when it has more (levels chosen by hand); the binding's when
    the source's count is not known (0)."""
    if not source_faces:
        return int(binding_levels)
    return max(int(binding_levels), auto_levels(cage_faces, source_faces))


def _diag(V):
    return core.bbox_diagonal(V)


def source_edit_problem(source):
    """Why ``source`` cannot be read now, or None: it is in Edit Mode (its own
    or a linked duplicate's), where its mesh holds the shape from before the
    Edit Mode session and no fingerprint can be taken (a bind of it went
    stale unnoticed)."""
    if not source.data.is_editmode:
        return None
    who = source.name if source.mode == 'EDIT' else next(
        (o.name for o in bpy.data.objects if o.data == source.data and o.mode == 'EDIT'),
        source.name)                                   # (a linked duplicate of it)
    if who != source.name:
        return (f"'{source.name}' shares its mesh with '{who}', which is in Edit Mode, where the "
                f"mesh does not have the edits yet: leave Edit Mode on '{who}' first")
    return (f"'{source.name}' is in Edit Mode, where its mesh does not have the edits yet: leave "
            f"Edit Mode on '{who}' first")


def read_source(source):
    """The source's mesh as the artist made it (MeshAdjust's own shape keys
    muted): ``(MeshArrays, fingerprint)``. A source in Edit Mode is refused
    (:func:`source_edit_problem`, :class:`core.MeshAdjustError`)."""
    why = source_edit_problem(source)
    if why:
        raise core.MeshAdjustError(why)
    # only MeshAdjust's keys (or keys at 0): the mesh itself, vertex groups usable
    plain = False if results.only_own_keys_and_no_modifiers(source) else None
    with results.own_keys_muted(source):
        depsgraph = bpy.context.evaluated_depsgraph_get()
        arrays = mesh_io.read_object(source, depsgraph=depsgraph, evaluated=plain)
    return arrays, staleness.source_fingerprint(source) or ""


def transform_problem(obj):
    """Why ``obj``'s world transform cannot carry MeshAdjust's objects, in
    words that say what to do, or None: a zero scale (no inverse: the cage's
    edit cannot be taken back to the source's space) or a shear (a rotated
    child of a non-uniformly scaled parent: the cage and the results take
    the source's transform as location, rotation and scale, which drop it)."""
    M = np.array(obj.matrix_world)[:3, :3]
    size = np.linalg.norm(M, axis=0)
    if not np.isfinite(M).all() or not size.min() > 1e-9 * size.max() \
            or not abs(np.linalg.det(M)) > 1e-9 * float(np.prod(size)):
        return (f"'{obj.name}' has a zero scale on an axis (its transform has no inverse): give "
                f"it a non-zero scale, or apply the scale (Object > Apply > Scale)")
    if np.abs(M.T @ M / np.outer(size, size) - np.eye(3)).max() > 1e-6:
        return (f"'{obj.name}' has a sheared transform (it is rotated under a parent scaled "
                f"unevenly), which its cage and results cannot copy: apply the parent's scale "
                f"(Object > Apply > Scale on '{obj.parent.name if obj.parent else obj.name}')")
    return None


def source_space(cage, source):
    """The (4,4) matrix from the cage's local space to the source's (their
    object transforms), both transforms checked (:func:`transform_problem`:
    a :class:`core.MeshAdjustError` naming the object), and the cage's own
    shape keys refused (its mesh is read, not what its keys show)."""
    for obj in (source, cage):
        why = transform_problem(obj)
        if why:
            raise core.MeshAdjustError(why)
    keys = cage.data.shape_keys
    if keys is not None and len(keys.key_blocks) > 1:
        raise core.MeshAdjustError(
            f"'{cage.name}' has shape keys: MeshAdjust reads the cage's mesh, not what its keys "
            f"show, so an edit made through them would be lost; apply them to the mesh (Shape "
            f"Keys > Apply All Shape Keys) or delete them")
    moving = _moving_modifiers(cage)
    if moving:
        raise core.MeshAdjustError(
            f"'{cage.name}' shows its vertices moved by its modifiers ({', '.join(moving)}): "
            f"MeshAdjust reads the cage's mesh, not what its modifiers show, so an edit made "
            f"through them would be lost; apply them to the mesh, or turn them off in the "
            f"viewport (a Subdivision Surface or Mirror preview is fine)")
    return np.array(source.matrix_world.inverted() @ cage.matrix_world)


def _moving_modifiers(cage):
    """The names of the cage's viewport modifiers when what they show has the
    cage's vertices elsewhere (a Displace, a Lattice: an edit made through
    them was silently left out), else []. A modifier that adds vertices (a
    Subdivision Surface or Mirror preview) shows more than the cage's
    vertices: not one of these."""
    shown = [m for m in cage.modifiers if m.show_viewport]
    if not shown:
        return []
    if cage.mode == 'EDIT':
        cage.update_from_editmode()
    ob_eval = cage.evaluated_get(bpy.context.evaluated_depsgraph_get())
    mesh = ob_eval.to_mesh()
    try:
        if len(mesh.vertices) != len(cage.data.vertices):
            return []
        V_shown = mesh_io.read_positions32(mesh)
    finally:
        ob_eval.to_mesh_clear()
    V = mesh_io.read_positions32(cage.data)
    tol = 1e-6 * max(core.bbox_diagonal(V.reshape(-1, 3).astype(np.float64)), 1e-300)
    if np.abs(V_shown - V).max(initial=0.0) <= tol:
        return []
    return [m.name for m in shown]


def _bound_source_matrix(cage):
    """The source's (4,4) world matrix when ``cage`` was bound, or None (not
    bound, or bound before it was recorded)."""
    edited = cage.meshadjust.edited
    return results.recorded_matrix(edited.meshadjust.source_matrix) if edited is not None else None


def _moved_since_bind(cage, source):
    """The matrix taking the source's local space at bind time to its space
    now, or None when its transform is the same (or was not recorded): the
    source moved, or its transform was applied to its mesh."""
    M0 = _bound_source_matrix(cage)
    if M0 is None:
        return None
    M = np.array(source.matrix_world)
    if np.abs(M - M0).max() <= 1e-6 * max(1.0, float(np.abs(M0).max())):
        return None
    return np.linalg.inv(M) @ M0


def check_source_in_place(cage, source):
    """Raise :class:`core.MeshAdjustError` when the source's transform changed
    since the bind (the binding, the cage's rest shape and the results are in
    its space then: Refine took the change for an edit of the whole cage, and
    the results jumped)."""
    source_space(cage, source)              # (a transform with no inverse named first)
    if _moved_since_bind(cage, source) is not None:
        raise core.MeshAdjustError(
            f"'{source.name}' was moved, rotated or scaled (or had its transform applied) since "
            f"'{cage.name}' was bound, and the binding is in its old place: Bind (Keep edit) "
            f"binds it where it is now and keeps the edit")


def cage_in_source_space(cage, source):
    """(n_cage,3) float64 cage positions in the source's local space (Edit
    Mode synced first; object transforms respected, :func:`source_space`)."""
    if cage.mode == 'EDIT':
        cage.update_from_editmode()
    V = mesh_io.read_positions(cage.data)
    M = source_space(cage, source)
    with np.errstate(invalid="ignore", over="ignore"):     # (named below)
        V_source = V @ M[:3, :3].T + M[:3, 3]
    bad = ~np.isfinite(V_source).all(axis=1)
    if bad.any():
        # (Refine, Bind and Fit had named the core's inner functions: 'turned_faces: 1
        # vertices of V_new have NaN ...', 'bbox_diagonal: ...')
        i = int(np.flatnonzero(bad)[0])
        raise core.InvalidMeshError(
            f"'{cage.name}' has {int(bad.sum()):,} vertex position{'s' if bad.sum() > 1 else ''} "
            f"that {'are' if bad.sum() > 1 else 'is'} not a number or infinite (vertex {i} = "
            f"{V[i].tolist()}): move {'them' if bad.sum() > 1 else 'it'} back, or undo")
    return V_source


def _source_to_cage(cage, source, V):
    M = np.linalg.inv(source_space(cage, source))
    return V @ M[:3, :3].T + M[:3, 3]


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
    #: the levels of the refined mesh a re-bind rewrites when they are not the binding's
    #: (:func:`refine_levels`; 0: the binding's, or no refined mesh to rewrite)
    refine_levels: int = 0
    refine_binding: object = None  #: the refined mesh's binding at those, after compute_bind
    fit: object = None           #: core.FitResult, after compute_fit
    cancelled: bool = False
    V_now: np.ndarray = None     #: the cage's current positions (source space)
    V_edited: np.ndarray = None  #: the edited original's positions, after compute_bind
    source_fingerprint: str = ""
    old_levels: int = 0          #: the binding's levels and scheme before (0: unbound)
    old_scheme: str = ""
    note: str = ""               #: what the commit re-made, for the report
    symmetry: str = None         #: the cage's mirror axis ('X', 'Y', 'Z'), kept by a fit
    faces_key: str = ""          #: ``mesh_io.polygon_key`` of the source's mesh read ("": unknown)
    #: the edited original's :func:`~.store.binding_stamp` when read (the commit refuses another)
    bound: object = None
    #: faces of more than three corners the commit triangulates (:func:`_cage_topology`)
    triangulated: int = 0

    @property
    def n_moved(self):
        """Cage vertices the edit moves (beyond float32 rounding)."""
        if self.V_now is None or self.V_now.shape != self.V_cage.shape:
            return 0
        tol = 1e-6 * max(_diag(self.V_cage), 1e-300)
        return int(np.count_nonzero(np.abs(self.V_now - self.V_cage).max(axis=1) > tol))


def _rest_of(cage, n):
    """The cage's saved rest shape (source space) when it has one for ``n``
    vertices, else None; in the source's space now when its transform
    changed since the bind (:func:`_moved_since_bind`)."""
    if cage.data.attributes.get(store.REST) is None and not cage.data.is_editmode:
        return None
    try:
        V_rest = store.load_rest(cage)
    except core.MeshAdjustError:
        return None
    if V_rest.shape[0] != n:
        return None
    A = _moved_since_bind(cage, cage.meshadjust.source)
    return V_rest if A is None else V_rest @ A[:3, :3].T + A[:3, 3]


def _check_cage_surface(cage, F_cage, n_cage):
    """Raise :class:`core.MeshAdjustError` naming what an edit made of the
    cage that no step can bind: no face left, edges of more than two faces,
    vertices where separate fans meet, faces with a repeated corner or on
    the same corners as another (the core's own check named its arguments:
    'fit_cage: F_cage has no faces', 'bind: the cage (F_cage): 3
    non-manifold edges')."""
    if F_cage.shape[0] == 0:
        raise core.MeshAdjustError(f"'{cage.name}' has no faces left: undo the edit that removed "
                                   f"them, or make a new cage with Simplify")
    rep = core.manifold_report(F_cage, n_cage)
    found = [f"{k:,} {what[k != 1]}" for k, what in (
        (rep.non_manifold_edges.shape[0], ("edge of more than two faces",
                                           "edges of more than two faces")),
        (rep.non_manifold_vertices.shape[0], ("vertex where separate fans of faces meet",
                                              "vertices where separate fans of faces meet")),
        (rep.degenerate_faces.shape[0], ("face with a repeated corner",
                                         "faces with a repeated corner")),
        (rep.duplicate_faces.shape[0], ("face on the same corners as another",
                                        "faces on the same corners as others"))) if k]
    if found:
        raise core.MeshAdjustError(
            f"'{cage.name}' has {', '.join(found)} (made in Edit Mode): a cage must be a clean "
            f"surface; undo that edit (or Merge by Distance, Delete Loose), or make a new cage "
            f"with Simplify")


def _check_rest(cage, V_rest, V_now, F_cage):
    """Refuse a rest shape that cannot be bound: faces made in Edit Mode after
    the bind (an extrusion, a fill) get their vertices' rest positions from
    the vertices they came from, so they can have no area at rest."""
    tol = 1e-12 * max(_diag(V_now), 1e-300) ** 2
    flat = (core.face_areas(V_rest, F_cage) <= tol) & (core.face_areas(V_now, F_cage) > tol)
    if flat.any():
        raise core.MeshAdjustError(
            f"'{cage.name}': {int(flat.sum()):,} faces added in Edit Mode have no rest shape "
            f"(e.g. an extrusion), so the edit cannot be kept on top of it: Bind with Keep edit "
            f"off makes the current shape the rest shape")


def prepare_cage_job(cage, *, levels=None, scheme=None, from_rest=False, keep_edit=False,
                     refined=None):
    """Read what a bind or a fit of ``cage`` needs (main thread).

    ``levels`` / ``scheme`` None (or 0 / ``'BOUND'``) keep the cage's. With
    ``keep_edit`` (or the older name ``from_rest``), the cage's saved rest
    shape is bound or fitted and the edit (current - rest) carried over; a
    cage without a rest shape counts as unedited. ``refined``: whether the
    re-bind also binds at the refined mesh's levels (:func:`refine_levels`)
    when they are not the binding's (None: when the cage has a refined
    mesh, which the commit rewrites)."""
    cs = cage.meshadjust
    source = cs.source
    if source is None:
        raise core.MeshAdjustError(f"'{cage.name}' is not a MeshAdjust cage (no source linked)")
    if levels is not None:
        levels = settings.checked("levels", levels, f"'{cage.name}'")
    if scheme is not None and scheme != 'BOUND':
        scheme = settings.checked("scheme", scheme, f"'{cage.name}'")
    why = results.edit_mode_problem(cs.edited, cs.refined)      # (a bind writes both)
    if why:
        raise core.MeshAdjustError(why)
    V_now = cage_in_source_space(cage, source)
    V_rest = _rest_of(cage, V_now.shape[0]) if (keep_edit or from_rest) else None
    F_cage, creases, split = _cage_topology(cage)
    _check_cage_surface(cage, F_cage, V_now.shape[0])
    if V_rest is not None:
        _check_rest(cage, V_rest, V_now, F_cage)
    results.follow_renamed_keys(source)      # (a renamed key is muted for the read, as its name was)
    src, fp = read_source(source)
    if results.shape_key_of(source, cage) is not None:      # (a bind rewrites the key too)
        why = results.shape_key_unavailable(source, src.V.shape[0], cage, binding=True)
        if why:
            raise core.MeshAdjustError(f"the shape key of '{cage.name}': {why}")
    if levels in (None, 0):
        levels = cs.levels or edit_levels(F_cage.shape[0], src.F.shape[0])
    if scheme in (None, 'BOUND'):
        scheme = cs.scheme
    bound = cs.edited is not None
    if refined is None:
        refined = cs.refined is not None
    finer = refine_levels(levels, F_cage.shape[0], src.F.shape[0]) if refined else 0
    return CageJob(cage.name, src.V, src.F, V_now if V_rest is None else V_rest, F_cage, creases,
                   levels, scheme, V_rest is not None, V_now=V_now, source_fingerprint=fp,
                   old_levels=cs.levels if bound else 0, old_scheme=cs.scheme if bound else "",
                   symmetry=None if cs.symmetry == 'NONE' else cs.symmetry,
                   faces_key=src.faces_key, refine_levels=finer if finer != levels else 0,
                   bound=store.binding_stamp(cs.edited), triangulated=split)


def _cage_topology(cage):
    """(F_cage, creases, split): the triangles and creases a bind or a fit
    of ``cage`` takes. A cage with faces of more than three corners in
    Object Mode is taken as the commit will triangulate it
    (:func:`_write_triangles`; ``split``: how many faces, else 0); in Edit
    Mode :func:`.store.cage_topology` names them."""
    split = 0 if cage.mode == 'EDIT' else mesh_io.split_polygons(cage.data)
    if not split:
        F, _, creases = store.cage_topology(cage)
        return F, creases, 0
    mesh = store.triangulated_copy(cage.data)
    try:
        F = mesh_io.read_triangles(mesh)[0]
        creases = mesh_io.get_edge_flags(mesh, store.CREASE)
    finally:
        bpy.data.meshes.remove(mesh)
    return F, (creases if creases.shape[0] else None), split


def _write_triangles(cage, job):
    """Give ``cage`` the triangles ``job`` was computed on when it has faces
    of more than three corners (:func:`_cage_topology`), inside the open
    rollback block: its mesh is swapped for :func:`.store.triangulated_copy`
    (the old one removed when the block succeeds, given back when it fails)."""
    if not mesh_io.split_polygons(cage.data):
        return
    old = cage.data
    cage.data = store.triangulated_copy(old)
    rollback.retire(old, successor=cage.data)
    if not np.array_equal(mesh_io.read_triangles(cage.data)[0], job.F_cage):
        raise core.MeshAdjustError(f"'{cage.name}' changed topology while the step ran: nothing "
                                   f"was changed; run it again")


def _triangulated_note(job):
    """The report's words for the faces :func:`_write_triangles` split ("" for none)."""
    k = job.triangulated
    return (f"triangulated {k:,} face{'s' if k != 1 else ''} of more than three corners of "
            f"'{job.cage_name}' (a cage is triangles)") if k else ""


def check_current(cage, job):
    """Raise :class:`core.MeshAdjustError` when what ``job`` was read from
    changed before its commit (the artist worked on while Fit or Bind ran in
    the background: a KeyError, or a binding of the old topology written
    under the new one, before): the cage's source gone, a result it writes
    in Edit Mode, the cage's topology, or the source's mesh or modifiers
    changed (its other shape keys are left to the staleness check: which of
    them are MeshAdjust's depends on the cages there are)."""
    cs = cage.meshadjust
    if cs.source is None:
        raise core.MeshAdjustError(f"'{cage.name}' lost its source object: nothing was changed")
    why = results.edit_mode_problem(cs.edited, cs.refined)
    if why:
        raise core.MeshAdjustError(why)
    F_now = _cage_topology(cage)[0]
    was, now = (staleness.fingerprint_fields(fp or "") for fp in
                (job.source_fingerprint, staleness.source_fingerprint(cs.source)))
    if F_now.shape != job.F_cage.shape or not np.array_equal(F_now, job.F_cage):
        what = f"'{cage.name}' changed topology"
    elif store.binding_stamp(cs.edited) != job.bound:
        what = f"'{cage.name}' was bound again"
    elif was and now and was._replace(keys="") != now._replace(keys=""):
        what = f"'{cs.source.name}' changed"
    else:
        return
    raise core.MeshAdjustError(f"{what} while the step ran: nothing was changed; run it again")


def compute_bind(job, *, progress=None):
    """Bind the source to the cage's rest shape and deform it by the edit
    (pure NumPy, any thread); with ``job.refine_levels``, bind it at those
    for the refined mesh too (:func:`refine_binding`). ``progress`` follows
    the binds' closest-point searches (the first 90%); returning False
    cancels (``job.cancelled``)."""
    if progress is not None and progress(0.0) is False:
        job.cancelled = True
        return job
    share = 0.2 if job.refine_levels else 0.9      # (the finer bind is the longer one)
    try:
        job.binding = core.bind(
            job.V, job.F, job.V_cage, job.F_cage, levels=job.levels, scheme=job.scheme,
            creases=job.creases,
            progress=None if progress is None else (lambda f: progress(share * f)))
        if job.refine_levels:
            job.refine_binding = refine_binding(
                job.V, job.F, job.V_cage, job.binding, job.refine_levels,
                progress=None if progress is None else (lambda f: progress(0.2 + 0.7 * f)))
    except core.CancelledError:
        job.cancelled = True
        return job
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
    use, re-made when the source's vertex count or faces changed), deformed by the
    edit; its binding attributes and fingerprints; the cage's rest shape;
    the other results that exist, updated. Returns the edited-original
    object (``job.notes`` gets what was re-made)."""
    check_current(cage, job)
    cs = cage.meshadjust
    source = cs.source
    with all_or_nothing() as rb:
        _write_triangles(cage, job)
        notes = [_triangulated_note(job)] if job.triangulated else []
        owner = results.copied_from(cage)
        if owner is not None:          # a copy of another cage: results of its own from now on
            cs.edited, cs.refined, cs.key_name, cs.key_written = None, None, "", ""
            notes.append(f"'{cage.name}' was a copy of '{owner.name}': given results of its own")
        if cs.edited is not None:
            rb.keep(cs.edited.data)
            if cs.edited.users_collection:
                results.aside_note(results.kept_aside(cs.edited), cs.edited, notes)
        if cs.refined is not None and cs.refined.users_collection:   # (before a move below)
            results.aside_note(results.kept_aside(cs.refined), cs.refined, notes)
        rb.keep(cage.data)
        A = _moved_since_bind(cage, source)            # (before the new matrix is recorded)
        edited, note = results.edited_copy(source, cage, job.V.shape[0], job.faces_key)
        notes += [note] if note else []
        if A is not None:      # the results keep their place beside the source's new space
            for obj in (edited, cs.refined):
                if obj is not None:
                    obj.matrix_world = obj.matrix_world @ results.blender_matrix(np.linalg.inv(A))
        edited.meshadjust.source_matrix = results.matrix_values(source.matrix_world)
        results.record_written(edited, mesh_io.write_positions(
            edited.data, job.V_edited if job.V_edited is not None else job.V))
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
            finer = job.refine_binding if job.refine_binding is not None else job.binding
            results.write_refined(cage, source, *core.refine(finer, V_now), notes=notes)
        if job.refine_binding is not None:
            keep_refine_binding(edited.session_uid, job.binding, job.refine_binding)
        if results.shape_key_of(source, cage) is not None:
            write_key(source, cage, edited, job.binding, job.V_edited, V_rest=job.V_cage,
                      notes=notes)
        job.note = "; ".join(notes)
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
    # (cleaned as a simplify to the cage's face count cleans it: the Simplify's own fit's
    # surface, without the specks too small for one face of the cage)
    job.fit = core.fit_cage(job.V, job.F, job.V_cage, job.F_cage, levels=fit_levels(job.levels),
                            scheme=job.scheme, creases=job.creases, symmetry=job.symmetry,
                            progress=fit_progress)
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
    check_current(cage, job)
    with all_or_nothing() as rb:
        _write_triangles(cage, job)
        rb.keep(cage.data)
        mesh_io.write_positions(cage.data, _source_to_cage(cage, source, job.V_now))
        if job.binding is not None:
            commit_bind(cage, job)
        else:
            job.note = _triangulated_note(job)
        staleness.touched(cage)
    return job.fit


def fit_cage_object(cage, *, levels=None, scheme=None, rebind=settings.default("rebind")):
    """Fit the cage (the synchronous path): its rest shape moves so its
    subdivision matches the source, the edit stays on top. Returns the
    core's ``FitResult``."""
    job = prepare_fit(cage, rebind=rebind, levels=levels, scheme=scheme)
    return commit_fit(cage, compute_fit(job))


_rest_dense = {}   #: edited session_uid -> (binding, dense positions of its rest shape)


def write_key(source, cage, edited, binding, V_edited, *, V_rest=None, notes=None):
    """The shape-key output: relative to the mesh that was bound."""
    V_bound = None
    if not results.only_own_keys_and_no_modifiers(source):
        hit = _rest_dense.get(edited.session_uid)
        if hit is None or hit[0] is not binding:
            if V_rest is None:
                V_rest = store.load_rest(cage)
            hit = (binding, core.deform(binding, V_rest))
            _rest_dense[edited.session_uid] = hit
        V_bound = hit[1]
    return results.write_shape_key(source, cage, V_edited, V_bound, notes)


_refine_bindings = {}   #: edited session_uid -> (the edit's binding, the refined mesh's binding)


def refine_binding(V, F, V_rest, binding, levels, *, progress=None):
    """The binding Refine makes the refined mesh with at other ``levels``
    than the edit's ``binding`` of the source (``V``, ``F``; ``V`` the
    positions ``binding`` binds): the source's detail at ``levels`` on the
    rest shape ``V_rest``, with the edit's scheme and creases, and no dense
    vertices (the refined mesh needs only the detail of its fine vertices;
    the edited original keeps ``binding``): :func:`core.bind_refined`, which
    finds it from ``binding`` (a 1M-vertex scan at five levels: 2.6x less CPU);
    a binding without its dense faces (read from an older file) binds the
    source again at ``levels``."""
    if binding.F_dense is not None:
        return core.bind_refined(binding, V, levels, V_cage=V_rest, progress=progress)
    finer = core.bind(V, F, V_rest, binding.F_cage, levels=levels, scheme=binding.scheme,
                      creases=binding.creases, progress=progress)
    none = np.zeros((0, 3))
    return replace(finer, fine_face=np.zeros(0, np.int64), bary=none, offset=none, F_dense=None)


def kept_refine_binding(edited_uid, binding, levels):
    """The refined mesh's binding at ``levels`` kept for the edit's
    ``binding`` of the edited original ``edited_uid`` (its ``session_uid``),
    or None: kept while that binding stays the one in use (a re-bind or an
    undo makes another)."""
    hit = _refine_bindings.get(edited_uid)
    if hit is not None and hit[0] is binding and hit[1].levels == levels:
        return hit[1]
    return None


def keep_refine_binding(edited_uid, binding, finer):
    """Keep ``finer`` (:func:`refine_binding`) for the edit's ``binding`` of
    the edited original ``edited_uid`` (the last one only)."""
    _refine_bindings[edited_uid] = (binding, finer)


def turned_cage_note(cage, binding, V_cage):
    """A warning when the edit turned faces of the cage itself over (normal
    more than 90 degrees from its rest normal, as the cage's map as a whole
    takes it: ``Binding.rest_as_a_whole``; a cage object mirrored (scale -1)
    had been said to turn 207 faces over): the results fold there whatever the
    scheme, and only the edit can undo it. Empty otherwise, or when the
    binding has no rest shape."""
    if binding.V_cage_rest is None:
        return ""
    turned = core.turned_faces(binding.rest_as_a_whole(V_cage), V_cage, binding.F_cage)
    if not turned.size:
        return ""
    listed = ", ".join(str(f) for f in turned[:_LISTED_FACES].tolist())
    more = ", ..." if turned.size > _LISTED_FACES else ""
    return (f"the edit turns {turned.size:,} face{'s' if turned.size > 1 else ''} of "
            f"'{cage.name}' over (face index {listed}{more}): the result folds there; "
            f"move those vertices back a little")
