"""What a fuzz of the add-on with the objects and habits artists have found
(2026-12-05): the artist working on while a step runs in the background,
a cage deleted or disabled before Edit Cage, a cage deleted for good and
made again, shape keys limited by a vertex group, pinned to show alone or
absolute (Relative off), Subdivide in place on an object with modifiers or
several materials.
Each is handled or refused naming the object, the scene left as it was."""

import threading
from types import SimpleNamespace

import bmesh
import bpy
import numpy as np
import pytest

from tests.addon.conftest import make_object
from tests.addon.test_nothing_lost import (assert_all_unchanged, bound_sphere, full_snapshot,
                                           lift_top, mod, pos)
from tests.addon.test_object_states import activate
from tests.addon.test_operators import bumpy_sphere, simplify


@pytest.fixture()
def bound(scene):
    return bound_sphere(3, 120)


class _WM:
    def event_timer_remove(self, timer):
        pass

    def progress_update(self, value):
        pass

    def progress_end(self):
        pass


def _background(op, obj, meddle, scene=None, **props):
    """Run ``op``'s background path by hand (invoke and modal never run
    headless): prepare on ``obj``, compute in a worker, ``meddle()`` as the
    artist would meanwhile, then the modal step that commits, with ``scene``
    shown then (None: the same). Returns ``(result, reports)``."""
    ops = mod("operators")
    cls = getattr(ops, f"MESHADJUST_OT_{op}")
    reports = []
    fake = SimpleNamespace(bl_label=cls.bl_label, _error=None, _cancel=False, _fraction=0.0,
                           _timer=None, report=lambda level, msg: reports.append((level, msg)),
                           **props)
    for name in ("finish", "_prepare", "_compute", "_commit", "_cage", "_cages", "give_back"):
        if hasattr(cls, name):
            setattr(fake, name, getattr(cls, name).__get__(fake))
    api = mod("api")
    if op == "simplify":
        fake._source_uid = obj.session_uid
        fake._job = api.prepare_simplify(obj, api.SimplifyParams(target_faces=60, levels=2))
        work = lambda: api.compute_simplify(fake._job)    # noqa: E731
    else:
        fake._cage_uid = obj.session_uid
        fake._job = fake._prepare(obj)
        work = lambda: fake._compute(fake._job)           # noqa: E731
    fake._thread = threading.Thread(target=work)
    fake._thread.start()
    fake._thread.join()
    meddle()
    fake._scene_uid = bpy.context.scene.session_uid
    scene = scene or bpy.context.scene
    layer = scene.view_layers[0]
    context = SimpleNamespace(window_manager=_WM(), scene=scene, screen=None, view_layer=layer,
                              selected_objects=[o for o in layer.objects if o.select_get()])
    return ops._Background.modal(fake, context, SimpleNamespace(type='TIMER')), reports


def _rotate_an_edge(cage):
    bm = bmesh.new()
    bm.from_mesh(cage.data)
    bm.edges.ensure_lookup_table()
    bmesh.ops.rotate_edges(bm, edges=[bm.edges[0]], use_ccw=False)
    bm.to_mesh(cage.data)
    bm.free()


def test_what_the_artist_changes_while_a_step_runs_is_followed_or_refused_by_name(bound):
    dense, cage = bound
    lift_top(cage)
    # renamed meanwhile: the commit follows the objects (a KeyError / AttributeError before)
    result, reports = _background("bind", cage, lambda: setattr(cage, "name", "Renamed"),
                                  levels=0, scheme='BOUND', keep_edit=True)
    assert result == {'FINISHED'} and "to 'Renamed'" in reports[0][1]
    other = make_object("other", *bumpy_sphere(2))
    result, _ = _background("simplify", other, lambda: setattr(other, "name", "Other"))
    assert result == {'FINISHED'} and bpy.data.objects["Other"].meshadjust.cage is not None
    # deleted, a result in Edit Mode, the cage's topology or the source changed meanwhile:
    # refused by name, nothing changed (tracebacks, or a binding of the old topology, before)
    edited = cage.meshadjust.edited

    def edit_mode(obj):
        activate(obj)
        bpy.ops.object.mode_set(mode='EDIT')

    cases = [("fit_cage", lambda: edit_mode(edited), "'dense_edited' is in Edit Mode"),
             ("bind", lambda: dense.data.vertices[0].co.__setitem__(2, 3.0),
              "'dense' changed while the step ran"),
             ("bind", lambda: _rotate_an_edge(cage), "'Renamed' changed topology while"),
             ("fit_cage", lambda: bpy.data.objects.remove(cage),
              "'Renamed' was deleted while Fit Cage ran")]
    for op, meddle, message in cases:
        before = []

        def meddle_then_look():
            meddle()
            before.append(full_snapshot())     # the scene as the artist left it

        props = dict(levels=0, scheme='BOUND', keep_edit=True) if op == "bind" else \
            dict(rebind=True)
        result, reports = _background(op, cage, meddle_then_look, **props)
        assert result == {'CANCELLED'} and message in reports[0][1], reports
        assert_all_unchanged(before[0])
        if edited.mode == 'EDIT':
            bpy.ops.object.mode_set(mode='OBJECT')
    # a source deleted while Simplify ran
    gone = make_object("gone", *bumpy_sphere(2))
    objects = set(bpy.data.objects) - {gone}
    result, reports = _background("simplify", gone, lambda: bpy.data.objects.remove(gone))
    assert result == {'CANCELLED'} and reports == [
        ({'ERROR'}, "'gone' was deleted while Simplify to Cage ran: nothing was changed")]
    assert set(bpy.data.objects) == objects


