#!/usr/bin/env python3
"""Benchmark: exact closest points (core.spatial) against Blender's BVHTree.find_nearest.

Run with Blender as a Python module (the bpy venv)::

    python scripts/bench_spatial.py            # full run, writes bench_results/spatial.md
    python scripts/bench_spatial.py --quick    # smaller meshes, no file written

Cases (fixed seeds, both tools in the same process on the same arrays):

1. *bind*: a 10k-face torus cage midpoint-subdivided twice (160k faces, the
   fine cage of a two-level binding) and 1M points of a bumpy torus (the dense
   mesh's vertices) near it.
2. *1M*: the bunny midpoint-subdivided twice (1.1M faces; an icosphere of
   1.3M faces when ../shared/meshes is absent) and 1M points sampled on it and
   moved off it by Gaussian noise of 0.2% of the diagonal.
3. *far*: 100k points uniform in twice the bounding box of mesh 1 (most of
   them far from the surface: the slow path of the index).
4. *metric*: ``surface_distance`` of mesh 2 with scan-like noise (0.2 edge
   lengths along the normals) against the coarse mesh it was subdivided from,
   default sample count (samples + vertices on both sides).

Blender: ``BVHTree.FromPolygons`` (build; the list conversion is timed apart)
and a Python loop of ``find_nearest`` (how an add-on queries it). Ours:
``TriangleIndex(V, F)`` and one ``index.closest(P)``. The last column is the
largest difference of the two distances in % of the diagonal (Blender works in
float32, so ~1e-5 % is agreement).
"""

import argparse
import os
import sys
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from core.io_obj import read_obj  # noqa: E402
from core.metrics import surface_distance  # noqa: E402
from core.spatial import TriangleIndex  # noqa: E402
from core.metrics import sample_surface  # noqa: E402
from tests.mesh_factory import icosphere, midpoint_split, torus  # noqa: E402

SHARED = os.path.normpath(os.path.join(ROOT, "..", "shared", "meshes"))


def surface_points(V, F, n, rng):
    """Area-weighted random points on the surface (seeded from ``rng``)."""
    return sample_surface(V, F, n, seed=int(rng.integers(2**31))).points


def diagonal(V):
    return float(np.linalg.norm(V.max(0) - V.min(0)))


def run_ours(V, F, P):
    c0, t0 = time.process_time(), time.perf_counter()
    index = TriangleIndex(V, F)
    t1 = time.perf_counter()
    r = index.closest(P)
    c2, t2 = time.process_time(), time.perf_counter()
    return t1 - t0, t2 - t1, c2 - c0, r.distance


