"""MeshAdjust operators: thin wrappers over :mod:`.api`.

Each catches the core's own errors (``core.MeshAdjustError``, which the
add-on's Blender layer raises too) and turns them into
``self.report({'ERROR'}, ...)`` plus ``{'CANCELLED'}``; any other exception
is a bug and surfaces as one. Nothing is changed in the scene before the
compute part has succeeded. Simplify, Fit, Bind and Refine run modal from the UI
(work in a worker thread, a progress bar, Esc cancels) and synchronously
from scripts and in background mode. Their properties are declared once, in
``settings.py``.
"""

import threading

import bpy

from .. import core
from . import api, basis, results, settings, staleness, store
from .report import fit_change

USER_ERRORS = (core.MeshAdjustError,)

SimplifyProps = settings.mixin("SimplifyProps", settings.SIMPLIFY)
FitProps = settings.mixin("FitProps", settings.FIT)
BindProps = settings.mixin("BindProps", settings.BIND)
RefineProps = settings.mixin("RefineProps", settings.REFINE)
SubdivideProps = settings.mixin("SubdivideProps", settings.SUBDIVIDE)


def cage_of(obj):
    """The cage an object belongs to (itself, its cage, or its results' cage)."""
    if obj is None or obj.type != 'MESH':
        return None
    st = obj.meshadjust
    if st.role == 'CAGE':
        return obj
    if st.cage is not None and st.cage.meshadjust.role == 'CAGE':
        return st.cage
    return None


def selected_cages(context):
    """The cages of the active and the selected objects, active first, each once."""
    cages = []
    for obj in [context.active_object, *context.selected_objects]:
        cage = cage_of(obj)
        if cage is not None and cage not in cages:
            cages.append(cage)
    return cages


def simplify_unavailable(context):
    """Why Simplify cannot run on the active object (None when it can)."""
    obj = context.active_object
    if obj is None:
        return "Select a mesh object"
    if obj.type != 'MESH':
        kind = obj.type.lower().replace("_", " ")
        return f"'{obj.name}' is {'an' if kind[0] in 'aeiou' else 'a'} {kind}, not a mesh"
    if obj.mode == 'EDIT':
        return "Leave Edit Mode to simplify"
    if obj.meshadjust.role == 'CAGE':
        return f"'{obj.name}' is already a cage"
    if len(obj.data.polygons) == 0 and not obj.modifiers:    # (a Screw modifier makes faces)
        return f"'{obj.name}' has no faces"
    return api.source_problem(obj)


def cage_unavailable(context, need_binding=False, reads_source=False):
    """Why a cage step cannot run (None when it can); ``reads_source``: the
    step reads the source (Fit, Bind), which cannot be read in Edit Mode."""
    obj = context.active_object
    cage = cage_of(obj)
    if cage is None:
        return "Simplify a mesh first: the active object is not a cage"
    if cage.meshadjust.source is None:
        return f"'{cage.name}' lost its source object"
    if reads_source:
        why = api.source_edit_problem(cage.meshadjust.source)
        if why:
            return why
    if need_binding:
        edited = cage.meshadjust.edited
        if edited is None:
            return f"'{cage.name}' is not bound: use Bind"
        copied = results.copy_problem(cage)
        if copied:
            return copied
        what = staleness.cage_change(cage, edited)
        if what:
            return f"'{cage.name}' changed topology since it was bound ({what}): re-bind it"
    return None


def binding_warnings(cage):
    """What is out of date about a bound cage, beside its topology (the
    source changed since the bind): a list of sentences, each fixed by Re-bind."""
    edited = cage.meshadjust.edited if cage is not None else None
    source = cage.meshadjust.source if cage is not None else None
    if edited is None or source is None:
        return []
    stale = staleness.source_change(source, edited.meshadjust.source_fingerprint) \
        or store.binding_misfit(edited)
    data = None if stale else staleness.source_data_change(source, edited)   # (said once)
    try:
        api.check_source_in_place(cage, source)
        moved = None
    except USER_ERRORS as exc:             # (moved or applied: Refine refuses until Re-bind)
        moved = str(exc)
    return [w for w in (stale, data, moved) if w]


