"""Every operator on real objects, headless: counts, links, in-place
updates, errors reported, the source never touched."""

import sys

import bmesh
import bpy
import numpy as np
import pytest

from tests.addon.conftest import MODULE, make_object
from tests.mesh_factory import icosphere, load_shared, regular_grid


def mio():
    return sys.modules[MODULE + ".meshadjust_addon.mesh_io"]


def bumpy_sphere(level=4):
    V, F = icosphere(level)
    r = 1.0 + 0.03 * np.sin(9 * V[:, 0]) * np.sin(7 * V[:, 1]) * np.sin(8 * V[:, 2])
    return V * r[:, None], F


def snapshot(obj):
    return mio().read_positions(obj.data), mio().read_triangles(obj.data)[0]


@pytest.fixture()
def dense(scene):
    V, F = bumpy_sphere(4)
    return make_object("dense", V, F)


def simplify(faces=300, **kw):
    kw.setdefault("fit", True)
    kw.setdefault("bind", True)
    kw.setdefault("levels", 2)
    return bpy.ops.meshadjust.simplify(target_mode='FACES', target_faces=faces, **kw)


def test_simplify_creates_linked_cage_and_keeps_source(dense):
    V0, F0 = snapshot(dense)
    assert simplify(300) == {'FINISHED'}
    cage = dense.meshadjust.cage
    assert cage is not None and cage is not dense
    assert cage.meshadjust.role == 'CAGE' and cage.meshadjust.source == dense
    assert len(cage.data.polygons) == 300
    V1, F1 = snapshot(dense)
    assert np.array_equal(V0, V1) and np.array_equal(F0, F1)
    assert "->" in cage.meshadjust.last_report and "% of size" in cage.meshadjust.last_report
    # the cage is a closed manifold of the sphere's topology
    core = sys.modules[MODULE + ".core"]
    Fc = mio().read_triangles(cage.data)[0]
    s = core.topology_summary(Fc, len(cage.data.vertices))
    assert (s.euler, s.components, s.boundary_edges, s.non_manifold_edges) == (2, 1, 0, 0)
    # bound copy exists, with the binding attributes
    edited = cage.meshadjust.edited
    assert edited is not None and len(edited.data.vertices) == len(dense.data.vertices)
    for name in ("meshadjust_face", "meshadjust_bary", "meshadjust_offset"):
        assert name in edited.data.attributes


def test_simplify_ratio_and_error_targets(dense):
    m = len(dense.data.polygons)
    assert bpy.ops.meshadjust.simplify(target_mode='RATIO', ratio=0.1, fit=False,
                                       bind=False) == {'FINISHED'}
    assert len(dense.meshadjust.cage.data.polygons) == round(0.1 * m)
    bpy.context.view_layer.objects.active = dense
    dense.hide_set(False)
    assert bpy.ops.meshadjust.simplify(target_mode='ERROR', max_error_pct=1.0, fit=False,
                                       bind=False) == {'FINISHED'}
    assert len(dense.meshadjust.cage.data.polygons) < m


def test_refine_without_edit_gives_the_original_back(dense):
    simplify(300)
    cage = dense.meshadjust.cage
    assert bpy.ops.meshadjust.refine(output='EDITED') == {'FINISHED'}
    edited = cage.meshadjust.edited
    V0 = mio().read_positions(dense.data)
    V1 = mio().read_positions(edited.data)
    assert np.abs(V1 - V0).max() < 1e-5   # float32 storage of positions and binding


def test_edit_moves_result_smoothly_and_in_place(dense):
    simplify(300)
    cage = dense.meshadjust.cage
    edited = cage.meshadjust.edited
    Vc = mio().read_positions(cage.data)
    top = int(np.argmax(Vc[:, 2]))
    Vc[top] += [0.0, 0.0, 0.3]
    mio().write_positions(cage.data, Vc)
    assert bpy.ops.meshadjust.refine(output='BOTH') == {'FINISHED'}
    refined = cage.meshadjust.refined
    V0 = mio().read_positions(dense.data)
    V1 = mio().read_positions(edited.data)
    moved = np.linalg.norm(V1 - V0, axis=1) > 1e-6
    assert 0 < moved.sum() < 0.5 * len(V0)           # local
    assert V1[:, 2].max() > V0[:, 2].max() + 0.05    # the top went up
    n_faces = len(refined.data.polygons)
    assert n_faces == 300 * 16
    # a second refine updates the same objects
    Vc[top] += [0.0, 0.0, 0.1]
    mio().write_positions(cage.data, Vc)
    names = set(o.name for o in bpy.data.objects)
    assert bpy.ops.meshadjust.refine(output='BOTH') == {'FINISHED'}
    assert set(o.name for o in bpy.data.objects) == names
    assert cage.meshadjust.refined == refined and cage.meshadjust.edited == edited
    assert mio().read_positions(edited.data)[:, 2].max() > V1[:, 2].max()


