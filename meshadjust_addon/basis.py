"""The source's Basis put back after the artist deleted it.

Deleting the reference key ("Basis") of a source makes the first remaining
key the reference key, the base shape its mesh and its other keys follow.
When that key is MeshAdjust's, the edit has become the source's own shape:
the steps refuse to write over it (:func:`~.results.reference_key_problem`)
and say how to go on; Restore Basis (:func:`restore_basis`) puts a Basis back
from the mesh that was bound (the cage's rest shape through the binding,
which gives the bound mesh back to float precision).

Blender 5 keeps the reference key first (a key cannot be moved above it), so
the reference key itself becomes the Basis again and MeshAdjust's key is made
anew over it, with its name, its shape and its settings::

    before:  [dense_cage (reference, = the edit)]
    after:   [Basis (reference, = the mesh bound), dense_cage (relative to Basis)]
"""

import numpy as np

from .. import core
from . import mesh_io, staleness, store
from .results import reference_key_problem, shape_key_unavailable
from .rollback import all_or_nothing

#: the settings of MeshAdjust's key carried over to the key made anew (sliders before the value)
KEY_SETTINGS = ("slider_min", "slider_max", "value", "mute", "vertex_group", "interpolation",
                "lock_shape")

#: the source fingerprint's fields for other shape keys and modifiers when there were none
PLAIN = "00000000"


def bound_plainly(edited):
    """Whether the mesh bound to ``edited`` was its source's Basis: no other
    shape keys and no modifiers at bind time (its source fingerprint says so)."""
    fields = staleness.fingerprint_fields(edited.meshadjust.source_fingerprint)
    return fields is not None and fields.keys == PLAIN and fields.modifiers == PLAIN


def basis_positions(cage):
    """(n,3) float64: the Basis of the cage's source as it was bound.

    Raises
    ------
    core.MeshAdjustError
        The mesh bound was not the Basis (other keys or modifiers then), or
        the binding cannot be read (:func:`~.store.load_binding`).
    """
    source, edited = cage.meshadjust.source, cage.meshadjust.edited
    if not bound_plainly(edited):
        raise core.MeshAdjustError(
            f"Restore Basis: '{source.name}' had other shape keys or modifiers when it was bound, "
            f"so the mesh bound was not its Basis: Undo the deletion instead")
    return core.deform(store.load_binding(edited, cage), store.load_rest(cage))


def swap_in_basis(source, V):
    """Make the reference key of ``source`` (MeshAdjust's key) a Basis with
    the positions ``V`` (n,3) and the mesh's, and MeshAdjust's key anew over
    it (same name, shape and settings). Returns the new key."""
    keys = source.data.shape_keys
    ref = keys.reference_key
    name, co = ref.name, mesh_io.read_key(ref)
    ref.name = "Basis"
    ref.data.foreach_set("co", np.ascontiguousarray(V, dtype=np.float32).ravel())
    mesh_io.write_positions(source.data, V)
    key = source.shape_key_add(name=name, from_mix=False)
    key.data.foreach_set("co", co)
    for attr in KEY_SETTINGS:
        if hasattr(ref, attr):                 # (lock_shape: Blender 5)
            setattr(key, attr, getattr(ref, attr))
    key.relative_key = ref
    source.data.update()
    return key


def _refresh_fingerprint(source, edited):
    """Record the source's fingerprint anew when only its base mesh differs
    from the one stored (the restored Basis is the mesh bound)."""
    now = staleness.source_fingerprint(source)
    a = staleness.fingerprint_fields(now) if now else None
    b = staleness.fingerprint_fields(edited.meshadjust.source_fingerprint)
    if a is not None and b is not None and a._replace(mesh="") == b._replace(mesh=""):
        edited.meshadjust.source_fingerprint = now


def restore_basis(cage):
    """Put back the Basis of the source of ``cage``, whose shape key became
    its reference key (all or nothing). Returns the sentence for the report.

    Raises
    ------
    core.MeshAdjustError
        The key is not the reference key (nothing to restore), the source's
        keys cannot be written, or the Basis is not known (:func:`basis_positions`).
    """
    source, edited = cage.meshadjust.source, cage.meshadjust.edited
    if source is None or edited is None or not reference_key_problem(source, cage):
        raise core.MeshAdjustError(f"Restore Basis: the shape key of '{cage.name}' is not the "
                                   f"reference key of its source: nothing to restore")
    V = basis_positions(cage)
    why = shape_key_unavailable(source, V.shape[0])
    if why:
        raise core.MeshAdjustError(f"Restore Basis: {why}")
    with all_or_nothing() as rb:
        rb.keep(source.data)
        key = swap_in_basis(source, V)
        _refresh_fingerprint(source, edited)
        staleness.touched(source)
    msg = (f"the Basis of '{source.name}' restored from the mesh that was bound; "
           f"'{key.name}' is MeshAdjust's key over it again")
    cage.meshadjust.last_report = msg
    return msg
