"""Object states an artist's scene has and the first tests did not: transforms
the cage cannot copy, sources in Edit Mode, disabled in the viewport, shared
or with a changed face set, renamed cages, cages with shape keys, a cage
moved as an object in live mode. Each is either handled or refused with a
report that names the object and what to do, the scene left as it was."""


import sys

import bpy
import numpy as np
import pytest

from tests.addon.conftest import MODULE, make_object
from tests.addon.test_nothing_lost import (assert_unchanged, bound_sphere, delete_a_face,
                                           lift_top, mod, pos, scene_snapshot)
from tests.addon.test_operators import bumpy_sphere, simplify


@pytest.fixture()
def bound(scene):
    return bound_sphere(3, 120)


def activate(obj):
    for o in bpy.context.view_layer.objects:
        o.select_set(False)
    obj.select_set(True)
    bpy.context.view_layer.objects.active = obj


def test_a_zero_scale_is_refused_by_name_everywhere_and_stops_live(bound):
    dense, cage = bound
    dense.scale = (1.0, 1.0, 0.0)                         # flattened after the bind
    bpy.context.view_layer.update()
    activate(cage)
    before = scene_snapshot()
    for op in (lambda: bpy.ops.meshadjust.refine(output='EDITED'), bpy.ops.meshadjust.fit_cage,
               bpy.ops.meshadjust.bind):
        with pytest.raises(RuntimeError, match="'dense' has a zero scale on an axis"):
            op()
        assert_unchanged(before)
    cage.meshadjust.live = True
    live = mod("live")
    live._pending[cage.name] = None
    live.refine_pending()                                 # (no traceback out of the timer)
    assert not cage.meshadjust.live
    assert cage.meshadjust.last_report.startswith("live refine stopped: 'dense' has a zero scale")
    # and Simplify refuses such a source before it starts
    other = make_object("flat", *bumpy_sphere(2))
    other.scale = (0.0, 1.0, 1.0)
    activate(other)
    with pytest.raises(RuntimeError, match="'flat' has a zero scale"):
        simplify(50)


def test_a_sheared_source_is_refused_with_what_to_do(scene):
    parent = bpy.data.objects.new("parent", None)
    scene.collection.objects.link(parent)
    parent.scale = (1.0, 3.0, 1.0)
    child = make_object("child", *bumpy_sphere(2))
    child.parent = parent
    child.rotation_euler = (0.0, 0.0, 0.6)                # rotated under an uneven scale
    bpy.context.view_layer.update()
    activate(child)
    with pytest.raises(RuntimeError, match="'child' has a sheared transform .* Apply > Scale "
                                           "on 'parent'"):
        simplify(50)
    # without the rotation there is no shear: the cage round-trips the source
    child.rotation_euler = (0.0, 0.0, 0.0)
    bpy.context.view_layer.update()
    assert simplify(50, fit=False) == {'FINISHED'}
    cage = child.meshadjust.cage
    assert np.allclose(np.array(cage.matrix_world), np.array(child.matrix_world), atol=1e-6)
    assert bpy.ops.meshadjust.refine(output='EDITED') == {'FINISHED'}
    assert np.abs(pos(cage.meshadjust.edited) - pos(child)).max() <= 1e-5


def test_a_refine_refused_after_its_rebind_would_be_computed_changes_nothing(bound):
    dense, cage = bound
    dense.modifiers.new("more", 'SUBSURF')               # the bound mesh is not the source's mesh
    activate(cage)
    assert bpy.ops.meshadjust.bind() == {'FINISHED'}
    lift_top(cage)
    detail = cage.meshadjust.edited.meshadjust.detail_mesh.name
    before = scene_snapshot()
    with pytest.raises(RuntimeError, match="cannot be a shape key"):
        bpy.ops.meshadjust.refine(output='SHAPE_KEY', levels=1, scheme='butterfly')
    assert_unchanged(before)
    assert (cage.meshadjust.levels, cage.meshadjust.scheme) == (2, 'loop')
    assert cage.meshadjust.edited.meshadjust.detail_mesh.name == detail
    assert bpy.ops.meshadjust.refine(output='EDITED') == {'FINISHED'}


def test_a_shape_key_on_a_source_in_edit_mode_is_refused(bound):
    dense, cage = bound
    lift_top(cage)
    activate(dense)
    bpy.ops.object.mode_set(mode='EDIT')
    bpy.context.view_layer.objects.active = cage
    cage.select_set(True)
    before = scene_snapshot()
    with pytest.raises(RuntimeError, match="'dense' is in Edit Mode: a shape key written now "
                                           "would be lost"):
        bpy.ops.meshadjust.refine(output='SHAPE_KEY')
    assert dense.data.shape_keys is None
    bpy.ops.object.mode_set(mode='OBJECT')
    assert_unchanged(before)


