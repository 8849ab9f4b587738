"""MeshAdjust's geometry core: pure NumPy, no Blender.

Meshes are ``V`` (n,3) float64 and ``F`` (m,3) int64. Functions never modify
their inputs; results are named tuples or dataclasses. Only relative imports,
so the package works both as ``core`` in tests and inside the installed
extension (``bl_ext.<repo>.meshadjust.core``).

The public API (one module per algorithm family):

==========================  ==============================================
``clean_mesh``              any mesh as scans arrive -> a clean manifold
``simplify``                QEM edge collapse to a clean manifold cage
``subdivide``               modified butterfly / Loop subdivision
``subdivision_operator``    the same as a reusable linear operator
``simplify_symmetric``      the same, mirror-symmetric (``simplify(symmetry=)``)
``mirror_partners``         each vertex's mirror image (``symmetrize``: exact)
``fit_cage``                cage positions whose subdivision fits a surface
``bind`` / ``deform``       carry a dense mesh (and its detail) on a cage
``refine``                  the subdivided edited cage with the detail
``bind_refined``            a binding's detail at other levels, for refine
``TriangleIndex``           exact closest points on a triangle mesh
``surface_distance``        two-sided Hausdorff / mean / RMS (Metro)
``DistanceFrom``            the same from one mesh to many (its index kept)
==========================  ==============================================
"""

from .errors import (CancelledError, InvalidArgumentError, InvalidMeshError, MeshAdjustError,
                     TopologyMismatchError)
from .mesh import (bbox_diagonal, check_mesh, enclosed_volume, face_areas, face_normals,
                   surface_diagonal, turned_faces, vertex_normals)
from .topology import EdgeMap, edge_map, euler_characteristic, manifold_report, topology_summary
from .io_mesh import MeshFile, read_mesh, read_obj, read_smf, write_mesh, write_obj, write_smf
from .spatial import ClosestPoints, TriangleIndex, closest_points
from .metrics import DistanceFrom, SurfaceDistance, percent, sample_surface, surface_distance
from .subdivide import SubdivisionOperator, SubdivisionResult, subdivide, subdivision_operator
from .clean import CleanedInput, CleanReport, CleanResult, clean_mesh
from .simplify import SimplifyResult, simplify
from .mirror import mirror_partners, symmetrize
from .symmetry import simplify_symmetric
from .fit import MAX_FIT_LEVELS, FitResult, fit_cage
from .binding import SEED_LEVELS, Binding, RefineResult, bind, bind_refined, deform, refine

__all__ = [
    "MeshAdjustError", "InvalidMeshError", "InvalidArgumentError", "TopologyMismatchError",
    "CancelledError",
    "check_mesh", "bbox_diagonal", "surface_diagonal", "enclosed_volume", "face_areas", "face_normals",
    "vertex_normals", "turned_faces", "EdgeMap", "edge_map", "manifold_report", "topology_summary",
    "euler_characteristic", "read_obj", "write_obj", "read_smf", "write_smf", "read_mesh",
    "write_mesh", "MeshFile",
    "TriangleIndex", "ClosestPoints", "closest_points",
    "surface_distance", "DistanceFrom", "SurfaceDistance", "sample_surface", "percent",
    "subdivide", "subdivision_operator", "SubdivisionOperator", "SubdivisionResult",
    "clean_mesh", "CleanResult", "CleanReport", "simplify", "SimplifyResult", "CleanedInput",
    "simplify_symmetric", "mirror_partners", "symmetrize", "fit_cage", "FitResult",
    "MAX_FIT_LEVELS",
    "bind", "bind_refined", "deform", "refine", "Binding", "RefineResult", "SEED_LEVELS",
]
