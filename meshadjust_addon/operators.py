"""MeshAdjust operators: thin wrappers over :mod:`.api`.

Each catches the core's own errors (``core.MeshAdjustError``) and Blender-side
input errors and turns them into ``self.report({'ERROR'}, ...)`` plus
``{'CANCELLED'}``; nothing is changed in the scene before the compute part has
succeeded. ``meshadjust.simplify`` runs modal from the UI (work in a worker
thread, a progress bar, Esc cancels) and synchronously from scripts and in
background mode.
"""

import threading

import bpy
from bpy.props import BoolProperty, EnumProperty, FloatProperty, IntProperty, StringProperty

from .. import core
from . import api
from .properties import OUTPUTS, SCHEMES, TARGET_MODES

USER_ERRORS = (core.MeshAdjustError, ValueError)


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
        return f"'{obj.name}' is a {obj.type.lower()}, not a mesh"
    if obj.mode == 'EDIT':
        return "Leave Edit Mode to simplify"
    if obj.meshadjust.role == 'CAGE':
        return f"'{obj.name}' is already a cage"
    if len(obj.data.polygons) == 0:
        return f"'{obj.name}' has no faces"
    return None


def cage_unavailable(context, need_binding=False):
    """Why a cage step cannot run (None when it can)."""
    obj = context.active_object
    cage = cage_of(obj)
    if cage is None:
        return "Simplify a mesh first: the active object is not a cage"
    if cage.meshadjust.source is None:
        return f"'{cage.name}' lost its source object"
    if need_binding:
        edited = cage.meshadjust.edited
        if edited is None:
            return f"'{cage.name}' is not bound: use Bind"
        counts = tuple(edited.meshadjust.cage_counts)
        if cage.mode != 'EDIT' and counts != (len(cage.data.vertices), len(cage.data.polygons)):
            return (f"'{cage.name}' changed topology since it was bound "
                    f"({counts[0]} -> {len(cage.data.vertices)} vertices): Bind to re-bind")
    return None


