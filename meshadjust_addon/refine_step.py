"""Refine an edited cage: its edited original, shape key and refined mesh.

The prepare / compute / commit split of the long steps (:mod:`.cage_steps`):
:func:`prepare_refine` reads and checks everything on the main thread;
:func:`compute_refine` (pure NumPy, any thread, cancellable) re-binds when
other levels or another scheme are asked for, deforms the source, binds it at
the refined mesh's levels when they are not the edit's (once: the binding is
kept for the next Refine) and refines; :func:`commit_refine` writes the
results, all or nothing, and reports. :func:`refine_object` runs the three.
"""

import time
from dataclasses import dataclass, field

import numpy as np

from .. import core
from . import mesh_io, results, staleness, store
from .cage_steps import (OUTPUT_NAMES, cage_in_source_space, check_source_in_place,
                         commit_bind, compute_bind, keep_refine_binding, kept_refine_binding,
                         prepare_cage_job, refine_binding, refine_levels, turned_cage_note,
                         write_key)
from .report import Report, about
from .rollback import all_or_nothing

@dataclass
class RefineJob:
    """What a Refine read and checked (:func:`prepare_refine`), then computed
    (:func:`compute_refine`) before it writes anything."""

    cage_name: str
    output: str
    binding: object              #: the edit's binding (the re-bind's, after compute, when one)
    rebind: object               #: the :class:`~.cage_steps.CageJob` of a re-bind, or None
    V_cage: np.ndarray           #: the cage as edited, in the source's space
    F_cage: np.ndarray           #: its faces when read (the commit refuses other ones)
    edited_uid: int              #: the edited original's ``session_uid``
    #: its :func:`~.store.binding_stamp` when read (the commit refuses another)
    bound: object
    dense_faces: int             #: the source's face count when bound (0: not known)
    #: the refined mesh's binding: the edit's, a kept finer one, or (after compute) one
    #: made at ``finer_levels``
    finer: object = None
    finer_levels: int = 0        #: levels of a finer binding compute makes (0: none)
    finer_rest: object = None    #: the rest shape it binds
    V_edited: object = None      #: the edited original's positions (None: not asked for)
    refined: object = None       #: (V, F) of the refined mesh (None: not asked for)
    parts: list = field(default_factory=list)    #: the report's sentences so far
    cancelled: bool = False
    started: float = 0.0         #: ``time.perf_counter()`` at prepare


def prepare_refine(cage, *, output='EDITED', levels=None, scheme=None):
    """Read and check a Refine of ``cage`` (main thread); see
    :func:`refine_object`. Returns a :class:`RefineJob`."""
    started = time.perf_counter()
    if output not in OUTPUT_NAMES:
        raise core.InvalidArgumentError(f"refine: output must be one of {OUTPUT_NAMES}, "
                                        f"got {output!r}")
    scheme = None if scheme == 'BOUND' else scheme
    cs = cage.meshadjust
    source, edited = cs.source, cs.edited
    if source is None:
        raise core.MeshAdjustError(f"'{cage.name}' is not a MeshAdjust cage (no source linked)")
    if edited is None:
        raise core.MeshAdjustError(f"'{cage.name}' is not bound yet: bind it first")
    why = results.copy_problem(cage)
    if why:
        raise core.MeshAdjustError(why)
    why = results.edit_mode_problem(edited)    # (its binding is read from its mesh)
    if why:
        raise core.MeshAdjustError(f"Refine: {why}")
    job, binding = None, None
    if (levels and levels != cs.levels) or (scheme is not None and scheme != cs.scheme):
        # (levels asked for are the refined mesh's too; at Auto, its own are bound beside)
        job = prepare_cage_job(cage, levels=levels, scheme=scheme, keep_edit=True,
                               refined=not levels and (cs.refined is not None
                                                       or output in ('REFINED', 'BOTH')))
        n_dense, F_cage = job.V.shape[0], job.F_cage
    else:
        check_source_in_place(cage, source)
        binding = store.load_binding(edited, cage)   # (of the cage's topology as it is now)
        n_dense, F_cage = binding.n_dense, binding.F_cage
    rj = RefineJob(cage.name, output, binding, job, cage_in_source_space(cage, source),
                   F_cage, edited.session_uid, store.binding_stamp(edited),
                   edited.meshadjust.dense_faces, started=started)
    _check_outputs(cage, rj, n_dense)
    if output in ('REFINED', 'BOTH') and not levels and job is None:
        _plan_finer(cage, rj)
    return rj


