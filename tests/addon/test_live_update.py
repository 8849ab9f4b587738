"""Live mode's incremental update of the edited original and of the refined
mesh (``meshadjust_addon.live_update``): equal to a full refine, only what
moved is recomputed, nothing is written when nothing moved, a re-bind starts
over."""

import re
import sys

import bpy
import numpy as np
import pytest

from tests.addon.conftest import MODULE, make_object
from tests.mesh_factory import icosphere


def _mod(name):
    return sys.modules[f"{MODULE}.meshadjust_addon.{name}"]


@pytest.fixture()
def bound_cage(scene):
    V, F = icosphere(4)
    V = V * (1.0 + 0.03 * np.sin(9 * V[:, 0]) * np.sin(7 * V[:, 1]))[:, None]
    dense = make_object("dense", V, F)
    assert bpy.ops.meshadjust.simplify(target_mode='FACES', target_faces=300, fit=True,
                                       bind=True, levels=2) == {'FINISHED'}
    _mod("live_update").forget()
    return dense.meshadjust.cage


def test_incremental_live_update_equals_a_full_refine(bound_cage):
    lu, mio = _mod("live_update"), _mod("mesh_io")
    cage = bound_cage
    edited = cage.meshadjust.edited
    first = lu.update_edited(cage)
    assert first.full and first.rows == len(edited.data.vertices)
    Vc = mio.read_positions(cage.data)
    Vc[[3, 4, 5]] += [0.0, 0.02, 0.05]
    mio.write_positions(cage.data, Vc)
    t = lu.update_edited(cage)
    assert not t.full and t.moved == 3 and 0 < t.rows < len(edited.data.vertices)
    assert "3 cage vertices moved" in cage.meshadjust.last_report
    live = mio.read_positions(edited.data)
    assert bpy.ops.meshadjust.refine(output='EDITED') == {'FINISHED'}
    full = mio.read_positions(edited.data)
    assert np.abs(live - full).max() <= 1e-6
    # nothing moved: nothing recomputed
    again = lu.update_edited(cage)
    assert again.moved == 0 and again.rows == 0 and not again.full
    assert np.array_equal(mio.read_positions(edited.data), full)


def test_live_report_warns_while_the_edit_turns_cage_faces_over(bound_cage):
    lu, mio = _mod("live_update"), _mod("mesh_io")
    cage = bound_cage
    lu.update_edited(cage)
    assert not lu.update_edited(cage).warning
    Vc = mio.read_positions(cage.data)
    top = int(np.argmax(Vc[:, 2]))
    rest = Vc[top].copy()
    Vc[top] = [0.0, 0.0, -0.5]                  # through the middle: its faces turn over
    mio.write_positions(cage.data, Vc)
    t = lu.update_edited(cage)
    assert t.warning.startswith("the edit turns ") and f"of '{cage.name}' over" in t.warning
    assert cage.meshadjust.last_report.endswith("; WARNING: " + t.warning)
    Vc[top] = rest                              # put back: the warning goes
    mio.write_positions(cage.data, Vc)
    assert not lu.update_edited(cage).warning
    assert "WARNING" not in cage.meshadjust.last_report


def test_rebind_starts_from_a_full_deform(bound_cage):
    lu = _mod("live_update")
    cage = bound_cage
    lu.update_edited(cage)
    assert bpy.ops.meshadjust.bind() == {'FINISHED'}
    assert lu.update_edited(cage).full


def test_edit_mode_and_transform_changes_are_followed(bound_cage):
    import bmesh
    lu, mio = _mod("live_update"), _mod("mesh_io")
    cage = bound_cage
    edited = cage.meshadjust.edited
    lu.update_edited(cage)
    bpy.context.view_layer.objects.active = cage
    bpy.ops.object.mode_set(mode='EDIT')
    bm = bmesh.from_edit_mesh(cage.data)
    bm.verts.ensure_lookup_table()
    for i in (0, 1):
        bm.verts[i].co.z += 0.05
    bmesh.update_edit_mesh(cage.data)
    t = lu.update_edited(cage)
    assert not t.full and t.moved == 2
    live = mio.read_positions(edited.data)
    assert bpy.ops.meshadjust.refine(output='EDITED') == {'FINISHED'}
    assert np.abs(live - mio.read_positions(edited.data)).max() <= 1e-6
    bpy.ops.object.mode_set(mode='OBJECT')
    # moving the cage object moves every cage vertex in the source's space: a full update
    cage.location = (0.25, 0.0, 0.0)
    bpy.context.view_layer.update()
    before = mio.read_positions(edited.data)
    assert lu.update_edited(cage).full
    assert np.allclose(mio.read_positions(edited.data)[:, 0] - before[:, 0], 0.25, atol=1e-4)