class _Background:
    """Mixin for long operators: the pure-NumPy compute half runs in a worker
    thread while a modal timer shows progress (``wm.progress_*`` and the
    panel's bar); Esc cancels, and nothing in the scene changes until
    ``finish()`` commits the result on the main thread. Headless (no window),
    ``execute()`` runs the synchronous path instead.

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
        settings = context.scene.meshadjust
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
        if self._error is not None:
            if isinstance(self._error, USER_ERRORS):
                self.report({'ERROR'}, str(self._error))
                return {'CANCELLED'}
            raise self._error
        if self._cancel or getattr(self._job, "cancelled", False):
            self.report({'WARNING'}, f"{self.bl_label} cancelled: nothing was changed")
            return {'CANCELLED'}
        try:
            return self.finish(context)
        except USER_ERRORS as exc:
            self.report({'ERROR'}, str(exc))
            return {'CANCELLED'}


class _TargetProps:
    target_mode: EnumProperty(name="Target", items=TARGET_MODES, default='FACES')
    target_faces: IntProperty(name="Faces", default=2000, min=4, soft_max=50000)
    ratio: FloatProperty(name="Ratio", default=0.02, min=1e-5, max=1.0, subtype='FACTOR')
    max_error_pct: FloatProperty(name="Max error %", default=0.5, min=0.0, soft_max=5.0)
    preserve_boundary: BoolProperty(name="Preserve boundary", default=True)
    preserve_topology: BoolProperty(name="Keep topology", default=True)
    feature_angle_deg: FloatProperty(name="Feature angle", default=60.0, min=0.0, max=180.0)
    weight_group: StringProperty(name="Importance group", default="")
    lock_group: StringProperty(name="Locked group", default="")
    fit: BoolProperty(name="Fit cage", default=True)
    bind: BoolProperty(name="Bind source", default=True)
    levels: IntProperty(name="Levels", default=2, min=1, max=5)
    scheme: EnumProperty(name="Scheme", items=SCHEMES, default='butterfly')
    hide_source: BoolProperty(name="Hide source", default=False)

    def params(self):
        return api.SimplifyParams(
            target_faces=self.target_faces if self.target_mode == 'FACES' else None,
            ratio=self.ratio if self.target_mode == 'RATIO' else None,
            max_error_pct=self.max_error_pct if self.target_mode == 'ERROR' else None,
            preserve_boundary=self.preserve_boundary, preserve_topology=self.preserve_topology,
            feature_angle_deg=None if self.feature_angle_deg >= 180.0 else self.feature_angle_deg,
            weight_group=self.weight_group, lock_group=self.lock_group, fit=self.fit,
            bind=self.bind, levels=self.levels, scheme=self.scheme, hide_source=self.hide_source)


class MESHADJUST_OT_simplify(_Background, _TargetProps, bpy.types.Operator):
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

    def _targets(self, context):
        objs = [o for o in context.selected_objects if o.type == 'MESH'
                and o.meshadjust.role != 'CAGE']
        act = context.active_object
        if act is not None and act not in objs:
            objs.insert(0, act)
        return objs

    def execute(self, context):
        messages = []
        for obj in self._targets(context):
            try:
                cage, report = api.simplify_object(obj, **vars_of(self.params()))
            except USER_ERRORS as exc:
                self.report({'ERROR'}, f"{obj.name}: {exc}")
                return {'CANCELLED'}
            messages.append(f"{obj.name}: {report.message}")
        for obj in context.selected_objects:
            obj.select_set(False)
        if messages:
            cage.select_set(True)
            context.view_layer.objects.active = cage
        self.report({'INFO'}, " | ".join(messages))
        return {'FINISHED'}

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
        self._job = job
        return self.start_background(context, f"Simplifying {obj.name}",
                                     lambda progress: api.compute_simplify(job, progress=progress))

    def finish(self, context):
        obj = bpy.data.objects.get(self._job.source_name)
        cage, report = api.commit_simplify(obj, self._job)
        for o in context.selected_objects:
            o.select_set(False)
        cage.select_set(True)
        context.view_layer.objects.active = cage
        self.report({'INFO'}, report.message)
        return {'FINISHED'}


class _CageStep:
    """Mixin: the operator runs on the active object's cage; ``poll`` says
    why not (``_needs_binding``: the cage must also have a valid binding)."""

    _needs_binding = False

    @classmethod
    def poll(cls, context):
        why = cage_unavailable(context, need_binding=cls._needs_binding)
        if why:
            cls.poll_message_set(why)
        return why is None


def vars_of(params):
    """A frozen dataclass as keyword arguments."""
    return {k: getattr(params, k) for k in params.__dataclass_fields__}


class _CageJobStep(_Background, _CageStep):
    """Mixin for the long cage steps (fit, bind): every selected cage in turn
    from ``execute()``; a single cage runs in the background from ``invoke()``.
    Subclasses implement ``_prepare(cage) -> job`` (main thread),
    ``_compute(job, progress) -> job`` (any thread) and ``_commit() -> message``."""

    def execute(self, context):
        messages = []
        for cage in selected_cages(context):
            try:
                self._job = self._compute(self._prepare(cage))
                messages.append(self._commit())
            except USER_ERRORS as exc:
                self.report({'ERROR'}, f"{cage.name}: {exc}")
                return {'CANCELLED'}
        self.report({'INFO'}, " | ".join(messages))
        return {'FINISHED'}

    def invoke(self, context, event):
        cages = selected_cages(context)
        if bpy.app.background or len(cages) != 1:
            return self.execute(context)
        try:
            job = self._prepare(cages[0])
        except USER_ERRORS as exc:
            self.report({'ERROR'}, str(exc))
            return {'CANCELLED'}
        return self.start_background(context, f"{self.bl_label}: {cages[0].name}",
                                     lambda progress: self._compute(job, progress))

    def finish(self, context):
        self.report({'INFO'}, self._commit())
        return {'FINISHED'}


class MESHADJUST_OT_fit_cage(_CageJobStep, bpy.types.Operator):
    """Move the cage's vertices so that its subdivision surface matches the source (undoes the shrinkage of simplification)"""

    bl_idname = "meshadjust.fit_cage"
    bl_label = "Fit Cage"
    bl_options = {'REGISTER', 'UNDO'}

    rebind: BoolProperty(name="Re-bind", default=True,
                         description="Bind the source again to the fitted cage")

    def _prepare(self, cage):
        if cage.mode == 'EDIT':
            bpy.ops.object.mode_set(mode='OBJECT')
        job = api.prepare_cage_job(cage)
        job.rebind = self.rebind and cage.meshadjust.edited is not None
        return job

    def _compute(self, job, progress=None):
        api.compute_fit(job, progress=progress)
        if job.rebind and not job.cancelled:
            job.V_cage = job.fit.V
            api.compute_bind(job)
        return job

    def _commit(self):
        cage = bpy.data.objects[self._job.cage_name]
        fit = api.commit_fit(cage, self._job)
        if self._job.binding is not None:
            api.commit_bind(cage, self._job)
        d = fit.mean_distance
        return (f"fitted '{cage.name}': mean distance {100 * d[0] / fit.diagonal:.3f}% -> "
                f"{100 * d[-1] / fit.diagonal:.3f}% of size"
                + ("; re-bound" if self._job.binding is not None else ""))


class MESHADJUST_OT_bind(_CageJobStep, bpy.types.Operator):
    """Bind (a copy of) the source to the cage as it is now: its current shape becomes the rest shape"""

    bl_idname = "meshadjust.bind"
    bl_label = "Bind"
    bl_options = {'REGISTER', 'UNDO'}

    levels: IntProperty(name="Levels", default=2, min=1, max=5,
                        description="Subdivision levels (unset: the cage's current ones)")
    scheme: EnumProperty(name="Scheme", items=SCHEMES, default='butterfly',
                         description="Subdivision scheme (unset: the cage's current one)")

    def _prepare(self, cage):
        """A bind job; unset levels / scheme keep the cage's current ones."""
        levels = self.levels if self.properties.is_property_set("levels") else None
        scheme = self.scheme if self.properties.is_property_set("scheme") else None
        return api.prepare_cage_job(cage, levels=levels, scheme=scheme)

    def _compute(self, job, progress=None):
        return api.compute_bind(job, progress=progress)

    def _commit(self):
        cage = bpy.data.objects[self._job.cage_name]
        edited = api.commit_bind(cage, self._job)
        return (f"bound '{edited.name}' ({len(edited.data.vertices):,} vertices) to "
                f"'{cage.name}' ({self._job.scheme}, {self._job.levels} levels)")