def test_refine_warns_when_the_edit_turns_cage_faces_over(dense):
    simplify(300)
    cage = dense.meshadjust.cage
    core = sys.modules[MODULE + ".core"]
    Vc = mio().read_positions(cage.data)
    Fc = mio().read_triangles(cage.data)[0]
    top = int(np.argmax(Vc[:, 2]))
    Vc[top, 2] += 0.1                                     # a gentle lift: no warning
    mio().write_positions(cage.data, Vc)
    assert bpy.ops.meshadjust.refine(output='EDITED') == {'FINISHED'}
    assert "WARNING" not in cage.meshadjust.last_report
    V_rest = Vc.copy()
    V_rest[top, 2] -= 0.1
    Vc[top] = [0.0, 0.0, -0.5]                            # pushed through the middle
    mio().write_positions(cage.data, Vc)
    turned = core.turned_faces(V_rest.astype(np.float64), Vc.astype(np.float64), Fc)
    assert turned.size >= 3
    assert bpy.ops.meshadjust.refine(output='EDITED') == {'FINISHED'}
    report = cage.meshadjust.last_report
    assert f"WARNING: the edit turns {turned.size} faces of '{cage.name}' over" in report
    assert f"(face index {turned[0]}, {turned[1]}" in report


def test_refine_syncs_edit_mode(dense):
    simplify(300)
    cage = dense.meshadjust.cage
    edited = cage.meshadjust.edited
    lift_in_edit_mode(cage)
    assert bpy.ops.meshadjust.refine(output='EDITED') == {'FINISHED'}
    assert cage.mode == 'EDIT'
    dz = mio().read_positions(edited.data)[:, 2] - mio().read_positions(dense.data)[:, 2]
    assert np.allclose(dz, 0.1, atol=1e-4)   # a translated cage translates the result


def test_cage_object_transform_is_respected(dense):
    simplify(300)
    cage = dense.meshadjust.cage
    cage.location = (0.5, 0.0, 0.0)
    bpy.context.view_layer.update()
    bpy.ops.meshadjust.refine(output='EDITED')
    dx = mio().read_positions(cage.meshadjust.edited.data)[:, 0] - \
        mio().read_positions(dense.data)[:, 0]
    assert np.allclose(dx, 0.5, atol=1e-4)


def lift_in_edit_mode(cage, dz=0.1):
    """Enter Edit Mode on the cage and lift every vertex by ``dz`` (left in Edit Mode)."""
    bpy.context.view_layer.objects.active = cage
    bpy.ops.object.mode_set(mode='EDIT')
    bm = bmesh.from_edit_mesh(cage.data)
    for v in bm.verts:
        v.co.z += dz
    bmesh.update_edit_mesh(cage.data)


def delete_cage_vertex(cage, index):
    """Change the cage's topology the way an artist would: in Edit Mode."""
    bpy.context.view_layer.objects.active = cage
    bpy.ops.object.mode_set(mode='EDIT')
    bm = bmesh.from_edit_mesh(cage.data)
    bm.verts.ensure_lookup_table()
    bmesh.ops.delete(bm, geom=[bm.verts[index]], context='VERTS')
    bmesh.update_edit_mesh(cage.data)
    bpy.ops.object.mode_set(mode='OBJECT')


def test_topology_changed_cage_is_refused_then_rebound(dense):
    simplify(300)
    cage = dense.meshadjust.cage
    delete_cage_vertex(cage, 0)
    with pytest.raises(RuntimeError, match="re-bind"):
        bpy.ops.meshadjust.refine(output='EDITED')


