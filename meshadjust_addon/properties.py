"""Add-on state: per-object links and parameters, panel inputs, preferences.

Small state lives in PropertyGroups (pointers survive save and reload); large
per-vertex data (the binding) lives in mesh attributes, see ``store.py``. The
user settings themselves are declared once, in ``settings.py``: the scene
settings and the preferences are built from that table.
"""

import bpy
from bpy.props import (BoolProperty, EnumProperty, FloatProperty, FloatVectorProperty, IntProperty,
                       IntVectorProperty, PointerProperty, StringProperty)

from . import app_handlers, settings as _settings
from .settings import AXES, OUTPUTS, SCHEMES, TARGET_MODES  # noqa: F401  (re-exported)

#: the plane a cage mirrors about, or none
MIRROR_PLANES = [('NONE', "None", "Not symmetric")] + AXES

ROLES = [
    ('NONE', "None", "Not part of a MeshAdjust workflow"),
    ('SOURCE', "Source", "A dense mesh that has a cage"),
    ('CAGE', "Cage", "A coarse cage made by Simplify"),
    ('EDITED', "Edited original", "A copy of the source, bound to the cage and deformed by it"),
    ('REFINED', "Refined", "The subdivided cage with detail"),
]


def _poll_mesh(self, obj):
    return obj.type == 'MESH'


def _live_toggled(state, context):
    """:func:`.live.live_toggled` (imported when called: live imports this module)."""
    from .live import live_toggled
    live_toggled(state, context)


class MeshAdjustObjectState(bpy.types.PropertyGroup):
    """What an object is in the MeshAdjust workflow and what it is linked to."""

    role: EnumProperty(name="Role", items=ROLES, default='NONE',
                       description="What this object is in the MeshAdjust workflow")
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
    cage_edges: IntProperty(name="Cage edges", default=0, min=0,
                            description="Edges of the cage at bind time")
    cage_topology: StringProperty(name="Cage topology key", default="",
                                  description="Checksum of the cage's half-edges at bind time "
                                              "(tells a re-connection from an edit)")
    source_fingerprint: StringProperty(name="Source fingerprint", default="",
                                       description="Checksum of the source (mesh, shape keys, "
                                                   "modifiers) at bind time")
    source_matrix: FloatVectorProperty(name="Source transform", size=16, default=(0.0,) * 16,
                                       description="The source's world matrix at bind time "
                                                   "(row by row; all 0: not recorded)")
    dense_vertices: IntProperty(name="Bound vertices", default=0, min=0,
                                description="Vertices of the edited original bound (0: not "
                                            "recorded); another count means its mesh was "
                                            "changed and its binding data no longer fits it")
    dense_faces: IntProperty(name="Source faces", default=0, min=0,
                             description="Triangles of the source at bind time")
    levels: IntProperty(name="Levels", default=2, min=0, max=6,
                        description="Subdivision levels of the binding")
    scheme: EnumProperty(name="Scheme", items=SCHEMES, default='loop',
                         description="Subdivision scheme of the binding")
    symmetry: EnumProperty(name="Symmetry", items=MIRROR_PLANES, default='NONE',
                           description="Mirror plane this cage was made symmetric about (Fit "
                                       "keeps it symmetric)")
    own_keys: StringProperty(name="MeshAdjust's shape keys", default="",
                             description="On a source: the shape keys its cages wrote, one name "
                                         "a line (kept when a cage is deleted: never read as "
                                         "the artist's own)")
    key_name: StringProperty(name="Shape key", default="",
                             description="The shape key this cage writes on its source (named "
                                         "after the cage when first written; renaming the "
                                         "cage keeps it)")
    written: StringProperty(name="Written", default="",
                            description="On a result: the vertex count and a checksum of the "
                                        "positions MeshAdjust last wrote ('live': kept by live "
                                        "mode), so a change made since (sculpting, an applied "
                                        "transform) is kept aside, not overwritten")
    data_written: StringProperty(name="Data written", default="",
                                 description="On an edited original: a checksum of its UV maps, "
                                             "attributes and materials as MeshAdjust last made "
                                             "them from the source (a bind brings a source's "
                                             "changed ones over, and keeps a version changed by "
                                             "hand aside)")
    written_matrix: FloatVectorProperty(name="Written transform", size=16, default=(0.0,) * 16,
                                        description="On a result: its world matrix when "
                                                    "MeshAdjust last wrote it (row by row; all "
                                                    "0: not recorded)")
    key_written: StringProperty(name="Shape key written", default="",
                                description="On a cage: a checksum of the shape key it last "
                                            "wrote on its source (a key sculpted since is kept "
                                            "aside, not overwritten)")
    live: BoolProperty(name="Live", default=False, update=_live_toggled,
                       description="Update the results (the Output chosen under Refine) while "
                                   "the cage is edited: only what the moved cage vertices "
                                   "reach is recomputed")
    last_report: StringProperty(name="Last report", default="",
                                description="What the last MeshAdjust step on this cage did")


