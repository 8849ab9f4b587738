"""MeshAdjust's Blender layer: properties, operators, the N-panel, live mode.

Thin by design: geometry happens in ``core`` (pure NumPy); this package moves
mesh data in and out (``mesh_io``), keeps state (``properties``, ``store``),
and exposes the workflow as operators, a panel and a context-free API
(``api``) for scripts and the batch CLI. Every user setting is declared once,
in ``settings``.
"""

import bpy

from . import leftovers, live, operators, panel, properties, staleness


def _menu_subdivide(self, context):
    self.layout.operator("meshadjust.subdivide")


def register():
    properties.register()
    for cls in operators.CLASSES + panel.CLASSES:
        bpy.utils.register_class(cls)
    bpy.types.VIEW3D_MT_object.append(_menu_subdivide)
    staleness.register()
    leftovers.register()
    live.register()


def unregister():
    live.unregister()
    leftovers.unregister()
    staleness.unregister()
    bpy.types.VIEW3D_MT_object.remove(_menu_subdivide)
    for cls in reversed(operators.CLASSES + panel.CLASSES):
        bpy.utils.unregister_class(cls)
    properties.unregister()
