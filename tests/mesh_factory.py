"""Meshes the tests build themselves, access to ``../shared/meshes``, and
``boundary_edges`` to read a mesh's borders back.

Every builder returns ``(V, F)`` as float64 / int64 arrays with outward,
consistent orientation.
"""

import os
import struct

import numpy as np
import pytest

from core.topology import edge_map

SHARED_MESHES = os.path.normpath(
    os.path.join(os.path.dirname(__file__), "..", "..", "shared", "meshes"))


def shared_mesh_path(name):
    """Path of a real mesh in ``../shared/meshes``; skips the test when absent."""
    path = os.path.join(SHARED_MESHES, name)
    if not os.path.exists(path):
        pytest.skip(f"real mesh {name} not found in {SHARED_MESHES} (shared/ is not checked out)")
    return path


def write_binary_stl(path, V, F, *, count=None, extra=b""):
    """A binary STL file of the triangles ``V[F]``, its header's triangle
    count ``count`` (None: the right one), ``extra`` bytes after them."""
    rec = np.zeros(len(F), dtype=[("normal", "<f4", 3), ("v", "<f4", (3, 3)), ("attr", "<u2")])
    rec["v"] = V[F]
    n = len(F) if count is None else count
    path.write_bytes(b"binary".ljust(80) + struct.pack("<I", n) + rec.tobytes() + extra)


def write_ply(path, V, F, *, ascii=False, counts=None, cut=0):
    """A PLY file of ``V`` (float32) and ``F`` (uchar count, int indices; rows
    of any length when ``F`` is a list), binary little-endian or ASCII; its
    header declaring ``counts`` (vertices, faces; None: the true ones), its
    last ``cut`` bytes dropped (a file cut short)."""
    nv, nf = (len(V), len(F)) if counts is None else counts
    head = (f"ply\nformat {'ascii' if ascii else 'binary_little_endian'} 1.0\n"
            f"element vertex {nv}\nproperty float x\nproperty float y\nproperty float z\n"
            f"element face {nf}\nproperty list uchar int vertex_indices\nend_header\n").encode()
    if ascii:
        body = "".join(f"{x} {y} {z}\n" for x, y, z in np.asarray(V, np.float32)) + \
            "".join(f"{len(f)} {' '.join(map(str, f))}\n" for f in F)
        body = body.encode()
    else:
        body = np.asarray(V, "<f4").tobytes() + b"".join(
            bytes([len(f)]) + np.asarray(f, "<i4").tobytes() for f in F)
    data = head + body
    path.write_bytes(data[:len(data) - cut])


def load_shared(name):
    """``(V, F)`` of a real mesh in ``../shared/meshes`` (skips when absent)."""
    from core.io_obj import read_obj
    return read_obj(shared_mesh_path(name))


def shared_mesh_names():
    """Names of the real OBJ meshes available (empty when shared/ is absent)."""
    if not os.path.isdir(SHARED_MESHES):
        return []
    return sorted(f for f in os.listdir(SHARED_MESHES) if f.endswith(".obj"))


def tetrahedron():
    V = np.array([[1, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1]], dtype=np.float64)
    F = np.array([[0, 1, 2], [0, 3, 1], [0, 2, 3], [1, 3, 2]], dtype=np.int64)
    return V, F


def octahedron():
    V = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], dtype=np.float64)
    F = np.array([[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4],
                  [2, 0, 5], [1, 2, 5], [3, 1, 5], [0, 3, 5]], dtype=np.int64)
    return V, F


def icosahedron():
    t = (1 + 5 ** 0.5) / 2
    V = np.array([[-1, t, 0], [1, t, 0], [-1, -t, 0], [1, -t, 0], [0, -1, t], [0, 1, t],
                  [0, -1, -t], [0, 1, -t], [t, 0, -1], [t, 0, 1], [-t, 0, -1], [-t, 0, 1]],
                 dtype=np.float64)
    V /= np.linalg.norm(V, axis=1)[:, None]
    F = np.array([[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9], [5, 11, 4],
                  [11, 10, 2], [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8],
                  [3, 8, 9], [4, 9, 5], [2, 4, 11], [6, 2, 10], [8, 6, 7], [9, 8, 1]], dtype=np.int64)
    return V, F


