"""What a step must not leave behind: a failed step's renames, MeshAdjust's
shape key left as the reference key when the Basis was deleted, the data of
a deleted edited original."""

import bpy
import numpy as np
import pytest

from tests.addon.conftest import make_object
from tests.addon.test_nothing_lost import (_bug, _raises_the_bug, assert_all_unchanged,
                                           bound_sphere, full_snapshot, lift_top, mod)
from tests.addon.test_operators import bumpy_sphere, simplify


@pytest.fixture()
def bound(scene):
    return bound_sphere()


def names():
    """``{session_uid: name}`` of every object and mesh (by the data-block, so a
    rename shows)."""
    return {id_.session_uid: id_.name for coll in (bpy.data.objects, bpy.data.meshes) for id_ in coll}


def renamed_since(before):
    """``{old name: new name}`` of the objects and meshes of ``before``
    (:func:`names`) renamed since (None: removed), and ``'added'``: the names
    of those added."""
    now = names()
    out = {name: now.get(uid) for uid, name in before.items() if now.get(uid) != name}
    added = sorted(name for uid, name in now.items() if uid not in before)
    return {**out, **({"added": added} if added else {})}


def test_a_failed_bind_gives_every_object_and_mesh_its_name_back(bound, monkeypatch):
    # (the bind names the detail mesh after its edited original: the artist renamed
    # that one, the failed bind left 'dense_edited.detail' renamed 'statue.detail')
    dense, cage = bound
    cage.meshadjust.edited.name = "statue"
    before, snapshot = names(), full_snapshot()
    monkeypatch.setattr(mod("store"), "save_rest", _bug)
    bpy.context.view_layer.objects.active = cage
    _raises_the_bug(lambda: bpy.ops.meshadjust.bind())
    monkeypatch.undo()
    assert renamed_since(before) == {}
    assert_all_unchanged(snapshot)
    assert bpy.ops.meshadjust.bind() == {'FINISHED'}          # the rename is the bind's own
    assert cage.meshadjust.edited.meshadjust.detail_mesh.name == "statue.detail"


def test_any_rename_in_a_failed_block_is_undone_even_swapped_names(bound):
    dense, cage = bound
    edited = cage.meshadjust.edited
    before = names()
    with pytest.raises(RuntimeError, match="boom"):
        with mod("rollback").all_or_nothing():
            dense.name, cage.name = "tmp", "dense"           # two objects swap names
            dense.name = "dense_cage"
            edited.data.name, dense.data.name = "x", "dense_edited"
            edited.data.name = "dense"
            _bug()
    assert renamed_since(before) == {}


def _key_co(kb):
    return mod("mesh_io").read_key(kb).reshape(-1, 3)


def _basis_deleted(dense, cage):
    """Write the cage's shape key (the top lifted), then delete the Basis as
    an artist would: the cage's key becomes the reference key, and the mesh
    takes its shape. Returns the Basis as it was (float32, (n,3))."""
    lift_top(cage, 0.2)
    assert bpy.ops.meshadjust.refine(output='SHAPE_KEY') == {'FINISHED'}
    keys = dense.data.shape_keys
    V0 = _key_co(keys.key_blocks["Basis"])
    dense.shape_key_remove(keys.key_blocks["Basis"])
    assert keys.reference_key.name == "dense_cage"
    return V0


def test_a_deleted_basis_is_named_not_written_over_and_restore_basis_puts_it_back(bound):
    # (Refine had written the edit over the reference key, the source's own shape:
    # the mesh out of step with it, the binding stale after every write; a re-bind
    # bound the edit as the artist's mesh)
    dense, cage = bound
    V0 = _basis_deleted(dense, cage)
    K = _key_co(dense.data.shape_keys.reference_key)
    bpy.context.view_layer.objects.active = cage
    before = full_snapshot()
    lost = "'dense_cage' is now the reference key of 'dense' \\(its Basis was deleted.*Restore Basis"
    for op in (lambda: bpy.ops.meshadjust.refine(output='SHAPE_KEY'), bpy.ops.meshadjust.bind,
               bpy.ops.meshadjust.fit_cage):
        with pytest.raises(RuntimeError, match=lost):
            op()
    assert_all_unchanged(before)
    assert "Restore Basis" in mod("panel").basis_lost(bpy.context)
    assert bpy.ops.meshadjust.restore_basis() == {'FINISHED'}
    keys = dense.data.shape_keys
    assert [kb.name for kb in keys.key_blocks] == ["Basis", "dense_cage"]
    assert keys.reference_key.name == "Basis"
    assert np.abs(_key_co(keys.reference_key) - V0).max() < 1e-6       # the mesh bound
    assert np.abs(mod("mesh_io").read_positions(dense.data) - V0).max() < 1e-6
    mine = keys.key_blocks["dense_cage"]
    assert np.array_equal(_key_co(mine), K)                            # the edit, bit for bit
    assert mine.value == 1.0 and mine.relative_key == keys.reference_key
    assert mod("operators").binding_warnings(cage) == []              # the Basis is the one bound
    assert mod("panel").basis_lost(bpy.context) is None
    assert "Basis of 'dense' restored" in cage.meshadjust.last_report
    lift_top(cage, 0.1)
    assert bpy.ops.meshadjust.refine(output='SHAPE_KEY') == {'FINISHED'}
    assert np.abs(_key_co(keys.reference_key) - V0).max() < 1e-6       # untouched since
    assert "changed since" not in cage.meshadjust.last_report


