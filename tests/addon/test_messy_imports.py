"""Scans as artists bring them in, through the add-on: Blender's own importers
(PLY and glTF with split seams, OBJ, STL), objects carrying every kind of
data (UV maps, colour attributes, vertex groups, custom normals, materials,
loose parts, hidden faces), modifiers on the cage, sources left in Edit Mode,
and the artist's flows on them. Each test is a bug that a campaign of such
scenes found (on 2026-12-05), and fails without its fix."""

import sys

import bmesh
import bpy
import numpy as np
import pytest

from tests.addon.conftest import MODULE



def mod(name):
    return sys.modules[MODULE + ".meshadjust_addon." + name]


def pos(obj):
    return mod("mesh_io").read_positions(obj.data)


def activate(obj):
    for o in bpy.context.view_layer.objects:
        o.select_set(False)
    obj.select_set(True)
    bpy.context.view_layer.objects.active = obj


def bumpy_uv_sphere(name="scan", segments=24, rings=12):
    """A UV sphere (quads, and triangle fans at the poles) with bumps, active."""
    bpy.ops.mesh.primitive_uv_sphere_add(segments=segments, ring_count=rings, radius=1.0)
    obj = bpy.context.active_object
    obj.name = obj.data.name = name
    V = pos(obj)
    r = 1.0 + 0.03 * np.sin(9 * V[:, 0]) * np.sin(7 * V[:, 1]) * np.sin(8 * V[:, 2])
    mod("mesh_io").write_positions(obj.data, V * r[:, None])
    return obj


def simplify(faces=100, **kw):
    kw.setdefault("fit", True)
    kw.setdefault("bind", True)
    return bpy.ops.meshadjust.simplify(target_mode='FACES', target_faces=faces, **kw)


def lift_in_edit_mode(cage, above=0.6, dz=0.2):
    """Enter Edit Mode on ``cage`` and lift its vertices above ``above``."""
    activate(cage)
    bpy.ops.object.mode_set(mode='EDIT')
    bm = bmesh.from_edit_mesh(cage.data)
    for v in bm.verts:
        if v.co.z > above:
            v.co.z += dz
    bmesh.update_edit_mesh(cage.data)


# --------------------------------------------------------------------------- the source
def test_a_source_left_in_edit_mode_is_refused_by_bind_and_fit_not_bound_stale(scene):
    """The artist edits the scan in Edit Mode (a vertex added, all moved) and,
    still there, binds its cage: the mesh from before the Edit Mode session
    was bound with no fingerprint, so the change was never flagged."""
    src = bumpy_uv_sphere()
    assert simplify(100, fit=False) == {'FINISHED'}
    cage = src.meshadjust.cage
    edited = cage.meshadjust.edited
    activate(src)
    bpy.ops.object.mode_set(mode='EDIT')
    bm = bmesh.from_edit_mesh(src.data)
    for v in bm.verts:
        v.co.x += 0.1
    bm.verts.new((0.0, 0.0, 5.0))
    bmesh.update_edit_mesh(src.data)
    fingerprint = edited.meshadjust.source_fingerprint
    V_edited = pos(edited)
    bpy.context.view_layer.objects.active = cage
    for op in (bpy.ops.meshadjust.bind, bpy.ops.meshadjust.fit_cage):
        with bpy.context.temp_override(active_object=cage, object=cage, selected_objects=[cage]):
            with pytest.raises(RuntimeError, match="'scan' is in Edit Mode, where its mesh does "
                                                   "not have the edits yet: leave Edit Mode on "
                                                   "'scan' first"):
                op()
    assert edited.meshadjust.source_fingerprint == fingerprint
    assert np.array_equal(pos(edited), V_edited)
    # the API's simplify too (the panel's button is greyed out)
    with pytest.raises(mod("api").core.MeshAdjustError, match="'scan' is in Edit Mode"):
        mod("api").simplify_object(src, target_faces=50)
    activate(src)
    bpy.ops.object.mode_set(mode='OBJECT')
    assert mod("operators").binding_warnings(cage) == [
        "'scan' changed since it was bound: its mesh was edited (266 -> 267 vertices, "
        "288 -> 288 faces)"]


# --------------------------------------------------------------------------- the cage
@pytest.mark.parametrize("kind", ["SUBSURF", "MIRROR"])
def test_a_cage_with_a_preview_modifier_refines_and_goes_live_from_edit_mode(scene, kind):
    """A Subdivision Surface (or Mirror) modifier on the cage to preview it, the
    cage edited in Edit Mode: Refine, Bind and live mode all stopped with
    "has modifiers that change its topology: leave Edit Mode to refine"."""
    src = bumpy_uv_sphere()
    assert simplify(100) == {'FINISHED'}
    cage = src.meshadjust.cage
    cage.modifiers.new("preview", kind)
    lift_in_edit_mode(cage)
    assert bpy.ops.meshadjust.refine(output='BOTH') == {'FINISHED'}
    in_edit = pos(cage.meshadjust.edited), pos(cage.meshadjust.refined)
    assert bpy.ops.meshadjust.bind() == {'FINISHED'}
    cage.meshadjust.live = True
    live = mod("live")
    live._pending.add(cage.name)
    live.refine_pending()
    assert cage.meshadjust.live, cage.meshadjust.last_report
    assert cage.meshadjust.last_report.startswith("live: ")
    assert cage.mode == 'EDIT'
    bpy.ops.object.mode_set(mode='OBJECT')
    cage.meshadjust.live = False
    assert bpy.ops.meshadjust.refine(output='BOTH') == {'FINISHED'}
    assert np.array_equal(pos(cage.meshadjust.edited), in_edit[0])
    assert np.array_equal(pos(cage.meshadjust.refined), in_edit[1])