def midpoint_split(V, F):
    """One 1-to-4 midpoint split (builds spheres and large test meshes
    without core code)."""
    n = V.shape[0]
    half = F[:, [1, 2, 2, 0, 0, 1]].reshape(-1, 2)
    key = np.minimum(half[:, 0], half[:, 1]) * n + np.maximum(half[:, 0], half[:, 1])
    uniq, inv = np.unique(key, return_inverse=True)
    E = np.stack([uniq // n, uniq % n], axis=1)
    mid = n + inv.reshape(-1, 3)  # mid[f, c]: midpoint of edge opposite corner c
    V2 = np.vstack([V, 0.5 * (V[E[:, 0]] + V[E[:, 1]])])
    a, b, c = F[:, 0], F[:, 1], F[:, 2]
    ma, mb, mc = mid[:, 0], mid[:, 1], mid[:, 2]
    F2 = np.concatenate([np.stack([a, mc, mb], 1), np.stack([b, ma, mc], 1),
                         np.stack([c, mb, ma], 1), np.stack([ma, mb, mc], 1)])
    return V2, F2


def icosphere(subdivisions=2, radius=1.0):
    V, F = icosahedron()
    for _ in range(subdivisions):
        V, F = midpoint_split(V, F)
        V /= np.linalg.norm(V, axis=1)[:, None]
    return V * radius, F


def sphere_binding(scheme):
    """A noisy sphere (4 subdivisions), its 120-face QEM cage and their
    binding at two levels of ``scheme``: ``(V_dense, V_cage, binding)``, the
    incremental deform's and refine's test case."""
    from core.binding import bind
    from core.simplify import simplify
    Vd, Fd = noisy_sphere(4, amp=0.02)
    cage = simplify(Vd, Fd, target_faces=120)
    return Vd, cage.V, bind(Vd, Fd, cage.V, cage.F, levels=2, scheme=scheme)


def drawn_edit(data, V_cage):
    """A cage edit drawn by hypothesis (``data``: ``st.data()``): 1-12 cage
    vertices (duplicates allowed) moved by normal noise of 0.05; ``(ids,
    edited copy of V_cage)``."""
    from hypothesis import strategies as st
    n = V_cage.shape[0]
    seed = data.draw(st.integers(0, 2**31 - 1))
    ids = np.array(data.draw(st.lists(st.integers(0, n - 1), min_size=1, max_size=12)))
    Ve = V_cage.copy()
    Ve[ids] += 0.05 * np.random.default_rng(seed).standard_normal((ids.shape[0], 3))
    return ids, Ve


def noisy_sphere(k=3, amp=0.03, seed=0):
    """An :func:`icosphere` of ``k`` subdivisions, each vertex moved along
    its radius by ``amp`` times a standard normal draw (``seed``)."""
    V, F = icosphere(k)
    rng = np.random.default_rng(seed)
    return V * (1 + amp * rng.standard_normal((V.shape[0], 1))), F


def grid(nx=10, ny=10, size=1.0, z=None):
    """Open (nx+1)x(ny+1)-vertex grid on [0,size]^2, triangulated with
    alternating diagonals (regular valence 6 inside needs a fixed diagonal:
    see ``regular_grid``). ``z`` may be a function of (x, y)."""
    return regular_grid(nx, ny, size=size, z=z)


def regular_grid(nx=10, ny=10, size=1.0, z=None):
    """Open grid with every interior vertex of valence 6 (all diagonals the
    same way), outward normal +z."""
    xs = np.linspace(0, size, nx + 1)
    ys = np.linspace(0, size, ny + 1)
    X, Y = np.meshgrid(xs, ys, indexing="xy")
    Z = np.zeros_like(X) if z is None else z(X, Y)
    V = np.stack([X.ravel(), Y.ravel(), Z.ravel()], axis=1).astype(np.float64)
    i, j = np.meshgrid(np.arange(nx), np.arange(ny), indexing="xy")
    v00 = (j * (nx + 1) + i).ravel()
    v10, v01, v11 = v00 + 1, v00 + nx + 1, v00 + nx + 2
    F = np.concatenate([np.stack([v00, v10, v11], 1), np.stack([v00, v11, v01], 1)]).astype(np.int64)
    return V, F


def cad_cylinder(n_around=1000, height=10.0, radius=1.0):
    """A closed cylinder as CAD programs export it: one row of side
    triangles the whole height long (``n_around`` of them per side,
    ``height / (2 pi radius / n_around)`` to 1: 1,600 to 1 by default) and
    two fans of needles from the caps' centres."""
    t = np.linspace(0, 2 * np.pi, n_around, endpoint=False)
    ring = np.c_[radius * np.cos(t), radius * np.sin(t)]
    V = np.vstack([np.c_[ring, np.zeros(n_around)], np.c_[ring, np.full(n_around, height)],
                   [[0.0, 0.0, 0.0], [0.0, 0.0, height]]])
    i = np.arange(n_around)
    j = (i + 1) % n_around
    bottom, top = 2 * n_around, 2 * n_around + 1
    F = np.vstack([np.c_[i, j, j + n_around], np.c_[i, j + n_around, i + n_around],
                   np.c_[np.full(n_around, bottom), j, i],
                   np.c_[np.full(n_around, top), i + n_around, j + n_around]])
    return V, F.astype(np.int64)


def needle_cone(n_around=1000, height=1.0, radius=1.0):
    """A closed cone as CAD programs export it: its side a fan of
    ``n_around`` needles from the apex, its base a flat fan of as many from
    its centre (two hubs of valence ``n_around``)."""
    t = np.linspace(0, 2 * np.pi, n_around, endpoint=False)
    V = np.vstack([np.c_[radius * np.cos(t), radius * np.sin(t), np.zeros(n_around)],
                   [[0.0, 0.0, height], [0.0, 0.0, 0.0]]])
    i = np.arange(n_around)
    j = (i + 1) % n_around
    F = np.vstack([np.c_[np.full(n_around, n_around), i, j],
                   np.c_[np.full(n_around, n_around + 1), j, i]])
    return V, F.astype(np.int64)


def fillet_cap(n_arc=1000, size=100.0, radius=5.0):
    """A box's corner region as CAD exports a filleted edge: the end cap a
    fan of ``n_arc + 2`` needles from one box corner to a quarter arc of
    ``n_arc`` segments (and the cap's two long edges), the fillet one row of
    ``size``-long strips, the box closed by two triangles a side. Closed."""
    k = n_arc
    a = np.linspace(0, np.pi / 2, k + 1)
    arc = np.c_[size - radius + radius * np.cos(a), size - radius + radius * np.sin(a)]
    V = np.vstack([np.c_[np.zeros(k + 1), arc], np.c_[np.full(k + 1, size), arc],
                   [[0, 0, 0], [size, 0, 0], [size, size, 0], [0, size, 0], [0, 0, size], [size, 0, size]]])
    c = 2 * (k + 1) + np.arange(6)
    i = np.arange(k)
    cap0 = np.r_[c[3], np.arange(0, k + 1), c[4]]
    cap1 = np.r_[c[2], np.arange(k + 1, 2 * k + 2), c[5]]
    F = np.vstack([np.c_[i, i + 1, i + k + 2], np.c_[i, i + k + 2, i + k + 1],
                   [[c[0], c[1], c[2]], [c[0], c[2], c[3]], [c[0], c[1], c[5]], [c[0], c[5], c[4]],
                    [c[3], c[2], k + 1], [c[3], k + 1, 0], [c[4], c[5], 2 * k + 1], [c[4], 2 * k + 1, k]],
                   np.c_[np.full(cap0.size - 1, c[0]), cap0[:-1], cap0[1:]],
                   np.c_[np.full(cap1.size - 1, c[1]), cap1[:-1], cap1[1:]]]).astype(np.int64)
    P = V[F]
    N = np.cross(P[:, 1] - P[:, 0], P[:, 2] - P[:, 0])
    out = np.einsum("ij,ij->i", N, P.mean(axis=1) - size / 2) < 0
    F[out] = F[out][:, ::-1]
    return V, F


def star_glyphs(count=3, spikes=200, depth=0.3):
    """``count`` extruded star-shaped glyphs side by side, as CAD exports
    text: each cap a fan of ``2 * spikes`` triangles from its centre (a hub
    of valence ``2 * spikes``, the outline alternating between radius 1 and
    0.15), one row of side quads; each glyph a closed genus-0 prism of
    ``8 * spikes`` faces."""
    m = 2 * spikes
    t = np.linspace(0, 2 * np.pi, m, endpoint=False)
    rad = np.where(np.arange(m) % 2 == 0, 1.0, 0.15)
    ring = np.c_[rad * np.cos(t), rad * np.sin(t)]
    i = np.arange(m)
    j = (i + 1) % m
    Vs, Fs = [], []
    for g in range(count):
        at = [2.5 * g, 0.0]
        V = np.vstack([np.c_[ring + at, np.zeros(m)], np.c_[ring + at, np.full(m, depth)],
                       [at + [0.0], at + [depth]]])
        F = np.vstack([np.c_[np.full(m, 2 * m), j, i], np.c_[np.full(m, 2 * m + 1), i + m, j + m],
                       np.c_[i, j, j + m], np.c_[i, j + m, i + m]])
        Fs.append(F + g * V.shape[0])
        Vs.append(V)
    return np.vstack(Vs), np.vstack(Fs).astype(np.int64)


def torus(n_major=24, n_minor=12, R=1.0, r=0.35, bump=0.0, bump_waves=(40, 12)):
    """Closed genus-1 torus, regular valence 6; ``bump`` adds a tube radius
    ``bump * sin(a u) sin(b v)`` with ``(a, b) = bump_waves`` (detail)."""
    u = np.arange(n_major) * 2 * np.pi / n_major
    v = np.arange(n_minor) * 2 * np.pi / n_minor
    U, W = np.meshgrid(u, v, indexing="ij")
    rr = r + bump * np.sin(bump_waves[0] * U) * np.sin(bump_waves[1] * W)
    V = np.stack([(R + rr * np.cos(W)) * np.cos(U), (R + rr * np.cos(W)) * np.sin(U),
                  rr * np.sin(W)], axis=-1).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(n_major), np.arange(n_minor), indexing="ij")
    a = (i * n_minor + j).ravel()
    b = (((i + 1) % n_major) * n_minor + j).ravel()
    c = (((i + 1) % n_major) * n_minor + (j + 1) % n_minor).ravel()
    d = (i * n_minor + (j + 1) % n_minor).ravel()
    F = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)]).astype(np.int64)
    return V, F


