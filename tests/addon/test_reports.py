"""What the reports say: the core's cleaning, a missed target or the topology
floor (a warning beyond 5%), the automatic levels and the refined count; only
the core's errors become reports, anything else surfaces as a bug; the
background steps (Simplify, Fit, Bind) commit only after their worker."""

import sys
import threading
from types import SimpleNamespace

import bpy
import numpy as np
import pytest

from tests.addon.conftest import MODULE, make_object
from tests.addon.test_nothing_lost import assert_unchanged, mod, scene_snapshot
from tests.addon.test_operators import bumpy_sphere, mio, simplify
from tests.mesh_factory import cad_cylinder, icosphere, mobius_strip, torus


def test_simplify_report_says_what_the_cleaning_did(scene):
    V, F = icosphere(3)
    soup = make_object("soup", V[F].reshape(-1, 3), np.arange(3 * len(F)).reshape(-1, 3))
    cage, report = mod("api").simplify_object(soup, target_faces=100, fit=False, bind=False)
    assert "cleaned the input: welded" in report.message
    assert report.cleaning["n_welded_vertices"] > 0 and report.level == 'INFO'
    assert len(cage.data.polygons) == 100


def test_a_soup_no_weld_joins_is_kept_unfitted_with_a_warning_to_weld_it(scene):
    # every corner moved by 1.5% of the size: no weld joins the faces, so the cage is the
    # soup itself (its topology floor); fitting and binding it are refused with what to
    # do (fitting such a soup took minutes), the cage is kept and the report warns
    V, F = icosphere(3)
    S = V[F].reshape(-1, 3) + 0.05 * np.random.default_rng(0).normal(size=(3 * len(F), 3))
    soup = make_object("soup", S, np.arange(3 * len(F)).reshape(-1, 3))
    cage, report = mod("api").simplify_object(soup, target_faces=100, fit=True, bind=True)
    assert report.level == 'WARNING' and len(cage.data.polygons) == len(F)
    assert f"the cage is {len(F):,} separate pieces" in report.message
    assert "triangle soup" in report.message and "weld the source first" in report.message
    assert "the cage is kept unfitted" in report.message
    assert "max deviation" not in report.message       # (a soup's pieces are not measured)


def test_a_one_sided_scan_is_cut_open_said_so_and_refines_to_itself(scene):
    V, F = mobius_strip(240, 24, bump=0.01)
    obj = make_object("strip", V, F)
    cage, report = mod("api").simplify_object(obj, target_faces=400, fit=True, bind=True)
    assert "cut 1 one-sided (non-orientable) components open along" in report.message
    assert report.cleaning["n_non_orientable_components"] == 1 and report.level == 'INFO'
    assert abs(len(cage.data.polygons) - 400) <= 1          # (a collapse takes one or two faces)
    assert bpy.ops.meshadjust.refine(output='EDITED') == {'FINISHED'}
    mio = sys.modules[MODULE + ".meshadjust_addon.mesh_io"]
    got = mio.read_positions(cage.meshadjust.edited.data)
    assert np.abs(got - V).max() <= 1e-5 * np.linalg.norm(np.ptp(V, axis=0))    # float32 in Blender


def test_a_missed_target_is_a_warning_with_the_cores_reason(scene):
    V, F = torus()
    obj = make_object("torus", V, F)
    cage, report = mod("api").simplify_object(obj, target_faces=4, fit=False, bind=False)
    assert report.level == 'WARNING' and len(cage.data.polygons) > 4
    assert f"stopped at {len(cage.data.polygons)} faces of 4 asked" in report.message
    assert report.warnings and "WARNING" in cage.meshadjust.last_report


