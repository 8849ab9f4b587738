"""Nothing lost silently: Fit and Re-bind keep the artist's edit, failed or
cancelled steps leave every object and mesh as it was, stale bindings are
detected and say what changed, no orphan data-blocks."""

import sys

import bmesh
import bpy
import numpy as np
import pytest

from tests.addon.conftest import MODULE, make_object
from tests.addon.test_operators import bumpy_sphere, delete_cage_vertex, lift_in_edit_mode, simplify


def mod(name):
    return sys.modules[MODULE + ".meshadjust_addon." + name]


def pos(obj):
    return mod("mesh_io").read_positions(obj.data)


def scene_snapshot():
    """Every object's and mesh's name, every mesh's positions and shape keys."""
    meshes = {}
    for m in bpy.data.meshes:
        keys = () if m.shape_keys is None else tuple(
            (kb.name, kb.value) for kb in m.shape_keys.key_blocks)
        meshes[m.name] = (mod("mesh_io").read_positions(m), keys)
    objects = {o.name: (o.data.name if o.data is not None else None) for o in bpy.data.objects}
    return objects, meshes


def assert_unchanged(before):
    objects, meshes = scene_snapshot()
    assert objects == before[0]
    assert set(meshes) == set(before[1])
    for name, (V, keys) in before[1].items():
        assert np.array_equal(meshes[name][0], V), f"{name} moved"
        assert meshes[name][1] == keys, f"{name}'s shape keys changed"


def orphans():
    return [m.name for m in bpy.data.meshes if m.users == 0] + \
        [m.name for m in bpy.data.meshes if m.name.endswith(".001")]


def bound_sphere(level=4, faces=300):
    """A bumpy sphere 'dense' simplified to a bound (unfitted) cage of ``faces``:
    ``(dense, cage)``."""
    dense = make_object("dense", *bumpy_sphere(level))
    assert simplify(faces, fit=False) == {'FINISHED'}
    return dense, dense.meshadjust.cage


@pytest.fixture()
def bound(scene):
    return bound_sphere()


def delete_a_face(obj):
    """Delete the first face of ``obj``'s mesh (as an artist would, through a BMesh)."""
    bm = bmesh.new()
    bm.from_mesh(obj.data)
    bm.faces.ensure_lookup_table()
    bmesh.ops.delete(bm, geom=[bm.faces[0]], context='FACES_ONLY')
    bm.to_mesh(obj.data)
    bm.free()


def lift_top(cage, dz=0.2):
    V = pos(cage)
    top = int(np.argmax(V[:, 2]))
    V[top, 2] += dz
    mod("mesh_io").write_positions(cage.data, V)
    return top


def test_fit_on_an_edited_cage_fits_the_rest_shape_and_keeps_the_edit(bound):
    dense, cage = bound
    store = mod("store")
    rest0 = store.load_rest(cage)
    top = lift_top(cage)
    assert bpy.ops.meshadjust.fit_cage() == {'FINISHED'}
    rest1 = store.load_rest(cage)
    assert np.abs(rest1 - rest0).max() > 1e-4                    # the rest shape was fitted
    offset = pos(cage) - rest1
    assert offset[top, 2] == pytest.approx(0.2, abs=1e-5)        # edited = fitted rest + edit
    offset[top] = 0
    assert np.abs(offset).max() < 1e-5
    edited = cage.meshadjust.edited
    lifted = pos(edited)[:, 2] - pos(dense)[:, 2]
    assert lifted.max() > 0.05                                  # the edited original kept it
    # and it is exactly what a refine of the cage as it is gives
    before = pos(edited)
    assert bpy.ops.meshadjust.refine(output='EDITED') == {'FINISHED'}
    assert np.abs(pos(edited) - before).max() < 1e-6
    # unedited cage: refining the fitted rest gives the source back
    mod("mesh_io").write_positions(cage.data, rest1)
    bpy.ops.meshadjust.refine(output='EDITED')
    assert np.abs(pos(edited) - pos(dense)).max() < 1e-5
    assert orphans() == []


def test_rebind_keeps_the_edit_unless_asked(bound):
    dense, cage = bound
    lift_top(cage)
    bpy.ops.meshadjust.refine(output='EDITED')
    edited = cage.meshadjust.edited
    with_edit = pos(edited)
    assert bpy.ops.meshadjust.bind() == {'FINISHED'}
    assert np.abs(pos(edited) - with_edit).max() < 1e-5
    assert bpy.ops.meshadjust.bind(keep_edit=False) == {'FINISHED'}   # current shape = new rest
    assert np.abs(pos(edited) - pos(dense)).max() < 1e-5
    assert np.allclose(mod("store").load_rest(cage), pos(cage), atol=1e-6)
    assert orphans() == []


def test_rebind_after_a_topology_change_keeps_the_edit(bound):
    dense, cage = bound
    top = lift_top(cage, 0.3)
    far = int(np.argmin(pos(cage)[:, 2]))          # delete a vertex away from the edit
    delete_cage_vertex(cage, far)
    assert bpy.ops.meshadjust.bind() == {'FINISHED'}
    assert pos(cage.meshadjust.edited)[:, 2].max() > pos(dense)[:, 2].max() + 0.05
    assert top != far


def _boom(*args, **kwargs):
    core = sys.modules[MODULE + ".core"]
    raise core.MeshAdjustError("boom: a core failure")


