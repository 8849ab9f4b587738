"""Live update of the edited original and of the refined mesh: recompute and
convert only what moved.

The fast path of live mode. Per edited object it keeps the state of the last
update: the cage positions used (in the source's space), the dense positions
(float64, updated in place by ``core.deform(..., moved=, out=)``) and the
float32 buffer handed to Blender. One update::

    V      = cage positions (Edit Mode synced), in the source's space
    moved  = cage vertices whose position differs from the last update's
    rows   = binding.influenced(moved, ordered=False)   dense vertices they move
    core.deform(binding, V, moved=moved, out=D)          only those rows
    rows  += binding.repaired(D), before and after       the fold repair's rows
    buf[rows] = D[rows]                                  float32, only those rows
    position attribute <- buf (one foreach_set), mesh tagged for redraw

Blender has no partial write of an attribute, so the last step writes the
whole buffer (a few milliseconds for a million vertices); everything before
it scales with the edit. Writing the whole buffer also means that whatever
else changed the edited mesh during a live session (an undo, a full refine)
is overwritten with the deform of the current cage; a version changed by
hand since MeshAdjust last wrote it (also between two live writes) is kept
aside first (:func:`~.results.kept_aside`). The state is rebuilt (one full deform) when
the binding object changes (re-bind, other levels or scheme), when the
edited mesh's vertex count changes, or when more than a quarter of the
cage moved (e.g. the cage's transform changed).

The refined mesh (:func:`update_refined`) goes the same way with
``core.refine(..., moved=, out=)`` and ``Binding.refined_rows``: its state is
rebuilt by a full Refine (:func:`~.refine_step.commit_refine`, which also
creates the refined mesh or links it back) when its binding changes or the
refined mesh is not the one the state wrote (its vertex or face count, or a
Refine wrote it since: :func:`~.results.holds_written`; the edited
original's state too).
"""

import time
from typing import NamedTuple

import numpy as np

from .. import core
from . import mesh_io, results, staleness, store
from .cage_steps import cage_in_source_space, check_source_in_place, turned_cage_note
from .refine_step import commit_refine, compute_refine
from .report import vertices

#: above this fraction of moved cage vertices a full deform is cheaper
FULL_FRACTION = 0.25

#: result object's session_uid (an edited original or a refined mesh) -> its :class:`_State`
_states = {}


class LiveTiming(NamedTuple):
    """What one live update did and where the time went (seconds)."""

    moved: int         #: cage vertices that moved (all of them on a full update)
    rows: int          #: dense vertices recomputed
    full: bool         #: True when the whole dense mesh was recomputed
    read_cage: float   #: binding lookup, cage positions read and put in source space
    compare: float     #: the moved cage vertices found; a hand change of the result looked for
    deform: float      #: core.deform (incremental or full)
    convert: float     #: float64 -> float32 of the recomputed rows
    write: float       #: foreach_set of the position attribute and the update tag
    total: float
    #: the edit turns cage faces over (:func:`~.cage_steps.turned_cage_note`), the source
    #: changed since the bind (:func:`~.staleness.bound_mesh_warning`)
    warning: str = ""
    note: str = ""     #: what else happened (a changed version of the edited original kept aside)

    def summary(self):
        what = "full deform" if self.full else f"{vertices(self.moved, 'cage')} moved"
        return (f"live: {what}, {self.rows:,} dense vertices updated in "
                f"{1e3 * self.total:.1f} ms (deform {1e3 * self.deform:.1f}, "
                f"write {1e3 * self.write:.1f})" + (f"; {self.note}" if self.note else "")
                + (f"; WARNING: {self.warning}" if self.warning else ""))


class _State(NamedTuple):
    """The last live update of one result (an edited original or a refined mesh)."""

    binding: object      #: the binding it was computed with
    V_cage: np.ndarray   #: (n_cage,3) float64, source space, of the last update
    out: np.ndarray      #: (n,3) float64, core.deform (or core.refine) of V_cage
    buf: np.ndarray      #: (n,3) float32, what was written to Blender


