#!/usr/bin/env python3
"""Benchmark: bind / deform / refine against Blender's Surface Deform modifier.

Run with Blender as a Python module (the bpy venv)::

    python scripts/bench_adjust.py            # full run, writes bench_results/adjust.md
    python scripts/bench_adjust.py --quick    # smaller meshes, no file written

Part 1, the analytic bend (same dense mesh, same cage, same edit for both):
an open tube (length 3, radius 0.3) with bumps of amplitude h is simplified
to an 800-face cage with ``core.simplify``; the cage is bent a quarter turn
with an analytic bend; the dense mesh is deformed by (a) ``core.deform``
after ``core.bind`` on the subdivided cage (two butterfly levels) and (b)
Blender's Surface Deform bound to the same cage. Both are compared with the
same bend applied to the dense vertices (the ground truth); errors are in
units of h. "plain cage" is the distance of the bent dense surface to the
subdivided bent cage (what the edit gives without the detail).

Part 2, scale: a bumpy torus of 1M vertices bound to a 10k-face cage at two
levels (targets: bind <= 15 s, re-deform <= 0.3 s, bind <= 0.5x Surface
Deform's); Surface Deform on the same pair, binds alternating, best of 3, wall
and CPU time. Then binds at an artist's sizes (the bunny, the bunny with one
vertex 1,000 diagonals off (a scan's spike, kept by its cage), bumpy tori of 100k,
250k and 1M vertices, 2,000-face cages, Loop x2: the add-on's Auto levels for
the edit; and the 1M one also at five, Auto's levels for the refined mesh,
which a Refine binds at when asked for it) against Surface Deform's.

Part 4, folds (``--only folds``): for every mesh in ../shared/meshes and a
1.1M-triangle synthetic scan (the bunny split twice, with noise), a QEM cage
of 2,000 faces fitted for each scheme, and artist-like edits at two cage
vertices: the vertex and its one-ring lifted along its normal by 1% and 3%
of the diagonal, and a smooth 5% lift with quartic falloff over 12%. Dense
faces turned by more than 90 degrees for ``core.deform`` with butterfly and
with Loop, and for Surface Deform on the same cage and edit; then per case
our bind against Surface Deform's and full against incremental deform
(``moved=`` the one-ring, and 5 random cage vertices: a first move and a
drag, each against the full deform of the same edited cage).

Part 5, live (``--only live``): one live update of a 1M-vertex scan through
the add-on (simplify + bind by the operator, then 5 neighbouring cage
vertices moved and ``live_update.update_edited``), with its breakdown, each
update moving other cage vertices; then a drag (the same vertices moved
again); at the add-on's default levels (Auto: two for the edit) and at five
(the levels closest to this scan's face count, chosen by hand). At Auto also
the refined mesh's live updates (the Refined output: the first a full Refine,
the next ones incremental) beside Blender's Subdivision Surface modifier on
the cage at about as many faces, evaluated after the same edits.

Part 3, fit (when ../shared/meshes is present): the QEM cage of 2,000
faces of the bunny, homer, rocker-arm and spot, before and after
``fit_cage``: two-sided mean distance and enclosed volume of the subdivided
cage (two butterfly levels).

Fixed seeds; both tools run in the same process on the same arrays.
"""

import argparse
import os
import sys
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from core.binding import Binding, bind, bind_refined, deform, refine  # noqa: E402
from core.fit import fit_cage  # noqa: E402
from core.io_obj import read_obj  # noqa: E402
from core.errors import MeshAdjustError  # noqa: E402
from core.mesh import bbox_diagonal, enclosed_volume, turned_faces, vertex_normals  # noqa: E402
from core.metrics import surface_distance  # noqa: E402
from core.simplify import simplify  # noqa: E402
from core.spatial import closest_points  # noqa: E402
from core.subdivide import subdivision_operator  # noqa: E402
from tests.mesh_factory import (BUMP, analytic_bend as bend, bumpy_tube, cad_cylinder,  # noqa: E402
                                 midpoint_split, torus)
from _bench import (blas_line, blender_object, empty_scene, evaluated_positions,  # noqa: E402
                    mesh_io)

SHARED = os.path.normpath(os.path.join(ROOT, "..", "shared", "meshes"))


def bumpy_torus(n_major, n_minor, bump=0.01):
    return torus(n_major, n_minor, bump=bump, bump_waves=(40, 20))


# ------------------------------------------------------------------ Blender side
def surface_deform_bound(V_dense, F_dense, V_cage, F_cage):
    """Blender's Surface Deform bound to the cage in an empty scene:
    (dense object, cage object, bind seconds, bind CPU seconds of this process)."""
    bpy = empty_scene()
    dense = blender_object("dense", V_dense, F_dense)
    cage = blender_object("cage", V_cage, F_cage)
    mod = dense.modifiers.new("SurfaceDeform", "SURFACE_DEFORM")
    mod.target = cage
    bpy.context.view_layer.objects.active = dense
    dense.select_set(True)
    t, c = time.perf_counter(), time.process_time()
    with bpy.context.temp_override(object=dense, active_object=dense):
        bpy.ops.object.surfacedeform_bind(modifier=mod.name)
    evaluated_positions(dense)  # the bind happens on the next evaluation
    t_bind, c_bind = time.perf_counter() - t, time.process_time() - c
    if not mod.is_bound:
        raise RuntimeError("Surface Deform did not bind")
    return dense, cage, t_bind, c_bind


