"""One file through the batch pipeline, timed step by step, reported honestly.

    read -> simplify -> [symmetry check] -> [fit] -> measure -> [bind -> refine] -> write

OBJ and SMF are read and written by the core (``core.read_mesh``: a bad
coordinate is an error naming the line, not a zero); PLY, STL and glTF go
through Blender (``cli.blender_io``). The geometry is the core's, as in the
add-on's ``api.compute_simplify``: QEM, the fit, the deviation of the cage
as written (fitted or not) measured with ``core.surface_distance``, the
binding and the refinement.

Outputs are written after every step (``cli.outputs``), under their final
names only when all succeeded: a file there is always a whole result.
Nothing computed is thrown away: when a step after the simplify fails (the
symmetry check, the fit, the binding or the refinement), the cage is kept as
``incomplete/NAME_cage.<ext>`` in the output folder and the file is marked
failed *in that step*, with the cause. With ``--symmetry`` an input whose
two sides differ by more than the core's ``ASYMMETRY_NOTE`` of its diagonal
gets no symmetric cage: the cage would lie between the sides and its
refinement fold into near-zero faces. A deviation that cannot be measured
(coordinates beyond what the measure takes) is a warning saying so, the
cage still written. A cage that missed its target by more than
:data:`TARGET_SLACK` or came back unchanged is a warning with the reason
(``stopped at 216 faces: 23 border loops kept``).
"""

import errno
import os
import time
from dataclasses import dataclass

import numpy as np

from .. import core
from ..core.simplify import ASYMMETRY_NOTE
from . import blender_io
from .file_check import InputFileError
from .outputs import CORE_FORMATS, INCOMPLETE_FOLDER, incomplete_path, write_outputs
from .runners import file_report

#: a cage with more than (1 + TARGET_SLACK) x its target faces is a warning
TARGET_SLACK = 0.05
#: samples per surface for the deviation (as in the add-on's reports)
MEASURE_SAMPLES = 60_000
INPUT_EXTENSIONS = CORE_FORMATS | set(blender_io.BLENDER_IMPORT)
OUTPUT_FORMATS = ("obj", "smf", "ply", "stl", "glb")


@dataclass(frozen=True)
class Options:
    """What the batch does to each file (JSON-able: workers get it as a dict)."""

    faces: int = None
    ratio: float = None
    max_error_pct: float = None      #: % of the bounding-box diagonal
    fit: bool = False
    refine: int = 0                  #: levels; 0 = no refined output
    scheme: str = "butterfly"
    feature_angle_deg: float = 60.0
    format: str = None               #: None: the input's own (glTF as glb)
    symmetry: str = None             #: 'X', 'Y' or 'Z': a cage mirror-symmetric about that plane
    max_dihedral_deg: float = None   #: no collapse bends adjacent cage faces more than this
    weld_distance: float = None      #: simplify's weld (share of the diagonal); None: automatic
    close_pinholes: bool = True      #: cap holes smaller than a cage face when they stop the cage

    @property
    def levels(self):
        """Subdivision levels of the fit and the binding."""
        return max(self.refine, 1) if (self.fit or self.refine) else 2


def output_format(path, opts):
    """The output extension (no dot) for input ``path``."""
    ext = os.path.splitext(path)[1].lower().lstrip(".")
    return opts.format or ("glb" if ext in ("gltf", "glb") else ext)


class StepFailed(Exception):
    """A step failed; ``step`` names it, the message is the cause."""

    def __init__(self, step, message):
        super().__init__(message)
        self.step = step


def _cause(exc):
    """An exception as a user-facing cause: our own errors by their message,
    anything else with its type."""
    if isinstance(exc, (core.MeshAdjustError, blender_io.BlenderIOError, InputFileError)):
        return str(exc)
    if isinstance(exc, OSError) and exc.strerror:
        return f"{exc.strerror}: {exc.filename}" if exc.filename else exc.strerror
    return f"{type(exc).__name__}: {exc}"