def lens(n=12, height=3e-4, rings=1):
    """A closed lens of radius 1: two flat cones, apexes at ``+-height``, on a
    rim of ``n`` vertices in the plane z = 0, each cone with ``rings``
    circles of vertices (the last the rim, shared). At the rim the faces above
    and below are within ``2 height`` radians of back to back: a fin.
    Vertices: the two apexes, then the top cone's circles inward-out (the
    rim last), then the bottom cone's others."""
    a = 2 * np.pi * np.arange(n) / n
    t = np.arange(1, rings + 1) / rings
    circle = np.stack([np.cos(a), np.sin(a), np.zeros(n)], axis=1)
    top = [circle * [r, r, 0] + [0, 0, height * (1 - r)] for r in t]
    bottom = [c * [1, 1, -1] for c in top[:-1]]
    V = np.vstack([[[0, 0, height], [0, 0, -height]], *top, *bottom])
    ids = 2 + np.arange(rings * n).reshape(rings, n)
    sides = (ids, np.vstack([2 + rings * n + np.arange((rings - 1) * n).reshape(-1, n),
                             ids[-1:]]))
    j, k = np.arange(n), (np.arange(n) + 1) % n
    F = []
    for apex, c in zip((0, 1), sides):
        side = [np.stack([np.full(n, apex), c[0][j], c[0][k]], 1)]
        for inner, outer in zip(c[:-1], c[1:]):
            side += [np.stack([inner[j], outer[j], outer[k]], 1),
                     np.stack([inner[j], outer[k], inner[k]], 1)]
        side = np.concatenate(side)
        F.append(side if apex == 0 else side[:, ::-1])
    return V, np.concatenate(F).astype(np.int64)


