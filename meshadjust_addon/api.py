"""MeshAdjust's plain Python API: the workflow steps without any UI context.

The operators, the batch CLI and other people's scripts call these. Each
step is split into a pure-NumPy *compute* part (safe to run in a worker
thread, cancellable through ``progress``) and a Blender *commit* part that
creates or updates objects. Everything that can fail is checked before the
commit writes anything, so a failed or cancelled step changes nothing in the
scene (and :func:`.rollback.all_or_nothing` undoes a commit that fails
anyway).

    cage, report = simplify_object(obj, target_faces=1400, fit=True, bind=True)
    ...move cage vertices...
    result = refine_object(cage, output='EDITED')

Geometry is processed in the source object's local space; the cage is created
with the source's transform, and a cage moved as an object is mapped back
through both transforms, so object transforms are respected. An edit is the
cage's current shape minus its rest shape; Fit and re-bind keep it.

The steps live in :mod:`.simplify_step` (simplify), :mod:`.cage_steps`
(bind, fit) and :mod:`.refine_step` (refine); this module gathers them and
adds ``subdivide_object``.
"""

import contextlib
import time

import bpy
import numpy as np

from .. import core
from . import carry, mesh_io, names, results, store
from .cage_steps import (MAX_AUTO_LEVELS, MAX_EDIT_LEVELS, OUTPUT_NAMES, CageJob,  # noqa: F401
                         auto_levels, bind_object, check_source_in_place, commit_bind,
                         commit_fit, compute_bind, compute_fit, edit_levels, fit_cage_object,
                         prepare_cage_job, prepare_fit, read_source, refine_levels,
                         source_edit_problem)
from .refine_step import (RefineJob, commit_refine, compute_refine, make_finer,  # noqa: F401
                          prepare_refine, refine_object)
from .report import Report, about, user_cause  # noqa: F401
from .rollback import all_or_nothing, retire
from .simplify_step import (MEASURE_SAMPLES, TARGET_TOLERANCE, SimplifyJob,  # noqa: F401
                            SimplifyParams, commit_simplify, compute_simplify, prepare_simplify,
                            simplify_object, source_problem)

CREASE = store.CREASE


def subdivide_object(obj, *, levels=1, scheme="butterfly", in_place=False):
    """Butterfly or Loop subdivision of any mesh object (creases: the edges
    marked sharp). Returns ``(object, Report)``: a new object beside ``obj``,
    or ``obj`` itself when ``in_place``. The result keeps the materials, UV
    maps, colour and other attributes, vertex groups and loose edges of what
    ``obj`` shows (:mod:`.carry`)."""
    t0 = time.perf_counter()
    if in_place and mesh_io.has_deformers(obj):
        raise core.MeshAdjustError(
            f"'{obj.name}' has modifiers or shape keys: in place, what they show would become "
            f"its mesh while they stay on it (a modifier applied twice, the keys lost); turn In "
            f"place off for a new object of what it shows, or apply them first")
    others = sorted(o.name for o in bpy.data.objects if o.data == obj.data and o != obj) \
        if in_place else []
    if others:          # (the active one alone had been given the new mesh, unlinked in silence)
        who = f"'{others[0]}'" + (f" and {len(others) - 1:,} more" if len(others) > 1 else "")
        raise core.MeshAdjustError(
            f"'{obj.name}' shares its mesh with {who}: in place would leave them the old one, "
            f"no longer linked; make it single-user first (Object > Relations > Make Single "
            f"User > Object & Data), or turn In place off for a new object")
    arrays = mesh_io.read_object(obj)
    if arrays.F.shape[0] == 0:     # (a Mask modifier on an empty group: "0 -> 0 faces")
        raise core.InvalidMeshError(f"'{obj.name}' shows no faces"
                                    + (" (its modifiers leave none)" if arrays.evaluated else ""))
    # sharp edges index the mesh data: they only apply when it was used as is
    creases = (np.zeros((0, 2), np.int64) if arrays.evaluated
               else mesh_io.get_edge_flags(obj.data, "sharp_edge"))
    try:
        op = core.subdivision_operator(arrays.F, arrays.V.shape[0], levels=levels,
                                       scheme=scheme, creases=creases if creases.shape[0] else None)
    except core.MeshAdjustError as exc:   # (said as Subdivide said it before it kept the data)
        raise type(exc)(str(exc).replace("subdivision_operator:", "subdivide:", 1)) from exc
    Vf, Ff = op.apply(arrays.V), op.F_fine
    name = names.suffixed(obj.name, f"_{scheme}{levels}")
    with all_or_nothing() as rb:
        rb.keep_object(obj)
        mesh = mesh_io.new_mesh(name, Vf, Ff)
        with _shown_mesh(obj, arrays.evaluated) as src:
            for mat in src.materials:
                mesh.materials.append(mat)
            groups, notes = carry.carry(src, obj, mesh, arrays.F, op)
        if in_place:
            old = obj.data
            obj.data = mesh
            retire(old)
            out = obj
        else:
            out = bpy.data.objects.new(name, mesh)
            out.matrix_world = obj.matrix_world.copy()
            results.link_like(out, obj)
            _same_slots(obj, out)
        carry.put_groups(out, groups)
    dt = time.perf_counter() - t0
    msg = f"{arrays.F.shape[0]:,} -> {Ff.shape[0]:,} faces ({scheme}, {levels} level"
    msg += "s" if levels != 1 else ""
    msg += f"), {dt:.2f} s"
    if arrays.triangulated:
        msg += (f"; triangulated {arrays.n_split:,} of {arrays.n_polygons:,} polygons (quads "
                f"and n-gons) first")
    if arrays.evaluated:
        msg += "; used the evaluated mesh (modifiers and shape keys applied)"
    msg += "".join(f"; {note}" for note in notes)
    return out, Report(msg, arrays.F.shape[0], Ff.shape[0], seconds=dt)


def _same_slots(obj, out):
    """The material slots of ``out`` linked as ``obj``'s, with their
    materials: a material linked to the object (not its mesh) was left out
    of a new object's slots, which showed the mesh's material instead."""
    for slot, src in zip(out.material_slots, obj.material_slots):
        if src.link == 'OBJECT':
            slot.link = 'OBJECT'
            slot.material = src.material


@contextlib.contextmanager
def _shown_mesh(obj, evaluated):
    """The mesh ``obj`` shows: its own, or (``evaluated``) its evaluated mesh,
    the one :func:`~.mesh_io.read_object` read."""
    if not evaluated:
        yield obj.data
        return
    ob_eval = obj.evaluated_get(bpy.context.evaluated_depsgraph_get())
    try:
        yield ob_eval.to_mesh()
    finally:
        ob_eval.to_mesh_clear()