def test_a_renamed_cage_keeps_writing_its_own_shape_key(bound):
    dense, cage = bound
    lift_top(cage)
    activate(cage)
    assert bpy.ops.meshadjust.refine(output='SHAPE_KEY') == {'FINISHED'}
    first = pos(dense).copy()
    cage.name = "MyCage"
    lift_top(cage, 0.1)
    assert bpy.ops.meshadjust.refine(output='SHAPE_KEY') == {'FINISHED'}
    keys = dense.data.shape_keys.key_blocks
    assert [kb.name for kb in keys] == ["Basis", "dense_cage"]
    # the key moved with the edit, and it is still MeshAdjust's own: no staleness
    assert np.abs(np.array([kb.co[:] for kb in keys["dense_cage"].data]) - first).max() > 1e-3
    assert "changed since it was bound" not in cage.meshadjust.last_report


def test_a_shape_key_on_a_shared_mesh_is_refused(bound):
    dense, cage = bound
    twin = bpy.data.objects.new("twin", dense.data)           # a linked duplicate
    bpy.context.scene.collection.objects.link(twin)
    lift_top(cage)
    activate(cage)
    with pytest.raises(RuntimeError, match="'dense' shares its mesh with 1 other object"):
        bpy.ops.meshadjust.refine(output='SHAPE_KEY')
    assert dense.data.shape_keys is None


def test_a_source_disabled_in_the_viewport_is_refused_not_read_without_its_modifiers(scene):
    dense = make_object("dense", *bumpy_sphere(2))
    dense.modifiers.new("more", 'SUBSURF')
    dense.hide_viewport = True
    activate(dense)
    before = scene_snapshot()
    with pytest.raises(RuntimeError, match="'dense' is disabled in the viewport"):
        simplify(60)
    assert_unchanged(before)
    dense.hide_viewport = False
    assert simplify(60, fit=False) == {'FINISHED'}
    # the evaluated mesh was bound: one subdivision level, 320 triangles -> 960 quads
    assert dense.meshadjust.cage.meshadjust.edited.meshadjust.dense_faces == 2 * 960


def test_a_rebind_after_a_source_face_was_deleted_remakes_the_edited_original(bound):
    dense, cage = bound
    delete_a_face(dense)
    activate(cage)
    assert bpy.ops.meshadjust.bind() == {'FINISHED'}
    edited = cage.meshadjust.edited
    assert len(edited.data.polygons) == len(dense.data.polygons) == 1279
    assert np.array_equal(mod("mesh_io").read_triangles(edited.data)[0],
                          mod("mesh_io").read_triangles(dense.data)[0])


def test_a_cage_with_shape_keys_is_refused(bound):
    dense, cage = bound
    cage.shape_key_add(name="Basis")
    pose = cage.shape_key_add(name="Pose")
    pose.value = 1.0
    activate(cage)
    before = scene_snapshot()
    with pytest.raises(RuntimeError, match="'dense_cage' has shape keys"):
        bpy.ops.meshadjust.refine(output='EDITED')
    assert_unchanged(before)


def test_live_follows_the_cage_moved_as_an_object(bound):
    dense, cage = bound
    live = mod("live")
    activate(cage)
    cage.meshadjust.live = True
    live._pending.clear()
    cage.location.x += 0.5
    bpy.context.view_layer.update()                       # depsgraph_update_post
    assert cage.name in live._pending
    live.refine_pending()
    edited = cage.meshadjust.edited
    assert np.abs(pos(edited)[:, 0] - pos(dense)[:, 0] - 0.5).max() <= 1e-5


def test_a_deleted_edited_original_is_linked_back_by_refine_and_stops_live(bound):
    dense, cage = bound
    edited = cage.meshadjust.edited
    for col in list(edited.users_collection):
        col.objects.unlink(edited)                          # deleted in the outliner
    cage.meshadjust.live = True
    live = mod("live")
    live._pending[cage.name] = None
    live.refine_pending()
    assert not cage.meshadjust.live
    assert "'dense_edited' was deleted" in cage.meshadjust.last_report
    activate(cage)
    assert bpy.ops.meshadjust.refine(output='EDITED') == {'FINISHED'}
    assert edited.users_collection
    assert "'dense_edited' had been deleted: linked back" in cage.meshadjust.last_report


