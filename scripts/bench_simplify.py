"""Benchmark: core.simplify against Blender's Decimate (COLLAPSE), same process.

Run with the bpy venv's Python (Blender as a module, NumPy 1.26)::

    python scripts/bench_simplify.py            # every shared mesh at 10%, 2%, 1,000 faces + 1M -> 10k
    python scripts/bench_simplify.py --quick    # a few small cases
    python scripts/bench_simplify.py --big      # also 4M -> 40k
    python scripts/bench_simplify.py --messy-only   # only the messy section
    python scripts/bench_simplify.py --small-only   # only the small-mesh section

For every case Decimate runs first; ``core.simplify`` then gets Decimate's
output face count as ``target_faces`` so both end at the same size. Where
the ``meshoptimizer`` Python binding installs (``.venv/bin/pip install meshoptimizer``,
a benchmark-only dependency: C++, one thread, float32), its ``simplify`` runs
in the same process as a second reference (its output is not cleaned: it can
leave unreferenced vertices and does not promise a manifold). Errors
are two-sided surface distances to the input (Metro: area-weighted samples
on both surfaces plus the vertices, exact point-to-triangle distances), in
% of the input's bounding-box diagonal. Also reported: non-manifold edges,
boundary edges and Euler characteristic (input -> output), flipped faces
(normal against the input's nearest face), the minimum angle, and the peak
memory of our run (peak RSS above the RSS before it). The table goes to bench_results/simplify.md
(bench_results/simplify-partial.md for a run with any option that leaves a section out).

The small-mesh section takes a flat grid, a cube (both 20,000 faces), a CAD
cylinder as tall as it is wide (caps fans of 2,500 needles, 10,000 faces),
fandisk and the bunny to 2,000, 200 and 4 faces (times: the best of three
runs): the fixed cost per pass that small meshes feel, CAD fans, and a
4-face target against a 2,000-face one.

The messy section runs every shared mesh as real scans arrive (an exact soup,
a soup jittered by 1e-7 of the diagonal, 300 specks of debris, 3 pinched
bow-tie vertices, double-sided sheets, 2% of the faces missing, the mesh twice
in place, whole and with 2% of its faces missing, one small triangle 1,000
diagonals off; built by ``tests/mesh_factory``) at
1,000 faces (10% for the small ones): ours and Decimate on the messy mesh,
both measured against the clean mesh (the scan alone), beside our cage of
the clean mesh; whether each result is a manifold, and what our cleaning did.
"""

import argparse
import math
import os
import sys
import time
import tracemalloc

import numpy as np

ROOT = os.path.normpath(os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))
sys.path.insert(0, ROOT)

from core.io_obj import read_obj  # noqa: E402
from core.metrics import surface_distance as core_surface_distance  # noqa: E402
from core.mesh import bbox_diagonal, face_normals  # noqa: E402
from core.simplify import simplify  # noqa: E402
from core.spatial import TriangleIndex  # noqa: E402
from core.topology import edge_map, euler_characteristic, manifold_report  # noqa: E402
from _bench import blas_line, blender_object, empty_scene, evaluated_arrays  # noqa: E402

MESHES = os.path.normpath(os.path.join(ROOT, "..", "shared", "meshes"))
SEED = 0

def surface_distance(Va, Fa, Vb, Fb):
    """(hausdorff, mean) two-sided distances in mesh units (Metro)."""
    d = core_surface_distance(Va, Fa, Vb, Fb, seed=SEED)
    return d.hausdorff, d.mean


def min_angle_deg(V, F):
    P = V[F]
    ang = []
    for i in range(3):
        u = P[:, (i + 1) % 3] - P[:, i]
        w = P[:, (i + 2) % 3] - P[:, i]
        c = np.einsum("ij,ij->i", u, w) / np.maximum(np.linalg.norm(u, axis=1) * np.linalg.norm(w, axis=1),
                                                      1e-300)
        ang.append(np.degrees(np.arccos(np.clip(c, -1, 1))))
    return float(np.min(ang)) if F.shape[0] else float("nan")


