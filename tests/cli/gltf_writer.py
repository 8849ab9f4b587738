"""glTF files for the tests, written by Blender's own exporter in a process
of its own (bpy stays out of the test process)."""

import os
import subprocess
import sys

import numpy as np

_SCRIPT = """
import sys
import numpy as np
import bpy
data = np.load(sys.argv[1])
bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
me = bpy.data.meshes.new("mesh")
me.from_pydata(data["V"].tolist(), [], data["F"].tolist())
ob = bpy.data.objects.new("mesh", me)
ob.location = data["location"].tolist()
bpy.context.scene.collection.objects.link(ob)
ob.select_set(True)
path = sys.argv[2]
bpy.ops.export_scene.gltf(filepath=path, use_selection=True, export_yup=False,
                          export_format="GLB" if path.endswith(".glb") else "GLTF_SEPARATE")
"""


def write_gltf(path, V, F, *, translation=(0.0, 0.0, 0.0)):
    """A ``.gltf`` (with its ``.bin`` beside it) or ``.glb`` file holding the
    mesh ``V``, ``F`` as given, in the file's own (Y-up) coordinates (no turn
    from Blender's Z-up), its node moved by ``translation``."""
    arrays = os.path.join(os.path.dirname(path), ".gltf_writer.npz")
    np.savez(arrays, V=np.asarray(V, float), F=np.asarray(F, int),
             location=np.asarray(translation, float))
    env = dict(os.environ, HOME=os.path.dirname(path),
               BLENDER_USER_RESOURCES=os.path.dirname(path))
    try:
        subprocess.run([sys.executable, "-c", _SCRIPT, arrays, str(path)], check=True,
                       capture_output=True, env=env, timeout=120)
    finally:
        os.remove(arrays)
