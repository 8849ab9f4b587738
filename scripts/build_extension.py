#!/usr/bin/env python3
"""Build and validate the extension zip with Blender's own extension tool.

    .venv/bin/python scripts/build_extension.py [--output-dir dist]

Blender's tool (``blender_ext.py``) ships inside the bpy wheel and runs as
plain Python; it reads ``blender_manifest.toml`` (its ``[build]`` section
keeps tests, scripts and caches out) and writes
``dist/meshadjust-<version>.zip``. The manifest is validated before the build
and the zip after it, and the zip's file list is checked against what an
extension may contain. Prints the zip's path on the last line.
"""

import argparse
import glob
import importlib.util
import os
import subprocess
import sys
import zipfile

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
ALLOWED_TOP = {"__init__.py", "blender_manifest.toml", "LICENSE", "core", "meshadjust_addon"}


def find_blender_ext(python):
    """Path of blender_ext.py inside the bpy package importable by ``python``."""
    if python == sys.executable:
        spec = importlib.util.find_spec("bpy")
        locations = list(spec.submodule_search_locations or []) if spec else []
    else:
        out = subprocess.run(
            [python, "-c", "import importlib.util as u; s = u.find_spec('bpy'); "
                           "print('\\n'.join(s.submodule_search_locations) if s else '')"],
            capture_output=True, text=True, check=True).stdout
        locations = [line for line in out.splitlines() if line]
    for loc in locations:
        hits = sorted(glob.glob(os.path.join(loc, "*", "scripts", "addons_core", "bl_pkg", "cli",
                                             "blender_ext.py")))
        if hits:
            return hits[-1]
    raise SystemExit("build_extension: the bpy module is not installed for this Python; "
                     "run scripts/setup and use .venv/bin/python")


def check_zip(path):
    """The zip holds only the add-on: no tests, scripts, caches or venvs."""
    with zipfile.ZipFile(path) as zf:
        names = zf.namelist()
    bad = [n for n in names if n.split("/")[0] not in ALLOWED_TOP or "__pycache__" in n
           or n.endswith(".pyc")]
    if bad:
        raise SystemExit(f"build_extension: unexpected files in {path}: {bad[:5]}")
    for needed in ("__init__.py", "blender_manifest.toml", "core/__init__.py",
                   "meshadjust_addon/__init__.py"):
        if needed not in names:
            raise SystemExit(f"build_extension: {needed} is missing from {path}")
    return names


def build(output_dir, python=sys.executable, source_dir=ROOT):
    """Validate the manifest, build the zip, validate the zip; return its path."""
    tool = find_blender_ext(python)
    os.makedirs(output_dir, exist_ok=True)

    def run(*args):
        proc = subprocess.run([python, tool, *args], capture_output=True, text=True)
        if proc.returncode != 0:
            raise SystemExit(f"build_extension: blender_ext {args[0]} failed:\n"
                             f"{proc.stdout}{proc.stderr}")
        return proc.stdout

    run("validate", source_dir)
    before = set(glob.glob(os.path.join(output_dir, "*.zip")))
    run("build", "--source-dir", source_dir, "--output-dir", output_dir)
    after = set(glob.glob(os.path.join(output_dir, "*.zip")))
    new = sorted(after - before) or sorted(after, key=os.path.getmtime)[-1:]
    zip_path = new[-1]
    run("validate", zip_path)
    check_zip(zip_path)
    return zip_path


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--output-dir", default=os.path.join(ROOT, "dist"),
                        help="where to write the zip (default: dist/)")
    args = parser.parse_args(argv)
    print(build(os.path.abspath(args.output_dir)))


if __name__ == "__main__":
    main()
