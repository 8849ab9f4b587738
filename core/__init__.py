"""MeshAdjust's geometry core: pure NumPy, no Blender.

Meshes are ``V`` (n,3) float64 and ``F`` (m,3) int64. Functions never modify
their inputs; results are named tuples or dataclasses. Only relative imports,
so the package works both as ``core`` in tests and inside the installed
extension (``bl_ext.<repo>.meshadjust.core``).

The public API (one module per algorithm family):

==========================  ==============================================
``simplify``                QEM edge collapse to a clean manifold cage
``subdivide``               modified butterfly / Loop subdivision
``subdivision_operator``    the same as a reusable linear operator
``fit_cage``                cage positions whose subdivision fits a surface
``bind`` / ``deform``       carry a dense mesh (and its detail) on a cage
``refine``                  the subdivided edited cage with the detail
``TriangleIndex``           exact closest points on a triangle mesh
``surface_distance``        two-sided Hausdorff / mean / RMS (Metro)
==========================  ==============================================

Algorithm modules are imported on first use of their names, so ``import
core`` stays cheap and a caller pays only for what it uses.
"""

import importlib

from .errors import InvalidArgumentError, InvalidMeshError, MeshAdjustError, TopologyMismatchError
from .mesh import (bbox_diagonal, check_mesh, enclosed_volume, face_areas, face_normals,
                   vertex_normals)
from .topology import EdgeMap, edge_map, euler_characteristic, manifold_report, topology_summary

#: public name -> module that defines it
_LAZY = {
    "simplify": ".simplify", "SimplifyResult": ".simplify",
    "subdivide": ".subdivide", "subdivision_operator": ".subdivide",
    "SubdivisionOperator": ".subdivide", "SubdivisionResult": ".subdivide",
    "fit_cage": ".fit", "FitResult": ".fit",
    "bind": ".binding", "deform": ".binding", "refine": ".binding", "Binding": ".binding",
    "RefineResult": ".binding",
    "TriangleIndex": ".spatial", "closest_points": ".spatial", "ClosestPoints": ".spatial",
    "surface_distance": ".metrics", "SurfaceDistance": ".metrics", "sample_surface": ".metrics",
    "read_obj": ".io_obj", "write_obj": ".io_obj",
}

__all__ = [
    "MeshAdjustError", "InvalidMeshError", "InvalidArgumentError", "TopologyMismatchError",
    "check_mesh", "bbox_diagonal", "enclosed_volume", "face_areas", "face_normals",
    "vertex_normals", "EdgeMap", "edge_map", "manifold_report", "topology_summary",
    "euler_characteristic", *_LAZY,
]


def __getattr__(name):
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(module, __name__), name)
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(_LAZY))