def test_live_update_follows_the_fold_repair(scene):
    """A rough torus bound with butterfly: a large one-ring lift turns dense
    faces over, the fold repair moves rows outside what the moved cage
    vertices influence through the subdivision, and the live update writes
    them too (equal to a full refine), also when the lift is undone."""
    from tests.mesh_factory import torus
    lu, mio, store = _mod("live_update"), _mod("mesh_io"), _mod("store")
    V, F = torus(96, 48, bump=0.01)
    V = V + 0.01 * np.random.default_rng(0).standard_normal(V.shape)
    dense = make_object("dense", V, F)
    assert bpy.ops.meshadjust.simplify(target_mode='FACES', target_faces=200, fit=False,
                                       bind=True, levels=2, scheme='butterfly') == {'FINISHED'}
    lu.forget()
    cage = dense.meshadjust.cage
    edited = cage.meshadjust.edited
    lu.update_edited(cage)
    binding = store.load_binding(edited, cage)
    Vc = mio.read_positions(cage.data)
    Fc = mio.read_triangles(cage.data)[0]
    core = _mod("live_update").core
    N = core.vertex_normals(Vc, Fc)
    diag = float(np.linalg.norm(V.max(axis=0) - V.min(axis=0)))
    lifted = None
    for v in range(0, Vc.shape[0], 7):        # a cage vertex whose one-ring lift needs a repair
        ring = np.unique(Fc[(Fc == v).any(axis=1)])
        Ve = Vc.copy()
        Ve[ring] += 0.08 * diag * N[v]
        D = core.deform(binding, Ve)
        if binding.repaired(D).size:
            lifted = Ve
            break
    assert lifted is not None
    for positions, said in ((lifted, True), (Vc, False)):
        mio.write_positions(cage.data, positions)
        t = lu.update_edited(cage)
        assert not t.full
        live = mio.read_positions(edited.data)
        assert bpy.ops.meshadjust.refine(output='EDITED') == {'FINISHED'}
        assert np.abs(live - mio.read_positions(edited.data)).max() <= 1e-6
        # the refine's report says when the repair acted
        assert ("dense vertices put back where the edit turned faces over"
                in cage.meshadjust.last_report) == said


def test_live_stops_on_an_internal_error_and_says_so_once(bound_cage, monkeypatch):
    live = _mod("live")
    cage = bound_cage
    cage.meshadjust.live = True
    live._pending[cage.name] = None

    def bug(_cage):
        raise ValueError("a bug")
    monkeypatch.setattr(_mod("live_update"), "update_edited", bug)
    with pytest.raises(ValueError, match="a bug"):     # (the console shows the traceback)
        live.refine_pending()
    assert not cage.meshadjust.live
    assert cage.meshadjust.last_report == ("live refine stopped by an internal error "
                                           "(ValueError: a bug); please report it")