class _Run:
    """The report of one file, filled in as the steps run; ``on_step(name)``
    is called as each step begins (None: nothing)."""

    def __init__(self, task, on_step=None):
        self.task = task
        self.on_step = on_step
        self.log = []
        self.r = file_report(task, "ok")

    def step(self, name, fn, *args, **kwargs):
        """Run one step, timed; a failure becomes :class:`StepFailed`."""
        if self.on_step is not None:
            self.on_step(name)
        t = time.perf_counter()
        try:
            return fn(*args, **kwargs)
        except Exception as exc:    # any failure of one file is that file's, not the batch's
            raise StepFailed(name, _cause(exc)) from exc
        finally:
            self.r["phases_s"][name] = round(time.perf_counter() - t, 4)

    def fail(self, exc):
        self.r["status"] = "failed"
        self.r["failed_step"] = exc.step
        self.r["error"] = f"{self.task['name']}: {exc.step} failed: {exc}"

    def keep_incomplete(self, exc, cage):
        """After ``exc`` (a :class:`StepFailed` after the simplify), write the
        cage ``(V, F)`` as ``incomplete/NAME_cage.<ext>`` and fail the file,
        saying so."""
        path = incomplete_path(self.task["cage"])
        what = {"fit": "the cage without the fit", "symmetry": "the symmetric cage"}.get(
            exc.step, "the cage")
        self.fail(exc)
        try:
            self.step("write", write_outputs, [(path, *cage)], self.log)
        except StepFailed as failed:
            self.r["warnings"].append(f"{what} could not be kept: {failed}")
            return
        self.r["incomplete"] = [path]
        self.r["error"] = (f"{self.task['name']}: {exc.step} failed ({what} was kept as "
                           f"{os.path.join(INCOMPLETE_FOLDER, os.path.basename(path))}): {exc}")


def _read(path, log):
    """``(V, F, n_polygons, notes, warnings)`` of an input file."""
    ext = os.path.splitext(path)[1].lower()
    if os.path.isdir(path):               # (a folder named scan.obj in a folder given)
        raise IsADirectoryError(errno.EISDIR, "a folder, not a mesh file", path)
    if not os.path.isfile(path):
        if os.path.exists(path):          # (a named pipe would block the reader for ever)
            raise OSError(errno.EINVAL, "not a regular file (a named pipe, a device or a "
                          "socket)", path)
        raise FileNotFoundError(2, "no such file", path)
    if ext in CORE_FORMATS:
        m = core.read_mesh(path)
        return m.V, m.F, m.n_polygons, _skipped_notes(m), []
    if ext not in blender_io.BLENDER_IMPORT:
        raise core.InvalidArgumentError(f"unsupported file type '{ext}' (use "
                                        f"{', '.join(sorted(INPUT_EXTENSIONS))})")
    return blender_io.read_with_blender(path, log)


def _skipped_notes(m):
    """The notes of the lines a :class:`core.MeshFile` skipped: per keyword
    (``skipped 3 'vt' lines``), then those starting with no keyword (binary
    junk, NUL bytes: ``skipped 5 unreadable lines (the first is line 6)``)."""
    notes = [f"skipped {n:,} '{k}' line" + ("s" if n != 1 else "")
             for k, n in sorted(m.skipped.items())]
    if m.n_unreadable == 1:
        notes.append(f"skipped 1 unreadable line (line {m.first_unreadable:,})")
    elif m.n_unreadable:
        notes.append(f"skipped {m.n_unreadable:,} unreadable lines "
                     f"(the first is line {m.first_unreadable:,})")
    return notes


def _check_target(r, res):
    """Warnings for an unchanged cage or a target missed by more than
    :data:`TARGET_SLACK`, with the simplify's own sentence as the reason."""
    out, target = r["faces_out"], r["target_faces"]
    if out >= res.n_clean_faces and res.stopped_because != "target":
        what = "the cage came back unchanged" if res.asymmetry is None else \
            "the cage is the input's positive side mirrored"   # (its face count may be more)
        r["warnings"].append(f"{what}, no collapse possible "
                             f"({res.stopped_because.replace('_', ' ')}): {res.message}")
    elif target is not None and out > (1 + TARGET_SLACK) * target:
        r["warnings"].append(f"target {target:,} missed by {100 * (out / max(target, 1) - 1):.0f}%"
                             f": {res.message}")


