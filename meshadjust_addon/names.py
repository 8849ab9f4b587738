"""The names MeshAdjust gives what it makes: ``<scan>_cage``, ``<scan>_edited``,
``<scan>_refined``, ``<edited>.detail``, ``<result>.hand``, the shape key named
after its cage.

Blender keeps at most :data:`ID_BYTES` bytes (UTF-8) of an object's or a
mesh's name and :data:`KEY_BYTES` of a shape key's, and cuts what is longer
at the end: a scan with a long name had its cage named like the scan itself
in Blender 4.2 (the ``_cage`` cut off) and its edited original ``<scan>.001``,
and in Blender 5 its shape key lost the end of the cage's name (and the
report said a key of the cage's name was the artist's). :func:`suffixed`
shortens the name given instead, so the suffix stays.
"""

import bpy

#: the longest object and mesh names Blender keeps, in bytes (255 since Blender 5.0)
ID_BYTES = 255 if bpy.app.version >= (5, 0, 0) else 63
#: the longest shape key names Blender keeps, in bytes
KEY_BYTES = 63


def suffixed(name, suffix, limit=ID_BYTES):
    """``name + suffix`` within ``limit`` bytes: ``name`` shortened (at a
    character, not inside one) so that the whole ``suffix`` stays.

    >>> suffixed("scan", "_cage")
    'scan_cage'
    """
    room = max(limit - len(suffix.encode()), 0)
    raw = name.encode()
    if len(raw) > room:
        name = raw[:room].decode("utf-8", "ignore")
    return name + suffix


def key_name_for(cage_name):
    """The name of a new shape key named after the cage ``cage_name``, as
    Blender will keep it."""
    return suffixed(cage_name, "", KEY_BYTES)
