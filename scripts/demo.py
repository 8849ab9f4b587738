#!/usr/bin/env python3
"""The MeshAdjust story, headless, end to end (run through ``scripts/demo``).

1. A dense mesh with real detail: Blender's Suzanne, Catmull-Clark level 4
   and a noise displacement (about 250k triangles), or a file you pass.
2. Simplify it to a cage, fit the cage, bind the dense mesh to it.
3. A scripted edit: a handful of cage vertices at the top of the head are
   pulled up and back with a smooth falloff.
4. Refine both ways: the *edited original* (the dense mesh deformed, same
   topology) and the *refined mesh* (the subdivided cage with the detail).
5. Write ``out/``: ``demo.blend`` with every stage, the meshes as OBJ,
   ``demo.png`` (Workbench renders: dense | cage | edited cage | edited
   original | refined) and ``report.txt`` (counts, errors, timings).
"""

import argparse
import os
import sys
import time

import bpy
import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, "scripts"))
from meshadjust_batch import import_mesh, load_package  # noqa: E402


def build_dense(level=4):
    """Suzanne, subdivided and roughened with a noise displacement."""
    bpy.ops.mesh.primitive_monkey_add(size=2.0)
    obj = bpy.context.active_object
    obj.name = "dense"
    sub = obj.modifiers.new("subdiv", 'SUBSURF')
    sub.levels = sub.render_levels = level
    tex = bpy.data.textures.new("detail", 'VORONOI')
    tex.noise_scale = 0.06
    disp = obj.modifiers.new("detail", 'DISPLACE')
    disp.texture = tex
    disp.strength = 0.025
    disp.mid_level = 0.5
    tri = obj.modifiers.new("tri", 'TRIANGULATE')
    tri.quad_method = 'FIXED'
    depsgraph = bpy.context.evaluated_depsgraph_get()
    mesh = bpy.data.meshes.new_from_object(obj.evaluated_get(depsgraph))
    old = obj.data
    obj.modifiers.clear()
    obj.data = mesh
    mesh.name = "dense"
    bpy.data.meshes.remove(old)
    return obj


def scripted_edit(cage, api_mesh_io):
    """Pull the cage vertices near the top of the head up and back."""
    V = api_mesh_io.read_positions(cage.data)
    top = V[np.argmax(V[:, 2])]
    radius = 0.35 * (V[:, 2].max() - V[:, 2].min())
    d = np.linalg.norm(V - top, axis=1)
    w = np.clip(1.0 - d / radius, 0.0, 1.0) ** 2
    moved = int((w > 0).sum())
    V_new = V + np.outer(w, np.array([0.0, 0.35, 0.45]) * radius)
    api_mesh_io.write_positions(cage.data, V_new)
    return moved


