"""Live refine: keep a cage's results updated while it is edited.

A ``depsgraph_update_post`` handler notices geometry and transform updates
of cages whose ``live`` toggle is on and schedules one refine through ``bpy.app.timers``,
at most every ``live_interval`` seconds (add-on preferences), so the viewport
stays responsive on dense meshes. The edited original is updated by
:func:`.live_update.update_edited`: only the cage vertices that moved since
the last update are followed through the binding (``core.deform`` with
``moved=``), so an update costs what the edit touches, not the whole scan.
The refined mesh goes the same way (:func:`.live_update.update_refined`:
``core.refine`` with ``moved=``); the shape key through ``api.refine_object``.
The first refined mesh at more levels than the edit's binding needs its own
binding (seconds on a large scan, :func:`.refine_step.make_finer`), made in
a worker thread while the viewport stays responsive, the refined mesh
updated when it is there.
Errors turn live mode off for that cage and are kept in its ``last_report``
rather than raised inside the handler.
"""

import threading
import time

import bpy

from .. import core
from . import api, app_handlers, live_update, results
from .properties import preferences

#: the pending cages: the name each was scheduled under -> its session_uid (None: found by
#: the name alone); a cage renamed before its update ran had been skipped (its edit followed
#: only at the next one)
_pending = {}
_last_run = {}
#: cage name -> (worker thread making its refined mesh's finer binding, {"error": exception},
#: the timer that looks for it)
_finer = {}
#: seconds between looks at a finer binding's worker
_FINER_POLL = 0.25


def _interval():
    prefs = preferences()
    return prefs.live_interval if prefs is not None else 0.15


def refine_pending():
    """Run the scheduled live refines (the timer callback; also callable
    directly, e.g. in tests). Returns None so the timer does not repeat."""
    uids = dict(_pending)
    _pending.clear()
    output = 'EDITED'
    scene = bpy.context.scene
    if scene is not None and hasattr(scene, "meshadjust"):
        output = scene.meshadjust.output
    for name, uid in uids.items():
        cage = bpy.data.objects.get(name)
        if uid is not None and (cage is None or cage.session_uid != uid):     # renamed
            cage = next((o for o in bpy.data.objects if o.session_uid == uid), None) or cage
        if cage is None or not cage.meshadjust.live:
            continue
        if cage.meshadjust.edited is None:
            # (removed for good, bpy.data.objects.remove: live stayed on, did nothing and
            # kept its last "... updated" line)
            cage.meshadjust.live = False
            cage.meshadjust.last_report = (f"live refine stopped: '{cage.name}' has no edited "
                                           f"original any more (deleted): Bind makes it again")
            continue
        name = cage.name
        try:
            if output in ('EDITED', 'BOTH'):
                report = live_update.update_edited(cage).summary()
                if output == 'BOTH':
                    report += "; " + _refine_refined(cage)
                cage.meshadjust.last_report = report
            elif output == 'REFINED':
                cage.meshadjust.last_report = _refine_refined(cage)
            else:
                api.refine_object(cage, output=output)
        except core.MeshAdjustError as exc:
            cage.meshadjust.live = False
            cage.meshadjust.last_report = f"live refine stopped: {exc}"
        except Exception as exc:           # a bug: live stops (not a traceback per edit)
            cage.meshadjust.live = False
            cage.meshadjust.last_report = (f"live refine stopped by an internal error "
                                           f"({type(exc).__name__}: {exc}); please report it")
            raise
        _last_run[name] = time.monotonic()
    return None