def surface_deform(V_dense, F_dense, V_cage, F_cage, V_cage_edited):
    """Blender's Surface Deform: (bind seconds, deform seconds, deformed positions,
    bind CPU seconds)."""
    dense, cage, t_bind, c_bind = surface_deform_bound(V_dense, F_dense, V_cage, F_cage)
    mesh_io().write_positions(cage.data, V_cage_edited)
    t = time.perf_counter()
    out = evaluated_positions(dense)
    t_def = time.perf_counter() - t
    return t_bind, t_def, out, c_bind


# ------------------------------------------------------------------ runs
def run_bend(quick):
    Vd, Fd = bumpy_tube(240, 96) if quick else bumpy_tube(480, 192)
    cage = simplify(Vd, Fd, target_faces=800)
    Vc, Fc = cage.V, cage.F
    creases = cage.feature_edges if len(cage.feature_edges) else None
    G = bend(Vd)
    Ve = bend(Vc)
    rows = []

    t = time.perf_counter()
    b = bind(Vd, Fd, Vc, Fc, levels=2, creases=creases)
    t_bind = time.perf_counter() - t
    deform(b, Ve)
    t = time.perf_counter()
    D = deform(b, Ve)
    t_def = time.perf_counter() - t
    err = np.linalg.norm(D - G, axis=1) / BUMP
    rows.append(("MeshAdjust bind/deform (butterfly x2)", t_bind, t_def, err.max(), err.mean()))

    t = time.perf_counter()
    fit = fit_cage(Vd, Fd, Vc, Fc, levels=2, creases=creases)
    t_fit = time.perf_counter() - t
    t = time.perf_counter()
    bf = bind(Vd, Fd, fit.V, Fc, levels=2, creases=creases)
    t_bind_f = time.perf_counter() - t
    t = time.perf_counter()
    Df = deform(bf, bend(fit.V))
    t_def_f = time.perf_counter() - t
    err_f = np.linalg.norm(Df - G, axis=1) / BUMP
    rows.append((f"MeshAdjust fit ({t_fit:.2f} s) + bind/deform", t_bind_f, t_def_f,
                 err_f.max(), err_f.mean()))

    for scheme in ("loop",):
        t = time.perf_counter()
        fit_l = fit_cage(Vd, Fd, Vc, Fc, levels=2, scheme=scheme, creases=creases)
        t_fit_l = time.perf_counter() - t
        t = time.perf_counter()
        bl = bind(Vd, Fd, fit_l.V, Fc, levels=2, scheme=scheme, creases=creases)
        t_bind_l = time.perf_counter() - t
        t = time.perf_counter()
        Dl = deform(bl, bend(fit_l.V))
        t_def_l = time.perf_counter() - t
        err_l = np.linalg.norm(Dl - G, axis=1) / BUMP
        rows.append((f"MeshAdjust {scheme} x2: fit ({t_fit_l:.2f} s) + bind/deform", t_bind_l,
                     t_def_l, err_l.max(), err_l.mean()))

    op = b.operator
    plain = closest_points(op.apply(Ve), op.F_fine, G).distance / BUMP
    rows.append(("plain subdivided bent cage (no detail)", float("nan"), float("nan"),
                 plain.max(), plain.mean()))

    Vr, Fr = refine(b, Ve)
    ref = closest_points(G, Fd, Vr).distance / BUMP
    rows.append(("MeshAdjust refine (regular mesh, fine vertices to truth)", float("nan"),
                 float("nan"), ref.max(), ref.mean()))

    sd_bind, sd_def, S, _ = surface_deform(Vd, Fd, Vc, Fc, Ve)
    err_s = np.linalg.norm(S - G, axis=1) / BUMP
    rows.append(("Blender Surface Deform (same cage)", sd_bind, sd_def, err_s.max(), err_s.mean()))
    info = (f"dense bumpy tube {Vd.shape[0]:,} vertices / {Fd.shape[0]:,} faces (length 3, "
            f"radius 0.3, bump h = {BUMP}), QEM cage {Fc.shape[0]} faces ({Vc.shape[0]} "
            f"vertices), axis bent a quarter turn")
    return info, rows, err.mean() / max(err_s.mean(), 1e-300)