def test_a_failed_live_update_keeps_nothing_aside(bound_cage):
    # The edited original sculpted, then a cage vertex sent 1e30 away (a script, a
    # broken snap): the update kept the sculpt aside as 'dense_edited.hand' before the
    # deform refused the cage ("reaches 1e+30"), so live mode stopped with a new object
    # in the scene and nothing written. Now the copy is made only once the deform went through: the scene is as
    # it was, and the first update that writes keeps the sculpt aside.
    lu, mio, live = _mod("live_update"), _mod("mesh_io"), _mod("live")
    cage = bound_cage
    edited = cage.meshadjust.edited
    lu.update_edited(cage)
    sculpt = mio.read_positions(edited.data)
    sculpt[10] += 0.05
    mio.write_positions(edited.data, sculpt)
    sculpt = mio.read_positions(edited.data)
    Vc = mio.read_positions(cage.data)
    bad = Vc.copy()
    bad[4, 0] = 1e30
    mio.write_positions(cage.data, bad)
    objects, meshes = sorted(bpy.data.objects.keys()), sorted(bpy.data.meshes.keys())
    cage.meshadjust.live = True
    live._pending[cage.name] = None
    live.refine_pending()
    assert not cage.meshadjust.live
    assert "reaches 1e+30" in cage.meshadjust.last_report
    assert sorted(bpy.data.objects.keys()) == objects
    assert sorted(bpy.data.meshes.keys()) == meshes
    assert np.array_equal(mio.read_positions(edited.data), sculpt)
    Vc[4] += [0.0, 0.0, 0.03]
    mio.write_positions(cage.data, Vc)
    t = lu.update_edited(cage)
    assert not t.full and t.moved == 1
    assert "kept as 'dense_edited.hand'" in t.note
    assert np.array_equal(mio.read_positions(bpy.data.objects["dense_edited.hand"].data), sculpt)


@pytest.mark.parametrize("step", ["live", "refine", "bind", "fit"])
def test_a_cage_vertex_that_is_not_a_number_is_named_on_the_cage(bound_cage, step):
    # Refine, Bind and Fit named the core's inner functions and arguments for it
    # ("turned_faces: 1 vertices of V_new have NaN ...", "bbox_diagonal: ..."); live
    # mode the deform's V_cage_edited. Now the cage and its vertex, nothing changed.
    lu, mio, live = _mod("live_update"), _mod("mesh_io"), _mod("live")
    cage = bound_cage
    lu.update_edited(cage)
    Vc = mio.read_positions(cage.data)
    Vc[4, 1] = np.inf
    mio.write_positions(cage.data, Vc)
    want = "'dense_cage' has 1 vertex position that is not a number or infinite (vertex 4 = ["
    edited = mio.read_positions(cage.meshadjust.edited.data)
    if step == "live":
        cage.meshadjust.live = True
        live._pending[cage.name] = None
        live.refine_pending()
        assert not cage.meshadjust.live
        assert cage.meshadjust.last_report.startswith("live refine stopped: " + want)
    else:
        bpy.context.view_layer.objects.active = cage
        op = {"refine": bpy.ops.meshadjust.refine, "bind": bpy.ops.meshadjust.bind,
              "fit": bpy.ops.meshadjust.fit_cage}[step]
        with pytest.raises(RuntimeError, match=r"has 1 vertex position that is not a number"):
            op()
    assert np.array_equal(mio.read_positions(cage.meshadjust.edited.data), edited)


@pytest.mark.parametrize("output", ['REFINED', 'BOTH'])
def test_live_makes_the_refined_mesh_s_first_finer_binding_in_the_background(scene, output):
    """Live with the refined mesh at Auto levels above the edit's: its first
    tick starts the finer binding in a worker and returns (the viewport is
    not held for the seconds it takes on a large scan); once made, the timer
    refines, and the refined mesh is what a Refine makes."""
    from tests.addon.test_operators import bumpy_sphere, simplify
    live, core = _mod("live"), sys.modules[MODULE + ".core"]
    dense = make_object("dense", *bumpy_sphere(4))                 # 5,120 faces
    assert simplify(80, levels=0) == {'FINISHED'}                   # bound at 2, refined at 3
    cage = dense.meshadjust.cage
    bpy.context.scene.meshadjust.output = output
    cage.meshadjust.live = True
    mio = _mod("mesh_io")
    Vc = mio.read_positions(cage.data)
    Vc[:4] *= 1.05
    mio.write_positions(cage.data, Vc)
    live._pending[cage.name] = None
    live.refine_pending()
    assert "binding the refined mesh at 3 levels in the background" in \
        cage.meshadjust.last_report
    assert cage.meshadjust.refined is None                         # (not yet)
    thread = live._finer[cage.name][0]
    thread.join()
    assert live.finer_done(cage.name) is None                      # (the timer's last call)
    refined = cage.meshadjust.refined
    assert refined is not None and len(refined.data.polygons) == 80 * 4 ** 3
    assert cage.name not in live._finer and cage.meshadjust.live
    got = mio.read_positions(refined.data)
    assert bpy.ops.meshadjust.refine(output='REFINED') == {'FINISHED'}
    assert np.array_equal(mio.read_positions(refined.data), got)
    assert "loop x3" in cage.meshadjust.last_report
    # the next ticks refine at once with the kept binding
    Vc[:4] *= 1.05
    mio.write_positions(cage.data, Vc)
    live._pending[cage.name] = None
    live.refine_pending()
    # (incremental: the kept finer binding's refine of the 4 moved cage vertices only)
    assert cage.name not in live._finer and \
        "refined mesh: 4 cage vertices moved" in cage.meshadjust.last_report
    assert np.abs(mio.read_positions(refined.data) - got).max() > 1e-3 * \
        core.bbox_diagonal(mio.read_positions(dense.data))