def test_a_refine_in_the_background_is_followed_or_refused_by_name(scene):
    """Refine runs in the background too (its first refined mesh at Auto
    levels binds the source at them): the artist's renames are followed,
    what would make its results wrong is refused, nothing changed; a
    cancelled Refine changes nothing either."""
    dense = make_object("dense", *bumpy_sphere(3))                # 1,280 faces
    assert simplify(20, fit=False, levels=0) == {'FINISHED'}      # bound at 2, refined at 3
    cage = dense.meshadjust.cage
    assert cage.meshadjust.levels == 2
    lift_top(cage)
    props = dict(output='BOTH', levels=0, scheme='BOUND')
    before = full_snapshot()
    api = mod("api")
    rj = api.compute_refine(api.prepare_refine(cage, output='BOTH'), progress=lambda f: f < 0.5)
    assert rj.cancelled and rj.refined is None
    with pytest.raises(mod("cage_steps").core.MeshAdjustError, match="cancelled"):
        api.commit_refine(cage, rj)
    assert_all_unchanged(before)
    edited = cage.meshadjust.edited

    def edit_mode(obj):
        activate(obj)
        bpy.ops.object.mode_set(mode='EDIT')

    result, reports = _background("refine", cage, lambda: setattr(cage, "name", "Renamed"),
                                  **props)
    assert result == {'FINISHED'} and "loop x3, about the source's 1,280" in reports[0][1]
    cases = [(lambda: edit_mode(edited), "'dense_edited' is in Edit Mode"),
             (lambda: _rotate_an_edge(cage), "'Renamed' changed topology while")]
    for meddle, message in cases:
        before = []

        def meddle_then_look():
            meddle()
            before.append(full_snapshot())     # the scene as the artist left it

        result, reports = _background("refine", cage, meddle_then_look, **props)
        assert result == {'CANCELLED'} and message in reports[0][1], reports
        assert_all_unchanged(before[0])
        if edited.mode == 'EDIT':
            bpy.ops.object.mode_set(mode='OBJECT')


def test_a_simplify_ending_with_its_collection_excluded_and_another_scene_shown(scene):
    part = bpy.data.collections.new("Part")
    scene.collection.children.link(part)
    obj = make_object("part", *bumpy_sphere(2))
    scene.collection.objects.unlink(obj)
    part.objects.link(obj)
    scene.meshadjust.running = True                 # (as the step's start set it)
    other = bpy.data.scenes.new("Other")

    def exclude():
        bpy.context.view_layer.layer_collection.children["Part"].exclude = True

    result, reports = _background("simplify", obj, exclude, scene=other)
    assert result == {'FINISHED'}, reports          # a traceback selecting the cage before
    assert obj.meshadjust.cage.users_collection == (part,)
    assert not scene.meshadjust.running             # its bar stayed on for good before


def test_edit_cage_brings_back_a_deleted_or_disabled_cage_and_names_an_excluded_one(bound):
    dense, cage = bound
    edited = cage.meshadjust.edited
    activate(cage)
    bpy.ops.object.delete()          # MeshAdjust's links keep it, in no collection
    assert cage.name in bpy.data.objects and not cage.users_collection
    activate(edited)
    assert bpy.ops.meshadjust.edit_cage() == {'FINISHED'}     # a traceback before
    assert bpy.context.active_object == cage and cage.mode == 'EDIT'
    assert cage.users_collection == dense.users_collection
    bpy.ops.object.mode_set(mode='OBJECT')
    cage.hide_viewport = True        # disabled in viewports: Blender cannot edit it
    activate(edited)
    assert bpy.ops.meshadjust.edit_cage() == {'FINISHED'}     # a traceback before
    assert cage.mode == 'EDIT' and not cage.hide_viewport
    bpy.ops.object.mode_set(mode='OBJECT')
    hidden = bpy.data.collections.new("Hidden")
    bpy.context.scene.collection.children.link(hidden)
    for col in list(cage.users_collection):
        col.objects.unlink(cage)
    hidden.objects.link(cage)
    bpy.context.view_layer.layer_collection.children["Hidden"].exclude = True
    activate(edited)
    with pytest.raises(RuntimeError, match="'dense_cage' is not in this view layer"):
        bpy.ops.meshadjust.edit_cage()