def flipped_faces(V0, F0, index0, V, F):
    """Faces whose normal points against the input's nearest face."""
    C = V[F].mean(axis=1)
    cp = index0.closest(C)
    n0 = face_normals(V0, F0)[cp.face]
    n1 = face_normals(V, F)
    return int((np.einsum("ij,ij->i", n0, n1) < 0).sum())


def clean_stats(V, F):
    n = V.shape[0]
    em = edge_map(F, n)
    rep = manifold_report(F, n)
    return dict(nm=int(rep.non_manifold_edges.shape[0]) + int(rep.non_manifold_vertices.shape[0]),
                bnd=int((em.edge_face_count == 1).sum()), euler=euler_characteristic(F, n))


def _status_kib(key):
    with open("/proc/self/status", encoding="ascii") as fh:
        for line in fh:
            if line.startswith(key):
                return int(line.split()[1]) * 1024
    return None


def _reset_peak_rss():
    """Reset the kernel's peak-RSS mark (Linux); returns the current RSS or None."""
    try:
        with open("/proc/self/clear_refs", "w", encoding="ascii") as fh:
            fh.write("5")
        return _status_kib("VmRSS:")
    except OSError:
        return None


def _peak_rss():
    return _status_kib("VmHWM:")


# ---------------------------------------------------------------- Blender
def blender_decimate(V, F, target):
    m = F.shape[0]
    empty_scene()
    ob = blender_object("bench", V, F)
    mod = ob.modifiers.new("dec", "DECIMATE")
    mod.decimate_type = "COLLAPSE"
    mod.use_collapse_triangulate = True
    mod.ratio = min(1.0, target / m)
    t0 = time.perf_counter()
    Vo, Fo = evaluated_arrays(ob)
    dt = time.perf_counter() - t0
    return Vo, Fo, dt


def meshopt_simplify(V, F, target):
    """meshoptimizer's simplify to ``target`` faces (no error bound), or None
    when the binding is not installed. Returns (V, F, seconds)."""
    try:
        import meshoptimizer
    except ImportError:
        return None
    idx = np.ascontiguousarray(F, dtype=np.uint32).ravel()
    pos = np.ascontiguousarray(V, dtype=np.float32)
    dest = np.zeros_like(idx)
    t0 = time.perf_counter()
    k = meshoptimizer.simplify(dest, idx, pos, target_index_count=3 * int(target), target_error=1.0)
    dt = time.perf_counter() - t0
    Fo = dest[:k].reshape(-1, 3).astype(np.int64)
    used = np.unique(Fo)
    remap = np.full(V.shape[0], -1, dtype=np.int64)
    remap[used] = np.arange(used.size)
    return V[used], remap[Fo], dt


# ---------------------------------------------------------------- cases
def synthetic(levels, noise=1e-4, name="stanford-bunny.obj"):
    """A shared mesh (the bunny) midpoint-subdivided ``levels`` times with
    small noise (fixed seed)."""
    from tests.mesh_factory import midpoint_split
    V, F = read_obj(os.path.join(MESHES, name))
    from core.clean import clean_mesh
    c = clean_mesh(V, F)
    V, F = c.V, c.F
    for _ in range(levels):
        V, F = midpoint_split(V, F)
    rng = np.random.default_rng(SEED)
    return V + rng.normal(scale=noise * bbox_diagonal(V), size=V.shape), F


