#!/usr/bin/env python3
"""MeshAdjust batch: simplify (and optionally fit and refine) many meshes headless.

Runs with Blender as a Python module or inside a Blender binary:

    .venv/bin/python scripts/meshadjust_batch.py scans/ --faces 2000 --fit --out out/
    blender -b -P scripts/meshadjust_batch.py -- scan.ply --ratio 0.01 --out out/

Inputs are files or folders (OBJ, PLY, STL, glTF/GLB, read with Blender's own
importers; a folder is searched for those, not recursively). For each input
``NAME.ext`` it writes ``NAME_cage.<fmt>`` and, with ``--refine``,
``NAME_refined.<fmt>`` (the subdivided cage with the input's detail) into
``--out``. A summary table (faces, error, time per file) is printed at the
end; the exit status is 1 when any file failed (the others still complete),
2 for bad arguments.
"""

import argparse
import json
import os
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
IMPORT_EXT = {".obj", ".ply", ".stl", ".gltf", ".glb"}
EXPORT_FMT = ("obj", "ply", "stl", "glb")


def parse_args(argv):
    p = argparse.ArgumentParser(
        prog="meshadjust_batch.py",
        description="Simplify meshes into cages with MeshAdjust (QEM), optionally fit the "
                    "cages to the originals and refine them back with the detail.",
        epilog="Exit status: 0 all files converted, 1 some file failed, 2 bad arguments. "
               "Inside Blender put the options after '--': blender -b -P "
               "scripts/meshadjust_batch.py -- IN... --faces N.")
    p.add_argument("inputs", nargs="+", help="mesh files or folders (.obj .ply .stl .gltf .glb)")
    target = p.add_mutually_exclusive_group(required=True)
    target.add_argument("--faces", type=int, metavar="N", help="cage face count")
    target.add_argument("--ratio", type=float, metavar="R", help="cage faces as a fraction "
                        "(0 < R <= 1) of the input's")
    target.add_argument("--max-error", type=float, metavar="E", help="stop before the error "
                        "exceeds E percent of the bounding-box diagonal")
    p.add_argument("--fit", action="store_true", help="fit the cage so its subdivision "
                   "matches the input (undoes QEM's shrinkage)")
    p.add_argument("--refine", type=int, metavar="LEVELS", default=0,
                   help="also write the cage refined LEVELS times with the input's detail")
    p.add_argument("--scheme", choices=("butterfly", "loop"), default="butterfly",
                   help="subdivision scheme for --fit and --refine (default: butterfly)")
    p.add_argument("--feature-angle", type=float, default=60.0, metavar="DEG",
                   help="dihedral angle above which edges are kept sharp (default 60)")
    p.add_argument("--out", default="out", metavar="DIR", help="output folder (default: out)")
    p.add_argument("--format", choices=EXPORT_FMT, default=None,
                   help="output format (default: the input's own, glTF as glb)")
    p.add_argument("--jobs", type=int, default=1, metavar="N",
                   help="files processed in parallel processes (default 1)")
    p.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.faces is not None and args.faces < 4:
        p.error("--faces must be at least 4")
    if args.ratio is not None and not 0 < args.ratio <= 1:
        p.error("--ratio must be in (0, 1]")
    if args.max_error is not None and args.max_error <= 0:
        p.error("--max-error must be positive")
    if args.refine < 0 or args.jobs < 1:
        p.error("--refine must be >= 0 and --jobs >= 1")
    return args


def collect_inputs(paths):
    """Files to process, in a stable order; folders are searched one level."""
    files = []
    for path in paths:
        if os.path.isdir(path):
            files += sorted(os.path.join(path, f) for f in os.listdir(path)
                            if os.path.splitext(f)[1].lower() in IMPORT_EXT)
        else:
            files.append(path)
    return files


# ----------------------------------------------------------------- in Blender
def load_package():
    """Import and register the add-on from this checkout as ``meshadjust``."""
    import importlib.util
    if "meshadjust" in sys.modules:
        return sys.modules["meshadjust"]
    spec = importlib.util.spec_from_file_location(
        "meshadjust", os.path.join(ROOT, "__init__.py"), submodule_search_locations=[ROOT])
    pkg = importlib.util.module_from_spec(spec)
    sys.modules["meshadjust"] = pkg
    spec.loader.exec_module(pkg)
    import bpy
    if not hasattr(bpy.types.Object, "meshadjust"):
        pkg.register()
    return pkg