def test_a_new_cage_never_writes_over_the_shape_key_of_a_cage_deleted_for_good(bound):
    dense, cage = bound
    lift_top(cage)
    activate(cage)
    assert bpy.ops.meshadjust.refine(output='SHAPE_KEY') == {'FINISHED'}
    kept = mod("mesh_io").read_key(dense.data.shape_keys.key_blocks["dense_cage"])
    bpy.ops.object.delete(use_global=True)          # Delete Globally: its name is free
    activate(dense)
    assert simplify(60, fit=False) == {'FINISHED'}
    new = dense.meshadjust.cage
    assert new.name == "dense_cage"
    lift_top(new, -0.2)
    assert bpy.ops.meshadjust.refine(output='SHAPE_KEY') == {'FINISHED'}
    keys = dense.data.shape_keys.key_blocks
    assert [kb.name for kb in keys] == ["Basis", "dense_cage", "dense_cage.001"]
    assert np.array_equal(mod("mesh_io").read_key(keys["dense_cage"]), kept)   # overwritten before
    assert new.meshadjust.key_name == "dense_cage.001"


def test_the_artists_own_key_named_like_the_cage_is_never_written_over(scene):
    """A key the artist made, named as the cage will be, before any cage: the
    cage's first shape-key Refine makes a key of its own beside it and says
    so (it took the artist's key over and rewrote it)."""
    obj = make_object("dense", *bumpy_sphere(3))
    obj.shape_key_add(name="Basis")
    mine = obj.shape_key_add(name="dense_cage", from_mix=False)
    co = mod("mesh_io").read_key(mine).reshape(-1, 3)
    co[:, 0] *= 1.5
    mine.data.foreach_set("co", co.ravel())
    mine.value = 0.0
    before = mod("mesh_io").read_key(mine)
    activate(obj)
    assert simplify(60, fit=False) == {'FINISHED'}
    cage = obj.meshadjust.cage
    assert cage.name == "dense_cage"
    lift_top(cage)
    activate(cage)
    assert bpy.ops.meshadjust.refine(output='SHAPE_KEY') == {'FINISHED'}
    keys = obj.data.shape_keys.key_blocks
    assert [kb.name for kb in keys] == ["Basis", "dense_cage", "dense_cage.001"]
    assert np.array_equal(mod("mesh_io").read_key(keys["dense_cage"]), before)
    assert keys["dense_cage"].value == 0.0
    assert cage.meshadjust.key_name == "dense_cage.001"
    assert "did not write is kept" in cage.meshadjust.last_report


def _keyed_sphere(name="keyed"):
    """A sphere with a Basis and a key 'Squash' (z halved)."""
    obj = make_object(name, *bumpy_sphere(3))
    obj.shape_key_add(name="Basis")
    key = obj.shape_key_add(name="Squash")
    co = mod("mesh_io").read_key(key).reshape(-1, 3)
    co[:, 2] *= 0.5
    key.data.foreach_set("co", co.ravel())
    return obj, key


def test_a_key_limited_to_a_group_or_absolute_keys_changed_after_the_bind_are_stale(scene):
    def warnings(cage):
        bpy.context.view_layer.update()             # (the panel asks after Blender's update)
        return mod("operators").binding_warnings(cage)

    obj, key = _keyed_sphere()
    key.value = 1.0
    group = obj.vertex_groups.new(name="top")
    group.add([v.index for v in obj.data.vertices if v.co.z > 0], 1.0, 'REPLACE')
    activate(obj)
    assert simplify(60, fit=False) == {'FINISHED'}
    cage = obj.meshadjust.cage
    assert warnings(cage) == []
    key.vertex_group = "top"                        # the source now shows half of the key
    assert warnings(cage) == ["'keyed' changed since it was bound: its shape keys changed"]
    key.vertex_group = ""
    assert warnings(cage) == []
    obj.data.shape_keys.use_relative = False        # absolute keys: the time picks the shape
    assert warnings(cage) == ["'keyed' changed since it was bound: its shape keys changed"]
    activate(cage)
    assert bpy.ops.meshadjust.bind() == {'FINISHED'}
    assert warnings(cage) == []
    obj.data.shape_keys.eval_time = 10.0            # now showing 'Squash'
    assert warnings(cage) == ["'keyed' changed since it was bound: its shape keys changed"]