def run_case(name, V, F, target, use_blender=True, repeat=1):
    """One case: Decimate, ours (time: the best of ``repeat`` runs), meshoptimizer."""
    diag = bbox_diagonal(V)
    index0 = TriangleIndex(V, F)
    row = dict(mesh=name, faces=F.shape[0])
    cin = clean_stats(V, F)
    if use_blender:
        Vb, Fb, tb = blender_decimate(V, F, target)
        target = Fb.shape[0]
        hb, mb = surface_distance(V, F, Vb, Fb)
        cb = clean_stats(Vb, Fb)
        row.update(b_time=tb, b_haus=100 * hb / diag, b_mean=100 * mb / diag, b_nm=cb["nm"],
                   b_bnd=cb["bnd"], b_euler=cb["euler"], b_flip=flipped_faces(V, F, index0, Vb, Fb),
                   b_minang=min_angle_deg(Vb, Fb))
    base = _reset_peak_rss()
    t0 = time.perf_counter()
    r = simplify(V, F, target_faces=int(target))
    t = time.perf_counter() - t0
    peak = _peak_rss() - base if base is not None else None
    for _ in range(repeat - 1):
        t0 = time.perf_counter()
        simplify(V, F, target_faces=int(target))
        t = min(t, time.perf_counter() - t0)
    if peak is None:  # no /proc: measure NumPy allocations instead (slower run, not timed)
        tracemalloc.start()
        simplify(V, F, target_faces=int(target))
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
    mo = meshopt_simplify(V, F, target)
    if mo is not None:
        hm, mm = surface_distance(V, F, mo[0], mo[1])
        row.update(mo_time=mo[2], mo_out=mo[1].shape[0], mo_haus=100 * hm / diag, mo_mean=100 * mm / diag,
                   mo_manifold=manifold_report(mo[1], mo[0].shape[0]).is_manifold)
    h, mn = surface_distance(V, F, r.V, r.F)
    c = clean_stats(r.V, r.F)
    row.update(target=int(target), out=r.F.shape[0], time=t, haus=100 * h / diag, mean=100 * mn / diag,
               nm_in=cin["nm"], nm=c["nm"], bnd_in=cin["bnd"], bnd=c["bnd"], euler_in=cin["euler"],
               euler=c["euler"], flip=flipped_faces(V, F, index0, r.V, r.F), minang=min_angle_deg(r.V, r.F),
               peak_mb=peak / 2**20, stop=r.stopped_because, passes=r.n_passes, seconds=r.seconds)
    return row


MESSY = ("soup", "jittered soup", "debris", "bowties", "sheets", "pinholes", "copy in place",
         "holed copy in place", "speck far off")

#: the small-mesh section's meshes (each to 2,000, 200 and 4 faces)
SMALL = ("flat grid 100x100", "cube 40x40 per side", "CAD cylinder, fans of 2,500 needles",
         "fandisk", "stanford-bunny")


def small_mesh(label):
    """A mesh of the small-mesh section, or None when its file is absent."""
    from tests.mesh_factory import cad_cylinder, cube, regular_grid
    if label.startswith("flat grid"):
        return regular_grid(100, 100)
    if label.startswith("cube"):
        return cube(40)
    if label.startswith("CAD cylinder"):        # as tall as wide: its caps' spokes cost nothing
        return cad_cylinder(2500, height=1.0)
    path = os.path.join(MESHES, label + ".obj")
    return read_obj(path)[:2] if os.path.exists(path) else None


def run_small(use_blender):
    """Flat, CAD and tiny targets (times: best of 3): the fixed cost per pass that
    small meshes feel, and a 4-face target against a 2,000-face one."""
    rows = []
    for label in SMALL:
        mesh = small_mesh(label)
        if mesh is None:
            continue
        V, F = mesh
        for tgt in (2000, 200, 4):
            rows.append(dict(run_case(f"{label} -> {tgt}", V, F, tgt, use_blender, repeat=3),
                             label=label, asked=tgt))
            print(fmt_table([rows[-1]], use_blender).splitlines()[-1], flush=True)
    return rows


def fmt_small(rows):
    """The small-mesh section's summary line."""
    small = [r for r in rows if r["faces"] <= 20000]
    text = (f"Meshes up to 20,000 faces: {min(r['time'] for r in small):.2f}-"
            f"{max(r['time'] for r in small):.2f} s, {max(r['passes'] for r in small)} passes at most. "
            if small else "")
    by = {}
    for r in rows:
        by.setdefault(r["label"], {})[r["asked"]] = r["time"]
    return text + "4-face target / 2,000-face target time: " + ", ".join(
        f"{k} {v[4] / v[2000]:.2f}" for k, v in by.items() if 4 in v and 2000 in v) + "."


