"""Shared pieces of the benchmark scripts (``scripts/bench_*.py``).

Blender objects are made and read with the add-on's own fast mesh transfer
(``meshadjust_addon.mesh_io``), so the benchmarks time the same code the
add-on runs; test meshes come from ``tests/mesh_factory``.
"""

import ctypes
import glob
import os
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
for path in (ROOT, os.path.join(ROOT, "scripts")):
    if path not in sys.path:
        sys.path.insert(0, path)

SHARED_MESHES = os.path.normpath(os.path.join(ROOT, "..", "shared", "meshes"))

#: OpenBLAS's kernel sets for the CPU's widest vectors (``OPENBLAS_CORETYPE`` names), the
#: widest first, with the /proc/cpuinfo flags each needs
BLAS_KERNELS = (("SkylakeX", {"avx512f", "avx512bw", "avx512dq", "avx512vl", "avx512cd"}),
                ("Haswell", {"avx2", "fma"}))

#: OpenBLAS kernel sets for AVX2 or wider: no hint when NumPy runs one of these
WIDE_KERNELS = {"Haswell", "Zen", "SkylakeX", "Cooperlake", "SapphireRapids"}


def mesh_io():
    """The add-on's mesh transfer module (registers the add-on once)."""
    from meshadjust_batch import load_package
    return load_package().meshadjust_addon.mesh_io


def empty_scene():
    """An empty Blender scene; returns ``bpy``."""
    import bpy
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    return bpy


def blender_object(name, V, F):
    """A new mesh object from core arrays, linked to the scene."""
    import bpy
    ob = bpy.data.objects.new(name, mesh_io().new_mesh(name, V, F))
    bpy.context.scene.collection.objects.link(ob)
    return ob


def evaluated_arrays(ob):
    """``(V, F)`` of the object with its modifiers applied (local space)."""
    arrays = mesh_io().read_object(ob, evaluated=True)
    return arrays.V, arrays.F


def evaluated_positions(ob):
    """(n,3) positions of the object with its modifiers applied: evaluating
    the depsgraph is what runs a modifier, so this is what gets timed."""
    import bpy
    ev = ob.evaluated_get(bpy.context.evaluated_depsgraph_get())
    return mesh_io().read_positions(ev.data)


def blas_kernels():
    """The kernel set NumPy's OpenBLAS runs on this CPU (its own name for it:
    ``"SkylakeX"``, ``"Haswell"``, ``"Prescott"``...), or None when NumPy's
    BLAS is not an OpenBLAS that says. An OpenBLAS older than the CPU falls
    back to old kernels: NumPy 1.26.4's (0.3.23) runs Prescott's (SSE3) on a
    Sapphire Rapids virtual machine where NumPy 2.4's picks SkylakeX, and its
    float32 products of the bind's tile bounds take 5-7x as long."""
    import numpy
    libs = os.path.join(os.path.dirname(os.path.dirname(numpy.__file__)), "numpy.libs")
    for path in sorted(glob.glob(os.path.join(libs, "*openblas*.so*"))):
        lib = ctypes.CDLL(path)         # the library NumPy has loaded: the same handle
        for name in ("openblas_get_corename64_", "scipy_openblas_get_corename64_",
                     "openblas_get_corename"):
            corename = getattr(lib, name, None)
            if corename is not None:
                corename.restype = ctypes.c_char_p
                return corename().decode()
    return None


def cpu_fields():
    """The first processor's fields of /proc/cpuinfo (name -> value; empty
    where there is none)."""
    fields = {}
    try:
        with open("/proc/cpuinfo") as fh:
            for row in fh:
                if not row.strip():
                    break
                name, _, value = row.partition(":")
                fields[name.strip()] = value.strip()
    except OSError:
        pass
    return fields


def cpu_name(fields):
    """The CPU as a benchmark's header names it: its model name, family and
    model numbers (a model name such as "AMD EPYC" says nothing of the
    generation: family 25 model 17 is a Zen 4), or "unknown CPU"."""
    if not fields.get("model name"):
        return "unknown CPU"
    return (f"{fields['model name']} (family {fields.get('cpu family', '?')}, "
            f"model {fields.get('model', '?')})")


def blas_line():
    """One line for a benchmark's header: the CPU (:func:`cpu_name`), NumPy's
    version, the BLAS kernels it runs and, when they are older than the
    CPU's widest vectors, the ``OPENBLAS_CORETYPE`` that gives the CPU's own."""
    import numpy
    kernels = blas_kernels()
    fields = cpu_fields()
    line = (f"{cpu_name(fields)}; NumPy {numpy.__version__}, OpenBLAS kernels "
            f"{kernels or 'unknown'}")
    flags = set(fields.get("flags", "").split())
    if not flags:
        return line
    best = next((name for name, need in BLAS_KERNELS if need <= flags), None)
    if best and kernels and kernels not in WIDE_KERNELS:
        line += (f" (older than this CPU's: OPENBLAS_CORETYPE={best} before starting "
                 "Python gives its own)")
    return line