def mobius_strip(n_around=120, n_across=12, width=0.3, bump=0.0):
    """A one-sided (non-orientable) strip of ``2 n_around (n_across - 1)``
    faces: the ring's last column is joined to its first turned over (row
    ``j`` to row ``n_across - 1 - j``); ``bump`` adds ``bump sin(9u) cos(7s)``
    along the normal-ish z axis (detail)."""
    u = np.arange(n_around) * 2 * np.pi / n_around
    s = np.linspace(-width, width, n_across)
    U, S = np.meshgrid(u, s, indexing="ij")
    r = 1 + S * np.cos(U / 2)
    V = np.stack([r * np.cos(U), r * np.sin(U),
                  S * np.sin(U / 2) + bump * np.sin(9 * U) * np.cos(7 * S / width)], -1).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(n_around), np.arange(n_across - 1), indexing="ij")
    a = i * n_across + j
    c = np.where(i < n_around - 1, (i + 1) * n_across + j, n_across - 1 - j)       # the twist
    d = np.where(i < n_around - 1, c + 1, n_across - 2 - j)
    F = np.concatenate([np.stack([a, c, a + 1], -1).reshape(-1, 3),
                        np.stack([a + 1, c, d], -1).reshape(-1, 3)])
    return V, F.astype(np.int64)


