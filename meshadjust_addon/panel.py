"""The "MeshAdjust" tab of the 3D Viewport sidebar (N-panel).

A parent panel (the progress bar of a running step) and one sub-panel per
step (``bl_parent_id``, each collapsible): Simplify, Edit Cage, Refine, and
Subdivide Any Mesh. A step that cannot run is drawn disabled (not hidden)
with the reason under it; a binding that is out of date (the cage's topology
or the source changed) says what changed and offers Re-bind.

The decisions are plain functions (:func:`panel_state`, :func:`simplify_fields`,
:func:`refine_messages`) so tests can check them headless (``draw()`` never
runs without a window). The properties drawn are the scene settings declared
in ``settings.py``, and the buttons get them through
:func:`settings.copy_to_operator`.
"""

import bpy

from . import settings
from .cage_steps import refine_levels
from .operators import binding_warnings, cage_of, cage_unavailable, simplify_unavailable
from .results import reference_key_problem


def panel_state(context):
    """For each step, ``(enabled, reason)``; reason is None when enabled."""
    state = {}
    why = simplify_unavailable(context)
    state["simplify"] = (why is None, why)
    why = cage_unavailable(context)
    state["edit"] = (why is None, why)
    why = cage_unavailable(context, reads_source=True)
    state["fit"] = (why is None, why)
    state["bind"] = (why is None, why)
    why = cage_unavailable(context, need_binding=True)
    state["refine"] = (why is None, why)
    return state


def simplify_fields(s):
    """The scene settings the Simplify panel shows, in order (the target
    field follows the target mode; the vertex groups are drawn apart)."""
    target = {'FACES': "target_faces", 'RATIO': "ratio", 'ERROR': "max_error_pct"}[s.target_mode]
    return [target, "preserve_boundary", "preserve_topology", "close_pinholes", "feature_angle_deg",
            "max_dihedral_deg", "use_symmetry", "symmetry_axis", "fit", "bind", "levels", "scheme",
            "hide_source"]


def refine_messages(context):
    """``[(text, offer_rebind)]`` for the Refine panel: why it cannot run,
    what is out of date, and the last report."""
    out = []
    enabled, reason = panel_state(context)["refine"]
    if reason:
        out.append((reason, "re-bind" in reason))
    cage = cage_of(context.active_object)
    if cage is not None:
        out.extend((text + ": re-bind to use it", True) for text in binding_warnings(cage))
        if cage.meshadjust.last_report:
            out.append((cage.meshadjust.last_report[:160], False))
    return out


def bound_text(cage, levels):
    """The Refine panel's line on the bound cage ``cage``: its scheme and
    levels, and the refined mesh's levels when Refine at ``levels`` (0:
    Auto) makes it at others (:func:`~.cage_steps.refine_levels`)."""
    cs = cage.meshadjust
    finer = levels or refine_levels(cs.levels, len(cage.data.polygons),
                                    cs.edited.meshadjust.dense_faces)
    return f"Bound: {cs.scheme}, {cs.levels} levels" + \
        (f"; refined at {finer}" if finer != cs.levels else "")


def basis_lost(context):
    """Why the active cage's shape key cannot be written because the source's
    Basis was deleted (the Edit Cage panel then offers Restore Basis), or None."""
    cage = cage_of(context.active_object)
    source = cage.meshadjust.source if cage is not None else None
    return reference_key_problem(source, cage) if source is not None else None


class _Panel:
    bl_space_type = 'VIEW_3D'
    bl_region_type = 'UI'
    bl_category = "MeshAdjust"


class MESHADJUST_PT_main(_Panel, bpy.types.Panel):
    """MeshAdjust: simplify a dense mesh into a cage, edit the cage, refine"""

    bl_label = "MeshAdjust"
    bl_idname = "MESHADJUST_PT_main"

    def draw(self, context):
        s = context.scene.meshadjust
        if s.running:
            self.layout.progress(factor=s.progress, type='BAR', text=s.progress_text or "Working")
            self.layout.label(text="Esc cancels", icon='INFO')