def run_blender(V, F, P):
    import bpy  # noqa: F401  (makes mathutils importable)
    from mathutils.bvhtree import BVHTree
    t0 = time.perf_counter()
    verts, polys, pts = V.tolist(), F.tolist(), P.tolist()
    t1 = time.perf_counter()
    c1 = time.process_time()
    tree = BVHTree.FromPolygons(verts, polys, all_triangles=True)
    t2 = time.perf_counter()
    find = tree.find_nearest
    d = np.array([find(p)[3] for p in pts])
    c3, t3 = time.process_time(), time.perf_counter()
    return t1 - t0, t2 - t1, t3 - t2, c3 - c1, d


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="smaller meshes, no file written")
    ap.add_argument("--no-blender", action="store_true", help="skip the Blender runs")
    args = ap.parse_args()
    quick = args.quick
    load0 = os.getloadavg()[0]
    rng = np.random.default_rng(0)
    n_pts = 200_000 if quick else 1_000_000

    cases = []
    # 1. bind-like: fine cage of a 10k-face torus cage vs a bumpy dense torus
    Vc, Fc = torus(50, 25) if quick else torus(100, 50)
    for _ in range(2):
        Vc, Fc = midpoint_split(Vc, Fc)
    Vd, Fd = torus(1000, 500, bump=0.01) if not quick else torus(400, 250, bump=0.01)
    P1 = surface_points(Vd, Fd, n_pts, rng)
    cases.append(("bind: %dk faces, %s points near" % (Fc.shape[0] // 1000, f"{n_pts:,}"),
                  Vc, Fc, P1))
    # 2. ~1M faces
    bunny = os.path.join(SHARED, "stanford-bunny.obj")
    if os.path.exists(bunny) and not quick:
        Vb, Fb = read_obj(bunny)
        used = np.unique(Fb)
        remap = np.zeros(Vb.shape[0], dtype=np.int64)
        remap[used] = np.arange(used.size)
        Vb, Fb = Vb[used], remap[Fb]
        V0, F0 = Vb, Fb
        for _ in range(2):
            Vb, Fb = midpoint_split(Vb, Fb)
        name2 = "bunny x2"
    else:
        V0, F0 = icosphere(3 if quick else 6)
        Vb, Fb = icosphere(5 if quick else 8)
        name2 = "icosphere"
    P2 = surface_points(Vb, Fb, n_pts, rng) + rng.normal(size=(n_pts, 3)) * 0.002 * diagonal(Vb)
    cases.append(("%s: %s faces, %s points near" % (name2, f"{Fb.shape[0]:,}", f"{n_pts:,}"),
                  Vb, Fb, P2))
    # 3. far queries
    lo, hi = Vc.min(0), Vc.max(0)
    n_far = 20_000 if quick else 100_000
    P3 = (lo + hi) / 2 + (rng.random((n_far, 3)) - 0.5) * 2 * (hi - lo)
    cases.append(("far: %dk faces, %s points in 2x bbox" % (Fc.shape[0] // 1000, f"{n_far:,}"),
                  Vc, Fc, P3))

    rows = []
    for name, V, F, P in cases:
        tb, tq, tc, d = run_ours(V, F, P)
        row = dict(name=name, ours_build=tb, ours_query=tq, ours_cpu=tc)
        if not args.no_blender:
            tl, bb, bq, bc, db = run_blender(V, F, P)
            row.update(bl_list=tl, bl_build=bb, bl_query=bq, bl_cpu=bc,
                       diff=100 * float(np.max(np.abs(d - db))) / diagonal(V))
        rows.append(row)
        print(row, flush=True)

    # 4. the metric: the ~1M mesh with scan-like noise (0.2 mean edge lengths along the
    #    normals) against the coarse mesh it came from (the original bunny)
    edge = float(np.mean(np.linalg.norm(Vb[Fb[:, 0]] - Vb[Fb[:, 1]], axis=1)))
    nrm = np.zeros_like(Vb)
    fn = np.cross(Vb[Fb[:, 1]] - Vb[Fb[:, 0]], Vb[Fb[:, 2]] - Vb[Fb[:, 0]])
    for k in range(3):
        np.add.at(nrm, Fb[:, k], fn)
    nrm /= np.maximum(np.linalg.norm(nrm, axis=1), 1e-300)[:, None]
    W = Vb + nrm * rng.normal(size=(Vb.shape[0], 1)) * 0.2 * edge
    t0 = time.perf_counter()
    sd = surface_distance(W, Fb, V0, F0)
    t_metric = time.perf_counter() - t0
    print("metric", t_metric, sd, flush=True)

    lines = ["# Closest points: core.spatial vs Blender BVHTree.find_nearest", "",
             "`python scripts/bench_spatial.py%s` (bpy %s, NumPy %s, 2-core machine shared "
             "with other jobs: wall-clock times vary by up to 2x between runs; the CPU-time "
             "ratio, build + query, is the steadier comparison)." % (
                 " --quick" if quick else "", _bpy_version(), np.__version__), "",
             "Load average (1 min) at the start and the end: %.1f, %.1f." % (
                 load0, os.getloadavg()[0]),
             "",
             "| case | ours: build | ours: query | Blender: build | Blender: query loop "
             "| ratio (ours / Blender), wall | ratio, CPU time | max diff (% diag) |",
             "| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: |"]
    for r in rows:
        if "bl_query" in r:
            lines.append("| %s | %.2f s | %.2f s | %.2f s | %.2f s | %.2f | %.2f | %.1e |" % (
                r["name"], r["ours_build"], r["ours_query"], r["bl_build"], r["bl_query"],
                (r["ours_build"] + r["ours_query"]) / (r["bl_build"] + r["bl_query"]),
                r["ours_cpu"] / r["bl_cpu"], r["diff"]))
        else:
            lines.append("| %s | %.2f s | %.2f s | - | - | - | - | - |" % (
                r["name"], r["ours_build"], r["ours_query"]))
    lines += ["", "Blender's list conversion (`tolist()` of vertices, faces and points, needed "
              "by `FromPolygons` and the loop) is not included above: %s." % ", ".join(
                  "%.2f s" % r["bl_list"] for r in rows if "bl_list" in r), "",
              "`surface_distance` of the %s-face mesh with noise of 0.2 edge lengths along the "
              "normals against the %s-face mesh it was subdivided from (default %s samples "
              "per side plus all vertices, two indexes built): %.2f s (Hausdorff %.4f %%, "
              "mean %.4f %% of the diagonal)." % (
                  f"{Fb.shape[0]:,}", f"{F0.shape[0]:,}", f"{sd.n_samples:,}", t_metric,
                  sd.hausdorff_pct, sd.mean_pct)]
    text = "\n".join(lines) + "\n"
    print(text)
    if not quick:
        os.makedirs(os.path.join(ROOT, "bench_results"), exist_ok=True)
        with open(os.path.join(ROOT, "bench_results", "spatial.md"), "w") as fh:
            fh.write(text)


def _bpy_version():
    try:
        import bpy
        return bpy.app.version_string
    except ImportError:
        return "absent"


if __name__ == "__main__":
    main()
