#!/usr/bin/env python3
"""MeshAdjust batch from a checkout: the ``meshadjust-batch`` console script
without installing the package.

    .venv/bin/python scripts/meshadjust_batch.py scans/ --faces 2000 --fit --out out/
    blender -b -P scripts/meshadjust_batch.py -- scan.ply --ratio 0.01 --out out/

The tool itself is ``cli/batch.py`` (``meshadjust.cli.batch``); ``--help``
documents everything. This file makes the checkout importable as the package
``meshadjust`` and keeps the helpers other scripts import from it
(``load_package``, ``import_mesh``).
"""

import importlib.util
import os
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def checkout_package():
    """The checkout as the package ``meshadjust`` (its ``core`` and ``cli``
    import without Blender); an installed ``meshadjust`` is not used."""
    if "meshadjust" in sys.modules:
        return sys.modules["meshadjust"]
    spec = importlib.util.spec_from_file_location(
        "meshadjust", os.path.join(ROOT, "__init__.py"), submodule_search_locations=[ROOT])
    pkg = importlib.util.module_from_spec(spec)
    sys.modules["meshadjust"] = pkg
    spec.loader.exec_module(pkg)
    return pkg


def load_package():
    """The checkout as ``meshadjust`` with the add-on registered in Blender."""
    pkg = checkout_package()
    import bpy
    import meshadjust.core  # noqa: F401  (sets pkg.core)
    import meshadjust.meshadjust_addon  # noqa: F401  (sets pkg.meshadjust_addon)
    if not hasattr(bpy.types.Object, "meshadjust"):
        pkg.register()
    return pkg


def import_mesh(path):
    """Import ``path`` with Blender's importer; returns one mesh object
    (several imported meshes are joined)."""
    checkout_package()
    from meshadjust.cli.blender_io import import_mesh as _import
    return _import(path)


def script_argv():
    """Arguments after '--' inside Blender, else the command line's."""
    if "--" in sys.argv:
        return sys.argv[sys.argv.index("--") + 1:]
    return sys.argv[1:]


if __name__ == "__main__":
    checkout_package()
    from meshadjust.cli import batch
    batch.exit_now(batch.main(script_argv(), entry=[os.path.abspath(__file__)],
                              prog="meshadjust_batch.py"))