def test_a_lock_group_that_holds_the_cage_short_is_named_in_the_warning(scene):
    # the upper half locked: the cage stops far above its target, and the warning says the
    # locked vertices hold it (it had blamed the geometry: "every collapse left would fold")
    V, F = icosphere(3)
    obj = make_object("sphere", V, F)
    obj.vertex_groups.new(name="pinned").add(np.flatnonzero(V[:, 2] > 0).tolist(), 1.0, 'REPLACE')
    cage, report = mod("api").simplify_object(obj, target_faces=50, lock_group="pinned",
                                              fit=False, bind=False)
    m = len(cage.data.polygons)
    assert report.level == 'WARNING' and m > 100
    assert f"stopped at {m:,} faces of 50 asked" in report.message
    assert "join two locked vertices (" in report.message and "unlock some to go lower" in \
        report.message
    assert "WARNING" in cage.meshadjust.last_report


def test_a_cage_of_slivers_is_a_warning_saying_what_to_do(scene):
    V, F = cad_cylinder(600)                # sides one row of long thin triangles
    obj = make_object("cylinder", V, F)
    cage, report = mod("api").simplify_object(obj, target_faces=200, fit=False, bind=False)
    assert report.level == 'WARNING' and len(cage.data.polygons) == 200
    assert "faces are slivers" in report.message and "remesh the input" in report.message
    assert "WARNING" in cage.meshadjust.last_report


def _job(stopped, m, target, message):
    res = SimpleNamespace(F=np.zeros((m, 3)), stopped_because=stopped, target=target,
                          message=message)
    return SimpleNamespace(result=res, params=SimpleNamespace(target_faces=target, ratio=None),
                           F=np.zeros((2053, 3)))


def test_topology_floor_is_said_and_a_warning_only_beyond_five_percent(addon):
    api = mod("simplify_step")
    msg = ("stopped at 216 faces of 205 asked: the topology floor (23 border loops, 1 component "
           "kept); welded 3 vertices")
    note, missed = api._target_note(_job("topology_floor", 216, 205, msg))
    assert note == ("stopped at 216 faces of 205 asked: the topology floor (23 border loops, "
                    "1 component kept)") and missed
    note, missed = api._target_note(_job("topology_floor", 216, 210, msg))
    assert note.startswith("stopped at 216") and not missed          # 2.9% over: info
    assert api._target_note(_job("target", 205, 205, "2,053 -> 205 faces")) == ("", False)


def test_automatic_levels_and_the_refined_count_in_the_report(scene):
    V, F = bumpy_sphere(4)                          # 5,120 faces
    dense = make_object("dense", V, F)
    assert bpy.ops.meshadjust.simplify(target_mode='FACES', target_faces=300) == {'FINISHED'}
    cage = dense.meshadjust.cage
    assert cage.meshadjust.levels == 2             # 300 * 16 = 4,800: closest to 5,120
    assert "levels 2, automatic" in cage.meshadjust.last_report
    assert bpy.ops.meshadjust.refine(output='REFINED') == {'FINISHED'}
    assert "refined: 4,800 faces, loop x2, about the source's 5,120" in \
        cage.meshadjust.last_report
    # levels chosen by hand, far from the source's count: the report does not say "about"
    assert bpy.ops.meshadjust.refine(output='REFINED', levels=1) == {'FINISHED'}
    assert "refined: 1,200 faces, loop x1, the source has 5,120" in cage.meshadjust.last_report


def test_face_counts_are_said_as_a_reader_says_them(addon):
    about = mod("api").about
    assert [about(n) for n in (5120, 9_999, 10_000, 251_904, 999_499)] == \
        ["5,120", "9,999", "10k", "252k", "999k"]
    assert [about(n) for n in (999_500, 2_000_000, 2_048_000, 1_111_216, 12_600_000)] == \
        ["1M", "2M", "2M", "1.1M", "12.6M"]          # (2,000,000 was "2000k")


def test_vertex_counts_are_said_in_the_singular_for_one(addon):
    vertices = mod("report").vertices
    assert [vertices(0), vertices(1, "cage"), vertices(3_001, "cage")] == \
        ["0 vertices", "1 cage vertex", "3,001 cage vertices"]       # (was "1 cage vertices")