def test_simplify_refuses_a_source_linked_from_a_library(scene, tmp_path):
    make_object("scan", *bumpy_sphere(2))
    path = str(tmp_path / "library.blend")
    bpy.data.libraries.write(path, {bpy.data.objects["scan"]})
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    with bpy.data.libraries.load(path, link=True) as (src, dst):
        dst.objects = ["scan"]
    linked = dst.objects[0]
    bpy.context.scene.collection.objects.link(linked)
    activate(linked)
    with pytest.raises(RuntimeError, match="'scan' is linked from a library"):
        simplify(50)


def world(obj):
    M = np.array(obj.matrix_world)
    return pos(obj) @ M[:3, :3].T + M[:3, 3]


def test_a_source_transform_applied_after_the_bind_is_refused_then_rebound_in_place(scene):
    dense = make_object("dense", *bumpy_sphere(3))
    dense.scale = (2.0, 2.0, 2.0)
    dense.location = (1.0, 0.0, 0.0)
    bpy.context.view_layer.update()
    assert simplify(120, fit=False) == {'FINISHED'}
    cage = dense.meshadjust.cage
    lift_top(cage)
    activate(cage)
    assert bpy.ops.meshadjust.refine(output='EDITED') == {'FINISHED'}
    edited = cage.meshadjust.edited
    shown = world(edited)
    activate(dense)
    bpy.ops.object.transform_apply(location=False, rotation=False, scale=True)
    assert np.abs(world(dense) - world(edited)).max() > 0.1          # (the edit shows)
    activate(cage)
    before = scene_snapshot()
    with pytest.raises(RuntimeError, match="'dense' was moved, rotated or scaled \\(or had its "
                                           "transform applied\\) since 'dense_cage' was bound"):
        bpy.ops.meshadjust.refine(output='EDITED')
    assert_unchanged(before)
    assert any("'dense' was moved" in w for w in mod("operators").binding_warnings(cage))
    # Bind (keep edit) binds it where it is: the same edit, the result where it was
    assert bpy.ops.meshadjust.bind() == {'FINISHED'}
    assert "the edit (1 cage vertex moved) kept on top" in cage.meshadjust.last_report
    assert bpy.ops.meshadjust.refine(output='EDITED') == {'FINISHED'}
    assert np.abs(world(edited) - shown).max() <= 1e-4
    assert not any("was moved" in w for w in mod("operators").binding_warnings(cage))


def test_an_edited_original_with_shape_keys_is_refused_and_a_result_cannot_be_simplified(bound):
    dense, cage = bound
    edited = cage.meshadjust.edited
    edited.shape_key_add(name="Basis")
    edited.shape_key_add(name="Variant").value = 1.0
    lift_top(cage)
    activate(cage)
    before = scene_snapshot()
    with pytest.raises(RuntimeError, match="'dense_edited' has shape keys, which hide the mesh"):
        bpy.ops.meshadjust.refine(output='EDITED')
    assert_unchanged(before)
    activate(edited)
    with pytest.raises(RuntimeError, match="'dense_edited' is the edited original of "
                                           "'dense_cage', which the cage rewrites"):
        simplify(40)


def test_the_api_refuses_levels_and_schemes_the_ui_does_not_offer(bound):
    dense, cage = bound
    api, core = mod("api"), sys.modules[MODULE + ".core"]
    before = scene_snapshot()
    for kw, text in (({"levels": 9}, "levels must be an integer from 0 to 5, got 9"),
                     ({"levels": 2.5}, "levels must be an integer from 0 to 5, got 2.5"),
                     ({"levels": -1}, "levels must be an integer from 0 to 5, got -1"),
                     ({"scheme": "catmull"}, "scheme must be one of 'loop', 'butterfly', "
                                             "got 'catmull'")):
        with pytest.raises(core.InvalidArgumentError, match=text):
            api.refine_object(cage, **kw)
        with pytest.raises(core.InvalidArgumentError, match=text):
            api.simplify_object(dense, target_faces=60, **kw)
    assert_unchanged(before)


def test_the_key_of_a_deleted_cage_is_never_baked_into_another_cages_binding(bound):
    dense, cage = bound
    activate(dense)
    assert simplify(60, fit=False) == {'FINISHED'}                 # a second cage
    second = dense.meshadjust.cage
    lift_top(second, 0.3)
    activate(second)
    assert bpy.ops.meshadjust.refine(output='SHAPE_KEY') == {'FINISHED'}
    bpy.data.objects.remove(second)                                # the artist deletes it
    assert mod("operators").binding_warnings(cage) == []           # (its key is not the artist's)
    activate(cage)
    assert bpy.ops.meshadjust.bind() == {'FINISHED'}
    # the first cage has no edit: its edited original is the source's mesh, not its key's mix
    assert np.abs(pos(cage.meshadjust.edited) - pos(dense)).max() <= 1e-6