def _read_input(run):
    """``(V, F)`` of the task's input, its notes and warnings reported."""
    r = run.r
    V, F, n_poly, notes, warnings = run.step("read", _read, run.task["input"], run.log)
    r["notes"] += notes
    r["warnings"] += warnings
    r["faces_in"], r["polygons_in"] = int(F.shape[0]), int(n_poly)
    if n_poly != F.shape[0]:
        r["notes"].append(f"triangulated {n_poly:,} polygons into {F.shape[0]:,} triangles")
    if F.shape[0] == 0:
        raise StepFailed("read", "no faces in the file")
    return V, F


def _simplified(run, V, F, opts):
    """The simplify's result, reported (faces, why it stopped, cleaning, notes)."""
    r = run.r
    max_error = None
    if opts.max_error_pct is not None:
        r["max_error_pct"] = opts.max_error_pct
        # of the surface's size, as the deviation (a stray loose vertex far off made the
        # bound many times what was asked: a sphere at 0.5% came back 5.4% off)
        max_error = opts.max_error_pct / 100.0 * core.surface_diagonal(V, F)
    res = run.step("simplify", core.simplify, V, F, target_faces=opts.faces,
                   ratio=opts.ratio, max_error=max_error,
                   feature_angle_deg=opts.feature_angle_deg, symmetry=opts.symmetry,
                   max_dihedral_deg=opts.max_dihedral_deg, weld_distance=opts.weld_distance,
                   close_pinholes=opts.close_pinholes)
    r["faces_out"] = int(res.F.shape[0])
    r["target_faces"] = res.target
    r["stopped_because"] = res.stopped_because
    r["message"] = res.message
    r["cleaning"] = res.cleaning.to_dict()
    if res.cleaning:
        r["notes"].append(f"cleaning: {res.cleaning.summary()}")
    _check_target(r, res)
    for note in (res.soup_note, res.sliver_note, res.pieces_note):
        if note:
            r["warnings"].append(f"the cage: {note}")
    return res


def _check_symmetry(res, opts):
    """Refuse a symmetric cage of an input whose two sides differ by more
    than ``ASYMMETRY_NOTE`` of its diagonal: the cage lies between them and
    its refinement folds into near-zero faces (a sphere 6% off its plane:
    faces 1e-17 of the median's area)."""
    if res.asymmetry is not None and res.asymmetry > ASYMMETRY_NOTE:
        raise core.InvalidArgumentError(
            f"the input is not mirror-symmetric about the plane {opts.symmetry} = 0: its two "
            f"sides differ by up to {100 * res.asymmetry:.1f}% of its size (a symmetric cage "
            f"takes at most {100 * ASYMMETRY_NOTE:g}%; beyond, it lies between them and its "
            f"refinement folds into near-zero faces): center it on its mirror plane, or leave "
            f"out --symmetry")


def _fitted(run, res, opts, creases):
    """The cage's positions: fitted with ``--fit`` to the input as simplify
    cleaned it (the fit reported)."""
    if not opts.fit:
        return res.V
    levels = min(opts.levels, core.MAX_FIT_LEVELS)        # (more cost, gain nothing)
    fit = run.step("fit", core.fit_cage, *res.cleaned, res.V, res.F, levels=levels,
                   scheme=opts.scheme, creases=creases, symmetry=opts.symmetry, clean=False)
    d = fit.mean_distance
    run.r["fit"] = {"mean_before_pct": 100 * d[0] / fit.diagonal,
                    "mean_after_pct": 100 * d[-1] / fit.diagonal, "levels": levels}
    return fit.V