def test_auto_binds_the_edit_at_two_levels_and_refines_at_the_sources_density(scene):
    """Auto levels: the edit bound at most two levels down (fast binds and
    live updates), the refined mesh at the levels closest to the source's
    face count, made from a finer binding in memory that leaves the edit's
    as it was; a re-bind rewrites the refined mesh at those levels too."""
    steps, store, core = mod("cage_steps"), mod("store"), sys.modules[MODULE + ".core"]
    V, F = bumpy_sphere(4)                          # 5,120 faces
    dense = make_object("dense", V, F)
    assert bpy.ops.meshadjust.simplify(target_mode='FACES', target_faces=80) == {'FINISHED'}
    cage = dense.meshadjust.cage
    assert len(cage.data.polygons) == 80 and cage.meshadjust.levels == steps.MAX_EDIT_LEVELS == 2
    assert "levels 2, automatic: refined at 3, closest to the source's faces" in \
        cage.meshadjust.last_report                 # 80 * 64 = 5,120
    edited = cage.meshadjust.edited
    bound = store.load_binding(edited, cage)
    assert bound.levels == 2
    Vc = mio().read_positions(cage.data)
    moved = Vc.copy()
    moved[:3] *= 1.05                               # an edit
    mio().write_positions(cage.data, moved)
    moved = mio().read_positions(cage.data)         # (as the mesh holds it: float32)
    assert bpy.ops.meshadjust.refine(output='BOTH') == {'FINISHED'}
    assert "refined: 5,120 faces, loop x3, about the source's 5,120" in \
        cage.meshadjust.last_report
    # the edit's binding is unchanged (two levels, the same object); the edited original is
    # its deform, the refined mesh a three-level binding's refine of the same rest shape
    assert cage.meshadjust.levels == 2 and store.load_binding(edited, cage) is bound
    D = mio().read_positions(edited.data)
    assert np.array_equal(D, core.deform(bound, moved).astype(np.float32))
    V_rest = store.load_rest(cage)
    finer = core.bind(V, F, V_rest, bound.F_cage, levels=3, scheme="loop",
                      creases=bound.creases)
    refined = cage.meshadjust.refined
    Vr, Fr = mio().read_positions(refined.data), mio().read_triangles(refined.data)[0]
    want = core.refine(finer, moved)
    assert np.array_equal(Fr, want.F)
    assert np.abs(Vr - want.V).max() <= 1e-6 * core.bbox_diagonal(V)
    bound_text = mod("panel").bound_text
    assert bound_text(cage, 0) == "Bound: loop, 2 levels; refined at 3"
    assert bound_text(cage, 2) == "Bound: loop, 2 levels"
    kept = steps._refine_bindings[edited.session_uid][1]
    assert kept.levels == 3 and kept.n_dense == 0   # (kept without its dense vertices)
    assert bpy.ops.meshadjust.refine(output='REFINED') == {'FINISHED'}
    assert steps._refine_bindings[edited.session_uid][1] is kept     # reused, not re-made
    # a re-bind (Auto: the cage's two levels) rewrites the refined mesh at three
    assert bpy.ops.meshadjust.bind(levels=0, scheme='BOUND', keep_edit=True) == {'FINISHED'}
    assert cage.meshadjust.levels == 2 and len(refined.data.polygons) == 5120
    assert np.abs(mio().read_positions(refined.data) - want.V).max() <= \
        1e-6 * core.bbox_diagonal(V)
    # a re-bind cancelled inside the refined mesh's bind leaves both bindings as they were
    job = steps.prepare_cage_job(cage, keep_edit=True)
    assert (job.levels, job.refine_levels) == (2, 3)
    fractions = []
    steps.compute_bind(job, progress=lambda f: fractions.append(f) or f < 0.5)
    assert job.cancelled and job.refine_binding is None and 0.2 < fractions[-1] < 0.9
    assert store.load_binding(edited, cage).levels == 2
    # levels asked for: the edit and the refined mesh at those
    assert bpy.ops.meshadjust.refine(output='REFINED', levels=3) == {'FINISHED'}
    assert cage.meshadjust.levels == 3 and "loop x3" in cage.meshadjust.last_report


