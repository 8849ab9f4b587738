"""Where a file's outputs go: a complete result under its final names,
anything less beside them under a name that says so.

    all steps done  -> each output to .part-<pid>-<k>.<ext> in its folder -> all renamed
    a step failed after the simplify -> the cage as incomplete/NAME_cage.<ext> in the
                                        output folder, nothing under the final names

A file under its final name (``NAME_cage.obj``, ``NAME_refined.obj``) is
therefore always the whole result of a run whose every step succeeded (the
report's status ``ok`` or ``warn``): ``--skip-existing`` and make-like
pipelines can take its presence as done. The final names' rename comes last,
after every compute, and a run that completes removes the incomplete file
an earlier failed run left. An incomplete file keeps its final name's
length, in a folder of its own: a name the output folder takes always fits
(``NAME_cage.incomplete.obj`` would not, for a 240-character stem).

:func:`write_problem` checks, before any compute, that a path can be
written: the file system's limits on names (a 250-character stem) and the
folder's permissions are only known by trying.
"""

import contextlib
import json
import os

from .. import core
from . import blender_io

CORE_FORMATS = {".obj", ".smf"}
#: the folder, in the output folder, of the results a failed step left
INCOMPLETE_FOLDER = "incomplete"


#: in the output folder: a line per output file written there, naming the input it was
#: made from (its real path, size and modification time), which ``--skip-existing``
#: compares; appended to (a whole JSON file rewritten after each of a batch's n files is
#: O(n^2) bytes: some 15 GB over 10,000 files, by estimate), an output's last line counting
SOURCES_FILE = ".meshadjust-sources.jsonl"


def source_stamp(path):
    """What identifies the input file ``path`` for :data:`SOURCES_FILE`: its
    real path, size and modification time (None when it cannot be read)."""
    try:
        st = os.stat(path)
    except OSError:
        return None
    return {"input": os.path.realpath(path), "size": st.st_size, "mtime_ns": st.st_mtime_ns}


def read_sources(folder):
    """The :data:`SOURCES_FILE` of ``folder``: output file name -> its input's
    :func:`source_stamp`, from its last line (empty when there is none or it
    cannot be read; a line cut short is passed over: its output runs again)."""
    found = {}
    try:
        with open(os.path.join(folder, SOURCES_FILE), encoding="utf-8") as fh:
            for line in fh:
                with contextlib.suppress(ValueError, TypeError, KeyError, AttributeError):
                    entry = json.loads(line)
                    found[entry.pop("output")] = entry
    except OSError:
        return {}
    return found


def record_sources(folder, written):
    """Append ``written`` (output file name -> :func:`source_stamp` of its
    input) to ``folder``'s :data:`SOURCES_FILE`, a line each (the newline
    first: a line an interrupted batch cut short leaves the next one whole).
    Returns False when it could not be written: a later ``--skip-existing``
    then converts those inputs again, nothing worse."""
    lines = "".join("\n" + json.dumps({"output": name, **(stamp or {})}, sort_keys=True)
                    for name, stamp in written.items())
    try:
        with open(os.path.join(folder, SOURCES_FILE), "a", encoding="utf-8") as fh:
            fh.write(lines)
    except OSError:
        return False
    return True


def incomplete_path(path):
    """Where the incomplete result of output ``path`` goes:
    ``out/incomplete/NAME_cage.obj`` for ``out/NAME_cage.obj``."""
    folder, base = os.path.split(path)
    return os.path.join(folder, INCOMPLETE_FOLDER, base)


def write_problem(path):
    """Why ``path`` cannot be written (the system's words, e.g. ``File name
    too long``), or None. A path that does not exist yet is created and
    removed again: only the file system knows which names it takes."""
    if os.path.isdir(path):
        return "it is a folder"
    if os.path.exists(path):
        return None                      # replaced by a rename: the folder's permission counts
    try:
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
    except FileExistsError:              # made in between: the name is a valid one
        return None
    except OSError as exc:
        return exc.strerror or str(exc)
    os.close(fd)
    os.remove(path)
    return None


def _write_one(tmp, path, V, F, log):
    """Write ``V``, ``F`` to ``tmp`` in ``path``'s format; errors name ``path``."""
    stem, ext = os.path.splitext(os.path.basename(path))
    try:
        if ext.lower() in CORE_FORMATS:
            core.write_mesh(tmp, V, F)
        else:
            blender_io.write_with_blender(tmp, V, F, log, name=stem, shown=path)
    except OSError as exc:
        raise OSError(exc.errno, exc.strerror, path) from exc


def part_path(path, k, pid):
    """The temporary name of output ``path``, the ``k``-th of its file's,
    written by process ``pid``: ``.part-<pid>-<k>.<ext>`` in its folder."""
    return os.path.join(os.path.dirname(path), f".part-{pid}-{k}{os.path.splitext(path)[1]}")


def remove_dead_parts(task, pid):
    """Remove the temporary outputs of ``task`` (its ``cage`` and ``refined``
    paths, or its incomplete cage) that process ``pid`` left when it died in
    the middle of writing them (a worker killed by a crash or SIGKILL: its
    own clean-up never ran)."""
    for paths in ([task["cage"], task["refined"]], [incomplete_path(task["cage"])]):
        for k, path in enumerate(p for p in paths if p):
            if os.path.isfile(part_path(path, k, pid)):
                os.remove(part_path(path, k, pid))


def write_outputs(outputs, log):
    """Write ``outputs``, a list of ``(path, V, F)``, each to a short
    temporary name in its folder (``.part-<pid>-<k>.<ext>``: any name the
    folder takes does), then rename them all to their paths; a run that
    completes this removes the incomplete files of an earlier one. An
    ``OSError`` names the path asked for, never the temporary one."""
    tmps = []
    try:
        for k, (path, V, F) in enumerate(outputs):
            os.makedirs(os.path.dirname(path) or ".", exist_ok=True)
            tmps.append(part_path(path, k, os.getpid()))
            _write_one(tmps[-1], path, V, F, log)
        _rename_all(tmps, [path for path, _, _ in outputs])
    finally:
        for tmp in tmps:
            if os.path.exists(tmp):
                os.remove(tmp)
    for path, _, _ in outputs:
        _remove_incomplete(incomplete_path(path))


def _rename_all(tmps, paths):
    """Rename each of ``tmps`` to its path of ``paths``, all or none: when a
    rename fails or a cancel (``KeyboardInterrupt``: a worker's SIGTERM, from
    Ctrl-C or ``--timeout``) comes between two, those already renamed are
    removed again (a cancel there would leave a cage under its final name
    without its refined mesh, its file reported cancelled or timed out)."""
    renamed = []
    try:
        for tmp, path in zip(tmps, paths):
            try:
                os.replace(tmp, path)
            except OSError as exc:
                raise OSError(exc.errno, exc.strerror, path) from exc
            renamed.append(path)
    except (OSError, KeyboardInterrupt):
        for path in renamed:
            with contextlib.suppress(OSError):
                os.remove(path)
        raise


def _remove_incomplete(path):
    """Remove an earlier run's incomplete result, and its folder once empty."""
    if os.path.isfile(path):
        os.remove(path)
        try:
            os.rmdir(os.path.dirname(path))
        except OSError:               # other files in it
            pass