def test_binding_survives_save_and_reload(dense, tmp_path):
    simplify(300)
    cage = dense.meshadjust.cage
    Vc = mio().read_positions(cage.data)
    Vc[np.argmax(Vc[:, 2])] += [0, 0, 0.2]
    mio().write_positions(cage.data, Vc)
    bpy.ops.meshadjust.refine(output='EDITED')
    expected = mio().read_positions(cage.meshadjust.edited.data)
    path = str(tmp_path / "bound.blend")
    bpy.ops.wm.save_as_mainfile(filepath=path)
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    bpy.ops.wm.open_mainfile(filepath=path)
    cage = bpy.data.objects["dense_cage"]
    edited = cage.meshadjust.edited
    sys.modules[MODULE + ".meshadjust_addon.store"]._cache.clear()   # force a reload from attributes
    mio().write_positions(edited.data, mio().read_positions(cage.meshadjust.source.data))
    bpy.context.view_layer.objects.active = cage
    assert bpy.ops.meshadjust.refine(output='EDITED') == {'FINISHED'}
    assert np.abs(mio().read_positions(edited.data) - expected).max() < 1e-5


def test_subdivide_operator_counts_and_interpolation(scene):
    V, F = icosphere(1)
    obj = make_object("ico", V, F)
    assert bpy.ops.meshadjust.subdivide(levels=2, scheme='butterfly') == {'FINISHED'}
    out = [o for o in bpy.data.objects if o is not obj][0]
    assert len(out.data.polygons) == 16 * len(F)
    Vf = mio().read_positions(out.data)
    assert np.array_equal(Vf[:len(V)], V.astype(np.float32).astype(np.float64))
    bpy.context.view_layer.objects.active = obj
    for o in bpy.data.objects:
        o.select_set(o is obj)
    assert bpy.ops.meshadjust.subdivide(levels=1, scheme='loop', in_place=True) == {'FINISHED'}
    assert len(obj.data.polygons) == 4 * len(F)


def test_subdivide_triangulates_quads_and_handles_several_objects(scene):
    bpy.ops.mesh.primitive_cube_add()
    a = bpy.context.active_object
    bpy.ops.mesh.primitive_cube_add(location=(3, 0, 0))
    b = bpy.context.active_object
    a.select_set(True)
    assert bpy.ops.meshadjust.subdivide(levels=1, scheme='loop') == {'FINISHED'}
    outs = [o for o in bpy.data.objects if o not in (a, b)]
    assert sorted(len(o.data.polygons) for o in outs) == [48, 48]


def test_errors_are_reported(scene):
    bpy.ops.object.camera_add()
    with pytest.raises(RuntimeError, match="not a mesh"):
        bpy.ops.meshadjust.simplify()
    empty = make_object("empty", np.zeros((0, 3)), np.zeros((0, 3), np.int64))
    with pytest.raises(RuntimeError, match="no faces"):
        bpy.ops.meshadjust.simplify()
    with pytest.raises(RuntimeError, match="not a cage"):
        bpy.ops.meshadjust.refine()
    V, F = regular_grid(3, 3)
    make_object("grid", V, F)
    with pytest.raises(RuntimeError, match="Error"):
        bpy.ops.meshadjust.simplify(target_mode='FACES', target_faces=4, weight_group="nope")
    assert len(bpy.data.objects) == 3   # nothing was created by the failed runs
    assert empty.name in bpy.data.objects


def test_modifiers_use_the_evaluated_mesh_and_say_so(scene):
    bpy.ops.mesh.primitive_ico_sphere_add(subdivisions=3)
    obj = bpy.context.active_object
    obj.modifiers.new("sub", 'SUBSURF').levels = 1
    assert bpy.ops.meshadjust.simplify(target_mode='FACES', target_faces=200, fit=False,
                                       bind=False) == {'FINISHED'}
    cage = obj.meshadjust.cage
    assert "evaluated mesh" in cage.meshadjust.last_report
    assert len(obj.modifiers) == 1   # the source is untouched


