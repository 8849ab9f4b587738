"""Results and shape keys across several cages, copies, renames and reloads
(a helper's fuzz of the add-on, 2026-12-05: each test failed before its fix)."""

import bpy
import numpy as np
import pytest

from tests.addon.test_nothing_lost import _sculpt, bound_sphere, lift_top, mod, pos


def activate(obj):
    if bpy.context.object is not None and bpy.context.object.mode != 'OBJECT':
        bpy.ops.object.mode_set(mode='OBJECT')
    for o in bpy.context.view_layer.objects:
        o.select_set(False)
    obj.select_set(True)
    bpy.context.view_layer.objects.active = obj


def refine(cage, output='EDITED', **kw):
    activate(cage)
    return bpy.ops.meshadjust.refine(output=output, **kw)


def kco(kb):
    co = np.empty(3 * len(kb.data), np.float32)
    kb.data.foreach_get("co", co)
    return co.reshape(-1, 3)


def _refined():
    """A bound sphere and its cage, its top lifted, refined to both outputs."""
    dense, cage = bound_sphere()
    lift_top(cage)
    assert refine(cage, 'BOTH') == {'FINISHED'}
    return dense, cage


def dup(obj):
    activate(obj)
    bpy.ops.object.duplicate(linked=False)          # Shift+D
    return bpy.context.active_object


def unlink(obj):
    for col in list(obj.users_collection):
        col.objects.unlink(obj)                      # deleted in the outliner


def test_binding_a_duplicated_cage_leaves_the_first_cage_s_shape_key_alone(scene):
    dense, cage = bound_sphere()
    lift_top(cage, 0.1)
    assert refine(cage, 'SHAPE_KEY') == {'FINISHED'}
    K0 = kco(dense.data.shape_keys.key_blocks["dense_cage"]).copy()
    copy = dup(cage)
    lift_top(copy, -0.3)
    activate(copy)
    assert bpy.ops.meshadjust.bind() == {'FINISHED'}    # "given results of its own"
    assert copy.meshadjust.key_name != "dense_cage"
    assert np.array_equal(kco(dense.data.shape_keys.key_blocks["dense_cage"]), K0)


def test_a_new_cage_beside_a_renamed_one_writes_a_key_of_its_own(scene):
    dense, cage = bound_sphere()
    lift_top(cage, 0.2)
    assert refine(cage, 'SHAPE_KEY') == {'FINISHED'}
    cage.name = "face_cage"
    K_first = kco(dense.data.shape_keys.key_blocks["dense_cage"]).copy()
    activate(dense)
    assert bpy.ops.meshadjust.simplify(target_mode='FACES', target_faces=200, fit=False,
                                       bind=True, levels=2) == {'FINISHED'}
    cage2 = bpy.context.active_object                # named 'dense_cage' again
    V = pos(cage2); V[np.argmin(V[:, 2]), 2] -= 0.3; mod("mesh_io").write_positions(cage2.data, V)
    assert refine(cage2, 'SHAPE_KEY') == {'FINISHED'}
    assert np.array_equal(kco(dense.data.shape_keys.key_blocks["dense_cage"]), K_first)


@pytest.mark.parametrize("step", ["bind", "fit", "refine_levels"])
def test_a_renamed_key_is_muted_for_a_rebind_not_baked_in(scene, step):
    dense, cage = bound_sphere()
    V0 = pos(dense).copy()
    lift_top(cage, 0.3)
    assert refine(cage, 'EDITED') == {'FINISHED'}
    want = pos(cage.meshadjust.edited)[:, 2].max() - V0[:, 2].max()
    assert refine(cage, 'SHAPE_KEY') == {'FINISHED'}
    dense.data.shape_keys.key_blocks[cage.name].name = "smile"
    activate(cage)
    {"bind": lambda: bpy.ops.meshadjust.bind(),
     "fit": lambda: bpy.ops.meshadjust.fit_cage(),
     "refine_levels": lambda: refine(cage, 'SHAPE_KEY', levels=1)}[step]()
    got = pos(cage.meshadjust.edited)[:, 2].max() - V0[:, 2].max()
    assert "changed since" not in cage.meshadjust.last_report
    assert got == pytest.approx(want, abs=0.03), f"edit shown {got:.3f}, want {want:.3f}"