def test_a_key_pinned_to_show_alone_is_read_as_shown_and_unpinning_it_is_stale(scene):
    obj, key = _keyed_sphere()
    key.value = 0.0
    obj.active_shape_key_index = 1
    obj.show_only_shape_key = True                  # the pin: 'Squash' shown alone, at full
    activate(obj)
    assert simplify(60, fit=False) == {'FINISHED'}
    cage = obj.meshadjust.cage
    z = mod("mesh_io").read_positions(cage.meshadjust.edited.data)[:, 2]
    assert np.ptp(z) < 1.1              # what is shown was bound (the Basis, 2 high, before)
    assert mod("operators").binding_warnings(cage) == []
    obj.show_only_shape_key = False
    bpy.context.view_layer.update()
    assert mod("operators").binding_warnings(cage) == [
        "'keyed' changed since it was bound: its shape keys changed"]


def test_the_shape_key_output_is_refused_on_absolute_keys_and_they_are_read_as_shown(scene):
    obj, key = _keyed_sphere()
    key.value = 0.0                                 # (a value says nothing about absolute keys)
    obj.data.shape_keys.use_relative = False
    obj.data.shape_keys.eval_time = 10.0            # shows 'Squash'
    activate(obj)
    assert simplify(60, fit=False) == {'FINISHED'}
    cage = obj.meshadjust.cage
    z = mod("mesh_io").read_positions(cage.meshadjust.edited.data)[:, 2]
    assert np.ptp(z) < 1.1              # what is shown was bound (the Basis, 2 high, before)
    lift_top(cage)
    before = full_snapshot()
    with pytest.raises(RuntimeError, match="'keyed' has absolute shape keys \\(Relative off\\)"):
        bpy.ops.meshadjust.refine(output='SHAPE_KEY')   # "updated" and nothing shown, before
    assert_all_unchanged(before)
    assert bpy.ops.meshadjust.refine(output='EDITED') == {'FINISHED'}


def test_subdivide_in_place_refuses_modifiers_and_keys_and_keeps_the_materials(scene):
    V, F = bumpy_sphere(2)
    obj = make_object("mirrored", V + [2.0, 0.0, 0.0], F)
    obj.modifiers.new("Mirror", 'MIRROR')
    before = full_snapshot()
    with pytest.raises(RuntimeError, match="'mirrored' has modifiers or shape keys: in place"):
        bpy.ops.meshadjust.subdivide(levels=1, in_place=True)    # the mirror applied twice before
    assert_all_unchanged(before)
    assert bpy.ops.meshadjust.subdivide(levels=1, in_place=False) == {'FINISHED'}
    bpy.ops.mesh.primitive_cylinder_add(vertices=8, end_fill_type='NGON')
    cyl = bpy.context.active_object
    mats = [bpy.data.materials.new(f"M{i}") for i in range(3)]
    for mat in mats:
        cyl.data.materials.append(mat)
    index = np.arange(len(cyl.data.polygons), dtype=np.int32) % 3
    cyl.data.polygons.foreach_set("material_index", index)
    tri_poly = mod("mesh_io").triangle_polygons(cyl.data)
    assert bpy.ops.meshadjust.subdivide(levels=2, scheme='loop', in_place=True) == {'FINISHED'}
    assert list(cyl.data.materials) == mats                      # all lost before
    fine = np.empty(len(cyl.data.polygons), np.int32)
    cyl.data.polygons.foreach_get("material_index", fine)
    assert np.array_equal(fine, np.repeat(index[tri_poly], 16))  # each face its polygon's


class _Interactive:
    """``bpy`` as the operators see it in a window (``app.background`` False)."""

    def __init__(self, real):
        self._real = real
        self.app = SimpleNamespace(background=False)

    def __getattr__(self, name):
        return getattr(self._real, name)


def test_a_fit_from_edit_mode_refused_before_it_starts_gives_edit_mode_back(bound, monkeypatch):
    dense, cage = bound
    dense.scale = (1.0, 1.0, 0.0)                         # refused by the fit's preparation
    bpy.context.view_layer.update()
    activate(cage)
    bpy.ops.object.mode_set(mode='EDIT')
    ops = mod("operators")
    monkeypatch.setattr(ops, "bpy", _Interactive(bpy))    # invoke() runs only in a window
    cls = ops.MESHADJUST_OT_fit_cage
    reports = []
    fake = SimpleNamespace(rebind=True, bl_label=cls.bl_label,
                           report=lambda level, msg: reports.append((level, msg)))
    for name in ("_prepare", "_cages", "give_back"):
        setattr(fake, name, getattr(cls, name).__get__(fake))
    assert cls.invoke(fake, bpy.context, SimpleNamespace(type='LEFTMOUSE')) == {'CANCELLED'}
    assert "'dense' has a zero scale" in reports[0][1]
    assert cage.mode == 'EDIT'                            # left in Object Mode before


