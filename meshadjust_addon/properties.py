"""Add-on state: per-object links and parameters, panel inputs, preferences.

Small state lives in PropertyGroups (pointers survive save and reload); large
per-vertex data (the binding) lives in mesh attributes, see ``store.py``.
"""

import bpy
from bpy.props import (BoolProperty, EnumProperty, FloatProperty, IntProperty, IntVectorProperty,
                       PointerProperty, StringProperty)

SCHEMES = [
    ('butterfly', "Butterfly", "Modified butterfly (Zorin et al. 1996): interpolating, the cage "
                               "vertices stay where they are"),
    ('loop', "Loop", "Loop (1987): approximating, smoother, shrinks slightly"),
]
TARGET_MODES = [
    ('FACES', "Faces", "Stop at a face count"),
    ('RATIO', "Ratio", "Stop at a fraction of the input's faces"),
    ('ERROR', "Max error", "Stop before any collapse whose error exceeds a percentage of the "
                           "mesh size (bounding-box diagonal)"),
]
OUTPUTS = [
    ('EDITED', "Edited original", "The source mesh deformed by the cage edit: same topology, "
                                  "UVs and attributes kept"),
    ('REFINED', "Refined mesh", "The subdivided edited cage with the source's detail added"),
    ('BOTH', "Both", "Update both results"),
]
ROLES = [
    ('NONE', "None", ""),
    ('SOURCE', "Source", "A dense mesh that has a cage"),
    ('CAGE', "Cage", "A coarse cage made by Simplify"),
    ('EDITED', "Edited original", "A copy of the source, bound to the cage and deformed by it"),
    ('REFINED', "Refined", "The subdivided cage with detail"),
]


def _poll_mesh(self, obj):
    return obj.type == 'MESH'


class MeshAdjustObjectState(bpy.types.PropertyGroup):
    """What an object is in the MeshAdjust workflow and what it is linked to."""

    role: EnumProperty(name="Role", items=ROLES, default='NONE')
    source: PointerProperty(name="Source", type=bpy.types.Object, poll=_poll_mesh,
                            description="The dense mesh this cage or result was made from")
    cage: PointerProperty(name="Cage", type=bpy.types.Object, poll=_poll_mesh,
                          description="The cage that drives this object")
    edited: PointerProperty(name="Edited original", type=bpy.types.Object, poll=_poll_mesh,
                            description="The bound copy of the source this cage deforms")
    refined: PointerProperty(name="Refined mesh", type=bpy.types.Object, poll=_poll_mesh,
                             description="The refined mesh this cage produces")
    detail_mesh: PointerProperty(name="Detail data", type=bpy.types.Mesh,
                                 description="Per-fine-vertex detail of the binding (data only)")
    fingerprint: StringProperty(name="Cage fingerprint", default="",
                                description="Topology fingerprint of the cage the binding was made for")
    cage_counts: IntVectorProperty(name="Cage counts", size=2, default=(0, 0),
                                   description="Vertices and faces of the cage at bind time "
                                               "(a cheap staleness check for the panel)")
    levels: IntProperty(name="Levels", default=2, min=0, max=6)
    scheme: EnumProperty(name="Scheme", items=SCHEMES, default='butterfly')
    live: BoolProperty(name="Live", default=False,
                       description="Update the results while the cage is edited")
    last_report: StringProperty(name="Last report", default="")