@pytest.mark.parametrize("step", ["fit", "bind", "refine_rebind", "refine_deform"])
def test_a_failed_step_leaves_every_object_and_mesh_as_it_was(bound, monkeypatch, step):
    dense, cage = bound
    lift_top(cage)
    bpy.ops.meshadjust.refine(output='BOTH')
    before = scene_snapshot()
    core = sys.modules[MODULE + ".core"]
    if step == "refine_deform":
        monkeypatch.setattr(core, "refine", _boom)     # (computed before any write since 2026-12-05)
    else:
        monkeypatch.setattr(core, "bind", _boom)
    with pytest.raises(RuntimeError, match="boom"):
        if step == "fit":
            bpy.ops.meshadjust.fit_cage()
        elif step == "bind":
            bpy.ops.meshadjust.bind(levels=1)
        elif step == "refine_rebind":
            bpy.ops.meshadjust.refine(output='BOTH', levels=1)
        else:
            bpy.ops.meshadjust.refine(output='BOTH')
    assert_unchanged(before)
    assert (cage.meshadjust.levels, cage.meshadjust.scheme) == (2, 'loop')


@pytest.mark.parametrize("step", ["fit", "bind"])
def test_a_cancelled_step_leaves_every_object_and_mesh_as_it_was(bound, step):
    dense, cage = bound
    api = mod("api")
    lift_top(cage)
    before = scene_snapshot()
    stop = lambda f: False   # noqa: E731  (Esc at the first progress call)
    if step == "fit":
        job = api.compute_fit(api.prepare_fit(cage), progress=stop)
    else:
        job = api.compute_bind(api.prepare_cage_job(cage, levels=1), progress=stop)
    assert job.cancelled
    assert_unchanged(before)


def test_simplify_keeps_the_cage_when_the_bind_fails_and_warns(scene, monkeypatch):
    V, F = bumpy_sphere(3)
    make_object("dense", V, F)
    core = sys.modules[MODULE + ".core"]
    monkeypatch.setattr(core, "bind", _boom)
    assert simplify(200) == {'FINISHED'}            # a warning, not a cancel
    dense = bpy.data.objects["dense"]
    cage = dense.meshadjust.cage
    assert cage is not None and cage.meshadjust.edited is None
    rep = cage.meshadjust.last_report
    assert "WARNING" in rep and "binding 'dense' to 'dense_cage' failed" in rep
    assert "kept" in rep and "fitted" in rep        # the fit was done and is kept


def test_esc_inside_the_bind_of_simplify_cancels_it_and_changes_nothing(scene):
    # Simplify (+ fit + bind, the panel's defaults): the bind reports from inside its
    # searches (93-99% of the bar); Esc there stops it and nothing is created
    V, F = bumpy_sphere(3)
    dense = make_object("dense", V, F)
    api = mod("api")
    before = scene_snapshot()
    seen = []

    def stop_in_bind(f):
        seen.append(f)
        return not (0.93 < f < 0.99)
    job = api.prepare_simplify(dense, api.SimplifyParams(target_faces=200))
    api.compute_simplify(job, progress=stop_in_bind)
    assert job.cancelled and job.binding is None and not job.bind_error
    assert job.fit is not None                      # it got that far
    assert any(0.93 < f < 0.99 for f in seen)
    assert_unchanged(before)


def test_non_manifold_failures_name_the_object_and_the_cause(addon):
    api = mod("api")
    core = sys.modules[MODULE + ".core"]
    exc = core.InvalidMeshError("subdivision_operator: 3 non-manifold vertices, e.g. vertex 748")
    msg = api.user_cause(exc, "binding 'scan' to", "scan_cage")
    assert msg.startswith("binding 'scan' to 'scan_cage' failed: the cage has non-manifold")
    assert "Keep topology off" in msg


def test_stale_source_is_detected_shown_and_fixed_by_rebind(bound):
    dense, cage = bound
    panel = mod("panel")
    bpy.context.view_layer.objects.active = cage
    assert panel.refine_messages(bpy.context) == [(cage.meshadjust.last_report[:160], False)]
    dense.modifiers.new("sub", 'SUBSURF').levels = 1
    bpy.context.view_layer.update()
    msgs = panel.refine_messages(bpy.context)
    assert any(rebind and "'dense' changed since it was bound: its modifiers changed" in text
               for text, rebind in msgs)
    from tests.addon.test_operators import _draw_panel
    drawn = [e for e in _draw_panel() if e == ("operator", "meshadjust.bind")]
    assert len(drawn) == 3                  # Edit Cage's Bind, Re-bind and Re-bind as Is
    assert bpy.ops.meshadjust.refine(output='EDITED') == {'FINISHED'}
    assert "WARNING" in cage.meshadjust.last_report
    assert bpy.ops.meshadjust.bind() == {'FINISHED'}             # Re-bind
    edited = cage.meshadjust.edited
    depsgraph = bpy.context.evaluated_depsgraph_get()
    assert len(edited.data.vertices) == len(dense.evaluated_get(depsgraph).data.vertices)
    bpy.context.view_layer.update()
    assert all(not rebind for _, rebind in panel.refine_messages(bpy.context))
    assert bpy.ops.meshadjust.refine(output='EDITED') == {'FINISHED'}
    assert "WARNING" not in cage.meshadjust.last_report
    assert orphans() == []


def test_a_shape_key_value_change_makes_the_binding_stale(scene):
    V, F = bumpy_sphere(3)
    dense = make_object("dense", V, F)
    dense.shape_key_add(name="Basis", from_mix=False)
    key = dense.shape_key_add(name="pose", from_mix=False)
    key.value = 0.0
    assert simplify(200) == {'FINISHED'}
    cage = dense.meshadjust.cage
    ops = mod("operators")
    assert ops.binding_warnings(cage) == []
    key.value = 0.5
    bpy.context.view_layer.update()
    (msg,) = ops.binding_warnings(cage)
    assert msg == "'dense' changed since it was bound: its shape keys changed"


def rotate_an_edge(cage):
    bpy.context.view_layer.objects.active = cage
    bpy.ops.object.mode_set(mode='EDIT')
    bm = bmesh.from_edit_mesh(cage.data)
    edge = next(e for e in bm.edges if len(e.link_faces) == 2)
    bmesh.ops.rotate_edges(bm, edges=[edge], use_ccw=False)
    bmesh.update_edit_mesh(cage.data)