def _check_outputs(cage, rj, n_dense):
    """Raise :class:`core.MeshAdjustError` when an output of ``rj`` cannot
    be written now (a shape key's source, a result in Edit Mode, ...)."""
    cs, output = cage.meshadjust, rj.output
    refined = cs.refined if output in ('REFINED', 'BOTH') else None
    why = results.shape_key_unavailable(cs.source, n_dense, cage) if output == 'SHAPE_KEY' else \
        results.keyed_problem(cs.edited) if output in ('EDITED', 'BOTH') else None
    why = why or results.edit_mode_problem(refined) or \
        (results.keyed_problem(refined) if refined is not None else None)
    if why:
        raise core.MeshAdjustError(f"Refine: {why}")


def _plan_finer(cage, rj):
    """The refined mesh's binding at Auto levels (:func:`refine_levels`) for
    the edit's binding as it is (a re-bind makes it beside the edit's,
    :func:`~.cage_steps.prepare_cage_job`): the one kept from the last
    Refine, or the levels and rest shape :func:`compute_refine` binds at."""
    finer = refine_levels(rj.binding.levels, rj.F_cage.shape[0], rj.dense_faces)
    if finer == rj.binding.levels:
        return
    rj.finer = kept_refine_binding(rj.edited_uid, rj.binding, finer)
    if rj.finer is None:
        rj.finer_levels = finer
        rj.finer_rest = rj.binding.V_cage_rest
        if rj.finer_rest is None:          # (bound before rest shapes were kept: unedited)
            rj.finer_rest = cage_in_source_space(cage, cage.meshadjust.source)


def compute_refine(rj, *, progress=None):
    """Compute what ``rj`` asks for (pure NumPy, any thread): the re-bind,
    the edited original, the refined mesh's finer binding and the refined
    mesh. ``progress(fraction)`` follows the binds; returning False cancels
    (``rj.cancelled``). Returns ``rj``."""
    def share(lo, hi):
        return None if progress is None else (lambda f: progress(lo + (hi - lo) * f))
    if rj.rebind is not None:
        compute_bind(rj.rebind, progress=share(0.0, 0.9))
        if rj.rebind.cancelled:
            rj.cancelled = True
            return rj
        rj.binding = rj.rebind.binding
        rj.finer = rj.rebind.refine_binding
        rj.parts.append(f"re-bound from the rest shape ({rj.rebind.old_scheme} x"
                        f"{rj.rebind.old_levels} -> {rj.rebind.scheme} x{rj.rebind.levels}), "
                        f"the edit kept")
    binding = rj.binding
    if rj.output in ('EDITED', 'BOTH', 'SHAPE_KEY'):
        rj.V_edited = core.deform(binding, rj.V_cage)
        repaired = binding.repaired(rj.V_edited).size
        if repaired:
            rj.parts.append(f"{repaired:,} dense vertices put back where the edit turned "
                            f"faces over")
    if rj.output not in ('REFINED', 'BOTH'):
        return rj
    if rj.finer_levels and make_finer(rj, progress=share(0.1, 0.95)).cancelled:
        return rj
    if rj.finer is None:
        rj.finer = binding
    rj.refined = core.refine(rj.finer, rj.V_cage)
    if progress is not None and progress(1.0) is False:
        rj.cancelled = True
    return rj


def make_finer(rj, *, progress=None):
    """Make the refined mesh's finer binding ``rj`` plans (``rj.finer_levels``;
    pure NumPy, any thread) and keep it for the edit's binding
    (:func:`~.cage_steps.keep_refine_binding`); ``progress`` returning False
    cancels (``rj.cancelled``). Returns ``rj``."""
    binding = rj.binding
    try:
        rj.finer = refine_binding(core.deform(binding, rj.finer_rest), binding.F_dense,
                                  rj.finer_rest, binding, rj.finer_levels, progress=progress)
    except core.CancelledError:
        rj.cancelled = True
        return rj
    keep_refine_binding(rj.edited_uid, binding, rj.finer)
    return rj


def _check_unchanged(cage, rj):
    """Raise :class:`core.MeshAdjustError` when what ``rj`` read changed
    before its commit (the artist worked on while Refine ran in the
    background): the cage's topology, its edited original, a result it
    writes in Edit Mode."""
    cs = cage.meshadjust
    if cs.edited is None or cs.edited.session_uid != rj.edited_uid:
        raise core.MeshAdjustError(f"'{cage.name}' lost its binding while Refine ran: "
                                   f"nothing was changed")
    if store.binding_stamp(cs.edited) != rj.bound:
        raise core.MeshAdjustError(f"'{cs.edited.name}' was bound again while Refine ran: "
                                   f"nothing was changed; run Refine again")
    F_now = store.cage_topology(cage)[0]
    if F_now.shape != rj.F_cage.shape or not np.array_equal(F_now, rj.F_cage):
        raise core.MeshAdjustError(f"'{cage.name}' changed topology while the step ran: nothing "
                                   f"was changed; run it again")
    why = results.edit_mode_problem(cs.edited)
    if why:
        raise core.MeshAdjustError(f"Refine: {why}")
    _check_outputs(cage, rj, rj.binding.n_dense)