def report_level(reports):
    """'WARNING' when any of the api reports is one, else 'INFO'."""
    return 'WARNING' if any(r.level == 'WARNING' for r in reports) else 'INFO'


def run_each(op, items, step):
    """Run ``step(item) -> api.Report`` on every item (objects or cages).

    An item that fails with the core's error is reported and the others
    still run: a single item that fails is an ERROR and ``{'CANCELLED'}``
    (nothing was changed), several of which some succeeded a WARNING naming
    the failed ones and ``{'FINISHED'}`` (what was done is kept, and undo can
    take it back)."""
    reports, failed = [], []
    for item in items:
        try:
            reports.append((item.name, step(item)))
        except USER_ERRORS as exc:
            failed.append(f"{item.name}: {exc}")
    text = " | ".join(f"{name}: {r.message}" if len(items) > 1 else r.message
                      for name, r in reports)
    if failed and not reports:
        op.report({'ERROR'}, " | ".join(failed))
        return {'CANCELLED'}
    if failed:
        op.report({'WARNING'}, f"failed: {' | '.join(failed)} (done: {text})")
        return {'FINISHED'}
    op.report({report_level([r for _, r in reports])}, text)
    return {'FINISHED'}


class _Background:
    """Mixin for long operators: the pure-NumPy compute half runs in a worker
    thread while a modal timer shows progress (``wm.progress_*`` and the
    panel's bar); Esc cancels, and nothing in the scene changes until
    ``finish()`` commits the result on the main thread. Headless (no window),
    ``execute()`` runs the synchronous path instead.

    An operator that changed something outside the scene's data before the
    work began (Fit leaves Edit Mode) defines ``give_back()``, called when the
    work fails or is cancelled.

    The operator calls ``start_background(context, label, compute)`` from
    ``invoke()``, where ``compute(progress)`` returns a job with a
    ``cancelled`` flag, and implements ``finish(context)``.
    """

    _timer = None
    _thread = None
    _job = None
    _error = None
    _cancel = False
    _fraction = 0.0

    def start_background(self, context, label, compute):
        self._scene_uid = context.scene.session_uid
        settings = context.scene.meshadjust
        settings.running = True
        settings.progress = 0.0
        settings.progress_text = label
        self._cancel = False
        self._error = None
        self._fraction = 0.0

        def progress(fraction):
            # worker thread: touch no Blender data here; modal() copies it
            self._fraction = fraction
            return not self._cancel

        def work():
            try:
                self._job = compute(progress)
            except Exception as exc:   # reported from the main thread in modal()
                self._error = exc

        self._thread = threading.Thread(target=work, daemon=True)
        self._thread.start()
        wm = context.window_manager
        wm.progress_begin(0, 100)
        self._timer = wm.event_timer_add(0.1, window=context.window)
        wm.modal_handler_add(self)
        return {'RUNNING_MODAL'}

    def modal(self, context, event):
        wm = context.window_manager
        # the bar of the scene the step started in (the artist may show another now: its
        # bar stayed "running" for good before)
        uid = getattr(self, "_scene_uid", None)
        settings = next((s for s in bpy.data.scenes if s.session_uid == uid),
                        context.scene).meshadjust
        if event.type == 'ESC':
            self._cancel = True
            settings.progress_text = "Cancelling..."
        if event.type != 'TIMER':
            return {'RUNNING_MODAL'} if event.type == 'ESC' else {'PASS_THROUGH'}
        settings.progress = self._fraction
        wm.progress_update(int(100 * self._fraction))
        for area in context.screen.areas if context.screen else []:
            if area.type == 'VIEW_3D':
                area.tag_redraw()
        if self._thread.is_alive():
            return {'RUNNING_MODAL'}
        wm.event_timer_remove(self._timer)
        wm.progress_end()
        settings.running = False
        settings.progress_text = ""
        give_back = getattr(self, "give_back", None) or (lambda: None)
        if self._error is not None:
            give_back()
            if isinstance(self._error, USER_ERRORS):
                self.report({'ERROR'}, str(self._error))
                return {'CANCELLED'}
            raise self._error   # a bug: let it show as one
        if self._cancel or getattr(self._job, "cancelled", False):
            give_back()
            self.report({'WARNING'}, f"{self.bl_label} cancelled: nothing was changed")
            return {'CANCELLED'}
        try:
            return self.finish(context)
        except USER_ERRORS as exc:
            give_back()
            self.report({'ERROR'}, str(exc))
            return {'CANCELLED'}