class RefinedTiming(NamedTuple):
    """What one live update of the refined mesh did and where the time went
    (seconds)."""

    moved: int         #: cage vertices that moved (all of them on a full update)
    rows: int          #: refined vertices recomputed
    full: bool         #: True when it was a full Refine
    refine: float      #: core.refine (incremental), or the whole Refine when full
    write: float       #: the rows converted, foreach_set of the position attribute
    total: float
    message: str = ""  #: the full Refine's report, or what else happened

    def summary(self):
        if self.full:
            return self.message
        return (f"refined mesh: {vertices(self.moved, 'cage')} moved, {vertices(self.rows)} "
                f"updated in {1e3 * self.total:.1f} ms (refine {1e3 * self.refine:.1f}, write "
                f"{1e3 * self.write:.1f})" + (f"; {self.message}" if self.message else ""))


def update_edited(cage):
    """Bring the cage's edited original up to date with the cage, touching
    only what the edit since the last update moved. Returns a
    :class:`LiveTiming`; the cage's ``last_report`` gets its summary.

    Raises
    ------
    core.MeshAdjustError
        The cage is not bound, or its topology changed since the bind.
    """
    t0 = time.perf_counter()
    edited, binding, V = _live_inputs(cage)
    t1 = time.perf_counter()
    state, moved = _kept_state(edited, binding, V, binding.n_dense)
    t2 = time.perf_counter()
    full = moved is None                # (no state kept that still applies, or most moved)
    changed = full or moved.size > 0    # (else nothing moved since the last update)
    if full:
        D = core.deform(binding, V)
        binding.influenced([])      # builds the incremental indices now, not on the first edit
    else:
        r = _deform_moved(binding, V, moved, state.out)
    t3 = time.perf_counter()
    notes = []
    if changed:
        # (once the deform went through, before the buffer changes: a version sculpted
        # since the last write, also between two live writes, is kept aside; 3-5 ms a
        # million vertices. Before the deform, a cage with a NaN made the copy and then
        # stopped live mode, nothing written)
        results.aside_note(results.kept_aside(edited), edited, notes)
    t_aside = time.perf_counter() - t3
    if full:
        state = _State(binding, V, D, D.astype(np.float32))
        rows = binding.n_dense
    else:
        state.buf[r] = np.take(state.out, r, axis=0)
        rows = r.shape[0]
        state = state._replace(V_cage=V)
    t4 = time.perf_counter()
    if changed:
        _write(edited, state.buf)
    _states[edited.session_uid] = state
    t5 = time.perf_counter()
    timing = LiveTiming(moved=V.shape[0] if full else int(moved.size), rows=int(rows),
                        full=full, read_cage=t1 - t0, compare=t2 - t1 + t_aside,
                        deform=t3 - t2, convert=t4 - t3 - t_aside, write=t5 - t4, total=t5 - t0,
                        warning=_warning(cage, edited, binding, V), note="; ".join(notes))
    cage.meshadjust.last_report = timing.summary()
    return timing


def _warning(cage, edited, binding, V):
    """A live update's warning ("": none): the cage faces the edit turns
    over, the source changed since the bind (as Refine's; memoised, the
    source is not what a live edit changes)."""
    said = [turned_cage_note(cage, binding, V),
            staleness.bound_mesh_warning(cage.meshadjust.source, edited)]
    return "; ".join(w for w in said if w)


def _live_inputs(cage):
    """The cage's edited original, its binding and the cage's positions in
    the source's space, checked (raises :class:`core.MeshAdjustError`)."""
    cs = cage.meshadjust
    source, edited = cs.source, cs.edited
    if source is None or edited is None:
        raise core.MeshAdjustError(f"'{cage.name}' is not a bound MeshAdjust cage")
    if not edited.users_collection:
        raise core.MeshAdjustError(f"'{edited.name}' was deleted: Refine (Edited original) "
                                   f"links it back")
    why = results.copy_problem(cage) or results.keyed_problem(edited) \
        or results.edit_mode_problem(edited)
    if why:
        raise core.MeshAdjustError(why)
    check_source_in_place(cage, source)
    return edited, store.load_binding(edited, cage), cage_in_source_space(cage, source)


