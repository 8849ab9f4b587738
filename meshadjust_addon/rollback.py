"""All or nothing for the Blender side of a step (undo is unavailable headless).

The steps check everything that can fail before they write, so a commit
normally cannot fail half-way; :func:`all_or_nothing` is the safety net for
the case where it does anyway: on an exception it removes the objects,
meshes and shape keys created inside the block, puts back the vertex
positions of the meshes registered with :meth:`Rollback.keep`, and re-raises.

    with all_or_nothing() as rb:
        rb.keep(cage.data)
        mesh_io.write_positions(cage.data, V)
        ...
"""

import contextlib

import bpy

from . import mesh_io


class Rollback:
    """What existed when the block began, and the positions to put back."""

    def __init__(self):
        self.objects = set(bpy.data.objects)
        self.meshes = set(bpy.data.meshes)
        self.positions = {}
        self.keys = {}

    def keep(self, mesh):
        """Remember ``mesh``'s positions (and its shape keys' names) before a write."""
        if mesh is not None and mesh.name_full not in self.positions:
            self.positions[mesh.name_full] = (mesh, mesh_io.read_positions(mesh))
            sk = mesh.shape_keys
            self.keys[mesh.name_full] = (mesh, None if sk is None else
                                         {kb.name for kb in sk.key_blocks})

    def undo(self):
        for obj in [o for o in bpy.data.objects if o not in self.objects]:
            bpy.data.objects.remove(obj)
        for mesh in [m for m in bpy.data.meshes if m not in self.meshes]:
            bpy.data.meshes.remove(mesh)
        for mesh, names in self.keys.values():
            sk = mesh.shape_keys
            if sk is None:
                continue
            owners = [o for o in bpy.data.objects if o.data == mesh]
            for kb in reversed([kb for kb in sk.key_blocks if names is None or kb.name not in names]):
                if owners:
                    owners[0].shape_key_remove(kb)
        for mesh, V in self.positions.values():
            if len(mesh.vertices) == V.shape[0]:
                mesh_io.write_positions(mesh, V)


@contextlib.contextmanager
def all_or_nothing():
    """Run a block of Blender writes; on any exception, undo them and re-raise."""
    rb = Rollback()
    try:
        yield rb
    except BaseException:
        rb.undo()
        raise