class MESHADJUST_PT_simplify(_Panel, bpy.types.Panel):
    bl_label = "1. Simplify"
    bl_idname = "MESHADJUST_PT_simplify"
    bl_parent_id = "MESHADJUST_PT_main"

    def draw(self, context):
        layout = self.layout
        s = context.scene.meshadjust
        enabled, reason = panel_state(context)["simplify"]
        col = layout.column(align=True)
        col.prop(s, "target_mode", expand=True)
        fields = simplify_fields(s)
        col.prop(s, fields[0])
        col = layout.column(align=True)
        for name in fields[1:]:
            if name == "use_symmetry":
                # as Decimate draws it: the toggle, then the axis it enables
                row = col.row(align=True)
                row.prop(s, "use_symmetry")
                sub = row.row(align=True)
                sub.active = s.use_symmetry
                sub.prop(s, "symmetry_axis", expand=True)
            elif name != "symmetry_axis":
                col.prop(s, name)
        obj = context.active_object
        if obj is not None and obj.type == 'MESH':
            col.prop_search(s, "weight_group", obj, "vertex_groups")
            col.prop_search(s, "lock_group", obj, "vertex_groups")
        sub = layout.column()
        sub.enabled = enabled
        op = sub.operator("meshadjust.simplify", icon='MOD_DECIM')
        settings.copy_to_operator(s, op, settings.SIMPLIFY)
        if reason:
            layout.label(text=reason, icon='INFO')


class MESHADJUST_PT_edit(_Panel, bpy.types.Panel):
    bl_label = "2. Edit Cage"
    bl_idname = "MESHADJUST_PT_edit"
    bl_parent_id = "MESHADJUST_PT_main"

    def draw(self, context):
        layout = self.layout
        enabled, reason = panel_state(context)["edit"]
        row = layout.row(align=True)
        row.enabled = enabled
        row.operator("meshadjust.edit_cage", icon='EDITMODE_HLT')
        row.operator("meshadjust.fit_cage", icon='SNAP_ON')
        row.operator("meshadjust.bind", icon='LINKED')
        if reason:
            layout.label(text=reason, icon='INFO')
        lost = basis_lost(context)
        if lost:
            layout.label(text=lost[:160], icon='ERROR')
            layout.operator("meshadjust.restore_basis", icon='SHAPEKEY_DATA')


class MESHADJUST_PT_refine(_Panel, bpy.types.Panel):
    bl_label = "3. Refine"
    bl_idname = "MESHADJUST_PT_refine"
    bl_parent_id = "MESHADJUST_PT_main"

    def draw(self, context):
        layout = self.layout
        s = context.scene.meshadjust
        enabled, _ = panel_state(context)["refine"]
        col = layout.column(align=True)
        col.prop(s, "output")
        row = col.row(align=True)
        row.prop(s, "refine_scheme", text="")
        row.prop(s, "levels")
        cage = cage_of(context.active_object)
        if cage is not None:
            col.prop(cage.meshadjust, "live", toggle=True, icon='PLAY')
        sub = layout.column()
        sub.enabled = enabled
        op = sub.operator("meshadjust.refine", icon='MOD_SUBSURF')
        settings.copy_to_operator(s, op, settings.REFINE)
        if cage is not None and cage.meshadjust.edited is not None:
            layout.label(text=bound_text(cage, s.levels))
        offered = False
        for text, rebind in refine_messages(context):
            layout.label(text=text, icon='ERROR' if rebind else 'INFO')
            if rebind and not offered:
                row = layout.row(align=True)
                row.operator("meshadjust.bind", text="Re-bind", icon='LINKED').keep_edit = True
                # when the edit cannot be kept (faces without a rest shape)
                row.operator("meshadjust.bind", text="Re-bind as Is").keep_edit = False
                offered = True


class MESHADJUST_PT_subdivide(_Panel, bpy.types.Panel):
    bl_label = "Subdivide Any Mesh"
    bl_idname = "MESHADJUST_PT_subdivide"
    bl_parent_id = "MESHADJUST_PT_main"
    bl_options = {'DEFAULT_CLOSED'}

    def draw(self, context):
        layout = self.layout
        s = context.scene.meshadjust
        row = layout.row(align=True)
        row.prop(s, "subdivide_scheme", text="")
        row.prop(s, "subdivide_levels")
        op = layout.operator("meshadjust.subdivide")
        settings.copy_to_operator(s, op, settings.SUBDIVIDE)


CLASSES = (MESHADJUST_PT_main, MESHADJUST_PT_simplify, MESHADJUST_PT_edit, MESHADJUST_PT_refine,
           MESHADJUST_PT_subdivide)