def _live_tick(cage, output):
    """One live update of ``cage`` with the scene's output ``output``; its report."""
    live = _mod("live")
    bpy.context.scene.meshadjust.output = output
    cage.meshadjust.live = True
    live._pending[cage.name] = None
    live.refine_pending()
    return cage.meshadjust.last_report


def _moved_cage(cage, ids, by):
    mio = _mod("mesh_io")
    Vc = mio.read_positions(cage.data)
    Vc[ids] += by
    mio.write_positions(cage.data, Vc)


def test_live_refined_mesh_recomputes_only_what_moved(bound_cage):
    # live mode refined the whole refined mesh at every tick (0.35 s for a 1M-vertex
    # one): now the first tick is a Refine, the next ones recompute the refined vertices
    # the moved cage vertices move (core.refine(moved=, out=)), with the same result
    mio = _mod("mesh_io")
    cage = bound_cage
    first = _live_tick(cage, 'REFINED')
    refined = cage.meshadjust.refined
    assert refined is not None and f"'{refined.name}' refined: " in first
    n = len(refined.data.vertices)
    _moved_cage(cage, [3, 4, 5], [0.0, 0.02, 0.05])
    report = _live_tick(cage, 'REFINED')
    assert report.startswith("refined mesh: 3 cage vertices moved, "), report
    rows = int(re.search(r"moved, ([\d,]+) vertices", report).group(1).replace(",", ""))
    assert 0 < rows < n // 2
    live = mio.read_positions(refined.data)
    assert bpy.ops.meshadjust.refine(output='REFINED') == {'FINISHED'}
    assert np.array_equal(mio.read_positions(refined.data), live)
    # nothing moved: nothing recomputed or written
    assert _live_tick(cage, 'REFINED').startswith("refined mesh: 0 cage vertices moved, 0 ")
    assert np.array_equal(mio.read_positions(refined.data), live)


def test_live_both_outputs_follow_a_drag(bound_cage):
    mio = _mod("mesh_io")
    cage = bound_cage
    _live_tick(cage, 'BOTH')
    refined, edited = cage.meshadjust.refined, cage.meshadjust.edited
    for _ in range(4):                    # the same vertices again and again: a drag
        _moved_cage(cage, [7, 8], [0.01, 0.0, -0.01])
        report = _live_tick(cage, 'BOTH')
        assert "2 cage vertices moved" in report and "refined mesh: 2 cage vertices" in report
    got_refined, got_edited = mio.read_positions(refined.data), mio.read_positions(edited.data)
    assert bpy.ops.meshadjust.refine(output='BOTH') == {'FINISHED'}
    assert np.abs(mio.read_positions(refined.data) - got_refined).max() <= 1e-6
    assert np.abs(mio.read_positions(edited.data) - got_edited).max() <= 1e-6