def test_locked_group_and_weights(scene):
    V, F = bumpy_sphere(3)
    obj = make_object("dense", V, F)
    locked = np.flatnonzero(V[:, 2] > 0.8)
    vg = obj.vertex_groups.new(name="lock")
    vg.add(locked.tolist(), 1.0, 'REPLACE')
    assert bpy.ops.meshadjust.simplify(target_mode='FACES', target_faces=400, lock_group="lock",
                                       fit=False, bind=False) == {'FINISHED'}
    Vc = mio().read_positions(obj.meshadjust.cage.data)
    Vl = V[locked].astype(np.float32).astype(np.float64)
    # every locked vertex is still a cage vertex, unmoved
    d = np.linalg.norm(Vl[:, None, :] - Vc[None, :, :], axis=2).min(axis=1)
    assert d.max() < 1e-6


def test_panel_state_reasons(scene):
    panel = sys.modules[MODULE + ".meshadjust_addon.panel"]
    st = panel.panel_state(bpy.context)
    assert st["simplify"] == (False, "Select a mesh object")
    V, F = bumpy_sphere(3)
    make_object("dense", V, F)
    st = panel.panel_state(bpy.context)
    assert st["simplify"][0] and not st["refine"][0] and "Simplify" in st["refine"][1]
    simplify(200)
    st = panel.panel_state(bpy.context)
    assert st["refine"] == (True, None) and st["edit"] == (True, None)
    assert not st["simplify"][0] and "already a cage" in st["simplify"][1]


def test_live_refine_updates_result(dense):
    live = sys.modules[MODULE + ".meshadjust_addon.live"]
    simplify(300)
    cage = dense.meshadjust.cage
    cage.meshadjust.live = True
    Vc = mio().read_positions(cage.data)
    mio().write_positions(cage.data, Vc + [0.0, 0.0, 0.05])
    bpy.context.view_layer.update()     # fires the depsgraph handler: schedules a refine
    assert cage.name in live._pending
    live.refine_pending()               # the timer's callback (timers never fire headless)
    dz = mio().read_positions(cage.meshadjust.edited.data)[:, 2] - \
        mio().read_positions(dense.data)[:, 2]
    assert np.allclose(dz, 0.05, atol=1e-4)


def test_real_scan_simplify_and_refine(scene):
    V, F = load_shared("spot.obj")
    obj = make_object("spot", V, F)
    assert simplify(500) == {'FINISHED'}
    cage = obj.meshadjust.cage
    assert len(cage.data.polygons) == 500
    assert bpy.ops.meshadjust.refine(output='EDITED') == {'FINISHED'}
    diag = np.linalg.norm(np.ptp(V, axis=0))
    err = np.abs(mio().read_positions(cage.meshadjust.edited.data) - V).max() / diag
    assert err < 1e-5


def test_panel_offers_rebind_after_topology_change(dense):
    panel = sys.modules[MODULE + ".meshadjust_addon.panel"]
    simplify(300)
    cage = dense.meshadjust.cage
    delete_cage_vertex(cage, 3)
    enabled, reason = panel.panel_state(bpy.context)["refine"]
    assert not enabled and "re-bind" in reason
    assert bpy.ops.meshadjust.bind() == {'FINISHED'}       # the offered fix
    assert panel.panel_state(bpy.context)["refine"] == (True, None)
    assert bpy.ops.meshadjust.refine(output='EDITED') == {'FINISHED'}


def test_preferences_seed_new_scenes_without_a_button(addon, scene):
    prefs = bpy.context.preferences.addons[MODULE].preferences
    saved = (prefs.target_faces, prefs.levels, prefs.scheme, prefs.hide_source)
    try:
        prefs.target_faces = 1234
        prefs.levels = 3
        prefs.scheme = 'loop'
        prefs.hide_source = True
        bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)   # load_post seeds
        s = bpy.context.scene.meshadjust
        assert (s.target_faces, s.levels, s.scheme, s.hide_source, s.initialized) == \
            (1234, 3, 'loop', True, True)
        new = bpy.data.scenes.new("other")                  # a scene made later: seeded by
        props = sys.modules[MODULE + ".meshadjust_addon.properties"]
        props._on_depsgraph_update(new, None)               # the depsgraph handler
        assert (new.meshadjust.target_faces, new.meshadjust.initialized) == (1234, True)
        s.target_faces = 99                                 # a scene's own value is kept...
        props.seed_scenes()
        assert s.target_faces == 99
        assert bpy.ops.meshadjust.apply_defaults() == {'FINISHED'}   # ...unless reset
        assert bpy.context.scene.meshadjust.target_faces == 1234
    finally:
        prefs.target_faces, prefs.levels, prefs.scheme, prefs.hide_source = saved