def test_another_cage_s_renamed_key_is_not_baked_into_a_rebind(scene):
    dense, cageA = bound_sphere()
    V0 = pos(dense).copy()
    activate(dense)
    assert bpy.ops.meshadjust.simplify(target_mode='FACES', target_faces=200, fit=False,
                                       bind=True, levels=2) == {'FINISHED'}
    cageB = bpy.context.active_object
    lift_top(cageB, 0.4)
    assert refine(cageB, 'SHAPE_KEY') == {'FINISHED'}
    dense.data.shape_keys.key_blocks[cageB.name].name = "big nose"
    activate(cageA)
    assert bpy.ops.meshadjust.bind(levels=1) == {'FINISHED'}      # A is unedited
    assert np.abs(pos(cageA.meshadjust.edited) - V0).max() < 1e-3


@pytest.mark.parametrize("output", ["EDITED", "REFINED"])
def test_an_edited_original_in_edit_mode_after_a_reload_is_refused_cleanly(scene, tmp_path, output):
    dense, cage = _refined()
    p = str(tmp_path / "f.blend")
    bpy.ops.wm.save_as_mainfile(filepath=p); bpy.ops.wm.open_mainfile(filepath=p)
    cage = bpy.data.objects["dense_cage"]
    activate(cage.meshadjust.edited); bpy.ops.object.mode_set(mode='EDIT')
    bpy.context.view_layer.objects.active = cage
    with pytest.raises(RuntimeError, match="'dense_edited' is in Edit Mode") as caught:
        bpy.ops.meshadjust.refine(output=output)      # (a raw TypeError with a cold cache)
    assert "Traceback" not in str(caught.value)


def test_a_sculpted_refined_mesh_follows_a_moved_source_on_bind(scene):
    dense, cage = _refined()
    refined = cage.meshadjust.refined
    _sculpt(refined)
    dense.location = (5, 0, 0)
    bpy.context.view_layer.update()
    activate(cage)
    assert bpy.ops.meshadjust.bind() == {'FINISHED'}
    assert tuple(refined.matrix_world.translation) == pytest.approx((5, 0, 0))   # (stayed at 0)


@pytest.mark.parametrize("step", ["refine", "bind"])
def test_a_deleted_refined_mesh_is_linked_back(scene, step):
    dense, cage = _refined()
    refined = cage.meshadjust.refined
    unlink(refined)
    activate(cage)
    assert (refine(cage, 'BOTH') if step == "refine" else bpy.ops.meshadjust.bind()) == {'FINISHED'}
    assert cage.meshadjust.refined == refined and refined.users_collection
    assert "dense_refined.001" not in bpy.data.objects


def test_a_refine_re_binding_reports_the_copies_it_kept(scene):
    dense, cage = _refined()
    _sculpt(cage.meshadjust.edited)
    lift_top(cage, 0.1)
    assert refine(cage, 'REFINED', levels=1) == {'FINISHED'}
    assert "dense_edited.hand" in bpy.data.objects
    assert "kept as" in cage.meshadjust.last_report              # (made, and had not been said)


def test_a_result_in_sculpt_mode_with_dynamic_topology_is_refused(scene):
    # (leaving the mode wrote the sculpt's BMesh back over Refine's write)
    dense, cage = bound_sphere()
    lift_top(cage)
    assert refine(cage, 'EDITED') == {'FINISHED'}
    edited = cage.meshadjust.edited
    activate(edited)
    bpy.ops.object.mode_set(mode='SCULPT')
    bpy.ops.sculpt.dynamic_topology_toggle()
    bpy.context.view_layer.objects.active = cage
    with pytest.raises(RuntimeError, match="Sculpt Mode with Dynamic Topology"):
        bpy.ops.meshadjust.refine(output='EDITED')