def klein_bottle(n_u=80, n_v=40, r=2.0):
    """A closed one-sided surface (the figure-8 immersion of the Klein bottle,
    ``2 n_u n_v`` faces; it passes through itself, as a scan's sheets may)."""
    u = np.arange(n_u) * 2 * np.pi / n_u
    v = np.arange(n_v) * 2 * np.pi / n_v
    U, W = np.meshgrid(u, v, indexing="ij")
    rad = r + np.cos(U / 2) * np.sin(W) - np.sin(U / 2) * np.sin(2 * W)
    V = np.stack([rad * np.cos(U), rad * np.sin(U),
                  np.sin(U / 2) * np.sin(W) + np.cos(U / 2) * np.sin(2 * W)], -1).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(n_u), np.arange(n_v), indexing="ij")
    a, b = i * n_v + j, i * n_v + (j + 1) % n_v
    c = np.where(i < n_u - 1, (i + 1) * n_v + j, (-j) % n_v)                      # the twist
    d = np.where(i < n_u - 1, (i + 1) * n_v + (j + 1) % n_v, (-(j + 1)) % n_v)
    F = np.concatenate([np.stack([a, c, b], -1).reshape(-1, 3),
                        np.stack([b, c, d], -1).reshape(-1, 3)])
    return V, F.astype(np.int64)


def cube(n=1, size=1.0):
    """Closed axis-aligned cube [-size/2, size/2]^3, each side an n x n grid
    of quads split into triangles; vertices shared along the cube edges."""
    s = np.linspace(-0.5, 0.5, n + 1) * size
    pts = {}
    faces = []
    verts = []

    def vid(p):
        key = tuple(np.round(p, 12))
        if key not in pts:
            pts[key] = len(verts)
            verts.append(p)
        return pts[key]

    # six sides: (normal axis, sign); a right-handed (u, v) frame so u x v = normal
    for axis in range(3):
        for sign in (-1.0, 1.0):
            u_ax, v_ax = (axis + 1) % 3, (axis + 2) % 3
            if sign < 0:
                u_ax, v_ax = v_ax, u_ax
            for i in range(n):
                for j in range(n):
                    quad = []
                    for di, dj in ((0, 0), (1, 0), (1, 1), (0, 1)):
                        p = np.zeros(3)
                        p[axis] = sign * size / 2
                        p[u_ax] = s[i + di]
                        p[v_ax] = s[j + dj]
                        quad.append(vid(p))
                    faces.append([quad[0], quad[1], quad[2]])
                    faces.append([quad[0], quad[2], quad[3]])
    return np.array(verts, dtype=np.float64), np.array(faces, dtype=np.int64)


