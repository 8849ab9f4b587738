"""The built extension: contents, validation, registration, install and run."""

import json
import os
import subprocess
import sys
import tempfile
import textwrap
import tomllib
import zipfile

import bpy

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def test_manifest_fields():
    with open(os.path.join(ROOT, "blender_manifest.toml"), "rb") as fh:
        m = tomllib.load(fh)
    assert m["schema_version"] == "1.0.0"
    assert m["id"] == "meshadjust"
    assert m["type"] == "add-on"
    assert m["blender_version_min"] == "4.2.0"
    assert m["license"] == ["SPDX:GPL-3.0-or-later"]
    assert len(m["tagline"]) <= 64 and not m["tagline"].endswith(".")
    assert set(m["tags"]) <= {"Mesh", "Modeling"}
    assert "permissions" not in m
    major, minor, patch = (int(x) for x in m["version"].split("."))
    with open(os.path.join(ROOT, "pyproject.toml"), "rb") as fh:
        assert tomllib.load(fh)["project"]["version"] == m["version"]


def test_zip_holds_only_the_addon(built_zip):
    with open(os.path.join(ROOT, "blender_manifest.toml"), "rb") as fh:
        version = tomllib.load(fh)["version"]
    assert os.path.basename(built_zip) == f"meshadjust-{version}.zip"
    with zipfile.ZipFile(built_zip) as zf:
        names = zf.namelist()
    tops = {n.split("/")[0] for n in names}
    assert tops == {"__init__.py", "blender_manifest.toml", "LICENSE", "core", "meshadjust_addon"}
    assert not [n for n in names if "__pycache__" in n or n.endswith(".pyc")]
    assert "core/simplify.py" in names and "meshadjust_addon/operators.py" in names


def test_addon_registers_every_operator(addon):
    for op in ("simplify", "fit_cage", "bind", "refine", "subdivide", "edit_cage"):
        assert hasattr(bpy.ops.meshadjust, op)
        assert getattr(bpy.ops.meshadjust, op).get_rna_type().name
    assert hasattr(bpy.types, "MESHADJUST_PT_main")
    assert "meshadjust" in bpy.types.Object.bl_rna.properties


def test_scene_reset_keeps_addon(scene):
    assert hasattr(bpy.ops.meshadjust, "simplify")
    assert len(bpy.data.objects) == 0


INSTALL_SCRIPT = textwrap.dedent("""
    import json, sys
    import bpy
    zip_path = sys.argv[1]
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    bpy.ops.extensions.package_install_files(filepath=zip_path, repo="user_default",
                                             enable_on_install=True)
    import addon_utils
    enabled = [m.__name__ for m in addon_utils.modules() if addon_utils.check(m.__name__)[1]]
    bpy.ops.mesh.primitive_ico_sphere_add(subdivisions=2)
    obj = bpy.context.active_object
    n_faces = len(obj.data.polygons)
    result = bpy.ops.meshadjust.subdivide(levels=1, scheme='butterfly')
    out = [o for o in bpy.data.objects if o is not obj][0]
    print("RESULT " + json.dumps({"enabled": enabled, "result": sorted(result),
                                  "faces_in": n_faces, "faces_out": len(out.data.polygons),
                                  "module": type(bpy.ops.meshadjust.subdivide).__module__}))
    sys.stdout.flush()
    import os
    os._exit(0)  # bpy 4.2 as a module can crash while the interpreter shuts down
""")


def test_install_zip_and_run_operator(built_zip, tmp_path):
    """Install the built zip into a fresh user repository in a fresh Blender
    process and run one of its operators on a real object."""
    script = tmp_path / "install.py"
    script.write_text(INSTALL_SCRIPT)
    user = tempfile.mkdtemp(dir=tmp_path)
    env = dict(os.environ, HOME=user, BLENDER_USER_RESOURCES=user)
    env.pop("BLENDER_USER_SCRIPTS", None)
    env.pop("BLENDER_USER_CONFIG", None)
    proc = subprocess.run([sys.executable, str(script), built_zip], capture_output=True,
                          text=True, env=env, timeout=300)
    lines = [l for l in proc.stdout.splitlines() if l.startswith("RESULT ")]
    assert proc.returncode == 0 and lines, proc.stdout + proc.stderr
    res = json.loads(lines[-1][len("RESULT "):])
    assert "bl_ext.user_default.meshadjust" in res["enabled"]
    assert res["result"] == ["FINISHED"]
    assert res["faces_out"] == 4 * res["faces_in"]