def import_mesh(path):
    """Import ``path`` with Blender's importer; returns one mesh object
    (several imported meshes are joined)."""
    import bpy
    ext = os.path.splitext(path)[1].lower()
    if not os.path.isfile(path):
        raise FileNotFoundError(f"no such file: {path}")
    before = set(bpy.data.objects)
    if ext == ".obj":
        bpy.ops.wm.obj_import(filepath=path)
    elif ext == ".ply":
        bpy.ops.wm.ply_import(filepath=path)
    elif ext == ".stl":
        bpy.ops.wm.stl_import(filepath=path)
    elif ext in (".gltf", ".glb"):
        bpy.ops.import_scene.gltf(filepath=path)
    else:
        raise ValueError(f"unsupported file type '{ext}' (use {sorted(IMPORT_EXT)})")
    meshes = [o for o in bpy.data.objects if o not in before and o.type == 'MESH'
              and len(o.data.polygons)]
    if not meshes:
        raise ValueError(f"{os.path.basename(path)}: no mesh with faces in the file")
    bpy.ops.object.select_all(action='DESELECT')
    for o in meshes:
        o.select_set(True)
    bpy.context.view_layer.objects.active = meshes[0]
    if len(meshes) > 1:
        bpy.ops.object.join()
    return bpy.context.view_layer.objects.active


def export_object(obj, path):
    """Export one object with Blender's exporter chosen by the extension."""
    import bpy
    bpy.ops.object.select_all(action='DESELECT')
    obj.hide_set(False)
    obj.select_set(True)
    bpy.context.view_layer.objects.active = obj
    fmt = os.path.splitext(path)[1].lower()
    if fmt == ".obj":
        bpy.ops.wm.obj_export(filepath=path, export_selected_objects=True, export_materials=False)
    elif fmt == ".ply":
        bpy.ops.wm.ply_export(filepath=path, export_selected_objects=True)
    elif fmt == ".stl":
        bpy.ops.wm.stl_export(filepath=path, export_selected_objects=True)
    else:
        bpy.ops.export_scene.gltf(filepath=path, use_selection=True, export_format='GLB')


def process_file(path, args):
    """Convert one file; returns a summary dict (raises on failure)."""
    import bpy
    pkg = load_package()
    api = pkg.meshadjust_addon.api
    t0 = time.perf_counter()
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    if not hasattr(bpy.context.scene, "meshadjust"):
        pkg.register()
    src = import_mesh(path)
    faces_in = len(src.data.polygons)
    levels = max(args.refine, 1) if (args.fit or args.refine) else 2
    cage, report = api.simplify_object(
        src, target_faces=args.faces, ratio=args.ratio, max_error_pct=args.max_error,
        feature_angle_deg=args.feature_angle, fit=args.fit, bind=args.refine > 0,
        levels=levels, scheme=args.scheme)
    stem = os.path.splitext(os.path.basename(path))[0]
    in_ext = os.path.splitext(path)[1].lower().lstrip(".")
    fmt = args.format or ("glb" if in_ext in ("gltf", "glb") else in_ext)
    os.makedirs(args.out, exist_ok=True)
    written = [os.path.join(args.out, f"{stem}_cage.{fmt}")]
    export_object(cage, written[0])
    refined_faces = 0
    if args.refine:
        api.refine_object(cage, output='REFINED')
        refined = cage.meshadjust.refined
        refined_faces = len(refined.data.polygons)
        written.append(os.path.join(args.out, f"{stem}_refined.{fmt}"))
        export_object(refined, written[-1])
    return {"file": path, "ok": True, "faces_in": faces_in, "faces_out": report.faces_out,
            "deviation_pct": report.deviation_pct, "refined_faces": refined_faces,
            "seconds": time.perf_counter() - t0, "written": written, "message": report.message}