def render_panel(objects, labels, path, spacing):
    """Render the objects side by side with Workbench into one PNG."""
    scene = bpy.context.scene
    scene.render.engine = 'BLENDER_WORKBENCH'
    shading = scene.display.shading
    shading.light = 'STUDIO'
    shading.color_type = 'OBJECT'
    shading.show_cavity = True
    shading.cavity_type = 'BOTH'
    scene.render.resolution_x = 2400
    scene.render.resolution_y = 640
    scene.render.film_transparent = False
    scene.world = scene.world or bpy.data.worlds.new("World")
    shown = []
    colours = [(0.8, 0.8, 0.8, 1), (0.95, 0.55, 0.2, 1), (0.95, 0.35, 0.2, 1),
               (0.55, 0.75, 0.95, 1), (0.6, 0.9, 0.6, 1)]
    for k, (obj, label) in enumerate(zip(objects, labels)):
        inst = bpy.data.objects.new(f"view_{label}", obj.data)
        inst.matrix_world = obj.matrix_world.copy()
        inst.location.x += k * spacing
        inst.color = colours[k % len(colours)]
        scene.collection.objects.link(inst)
        shown.append(inst)
        if obj.meshadjust.role == 'CAGE':
            # Workbench renders no overlays: draw the cage's edges as thin tubes
            wire = bpy.data.objects.new(f"wire_{label}", obj.data)
            wire.matrix_world = obj.matrix_world.copy()
            wire.location.x += k * spacing
            mod = wire.modifiers.new("wire", 'WIREFRAME')
            mod.thickness = 0.004 * spacing
            mod.use_replace = True
            wire.color = (0.15, 0.1, 0.08, 1)
            scene.collection.objects.link(wire)
            shown.append(wire)
        curve = bpy.data.curves.new(f"label_{label}", 'FONT')
        curve.body = label
        curve.align_x = 'CENTER'
        curve.size = 0.22
        text = bpy.data.objects.new(f"label_{label}", curve)
        text.location = (k * spacing, 0.0, -1.25)
        text.rotation_euler = (np.pi / 2, 0.0, 0.0)
        text.color = (0.1, 0.1, 0.1, 1)
        scene.collection.objects.link(text)
        shown.append(text)
    cam_data = bpy.data.cameras.new("demo_camera")
    cam_data.type = 'ORTHO'
    cam_data.ortho_scale = spacing * len(objects)
    cam = bpy.data.objects.new("demo_camera", cam_data)
    cam.location = (spacing * (len(objects) - 1) / 2, -10.0, 0.1)
    cam.rotation_euler = (np.pi / 2, 0.0, 0.0)
    scene.collection.objects.link(cam)
    scene.camera = cam
    for obj in objects:
        obj.hide_render = True
    scene.render.filepath = path
    bpy.ops.render.render(write_still=True)
    for obj in objects:
        obj.hide_render = False
    for inst in shown + [cam]:
        bpy.data.objects.remove(inst)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("mesh", nargs="?", help="a mesh file to use instead of the built-in Suzanne")
    p.add_argument("--faces", type=int, default=1500, help="cage faces (default 1500)")
    p.add_argument("--levels", type=int, default=0,
                   help="subdivision levels (default 0, Auto as in the add-on: the refined "
                        "mesh at the level whose face count is closest to the source's, the "
                        "edit bound at it or at 2, whichever is fewer)")
    p.add_argument("--out", default=os.path.join(ROOT, "out"), help="output folder")
    args = p.parse_args(argv)
    os.makedirs(args.out, exist_ok=True)

    pkg = load_package()
    api = pkg.meshadjust_addon.api
    mesh_io = pkg.meshadjust_addon.mesh_io
    core = pkg.core
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    if not hasattr(bpy.context.scene, "meshadjust"):
        pkg.register()
    lines = []
    t = time.perf_counter()
    dense = import_mesh(args.mesh) if args.mesh else build_dense()
    V0 = mesh_io.read_positions(dense.data)
    F0, _ = mesh_io.read_triangles(dense.data)
    diag = core.bbox_diagonal(V0)
    lines.append(f"dense mesh: {len(V0):,} vertices, {len(F0):,} triangles "
                 f"({time.perf_counter() - t:.1f} s to build/load)")

    t = time.perf_counter()
    cage, report = api.simplify_object(dense, target_faces=args.faces, fit=True, bind=True,
                                       levels=args.levels, scheme="butterfly")
    lines.append(f"simplify + fit + bind: {report.message} ({time.perf_counter() - t:.1f} s)")
    edited = cage.meshadjust.edited

    # the untouched cage refines back to the original
    t = time.perf_counter()
    api.refine_object(cage, output='EDITED')
    err0 = np.abs(mesh_io.read_positions(edited.data) - V0).max() / diag
    lines.append(f"refine with no edit: max vertex error {err0:.2e} of the diagonal "
                 f"({time.perf_counter() - t:.2f} s)")

    cage_rest = bpy.data.objects.new("cage (rest)", cage.data.copy())
    cage_rest.matrix_world = cage.matrix_world.copy()
    cage_rest.meshadjust.role = 'CAGE'
    bpy.context.scene.collection.objects.link(cage_rest)
    moved = scripted_edit(cage, mesh_io)
    t = time.perf_counter()
    rep = api.refine_object(cage, output='BOTH')
    lines.append(f"edit: {moved} cage vertices moved; refine both ways: {rep.message}")
    refined = cage.meshadjust.refined
    V1 = mesh_io.read_positions(edited.data)
    lines.append(f"edited original: max displacement {np.linalg.norm(V1 - V0, axis=1).max() / diag:.1%}"
                 f" of the diagonal, {np.count_nonzero(np.linalg.norm(V1 - V0, axis=1) > 1e-6 * diag):,}"
                 f" of {len(V0):,} vertices moved")

    dense.hide_set(False)
    for obj, name in ((dense, "dense"), (cage_rest, "cage"), (cage, "edited_cage"),
                      (edited, "edited_original"), (refined, "refined")):
        Vx = mesh_io.read_positions(obj.data)
        Fx, _ = mesh_io.read_triangles(obj.data)
        core.write_obj(os.path.join(args.out, f"{name}.obj"), Vx, Fx)
    t = time.perf_counter()
    png = os.path.join(args.out, "demo.png")
    render_panel([dense, cage_rest, cage, edited, refined],
                 ["dense", "cage", "edited cage", "edited original", "refined"], png,
                 spacing=1.15 * max(np.ptp(V0[:, 0]), np.ptp(V0[:, 2])))
    lines.append(f"render: {png} ({time.perf_counter() - t:.1f} s)")
    blend = os.path.join(args.out, "demo.blend")
    bpy.ops.wm.save_as_mainfile(filepath=blend)
    lines.append(f"saved {blend}")
    text = "\n".join(lines)
    with open(os.path.join(args.out, "report.txt"), "w") as fh:
        fh.write(text + "\n")
    print(text)
    return 0


if __name__ == "__main__":
    status = main()
    sys.stdout.flush()
    os._exit(status)