def _select_only(context, obj):
    """Select ``obj`` alone and make it active, when it is in the view layer
    (not when its collection was excluded, or another scene shown, while the
    step ran in the background: a traceback before)."""
    if obj.name not in context.view_layer.objects:
        return
    for o in context.selected_objects:
        o.select_set(False)
    obj.select_set(True)
    context.view_layer.objects.active = obj


def object_by_uid(uid, name, label):
    """The object whose ``session_uid`` is ``uid`` (renamed or not), for the
    commit of a background step; :class:`core.MeshAdjustError` when the
    artist deleted ``name`` while ``label`` ran (it had been a KeyError)."""
    found = next((o for o in bpy.data.objects if o.session_uid == uid), None)
    if found is None:
        raise core.MeshAdjustError(f"'{name}' was deleted while {label} ran: nothing was changed")
    return found


class MESHADJUST_OT_simplify(_Background, SimplifyProps, bpy.types.Operator):
    """Simplify the selected dense meshes into coarse cages (QEM edge collapse); the sources are never modified"""

    bl_idname = "meshadjust.simplify"
    bl_label = "Simplify to Cage"
    bl_options = {'REGISTER', 'UNDO'}

    @classmethod
    def poll(cls, context):
        why = simplify_unavailable(context)
        if why:
            cls.poll_message_set(why)
        return why is None

    def params(self):
        return api.SimplifyParams.from_settings(self)

    def _targets(self, context):
        objs = [o for o in context.selected_objects if o.type == 'MESH'
                and o.meshadjust.role != 'CAGE']
        act = context.active_object
        if act is not None and act not in objs:
            objs.insert(0, act)
        return objs

    def execute(self, context):
        cages = []

        def step(obj):
            cage, report = api.simplify_object(obj, **self.params().keywords())
            cages.append(cage)
            return report

        result = run_each(self, self._targets(context), step)
        if cages:
            _select_only(context, cages[-1])
        return result

    # --- interactive path: compute in a worker thread, Esc cancels
    def invoke(self, context, event):
        if bpy.app.background or len(self._targets(context)) != 1:
            return self.execute(context)
        obj = context.active_object
        try:
            job = api.prepare_simplify(obj, self.params())
        except USER_ERRORS as exc:
            self.report({'ERROR'}, f"{obj.name}: {exc}")
            return {'CANCELLED'}
        self._job, self._source_uid = job, obj.session_uid
        return self.start_background(context, f"Simplifying {obj.name}",
                                     lambda progress: api.compute_simplify(job, progress=progress))

    def finish(self, context):
        obj = object_by_uid(self._source_uid, self._job.source_name, self.bl_label)
        cage, report = api.commit_simplify(obj, self._job)
        _select_only(context, cage)
        self.report({report.level}, report.message)
        return {'FINISHED'}


