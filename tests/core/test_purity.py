"""core/ is pure NumPy: no bpy, bmesh, mathutils or scipy, relative imports only."""

import ast
import os
import subprocess
import sys

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
CORE = os.path.join(ROOT, "core")
FORBIDDEN = {"bpy", "bmesh", "mathutils", "scipy", "bpy_extras", "gpu"}


def core_sources():
    return sorted(os.path.join(CORE, f) for f in os.listdir(CORE) if f.endswith(".py"))


@pytest.mark.parametrize("path", core_sources(), ids=os.path.basename)
def test_core_module_imports_only_numpy_stdlib_and_itself(path):
    tree = ast.parse(open(path, encoding="utf-8").read(), filename=path)
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                top = alias.name.split(".")[0]
                assert top not in FORBIDDEN, f"{path}:{node.lineno} imports {alias.name}"
                assert top != "core", f"{path}:{node.lineno}: use a relative import"
        elif isinstance(node, ast.ImportFrom):
            if node.level == 0:
                top = (node.module or "").split(".")[0]
                assert top not in FORBIDDEN, f"{path}:{node.lineno} imports {node.module}"
                assert top != "core", f"{path}:{node.lineno}: use a relative import"


#: NumPy 2.3+ finds these values with a hash table, 10-75x slower than the sort NumPy 1.x
#: used (np.unique of 2M int64: 1.36 s against 0.018): core/_groups.sorted_unique and
#: member_of sort instead (np.unique with return_index / _inverse / _counts or axis sorts)
HASHED = {"union1d", "setdiff1d", "intersect1d", "setxor1d", "isin", "in1d", "unique_values"}


@pytest.mark.parametrize("path", core_sources(), ids=os.path.basename)
def test_core_never_calls_numpys_hashed_set_operations(path):
    tree = ast.parse(open(path, encoding="utf-8").read(), filename=path)
    for node in ast.walk(tree):
        if not (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
                and isinstance(node.func.value, ast.Name) and node.func.value.id == "np"):
            continue
        name, flags = node.func.attr, {k.arg for k in node.keywords}
        assert name not in HASHED, f"{path}:{node.lineno}: np.{name} (use _groups.member_of)"
        if name == "unique" and os.path.basename(path) != "_groups.py":
            assert flags & {"return_index", "return_inverse", "return_counts", "axis"}, \
                f"{path}:{node.lineno}: a plain np.unique (use _groups.sorted_unique)"


def test_core_imports_with_blender_modules_blocked():
    """Import core (and every submodule) in a fresh interpreter where bpy,
    bmesh, mathutils and scipy cannot be imported."""
    code = f"""
import importlib, pkgutil, sys
class Block:
    def find_spec(self, name, path=None, target=None):
        if name.split('.')[0] in {sorted(FORBIDDEN)!r}:
            raise ImportError('blocked: ' + name)
        return None
sys.meta_path.insert(0, Block())
sys.path.insert(0, {ROOT!r})
import core
for mod in pkgutil.iter_modules(core.__path__):
    importlib.import_module('core.' + mod.name)
bad = sorted(m for m in sys.modules if m.split('.')[0] in {sorted(FORBIDDEN)!r})
print('LOADED', bad)
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    assert "LOADED []" in out.stdout


def test_public_api_is_reexported():
    import core
    for name in ("simplify", "SimplifyResult", "subdivide", "subdivision_operator",
                 "fit_cage", "bind", "deform", "refine", "Binding", "surface_distance",
                 "TriangleIndex", "InvalidMeshError", "MeshAdjustError"):
        assert hasattr(core, name), name