def test_a_bind_refused_for_its_shape_key_says_how_to_bind_not_to_re_bind(bound):
    dense, cage = bound
    lift_top(cage)
    activate(cage)
    assert bpy.ops.meshadjust.refine(output='SHAPE_KEY') == {'FINISHED'}
    dense.modifiers.new("more", 'SUBSURF')              # its evaluated mesh has more vertices
    for op in (bpy.ops.meshadjust.bind, bpy.ops.meshadjust.fit_cage):
        with pytest.raises(RuntimeError) as caught:
            op()
        text = str(caught.value)        # ("... or re-bind", from inside a refused bind, before)
        assert "to bind, delete that shape key or those modifiers first" in text
        assert "re-bind" not in text and "were bound" not in text


def test_a_bind_made_while_a_refine_ran_is_kept_and_the_refine_refused(scene):
    """The artist sculpts the source and binds again while a Refine runs in the
    background: the Refine had written its result from the binding before
    over the new one (the sculpt gone, reported as done). Now refused, the
    new bind's result kept; with source vertices deleted it had failed with
    an internal count mismatch."""
    dense = make_object("dense", *bumpy_sphere(3))
    assert simplify(60, fit=False) == {'FINISHED'}
    cage = dense.meshadjust.cage
    lift_top(cage)
    edited = cage.meshadjust.edited
    kept = []

    def sculpt_and_bind():
        V = pos(dense) + [0.0, 0.0, 0.5]
        mod("mesh_io").write_positions(dense.data, V)
        dense.data.update()
        activate(cage)
        assert bpy.ops.meshadjust.bind(keep_edit=True) == {'FINISHED'}
        kept.append(full_snapshot())

    result, reports = _background("refine", cage, sculpt_and_bind, output='EDITED', levels=0,
                                  scheme='BOUND')
    assert result == {'CANCELLED'}
    assert reports[0][1] == ("'dense_edited' was bound again while Refine ran: nothing was "
                             "changed; run Refine again")
    assert_all_unchanged(kept[0])
    assert pos(edited)[:, 2].mean() > 0.4           # the sculpt, carried by the new binding


def _assert_live_followed(cage, edited, before):
    """The live update just run moved ``edited`` from ``before`` to what a
    Refine of ``cage`` gives; live turned off again."""
    after = pos(edited).copy()
    activate(cage)
    assert bpy.ops.meshadjust.refine(output='EDITED') == {'FINISHED'}
    assert np.abs(after - before).max() > 0.05 and np.abs(pos(edited) - after).max() < 1e-6
    cage.meshadjust.live = False


def test_live_turned_on_follows_the_edit_made_while_it_was_off(bound):
    """An edit made with Live off stayed unapplied when Live was turned on,
    until the next edit: turning it on schedules an update."""
    dense, cage = bound
    live = mod("live")
    edited = cage.meshadjust.edited
    lift_top(cage, 0.3)
    cage.data.update()
    before = pos(edited).copy()
    cage.meshadjust.live = True
    assert cage.name in live._pending
    live.refine_pending()
    _assert_live_followed(cage, edited, before)


def test_subdivide_in_place_refuses_a_mesh_shared_by_linked_duplicates(scene):
    """Only the active object got the new mesh: its Alt+D copy kept the old
    one, no longer linked, in silence."""
    rock = make_object("Rock", *bumpy_sphere(2))
    twin = bpy.data.objects.new("Rock.001", rock.data)
    bpy.context.scene.collection.objects.link(twin)
    activate(rock)
    before = full_snapshot()
    with pytest.raises(RuntimeError, match=r"'Rock' shares its mesh with 'Rock\.001': in place "
                                           r"would leave them the old one, no longer linked; "
                                           r"make it single-user first"):
        bpy.ops.meshadjust.subdivide(levels=1, in_place=True)
    assert_all_unchanged(before)
    assert bpy.ops.meshadjust.subdivide(levels=1, in_place=False) == {'FINISHED'}
    assert twin.data == rock.data