class _CageStep:
    """Mixin: the operator runs on the active object's cage; ``poll`` says
    why not (``_needs_binding``: the cage must also have a valid binding;
    ``_reads_source``: the step reads the source, which must not be in Edit
    Mode)."""

    _needs_binding = False
    _reads_source = False

    @classmethod
    def poll(cls, context):
        why = cage_unavailable(context, need_binding=cls._needs_binding,
                               reads_source=cls._reads_source)
        if why:
            cls.poll_message_set(why)
        return why is None


def _object_mode(obj):
    """Leave Edit Mode on ``obj`` (its edits reach its mesh)."""
    if obj.mode == 'EDIT':
        try:
            with bpy.context.temp_override(active_object=obj, object=obj):
                bpy.ops.object.mode_set(mode='OBJECT')
        except RuntimeError as exc:   # Blender's own refusal, e.g. another object's mode
            raise core.MeshAdjustError(f"could not leave Edit Mode on '{obj.name}': {exc}") from exc


def _edit_mode(obj):
    """Enter Edit Mode on ``obj`` again."""
    try:
        with bpy.context.temp_override(active_object=obj, object=obj):
            bpy.ops.object.mode_set(mode='EDIT')
    except RuntimeError as exc:
        raise core.MeshAdjustError(f"could not enter Edit Mode on '{obj.name}': {exc}") from exc


class _CageJobStep(_Background, _CageStep):
    """Mixin for the long cage steps (fit, bind, refine): every selected cage in turn
    from ``execute()``; a single cage runs in the background from ``invoke()``.
    Subclasses implement ``_prepare(cage) -> job`` (main thread),
    ``_compute(job, progress) -> job`` (any thread) and ``_commit()`` (a
    message or an :class:`api.Report`), and may narrow ``_cages(context)``.
    Several cages run as :func:`run_each` says: a cage that fails is named,
    the others still run."""

    def _cages(self, context):
        return selected_cages(context)

    def execute(self, context):
        give_back = getattr(self, "give_back", None) or (lambda: None)

        def step(cage):
            try:
                self._cage_uid = cage.session_uid
                self._job = self._compute(self._prepare(cage))
                if self._job.cancelled:
                    raise core.MeshAdjustError(f"{self.bl_label} cancelled: nothing was changed")
                return _as_report(self._commit())
            except USER_ERRORS:
                give_back()
                raise

        return run_each(self, self._cages(context), step)

    def invoke(self, context, event):
        cages = self._cages(context)
        if bpy.app.background or len(cages) != 1:
            return self.execute(context)
        try:
            self._cage_uid = cages[0].session_uid
            job = self._prepare(cages[0])
        except USER_ERRORS as exc:
            (getattr(self, "give_back", None) or (lambda: None))()   # (Fit left Edit Mode)
            self.report({'ERROR'}, f"{cages[0].name}: {exc}")
            return {'CANCELLED'}
        self._job = job
        return self.start_background(context, f"{self.bl_label}: {cages[0].name}",
                                     lambda progress: self._compute(job, progress))

    def finish(self, context):
        report = _as_report(self._commit())
        self.report({report.level}, report.message)
        return {'FINISHED'}

    def _cage(self):
        """The cage the job was prepared for, also when renamed since."""
        return object_by_uid(self._cage_uid, self._job.cage_name, self.bl_label)


def _as_report(result):
    """A step's commit result (a message or an :class:`api.Report`) as a Report."""
    return result if isinstance(result, api.Report) else api.Report(result)


def _edit_note(job):
    n = job.n_moved
    return (f"; the edit ({n:,} cage {'vertex' if n == 1 else 'vertices'} moved) kept on top"
            if n else "")