def run_scale(quick):
    n_major, n_minor = (400, 250) if quick else (1000, 1000)
    Vd, Fd = bumpy_torus(n_major, n_minor)
    Vc, Fc = bumpy_torus(100, 50, bump=0.0)
    Ve = Vc.copy()
    Ve[:, 2] += 0.2 * np.exp(-((Vc[:, 0] - 1.0) ** 2 + Vc[:, 1] ** 2) / 0.1)
    rows = []
    # ours and Surface Deform alternate, three times, best of each (the machine is
    # shared: alternating keeps a load change from favouring one side); wall and CPU
    # time of this process (both tools run threads in it)
    t_binds, sd_binds, sd_defs, c_binds, sd_cpus = [], [], [], [], []
    for _ in range(1 if quick else 3):
        t, c = time.perf_counter(), time.process_time()
        b = bind(Vd, Fd, Vc, Fc, levels=2)
        t_binds.append(time.perf_counter() - t)
        c_binds.append(time.process_time() - c)
        sd_bind, sd_def, _, sd_cpu = surface_deform(Vd, Fd, Vc, Fc, Ve)
        sd_binds.append(sd_bind)
        sd_defs.append(sd_def)
        sd_cpus.append(sd_cpu)
    t_bind = min(t_binds)
    times = []
    for _ in range(3):
        t = time.perf_counter()
        deform(b, Ve)
        times.append(time.perf_counter() - t)
    t = time.perf_counter()
    refine(b, Ve)
    t_ref = time.perf_counter() - t
    rows.append(("MeshAdjust bind (2 levels) / deform (best of 3)", t_bind, min(times), t_ref))
    rows.append(("Blender Surface Deform (cage itself)", min(sd_binds), min(sd_defs),
                 float("nan")))
    info = (f"dense torus {Vd.shape[0]:,} vertices / {Fd.shape[0]:,} faces, cage {Fc.shape[0]:,} "
            f"faces; binds alternating ours / Surface Deform, best of {len(t_binds)}: ours "
            + ", ".join(f"{t:.2f}" for t in t_binds) + " s, Surface Deform "
            + ", ".join(f"{t:.2f}" for t in sd_binds) + f" s; bind ratio {t_bind / min(sd_binds):.2f} "
            f"(target <= 0.5); CPU time ours {min(c_binds):.2f} s, Surface Deform "
            f"{min(sd_cpus):.2f} s (ratio {min(c_binds) / min(sd_cpus):.2f})")
    return info, rows


def spiked(V, F, far=1e3):
    """``(V, F)`` with vertex 5 moved ``far`` bounding-box diagonals along x
    (a scan's bad depth sample: its faces a spike across the box)."""
    V = np.array(V, dtype=float)
    V[5, 0] += far * float(np.linalg.norm(V.max(axis=0) - V.min(axis=0)))
    return V, F


def run_typical_binds(quick):
    """Binds at an artist's sizes (a scan of 36k-250k vertices, the bunny also
    with a spike, a 2,000-face cage, two levels, the add-on's Loop; and,
    without ``quick``, a 1M-vertex scan at two levels and at the levels
    closest to its face count, the add-on's Auto for the refined mesh), ours
    and Surface Deform's
    alternating, best of 3 (of 1 with ``quick``): rows (case, dense
    vertices, levels label, ours s, Surface Deform s)."""
    cases = [("bumpy torus 100k", *bumpy_torus(400, 250))]
    if not quick:
        cases.append(("bumpy torus 250k", *bumpy_torus(625, 400)))
        cases.append(("bumpy torus 1M", *bumpy_torus(1000, 1000)))
    bunny = os.path.join(SHARED, "stanford-bunny.obj")
    if os.path.exists(bunny):
        V, F = read_obj(bunny)[:2]
        cases[:0] = [("stanford-bunny", V, F),
                     ("stanford-bunny, one vertex 1,000 diagonals off (a spike)", *spiked(V, F))]
    from meshadjust_batch import load_package
    steps = load_package().meshadjust_addon.cage_steps
    rows = []
    for name, V, F in cases:
        cage = simplify(V, F, target_faces=2000)
        edit = steps.edit_levels(cage.F.shape[0], F.shape[0])
        auto = steps.auto_levels(cage.F.shape[0], F.shape[0])
        two = None
        for levels in [2] + ([auto] if name.endswith("1M") and auto != 2 else []):
            ours, theirs, finer = [], [], []
            for _ in range(1 if quick else 3):
                t = time.perf_counter()
                b = bind(V, F, cage.V, cage.F, levels=levels, scheme="loop")
                ours.append(time.perf_counter() - t)
                theirs.append(surface_deform_bound(V, F, cage.V, cage.F)[2])
                if levels == 2:
                    two = b
                else:                 # the refined mesh's binding as Refine makes it
                    t = time.perf_counter()
                    bind_refined(two, V, levels)
                    finer.append(time.perf_counter() - t)
            label = f"{levels}" + (" (Auto)" if levels == edit else
                                   " (Auto, refined)" if levels == auto else "")
            rows.append((name, V.shape[0], label, min(ours), min(theirs)))
            if finer:
                rows.append((name, V.shape[0], f"{levels} (Auto, refined): bind_refined from "
                             "the two-level binding", min(finer), min(theirs)))
    return rows


def run_fit(names, built=()):
    """QEM cage of 2,000 faces, two butterfly levels: distance and volume
    before/after fit_cage, for the shared meshes ``names`` and the ``built``
    (name, V, F) cases."""
    rows = []
    cases = [(name, *read_obj(os.path.join(SHARED, name))[:2]) for name in names
             if os.path.exists(os.path.join(SHARED, name))]
    for name, V, F in cases + list(built):
        cage = simplify(V, F, target_faces=2000)
        creases = cage.feature_edges if len(cage.feature_edges) else None
        t = time.perf_counter()
        fit = fit_cage(V, F, cage.V, cage.F, levels=2, scheme="butterfly", creases=creases)
        t_fit = time.perf_counter() - t
        op = subdivision_operator(cage.F, cage.V.shape[0], levels=2, creases=creases)
        vol = enclosed_volume(V, F)
        out = []
        for Vc in (cage.V, fit.V):
            Vf = op.apply(Vc)
            d = surface_distance(V, F, Vf, op.F_fine)
            out.append((d.mean_pct, d.hausdorff_pct, 100 * (enclosed_volume(Vf, op.F_fine) - vol) / vol))
        rows.append((name, cage.F.shape[0], t_fit, out[0], out[1]))
    return rows


