"""Symmetry on the simplify operator (Decimate's use_symmetry / symmetry_axis):
a symmetric Suzanne gives a mirror-symmetric cage, an asymmetric scan still
binds and round-trips."""

import sys

import bpy
import numpy as np

from tests.addon.conftest import MODULE


def mio():
    return sys.modules[MODULE + ".meshadjust_addon.mesh_io"]


def suzanne(seed=None):
    """Suzanne, subdivided once (Catmull-Clark, applied), with bumps that are
    even in x; ``seed`` jitters the -x side (an asymmetric scan)."""
    bpy.ops.mesh.primitive_monkey_add(size=2.0)
    obj = bpy.context.active_object
    mod = obj.modifiers.new("subsurf", 'SUBSURF')
    mod.levels = 1
    me = bpy.data.meshes.new_from_object(obj.evaluated_get(bpy.context.evaluated_depsgraph_get()))
    obj.modifiers.remove(mod)
    old, obj.data = obj.data, me
    bpy.data.meshes.remove(old)
    V = mio().read_positions(me)
    V *= (1.0 + 0.04 * np.cos(9 * V[:, 0]) * np.cos(7 * V[:, 1]) * np.cos(5 * V[:, 2]))[:, None]
    if seed is not None:
        neg = V[:, 0] < -0.05
        V[neg] += 0.01 * np.random.default_rng(seed).standard_normal((int(neg.sum()), 3))
    me.vertices.foreach_set("co", V.astype(np.float32).ravel())
    me.update()
    return obj


def simplify(**kw):
    return bpy.ops.meshadjust.simplify(target_mode='FACES', target_faces=500, fit=True, bind=True,
                                       levels=2, use_symmetry=True, symmetry_axis='X', **kw)


def assert_mirror_symmetric(core, cage):
    V = mio().read_positions(cage.data)
    F = mio().read_triangles(cage.data)[0]
    sym = sys.modules[MODULE + ".core.mirror"]
    p = sym.mirror_partners(V, 'X', tolerance=1e-6)      # raises when a vertex has none
    assert np.array_equal(sym.mirror(V, 0)[p], V)         # exactly (float32 negates exactly)
    assert np.all(V[p == np.arange(V.shape[0]), 0] == 0.0) and (p == np.arange(V.shape[0])).any()
    n = np.int64(V.shape[0])

    def directed(F):
        h = F[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
        return np.sort(h[:, 0] * n + h[:, 1])

    assert np.array_equal(directed(F), directed(p[F][:, [0, 2, 1]]))
    assert core.manifold_report(F, V.shape[0]).is_oriented_manifold
    return V, F


def test_symmetric_suzanne_gives_a_mirror_symmetric_cage(scene, core):
    src = suzanne()
    assert simplify() == {'FINISHED'}
    cage = src.meshadjust.cage
    V, F = assert_mirror_symmetric(core, cage)
    assert 450 <= F.shape[0] <= 500
    assert "mirror-symmetric in X" in cage.meshadjust.last_report
    # the same Euler characteristic as the cage without symmetry
    Vs = mio().read_positions(src.data)
    Fs = mio().read_triangles(src.data)[0]
    plain = core.simplify(Vs, Fs, target_faces=500)
    assert core.euler_characteristic(F) == core.euler_characteristic(plain.F)


def test_asymmetric_scan_with_symmetry_binds_and_round_trips(scene, core):
    src = suzanne(seed=3)
    assert simplify() == {'FINISHED'}
    cage = src.meshadjust.cage
    assert_mirror_symmetric(core, cage)
    assert cage.meshadjust.edited is not None and "bound" in cage.meshadjust.last_report
    assert bpy.ops.meshadjust.refine(output='EDITED') == {'FINISHED'}
    V0 = mio().read_positions(src.data)
    V1 = mio().read_positions(cage.meshadjust.edited.data)
    assert np.abs(V1 - V0).max() < 1e-5                   # float32 storage of positions and binding
    # an X-mirror edit of the cage moves both sides of the result alike
    Vc = mio().read_positions(cage.data)
    sym = sys.modules[MODULE + ".core.mirror"]
    p = sym.mirror_partners(Vc, 'X')
    i = int(np.argmax(Vc[:, 0]))
    Vc[[i, p[i]], 2] += 0.1
    cage.data.vertices.foreach_set("co", Vc.astype(np.float32).ravel())
    cage.data.update()
    assert bpy.ops.meshadjust.refine(output='EDITED') == {'FINISHED'}
    V2 = mio().read_positions(cage.meshadjust.edited.data)
    moved = np.linalg.norm(V2 - V0, axis=1)
    assert moved[V0[:, 0] > 0].max() > 0.02 and moved[V0[:, 0] < 0].max() > 0.02


def test_fit_button_keeps_a_symmetric_cage_symmetric(scene, core):
    src = suzanne(seed=5)
    assert bpy.ops.meshadjust.simplify(target_mode='FACES', target_faces=500, fit=False, bind=True,
                                       levels=2, use_symmetry=True, symmetry_axis='X') == {'FINISHED'}
    cage = src.meshadjust.cage
    assert cage.meshadjust.symmetry == 'X'
    bpy.context.view_layer.objects.active = cage
    for _ in range(2):                               # a fit, then a fit of the fitted cage
        assert bpy.ops.meshadjust.fit_cage() == {'FINISHED'}
        assert_mirror_symmetric(core, cage)