def double_torus(resolution=40):
    """A closed genus-2 surface: two tori fused (marching-free construction:
    two regular tori with a hole cut in each and the holes bridged)."""
    V1, F1 = torus(resolution, resolution // 3, R=1.0, r=0.4)
    V2, F2 = torus(resolution, resolution // 3, R=1.0, r=0.4)
    V2 = V2 + np.array([2.8, 0.0, 0.0])
    nm = resolution // 3
    # the quad facing the other torus: major index 0 (x max) on torus 1,
    # major index resolution//2 (x min) on torus 2, minor index 0 (outer equator)
    def quad_faces(i, j, n_major):
        a = i * nm + j
        b = ((i + 1) % n_major) * nm + j
        c = ((i + 1) % n_major) * nm + (j + 1) % nm
        d = i * nm + (j + 1) % nm
        return a, b, c, d

    a1, b1, c1, d1 = quad_faces(resolution - 1, nm - 1, resolution)
    a1, b1, c1, d1 = quad_faces(resolution - 1, 0, resolution)
    i2 = resolution // 2
    a2, b2, c2, d2 = quad_faces(i2 - 1, 0, resolution)

    def drop_quad(F, a, b, c, d):
        keep = ~(np.all(np.isin(F, [a, b, c, d]), axis=1))
        return F[keep]

    F1 = drop_quad(F1, a1, b1, c1, d1)
    F2 = drop_quad(F2, a2, b2, c2, d2)
    off = V1.shape[0]
    # torus-1 hole loop a1-b1-c1-d1, torus-2 hole loop a2-b2-c2-d2 (faces mirror in x)
    loop1 = [a1, b1, c1, d1]
    loop2 = [b2 + off, a2 + off, d2 + off, c2 + off]
    bridge = []
    for k in range(4):
        p, q = loop1[k], loop1[(k + 1) % 4]
        r, s_ = loop2[k], loop2[(k + 1) % 4]
        bridge.append([p, q, r])
        bridge.append([r, q, s_])
    V = np.vstack([V1, V2])
    F = np.vstack([F1, F2 + off, np.array(bridge, dtype=np.int64)])
    return V, F


# --- a smooth shape with high-frequency detail, and an analytic edit of it ---

BUMP = 0.01                        # bump amplitude
TUBE_LENGTH, TUBE_RADIUS = 3.0, 0.3
BEND_RADIUS = TUBE_LENGTH / (np.pi / 2)   # the tube's axis bends a quarter turn


def bumpy_tube(nu=240, nv=96):
    """Open tube along x (length 3, radius 0.3) with bumps of amplitude
    ``BUMP`` (wavelength 0.125 along the axis, 16 around): a smooth shape
    with high-frequency detail no 800-face cage can hold."""
    u = np.linspace(0.0, TUBE_LENGTH, nu + 1)
    v = np.arange(nv) * 2 * np.pi / nv
    U, W = np.meshgrid(u, v, indexing="ij")
    r = TUBE_RADIUS + BUMP * np.sin(2 * np.pi * U / 0.125) * np.sin(16 * W)
    V = np.stack([U, r * np.cos(W), r * np.sin(W)], axis=-1).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(nu), np.arange(nv), indexing="ij")
    a = (i * nv + j).ravel()
    b = ((i + 1) * nv + j).ravel()
    c = ((i + 1) * nv + (j + 1) % nv).ravel()
    d = (i * nv + (j + 1) % nv).ravel()
    F = np.concatenate([np.stack([a, c, b], 1), np.stack([a, d, c], 1)]).astype(np.int64)
    return V, F


def analytic_bend(V):
    """Bend around the axis (x=0, z=-R) parallel to y: the line z = 0 maps
    isometrically onto the circle of radius R, z offsets go along its normal."""
    th = V[:, 0] / BEND_RADIUS
    r = BEND_RADIUS + V[:, 2]
    return np.stack([r * np.sin(th), V[:, 1], r * np.cos(th) - BEND_RADIUS], axis=1)


def boundary_edges(F, n):
    """(k,2) int64: the edges of ``F`` used by exactly one face."""
    em = edge_map(F, n)
    return em.E[em.edge_face_count == 1]


# ---------------------------------------------------------------- messy variants (as scans arrive)
def bend_angles_deg(V, F, skip_edges=()):
    """Angle between the normals of the two faces of every interior edge,
    in degrees, leaving out the edges ``skip_edges`` (k,2)."""
    em = edge_map(F, V.shape[0])
    N = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    N = N / np.linalg.norm(N, axis=1)[:, None]
    fe = em.face_edge.ravel()
    order = np.argsort(fe, kind="stable")
    e, f = fe[order], order // 3
    pair = np.flatnonzero(e[1:] == e[:-1])
    edges, a, b = e[pair], f[pair], f[pair + 1]
    if len(skip_edges):
        skip = {tuple(x) for x in np.sort(np.asarray(skip_edges), axis=1).tolist()}
        keep = np.array([tuple(x) not in skip for x in em.E[edges].tolist()], dtype=bool)
        a, b = a[keep], b[keep]
    return np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", N[a], N[b]), -1.0, 1.0)))


def unwelded(V, F, jitter=0.0, seed=0):
    """A triangle soup of the mesh: three vertices of its own per face, each
    moved by ``jitter`` of the bounding-box diagonal (Gaussian)."""
    rng = np.random.default_rng(seed)
    d = float(np.linalg.norm(V.max(axis=0) - V.min(axis=0)))
    S = V[F.ravel()] + rng.normal(scale=jitter * d, size=(F.size, 3)) * (jitter > 0)
    return S, np.arange(F.size, dtype=np.int64).reshape(-1, 3)


def pinched(V, F, k=3, seed=1):
    """``k`` bow-tie vertices: pairs of far-apart vertices merged into one
    index (positions kept: the second vertex becomes unreferenced)."""
    rng = np.random.default_rng(seed)
    F = F.copy()
    used = np.unique(F)
    for _ in range(k):
        a, b = rng.choice(used, 2, replace=False)
        F[F == b] = a
        used = used[used != b]
    keep = (F[:, 0] != F[:, 1]) & (F[:, 1] != F[:, 2]) & (F[:, 2] != F[:, 0])
    return V.copy(), F[keep]


def with_debris(V, F, k=300, size=1e-3, seed=2):
    """``k`` closed tetrahedra of ``size`` times the diagonal scattered near
    the surface."""
    rng = np.random.default_rng(seed)
    d = float(np.linalg.norm(V.max(axis=0) - V.min(axis=0)))
    tet = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1.0]]) * size * d
    tf = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    c = V[rng.integers(0, len(V), k)] + rng.normal(scale=0.02 * d, size=(k, 3))
    return (np.concatenate([V, (c[:, None, :] + tet[None]).reshape(-1, 3)]),
            np.concatenate([F, (tf[None] + 4 * np.arange(k)[:, None, None] + len(V)).reshape(-1, 3)]))


