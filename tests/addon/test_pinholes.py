"""Simplify's Close pinholes (close_pinholes) through the operator: a scan with
300 one-triangle holes reaches its target and the report counts the caps; off,
the holes stay and the report says the cage stopped short, and why."""

import bpy

from tests.addon.conftest import make_object
from tests.core.test_pinholes import without
from tests.mesh_factory import apart_faces, icosphere


def test_close_pinholes_reaches_the_target_and_off_keeps_the_holes(scene):
    V, F = icosphere(4)
    obj = make_object("holed", V, without(F, apart_faces(F, 300, seed=2)))
    assert bpy.ops.meshadjust.simplify(target_mode='FACES', target_faces=60, fit=False,
                                       bind=False) == {'FINISHED'}
    cage = obj.meshadjust.cage
    assert len(cage.data.polygons) <= 60
    assert "closed 300 pinholes (300 faces)" in cage.meshadjust.last_report
    bpy.context.view_layer.objects.active = obj
    obj.hide_set(False)
    assert bpy.ops.meshadjust.simplify(target_mode='FACES', target_faces=60, fit=False,
                                       bind=False, close_pinholes=False) == {'FINISHED'}
    cage = obj.meshadjust.cage
    n = len(cage.data.polygons)
    assert n > 60
    report = cage.meshadjust.last_report
    assert f"stopped at {n:,} faces of 60 asked" in report and "300 border loops" in report
    assert "pinholes" not in report
