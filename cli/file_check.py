"""What an input file's own structure says, found before Blender's importer
reads it: the shared result and error of ``stl_file``, ``ply_file`` and
``gltf_file``, each of which has a ``check(path)`` returning a
:class:`FileCheck` or raising :class:`InputFileError`."""

from typing import NamedTuple


class InputFileError(Exception):
    """An input file is damaged or holds other than what its format's header
    says (cut short, a wrong count, a buffer too short); the message names
    the file and what is wrong, in words a user can act on."""


class FileCheck(NamedTuple):
    """What a file's own structure says, found before Blender reads it."""

    expected_faces: int = None    #: faces the file holds (None: unknown)
    notes: tuple = ()             #: what was done about it (a blank count filled in)
    warnings: tuple = ()          #: what may be wrong, the file still read