def test_a_refine_in_another_scheme_at_auto_levels_binds_its_refined_mesh_beside(scene):
    """Another scheme re-binds the edit (two levels) and, at Auto, the
    refined mesh at its own levels beside it, kept for the next Refine."""
    steps, store = mod("cage_steps"), mod("store")
    dense = make_object("dense", *bumpy_sphere(4))                 # 5,120 faces
    assert bpy.ops.meshadjust.simplify(target_mode='FACES', target_faces=80) == {'FINISHED'}
    cage = dense.meshadjust.cage
    assert cage.meshadjust.refined is None
    assert bpy.ops.meshadjust.refine(output='REFINED', scheme='butterfly') == {'FINISHED'}
    report = cage.meshadjust.last_report
    assert "re-bound from the rest shape (loop x2 -> butterfly x2)" in report
    assert "refined: 5,120 faces, butterfly x3" in report
    bound = store.load_binding(cage.meshadjust.edited, cage)
    assert (bound.levels, bound.scheme) == (2, "butterfly")
    kept = steps.kept_refine_binding(cage.meshadjust.edited.session_uid, bound, 3)
    assert kept is not None and kept.scheme == "butterfly" and kept.n_dense == 0


def test_a_bug_is_not_reported_as_the_users_mistake(scene, monkeypatch):
    V, F = bumpy_sphere(3)
    dense = make_object("dense", V, F)
    assert simplify(200) == {'FINISHED'}
    core = sys.modules[MODULE + ".core"]

    def bug(*args, **kwargs):
        return 1 / 0

    monkeypatch.setattr(core, "bind", bug)
    before = scene_snapshot()
    with pytest.raises(RuntimeError, match="ZeroDivisionError"):   # a traceback, not a report
        bpy.ops.meshadjust.bind(levels=1)
    assert_unchanged(before)
    bpy.context.view_layer.objects.active = dense
    dense.hide_set(False)
    with pytest.raises(RuntimeError, match="ZeroDivisionError"):
        simplify(150)


class _WM:
    def __init__(self):
        self.calls = []

    def event_timer_remove(self, timer):
        self.calls.append("timer_remove")

    def progress_update(self, value):
        self.calls.append(("progress", value))

    def progress_end(self):
        self.calls.append("progress_end")


def _drive_modal(job=None, error=None, cancel=False):
    """Run ``_Background.modal`` on a fake operator (modal never runs headless)."""
    ops = mod("operators")
    reports, finished = [], []
    worker = threading.Thread(target=lambda: None)
    worker.start()
    worker.join()
    fake = SimpleNamespace(_thread=worker, _timer=object(), _job=job, _error=error,
                           _cancel=cancel, _fraction=0.5, bl_label="Bind",
                           report=lambda level, msg: reports.append((level, msg)),
                           finish=lambda context: finished.append(True) or {'FINISHED'})
    wm = _WM()
    context = SimpleNamespace(window_manager=wm, scene=bpy.context.scene, screen=None)
    result = ops._Background.modal(fake, context, SimpleNamespace(type='TIMER'))
    return result, reports, finished, wm


def test_the_background_path_commits_only_a_finished_worker(scene):
    core = sys.modules[MODULE + ".core"]
    result, reports, finished, wm = _drive_modal(job=SimpleNamespace(cancelled=False))
    assert result == {'FINISHED'} and finished and "progress_end" in wm.calls
    assert bpy.context.scene.meshadjust.running is False
    result, reports, finished, _ = _drive_modal(job=SimpleNamespace(cancelled=False), cancel=True)
    assert result == {'CANCELLED'} and not finished and reports[0][0] == {'WARNING'}
    result, reports, finished, _ = _drive_modal(error=core.MeshAdjustError("bad cage"))
    assert result == {'CANCELLED'} and reports == [({'ERROR'}, "bad cage")] and not finished
    with pytest.raises(ZeroDivisionError):
        _drive_modal(error=ZeroDivisionError("a bug"))
    ops = mod("operators")
    for cls in (ops.MESHADJUST_OT_simplify, ops.MESHADJUST_OT_fit_cage, ops.MESHADJUST_OT_bind):
        assert issubclass(cls, ops._Background) and hasattr(cls, "invoke")