def test_messages_say_what_changed_in_the_cage(bound):
    dense, cage = bound
    ops = mod("operators")
    rotate_an_edge(cage)
    bpy.context.view_layer.update()
    why = ops.cage_unavailable(bpy.context, need_binding=True)    # still in Edit Mode
    assert why is not None and "connected differently" in why and "re-bind" in why
    bpy.ops.object.mode_set(mode='OBJECT')
    with pytest.raises(RuntimeError, match="connected differently"):
        bpy.ops.meshadjust.refine(output='EDITED')
    assert bpy.ops.meshadjust.bind() == {'FINISHED'}
    delete_cage_vertex(cage, 5)
    why = ops.cage_unavailable(bpy.context, need_binding=True)
    assert "1 vertex" in why and "removed" in why


def test_rebinds_inside_refine_are_reported(bound):
    dense, cage = bound
    assert bpy.ops.meshadjust.refine(output='EDITED', levels=1, scheme='butterfly') == {'FINISHED'}
    rep = cage.meshadjust.last_report
    assert "re-bound" in rep and "loop x2 -> butterfly x1" in rep
    assert orphans() == []


def test_no_orphans_after_a_whole_session(bound):
    dense, cage = bound
    lift_top(cage)
    for op in (lambda: bpy.ops.meshadjust.refine(output='BOTH'),
               lambda: bpy.ops.meshadjust.fit_cage(),
               lambda: bpy.ops.meshadjust.bind(levels=1),
               lambda: bpy.ops.meshadjust.refine(output='BOTH', levels=2),
               lambda: bpy.ops.meshadjust.bind(keep_edit=False)):
        assert op() == {'FINISHED'}
        assert orphans() == []
    names = sorted(m.name for m in bpy.data.meshes)
    assert names == sorted(["dense", "dense_cage", "dense_edited", "dense_edited.detail",
                            "dense_refined"])


def test_a_simplify_whose_commit_fails_leaves_the_scene_and_the_source_as_they_were(
        scene, monkeypatch):
    V, F = bumpy_sphere(3)
    dense = make_object("dense", V, F)
    before = scene_snapshot()
    monkeypatch.setattr(mod("cage_steps"), "commit_bind", _boom)   # as simplify calls it
    with pytest.raises(RuntimeError, match="boom"):
        simplify(200)
    assert_unchanged(before)
    assert (dense.meshadjust.role, dense.meshadjust.cage) == ('NONE', None)


def test_several_objects_one_fails_the_others_are_kept_and_named(scene):
    objs = []
    for k in range(2):
        V, F = bumpy_sphere(3)
        objs.append(make_object(f"dense{k}", V + [3.0 * k, 0, 0], F))
    vg = objs[0].vertex_groups.new(name="w")
    vg.add(list(range(10)), 1.0, 'REPLACE')
    for o in objs:
        o.select_set(True)
    bpy.context.view_layer.objects.active = objs[0]
    assert bpy.ops.meshadjust.simplify(target_mode='FACES', target_faces=200, weight_group="w",
                                       fit=False, bind=False) == {'FINISHED'}
    assert objs[0].meshadjust.cage is not None and objs[1].meshadjust.cage is None


def test_steps_from_edit_mode_keep_the_edit_and_the_mode(bound):
    dense, cage = bound
    store = mod("store")
    rest0 = store.load_rest(cage)
    lift_in_edit_mode(cage)
    # a re-bind inside Refine from Edit Mode: the rest shape is kept, so is the edit
    assert bpy.ops.meshadjust.refine(output='EDITED', levels=1) == {'FINISHED'}
    assert cage.mode == 'EDIT' and cage.meshadjust.levels == 1
    dz = pos(cage.meshadjust.edited)[:, 2] - pos(dense)[:, 2]
    assert np.allclose(dz, 0.1, atol=1e-4)
    # Bind with Keep edit off from Edit Mode: the current shape is the new rest
    assert bpy.ops.meshadjust.bind(keep_edit=False) == {'FINISHED'}
    bpy.ops.object.mode_set(mode='OBJECT')
    assert np.abs(store.load_rest(cage) - pos(cage)).max() < 1e-6
    assert np.abs(store.load_rest(cage) - rest0).max() > 0.09
    bpy.ops.object.mode_set(mode='EDIT')
    assert bpy.ops.meshadjust.fit_cage() == {'FINISHED'}
    assert cage.mode == 'EDIT'                                   # given back
    assert bpy.ops.meshadjust.refine(output='SHAPE_KEY') == {'FINISHED'}
    assert dense.data.shape_keys.key_blocks.get("dense_cage") is not None


def test_simplify_keeps_the_cage_when_the_fit_fails_and_still_binds_it(scene, monkeypatch):
    V, F = bumpy_sphere(3)
    dense = make_object("dense", V, F)
    core = sys.modules[MODULE + ".core"]
    monkeypatch.setattr(core, "fit_cage", _boom)
    assert simplify(200) == {'FINISHED'}
    cage = dense.meshadjust.cage
    rep = cage.meshadjust.last_report
    assert "WARNING: fitting 'dense_cage' failed: boom" in rep and "kept unfitted" in rep
    assert cage.meshadjust.edited is not None                     # bound all the same
    assert bpy.ops.meshadjust.refine(output='EDITED') == {'FINISHED'}
    assert np.abs(pos(cage.meshadjust.edited) - pos(dense)).max() < 1e-5


def test_a_result_the_artist_deleted_is_made_again(bound):
    dense, cage = bound
    bpy.ops.meshadjust.refine(output='BOTH')
    for obj in (cage.meshadjust.edited, cage.meshadjust.refined):
        for col in list(obj.users_collection):
            col.objects.unlink(obj)                             # deleted in the outliner
    assert bpy.ops.meshadjust.bind() == {'FINISHED'}
    assert bpy.ops.meshadjust.refine(output='BOTH') == {'FINISHED'}
    assert cage.meshadjust.edited.users_collection and cage.meshadjust.refined.users_collection