def _write(cage, rj):
    """The Blender half of :func:`commit_refine`: the re-bind, the edited
    original, the shape key and the refined mesh written (all or nothing);
    their sentences added to ``rj.parts``."""
    source, edited, binding, parts = cage.meshadjust.source, cage.meshadjust.edited, \
        rj.binding, rj.parts
    output = rj.output
    with all_or_nothing() as rb:
        if rj.rebind is not None:
            commit_bind(cage, rj.rebind)
            parts.extend([rj.rebind.note] if rj.rebind.note else [])
        if output in ('EDITED', 'BOTH'):
            if not edited.users_collection:         # deleted by the artist: shown again
                parts.append(results.link_back(edited, source))
            else:
                results.aside_note(results.kept_aside(edited), edited, parts)
            rb.keep(edited.data)
            results.record_written(edited, mesh_io.write_positions(edited.data, rj.V_edited))
            parts.append(f"'{edited.name}' deformed ({binding.n_dense:,} vertices)")
        if output == 'SHAPE_KEY':
            rb.keep(source.data)
            key = write_key(source, cage, edited, binding, rj.V_edited, notes=parts)
            parts.append(f"shape key '{key.name}' of '{source.name}' updated "
                         f"({binding.n_dense:,} vertices)")
        if rj.refined is not None:
            Vr, Fr = rj.refined
            refined = results.write_refined(cage, source, Vr, Fr, notes=parts)
            parts.append(f"'{refined.name}' refined: {Fr.shape[0]:,} faces, {rj.finer.scheme} x"
                         f"{rj.finer.levels}" + _density_note(Fr.shape[0],
                                                              edited.meshadjust.dense_faces))


def commit_refine(cage, rj):
    """Write what :func:`compute_refine` made (main thread) and report it:
    a :class:`Report`, a warning when the edit turns cage faces over or the
    source changed since the bind."""
    if rj.cancelled:
        raise core.MeshAdjustError("Refine cancelled: nothing was changed")
    _check_unchanged(cage, rj)
    turned = turned_cage_note(cage, rj.binding, rj.V_cage)
    warnings = [turned] if turned else []
    _write(cage, rj)
    cs = cage.meshadjust
    source, edited = cs.source, cs.edited
    own = results.shape_key_of(source, cage)
    miss = results.key_miss(source, rj.V_edited, own.name if own is not None else None) \
        if rj.output == 'SHAPE_KEY' else None
    warnings += [miss] if miss else []
    stale = staleness.bound_mesh_warning(source, edited, fresh=True)
    warnings += [stale] if stale else []
    data = staleness.source_data_change(source, edited, fresh=True) \
        if rj.output in ('EDITED', 'BOTH') and not stale else None
    if data:
        warnings.append(f"{data}: re-bind to bring them over")
    dt = time.perf_counter() - rj.started
    msg = "; ".join(rj.parts) + f", {dt:.2f} s"
    if warnings:
        msg += "; WARNING: " + "; ".join(warnings)
    cs.last_report = msg
    return Report(msg, seconds=dt, level='WARNING' if warnings else 'INFO',
                  warnings=tuple(warnings))


def _density_note(n_refined, n_source):
    """``", about the source's 252k"`` when the refined mesh is within 2x
    of the source's face count, else what the source has (``", the
    source has 252k"``); nothing when the source's count is not known."""
    if not n_source:
        return ""
    if 0.5 <= n_refined / n_source <= 2.0:
        return f", about the source's {about(n_source)}"
    return f", the source has {about(n_source)}"


def refine_object(cage, *, output='EDITED', levels=None, scheme=None):
    """Update the results of an edited cage; returns a :class:`Report`.

    ``output``: ``'EDITED'`` (the bound copy of the source, deformed; same
    topology, UVs and attributes), ``'SHAPE_KEY'`` (the edit as a shape key
    of the source named after the cage), ``'REFINED'`` (the subdivided cage
    with the source's detail) or ``'BOTH'`` (edited and refined). Results
    are created once and updated in place afterwards. ``levels`` None (Auto):
    the refined mesh at the levels closest to the source's face count (the
    source bound at them the first time when the edit's binding has fewer);
    other ``levels`` / ``scheme`` than the binding's re-bind from the rest
    shape, keeping the edit (and the report says so). A source changed since
    the bind makes the report a warning.
    """
    rj = compute_refine(prepare_refine(cage, output=output, levels=levels, scheme=scheme))
    return commit_refine(cage, rj)