def test_refine_with_other_levels_and_scheme_keeps_the_edit(dense):
    simplify(300)
    cage = dense.meshadjust.cage
    Vc = mio().read_positions(cage.data)
    mio().write_positions(cage.data, Vc + [0.0, 0.0, 0.2])      # the edit: a translation
    assert bpy.ops.meshadjust.refine(output='BOTH', levels=1, scheme='loop') == {'FINISHED'}
    assert (cage.meshadjust.levels, cage.meshadjust.scheme) == (1, 'loop')
    assert len(cage.meshadjust.refined.data.polygons) == 4 * 300
    dz = mio().read_positions(cage.meshadjust.edited.data)[:, 2] - \
        mio().read_positions(dense.data)[:, 2]
    assert np.allclose(dz, 0.2, atol=1e-4)   # re-bound from the rest shape: the edit survives


@pytest.mark.parametrize("stop_at", [0.3, 0.75, 0.85, 0.95])   # simplify, measure, fit, bind
def test_cancelled_simplify_leaves_the_scene_unchanged(dense, stop_at):
    api = sys.modules[MODULE + ".meshadjust_addon.api"]
    objects = set(bpy.data.objects)
    meshes = set(bpy.data.meshes)
    cage, report = api.simplify_object(dense, target_faces=300, fit=True, bind=True,
                                       progress=lambda f: f < stop_at)
    assert cage is None and "cancelled" in report.message
    assert set(bpy.data.objects) == objects and set(bpy.data.meshes) == meshes
    assert dense.meshadjust.cage is None and dense.meshadjust.role == 'NONE'


def test_fit_cage_operator_moves_the_cage_closer_and_rebinds(dense):
    simplify(300, fit=False)
    cage = dense.meshadjust.cage
    before = mio().read_positions(cage.data)
    assert bpy.ops.meshadjust.fit_cage() == {'FINISHED'}
    after = mio().read_positions(cage.data)
    assert np.abs(after - before).max() > 1e-4
    # re-bound to the fitted cage: refining the unedited cage gives the source back
    assert bpy.ops.meshadjust.refine(output='EDITED', levels=2, scheme='butterfly') == {'FINISHED'}
    err = np.abs(mio().read_positions(cage.meshadjust.edited.data)
                 - mio().read_positions(dense.data)).max()
    assert err < 1e-5


def test_background_operator_runs_compute_then_commit(dense):
    """The modal path's parts, driven by hand (invoke/modal never run headless):
    compute in a thread, nothing changes until finish() commits."""
    import threading
    ops = sys.modules[MODULE + ".meshadjust_addon.operators"]
    api = sys.modules[MODULE + ".meshadjust_addon.api"]
    simplify(300, bind=False, fit=False)
    cage = dense.meshadjust.cage
    job = api.prepare_cage_job(cage, levels=2, scheme='butterfly')
    box = {}
    worker = threading.Thread(target=lambda: box.update(job=api.compute_bind(job)))
    worker.start()
    worker.join()
    assert cage.meshadjust.edited is None            # nothing committed yet
    edited = api.commit_bind(cage, box["job"])
    assert edited is not None and cage.meshadjust.edited == edited
    assert issubclass(ops.MESHADJUST_OT_bind, ops._Background)
    assert issubclass(ops.MESHADJUST_OT_fit_cage, ops._Background)
    assert issubclass(ops.MESHADJUST_OT_simplify, ops._Background)


class _FakeLayout:
    """Records what a panel's draw() asks for and checks every property and
    operator name against Blender's RNA (draw() itself never runs headless)."""

    def __init__(self, log):
        self.log = log
        self.enabled = True

    def _child(self, *args, **kwargs):
        return _FakeLayout(self.log)

    box = column = row = _child

    def label(self, text="", **kwargs):
        self.log.append(("label", text))

    def prop(self, data, name, **kwargs):
        assert name in data.bl_rna.properties, f"{type(data).__name__} has no property {name}"
        self.log.append(("prop", name))

    def prop_search(self, data, name, search_data, search_name, **kwargs):
        assert name in data.bl_rna.properties and hasattr(search_data, search_name)
        self.log.append(("prop_search", name))

    def progress(self, **kwargs):
        self.log.append(("progress", kwargs.get("factor")))

    def operator(self, idname, **kwargs):
        mod, name = idname.split(".")
        rna = getattr(getattr(bpy.ops, mod), name).get_rna_type()
        self.log.append(("operator", idname))
        log = self.log

        class Props:
            def __setattr__(self, key, value):
                assert key in rna.properties, f"{idname} has no property {key}"
                log.append(("set", idname, key))
        return Props()


