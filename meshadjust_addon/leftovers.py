"""The detail data of a deleted edited original, removed.

The detail mesh of an edited original (``<edited>.detail``, :mod:`.store`)
has a fake user, so Blender keeps it when nothing else uses it. When the
edited original is removed from the file (``bpy.data.objects.remove``, or an
object deleted and the file saved and reloaded) nothing points to it any
more, and it would stay in the file for ever. :func:`remove_orphan_details`
removes it: after every MeshAdjust step that succeeds (the rollback's
``finish``) and when a file is loaded.

A detail mesh is known by the custom property :data:`TAG` (given when it is
made, and to those the edited originals point to, for files made before the
tag). One is removed only when its fake user is its only user: no object
uses it as its mesh, no edited original points to it, nothing else holds it.
"""

import bpy

from . import app_handlers

#: the custom property that marks a mesh as MeshAdjust's detail data
TAG = "meshadjust_detail"


def tag_detail(mesh):
    """Mark ``mesh`` as the detail data of an edited original."""
    mesh[TAG] = True


def tag_referenced():
    """Tag the detail meshes the edited originals point to (a file made
    before the tag existed)."""
    for obj in bpy.data.objects:
        detail = obj.meshadjust.detail_mesh if obj.type == 'MESH' else None
        if detail is not None and not detail.get(TAG) and detail.library is None:
            tag_detail(detail)


def orphan_details():
    """The tagged detail meshes held by their fake user alone (a list)."""
    held = {o.meshadjust.detail_mesh for o in bpy.data.objects if o.type == 'MESH'}
    return [m for m in bpy.data.meshes
            if m.get(TAG) and m.library is None and m not in held
            and m.users == int(m.use_fake_user)]


def remove_orphan_details():
    """Remove the detail meshes of the edited originals that are gone;
    returns their names."""
    tag_referenced()
    gone = orphan_details()
    names = [m.name for m in gone]
    for mesh in gone:
        bpy.data.meshes.remove(mesh)
    return names


@bpy.app.handlers.persistent
def _on_load_post(*_args):
    remove_orphan_details()


_HANDLERS = (("load_post", _on_load_post),)


def register():
    """Sweep on every file load."""
    app_handlers.add(_HANDLERS)


def unregister():
    """Stop sweeping on load."""
    app_handlers.remove(_HANDLERS)