def with_far_speck(V, F, far=1e3, at=None):
    """The mesh and one more triangle, its first face at a tenth of its size,
    ``far`` diagonals beyond its bounding box's upper corner (or at ``at``):
    a stray speck, or a triangle left at the origin of a scan placed far off."""
    d = float(np.linalg.norm(V.max(axis=0) - V.min(axis=0)))
    at = V.max(axis=0) + far * d if at is None else np.asarray(at, dtype=np.float64)
    tri = 0.1 * (V[F[0]] - V[F[0]].mean(axis=0)) + at
    return np.vstack([V, tri]), np.vstack([F, np.arange(3) + V.shape[0]])


def with_sheets(V, F, k=5, seed=3):
    """``k`` double-sided sheets: the faces around ``k`` vertices repeated
    with the opposite orientation."""
    rng = np.random.default_rng(seed)
    faces = np.unique(np.flatnonzero(np.isin(F, rng.choice(np.unique(F), k, replace=False)).any(axis=1)))
    return V.copy(), np.concatenate([F, F[faces][:, ::-1]])


def apart_faces(F, k, seed=0):
    """Up to ``k`` faces of ``F`` sharing no vertex with each other nor with
    a border of ``F`` (random)."""
    from core._clean import BOUNDARY, half_edge_ends, twin_table
    rng = np.random.default_rng(seed)
    used = np.zeros(int(F.max()) + 1, dtype=bool)
    border = np.flatnonzero(twin_table(F, used.shape[0]) == BOUNDARY)
    for ends in half_edge_ends(F, border):
        used[ends] = True
    out = []
    for f in rng.permutation(F.shape[0]):
        if not used[F[f]].any():
            used[F[f]] = True
            out.append(f)
            if len(out) == k:
                break
    return np.array(out, dtype=np.int64)