def _kept_state(result, binding, V, n):
    """The state of the last update of the result ``result`` (``n`` rows
    computed with ``binding``) when it still applies, and the cage vertices
    moved since (None: a full update, also when more than ``FULL_FRACTION``
    of them moved). It applies while it is of ``binding`` and of a cage of
    ``V``'s size, and ``result`` has ``n`` vertices and holds what it wrote
    (:func:`~.results.holds_written`: not a Refine's since)."""
    state = _states.get(result.session_uid)
    if state is None or state.binding is not binding or state.V_cage.shape != V.shape \
            or state.out.shape[0] != n or len(result.data.vertices) != n \
            or not results.holds_written(result, state.buf):
        return None, None
    moved = np.flatnonzero((V != state.V_cage).any(axis=1))
    return state, (None if moved.size > FULL_FRACTION * V.shape[0] else moved)


def _deform_moved(binding, V, moved, D):
    """The incremental deform of ``D`` (in place) for the cage vertices
    ``moved``; returns the dense rows it changed (with those the fold repair
    wrote, or unwrote)."""
    r = binding.influenced(moved, ordered=False)
    before = binding.repaired(D)
    core.deform(binding, V, moved=moved, out=D)
    after = binding.repaired(D)
    if before.size or after.size:     # (a mask, not np.union1d: NumPy 2.3+ hashes its values,
        rows = np.zeros(D.shape[0], dtype=bool)   # 15 ms for 25k rows)
        for part in (r, before, after):
            rows[part] = True
        r = np.flatnonzero(rows)
    return r


def _write(edited, buf):
    """Hand the positions ``buf`` to Blender (one ``foreach_set``) and
    remember them as live mode's (:func:`~.results.record_live`)."""
    edited.data.attributes["position"].data.foreach_set("vector", buf.reshape(-1))
    mesh_io.tag_positions_changed(edited.data)      # (its normals were left as they were)
    edited.data.update_tag()
    results.record_live(edited, buf)


def update_refined(cage, rj):
    """Bring the cage's refined mesh up to date with the cage, recomputing
    only the refined vertices the edit since the last update moved; ``rj``:
    the :class:`~.refine_step.RefineJob` of a Refine of the refined mesh
    (:func:`~.refine_step.prepare_refine`: everything read and checked),
    whose refined mesh's binding is there (no finer binding to make). A
    full Refine (``rj`` computed and committed) when no kept state applies.
    Returns a :class:`RefinedTiming`."""
    t0 = time.perf_counter()
    binding = rj.finer if rj.finer is not None else rj.binding
    refined = cage.meshadjust.refined
    V = rj.V_cage
    state, moved = None, None
    if refined is not None and refined.users_collection \
            and len(refined.data.polygons) == binding.operator.F_fine.shape[0]:
        state, moved = _kept_state(refined, binding, V, binding.operator.n_fine)
    if moved is None:
        message = commit_refine(cage, compute_refine(rj)).message
        refined = cage.meshadjust.refined
        R = rj.refined.V
        binding.refined_rows([])          # (the incremental indices built now, not at the edit)
        buf = np.ascontiguousarray(R, dtype=np.float32)
        _states[refined.session_uid] = _State(binding, V, R, buf)
        results.record_live(refined, buf)
        dt = time.perf_counter() - t0
        return RefinedTiming(V.shape[0], R.shape[0], True, dt, 0.0, dt, message)
    notes = []
    rows = binding.refined_rows(moved)
    if moved.size:
        core.refine(binding, V, moved=moved, out=state.out)
    t1 = time.perf_counter()
    if moved.size:
        results.aside_note(results.kept_aside(refined), refined, notes)
        state.buf[rows] = np.take(state.out, rows, axis=0)
        _write(refined, state.buf)
    _states[refined.session_uid] = state._replace(V_cage=V)
    t2 = time.perf_counter()
    warning = _warning(cage, cage.meshadjust.edited, rj.binding, V)
    notes += [f"WARNING: {warning}"] if warning else []
    return RefinedTiming(int(moved.size), int(rows.shape[0]), False, t1 - t0, t2 - t1,
                         t2 - t0, "; ".join(notes))


def forget(edited=None):
    """Drop the kept state of one edited object (or of every result, the
    refined meshes' too): the next update is a full deform."""
    if edited is None:
        _states.clear()
    else:
        _states.pop(edited.session_uid, None)