# ------------------------------------------------------------------ folds
FOLD_SCHEMES = ("butterfly", "loop")


def synthetic_scan(levels=2, noise=1e-4, seed=0):
    """The bunny midpoint-split ``levels`` times (1.1M triangles for 2) with
    noise of ``noise`` diagonals (fixed seed): a ~1M-triangle stand-in scan."""
    V, F = read_obj(os.path.join(SHARED, "stanford-bunny.obj"))
    used = np.zeros(V.shape[0], dtype=bool)
    used[F.ravel()] = True
    remap = np.cumsum(used) - 1
    V, F = V[used], remap[F]
    for _ in range(levels):
        V, F = midpoint_split(V, F)
    rng = np.random.default_rng(seed)
    return V + rng.normal(scale=noise * bbox_diagonal(V), size=V.shape), F


def one_ring(F, v):
    """``v`` and its neighbours in the triangles ``F``."""
    rows = np.flatnonzero((F == v).any(axis=1))
    return np.unique(np.concatenate([[v], F[rows].ravel()]))


def artist_edits(Vc, Fc, diag, centres):
    """Per centre cage vertex: its one-ring lifted along its normal by 1% and
    3% of the diagonal, and a smooth proportional lift of 5% (weight
    (1 - (d/r)^2)^2, r = 12% of the diagonal). Returns [(label, V_edited)]."""
    N = vertex_normals(Vc, Fc)
    out = []
    for v in centres:
        ring = one_ring(Fc, v)
        for pct in (1, 3):
            Ve = Vc.copy()
            Ve[ring] += pct / 100 * diag * N[v]
            out.append((f"v{v} one-ring {pct}%", Ve))
        d = np.linalg.norm(Vc - Vc[v], axis=1) / (0.12 * diag)
        w = np.clip(1 - d ** 2, 0.0, None) ** 2
        out.append((f"v{v} smooth 5%", Vc + 0.05 * diag * w[:, None] * N[v]))
    return out


def count_folds(V_rest, V_new, F):
    """Faces whose normal turned by more than 90 degrees (``core.turned_faces``)."""
    return int(turned_faces(V_rest, V_new, F).size)


def surface_deform_many(V_dense, F_dense, V_cage, F_cage, edits):
    """Surface Deform bound once, evaluated for each edited cage: list of
    deformed positions, and the bind seconds."""
    dense, cage, t_bind, _ = surface_deform_bound(V_dense, F_dense, V_cage, F_cage)
    out = []
    for Ve in edits:
        mesh_io().write_positions(cage.data, Ve)
        out.append(evaluated_positions(dense))
    return out, t_bind


def best_of(fn, repeat=3):
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return min(times)


def deform_timings(b, Vc, Fc, centre, seed=0, sets=3):
    """Seconds: full deform of the unedited cage; for the one-ring of
    ``centre`` moved and for 5 random cage vertices moved, the incremental
    deform of a first move (best of ``sets`` first moves, each of a set of
    cage vertices never moved before: the one-rings of ``centre`` and of
    random cage vertices, or other random fives; each from the unedited
    result, after a full deform), of a drag (the first set moved again: best
    of the 3rd to 5th moves) and the full deform of the first set's edited
    cage (what they replace: it also tests the edited region for folds; best
    of 3). A first move of the same vertices again would reuse what the last
    one found (the rows and the faces around them) and be faster than an
    artist's. The first incremental call, which builds the index, moves
    another vertex and is not timed."""
    D = deform(b, Vc)
    t_full = best_of(lambda: deform(b, Vc, out=D))
    out = {"full": t_full}
    rng = np.random.default_rng(seed)
    full = np.empty_like(D)
    n = Vc.shape[0]
    rings = [one_ring(Fc, v) for v in [centre, *rng.choice(n, sets - 1, replace=False)]]
    fives = [rng.choice(n, 5, replace=False) for _ in range(sets)]
    spare = int(np.setdiff1d(np.arange(n), np.concatenate(rings + fives))[0])
    Ve = Vc.copy()
    Ve[spare] += 0.001
    deform(b, Ve, moved=[spare], out=D)
    for label, id_sets in (("one-ring", rings), ("5 random", fives)):
        first = []
        for ids in id_sets:
            Ve = Vc.copy()
            Ve[ids] += 0.001
            deform(b, Vc, out=D)                   # (a full deform: the next move is a first one)
            t = time.perf_counter()
            deform(b, Ve, moved=ids, out=D)
            first.append(time.perf_counter() - t)
        ids = id_sets[0]
        Ve = Vc.copy()
        Ve[ids] += 0.001
        drag, Vd = [], Ve.copy()
        for _ in range(5):
            Vd[ids] += 1e-4
            t = time.perf_counter()
            deform(b, Vd, moved=ids, out=D)
            drag.append(time.perf_counter() - t)
        out[label] = min(first)
        out[label + " drag"] = min(drag[2:])
        out[label + " full"] = best_of(lambda: deform(b, Ve, out=full))
        out[label + " moved"] = len(ids)
        out[label + " rows"] = int((full != deform(b, Vc)).any(axis=1).sum())
        deform(b, Vc, out=D)
    return out


