"""Blender's app handlers (``bpy.app.handlers``), each added and removed once:
the one idiom the add-on's modules register theirs with."""

import bpy


def add(pairs):
    """Append each function to its handler list, ``pairs`` of (list name,
    e.g. ``"load_post"``, function), unless it is already there (a second
    register() of the add-on adds nothing)."""
    for name, fn in pairs:
        handlers = getattr(bpy.app.handlers, name)
        if fn not in handlers:
            handlers.append(fn)


def remove(pairs):
    """Take each function of ``pairs`` (as :func:`add` takes them) out of its
    handler list, where it is there."""
    for name, fn in pairs:
        handlers = getattr(bpy.app.handlers, name)
        if fn in handlers:
            handlers.remove(fn)