def test_restore_basis_failing_late_leaves_the_source_as_it_was(bound, monkeypatch):
    dense, cage = bound
    _basis_deleted(dense, cage)
    bpy.context.view_layer.objects.active = cage
    before = full_snapshot()
    monkeypatch.setattr(mod("staleness"), "touched", _bug)
    _raises_the_bug(bpy.ops.meshadjust.restore_basis)
    monkeypatch.undo()
    assert_all_unchanged(before)
    assert dense.data.shape_keys.reference_key.name == "dense_cage"


def test_a_deleted_basis_kept_as_the_source_s_shape_by_renaming_the_key(bound):
    # (the other way out the message names: the edit becomes the artist's own shape)
    dense, cage = bound
    _basis_deleted(dense, cage)
    keys = dense.data.shape_keys
    keys.reference_key.name = "edited"
    K = _key_co(keys.reference_key)
    bpy.context.view_layer.objects.active = cage
    assert bpy.ops.meshadjust.bind(keep_edit=False) == {'FINISHED'}
    lift_top(cage, 0.1)
    assert bpy.ops.meshadjust.refine(output='SHAPE_KEY') == {'FINISHED'}
    assert [kb.name for kb in keys.key_blocks] == ["edited", "dense_cage"]
    assert np.array_equal(_key_co(keys.reference_key), K)
    lifted = _key_co(keys.key_blocks["dense_cage"])[:, 2] - K[:, 2]
    assert 0.05 < lifted.max() < 0.15                      # the new lift only, not the old again
    with pytest.raises(RuntimeError, match="not the reference key of its source: nothing to restore"):
        bpy.ops.meshadjust.restore_basis()


def test_restore_basis_refuses_a_basis_it_does_not_know(scene):
    # bound over another key of the artist: the mesh bound was not the Basis
    dense = make_object("dense", *bumpy_sphere(3))
    dense.shape_key_add(name="Basis", from_mix=False)
    dense.shape_key_add(name="pose", from_mix=False).value = 0.5
    assert simplify(200, fit=False) == {'FINISHED'}
    cage = dense.meshadjust.cage
    keys = dense.data.shape_keys
    lift_top(cage, 0.2)
    assert bpy.ops.meshadjust.refine(output='SHAPE_KEY') == {'FINISHED'}
    dense.shape_key_remove(keys.key_blocks["pose"])
    dense.shape_key_remove(keys.key_blocks["Basis"])
    assert keys.reference_key.name == "dense_cage"
    bpy.context.view_layer.objects.active = cage
    before = full_snapshot()
    with pytest.raises(RuntimeError, match="other shape keys or modifiers when it was bound.*Undo"):
        bpy.ops.meshadjust.restore_basis()
    assert_all_unchanged(before)


def _details():
    """The names of the detail meshes (``<edited>.detail``) in the file."""
    return sorted(m.name for m in bpy.data.meshes if ".detail" in m.name)


def test_the_detail_data_of_a_removed_edited_original_goes_with_the_next_step(bound, monkeypatch):
    # (its fake user had kept it in the file for ever)
    dense, cage = bound
    bpy.data.objects.remove(cage.meshadjust.edited)
    assert _details() == ["dense_edited.detail"]
    bpy.context.view_layer.objects.active = cage
    before = full_snapshot()
    monkeypatch.setattr(mod("store"), "save_rest", _bug)
    _raises_the_bug(bpy.ops.meshadjust.bind)               # a failed step removes nothing
    monkeypatch.undo()
    assert_all_unchanged(before)
    assert bpy.ops.meshadjust.bind() == {'FINISHED'}
    edited = cage.meshadjust.edited
    assert _details() == ["dense_edited.detail"]            # the new one, under the old name
    assert edited.meshadjust.detail_mesh.name == "dense_edited.detail"
    assert [m.name for m in bpy.data.meshes if m.users == int(m.use_fake_user)] == \
        ["dense_edited"]                                      # (Blender's own orphan: the
    # removed object's mesh, no fake user, purged on save as for any deleted object)


def test_a_detail_mesh_still_used_is_never_removed(bound):
    dense, cage = bound
    edited = cage.meshadjust.edited
    detail = edited.meshadjust.detail_mesh
    twin = edited.copy()                                    # points to the same detail data
    bpy.context.scene.collection.objects.link(twin)
    bpy.data.objects.remove(edited)
    mod("leftovers").remove_orphan_details()
    assert detail.name in bpy.data.meshes
    shown = bpy.data.objects.new("shown", detail)           # the artist uses it as a mesh
    bpy.data.objects.remove(twin)
    mod("leftovers").remove_orphan_details()
    assert detail.name in bpy.data.meshes and shown.data == detail
    bpy.data.objects.remove(shown)
    assert mod("leftovers").remove_orphan_details() == ["dense_edited.detail"]


def test_a_leaked_detail_mesh_is_removed_when_the_file_is_loaded(bound, tmp_path):
    dense, cage = bound
    tag = mod("leftovers").TAG
    del cage.meshadjust.edited.meshadjust.detail_mesh[tag]    # a file made before the tag:
    path = str(tmp_path / "leak.blend")
    bpy.ops.wm.save_as_mainfile(filepath=path)
    bpy.ops.wm.open_mainfile(filepath=path)
    edited = bpy.data.objects["dense_edited"]
    assert edited.meshadjust.detail_mesh.get(tag)             # tagged when loaded
    bpy.data.objects.remove(edited)
    bpy.ops.wm.save_as_mainfile(filepath=path)
    bpy.ops.wm.open_mainfile(filepath=path)
    assert "dense_edited.detail" not in bpy.data.meshes
    assert sorted(m.name for m in bpy.data.meshes) == ["dense", "dense_cage"]
