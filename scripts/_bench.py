"""Shared pieces of the benchmark scripts (``scripts/bench_*.py``).

Blender objects are made and read with the add-on's own fast mesh transfer
(``meshadjust_addon.mesh_io``), so the benchmarks time the same code the
add-on runs; test meshes come from ``tests/mesh_factory``.
"""

import os
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
for path in (ROOT, os.path.join(ROOT, "scripts")):
    if path not in sys.path:
        sys.path.insert(0, path)

SHARED_MESHES = os.path.normpath(os.path.join(ROOT, "..", "shared", "meshes"))


def mesh_io():
    """The add-on's mesh transfer module (registers the add-on once)."""
    from meshadjust_batch import load_package
    return load_package().meshadjust_addon.mesh_io


def empty_scene():
    """An empty Blender scene; returns ``bpy``."""
    import bpy
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    return bpy


def blender_object(name, V, F):
    """A new mesh object from core arrays, linked to the scene."""
    import bpy
    ob = bpy.data.objects.new(name, mesh_io().new_mesh(name, V, F))
    bpy.context.scene.collection.objects.link(ob)
    return ob


def evaluated_arrays(ob):
    """``(V, F)`` of the object with its modifiers applied (local space)."""
    arrays = mesh_io().read_object(ob, evaluated=True)
    return arrays.V, arrays.F


def evaluated_positions(ob):
    """(n,3) positions of the object with its modifiers applied: evaluating
    the depsgraph is what runs a modifier, so this is what gets timed."""
    import bpy
    ev = ob.evaluated_get(bpy.context.evaluated_depsgraph_get())
    return mesh_io().read_positions(ev.data)
