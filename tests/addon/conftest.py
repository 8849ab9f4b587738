"""Headless Blender (the bpy module) fixtures.

Blender's user folders point at a temporary directory before bpy is
imported, so no user configuration is read or written. The session fixture
builds the extension zip with Blender's own tool, unpacks it into the
temporary user extension repository exactly as an install would, and enables
it with ``addon_utils``; each test starts from an empty scene.
"""

import os
import sys
import tempfile
import zipfile

import pytest

_USER = tempfile.mkdtemp(prefix="meshadjust-blender-user-")
os.environ["HOME"] = _USER
os.environ["BLENDER_USER_RESOURCES"] = _USER
os.environ["BLENDER_USER_CONFIG"] = os.path.join(_USER, "config")
os.environ["BLENDER_USER_SCRIPTS"] = os.path.join(_USER, "scripts")

bpy = pytest.importorskip("bpy", reason="the bpy module is not installed (run scripts/setup "
                                        "and use .venv/bin/python)")

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
MODULE = "bl_ext.user_default.meshadjust"


def pytest_collection_modifyitems(items):
    for item in items:
        item.add_marker(pytest.mark.blender)


@pytest.fixture(scope="session")
def built_zip(tmp_path_factory):
    """The extension zip, built and validated by Blender's own tool."""
    sys.path.insert(0, os.path.join(ROOT, "scripts"))
    try:
        import build_extension
    finally:
        sys.path.pop(0)
    return build_extension.build(str(tmp_path_factory.mktemp("dist")))


@pytest.fixture(scope="session")
def addon(built_zip):
    """The add-on package as Blender imports it (``bl_ext.user_default.meshadjust``)."""
    import addon_utils
    repo_dir = bpy.utils.user_resource('EXTENSIONS', path="user_default", create=True)
    target = os.path.join(repo_dir, "meshadjust")
    with zipfile.ZipFile(built_zip) as zf:
        zf.extractall(target)
    bpy.ops.extensions.repo_refresh_all()
    mod = addon_utils.enable(MODULE, default_set=True, handle_error=_raise)
    assert mod is not None, f"could not enable {MODULE}"
    yield sys.modules[MODULE]
    addon_utils.disable(MODULE, default_set=True)


def _raise(exc):
    raise exc


@pytest.fixture()
def scene(addon):
    """An empty scene with the add-on enabled."""
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    return bpy.context.scene


@pytest.fixture()
def core(addon):
    """The core package as imported inside the installed extension."""
    return sys.modules[MODULE + ".core"]


def make_object(name, V, F, *, scene=None):
    """Link a new mesh object built from core arrays and make it active."""
    import numpy as np
    mesh_io = sys.modules[MODULE + ".meshadjust_addon.mesh_io"]
    mesh = mesh_io.new_mesh(name, np.asarray(V), np.asarray(F))
    obj = bpy.data.objects.new(name, mesh)
    (scene or bpy.context.scene).collection.objects.link(obj)
    for o in bpy.context.view_layer.objects:
        o.select_set(False)
    obj.select_set(True)
    bpy.context.view_layer.objects.active = obj
    return obj


_exit_status = 0


def pytest_sessionfinish(session, exitstatus):
    global _exit_status
    _exit_status = int(exitstatus)


@pytest.hookimpl(trylast=True)
def pytest_unconfigure(config):
    """bpy as a module (4.2 in particular) can crash while the interpreter
    shuts down, after every result is written: leave with pytest's own status."""
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(_exit_status)