def _rigged(name, angle_deg):
    """A bumpy sphere ``name`` deformed by an Armature whose one bone is
    turned by ``angle_deg`` about x, simplified to a bound 60-face cage with
    its top lifted: the cage."""
    from math import radians
    body = make_object(name, *bumpy_sphere(3))
    rig = bpy.data.objects.new(name + "_rig", bpy.data.armatures.new(name + "_rig"))
    bpy.context.scene.collection.objects.link(rig)
    activate(rig)
    bpy.ops.object.mode_set(mode='EDIT')
    bone = rig.data.edit_bones.new("bone")
    bone.head, bone.tail = (0, 0, -1), (0, 0, 1)
    bpy.ops.object.mode_set(mode='OBJECT')
    body.vertex_groups.new(name="bone").add(list(range(len(body.data.vertices))), 1.0,
                                            'REPLACE')
    body.modifiers.new("Armature", 'ARMATURE').object = rig
    pose = rig.pose.bones["bone"]
    pose.rotation_mode = 'XYZ'
    pose.rotation_euler = (radians(angle_deg), 0, 0)
    activate(body)
    assert simplify(60, fit=False) == {'FINISHED'}
    cage = body.meshadjust.cage
    lift_top(cage)
    activate(cage)
    return cage


def test_a_shape_key_through_a_posed_armature_says_it_misses_the_edit(scene):
    """A key is applied before the modifiers, so on a posed rig the edit of
    the cage, lifted up, showed sideways in the source with the key, reported
    as done. Now a warning naming the Armature and how far off it is; at the
    rest pose the key shows the edit, and nothing is said."""
    report = mod("api").refine_object(_rigged("rest", 0.0), output='SHAPE_KEY')
    assert report.level == 'INFO', report.message
    report = mod("api").refine_object(_rigged("posed", 90.0), output='SHAPE_KEY')
    assert report.level == 'WARNING'
    assert "'posed' shows its shape key through its modifiers (Armature), which Blender " \
           "applies after it" in report.message


def test_messages_for_a_deleted_source_and_an_empty(bound):
    """A source deleted with X (Blender keeps it while a cage points to it)
    with a modifier was "disabled in the viewport: enable it", which the
    artist cannot; an Empty was "a empty"."""
    dense, cage = bound
    dense.modifiers.new("Smooth", 'SMOOTH')
    activate(dense)
    bpy.ops.object.delete()
    activate(cage)
    with pytest.raises(RuntimeError, match=r"'dense' was deleted from the scene \(Blender keeps "
                                           r"it while MeshAdjust points to it\)"):
        bpy.ops.meshadjust.bind()
    empty = bpy.data.objects.new("Empty", None)
    bpy.context.scene.collection.objects.link(empty)
    activate(empty)
    assert mod("operators").simplify_unavailable(bpy.context) == \
        "'Empty' is an empty, not a mesh"


def test_a_live_update_pending_when_the_cage_is_renamed_still_runs(bound):
    """The pending update was found by the cage's name: renamed before the
    timer ran, the edit followed only at the next one."""
    dense, cage = bound
    live = mod("live")
    edited = cage.meshadjust.edited
    cage.meshadjust.live = True
    live.refine_pending()
    before = pos(edited).copy()
    lift_top(cage, 0.3)
    cage.data.update()
    live.schedule(cage)
    cage.name = "Renamed cage"
    live.refine_pending()
    _assert_live_followed(cage, edited, before)


def _split_edges(cage, edges, cuts):
    """Subdivide ``edges`` (indices) of the cage's mesh with ``cuts`` each, as
    Edit Mode's Subdivide does: the faces beside them get more corners."""
    bm = bmesh.new()
    bm.from_mesh(cage.data)
    bm.edges.ensure_lookup_table()
    bmesh.ops.subdivide_edges(bm, edges=[bm.edges[i] for i in edges], cuts=cuts,
                              use_grid_fill=False)
    bm.to_mesh(cage.data)
    bm.free()
    cage.data.update()


def _corners(mesh):
    return sorted({len(p.vertices) for p in mesh.polygons})