def test_live_refined_mesh_keeps_a_hand_change_aside_and_links_a_deleted_one_back(bound_cage):
    mio = _mod("mesh_io")
    cage = bound_cage
    _live_tick(cage, 'REFINED')
    refined = cage.meshadjust.refined
    hand = mio.read_positions(refined.data)
    hand[7] += 0.1
    mio.write_positions(refined.data, hand)
    hand = mio.read_positions(refined.data)
    _moved_cage(cage, [3], [0.0, 0.0, 0.03])
    report = _live_tick(cage, 'REFINED')
    assert report.startswith("refined mesh: 1 cage vertex moved")
    copy = bpy.data.objects[f"{refined.name}.hand"]
    assert f"kept as '{copy.name}'" in report
    assert np.array_equal(mio.read_positions(copy.data), hand)
    got = mio.read_positions(refined.data)
    assert bpy.ops.meshadjust.refine(output='REFINED') == {'FINISHED'}
    assert np.array_equal(mio.read_positions(refined.data), got)     # the cage's refine again
    # deleted by the artist (unlinked): the next tick is a Refine, which links it back
    for collection in list(refined.users_collection):
        collection.objects.unlink(refined)
    _moved_cage(cage, [4], [0.0, 0.0, 0.03])
    report = _live_tick(cage, 'REFINED')
    assert refined.users_collection and not report.startswith("refined mesh:")
    got = mio.read_positions(refined.data)
    assert bpy.ops.meshadjust.refine(output='REFINED') == {'FINISHED'}
    assert np.array_equal(mio.read_positions(refined.data), got)


@pytest.mark.parametrize("output", ['EDITED', 'REFINED'])
def test_a_live_update_after_a_refine_of_another_cage_writes_the_cage_s_result(bound_cage,
                                                                               output):
    # live at the cage V0; a Refine at V1 (outside live); the cage back at V0 (as an
    # undo does): the next live update found no cage vertex moved since its own last
    # update and wrote nothing, leaving V1's result. Now it sees the result is not what
    # it wrote last and makes a full update.
    mio = _mod("mesh_io")
    cage = bound_cage
    _live_tick(cage, output)
    result = cage.meshadjust.edited if output == 'EDITED' else cage.meshadjust.refined
    V0 = mio.read_positions(cage.data)
    _moved_cage(cage, [3, 4, 5], [0.0, 0.02, 0.05])
    cage.meshadjust.live = False
    assert bpy.ops.meshadjust.refine(output=output) == {'FINISHED'}
    at_v1 = mio.read_positions(result.data)
    mio.write_positions(cage.data, V0)
    _live_tick(cage, output)
    got = mio.read_positions(result.data)
    assert np.abs(got - at_v1).max() > 1e-3
    assert bpy.ops.meshadjust.refine(output=output) == {'FINISHED'}
    assert np.array_equal(mio.read_positions(result.data), got)


def test_a_refined_mesh_with_shape_keys_is_refused_by_name(bound_cage):
    # Blender shows the keys' mix over the mesh Refine writes: a Refine (and live
    # mode) said "refined" and nothing moved on screen
    mio = _mod("mesh_io")
    cage = bound_cage
    _live_tick(cage, 'REFINED')
    refined = cage.meshadjust.refined
    refined.shape_key_add(name="Basis")
    refined.shape_key_add(name="mine")
    before = mio.read_positions(refined.data)
    _moved_cage(cage, [3], [0.0, 0.0, 0.03])
    report = _live_tick(cage, 'REFINED')
    assert not cage.meshadjust.live
    assert report.startswith(f"live refine stopped: Refine: '{refined.name}' has shape keys")
    assert np.array_equal(mio.read_positions(refined.data), before)
    with pytest.raises(RuntimeError, match="has shape keys, which hide the mesh Refine writes"):
        bpy.ops.meshadjust.refine(output='REFINED')


def test_a_finer_binding_whose_timer_went_with_a_file_load_is_started_again(scene):
    # the worker of the refined mesh's first binding and its timer: a file loaded before
    # the timer ran removed the timer, and every later tick of a cage of that name said
    # "being made" for ever
    from tests.addon.test_operators import bumpy_sphere, simplify
    live = _mod("live")
    dense = make_object("dense", *bumpy_sphere(4))
    assert simplify(80, levels=0) == {'FINISHED'}                   # bound at 2, refined at 3
    cage = dense.meshadjust.cage
    live._finer[cage.name] = (None, {}, lambda: None)              # (its timer not registered)
    report = _live_tick(cage, 'REFINED')
    assert "binding the refined mesh at 3 levels in the background" in report
    live._finer[cage.name][0].join()
    assert live.finer_done(cage.name) is None
    assert cage.meshadjust.refined is not None


