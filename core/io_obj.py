"""A small, fast Wavefront OBJ reader and writer (positions and faces only).

Used by tests, benchmarks and the demo when Blender is not at hand; inside
Blender the add-on uses Blender's own importers. Polygons are fan-triangulated
(``v0 v1 v2``, ``v0 v2 v3`` ...); texture and normal indices (``v/vt/vn``) are
ignored; negative (relative) indices are resolved.
"""

import numpy as np

from .errors import InvalidMeshError


def read_obj(path):
    """Read an OBJ file.

    Returns
    -------
    V : (n,3) float64
    F : (m,3) int64, fan-triangulated.
    """
    verts = []
    tris = []
    with open(path, "r", encoding="utf-8", errors="replace") as fh:
        for lineno, line in enumerate(fh, 1):
            if line.startswith("v "):
                parts = line.split()
                verts.append(parts[1:4])
            elif line.startswith("f "):
                idx = []
                for tok in line.split()[1:]:
                    i = int(tok.split("/")[0])
                    idx.append(i - 1 if i > 0 else len(verts) + i)
                if len(idx) < 3:
                    raise InvalidMeshError(f"read_obj: {path}:{lineno}: a face needs 3 vertices")
                for k in range(1, len(idx) - 1):
                    tris.append((idx[0], idx[k], idx[k + 1]))
    V = np.array(verts, dtype=np.float64).reshape(-1, 3)
    F = np.array(tris, dtype=np.int64).reshape(-1, 3)
    return V, F


def write_obj(path, V, F):
    """Write positions and triangles to an OBJ file."""
    V = np.asarray(V, dtype=np.float64)
    F = np.asarray(F, dtype=np.int64)
    with open(path, "w", encoding="utf-8") as fh:
        fh.write("# written by MeshAdjust\n")
        np.savetxt(fh, V, fmt="v %.9g %.9g %.9g")
        np.savetxt(fh, F + 1, fmt="f %d %d %d")