def test_rebind_after_an_extrusion_refuses_to_keep_the_edit_and_says_why(bound):
    dense, cage = bound
    bpy.context.view_layer.objects.active = cage
    bpy.ops.object.mode_set(mode='EDIT')
    bm = bmesh.from_edit_mesh(cage.data)
    bm.faces.ensure_lookup_table()
    out = bmesh.ops.extrude_discrete_faces(bm, faces=[bm.faces[0]])
    for v in out["faces"][0].verts:
        v.co += 0.05 * out["faces"][0].normal
    bmesh.update_edit_mesh(cage.data)
    bpy.ops.object.mode_set(mode='OBJECT')
    before = scene_snapshot()
    # (the extrusion's sides are quads: Bind triangulates them, see test_artist_meddles)
    with pytest.raises(RuntimeError, match="6 faces added in Edit Mode have no rest shape "
                                           ".*Keep edit off"):
        bpy.ops.meshadjust.bind()
    assert_unchanged(before)
    assert bpy.ops.meshadjust.bind(keep_edit=False) == {'FINISHED'}
    assert "triangulated 3 faces of more than three corners" in cage.meshadjust.last_report


def test_a_failed_fit_from_edit_mode_gives_edit_mode_back(bound, monkeypatch):
    dense, cage = bound
    bpy.context.view_layer.objects.active = cage
    bpy.ops.object.mode_set(mode='EDIT')
    monkeypatch.setattr(sys.modules[MODULE + ".core"], "fit_cage", _boom)
    with pytest.raises(RuntimeError, match="boom"):
        bpy.ops.meshadjust.fit_cage()
    assert cage.mode == 'EDIT'


def test_esc_during_the_bind_itself_cancels_it(bound):
    # the bind reports from inside its closest-point searches: Esc there stops it
    dense, cage = bound
    api = mod("api")
    lift_top(cage)
    before = scene_snapshot()
    seen = []

    def stop_inside(f):
        seen.append(f)
        return not (0.0 < f < 0.9)
    job = api.compute_bind(api.prepare_cage_job(cage, levels=1), progress=stop_inside)
    assert job.cancelled and job.binding is None and any(0.0 < f < 0.9 for f in seen)
    assert_unchanged(before)


def full_snapshot():
    """Everything a step may write: per object its mesh, transform, visibility
    and MeshAdjust state (pointers by name); per mesh its positions, shape
    keys' shapes, attributes (every value) and fake user."""
    objects = {}
    for o in bpy.data.objects:
        st = {}
        for prop in o.meshadjust.bl_rna.properties:
            if prop.identifier == "rna_type":
                continue
            v = getattr(o.meshadjust, prop.identifier)
            st[prop.identifier] = (v.name if isinstance(v, bpy.types.ID) else
                                   tuple(v) if getattr(prop, "is_array", False) else v)
        objects[o.name] = (o.data.name, tuple(map(tuple, o.matrix_world)), o.hide_get(), st)
    meshes = {}
    for m in bpy.data.meshes:
        keys = () if m.shape_keys is None else tuple(
            (kb.name, kb.value, _values(kb.data, "co", 3)) for kb in m.shape_keys.key_blocks)
        attrs = {a.name: (a.domain, a.data_type, _values(a.data, *{
            'FLOAT_VECTOR': ("vector", 3), 'INT': ("value", 1), 'BOOLEAN': ("value", 1),
            'FLOAT': ("value", 1)}.get(a.data_type, (None, 0)))) for a in m.attributes
            if not a.name.startswith(".")}
        meshes[m.name] = (pos_of(m), keys, attrs, m.use_fake_user)
    return objects, meshes


def _values(data, field, width):
    if field is None:
        return None
    buf = np.empty(len(data) * width, dtype=np.float64)
    data.foreach_get(field, buf)
    return buf.tobytes()


def pos_of(mesh):
    return mod("mesh_io").read_positions(mesh).tobytes()


def assert_all_unchanged(before):
    after = full_snapshot()
    assert set(after[0]) == set(before[0]), "objects added or removed"
    assert set(after[1]) == set(before[1]), "meshes added or removed"
    for name, record in before[0].items():
        assert after[0][name] == record, f"object {name} changed"
    for name, record in before[1].items():
        for what, a, b in zip(("positions", "shape keys", "attributes", "fake user"),
                              after[1][name], record):
            assert a == b, f"mesh {name}: {what} changed"


def _bug(*args, **kwargs):
    raise RuntimeError("boom: a bug late in the commit")


def _raises_the_bug(op):
    """Run the operator ``op`` and check it fails with the bug itself (not
    with an error of the rollback, which would show in the traceback)."""
    with pytest.raises(RuntimeError, match="boom") as caught:
        op()
    assert "ReferenceError" not in str(caught.value) and "KeyError" not in str(caught.value)


def test_a_refine_failing_after_its_rebind_was_written_puts_everything_back(bound, monkeypatch):
    # The re-bind at one level writes the binding attributes, the states, a new
    # detail mesh (the old one retired), the edited original; the refined mesh
    # then fails. Everything comes back, the old detail mesh included, and the
    # next Refine gives what the first did (no binding cached from the failed run:
    # at one level it would refine to 1,200 faces, not 4,800).
    dense, cage = bound
    lift_top(cage)
    assert bpy.ops.meshadjust.refine(output='BOTH') == {'FINISHED'}
    edited = cage.meshadjust.edited
    detail = edited.meshadjust.detail_mesh
    before = full_snapshot()
    monkeypatch.setattr(mod("results"), "write_refined", _bug)
    _raises_the_bug(lambda: bpy.ops.meshadjust.refine(output='BOTH', levels=1))
    monkeypatch.undo()
    assert_all_unchanged(before)
    assert edited.meshadjust.detail_mesh == detail
    V_edited, n_refined = pos(edited), len(cage.meshadjust.refined.data.polygons)
    assert bpy.ops.meshadjust.refine(output='BOTH') == {'FINISHED'}
    # (the binding now read back from its float32 attributes: 1e-7 of the size apart)
    assert np.abs(pos(edited) - V_edited).max() < 1e-6
    assert len(cage.meshadjust.refined.data.polygons) == n_refined