def with_pinholes(V, F, share=0.02, seed=5):
    """A ``share`` of the faces missing, one here and one there (no two
    sharing a vertex, none at a border): a scan's dropouts, one-triangle holes."""
    keep = np.ones(F.shape[0], dtype=bool)
    keep[apart_faces(F, int(round(share * F.shape[0])), seed)] = False
    return V.copy(), F[keep]


def duplicated(V, F, offset=1e-7, seed=6):
    """The mesh and a copy of it on vertices of its own, moved by ``offset``
    of the diagonal (an object exported twice, in place)."""
    rng = np.random.default_rng(seed)
    d = float(np.linalg.norm(V.max(axis=0) - V.min(axis=0)))
    return np.concatenate([V, V + offset * d * rng.normal(size=3)]), np.concatenate([F, F + len(V)])


def with_fins(V, F, k=4, seed=4):
    """``k`` fins: a triangle on an existing edge, sticking out (the edge then
    has three faces)."""
    rng = np.random.default_rng(seed)
    f = rng.choice(F.shape[0], k, replace=False)
    a, b = F[f, 0], F[f, 1]
    mid = 0.5 * (V[a] + V[b])
    tip = mid + (mid - V.mean(axis=0)) * 0.3
    n = V.shape[0]
    return np.concatenate([V, tip]), np.concatenate([F, np.stack([b, a, n + np.arange(k)], axis=1)])


def random_winding(V, F, share=0.5, seed=7):
    """Each face reversed with probability ``share`` (photogrammetry and some
    scanner exports write each triangle's winding at random)."""
    rng = np.random.default_rng(seed)
    F = F.copy()
    turn = rng.random(F.shape[0]) < share
    F[turn] = F[turn][:, ::-1]
    return V.copy(), F


def cyclic_rows(F):
    """``F`` with each row rotated to start at its smallest index, keeping
    its cyclic order (two faces are the same oriented face when their rows
    are equal here)."""
    F = np.asarray(F)
    first = np.argmin(F, axis=1)
    cols = (first[:, None] + np.arange(3)[None]) % 3
    return np.take_along_axis(F, cols, axis=1)


def with_pebbles(V, F, k=100, size=0.02, seed=8):
    """The mesh beside ``k`` closed pebbles (80-face icospheres of radius ``size``
    times the diagonal, squashed at random), on a ring around it: a scan of
    an object on gravel. Their area is too large a share for debris."""
    rng = np.random.default_rng(seed)
    lo, hi = V.min(axis=0), V.max(axis=0)
    d = float(np.linalg.norm(hi - lo))
    P, Q = icosphere(1)
    angle = np.linspace(0.0, 2.0 * np.pi, k, endpoint=False)
    centre = 0.5 * (lo + hi) + 0.9 * d * np.stack([np.cos(angle), np.sin(angle), 0 * angle], axis=1)
    pebbles = P[None] * size * d * rng.uniform(0.6, 1.0, (k, 1, 3)) + centre[:, None]
    faces = Q[None] + V.shape[0] + P.shape[0] * np.arange(k)[:, None, None]
    return np.vstack([V, pebbles.reshape(-1, 3)]), np.vstack([F, faces.reshape(-1, 3)])


def out_files(folder):
    """The names in an output ``folder``, sorted, but the batch's own hidden
    record of each output's input (``cli.outputs.SOURCES_FILE``)."""
    return sorted(n for n in os.listdir(folder) if not n.startswith("."))