def _refine_refined(cage):
    """Live's update of the cage's refined mesh (a Refine of it); its report.
    When the refined mesh first needs its finer binding, that binding is made
    in a worker thread (:func:`finer_done` looks for it, then refines)."""
    entry = _finer.get(cage.name)
    if entry is not None and bpy.app.timers.is_registered(entry[2]):
        return "the refined mesh's binding is being made (first time): it follows then"
    # (an entry whose timer is gone: a file was loaded while its worker ran, and the
    # binding it makes is of that file's objects; every later tick had waited for it)
    _finer.pop(cage.name, None)
    rj = api.prepare_refine(cage, output='REFINED')
    if not rj.finer_levels:
        return live_update.update_refined(cage, rj).summary()
    box = {}

    def work():
        try:
            api.make_finer(rj)
        except Exception as exc:      # (reported from the main thread by finer_done)
            box["error"] = exc

    thread = threading.Thread(target=work, daemon=True)
    name = cage.name

    def look():
        return finer_done(name)
    _finer[name] = (thread, box, look)
    thread.start()
    bpy.app.timers.register(look, first_interval=_FINER_POLL)
    return (f"binding the refined mesh at {rj.finer_levels} levels in the background (first "
            f"time): it follows then")


def finer_done(name):
    """The timer that looks for the finer binding of cage ``name`` (live
    mode): while its worker runs, again in ``_FINER_POLL`` seconds; then the
    refined mesh updated (a live refine of the cage), or its error reported
    and live mode stopped. Returns the next interval or None."""
    thread, box, _ = _finer.get(name, (None, {}, None))
    if thread is not None and thread.is_alive():
        return _FINER_POLL
    _finer.pop(name, None)
    cage = bpy.data.objects.get(name)
    if cage is None or not cage.meshadjust.live:
        return None
    error = box.get("error")
    if isinstance(error, core.MeshAdjustError):
        cage.meshadjust.live = False
        cage.meshadjust.last_report = f"live refine stopped: {error}"
    elif error is not None:          # a bug: live stops, and it shows as one
        cage.meshadjust.live = False
        cage.meshadjust.last_report = (f"live refine stopped by an internal error "
                                       f"({type(error).__name__}: {error}); please report it")
        raise error
    else:
        _pending.setdefault(name, None)
        refine_pending()
    return None


@bpy.app.handlers.persistent   # stays registered when a .blend is loaded
def on_depsgraph_update(scene, depsgraph):
    """Schedule a throttled refine for every live cage whose geometry or
    object transform changed (a cage moved as an object moves the results,
    as Refine does)."""
    for update in depsgraph.updates:
        obj = update.id
        if not isinstance(obj, bpy.types.Object) or not (update.is_updated_geometry
                                                         or update.is_updated_transform):
            continue
        obj = obj.original
        if obj.type != 'MESH' or obj.meshadjust.role != 'CAGE' or not obj.meshadjust.live:
            continue
        schedule(obj)


def schedule(cage):
    """Schedule a throttled live refine of the object ``cage`` (once while
    one is pending; found again by its session_uid if renamed meanwhile)."""
    name = cage.name
    waiting = name in _pending
    _pending[name] = cage.session_uid
    if waiting:
        return
    wait = max(0.0, _interval() - (time.monotonic() - _last_run.get(name, 0.0)))
    if not bpy.app.timers.is_registered(refine_pending):
        bpy.app.timers.register(refine_pending, first_interval=wait)


def live_toggled(state, _context):
    """The ``live`` property's update: a cage put live is brought up to date
    at once (an edit made while live was off had stayed unapplied until the
    next one)."""
    cage = state.id_data
    if state.live and isinstance(cage, bpy.types.Object) and state.role == 'CAGE':
        schedule(cage)


@bpy.app.handlers.persistent
def on_save_pre(*_args):
    """Before a save: what live mode wrote is recorded as checksums, so a
    result sculpted after a reload is still found changed (the buffers are
    gone then)."""
    results.settle_live_written()


_HANDLERS = (("depsgraph_update_post", on_depsgraph_update), ("save_pre", on_save_pre))


def register():
    app_handlers.add(_HANDLERS)


def unregister():
    app_handlers.remove(_HANDLERS)
    for look in [entry[2] for entry in _finer.values()] + [refine_pending]:
        if bpy.app.timers.is_registered(look):
            bpy.app.timers.unregister(look)
    _pending.clear()
    _finer.clear()
    live_update.forget()