def _measure(run, V, F, res, V_cage):
    """The deviation of the cage as written (``V_cage``, ``res.F``) from the
    input, over the faces the cage stands for; one that cannot be measured
    (or comes out not finite) is a warning, the report's figures empty."""
    try:
        d = run.step("measure", res.deviation, V, F, samples=MEASURE_SAMPLES, V_cage=V_cage)
    except StepFailed as exc:
        run.r["warnings"].append(f"the deviation could not be measured: {exc}")
        return
    with np.errstate(all="ignore"):
        pct = 100.0 * np.array([d.hausdorff, d.mean]) / d.diagonal
    if not (np.isfinite(pct).all() and d.diagonal > 0):
        run.r["warnings"].append(f"the deviation could not be measured: it came out "
                                 f"{d.hausdorff!r} on a diagonal of {d.diagonal!r}")
        return
    run.r["deviation_pct"], run.r["mean_deviation_pct"] = float(pct[0]), float(pct[1])
    _check_bound(run.r, res, V, F, d.diagonal)


def _check_bound(r, res, V, F, size):
    """A warning when the deviation measured (of ``size``, the diagonal of
    the faces the cage stands for) exceeds the ``--max-error`` asked. The
    simplify's bound is a share of the size of all the file's faces and
    holds against the input as cleaned: the cage lies further from the
    input itself, in its share of the size, where the cleaning dropped
    faces beyond the rest (a sphere's 300 specks of debris: 0.971% of the
    box with the specks, 1.047% of the sphere's) or changed the surface
    (the beetle at 0.5%: 0.482% from its cleaned self, 0.577% from the
    file). Both had been reported "ok"."""
    asked, got = r["max_error_pct"], r["deviation_pct"]
    if asked is None or got is None or got <= asked * (1 + 1e-9):
        return
    what = "the fitted cage" if r["fit"] else "the cage"
    done = f": {res.cleaning.summary()}" if res.cleaning else ""
    whole = core.surface_diagonal(V, F)
    if size < whole * (1 - 1e-9):
        why = (f"the bound is a share of the size of all the file's faces ({whole:.6g} across), "
               f"the deviation of the faces the cage stands for ({size:.6g}){done}")
    elif res.bound_note and not r["fit"]:
        why = res.bound_note           # (a symmetric cage of an input whose sides differ)
    elif res.hausdorff is not None and not r["fit"]:
        why = (f"the bound holds against the input as cleaned, which the cage is "
               f"{100 * res.hausdorff / size:.3f}% off{done}")
    else:
        why = "the fit moved the cage's vertices after the simplify" if r["fit"] else ""
    r["warnings"].append(f"{what} is {got:.3f}% of the input's size off the input, more than "
                         f"the {asked:g}% asked" + (f" ({why})" if why else ""))


def _results(run, V, F, res, opts):
    """``(outputs, failure)``: the ``(path, V, F)`` to write, and the
    :class:`StepFailed` of a step after the simplify or None."""
    task, creases = run.task, (res.feature_edges if len(res.feature_edges) else None)
    V_cage = res.V
    try:
        if opts.symmetry:
            run.step("symmetry", _check_symmetry, res, opts)
        V_cage = _fitted(run, res, opts, creases)
    except StepFailed as exc:
        return [(task["cage"], V_cage, res.F)], exc
    if res.n_input_pieces is None:
        _measure(run, V, F, res, V_cage)
    else:          # (a soup's overlapping pieces: 28 s for 5,805 of them, to say nothing)
        run.r["notes"].append(f"the deviation is not measured: the cage is the input's "
                              f"{res.n_input_pieces:,} separate pieces")
    outputs = [(task["cage"], V_cage, res.F)]
    if task.get("refined"):
        try:
            binding = run.step("bind", bind_for_refined, V, F, V_cage, res.F, opts.levels,
                               opts.scheme, creases)
            Vr, Fr = run.step("refine", core.refine, binding, V_cage)
        except StepFailed as exc:
            return outputs, exc
        run.r["refined_faces"] = int(Fr.shape[0])
        outputs.append((task["refined"], Vr, Fr))
    return outputs, None