# ------------------------------------------------------------------ driver
def worker_argv(args, path):
    """The options of ``args`` for a worker process that converts ``path``."""
    out = []
    if args.faces is not None:
        out += ["--faces", str(args.faces)]
    elif args.ratio is not None:
        out += ["--ratio", repr(args.ratio)]
    else:
        out += ["--max-error", repr(args.max_error)]
    if args.fit:
        out.append("--fit")
    out += ["--refine", str(args.refine), "--scheme", args.scheme,
            "--feature-angle", repr(args.feature_angle), "--out", os.path.abspath(args.out)]
    if args.format:
        out += ["--format", args.format]
    return out + ["--worker", path]


def worker_command(args, path):
    """The command line of a worker process: this script again, with the bpy
    module's Python, or inside the Blender binary that runs us."""
    script = os.path.abspath(__file__)
    import bpy
    binary = bpy.app.binary_path
    if binary and os.path.basename(binary).lower().startswith("blender"):
        return [binary, "-b", "--factory-startup", "-P", script, "--"] + worker_argv(args, path)
    return [sys.executable, script] + worker_argv(args, path)


def run_worker(path, args):
    proc = subprocess.run(worker_command(args, path), capture_output=True, text=True)
    for line in reversed(proc.stdout.splitlines()):
        if line.startswith("MESHADJUST_RESULT "):
            return json.loads(line[len("MESHADJUST_RESULT "):])
    tail = (proc.stderr or proc.stdout).strip().splitlines()[-3:]
    return {"file": path, "ok": False, "error": " | ".join(tail) or f"exit {proc.returncode}"}


def progress_bar(done, total, name, width=28):
    filled = int(width * done / max(total, 1))
    sys.stderr.write(f"\r[{'#' * filled}{'.' * (width - filled)}] {done}/{total} {name[:40]:<40}")
    sys.stderr.flush()
    if done == total:
        sys.stderr.write("\n")


def summary_table(results):
    lines = ["| file | faces in | cage faces | max dev % | refined faces | time s | status |",
             "| --- | ---: | ---: | ---: | ---: | ---: | --- |"]
    for r in results:
        name = os.path.basename(r["file"])
        if r["ok"]:
            lines.append(f"| {name} | {r['faces_in']:,} | {r['faces_out']:,} | "
                         f"{r['deviation_pct']:.3f} | {r['refined_faces']:,} | "
                         f"{r['seconds']:.2f} | ok |")
        else:
            lines.append(f"| {name} | | | | | | FAILED: {r['error']} |")
    return "\n".join(lines)


def script_argv():
    """Arguments after '--' inside Blender, else the command line's."""
    if "--" in sys.argv:
        return sys.argv[sys.argv.index("--") + 1:]
    return sys.argv[1:]


def main(argv=None):
    argv = script_argv() if argv is None else argv
    args = parse_args(argv)
    if args.worker:
        path = args.inputs[-1]
        try:
            res = process_file(path, args)
        except Exception as exc:   # reported to the driver, which carries on
            res = {"file": path, "ok": False, "error": f"{type(exc).__name__}: {exc}"}
        print("MESHADJUST_RESULT " + json.dumps(res), flush=True)
        os._exit(0)   # bpy as a module may crash at interpreter shutdown
    files = collect_inputs(args.inputs)
    if not files:
        print("meshadjust_batch: no input files found", file=sys.stderr)
        return 2
    results = [None] * len(files)
    done = 0
    progress_bar(0, len(files), "")
    if args.jobs == 1:
        for i, path in enumerate(files):
            try:
                results[i] = process_file(path, args)
            except Exception as exc:   # one bad file must not stop the batch
                results[i] = {"file": path, "ok": False, "error": f"{type(exc).__name__}: {exc}"}
            done += 1
            progress_bar(done, len(files), os.path.basename(path))
    else:
        with ThreadPoolExecutor(max_workers=args.jobs) as pool:
            futures = {pool.submit(run_worker, path, args): i for i, path in enumerate(files)}
            for fut in futures:
                i = futures[fut]
                results[i] = fut.result()
                done += 1
                progress_bar(done, len(files), os.path.basename(files[i]))
    print(summary_table(results))
    failed = sum(not r["ok"] for r in results)
    print(f"{len(results) - failed} converted, {failed} failed; output in {args.out}")
    return 1 if failed else 0


if __name__ == "__main__":
    status = main()
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(status)