def _draw_panel():
    panel = sys.modules[MODULE + ".meshadjust_addon.panel"]
    log = []
    fake = type("P", (), {"layout": _FakeLayout(log)})()
    for cls in panel.CLASSES:
        cls.draw(fake, bpy.context)
    return log


def test_panel_draw_uses_existing_properties_and_operators(scene):
    log = _draw_panel()                                   # nothing selected
    assert ("label", "Select a mesh object") in log
    V, F = bumpy_sphere(3)
    make_object("dense", V, F)
    bpy.context.scene.meshadjust.running = True           # the progress bar row
    log = _draw_panel()
    assert ("operator", "meshadjust.simplify") in log and any(e[0] == "progress" for e in log)
    bpy.context.scene.meshadjust.running = False
    simplify(200)
    log = _draw_panel()                                   # a bound cage is active
    assert ("operator", "meshadjust.refine") in log and ("prop", "live") in log
    assert any(e[0] == "label" and e[1].startswith("Bound:") for e in log)


def test_cage_steps_handle_several_selected_cages(scene):
    objs = []
    for k in range(2):
        V, F = bumpy_sphere(3)
        obj = make_object(f"dense{k}", V + [3.0 * k, 0, 0], F)
        assert simplify(200) == {'FINISHED'}
        objs.append(obj)
    cages = [o.meshadjust.cage for o in objs]
    for c in cages:
        c.select_set(True)
        mio().write_positions(c.data, mio().read_positions(c.data) + [0.0, 0.0, 0.1])
    assert bpy.ops.meshadjust.refine(output='EDITED') == {'FINISHED'}
    for obj, c in zip(objs, cages):
        dz = mio().read_positions(c.meshadjust.edited.data)[:, 2] - \
            mio().read_positions(obj.data)[:, 2]
        assert np.allclose(dz, 0.1, atol=1e-4)
    assert bpy.ops.meshadjust.bind(levels=1) == {'FINISHED'}      # both re-bound, one level
    assert [c.meshadjust.levels for c in cages] == [1, 1]


def test_vertex_groups_follow_a_rig_and_not_modifiers_that_add_vertices(scene):
    # a lock group on a source with modifiers or shape keys was refused outright ("apply
    # them first": a rig applied is a rig lost); modifiers that only move the vertices keep
    # the group's vertices, so it is used; those that add vertices are named
    V, F = bumpy_sphere(3)
    obj = make_object("dense", V, F)
    locked = np.flatnonzero(V[:, 2] > 0.8)
    obj.vertex_groups.new(name="lock").add(locked.tolist(), 1.0, 'REPLACE')
    lift = obj.modifiers.new("lift", 'DISPLACE')      # (no texture: every vertex up by 0.25)
    lift.direction, lift.mid_level, lift.strength = 'Z', 0.0, 0.25
    assert bpy.ops.meshadjust.simplify(target_mode='FACES', target_faces=400, lock_group="lock",
                                       fit=False, bind=False) == {'FINISHED'}
    cage = obj.meshadjust.cage
    assert "evaluated mesh" in cage.meshadjust.last_report
    Vc = mio().read_positions(cage.data)
    Vl = (V[locked] + [0.0, 0.0, 0.25]).astype(np.float32).astype(np.float64)
    d = np.linalg.norm(Vl[:, None, :] - Vc[None, :, :], axis=2).min(axis=1)
    assert d.max() < 1e-6                  # every locked vertex a cage vertex, where it shows
    obj.modifiers.new("sub", 'SUBSURF').levels = 1
    names = set(bpy.data.objects.keys())
    with pytest.raises(RuntimeError, match="make 3,842 vertices of its 642"):
        bpy.ops.meshadjust.simplify(target_mode='FACES', target_faces=400, lock_group="lock",
                                    fit=False, bind=False)
    assert set(bpy.data.objects.keys()) == names