def test_a_bind_failing_after_the_edited_original_was_remade_gives_back_its_mesh(
        bound, monkeypatch):
    dense, cage = bound
    lift_top(cage)
    assert bpy.ops.meshadjust.refine(output='BOTH') == {'FINISHED'}
    edited = cage.meshadjust.edited
    delete_a_face(dense)
    old_mesh = edited.data
    before = full_snapshot()
    monkeypatch.setattr(mod("store"), "save_rest", _bug)     # after the re-made mesh and binding
    bpy.context.view_layer.objects.active = cage
    with pytest.raises(RuntimeError, match="boom"):
        bpy.ops.meshadjust.bind()
    monkeypatch.undo()
    assert_all_unchanged(before)
    assert edited.data == old_mesh
    assert bpy.ops.meshadjust.bind() == {'FINISHED'}              # and then it works
    assert len(edited.data.polygons) == len(dense.data.polygons) == 5119
    assert orphans() == []


@pytest.mark.parametrize("first, module, name", [
    # a re-bind at one level writes the key, then the refined mesh fails (none yet: made)
    ('SHAPE_KEY', "results", "write_refined"),
    # a re-bind at one level writes a new refined mesh, then the report fails
    ('BOTH', "refine_step", "_density_note")])
def test_a_refine_re_binding_and_failing_late_is_undone(bound, monkeypatch, first, module, name):
    dense, cage = bound
    lift_top(cage)
    assert bpy.ops.meshadjust.refine(output=first) == {'FINISHED'}
    lift_top(cage, 0.1)
    before = full_snapshot()
    monkeypatch.setattr(mod(module), name, _bug)
    _raises_the_bug(lambda: bpy.ops.meshadjust.refine(output='BOTH', levels=1))
    monkeypatch.undo()
    assert_all_unchanged(before)


def test_a_bind_from_edit_mode_failing_late_puts_the_rest_layer_back(bound, monkeypatch):
    # In Edit Mode the rest shape is a layer of the cage's BMesh, written per vertex
    dense, cage = bound
    assert bpy.ops.meshadjust.refine(output='BOTH') == {'FINISHED'}
    store = mod("store")
    rest0 = store.load_rest(cage)
    lift_in_edit_mode(cage)
    monkeypatch.setattr(mod("results"), "write_refined", _bug)
    with pytest.raises(RuntimeError, match="boom"):
        bpy.ops.meshadjust.bind(levels=1, keep_edit=False)     # the lifted shape as the rest
    monkeypatch.undo()
    assert cage.mode == 'EDIT'
    assert np.array_equal(store.load_rest(cage), rest0)
    bpy.ops.object.mode_set(mode='OBJECT')
    assert np.array_equal(store.load_rest(cage), rest0)
    assert cage.meshadjust.levels == 2


def _live_session(cage):
    """Live mode's module, with a first live write after the cage's top was lifted."""
    lu = mod("live_update")
    lu.forget()
    lift_top(cage, 0.1)
    lu.update_edited(cage)
    return lu


def _sculpt(obj, dz=0.05):
    """Change ``obj``'s mesh by hand (as a sculpt stroke would): lift a few vertices."""
    V = pos(obj)
    V[:20, 2] += dz
    mod("mesh_io").write_positions(obj.data, V)
    return V


def _assert_artists_copy(copy, V):
    assert copy is not None and np.array_equal(pos(copy), V.astype(np.float32))
    assert copy.meshadjust.role == 'NONE' and copy.meshadjust.source is None
    assert not [a.name for a in copy.data.attributes if a.name.startswith("meshadjust_")]
    assert copy.users_collection


@pytest.mark.parametrize("step", ["refine", "rebind", "fit"])
def test_an_edited_original_changed_by_hand_is_kept_aside_not_overwritten(bound, step):
    dense, cage = bound
    lift_top(cage)
    assert bpy.ops.meshadjust.refine(output='EDITED') == {'FINISHED'}
    edited = cage.meshadjust.edited
    V_hand = _sculpt(edited)
    lift_top(cage, 0.1)
    bpy.context.view_layer.objects.active = cage
    if step == "refine":
        assert bpy.ops.meshadjust.refine(output='EDITED') == {'FINISHED'}
    elif step == "rebind":
        assert bpy.ops.meshadjust.bind(levels=1) == {'FINISHED'}
    else:
        assert bpy.ops.meshadjust.fit_cage() == {'FINISHED'}
    copy = bpy.data.objects.get(f"{edited.name}.hand")
    _assert_artists_copy(copy, V_hand)
    assert "kept as 'dense_edited.hand'" in cage.meshadjust.last_report
    assert not np.array_equal(pos(edited), pos(copy))           # the edit was written
    # written by MeshAdjust since: the next step keeps nothing more aside
    n = len(bpy.data.objects)
    assert bpy.ops.meshadjust.refine(output='EDITED') == {'FINISHED'}
    assert len(bpy.data.objects) == n and "kept as" not in cage.meshadjust.last_report