def run_folds(cases, faces=2000, centres_per_mesh=2, seed=1, timings=None, levels=2):
    """Fold counts per edit: rows (mesh, edit, {column: folds}); columns
    butterfly / Loop (core.deform, each on its own fitted cage, two levels)
    and Surface Deform on each of those cages. ``timings`` (a list) receives
    (mesh, scheme, n_dense, cage faces, bind s, Surface Deform bind s,
    :func:`deform_timings`)."""
    rows = []
    for name, V, F in cases:
        diag = bbox_diagonal(V)
        try:
            cage = simplify(V, F, target_faces=min(faces, F.shape[0] // 4))
        except MeshAdjustError as exc:
            print(f"folds: {name} skipped ({exc})")
            continue
        creases = cage.feature_edges if len(cage.feature_edges) else None
        rng = np.random.default_rng(seed)
        centres = np.sort(rng.choice(cage.V.shape[0], centres_per_mesh, replace=False))
        res = {}
        for scheme in FOLD_SCHEMES:
            try:
                # fitted at most at 2 levels, as the add-on does (MAX_FIT_LEVELS)
                Vc = fit_cage(V, F, cage.V, cage.F, levels=min(levels, 2), scheme=scheme,
                              creases=creases).V
                t = time.perf_counter()
                b = bind(V, F, Vc, cage.F, levels=levels, scheme=scheme, creases=creases)
                t_bind = time.perf_counter() - t
            except MeshAdjustError as exc:
                print(f"folds: {name} {scheme} skipped ({exc})")
                break
            edits = artist_edits(Vc, cage.F, diag, centres)
            sd, t_sd = surface_deform_many(V, F, Vc, cage.F, [e for _, e in edits])
            if timings is not None:
                timings.append((name, scheme, V.shape[0], cage.F.shape[0], t_bind, t_sd,
                                deform_timings(b, Vc, cage.F, centres[0])))
            for (label, Ve), S in zip(edits, sd):
                r = res.setdefault(label, {})
                r[scheme] = count_folds(V, deform(b, Ve), F)
                r[f"SD {scheme} cage"] = count_folds(V, S, F)
                r[f"{scheme} cage folds"] = count_folds(Vc, Ve, cage.F)
        rows += [(name, label, r) for label, r in res.items()]
    return rows


def fold_cases(quick):
    names = ["spot.obj"] if quick else sorted(
        f for f in os.listdir(SHARED) if f.endswith(".obj")) if os.path.isdir(SHARED) else []
    cases = [(n[:-4], *read_obj(os.path.join(SHARED, n))) for n in names]
    if not quick and os.path.isdir(SHARED):
        cases.append(("bunny x16 (1.1M tris)", *synthetic_scan()))
    return cases


# ------------------------------------------------------------------ live update
def run_live(quick, updates=5, seed=0, levels=0):
    """One live update of a bound scan through the add-on, in Blender: a
    bumpy torus (1M vertices; 62.5k with --quick) simplified to a 2,000-face
    cage and bound (Loop, ``levels``; 0, the default, is the add-on's own
    default, Auto: the levels closest to the source's face count, at most
    two) by the
    add-on's own operator; then, per update, a cage vertex and 4 of its
    neighbours are moved and ``live_update.update_edited`` brings the edited
    original up to date; then the last 5 are moved again ``updates`` times
    (a drag). Returns (info, list of LiveTiming, seconds of the depsgraph
    evaluation after each update, max |evaluated - core.deform|, list of
    LiveTiming of the drag, :func:`deform_timings` of the same binding in the
    core: the incremental deform against a full one at these levels)."""
    n_major, n_minor = (250, 250) if quick else (1000, 1000)
    Vd, Fd = bumpy_torus(n_major, n_minor)
    bpy = empty_scene()
    dense = blender_object("scan", Vd, Fd)
    bpy.context.view_layer.objects.active = dense
    dense.select_set(True)
    t = time.perf_counter()
    bpy.ops.meshadjust.simplify(target_mode='FACES', target_faces=2000, fit=False, bind=True,
                                levels=levels, scheme='loop')
    t_setup = time.perf_counter() - t
    cage = dense.meshadjust.cage
    edited = cage.meshadjust.edited
    from meshadjust_batch import load_package
    package = load_package()
    addon = package.meshadjust_addon
    lu = addon.live_update
    lu.forget()
    first = lu.update_edited(cage)
    io = mesh_io()
    Vc = io.read_positions(cage.data)
    Fc = io.read_triangles(cage.data)[0]
    rng = np.random.default_rng(seed)
    timings, evals = [], []
    for _ in range(updates):
        v = int(rng.integers(Vc.shape[0]))
        ids = one_ring(Fc, v)[:5]
        Vc[ids] += 0.002 * rng.standard_normal((ids.shape[0], 3))
        io.write_positions(cage.data, Vc)            # the artist's edit
        timings.append(lu.update_edited(cage))
        t = time.perf_counter()
        got = evaluated_positions(edited)
        evals.append(time.perf_counter() - t)
    # a drag: the same cage vertices moved again, update after update
    drags = []
    for _ in range(updates):
        Vc[ids] += 0.002 * rng.standard_normal((ids.shape[0], 3))
        io.write_positions(cage.data, Vc)
        drags.append(lu.update_edited(cage))
        got = evaluated_positions(edited)
    binding = addon.store.load_binding(edited, cage)
    V_src = lu.cage_in_source_space(cage, dense)
    refined = run_live_refined(addon, cage, Fc, rng, updates) if not levels else None
    err = float(np.abs(got - package.core.deform(binding, V_src)).max())
    # the tenth at these levels (the add-on's binding, as this script's core has it)
    core_times = deform_timings(Binding.from_arrays(binding.to_arrays()), V_src, Fc, v, seed)
    used = binding.levels
    info = (f"bumpy torus {Vd.shape[0]:,} vertices / {Fd.shape[0]:,} faces, cage "
            f"{Fc.shape[0]:,} faces, Loop x{used}{' (Auto, the add-on default)' if not levels else ''} "
            f"(simplify + bind through the operator "
            f"{t_setup:.1f} s; first update, a full deform: {1e3 * first.total:.0f} ms)")
    return info, timings, evals, err, drags, core_times, refined


def run_live_refined(addon, cage, Fc, rng, updates):
    """The live updates of the cage's refined mesh (the Refined output, at
    Auto levels: the source's density), as live mode makes them (a Refine's
    checks, then ``live_update.update_refined``): its finer binding made
    first (live mode makes it once, in the background), then the first
    update (a Refine making the refined mesh, and the incremental indices),
    a Refine of it (best of 3: what every update was before), then
    ``updates`` updates moving 5 neighbouring cage vertices each, and a drag;
    beside them Blender's Subdivision Surface modifier (Catmull-Clark, limit
    surface off, its fastest) on a copy of the cage at the level giving about
    as many faces, its evaluation after the same edits. Returns a dict."""
    import bpy
    api, lu, io = addon.api, addon.live_update, mesh_io()
    rj = api.prepare_refine(cage, output='REFINED')
    t = time.perf_counter()
    if rj.finer_levels:
        api.make_finer(rj)
    t_finer = time.perf_counter() - t

    def tick():
        t0 = time.perf_counter()
        job = api.prepare_refine(cage, output='REFINED')
        t1 = time.perf_counter()
        timing = lu.update_refined(cage, job)
        return timing, t1 - t0, time.perf_counter() - t0
    first = tick()
    n_refined = len(cage.meshadjust.refined.data.polygons)
    full = []                     # what every update was before: a Refine of the refined mesh
    for _ in range(3):
        t = time.perf_counter()
        api.refine_object(cage, output='REFINED')
        full.append(time.perf_counter() - t)
    # Blender's modifier on a copy of the cage: 3 quads a triangle, then 4 a level
    level = max(1, int(round(np.log(n_refined / (3.0 * Fc.shape[0])) / np.log(4.0))) + 1)
    copy = blender_object("cage_subsurf", io.read_positions(cage.data), Fc)
    mod = copy.modifiers.new("subsurf", "SUBSURF")
    mod.levels, mod.render_levels, mod.use_limit_surface, mod.quality = level, level, False, 1
    evaluated_positions(copy)
    Vc = io.read_positions(cage.data)
    ticks, drags, blender = [], [], []
    for _ in range(updates):
        ids = one_ring(Fc, int(rng.integers(Vc.shape[0])))[:5]
        Vc[ids] += 0.002 * rng.standard_normal((ids.shape[0], 3))
        io.write_positions(cage.data, Vc)
        ticks.append(tick())
        io.write_positions(copy.data, Vc)
        t = time.perf_counter()
        evaluated_positions(copy)
        blender.append(time.perf_counter() - t)
    for _ in range(updates):
        Vc[ids] += 0.002 * rng.standard_normal((ids.shape[0], 3))
        io.write_positions(cage.data, Vc)
        drags.append(tick())
    faces = sum(len(p.vertices) - 2 for p in evaluated_mesh_polygons(copy))
    bpy.data.objects.remove(copy)
    return {"finer s": t_finer, "first": first, "full": min(full), "ticks": ticks,
            "drags": drags,
            "blender": blender, "blender level": level, "blender faces": faces,
            "refined faces": n_refined}


def evaluated_mesh_polygons(ob):
    """The polygons of ``ob`` with its modifiers applied."""
    import bpy
    return ob.evaluated_get(bpy.context.evaluated_depsgraph_get()).data.polygons


def _live_section(quick, levels=0):
    info, timings, evals, err, drags, core_times, refined = run_live(quick, levels=levels)
    lines = ["## Live update (add-on, bpy): 5 neighbouring cage vertices moved", "", info, "",
             "| update | moved | dense rows | read cage ms | compare ms | deform ms | "
             "convert ms | write ms | total ms | depsgraph eval after ms |",
             "| ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |"]
    for i, (t, e) in enumerate(zip(timings, evals)):
        lines.append(f"| {i + 1} | {t.moved} | {t.rows:,} | {1e3 * t.read_cage:.1f} | "
                     f"{1e3 * t.compare:.1f} | {1e3 * t.deform:.1f} | {1e3 * t.convert:.1f} | "
                     f"{1e3 * t.write:.1f} | **{1e3 * t.total:.1f}** | {1e3 * e:.1f} |")
    for i, t in enumerate(drags):
        lines.append(f"| drag {i + 1} | {t.moved} | {t.rows:,} | {1e3 * t.read_cage:.1f} | "
                     f"{1e3 * t.compare:.1f} | {1e3 * t.deform:.1f} | {1e3 * t.convert:.1f} | "
                     f"{1e3 * t.write:.1f} | {1e3 * t.total:.1f} | - |")
    med = float(np.median([t.total for t in timings]))
    med_drag = float(np.median([t.total for t in drags]))
    lines += ["", f"median update {1e3 * med:.1f} ms (target 30 ms; each update moves other "
              f"cage vertices); a drag (the same vertices moved again) {1e3 * med_drag:.1f} ms; "
              f"evaluated edited mesh vs core.deform: max {err:.2e} (float32); load average "
              f"{os.getloadavg()[0]:.1f}",
              "", "core.deform on the same binding (first move, drag, full, first / full; "
              f"best of 3): one-ring {_vs_full(core_times, 'one-ring')}; 5 random cage vertices "
              f"{_vs_full(core_times, '5 random')} (ms)", ""]
    return lines + (_live_refined_lines(refined) if refined is not None else [])


def _live_refined_lines(r):
    """The README table of :func:`run_live_refined`'s dict ``r``."""
    timing, prepare, first = r["first"]
    total = r["full"]
    lines = ["### The refined mesh live (Refined output, Auto levels)", "",
             f"refined mesh {r['refined faces']:,} faces; its finer binding made first "
             f"{r['finer s']:.1f} s (live mode makes it once, in the background); the first "
             f"update (a Refine making the refined mesh, and the incremental indices) "
             f"{1e3 * first:.0f} ms; a Refine of it, what every update was before (best of 3): "
             f"{1e3 * total:.0f} ms",
             "", "| update | moved | refined rows | checks ms | refine ms | write ms | total ms | "
             f"Blender Subdivision Surface x{r['blender level']} eval ms |",
             "| ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |"]
    for i, ((t, prep, tot), b) in enumerate(zip(r["ticks"], r["blender"])):
        lines.append(f"| {i + 1} | {t.moved} | {t.rows:,} | {1e3 * prep:.1f} | "
                     f"{1e3 * t.refine:.1f} | {1e3 * t.write:.1f} | **{1e3 * tot:.1f}** | "
                     f"{1e3 * b:.1f} |")
    for i, (t, prep, tot) in enumerate(r["drags"]):
        lines.append(f"| drag {i + 1} | {t.moved} | {t.rows:,} | {1e3 * prep:.1f} | "
                     f"{1e3 * t.refine:.1f} | {1e3 * t.write:.1f} | {1e3 * tot:.1f} | - |")
    med = float(np.median([tot for _, _, tot in r["ticks"]]))
    med_b = float(np.median(r["blender"]))
    lines += ["", f"median update {1e3 * med:.1f} ms against {1e3 * total:.0f} ms for the full "
              f"Refine ({med / total:.2f}x); Blender's Subdivision Surface x{r['blender level']} "
              f"({r['blender faces']:,} triangles' worth of quads) {1e3 * med_b:.1f} ms after the "
              f"same edits: ours / Blender's {med / med_b:.2f}; load average "
              f"{os.getloadavg()[0]:.1f}", ""]
    return lines


def _fmt(x, digits=3):
    return "-" if x != x else f"{x:.{digits}f}"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="smaller meshes, no results file")
    ap.add_argument("--levels", type=int, default=2,
                    help="subdivision levels of the folds part (fits use at most 2)")
    ap.add_argument("--live-levels", type=int, action="append",
                    help="levels of the live part (repeatable; 0 = Auto, the add-on's default; "
                         "default: 0 and 5)")
    ap.add_argument("--only", choices=("bend", "scale", "fit", "folds", "live"), action="append",
                    help="run only these parts (repeatable); the results file is then not written")
    args = ap.parse_args(argv)
    parts = set(args.only or ("bend", "scale", "fit", "folds", "live"))
    lines = [f"run of {time.strftime('%Y-%m-%d %H:%M', time.gmtime())} UTC, 1-minute load average at the "
             f"start {os.getloadavg()[0]:.1f}; {blas_line()}", ""]
    if "live" in parts:
        for levels in args.live_levels or (0, 5):
            lines += _live_section(args.quick, levels)
    if "folds" in parts:
        lines += _folds_section(args.quick, args.levels)
    if "bend" in parts:
        lines += _bend_section(args.quick)
    if "scale" in parts:
        lines += _scale_section(args.quick)
    if "fit" in parts:
        lines += _fit_section(args.quick)
    text = "\n".join(lines)
    print(text)
    if not args.quick and not args.only:
        os.makedirs(os.path.join(ROOT, "bench_results"), exist_ok=True)
        with open(os.path.join(ROOT, "bench_results", "adjust.md"), "w") as fh:
            fh.write("# bench_adjust\n\n" + text)


def _bend_section(quick):
    lines = []
    info, rows, ratio = run_bend(quick)
    lines += ["## Analytic bend of a bumpy tube", "", info, "",
              "| method | bind s | deform s | max error / h | mean error / h |",
              "| --- | ---: | ---: | ---: | ---: |"]
    lines += [f"| {r[0]} | {_fmt(r[1])} | {_fmt(r[2])} | {_fmt(r[3])} | {_fmt(r[4])} |" for r in rows]
    lines += ["", f"mean error ratio MeshAdjust / Surface Deform: {ratio:.3f}", ""]
    return lines


def _scale_section(quick):
    lines = []
    info, rows = run_scale(quick)
    lines += ["## Scale", "", info, "",
              "| method | bind s | deform s | refine s |", "| --- | ---: | ---: | ---: |"]
    lines += [f"| {r[0]} | {_fmt(r[1], 2)} | {_fmt(r[2], 3)} | {_fmt(r[3], 3)} |" for r in rows]
    lines += ["", "targets: bind <= 15 s, deform <= 0.3 s; 1-minute load average of the "
              f"2-core machine after the run: {os.getloadavg()[0]:.1f}", ""]
    lines += [f"### Binds at an artist's sizes (2,000-face cage, Loop; best of {1 if quick else 3}"
              ", alternating)",
              "", "| scan | dense vertices | levels | ours s | Surface Deform s "
              "| ours / Surface Deform |", "| --- | ---: | ---: | ---: | ---: | ---: |"]
    lines += [f"| {name} | {n:,} | {levels} | {ours:.3f} | {sd:.3f} | **{ours / sd:.2f}** |"
              for name, n, levels, ours, sd in run_typical_binds(quick)]
    return lines + [""]


def _folds_section(quick, levels=2):
    timings = []
    rows = run_folds(fold_cases(quick), timings=timings, levels=levels)
    cols = [c for s in FOLD_SCHEMES for c in (s, f"SD {s} cage", f"{s} cage folds")]
    lines = ["## Folds of artist-like edits (faces turned by more than 90 degrees)", "",
             "QEM cage of 2,000 faces (a quarter of the input's faces when smaller), fitted "
             f"for each scheme, {levels} levels; Surface Deform (bpy) on the same cage and edit; "
             "'cage folds': faces of the edited cage itself turned by more than 90 degrees "
             "(the edit folds the cage: its subdivision surface folds too)",
             "", "| mesh | edit | " + " | ".join(cols) + " |",
             "| --- | --- | " + " | ".join("---:" for _ in cols) + " |"]
    total, unfolded = dict.fromkeys(cols, 0), dict.fromkeys(cols, 0)
    n_unfolded = dict.fromkeys(FOLD_SCHEMES, 0)
    for name, label, r in rows:
        lines.append(f"| {name} | {label} | " + " | ".join(str(r.get(c, "-")) for c in cols) + " |")
        for c in cols:
            total[c] += r.get(c, 0)
        for s in FOLD_SCHEMES:
            if r.get(f"{s} cage folds", 0) == 0:
                n_unfolded[s] += 1
                for c in (s, f"SD {s} cage"):
                    unfolded[c] += r.get(c, 0)
    lines.append("| **total** | " + f"{len(rows)} edits | " + " | ".join(
        f"**{total[c]}**" for c in cols) + " |")
    lines.append("| **total, edits that keep the cage unfolded** | " + " / ".join(
        f"{n_unfolded[s]} {s}" for s in FOLD_SCHEMES) + " | " + " | ".join(
        f"**{unfolded[c]}**" if "cage folds" not in c else "-" for c in cols) + " |")
    lines += ["", "## Bind and deform per case (same run; incremental = deform(moved=, out=))", "",
              "| mesh | scheme | dense vertices | cage faces | bind s | Surface Deform bind s | "
              "bind / SD | full deform ms | one-ring: moved, rows, ms, drag ms, full ms, / full | "
              "5 random: rows, ms, drag ms, full ms, / full |",
              "| --- | --- | ---: | ---: | ---: | ---: | ---: | ---: | --- | --- |"]
    for name, scheme, n, m, tb, tsd, d in timings:
        f = d["full"]
        lines.append(
            f"| {name} | {scheme} | {n:,} | {m:,} | {tb:.2f} | {tsd:.2f} | {tb / tsd:.2f} | "
            f"{1e3 * f:.1f} | {d['one-ring moved']}, {d['one-ring rows']:,}, "
            f"{_vs_full(d, 'one-ring')} | {d['5 random rows']:,}, {_vs_full(d, '5 random')} |")
    lines += ["", f"load average after the fold runs: {os.getloadavg()[0]:.1f}", ""]
    return lines


def _vs_full(d, label):
    """'first move ms, drag ms, full ms, first move / full' of one edit of
    :func:`deform_timings`."""
    t, f = d[label], d[label + " full"]
    return f"{1e3 * t:.1f}, {1e3 * d[label + ' drag']:.1f}, {1e3 * f:.1f}, {t / f:.3f}"


def _fit_section(quick):
    lines = []
    names = ["stanford-bunny.obj"] if quick else [
        "stanford-bunny.obj", "homer.obj", "rocker-arm.obj", "spot.obj"]
    # CAD parts: cylinders whose caps are fans of needles and sides strips of them
    built = [] if quick else [(f"CAD cylinder, {4 * n // 1000}k faces",
                               *cad_cylinder(n, height=1.0)) for n in (2500, 10000)]
    rows = run_fit(names, built)
    if rows:
        lines += ["## fit_cage (QEM cage of 2,000 faces, two butterfly levels)", "",
                  "distances two-sided (Metro), % of the bounding-box diagonal; volume of the "
                  "subdivided cage vs the original's (closed meshes)", "",
                  "| mesh | cage faces | fit s | mean before | mean after | improvement | "
                  "Hausdorff before | Hausdorff after | volume before | volume after |",
                  "| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |"]
        for name, m, t_fit, b, a in rows:
            lines.append(f"| {name} | {m} | {t_fit:.1f} | {b[0]:.4f} | {a[0]:.4f} | "
                         f"{b[0] / a[0]:.2f}x | {b[1]:.3f} | {a[1]:.3f} | {b[2]:+.3f}% | {a[2]:+.3f}% |")
        lines.append("")
    return lines


if __name__ == "__main__":
    main()