class MESHADJUST_OT_fit_cage(FitProps, _CageJobStep, bpy.types.Operator):
    """Move the cage's rest shape so that its subdivision surface matches the source (undoes the shrinkage of simplification); an edit is kept on top"""

    bl_idname = "meshadjust.fit_cage"
    bl_label = "Fit Cage"
    bl_options = {'REGISTER', 'UNDO'}

    _reads_source = True

    def _prepare(self, cage):
        self._edit_cage = cage.name if cage.mode == 'EDIT' else ""   # given back afterwards
        _object_mode(cage)
        return api.prepare_fit(cage, rebind=self.rebind)

    def _compute(self, job, progress=None):
        return api.compute_fit(job, progress=progress)

    def give_back(self):
        """Edit Mode again on a cage the fit took out of it."""
        cage = bpy.data.objects.get(getattr(self, "_edit_cage", ""))
        if cage is not None and cage.mode != 'EDIT':
            _edit_mode(cage)

    def _commit(self):
        cage = self._cage()
        _object_mode(cage)          # (the artist may have entered it while the fit ran)
        fit = api.commit_fit(cage, self._job)
        self.give_back()
        msg = f"fitted '{cage.name}': mean distance {fit_change(fit)} of size"
        if self._job.binding is not None:
            msg += f"; re-bound '{cage.meshadjust.edited.name}'"
        elif cage.meshadjust.edited is not None:
            msg += "; not re-bound: the fit counts as an edit of the bound rest shape"
        msg += _edit_note(self._job) + (f"; {self._job.note}" if self._job.note else "")
        cage.meshadjust.last_report = msg          # (the panel's line: Refine's was stale)
        return msg


class MESHADJUST_OT_bind(BindProps, _CageJobStep, bpy.types.Operator):
    """Bind (a copy of) the source to the cage: its rest shape (the edit kept on top) or, with Keep edit off, its current shape"""

    bl_idname = "meshadjust.bind"
    bl_label = "Bind"
    bl_options = {'REGISTER', 'UNDO'}

    _reads_source = True

    def _prepare(self, cage):
        """A bind job; levels 0 / scheme 'As bound' keep the cage's current ones."""
        return api.prepare_cage_job(cage, levels=self.levels, scheme=self.scheme,
                                    keep_edit=self.keep_edit)

    def _compute(self, job, progress=None):
        return api.compute_bind(job, progress=progress)

    def _commit(self):
        cage = self._cage()
        edited = api.commit_bind(cage, self._job)
        job = self._job
        msg = (f"bound '{edited.name}' ({len(edited.data.vertices):,} vertices) to "
               f"'{cage.name}' ({job.scheme}, {job.levels} levels)")
        if job.old_levels and (job.old_levels, job.old_scheme) != (job.levels, job.scheme):
            msg += f", was {job.old_scheme} x{job.old_levels}"
        msg += _edit_note(job) + (f"; {job.note}" if job.note else "")
        cage.meshadjust.last_report = msg          # (the panel's line: Refine's was stale)
        return msg


class MESHADJUST_OT_refine(RefineProps, _CageJobStep, bpy.types.Operator):
    """Refine the edited cage: deform the bound copy of the source, write the edit as a shape key of the source, and/or build the subdivided cage with the source's detail"""

    bl_idname = "meshadjust.refine"
    bl_label = "Refine"
    bl_options = {'REGISTER', 'UNDO'}

    _needs_binding = True

    def _cages(self, context):
        return [c for c in selected_cages(context) if c.meshadjust.edited is not None]

    def _prepare(self, cage):
        return api.prepare_refine(cage, output=self.output, levels=self.levels or None,
                                  scheme=self.scheme)

    def _compute(self, job, progress=None):
        return api.compute_refine(job, progress=progress)

    def _commit(self):
        return api.commit_refine(self._cage(), self._job)


