"""MeshAdjust extension entry point: Blender calls register() / unregister().

Everything lives in the sub-packages: ``core`` (pure NumPy geometry) and
``meshadjust_addon`` (the Blender layer). Imports are deferred so that
importing this package never pulls in bpy by itself.
"""


def register():
    from .meshadjust_addon import register as _register
    _register()


def unregister():
    from .meshadjust_addon import unregister as _unregister
    _unregister()