SceneSettings = _settings.mixin("SceneSettings", _settings.SCENE)
PreferenceSettings = _settings.mixin("PreferenceSettings", _settings.PREFERENCES)


class MeshAdjustSettings(SceneSettings, bpy.types.PropertyGroup):
    """Inputs of the N-panel (per scene), declared in ``settings.py``; the
    panel copies them onto the operators it calls."""

    progress: FloatProperty(name="Progress", default=0.0, min=0.0, max=1.0, subtype='FACTOR',
                            description="Progress of the running background step")
    progress_text: StringProperty(name="Progress text", default="",
                                  description="What the running background step does")
    running: BoolProperty(name="Running", default=False,
                          description="A background step is running")
    initialized: BoolProperty(name="Defaults applied", default=False,
                              description="The add-on preferences' values were copied here")


class MeshAdjustPreferences(PreferenceSettings, bpy.types.AddonPreferences):
    """Defaults of every scene's MeshAdjust settings (copied into a scene the
    first time it is seen), and the live update interval."""

    bl_idname = __package__.rpartition(".")[0] or __package__

    def draw(self, context):
        col = self.layout.column()
        col.use_property_split = True
        for key in _settings.PREFERENCES:
            col.prop(self, key)


def preferences(context=None):
    """The add-on's preferences, or None when registered without addon_utils."""
    context = context or bpy.context
    addon = context.preferences.addons.get(MeshAdjustPreferences.bl_idname)
    return addon.preferences if addon else None


def apply_preferences(scene, context=None, *, force=False):
    """Copy the preferences' values into a scene's settings, once per scene
    (``force``: again). Returns True when they were copied."""
    settings = scene.meshadjust
    prefs = preferences(context)
    if (settings.initialized and not force) or prefs is None:
        return False
    _settings.seed(settings, prefs)
    settings.initialized = True
    return True


def seed_scenes():
    """Seed every scene not seeded yet (load, register, new scenes)."""
    data = bpy.data
    if not hasattr(data, "scenes"):   # restricted while Blender starts
        return
    for scene in data.scenes:
        if not scene.meshadjust.initialized:
            apply_preferences(scene)


def _seed_soon():
    seed_scenes()
    return None   # once


@bpy.app.handlers.persistent
def _on_load_post(*_args):
    seed_scenes()


@bpy.app.handlers.persistent
def _on_depsgraph_update(scene, _depsgraph):
    # a scene created after load (Scene > New) gets the preferences too
    if not scene.meshadjust.initialized:
        apply_preferences(scene)


CLASSES = (MeshAdjustObjectState, MeshAdjustSettings, MeshAdjustPreferences)
_HANDLERS = (("load_post", _on_load_post), ("depsgraph_update_post", _on_depsgraph_update))


def register():
    for cls in CLASSES:
        bpy.utils.register_class(cls)
    bpy.types.Object.meshadjust = PointerProperty(type=MeshAdjustObjectState)
    bpy.types.Scene.meshadjust = PointerProperty(type=MeshAdjustSettings)
    app_handlers.add(_HANDLERS)
    # register() runs with bpy.data restricted: seed the open scenes just after
    # (timers fire in a UI session; headless, load_post and the handler do it)
    if not bpy.app.timers.is_registered(_seed_soon):
        bpy.app.timers.register(_seed_soon, first_interval=0.0)


def unregister():
    if bpy.app.timers.is_registered(_seed_soon):
        bpy.app.timers.unregister(_seed_soon)
    app_handlers.remove(_HANDLERS)
    del bpy.types.Scene.meshadjust
    del bpy.types.Object.meshadjust
    for cls in reversed(CLASSES):
        bpy.utils.unregister_class(cls)