def messy_variant(V, F, how):
    """The mesh as a scan may arrive (see ``tests/mesh_factory``)."""
    from tests import mesh_factory as mf
    return {"soup": lambda: mf.unwelded(V, F), "jittered soup": lambda: mf.unwelded(V, F, 1e-7),
            "debris": lambda: mf.with_debris(V, F), "bowties": lambda: mf.pinched(V, F),
            "sheets": lambda: mf.with_sheets(V, F), "pinholes": lambda: mf.with_pinholes(V, F),
            "copy in place": lambda: mf.duplicated(V, F),
            "holed copy in place": lambda: mf.duplicated(*mf.with_pinholes(V, F)),
            "speck far off": lambda: mf.with_far_speck(V, F)}[how]()


def run_messy(name, V, F, target, use_blender=True):
    """Rows of the messy section for one shared mesh (see the module docstring)."""
    from core.clean import clean_mesh
    clean = clean_mesh(V, F)
    Vc, Fc = clean.V, clean.F
    diag = bbox_diagonal(Vc)
    ref = simplify(Vc, Fc, target_faces=target)
    _, ref_mean = surface_distance(Vc, Fc, ref.V, ref.F)
    rows = []
    for how in MESSY:
        Vm, Fm = messy_variant(V, F, how)
        row = dict(mesh=name, how=how, faces=Fm.shape[0], target=target,
                   ref_mean=100 * ref_mean / diag)
        t0 = time.perf_counter()
        r = simplify(Vm, Fm, target_faces=target)
        row.update(time=time.perf_counter() - t0, out=r.F.shape[0], stop=r.stopped_because,
                   manifold=manifold_report(r.F, r.V.shape[0]).is_oriented_manifold,
                   cleaning=r.cleaning.summary())
        h, mn = surface_distance(Vc, Fc, r.V, r.F)
        row.update(haus=100 * h / diag, mean=100 * mn / diag)
        if use_blender:
            Vb, Fb, tb = blender_decimate(Vm, Fm, target)
            hb, mb = surface_distance(Vc, Fc, Vb, Fb)
            row.update(b_time=tb, b_out=Fb.shape[0], b_haus=100 * hb / diag, b_mean=100 * mb / diag,
                       b_manifold=manifold_report(Fb, Vb.shape[0]).is_manifold)
        rows.append(row)
    return rows


