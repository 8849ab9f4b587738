"""MeshAdjust's geometry core: pure NumPy, no Blender.

Meshes are ``V`` (n,3) float64 and ``F`` (m,3) int64. Functions never modify
their inputs; results are named tuples or dataclasses. Only relative imports,
so the package works both as ``core`` in tests and inside the installed
extension (``bl_ext.<repo>.meshadjust.core``).
"""

from .errors import InvalidArgumentError, InvalidMeshError, MeshAdjustError, TopologyMismatchError
from .mesh import bbox_diagonal, check_mesh, enclosed_volume, face_areas, face_normals, vertex_normals
from .topology import EdgeMap, edge_map, manifold_report, topology_summary, euler_characteristic

__all__ = [
    "MeshAdjustError", "InvalidMeshError", "InvalidArgumentError", "TopologyMismatchError",
    "check_mesh", "bbox_diagonal", "enclosed_volume", "face_areas", "face_normals", "vertex_normals",
    "EdgeMap", "edge_map", "manifold_report", "topology_summary", "euler_characteristic",
]
