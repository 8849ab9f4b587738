"""Simplify's Max bend (max_dihedral_deg) through the operator."""

import sys

import bpy
import numpy as np

from tests.addon.conftest import MODULE, make_object
from tests.mesh_factory import bend_angles_deg, icosphere


def mio():
    return sys.modules[MODULE + ".meshadjust_addon.mesh_io"]


def test_max_bend_stops_the_cage_early_and_the_report_says_why(scene):
    V, F = icosphere(4)
    obj = make_object("ball", V, F)
    assert bpy.ops.meshadjust.simplify(target_mode='FACES', target_faces=60, fit=False, bind=False,
                                       max_dihedral_deg=20.0) == {'FINISHED'}
    cage = obj.meshadjust.cage
    n = len(cage.data.polygons)
    assert n > 60
    report = cage.meshadjust.last_report
    assert "dihedral" in report and f"stopped at {n:,} faces of 60 asked" in report
    # every pair of adjacent cage faces bends by at most 20 degrees
    Vc = mio().read_positions(cage.data).astype(np.float64)
    Fc = mio().read_triangles(cage.data)[0]
    assert bend_angles_deg(Vc, Fc).max() <= 20.0 + 1e-4
    # off (180, the default) reaches the target
    bpy.context.view_layer.objects.active = obj
    obj.hide_set(False)
    assert bpy.ops.meshadjust.simplify(target_mode='FACES', target_faces=60, fit=False,
                                       bind=False) == {'FINISHED'}
    assert len(obj.meshadjust.cage.data.polygons) == 60
