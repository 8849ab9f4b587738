"""The "MeshAdjust" tab of the 3D Viewport sidebar (N-panel).

Three steps on the active object: Simplify, Edit cage, Refine. A step that
cannot run is drawn disabled (not hidden) with the reason under it. The
decisions are made by :func:`panel_state`, a plain function, so tests can
check them headless (``draw()`` never runs without a window).
"""

import bpy

from .operators import cage_of, cage_unavailable, simplify_unavailable


def panel_state(context):
    """For each step, ``(enabled, reason)``; reason is None when enabled."""
    state = {}
    why = simplify_unavailable(context)
    state["simplify"] = (why is None, why)
    why = cage_unavailable(context)
    state["edit"] = (why is None, why)
    state["fit"] = (why is None, why)
    state["bind"] = (why is None, why)
    why = cage_unavailable(context, need_binding=True)
    state["refine"] = (why is None, why)
    return state


def _step(layout, enabled, reason):
    col = layout.column(align=True)
    col.enabled = enabled
    return col, reason


class MESHADJUST_PT_main(bpy.types.Panel):
    bl_label = "MeshAdjust"
    bl_idname = "MESHADJUST_PT_main"
    bl_space_type = 'VIEW_3D'
    bl_region_type = 'UI'
    bl_category = "MeshAdjust"

    def draw(self, context):
        layout = self.layout
        s = context.scene.meshadjust
        state = panel_state(context)
        if not s.initialized:
            layout.operator("meshadjust.apply_defaults", icon='PREFERENCES')
        obj = context.active_object

        box = layout.box()
        box.label(text="1. Simplify", icon='MOD_DECIM')
        col = box.column(align=True)
        col.prop(s, "target_mode", expand=True)
        if s.target_mode == 'FACES':
            col.prop(s, "target_faces")
        elif s.target_mode == 'RATIO':
            col.prop(s, "ratio")
        else:
            col.prop(s, "max_error_pct")
        col = box.column(align=True)
        col.prop(s, "preserve_boundary")
        col.prop(s, "preserve_topology")
        col.prop(s, "feature_angle_deg")
        if obj is not None and obj.type == 'MESH':
            col.prop_search(s, "weight_group", obj, "vertex_groups")
            col.prop_search(s, "lock_group", obj, "vertex_groups")
        row = box.row(align=True)
        row.prop(s, "fit")
        row.prop(s, "bind")
        box.prop(s, "hide_source")
        if s.running:
            box.progress(factor=s.progress, type='BAR', text=s.progress_text or "Working")
            box.label(text="Esc cancels", icon='INFO')
        sub = box.column()
        sub.enabled = state["simplify"][0]
        op = sub.operator("meshadjust.simplify", icon='MOD_DECIM')
        for name in ("target_mode", "target_faces", "ratio", "max_error_pct", "preserve_boundary",
                     "preserve_topology", "feature_angle_deg", "weight_group", "lock_group",
                     "fit", "bind", "levels", "scheme", "hide_source"):
            setattr(op, name, getattr(s, name))
        if state["simplify"][1]:
            box.label(text=state["simplify"][1], icon='INFO')

        box = layout.box()
        box.label(text="2. Edit cage", icon='EDITMODE_HLT')
        row = box.row(align=True)
        row.enabled = state["edit"][0]
        row.operator("meshadjust.edit_cage", icon='EDITMODE_HLT')
        row.operator("meshadjust.fit_cage", icon='SNAP_ON')
        row.operator("meshadjust.bind", icon='LINKED')
        if state["edit"][1]:
            box.label(text=state["edit"][1], icon='INFO')

        box = layout.box()
        box.label(text="3. Refine", icon='MOD_SUBSURF')
        col = box.column(align=True)
        col.prop(s, "output", text="")
        cage = cage_of(obj)
        if cage is not None:
            col.prop(cage.meshadjust, "live", toggle=True, icon='PLAY')
        sub = box.column()
        sub.enabled = state["refine"][0]
        row = box.row(align=True)
        row.prop(s, "scheme", text="")
        row.prop(s, "levels")
        op = sub.operator("meshadjust.refine", icon='MOD_SUBSURF')
        op.output = s.output
        op.levels = s.levels
        op.scheme = s.scheme
        if cage is not None and cage.meshadjust.edited is not None:
            box.label(text=f"Bound: {cage.meshadjust.scheme}, {cage.meshadjust.levels} levels")
        if state["refine"][1]:
            box.label(text=state["refine"][1], icon='INFO')
            if "re-bind" in state["refine"][1]:
                box.operator("meshadjust.bind", text="Re-bind", icon='LINKED')
        if cage is not None and cage.meshadjust.last_report:
            box.label(text=cage.meshadjust.last_report[:120])

        box = layout.box()
        box.label(text="Subdivide any mesh")
        row = box.row(align=True)
        row.prop(s, "scheme", text="")
        row.prop(s, "levels")
        op = box.operator("meshadjust.subdivide")
        op.scheme = s.scheme
        op.levels = s.levels


CLASSES = (MESHADJUST_PT_main,)