def test_a_cage_given_quads_is_triangulated_by_bind_and_fit(bound, monkeypatch):
    """Subdivide on cage edges (or a Grid Fill, a Knife cut) leaves faces of
    four or more corners, which Blender splits along the diagonal their shape
    favours: a quad with a straight corner split through it had a face of no
    area and an edge of three faces, Fit was rolled back every time as
    'changed topology while the step ran', Refine called a moved corner a new
    topology; then each step refused them, asking for Ctrl+T. Bind and Fit
    now triangulate them (Face > Triangulate Faces, Beauty) and say so; the
    cage keeps its vertices, their order, its rest shape and its mesh's name;
    a failed bind gives the faces back as they were; in Edit Mode (the mesh
    cannot be swapped there) and for Refine they are named with what to do."""
    dense, cage = bound
    name = cage.data.name
    _split_edges(cage, [0, 40], cuts=2)             # two pentagons, two more beside them
    assert _corners(cage.data) == [3, 5]
    n_v, V0 = len(cage.data.vertices), pos(cage)
    before = full_snapshot()
    activate(cage)
    bpy.ops.object.mode_set(mode='EDIT')
    with pytest.raises(RuntimeError, match=r"'dense_cage' has 4 faces of more than three corners "
                                           r".*; leave Edit Mode and Bind again, which "
                                           r"triangulates them, or .* Ctrl\+T"):
        bpy.ops.meshadjust.bind(keep_edit=False)
    bpy.ops.object.mode_set(mode='OBJECT')
    assert_all_unchanged(before)
    with pytest.raises(RuntimeError, match="'dense_cage' changed topology since it was bound"):
        bpy.ops.meshadjust.refine()                      # (its poll: then Bind says why)
    monkeypatch.setattr(mod("api").core, "bind", _fail)
    with pytest.raises(RuntimeError, match="no bind today"):
        bpy.ops.meshadjust.bind(keep_edit=False)
    assert_all_unchanged(before)                    # its pentagons given back
    assert _corners(cage.data) == [3, 5]
    monkeypatch.undo()
    assert bpy.ops.meshadjust.bind(keep_edit=False) == {'FINISHED'}
    assert ("triangulated 4 faces of more than three corners of 'dense_cage' (a cage is "
            "triangles)") in cage.meshadjust.last_report
    assert _corners(cage.data) == [3] and cage.data.name == name
    assert len(cage.data.vertices) == n_v and np.array_equal(pos(cage), V0)
    assert name + ".001" not in bpy.data.meshes
    F = mod("mesh_io").read_triangles(cage.data)[0]
    binding = mod("store").load_binding(cage.meshadjust.edited, cage)
    assert np.array_equal(binding.F_cage, F)
    np.testing.assert_allclose(mod("store").load_rest(cage), V0, atol=1e-6)  # (both at identity)
    lift_top(cage)
    assert bpy.ops.meshadjust.refine() == {'FINISHED'}
    _split_edges(cage, [7], cuts=1)                 # two quads, on an edited cage
    assert _corners(cage.data) == [3, 4]
    assert bpy.ops.meshadjust.fit_cage() == {'FINISHED'}
    assert "triangulated 2 faces of more than three corners" in cage.meshadjust.last_report
    assert _corners(cage.data) == [3]
    assert bpy.ops.meshadjust.refine() == {'FINISHED'}


def _fail(*args, **kwargs):
    raise RuntimeError("no bind today")


@pytest.mark.parametrize("kind, domain", [('FLOAT', 'POINT'), ('FLOAT_VECTOR', 'FACE')])
def test_a_converted_rest_shape_is_no_rest_shape_and_a_converted_binding_is_named(bound, kind,
                                                                                   domain):
    """Convert Attribute (the Attributes panel) on the cage's rest shape made
    Fit and Bind fail with a Python traceback (a FLOAT attribute has no
    vectors to read; on faces, 'internal error setting the array'). It is
    read as no rest shape, as a removed one is: the steps bind the cage as it
    is. The edited original's binding attributes converted are named, with
    what to do."""
    dense, cage = bound
    me = cage.data
    me.attributes.remove(me.attributes["meshadjust_rest"])
    me.attributes.new("meshadjust_rest", kind, domain)
    activate(cage)
    assert bpy.ops.meshadjust.fit_cage() == {'FINISHED'}
    rest = me.attributes["meshadjust_rest"]
    assert rest.domain == 'POINT' and rest.data_type == 'FLOAT_VECTOR'
    edited = cage.meshadjust.edited
    offset = edited.data.attributes["meshadjust_offset"]
    edited.data.attributes.remove(offset)
    edited.data.attributes.new("meshadjust_offset", kind, domain)
    mod("store")._cache.clear()                          # (as after a reload)
    before = full_snapshot()
    with pytest.raises(RuntimeError, match="its attribute 'meshadjust_offset' is .* not the "
                                           "FLOAT_VECTOR per vertex MeshAdjust wrote"):
        bpy.ops.meshadjust.refine()
    assert_all_unchanged(before)
    assert bpy.ops.meshadjust.bind() == {'FINISHED'}
    assert bpy.ops.meshadjust.refine() == {'FINISHED'}