def fmt_messy(rows, blender):
    head = ["mesh", "as it arrives", "faces", "target", "ours faces", "ours s", "ours mean %",
            "ours haus %", "clean-mesh cage mean %", "ours manifold"]
    if blender:
        head += ["Dec faces", "Dec s", "Dec mean %", "Dec haus %", "Dec manifold", "t ratio"]
    head += ["what our cleaning did"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in rows:
        cells = [r["mesh"], r["how"], f"{r['faces']:,}", f"{r['target']:,}", f"{r['out']:,}",
                 f"{r['time']:.2f}", f"{r['mean']:.4f}", f"{r['haus']:.3f}", f"{r['ref_mean']:.4f}",
                 "yes" if r["manifold"] else "NO"]
        if blender:
            cells += [f"{r['b_out']:,}", f"{r['b_time']:.2f}", f"{r['b_mean']:.4f}", f"{r['b_haus']:.3f}",
                      "yes" if r["b_manifold"] else "no", f"{r['time'] / r['b_time']:.2f}"]
        cells += [r["cleaning"] or "-"]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def fmt_table(rows, blender):
    meshopt = any("mo_time" in r for r in rows)
    head = ["mesh", "faces", "target / ours", "passes", "ours s", "mean %", "haus %"]
    if blender:
        head += ["Dec s", "Dec mean %", "Dec haus %", "t ratio", "mean ratio", "haus ratio"]
    if meshopt:
        head += ["meshopt s", "meshopt mean %", "meshopt haus %", "meshopt manifold", "t / meshopt"]
    head += ["nm in/ours" + ("/Dec" if blender else ""), "bnd in/ours" + ("/Dec" if blender else ""),
             "euler in/ours" + ("/Dec" if blender else ""), "flips ours" + ("/Dec" if blender else ""),
             "min angle ours" + ("/Dec" if blender else ""), "peak MiB"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in rows:
        cells = [r["mesh"], f"{r['faces']:,}", f"{r['target']:,} / {r['out']:,}", f"{r['passes']}",
                 f"{r['time']:.2f}", f"{r['mean']:.4f}", f"{r['haus']:.3f}"]
        if blender:
            cells += [f"{r['b_time']:.2f}", f"{r['b_mean']:.4f}", f"{r['b_haus']:.3f}",
                      f"{r['time'] / r['b_time']:.2f}", f"{r['mean'] / r['b_mean']:.2f}",
                      f"{r['haus'] / r['b_haus']:.2f}"]
        if meshopt:
            cells += ([f"{r['mo_time']:.3f}", f"{r['mo_mean']:.4f}", f"{r['mo_haus']:.3f}",
                       "yes" if r["mo_manifold"] else "no", f"{r['time'] / r['mo_time']:.1f}"]
                      if "mo_time" in r else ["-"] * 5)
        sfx = lambda k: f"/{r['b_' + k]}" if blender else ""  # noqa: E731
        cells += [f"{r['nm_in']}/{r['nm']}{sfx('nm')}", f"{r['bnd_in']}/{r['bnd']}{sfx('bnd')}",
                  f"{r['euler_in']}/{r['euler']}{sfx('euler')}", f"{r['flip']}{sfx('flip')}",
                  f"{r['minang']:.1f}" + (f"/{r['b_minang']:.1f}" if blender else ""), f"{r['peak_mb']:.0f}"]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def fmt_stages(rows):
    """Seconds per stage of our runs (``SimplifyResult.seconds``)."""
    stages = list(dict.fromkeys(k for r in rows for k in r["seconds"]))
    head = ["mesh", "passes"] + stages
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in rows:
        lines.append("| " + " | ".join([r["mesh"], str(r["passes"])]
                                       + [f"{r['seconds'].get(k, 0.0):.2f}" for k in stages]) + " |")
    return "\n".join(lines)


def geomean(xs):
    xs = [x for x in xs if x > 0 and math.isfinite(x)]
    return math.exp(sum(math.log(x) for x in xs) / len(xs)) if xs else float("nan")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="a few small cases only")
    ap.add_argument("--big", action="store_true", help="also the 4M-triangle synthetic mesh")
    ap.add_argument("--no-blender", action="store_true", help="ours only")
    ap.add_argument("--meshes", nargs="*", help="only these shared meshes (file names)")
    ap.add_argument("--no-synthetic", action="store_true", help="skip the synthetic 1M and 1.3M meshes")
    ap.add_argument("--no-messy", action="store_true", help="skip the messy section")
    ap.add_argument("--messy-only", action="store_true", help="only the messy section")
    ap.add_argument("--no-small", action="store_true", help="skip the small-mesh section")
    ap.add_argument("--small-only", action="store_true", help="only the small-mesh section")
    args = ap.parse_args()
    blender = not args.no_blender
    if blender:
        import bpy  # noqa: F401  (fail early when run with the wrong Python)
    names = sorted(f for f in os.listdir(MESHES) if f.endswith(".obj")) if os.path.isdir(MESHES) else []
    if args.meshes:
        names = [n for n in names if n in args.meshes]
    if args.quick:
        names = [n for n in names if n in ("fandisk.obj", "cow.obj", "beetle.obj")]
    rows = []
    messy = []
    if not args.no_messy and not args.small_only:
        for name in names:
            V, F = read_obj(os.path.join(MESHES, name))
            target = min(1000, int(round(0.1 * F.shape[0])))
            messy += run_messy(name[:-4], V, F, target, blender)
            print(fmt_messy(messy[-len(MESSY):], blender), flush=True)
    small = [] if args.no_small or args.quick or args.messy_only or args.meshes else run_small(blender)
    if args.messy_only or args.small_only:
        names = []
    for name in names:
        V, F = read_obj(os.path.join(MESHES, name))
        m = F.shape[0]
        for label, tgt in (("10%", int(round(0.1 * m))), ("2%", int(round(0.02 * m))), ("1000", 1000)):
            if args.quick and label == "10%":
                continue
            if tgt >= m:
                continue
            row = run_case(f"{name[:-4]} {label}", V, F, tgt, blender)
            rows.append(row)
            print(fmt_table([row], blender).splitlines()[-1], flush=True)
    real = list(rows)
    if not args.quick and not args.no_synthetic and not args.small_only:
        big = [(2, 10_000, "bunny x16 (1M)", "stanford-bunny.obj"),
               (3, 10_000, "rocker-arm x64 (1.3M, held-out style)", "rocker-arm.obj")]
        if args.big:
            big.append((3, 40_000, "bunny x64 (4M)", "stanford-bunny.obj"))
        for levels, tgt, label, name in big:
            V, F = synthetic(levels, name=name)
            row = run_case(label, V, F, tgt, blender)
            rows.append(row)
            print(fmt_table([row], blender).splitlines()[-1], flush=True)
    text = fmt_table(rows, blender) if rows else ""
    big_rows = [r for r in rows if r not in real]
    if big_rows:
        text += "\n\n## Where our time goes (seconds per stage)\n\n" + fmt_stages(big_rows)
    if small:
        text += ("\n\n## Small meshes, flat and CAD meshes, tiny targets\n\n" + fmt_table(small, blender)
                 + "\n\n" + fmt_small(small))
    if messy:
        text += ("\n\n## Messy inputs\n\nDistances to the clean mesh (the scan alone), "
                 "% of its diagonal.\n\n" + fmt_messy(messy, blender))
    if blender and real:
        gm = geomean([r["mean"] / r["b_mean"] for r in real])
        gh = geomean([r["haus"] / r["b_haus"] for r in real])
        gt = geomean([r["time"] / r["b_time"] for r in real])
        worst_m = max(r["mean"] / r["b_mean"] for r in real)
        worst_h = max(r["haus"] / r["b_haus"] for r in real)
        text += (f"\n\nShared meshes ({len(real)} cases), geometric mean of ours / Decimate: "
                 f"mean distance {gm:.3f}, Hausdorff {gh:.3f}, time {gt:.2f}; "
                 f"worst case mean {worst_m:.2f}, Hausdorff {worst_h:.2f}; "
                 f"passes {sum(r['passes'] for r in real)} in all.")
    mo_rows = [r for r in real if "mo_time" in r]
    if mo_rows:
        text += (f"\nOurs / meshoptimizer over the same cases: mean distance "
                 f"{geomean([r['mean'] / r['mo_mean'] for r in mo_rows]):.3f}, Hausdorff "
                 f"{geomean([r['haus'] / r['mo_haus'] for r in mo_rows]):.3f}, time "
                 f"{geomean([r['time'] / r['mo_time'] for r in mo_rows]):.1f}.")
    load = os.getloadavg() if hasattr(os, "getloadavg") else None
    text += "\nDistances: core.metrics.surface_distance, % of the input's bounding-box diagonal."
    text += (f"\nRun {time.strftime('%Y-%m-%d %H:%M')} on this machine ({os.cpu_count()} cores"
             + (f", load average {load[0]:.1f} at the end" if load else "") + f"); {blas_line()}.")
    print()
    print(text)
    out = os.path.join(ROOT, "bench_results")
    os.makedirs(out, exist_ok=True)
    full = not (args.quick or args.meshes or args.messy_only or args.no_blender or args.no_synthetic
                or args.no_messy or args.no_small or args.small_only)
    name = "simplify.md" if full else "simplify-partial.md"   # a partial run keeps the full table
    with open(os.path.join(out, name), "w", encoding="utf-8") as fh:
        fh.write("# core.simplify vs Blender Decimate (COLLAPSE)\n\n" + text + "\n")


if __name__ == "__main__":
    main()