def test_an_applied_transform_and_a_sculpted_refined_mesh_are_kept_aside(bound):
    dense, cage = bound
    assert bpy.ops.meshadjust.refine(output='BOTH') == {'FINISHED'}
    edited, refined = cage.meshadjust.edited, cage.meshadjust.refined
    edited.location = (2.0, 0.0, 0.0)
    bpy.context.view_layer.update()
    for o in bpy.context.selected_objects:
        o.select_set(False)
    edited.select_set(True)
    bpy.context.view_layer.objects.active = edited
    bpy.ops.object.transform_apply(location=True, rotation=False, scale=False)
    V_applied = pos(edited)
    V_hand = _sculpt(refined)
    bpy.context.view_layer.objects.active = cage
    assert bpy.ops.meshadjust.refine(output='BOTH') == {'FINISHED'}
    _assert_artists_copy(bpy.data.objects.get("dense_edited.hand"), V_applied)
    _assert_artists_copy(bpy.data.objects.get("dense_refined.hand"), V_hand)


def test_a_shape_key_changed_by_hand_is_kept_aside_as_a_key_at_value_0(bound):
    dense, cage = bound
    lift_top(cage)
    assert bpy.ops.meshadjust.refine(output='SHAPE_KEY') == {'FINISHED'}
    key = dense.data.shape_keys.key_blocks[cage.meshadjust.key_name]
    co = np.empty(3 * len(key.data), dtype=np.float32)
    key.data.foreach_get("co", co)
    co[:30] += 0.05
    key.data.foreach_set("co", co)
    lift_top(cage, 0.1)
    assert bpy.ops.meshadjust.refine(output='SHAPE_KEY') == {'FINISHED'}
    hand = dense.data.shape_keys.key_blocks.get(f"{key.name}.hand")
    assert hand is not None and hand.value == 0.0
    got = np.empty_like(co)
    hand.data.foreach_get("co", got)
    assert np.array_equal(got, co)
    assert "kept as" in cage.meshadjust.last_report
    assert bpy.ops.meshadjust.refine(output='SHAPE_KEY') == {'FINISHED'}   # nothing more
    assert len(dense.data.shape_keys.key_blocks) == 3
    # (the copy is a version of MeshAdjust's key: the binding is not stale for it)
    assert "changed since" not in cage.meshadjust.last_report


def test_live_mode_keeps_a_changed_edited_original_aside_once_and_its_own_writes_are_not_changes(
        bound):
    dense, cage = bound
    lu = mod("live_update")
    lu.forget()
    assert bpy.ops.meshadjust.refine(output='EDITED') == {'FINISHED'}
    edited = cage.meshadjust.edited
    V_hand = _sculpt(edited)
    first = lu.update_edited(cage)
    _assert_artists_copy(bpy.data.objects.get("dense_edited.hand"), V_hand)
    assert "kept as 'dense_edited.hand'" in first.note
    lift_top(cage, 0.1)
    assert not lu.update_edited(cage).note
    n = len(bpy.data.objects)
    assert bpy.ops.meshadjust.refine(output='EDITED') == {'FINISHED'}      # live's own writes
    assert len(bpy.data.objects) == n


def test_a_first_bind_failing_late_leaves_the_cage_without_a_rest_shape(scene, monkeypatch):
    # (the rest-shape attribute the failed run added to the cage is removed; the
    # edited original it made is removed whole)
    dense = make_object("dense", *bumpy_sphere(3))
    assert simplify(200, bind=False, fit=False) == {'FINISHED'}
    cage = dense.meshadjust.cage
    before = full_snapshot()
    monkeypatch.setattr(mod("store"), "save_rest", _bug)
    bpy.context.view_layer.objects.active = cage
    _raises_the_bug(lambda: bpy.ops.meshadjust.bind())
    assert_all_unchanged(before)


def _edit_mode_on(obj):
    for o in bpy.context.view_layer.objects:
        o.select_set(False)
    obj.select_set(True)
    bpy.context.view_layer.objects.active = obj
    bpy.ops.object.mode_set(mode='EDIT')


def test_results_in_edit_mode_are_refused_by_name_and_left_as_they_are(bound):
    # (writing them raised a KeyError from Blender: the mesh of an object in Edit
    # Mode is its BMesh's until the mode is left)
    dense, cage = bound
    lift_top(cage)
    assert bpy.ops.meshadjust.refine(output='BOTH') == {'FINISHED'}
    edited, refined = cage.meshadjust.edited, cage.meshadjust.refined
    lift_top(cage, 0.1)
    _edit_mode_on(edited)
    before = full_snapshot()
    bpy.context.view_layer.objects.active = cage
    for op in (lambda: bpy.ops.meshadjust.refine(output='EDITED'),
               lambda: bpy.ops.meshadjust.refine(output='BOTH'),
               lambda: bpy.ops.meshadjust.bind(),
               lambda: bpy.ops.meshadjust.fit_cage()):
        with pytest.raises(RuntimeError, match="'dense_edited' is in Edit Mode.*leave Edit Mode"):
            op()
    with pytest.raises(sys.modules[MODULE + ".core"].MeshAdjustError, match="in Edit Mode"):
        mod("live_update").update_edited(cage)
    with pytest.raises(RuntimeError, match="'dense_edited' is in Edit Mode"):
        bpy.ops.meshadjust.refine(output='REFINED')     # (its binding is read from its mesh)
    assert_all_unchanged(before)
    assert edited.mode == 'EDIT'
    bpy.context.view_layer.objects.active = edited
    bpy.ops.object.mode_set(mode='OBJECT')
    _edit_mode_on(refined)
    bpy.context.view_layer.objects.active = cage
    with pytest.raises(RuntimeError, match="'dense_refined' is in Edit Mode"):
        bpy.ops.meshadjust.refine(output='BOTH')
    assert bpy.ops.meshadjust.refine(output='EDITED') == {'FINISHED'}


