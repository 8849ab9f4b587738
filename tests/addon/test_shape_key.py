"""The edit as a shape key of the source: Basis untouched, a key named after
the cage (value 1.0) equal to the edited original, updated in place by
Refine and by Live, never bound as if it were the artist's mesh."""

import bpy
import numpy as np
import pytest

from tests.addon.conftest import make_object
from tests.addon.test_nothing_lost import lift_top, mod, orphans, pos
from tests.addon.test_operators import bumpy_sphere, simplify


def key_co(kb):
    co = np.empty(3 * len(kb.data), np.float32)
    kb.data.foreach_get("co", co)
    return co.reshape(-1, 3).astype(np.float64)


@pytest.fixture()
def bound(scene):
    V, F = bumpy_sphere(4)
    dense = make_object("dense", V, F)
    assert simplify(300) == {'FINISHED'}
    return dense, dense.meshadjust.cage


def test_shape_key_output_basis_untouched_key_equals_edited_original(bound):
    dense, cage = bound
    V0 = pos(dense)
    lift_top(cage, 0.2)
    assert bpy.ops.meshadjust.refine(output='SHAPE_KEY') == {'FINISHED'}
    keys = dense.data.shape_keys
    assert [kb.name for kb in keys.key_blocks] == ["Basis", "dense_cage"]
    assert np.array_equal(key_co(keys.reference_key), V0.astype(np.float32).astype(np.float64))
    assert np.array_equal(pos(dense), V0)                    # the mesh itself is untouched
    kb = keys.key_blocks["dense_cage"]
    assert kb.value == 1.0 and kb.relative_key == keys.reference_key
    assert bpy.ops.meshadjust.refine(output='EDITED') == {'FINISHED'}
    assert np.abs(key_co(kb) - pos(cage.meshadjust.edited)).max() < 1e-6
    assert key_co(kb)[:, 2].max() > V0[:, 2].max() + 0.05
    # updated in place
    lift_top(cage, 0.1)
    assert bpy.ops.meshadjust.refine(output='SHAPE_KEY') == {'FINISHED'}
    assert len(dense.data.shape_keys.key_blocks) == 2
    assert "shape key 'dense_cage' of 'dense' updated" in cage.meshadjust.last_report
    assert key_co(dense.data.shape_keys.key_blocks["dense_cage"])[:, 2].max() > \
        key_co(kb)[:, 2].max() - 1e-9
    assert mod("operators").binding_warnings(cage) == []     # its own key is not a change
    assert orphans() == []


def test_the_own_key_is_not_bound_as_the_artists_mesh(bound):
    dense, cage = bound
    lift_top(cage, 0.2)
    bpy.ops.meshadjust.refine(output='SHAPE_KEY')
    before = key_co(dense.data.shape_keys.key_blocks["dense_cage"])
    assert bpy.ops.meshadjust.bind() == {'FINISHED'}         # re-bind: keeps the edit
    bpy.ops.meshadjust.refine(output='SHAPE_KEY')
    after = key_co(dense.data.shape_keys.key_blocks["dense_cage"])
    assert np.abs(after - before).max() < 1e-5               # not applied twice
    assert not dense.data.shape_keys.key_blocks["dense_cage"].mute


def test_shape_key_on_a_source_with_its_own_keys_is_relative_to_what_was_bound(scene):
    V, F = bumpy_sphere(4)
    dense = make_object("dense", V, F)
    dense.shape_key_add(name="Basis", from_mix=False)
    pose = dense.shape_key_add(name="pose", from_mix=False)
    co = key_co(pose)
    co[:, 0] += 0.1
    pose.data.foreach_set("co", co.astype(np.float32).ravel())
    pose.value = 1.0
    assert simplify(300) == {'FINISHED'}
    cage = dense.meshadjust.cage
    lift_top(cage, 0.2)
    assert bpy.ops.meshadjust.refine(output='SHAPE_KEY') == {'FINISHED'}
    bpy.ops.meshadjust.refine(output='EDITED')
    kb = dense.data.shape_keys.key_blocks["dense_cage"]
    # the key's displacement from the Basis is the edit alone (the pose stays the pose's)
    disp = key_co(kb) - key_co(dense.data.shape_keys.reference_key)
    edit = pos(cage.meshadjust.edited) - (V + [0.1, 0.0, 0.0])
    assert np.abs(disp - edit).max() < 1e-4


def test_live_updates_the_shape_key(bound):
    dense, cage = bound
    live = mod("live")
    bpy.context.scene.meshadjust.output = 'SHAPE_KEY'
    cage.meshadjust.live = True
    Vc = pos(cage)
    mod("mesh_io").write_positions(cage.data, Vc + [0.0, 0.0, 0.05])
    bpy.context.view_layer.update()
    assert cage.name in live._pending
    live.refine_pending()
    kb = dense.data.shape_keys.key_blocks["dense_cage"]
    assert np.allclose(key_co(kb)[:, 2] - pos(dense)[:, 2], 0.05, atol=1e-4)


def test_shape_key_refused_when_modifiers_change_the_vertex_count(scene):
    V, F = bumpy_sphere(3)
    dense = make_object("dense", V, F)
    dense.modifiers.new("sub", 'SUBSURF').levels = 1
    assert simplify(300) == {'FINISHED'}
    assert dense.meshadjust.cage is not None
    from tests.addon.test_nothing_lost import scene_snapshot, assert_unchanged
    before = scene_snapshot()
    with pytest.raises(RuntimeError, match="cannot be a shape key"):
        bpy.ops.meshadjust.refine(output='SHAPE_KEY')
    assert_unchanged(before)
    assert dense.data.shape_keys is None


def test_a_source_with_only_its_meshadjust_key_simplifies_as_a_plain_mesh(bound):
    dense, cage = bound
    lift_top(cage, 0.2)
    bpy.ops.meshadjust.refine(output='SHAPE_KEY')
    vg = dense.vertex_groups.new(name="lock")
    vg.add(list(range(20)), 1.0, 'REPLACE')
    bpy.context.view_layer.objects.active = dense
    for o in bpy.data.objects:
        o.select_set(o is dense)
    assert bpy.ops.meshadjust.simplify(target_mode='FACES', target_faces=200, lock_group="lock",
                                       fit=False, bind=False) == {'FINISHED'}
    second = dense.meshadjust.cage
    assert second != cage and "evaluated mesh" not in second.meshadjust.last_report


def test_shape_key_under_a_modifier_that_keeps_the_vertex_count(scene):
    V, F = bumpy_sphere(4)
    dense = make_object("dense", V, F)
    dense.modifiers.new("disp", 'DISPLACE').strength = 0.05     # along the normals, no texture
    assert simplify(300) == {'FINISHED'}
    cage = dense.meshadjust.cage
    lift_top(cage, 0.2)
    assert bpy.ops.meshadjust.refine(output='SHAPE_KEY') == {'FINISHED'}
    assert bpy.ops.meshadjust.refine(output='EDITED') == {'FINISHED'}
    # the key moves the base mesh by the edit; the modifier then acts on top, as it
    # did on the mesh that was bound
    kb = dense.data.shape_keys.key_blocks["dense_cage"]
    disp = key_co(kb) - key_co(dense.data.shape_keys.reference_key)
    depsgraph = bpy.context.evaluated_depsgraph_get()
    kb.value = 0.0
    depsgraph.update()
    bound = mod("mesh_io").read_positions(dense.evaluated_get(depsgraph).data)
    assert np.abs(disp - (pos(cage.meshadjust.edited) - bound)).max() < 1e-4
    assert disp[:, 2].max() > 0.05