class MeshAdjustSettings(bpy.types.PropertyGroup):
    """Inputs of the N-panel (per scene), mirrored by each operator's own
    properties for the redo panel."""

    target_mode: EnumProperty(name="Target", items=TARGET_MODES, default='FACES')
    target_faces: IntProperty(name="Faces", default=2000, min=4, soft_max=50000,
                              description="Number of triangles of the cage")
    ratio: FloatProperty(name="Ratio", default=0.02, min=1e-5, max=1.0, subtype='FACTOR',
                         description="Cage faces as a fraction of the source's")
    max_error_pct: FloatProperty(name="Max error %", default=0.5, min=0.0, soft_max=5.0,
                                 description="Largest allowed deviation, % of the bounding-box "
                                             "diagonal")
    preserve_boundary: BoolProperty(name="Preserve boundary", default=True)
    preserve_topology: BoolProperty(name="Keep topology", default=True,
                                    description="Keep genus, holes and components. Off: once "
                                                "nothing else can collapse, holes of three edges "
                                                "close and tiny pieces that cannot shrink go")
    feature_angle_deg: FloatProperty(name="Feature angle", default=60.0, min=0.0, max=180.0,
                                     description="Edges sharper than this are kept as creases "
                                                 "(180 turns it off)")
    weight_group: StringProperty(name="Importance", default="",
                                 description="Vertex group whose weights make areas more important")
    lock_group: StringProperty(name="Locked", default="",
                               description="Vertex group of vertices that must not move")
    fit: BoolProperty(name="Fit cage", default=True,
                      description="Move the cage so its subdivision matches the source "
                                  "(undoes QEM's shrinkage)")
    bind: BoolProperty(name="Bind source", default=True,
                       description="Bind a copy of the source to the cage so cage edits deform it")
    hide_source: BoolProperty(name="Hide source", default=True)
    scheme: EnumProperty(name="Scheme", items=SCHEMES, default='butterfly')
    levels: IntProperty(name="Levels", default=2, min=1, max=5)
    output: EnumProperty(name="Output", items=OUTPUTS, default='EDITED')
    progress: FloatProperty(name="Progress", default=0.0, min=0.0, max=1.0, subtype='FACTOR')
    progress_text: StringProperty(name="Progress text", default="")
    running: BoolProperty(name="Running", default=False)
    initialized: BoolProperty(name="Defaults applied", default=False,
                              description="The add-on preferences' defaults were copied here")


class MeshAdjustPreferences(bpy.types.AddonPreferences):
    """Defaults for new scenes' MeshAdjust settings."""

    bl_idname = __package__.rpartition(".")[0] or __package__

    default_faces: IntProperty(name="Default cage faces", default=2000, min=4)
    default_levels: IntProperty(name="Default levels", default=2, min=1, max=5)
    default_scheme: EnumProperty(name="Default scheme", items=SCHEMES, default='butterfly')
    default_fit: BoolProperty(name="Fit cages by default", default=True)
    live_interval: FloatProperty(name="Live update interval (s)", default=0.15, min=0.02, max=2.0,
                                 description="Minimum time between live refines while editing")

    def draw(self, context):
        col = self.layout.column()
        col.prop(self, "default_faces")
        col.prop(self, "default_levels")
        col.prop(self, "default_scheme")
        col.prop(self, "default_fit")
        col.prop(self, "live_interval")


def preferences(context=None):
    """The add-on's preferences, or None when registered without addon_utils."""
    context = context or bpy.context
    addon = context.preferences.addons.get(MeshAdjustPreferences.bl_idname)
    return addon.preferences if addon else None


def apply_preferences(scene, context=None):
    """Copy the preferences' defaults into a scene's settings, once per scene."""
    settings = scene.meshadjust
    prefs = preferences(context)
    if settings.initialized or prefs is None:
        return False
    settings.target_faces = prefs.default_faces
    settings.levels = prefs.default_levels
    settings.scheme = prefs.default_scheme
    settings.fit = prefs.default_fit
    settings.initialized = True
    return True


@bpy.app.handlers.persistent
def _on_load_post(*_args):
    for scene in bpy.data.scenes:
        apply_preferences(scene)


CLASSES = (MeshAdjustObjectState, MeshAdjustSettings, MeshAdjustPreferences)


def register():
    for cls in CLASSES:
        bpy.utils.register_class(cls)
    bpy.types.Object.meshadjust = PointerProperty(type=MeshAdjustObjectState)
    bpy.types.Scene.meshadjust = PointerProperty(type=MeshAdjustSettings)
    bpy.app.handlers.load_post.append(_on_load_post)


def unregister():
    if _on_load_post in bpy.app.handlers.load_post:
        bpy.app.handlers.load_post.remove(_on_load_post)
    del bpy.types.Scene.meshadjust
    del bpy.types.Object.meshadjust
    for cls in reversed(CLASSES):
        bpy.utils.unregister_class(cls)
