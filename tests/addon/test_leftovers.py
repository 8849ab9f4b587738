"""What a step must not leave behind: a failed step's renames, MeshAdjust's
shape key left as the reference key when the Basis was deleted, the data of
a deleted edited original."""

import bpy
import pytest

from tests.addon.test_nothing_lost import (_bug, _raises_the_bug, assert_all_unchanged,
                                           bound_sphere, full_snapshot, mod)


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