def test_a_cage_mirrored_or_turned_as_a_whole_is_not_said_to_fold(bound_cage):
    # the cage object scaled by -1 in X: its results are the exact mirror, and the
    # report warned that the edit turned 207 faces over; a half turn the same
    mio = _mod("mesh_io")
    cage = bound_cage
    _live_tick(cage, 'REFINED')
    refined = cage.meshadjust.refined
    R = mio.read_positions(refined.data)
    for scale, rotation in (((-1.0, 1.0, 1.0), (0.0, 0.0, 0.0)),
                            ((1.0, 1.0, 1.0), (0.0, 3.0, 0.0))):
        cage.scale, cage.rotation_euler = scale, rotation
        bpy.context.view_layer.update()
        report = _live_tick(cage, 'REFINED')
        assert "WARNING" not in report and "turns" not in report, report
    cage.scale, cage.rotation_euler = (-1.0, 1.0, 1.0), (0.0, 0.0, 0.0)
    bpy.context.view_layer.update()
    _live_tick(cage, 'REFINED')
    ox = cage.matrix_world.translation.x
    assert np.abs(mio.read_positions(refined.data) - (R * [-1, 1, 1] + [2 * ox, 0, 0])).max() \
        <= 1e-5
    # a fold made by the edit itself is still said
    cage.scale = (1.0, 1.0, 1.0)
    bpy.context.view_layer.update()
    Vc = mio.read_positions(cage.data)
    top = int(np.argmax(Vc[:, 2]))
    Vc[top] = [0.0, 0.0, -0.5]
    mio.write_positions(cage.data, Vc)
    assert "WARNING: the edit turns " in _live_tick(cage, 'REFINED')


def test_live_stops_and_says_so_when_its_results_are_removed(bound_cage):
    """The edited original and the refined mesh removed for good
    (``bpy.data.objects.remove``): live stayed on, did nothing at each edit
    and kept its old '... updated' line."""
    cage, live = bound_cage, _mod("live")
    cage.meshadjust.live = True
    live._pending[cage.name] = None
    live.refine_pending()
    assert cage.meshadjust.live and "updated" in cage.meshadjust.last_report
    for obj in (cage.meshadjust.edited, cage.meshadjust.refined):
        if obj is not None:
            bpy.data.objects.remove(obj)
    assert cage.meshadjust.edited is None
    live._pending[cage.name] = None
    live.refine_pending()
    assert not cage.meshadjust.live
    assert cage.meshadjust.last_report == ("live refine stopped: 'dense_cage' has no edited "
                                           "original any more (deleted): Bind makes it again")
    assert bpy.ops.meshadjust.bind() == {'FINISHED'} and cage.meshadjust.edited is not None


def test_live_warns_when_the_source_changed_since_the_bind(bound_cage):
    """Refine warned that its result used the mesh that was bound when the
    source was edited since; live's line said only 'updated'. Both the
    edited original's and the refined mesh's live lines now say it."""
    cage, live = bound_cage, _mod("live")
    source = cage.meshadjust.source
    cage.meshadjust.live = True
    live._pending[cage.name] = None
    live.refine_pending()
    assert "updated" in cage.meshadjust.last_report
    assert "WARNING" not in cage.meshadjust.last_report
    V = _mod("mesh_io").read_positions(source.data)
    V[0] += 0.01
    _mod("mesh_io").write_positions(source.data, V)
    source.data.update()
    bpy.context.view_layer.update()
    cage.data.vertices[0].co.z += 0.01
    cage.data.update()
    bpy.context.view_layer.update()
    bpy.context.scene.meshadjust.output = 'BOTH'
    live._pending[cage.name] = None
    live.refine_pending()
    report = cage.meshadjust.last_report
    said = ("WARNING: 'dense' changed since it was bound: its mesh was edited (vertices moved): "
            "the result uses the mesh that was bound; re-bind to use the new one")
    assert "updated" in report and said in report, report
    for _ in range(2):                  # (the refined mesh's first update binds it, then follows)
        if cage.name in live._finer:
            live.finer_done(cage.name)
        cage.data.vertices[0].co.z += 0.01
        cage.data.update()
        live._pending[cage.name] = None
        live.refine_pending()
    report = cage.meshadjust.last_report
    assert "refined mesh: 1 cage vertex moved" in report and report.count(said) == 2, report
    assert cage.meshadjust.live