class MESHADJUST_OT_refine(_CageStep, bpy.types.Operator):
    """Refine the edited cage: deform the bound copy of the source and/or build the subdivided cage with the source's detail"""

    bl_idname = "meshadjust.refine"
    bl_label = "Refine"
    bl_options = {'REGISTER', 'UNDO'}

    output: EnumProperty(name="Output", items=OUTPUTS, default='EDITED')
    levels: IntProperty(name="Levels", default=0, min=0, max=5,
                        description="Subdivision levels (0: those of the binding); other "
                                    "values re-bind from the rest shape, keeping the edit")
    scheme: EnumProperty(name="Scheme", items=[('BOUND', "As bound", "The binding's scheme")]
                         + SCHEMES, default='BOUND')
    _needs_binding = True

    def execute(self, context):
        messages = []
        for cage in selected_cages(context):
            if cage.meshadjust.edited is None:
                continue
            try:
                report = api.refine_object(cage, output=self.output, levels=self.levels or None,
                                           scheme=None if self.scheme == 'BOUND' else self.scheme)
            except core.TopologyMismatchError as exc:
                self.report({'ERROR'}, f"{exc} (Bind re-binds the changed cage)")
                return {'CANCELLED'}
            except USER_ERRORS as exc:
                self.report({'ERROR'}, f"{cage.name}: {exc}")
                return {'CANCELLED'}
            messages.append(report.message)
        self.report({'INFO'}, " | ".join(messages))
        return {'FINISHED'}


class MESHADJUST_OT_subdivide(bpy.types.Operator):
    """Subdivide the selected meshes with modified butterfly (interpolating) or Loop (approximating); edges marked sharp stay creases"""

    bl_idname = "meshadjust.subdivide"
    bl_label = "Subdivide (Butterfly / Loop)"
    bl_options = {'REGISTER', 'UNDO'}

    levels: IntProperty(name="Levels", default=1, min=1, max=5)
    scheme: EnumProperty(name="Scheme", items=SCHEMES, default='butterfly')
    in_place: BoolProperty(name="In place", default=False,
                           description="Replace the object's mesh instead of adding a new object")

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
        messages = []
        for obj in objs:
            if len(obj.data.polygons) == 0:
                self.report({'ERROR'}, f"{obj.name}: the mesh has no faces")
                return {'CANCELLED'}
            try:
                _, report = api.subdivide_object(obj, levels=self.levels, scheme=self.scheme,
                                                 in_place=self.in_place)
            except USER_ERRORS as exc:
                self.report({'ERROR'}, f"{obj.name}: {exc}")
                return {'CANCELLED'}
            messages.append(f"{obj.name}: {report.message}")
        self.report({'INFO'}, " | ".join(messages))
        return {'FINISHED'}


class MESHADJUST_OT_edit_cage(_CageStep, bpy.types.Operator):
    """Make the cage active and enter Edit Mode on it (move its vertices with Blender's own tools)"""

    bl_idname = "meshadjust.edit_cage"
    bl_label = "Edit Cage"
    bl_options = {'REGISTER', 'UNDO'}

    def execute(self, context):
        cage = cage_of(context.active_object)
        if context.active_object is not None and context.active_object.mode != 'OBJECT':
            bpy.ops.object.mode_set(mode='OBJECT')
        for o in context.selected_objects:
            o.select_set(False)
        cage.hide_set(False)
        cage.select_set(True)
        context.view_layer.objects.active = cage
        bpy.ops.object.mode_set(mode='EDIT')
        return {'FINISHED'}


CLASSES = (MESHADJUST_OT_simplify, MESHADJUST_OT_fit_cage, MESHADJUST_OT_bind,
           MESHADJUST_OT_refine, MESHADJUST_OT_subdivide, MESHADJUST_OT_edit_cage)


class MESHADJUST_OT_apply_defaults(bpy.types.Operator):
    """Copy the add-on preferences' defaults (faces, levels, scheme, fit) into this scene's MeshAdjust settings"""

    bl_idname = "meshadjust.apply_defaults"
    bl_label = "Apply Preference Defaults"
    bl_options = {'REGISTER', 'UNDO'}

    def execute(self, context):
        from .properties import apply_preferences
        context.scene.meshadjust.initialized = False
        if not apply_preferences(context.scene, context):
            self.report({'WARNING'}, "the add-on preferences are not available")
            return {'CANCELLED'}
        return {'FINISHED'}


CLASSES = CLASSES + (MESHADJUST_OT_apply_defaults,)