@pytest.mark.parametrize("where", ["touched", "save_rest"])
def test_a_simplify_with_bind_failing_late_is_undone_by_the_rollback_itself(
        scene, monkeypatch, where):
    # (the rollback read the edited original's mesh, made inside the block, after
    # removing it: a ReferenceError replaced the bug, and what followed was not undone)
    make_object("dense", *bumpy_sphere(3))
    before = full_snapshot()
    monkeypatch.setattr(mod("staleness" if where == "touched" else "store"), where, _bug)
    _raises_the_bug(lambda: simplify(150))
    monkeypatch.undo()
    assert_all_unchanged(before)


def test_a_linked_duplicate_of_a_result_in_edit_mode_is_named(bound):
    dense, cage = bound
    assert bpy.ops.meshadjust.refine(output='BOTH') == {'FINISHED'}
    edited = cage.meshadjust.edited
    _edit_mode_on(edited)
    bpy.ops.object.mode_set(mode='OBJECT')
    bpy.ops.object.duplicate(linked=True)
    twin = bpy.context.view_layer.objects.active
    assert twin is not edited and twin.data == edited.data
    bpy.ops.object.mode_set(mode='EDIT')
    bpy.context.view_layer.objects.active = cage
    with pytest.raises(RuntimeError, match=f"'{twin.name}' is in Edit Mode.*'dense_edited', "
                                           "whose mesh it shares"):
        bpy.ops.meshadjust.refine(output='EDITED')
    with pytest.raises(sys.modules[MODULE + ".core"].MeshAdjustError, match="whose mesh it shares"):
        mod("live_update").update_edited(cage)


def test_live_keeps_a_version_sculpted_between_two_live_writes(bound):
    dense, cage = bound
    lu = _live_session(cage)
    edited = cage.meshadjust.edited
    V_hand = _sculpt(edited)
    lift_top(cage, 0.05)
    t = lu.update_edited(cage)                         # incremental
    assert not t.full and "kept as 'dense_edited.hand'" in t.note
    _assert_artists_copy(bpy.data.objects.get("dense_edited.hand"), V_hand)
    lift_top(cage, 0.05)
    assert not lu.update_edited(cage).note             # live's own write: no change


def test_a_sculpt_after_a_live_session_saved_and_reloaded_is_kept(bound, tmp_path):
    dense, cage = bound
    _live_session(cage)
    path = str(tmp_path / "live.blend")
    bpy.ops.wm.save_as_mainfile(filepath=path)
    bpy.ops.wm.open_mainfile(filepath=path)
    cage = bpy.data.objects["dense_cage"]
    V_hand = _sculpt(cage.meshadjust.edited)
    bpy.context.view_layer.objects.active = cage
    assert bpy.ops.meshadjust.refine(output='EDITED') == {'FINISHED'}
    _assert_artists_copy(bpy.data.objects.get("dense_edited.hand"), V_hand)


def test_a_failed_refine_after_live_keeps_live_mode_s_record(bound, monkeypatch):
    dense, cage = bound
    _live_session(cage)
    edited = cage.meshadjust.edited
    V_hand = _sculpt(edited)
    monkeypatch.setattr(mod("results"), "write_refined", _bug)
    _raises_the_bug(lambda: bpy.ops.meshadjust.refine(output='BOTH'))
    monkeypatch.undo()
    assert bpy.ops.meshadjust.refine(output='EDITED') == {'FINISHED'}
    _assert_artists_copy(bpy.data.objects.get("dense_edited.hand"), V_hand)


def test_a_scaled_source_s_edited_original_with_its_transform_applied_goes_back_in_place(scene):
    V, F = bumpy_sphere(3)
    dense = make_object("dense", V * 100.0, F)
    dense.scale = (0.01, 0.01, 0.01)
    dense.location = (3.0, 0.0, 0.0)
    bpy.context.view_layer.update()
    assert simplify(300, fit=False) == {'FINISHED'}
    cage = dense.meshadjust.cage
    edited = cage.meshadjust.edited
    placed = edited.matrix_world.copy()
    _edit_mode_on(edited)
    bpy.ops.object.mode_set(mode='OBJECT')
    bpy.ops.object.transform_apply(location=True, rotation=True, scale=True)
    V_applied = pos(edited)
    bpy.context.view_layer.objects.active = cage
    assert bpy.ops.meshadjust.refine(output='EDITED') == {'FINISHED'}
    _assert_artists_copy(bpy.data.objects.get("dense_edited.hand"), V_applied)
    assert edited.matrix_world == placed                 # back on the source, not 100x
    world = np.array(edited.matrix_world) @ np.c_[pos(edited), np.ones(len(pos(edited)))].T
    assert np.abs(world[:3].T - (V * 1.0 + [3.0, 0.0, 0.0])).max() < 1e-4


def test_an_edited_original_re_topologized_by_hand_is_refused_then_remade_by_bind(bound):
    # (a Subdivision modifier applied on it had interpolated its binding attributes,
    # and Refine wrote a spiky shape 2 units off on a unit sphere)
    dense, cage = bound
    edited = cage.meshadjust.edited
    _edit_mode_on(edited)
    bpy.ops.object.mode_set(mode='OBJECT')
    edited.modifiers.new("Sub", 'SUBSURF').levels = 1
    bpy.ops.object.modifier_apply(modifier="Sub")
    V_hand = pos(edited)
    bpy.context.view_layer.objects.active = cage
    with pytest.raises(RuntimeError, match="'dense_edited' has 15,362 vertices, 2,562 were bound"):
        bpy.ops.meshadjust.refine(output='EDITED')
    with pytest.raises(sys.modules[MODULE + ".core"].MeshAdjustError, match="were bound"):
        mod("live_update").update_edited(cage)
    assert any("2,562 were bound" in text and rebind
               for text, rebind in mod("panel").refine_messages(bpy.context))
    assert bpy.ops.meshadjust.bind() == {'FINISHED'}
    _assert_artists_copy(bpy.data.objects.get("dense_edited.hand"), V_hand)
    assert len(edited.data.vertices) == len(dense.data.vertices) == 2562
    assert bpy.ops.meshadjust.refine(output='EDITED') == {'FINISHED'}