def test_faces_are_counted_on_what_the_object_shows(scene):
    """A Mask modifier on an empty vertex group shows no face: Subdivide said
    '0 -> 0 faces' and made an empty object; an edge profile with a Screw
    modifier shows a lathed surface: Subdivide and Simplify's poll said it
    had no faces. Both are read as shown."""
    from tests.mesh_factory import icosphere
    V, F = icosphere(2)
    masked = make_object("masked", V, F)
    masked.vertex_groups.new(name="nothing")
    mask = masked.modifiers.new("mask", 'MASK')
    mask.vertex_group = "nothing"
    before = full_snapshot()
    with pytest.raises(RuntimeError, match="'masked' shows no faces \\(its modifiers leave none\\)"):
        bpy.ops.meshadjust.subdivide(levels=1)
    assert_all_unchanged(before)
    mesh = bpy.data.meshes.new("profile")
    mesh.from_pydata([(0.5, 0, -0.5), (0.8, 0, 0), (0.5, 0, 0.5)], [(0, 1), (1, 2)], [])
    lathe = bpy.data.objects.new("lathe", mesh)
    scene.collection.objects.link(lathe)
    lathe.modifiers.new("screw", 'SCREW').steps = 32
    activate(lathe)
    assert bpy.ops.meshadjust.simplify.poll()
    assert bpy.ops.meshadjust.subdivide(levels=1) == {'FINISHED'}
    made = bpy.data.objects["lathe_butterfly1"]
    assert len(made.data.polygons) == 4 * 2 * 2 * 32        # the 64 quads split, times 4
    activate(lathe)
    assert bpy.ops.meshadjust.simplify(target_faces=40, fit=False, bind=False) == {'FINISHED'}
    assert len(lathe.meshadjust.cage.data.polygons) <= 40


def test_other_shape_keys_shown_with_the_edit_are_said(bound):
    """The artist's own key made relative to MeshAdjust's, at 0.5, took half
    of the edit back in what the source shows, and Refine's shape key said
    it was updated: a warning names the key and how far off the source is;
    at 0 nothing is said."""
    dense, cage = bound
    api = mod("api")
    assert api.refine_object(cage, output='SHAPE_KEY').level == 'INFO'
    keys = dense.data.shape_keys
    smile = dense.shape_key_add(name="Smile", from_mix=False)
    smile.relative_key = keys.key_blocks[cage.meshadjust.key_name]
    smile.value = 0.0
    activate(cage)
    assert bpy.ops.meshadjust.bind() == {'FINISHED'}      # (a new key: the source changed)
    lift_top(cage)
    report = api.refine_object(cage, output='SHAPE_KEY')
    assert report.level == 'INFO', report.message
    smile.value = 0.5
    lift_top(cage)
    report = api.refine_object(cage, output='SHAPE_KEY')
    assert report.level == 'WARNING'
    assert "'dense' shows other shape keys with the edit ('Smile'): up to" in report.message


def test_a_target_above_the_input_count_is_a_warning_not_done(scene):
    """A 320-face sphere asked for 1,000 faces came back '320 -> 320 faces'
    as done: the cage is the input, and the report says so as a warning."""
    from tests.mesh_factory import icosphere
    sphere = make_object("sphere", *icosphere(2))
    cage, report = mod("api").simplify_object(sphere, target_faces=1000, fit=False, bind=False)
    assert len(cage.data.polygons) == 320 and report.level == 'WARNING'
    assert "320 faces (of 1,000 asked: the input has no more, nothing to collapse)" in \
        report.message


def test_a_cage_edited_into_no_surface_is_named_by_the_add_on_not_the_core(bound):
    """Every cage face deleted, or a fin added on a cage edge: Fit and Bind
    said 'fit_cage: F_cage has no faces' and 'bind: the cage (F_cage): 1
    non-manifold edges', the core's argument names. They name the cage and
    what is wrong with it, and leave the scene as it was."""
    dense, cage = bound
    bm = bmesh.new()
    bm.from_mesh(cage.data)
    bm.edges.ensure_lookup_table()
    edge = bm.edges[0]
    tip = bm.verts.new((edge.verts[0].co + edge.verts[1].co) / 2 + edge.link_faces[0].normal)
    bm.faces.new((edge.verts[0], edge.verts[1], tip))
    bm.to_mesh(cage.data)
    bm.free()
    activate(cage)
    before = full_snapshot()
    for op in (bpy.ops.meshadjust.bind, bpy.ops.meshadjust.fit_cage):
        with pytest.raises(RuntimeError, match="'dense_cage' has 1 edge of more than two faces, "
                                               "2 vertices where separate fans of faces meet "
                                               r"\(made in Edit Mode\): a cage must be a clean"):
            op(keep_edit=False) if op == bpy.ops.meshadjust.bind else op()
        assert_all_unchanged(before)
    bm = bmesh.new()
    bm.from_mesh(cage.data)
    bmesh.ops.delete(bm, geom=bm.faces[:], context='FACES_ONLY')
    bm.to_mesh(cage.data)
    bm.free()
    before = full_snapshot()
    with pytest.raises(RuntimeError, match="'dense_cage' has no faces left: undo the edit"):
        bpy.ops.meshadjust.bind(keep_edit=False)
    assert_all_unchanged(before)