class MESHADJUST_OT_subdivide(SubdivideProps, bpy.types.Operator):
    """Subdivide the selected meshes with modified butterfly (interpolating) or Loop (approximating); edges marked sharp stay creases"""

    bl_idname = "meshadjust.subdivide"
    bl_label = "Subdivide (Butterfly / Loop)"
    bl_options = {'REGISTER', 'UNDO'}

    @classmethod
    def poll(cls, context):
        objs = [o for o in context.selected_objects if o.type == 'MESH']
        act = context.active_object
        if not objs and (act is None or act.type != 'MESH'):
            cls.poll_message_set("Select a mesh object")
            return False
        if act is not None and act.mode == 'EDIT':
            cls.poll_message_set("Leave Edit Mode to subdivide")
            return False
        return True

    def execute(self, context):
        objs = [o for o in context.selected_objects if o.type == 'MESH']
        act = context.active_object
        if act is not None and act.type == 'MESH' and act not in objs:
            objs.insert(0, act)
        # (what they show is read: one with modifiers may make faces, or leave none)
        empty = [o.name for o in objs if len(o.data.polygons) == 0 and not o.modifiers]
        if empty:
            self.report({'ERROR'}, f"{empty[0]}: the mesh has no faces")
            return {'CANCELLED'}
        return run_each(self, objs, lambda obj: api.subdivide_object(
            obj, levels=self.levels, scheme=self.scheme, in_place=self.in_place)[1])


class MESHADJUST_OT_edit_cage(_CageStep, bpy.types.Operator):
    """Make the cage active and enter Edit Mode on it (move its vertices with Blender's own tools)"""

    bl_idname = "meshadjust.edit_cage"
    bl_label = "Edit Cage"
    bl_options = {'REGISTER', 'UNDO'}

    @classmethod
    def poll(cls, context):
        why = cage_unavailable(context)
        cage = cage_of(context.active_object)
        if why is None and cage.users_collection and cage.name not in context.view_layer.objects:
            why = (f"'{cage.name}' is not in this view layer (its collection is excluded, or it "
                   f"is in another scene): include it first")
        if why:
            cls.poll_message_set(why)
        return why is None

    def execute(self, context):
        cage = cage_of(context.active_object)
        if context.active_object is not None and context.active_object.mode != 'OBJECT':
            bpy.ops.object.mode_set(mode='OBJECT')
        if not cage.users_collection:   # deleted (MeshAdjust's links keep it): as results are
            source = cage.meshadjust.source
            self.report({'INFO'}, results.link_back(
                cage, source if source.name in context.view_layer.objects else None))
        for o in context.selected_objects:
            o.select_set(False)
        cage.hide_viewport = False      # (Blender cannot edit an object disabled in viewports)
        cage.hide_set(False)
        cage.select_set(True)
        context.view_layer.objects.active = cage
        bpy.ops.object.mode_set(mode='EDIT')
        return {'FINISHED'}


class MESHADJUST_OT_restore_basis(_CageStep, bpy.types.Operator):
    """Put back the source's Basis shape key from the mesh that was bound, after it was deleted and MeshAdjust's key became the source's reference key"""

    bl_idname = "meshadjust.restore_basis"
    bl_label = "Restore Basis"
    bl_options = {'REGISTER', 'UNDO'}

    _needs_binding = True

    def execute(self, context):
        return run_each(self, [cage_of(context.active_object)],
                        lambda cage: api.Report(basis.restore_basis(cage)))


class MESHADJUST_OT_apply_defaults(bpy.types.Operator):
    """Set this scene's MeshAdjust settings back to the add-on preferences' values (new scenes get them on their own)"""

    bl_idname = "meshadjust.apply_defaults"
    bl_label = "Reset Settings to Preferences"
    bl_options = {'REGISTER', 'UNDO'}

    def execute(self, context):
        from .properties import apply_preferences
        if not apply_preferences(context.scene, context, force=True):
            self.report({'WARNING'}, "the add-on preferences are not available")
            return {'CANCELLED'}
        return {'FINISHED'}


CLASSES = (MESHADJUST_OT_simplify, MESHADJUST_OT_fit_cage, MESHADJUST_OT_bind,
           MESHADJUST_OT_refine, MESHADJUST_OT_subdivide, MESHADJUST_OT_edit_cage,
           MESHADJUST_OT_restore_basis, MESHADJUST_OT_apply_defaults)
