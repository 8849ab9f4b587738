"""OBJ reading and writing: kept under this name for the scripts and tests
that import ``core.io_obj``; the code lives in :mod:`core.io_mesh` beside SMF."""

from .io_mesh import read_obj, write_obj

__all__ = ["read_obj", "write_obj"]