def bind_for_refined(V, F, V_cage, F_cage, levels, scheme, creases):
    """The binding the refined output is made with: ``V``, ``F`` bound to the
    cage at ``levels``, or above ``core.SEED_LEVELS`` bound at those and the
    detail found at ``levels`` from that binding (:func:`core.bind_refined`:
    a 1M-vertex scan at five levels in 2.6x less CPU time than a bind there,
    nearly every refined vertex the same)."""
    if levels <= core.SEED_LEVELS:
        return core.bind(V, F, V_cage, F_cage, levels=levels, scheme=scheme, creases=creases)
    seed = core.bind(V, F, V_cage, F_cage, levels=core.SEED_LEVELS, scheme=scheme,
                     creases=creases)
    return core.bind_refined(seed, V, levels)


def _shared_positions(V, F):
    """How many of the vertices ``F`` uses sit where another used vertex
    sits (the used vertices less their distinct positions): a mask, a sort
    of the x coordinates, and a sort of the rows only among equal ones
    (``np.unique(F)`` and ``np.unique(..., axis=0)`` took 4.5 s for 2M
    vertices, this 0.3)."""
    used = np.zeros(V.shape[0], dtype=bool)
    used[F.ravel()] = True
    P = V[used]
    order = np.argsort(P[:, 0], kind="stable")
    tie = np.flatnonzero(P[order[1:], 0] == P[order[:-1], 0])
    if not tie.size:
        return 0
    both = np.zeros(P.shape[0], dtype=bool)     # (not np.union1d: NumPy 2.3+ hashes it)
    both[tie] = True
    both[tie + 1] = True
    Q = P[order[np.flatnonzero(both)]]
    S = Q[np.lexsort(Q.T[::-1])]
    return int(np.count_nonzero((S[1:] == S[:-1]).all(axis=1)))


def _stl_joins(outputs):
    """Warnings for the STL ``outputs`` (``(path, V, F)``) with vertices that
    share a position with another (a bow-tie the cleaning split, a seam):
    STL stores each triangle's corners and no connectivity, so any reader
    joins them again, and a cage read back has the bow-tie the cleaning
    took apart."""
    warnings = []
    for path, V, F in outputs:
        if os.path.splitext(path)[1].lower() != ".stl":
            continue
        shared = _shared_positions(V, F)
        if shared:
            warnings.append(
                f"{os.path.basename(path)}: {shared:,} of its vertices share a position with "
                f"another (a bow-tie split apart); STL keeps no connectivity, so whatever reads "
                f"it joins them again: write OBJ or PLY (--format obj) to keep them apart")
    return warnings


def convert(task, opts, *, on_step=None):
    """Convert one file; returns its report (a JSON-able dict).

    ``task``: ``input`` (path), ``name`` (as shown), ``cage`` (output path),
    ``refined`` (output path or None). Never raises for a bad file: the
    report's ``status`` is ``"failed"`` and ``error`` names the file, the
    step and the cause. ``KeyboardInterrupt`` goes through. ``on_step(name)``
    is called as each step (``read``, ``simplify``, ... ``write``) begins: a
    worker prints it, and the batch's ``--timeout`` names the step a file
    was stopped in.
    """
    run = _Run(task, on_step)
    r = run.r
    t_start = time.perf_counter()
    try:
        V, F = _read_input(run)
        res = _simplified(run, V, F, opts)
        outputs, failure = _results(run, V, F, res, opts)
        r["warnings"] += _stl_joins(outputs)
        if failure is None:
            run.step("write", write_outputs, outputs, run.log)
            r["outputs"] = [path for path, _, _ in outputs]
        else:
            run.keep_incomplete(failure, outputs[0][1:])
    except StepFailed as exc:
        run.fail(exc)
    if r["status"] == "ok" and r["warnings"]:
        r["status"] = "warn"
    r["seconds"] = round(time.perf_counter() - t_start, 4)
    r["log"] = "".join(run.log)
    return r