def test_a_duplicated_cage_is_refused_until_bound_then_gets_results_of_its_own(bound):
    # (Shift+D copies the MeshAdjust state: the copy's Refine overwrote the original
    # cage's edited original and shape key)
    dense, cage = bound
    lift_top(cage)
    assert bpy.ops.meshadjust.refine(output='EDITED') == {'FINISHED'}
    edited = cage.meshadjust.edited
    V_edited = pos(edited)
    _edit_mode_on(cage)
    bpy.ops.object.mode_set(mode='OBJECT')
    bpy.ops.object.duplicate()
    copy = bpy.context.view_layer.objects.active
    assert copy is not cage and copy.meshadjust.edited == edited
    lift_top(copy, 0.2)
    with pytest.raises(RuntimeError, match=f"'{copy.name}' is a copy of 'dense_cage' and shares "
                                           f"its results: Bind '{copy.name}'"):
        bpy.ops.meshadjust.refine(output='EDITED')
    assert mod("panel").panel_state(bpy.context)["refine"][1].startswith(f"'{copy.name}' is a copy")
    with pytest.raises(sys.modules[MODULE + ".core"].MeshAdjustError, match="is a copy of"):
        mod("live_update").update_edited(copy)
    assert bpy.ops.meshadjust.bind() == {'FINISHED'}
    assert "given results of its own" in copy.meshadjust.last_report
    mine = copy.meshadjust.edited
    assert mine is not None and mine != edited and mine.meshadjust.cage == copy
    assert bpy.ops.meshadjust.refine(output='SHAPE_KEY') == {'FINISHED'}
    assert copy.meshadjust.key_name == copy.name
    assert np.array_equal(pos(edited), V_edited) and cage.meshadjust.edited == edited
    bpy.context.view_layer.objects.active = cage
    assert bpy.ops.meshadjust.refine(output='EDITED') == {'FINISHED'}
    assert not bpy.data.objects.get("dense_edited.hand")


def test_a_deleted_edited_original_is_linked_back_by_bind_too_and_a_failure_undoes_it(
        bound, monkeypatch):
    dense, cage = bound
    assert bpy.ops.meshadjust.refine(output='BOTH') == {'FINISHED'}
    edited = cage.meshadjust.edited
    for col in list(edited.users_collection):       # deleted by the artist (the object's
        col.objects.unlink(edited)                  # data stays, as Blender keeps it)
    lift_top(cage, 0.05)
    bpy.context.view_layer.objects.active = cage
    monkeypatch.setattr(mod("results"), "write_refined", _bug)
    _raises_the_bug(lambda: bpy.ops.meshadjust.refine(output='BOTH'))
    monkeypatch.undo()
    assert not edited.users_collection               # the link back undone with the step
    n = len(bpy.data.objects)
    assert bpy.ops.meshadjust.bind() == {'FINISHED'}
    assert edited.users_collection and cage.meshadjust.edited == edited
    assert len(bpy.data.objects) == n and "linked back" in cage.meshadjust.last_report


def test_bind_and_fit_refuse_a_shape_key_they_cannot_write_before_any_work(bound):
    # (they failed at commit, after the compute, with "Refine: ...")
    dense, cage = bound
    lift_top(cage)
    assert bpy.ops.meshadjust.refine(output='SHAPE_KEY') == {'FINISHED'}
    _edit_mode_on(dense)
    before = full_snapshot()
    bpy.context.view_layer.objects.active = cage
    for op in (bpy.ops.meshadjust.bind, bpy.ops.meshadjust.fit_cage):
        # (since 2026-12-05 any bind of a source in Edit Mode is refused, its mesh stale)
        with pytest.raises(RuntimeError, match="'dense' is in Edit Mode"):
            op()
    assert_all_unchanged(before)


def test_a_shape_key_renamed_by_the_artist_is_followed_not_written_twice(bound):
    dense, cage = bound
    lift_top(cage)
    assert bpy.ops.meshadjust.refine(output='SHAPE_KEY') == {'FINISHED'}
    dense.data.shape_keys.key_blocks[cage.name].name = "smile"
    lift_top(cage, 0.1)
    assert bpy.ops.meshadjust.refine(output='SHAPE_KEY') == {'FINISHED'}
    names = [kb.name for kb in dense.data.shape_keys.key_blocks]
    assert names == ["Basis", "smile"] and cage.meshadjust.key_name == "smile"
    assert "changed since" not in cage.meshadjust.last_report
    assert "smile" in dense.meshadjust.own_keys.split("\n")


def test_a_shape_key_made_relative_to_another_key_still_shows_the_edit(bound):
    dense, cage = bound
    lift_top(cage)
    assert bpy.ops.meshadjust.refine(output='SHAPE_KEY') == {'FINISHED'}
    keys = dense.data.shape_keys
    mine = keys.key_blocks[cage.name]
    shown = mod("mesh_io").read_positions(dense.evaluated_get(
        bpy.context.evaluated_depsgraph_get()).to_mesh())
    base = dense.shape_key_add(name="Base2", from_mix=False)      # an artist's key,
    co = np.empty(3 * len(base.data), np.float32)                  # a lifted copy of Basis
    base.data.foreach_get("co", co)
    base.data.foreach_set("co", co + 0.25)
    base.value = 0.0
    mine.relative_key = base
    assert bpy.ops.meshadjust.refine(output='SHAPE_KEY') == {'FINISHED'}
    bpy.context.view_layer.update()
    ev = dense.evaluated_get(bpy.context.evaluated_depsgraph_get())
    now = mod("mesh_io").read_positions(ev.to_mesh())
    ev.to_mesh_clear()
    assert np.abs(now - shown).max() < 1e-5           # the same edit shown over the Basis
