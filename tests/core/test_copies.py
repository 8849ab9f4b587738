"""Coincident copies (``core.copies``, stages of ``clean_mesh``): a component
lying on another one vertex for vertex (an object duplicated in place, a patch
stacked twice), or a piece lying on another face for face before the weld (a
holed scan twice), is dropped and reported; components that only touch stay."""

import numpy as np
import pytest

from core import bbox_diagonal, simplify, topology_summary
from core._clean import twin_table
from core.clean import clean_mesh
from core.copies import stacked_copies
from tests.mesh_factory import icosphere, load_shared, shared_mesh_names, with_fins, with_pinholes


def twice(V, F, offset=0.0, faces=None):
    """``(V, F)`` and a copy of its ``faces`` (all by default) on vertices of
    their own, moved by ``offset`` diagonals."""
    sel = np.arange(F.shape[0]) if faces is None else faces
    used, inv = np.unique(F[sel], return_inverse=True)
    shift = offset * bbox_diagonal(V) * np.array([0.3, 0.5, 0.8])
    return (np.concatenate([V, V[used] + shift]),
            np.concatenate([F, inv.reshape(-1, 3) + V.shape[0]]))


def components(r):
    return topology_summary(r.F, r.V.shape[0]).components


@pytest.mark.parametrize("offset", [0.0, 1e-7])
def test_an_object_duplicated_in_place_is_dropped(offset):
    V, F = icosphere(3)
    r = clean_mesh(*twice(V, F, offset))
    assert r.report.n_copies == 1 and r.report.n_copy_faces == F.shape[0]
    assert "dropped 1 coincident copies (1,280 faces" in r.report.summary()
    # the first one stays, as it came: the clean mesh of the sphere alone
    alone = clean_mesh(V, F)
    np.testing.assert_array_equal(r.F, alone.F)
    np.testing.assert_array_equal(r.V, alone.V)
    np.testing.assert_array_equal(r.face_to_input, alone.face_to_input)


def test_copies_farther_than_a_weld_stay():
    V, F = icosphere(3)
    r = clean_mesh(*twice(V, F, 1e-3))
    assert r.report.n_copies == 0 and components(r) == 2


def test_a_stacked_patch_goes_and_three_copies_leave_one():
    V, F = icosphere(3)
    top = np.flatnonzero(V[F].mean(axis=1)[:, 2] > 0.5)
    r = clean_mesh(*twice(V, F, 1e-7, faces=top))
    assert r.report.n_copies == 1 and r.report.n_copy_faces == top.size
    assert r.F.shape[0] == F.shape[0] and components(r) == 1
    V3, F3 = twice(*twice(V, F), 0.0, faces=np.arange(F.shape[0]))
    r = clean_mesh(V3, F3)
    assert r.report.n_copies == 2 and r.F.shape[0] == F.shape[0] and components(r) == 1


def test_components_that_touch_stay():
    """Two spheres touching at one vertex (a bow-tie, split) and a sphere with
    a lid sharing its rim: some vertices coincide, not all."""
    V, F = icosphere(2)
    top = int(np.argmax(V[:, 2]))
    above = V * [1, 1, -1] + [0, 0, 2 * V[top, 2]]              # touches at the pole
    r = clean_mesh(np.concatenate([V, above]), np.concatenate([F, F[:, ::-1] + V.shape[0]]))
    assert r.report.n_copies == 0 and components(r) == 2
    # a lid: the sphere's top cap again as its own disk, its centre lifted
    cap = np.flatnonzero(V[F].mean(axis=1)[:, 2] > 0.7)
    V3, F3 = twice(V, F, 0.0, faces=cap)
    V3[V.shape[0] + np.unique(F[cap], return_inverse=True)[1].reshape(-1, 3)[:, 0]] += [0, 0, 0.05]
    r = clean_mesh(V3, F3)
    assert r.report.n_copies == 0 and components(r) == 2


def test_a_protected_copy_stays():
    V, F = icosphere(2)
    V2, F2 = twice(V, F)
    protected = np.zeros(V2.shape[0], dtype=bool)
    protected[V.shape[0]] = True
    r = clean_mesh(V2, F2, protected=protected)
    assert r.report.n_copies == 0 and components(r) == 2


def test_the_cow_twice_gives_the_cows_cage():
    V, F = load_shared("cow.obj")
    one = simplify(V, F, target_faces=300)
    two = simplify(*twice(V, F, 1e-7), target_faces=300)
    assert two.cleaning.n_copies == 1 and two.n_components == 1
    np.testing.assert_array_equal(two.F, one.F)
    np.testing.assert_array_equal(two.V, one.V)
    np.testing.assert_array_equal(two.vertex_map[:V.shape[0]], one.vertex_map)
    assert (two.vertex_map[V.shape[0]:] == -1).all()


def test_an_open_surface_twice_in_place_keeps_one_layer_facing_as_it_came():
    """The weld joins two copies of an open surface along their borders into
    one flat closed pillow; its second layer goes, and the layer that stays
    faces the way the input did (the pillow's orientation is a coin toss)."""
    V, F = icosphere(3)
    bowl = F[V[F].mean(axis=1)[:, 2] < 0.3]
    for flip in (False, True):
        G = bowl[:, ::-1] if flip else bowl
        alone = clean_mesh(V, G)
        r = clean_mesh(*twice(V, G, 1e-7))
        assert r.report.n_copies == 1 and r.report.n_copy_faces == G.shape[0]
        np.testing.assert_array_equal(r.F, alone.F)
        np.testing.assert_array_equal(r.V, alone.V)
        np.testing.assert_array_equal(r.twin, twin_table(r.F, r.V.shape[0]))


@pytest.mark.slow
@pytest.mark.parametrize("holed", [False, True])
@pytest.mark.parametrize("name", shared_mesh_names())
def test_every_shared_mesh_twice_in_place_gives_its_own_cage(name, holed):
    """Also with 2% of its faces missing in both copies (a scan exported twice
    with its dropouts): before the weld looks at the holes' rims, the second
    copy goes, so it is never stitched to the first (the bunny's cage stopped
    at 20,711 faces of 300 that way; the beetle's, with its own non-manifold
    edges, was 2.3 times its own cage's distance from the input)."""
    V, F = load_shared(name)
    if holed:
        V, F = with_pinholes(V, F)
    one = simplify(V, F, target_faces=300)
    two = simplify(*twice(V, F, 1e-7), target_faces=300)
    # a whole copy of what the cleaning keeps went
    assert two.cleaning.n_copy_faces >= clean_mesh(V, F).F.shape[0]
    assert two.cleaning.n_non_manifold_edges == one.cleaning.n_non_manifold_edges
    np.testing.assert_array_equal(two.F, one.F)
    np.testing.assert_allclose(two.V, one.V, rtol=0, atol=1e-12 * bbox_diagonal(V))


def test_a_holed_sphere_twice_in_place_cleans_to_the_holed_sphere():
    """Holes an edge apart: welded at their rims, the two copies would share
    that edge four times (non-manifold); the copy goes first."""
    V, F = icosphere(4)
    Vh, Fh = with_pinholes(V, F, share=0.05)
    alone = clean_mesh(Vh, Fh)
    r = clean_mesh(*twice(Vh, Fh, 1e-7))
    assert r.report.n_copies == 1 and r.report.n_copy_faces == Fh.shape[0]
    assert r.report.n_non_manifold_edges == 0 and r.report.n_welded_vertices == 0
    np.testing.assert_array_equal(r.F, alone.F)
    np.testing.assert_array_equal(r.V, alone.V)
    np.testing.assert_array_equal(r.face_to_input, alone.face_to_input)
    # protected, the copy stays (and the weld joins it to the first as it can)
    protected = np.zeros(2 * Vh.shape[0], dtype=bool)
    protected[Vh.shape[0] + Fh[0, 0]] = True
    assert clean_mesh(*twice(Vh, Fh, 1e-7), protected=protected).report.n_copy_faces < Fh.shape[0]


def test_pieces_that_meet_at_seams_are_not_copies():
    """A seam-split sphere (each face its own piece of three vertices here and
    there, a one-face piece whose corners all lie on one other piece) with a
    non-manifold fin (so the stage runs): pieces share vertices' places, not
    faces, and none goes."""
    V, F = icosphere(3)
    V2, F2 = with_fins(V, F, k=2)
    lone = np.array([5, 77, 300])
    used, inv = np.unique(F2[lone], return_inverse=True)
    F3 = F2.copy()
    F3[lone] = inv.reshape(-1, 3) + V2.shape[0]
    V3 = np.concatenate([V2, V2[used]])
    assert stacked_copies((V3 - V3.min(axis=0)) / bbox_diagonal(V3), F3,
                          np.ones(F3.shape[0]), 1e-6) is None
    r = clean_mesh(V3, F3)
    assert r.report.n_copies == 0 and r.report.n_welded_vertices == 9
    assert r.report.n_non_manifold_edges == 2


@pytest.mark.parametrize("source", ["icosphere", "cow.obj"])
def test_a_mesh_squashed_flat_is_not_a_pillow(source):
    """Squashed to a millionth of its size across (x 1e3, z 1e-3), a closed
    mesh has next to no volume and faces that coincide here and there, but it
    is not two whole layers: nothing is dropped as a copy, and the cleaned mesh
    stays vertex-manifold (dropping those faces left the cow with 163
    non-manifold vertices)."""
    if source == "icosphere":
        V, F = icosphere(4)
    else:
        V, F = load_shared(source)
    r = clean_mesh(V * [1e3, 1.0, 1e-3], F)
    assert r.report.n_copies == 0
    s = topology_summary(r.F, r.V.shape[0])
    assert (s.non_manifold_edges, s.non_manifold_vertices) == (0, 0)


def _holed_twice(share_a, share_b, fins=0):
    """An icosphere and a copy of it in place (1e-7 apart), each with holes of
    its own (one-face dropouts, ``share_a`` / ``share_b`` of the faces), the
    copy with ``fins`` fins; and the faces missing from both."""
    from tests.mesh_factory import apart_faces
    V, F = icosphere(4)
    holes_a = apart_faces(F, int(share_a * F.shape[0]), seed=1)
    holes_b = apart_faces(F, int(share_b * F.shape[0]), seed=2)
    keep_b = np.setdiff1d(np.arange(F.shape[0]), holes_b)
    V2, F2 = twice(V, F, 1e-7, faces=keep_b)
    F2 = np.concatenate([np.delete(F, holes_a, axis=0), F2[F.shape[0]:]])
    if fins:
        n = F.shape[0] - holes_a.size
        Vf, Ff = with_fins(V2, F2[n:], k=fins, seed=3)        # fins on the copy's edges
        V2, F2 = Vf, np.concatenate([F2[:n], Ff])
    return V2, F2, np.intersect1d(holes_a, holes_b), holes_a, holes_b


def test_a_copy_with_dropouts_of_its_own_fills_the_holes_it_covers():
    """A scan twice in place, each copy with its own dropouts: the copy keeps
    only the faces its original lacks, and the weld joins them to it: the
    holes left are those of both (the bunny so, with 8 fins, gave 8,986
    non-manifold edges cut and a cage of 19,547 faces of 1,000)."""
    V, F, both, holes_a, holes_b = _holed_twice(0.02, 0.04)
    r = clean_mesh(V, F)
    m = 20 * 4 ** 4
    assert r.F.shape[0] == m - both.size and r.report.n_non_manifold_edges == 0
    s = topology_summary(r.F, r.V.shape[0])
    assert (s.components, s.boundary_loops, s.boundary_edges) == (1, both.size, 3 * both.size)
    # the copy (more holes: less area) lost exactly the faces that lie on the original's
    dup = m - holes_b.size - np.setdiff1d(holes_a, holes_b).size
    assert r.report.n_copies == 1 and r.report.n_copy_faces == dup
    # it keeps the faces over the original's holes, its own faces there
    keep_b = np.setdiff1d(np.arange(m), holes_b)
    copy_kept = r.face_to_input[r.face_to_input >= m - holes_a.size] - (m - holes_a.size)
    assert np.array_equal(np.sort(keep_b[copy_kept]), np.setdiff1d(holes_a, holes_b))
    assert both.size > 0 and r.report.n_welded_vertices > 0


def test_a_copy_with_dropouts_and_fins_still_gives_a_cage_on_target():
    """Fins on the copy stick out of its original's bounding box: it was then
    not looked at as a copy (both layers were kept and stitched together at
    every hole's rim)."""
    V, F, both, _, _ = _holed_twice(0.05, 0.05, fins=6)
    r = simplify(V, F, target_faces=300)
    assert r.stopped_because == "target" and abs(r.F.shape[0] - 300) <= 3
    assert r.cleaning.n_copies == 1 and components(r) == 1
    s = topology_summary(r.F, r.V.shape[0])          # a sphere with the holes of both copies
    assert both.size > 0 and (s.boundary_loops, s.euler) == (both.size, 2 - both.size)


def test_faces_wound_the_other_way_are_not_duplicates():
    """A piece lying on another face for face but wound the other way (two
    closed parts touching) keeps those faces; the ones wound the same way go."""
    from tests.mesh_factory import regular_grid
    V, F = regular_grid(4, 4, z=lambda x, y: 0.3 * x * y)
    # a second piece on vertices of its own: two faces reversed, two the same way
    own = np.array([0, 1, 2, 3])                    # a strip: each shares a vertex with the next
    used, inv = np.unique(F[own], return_inverse=True)
    G = inv.reshape(-1, 3) + V.shape[0]
    G[:2] = G[:2, ::-1]
    # and a face of its own, standing up from its edge (else the whole piece is a copy)
    n2 = V.shape[0] + used.size
    G = np.concatenate([G, [[G[2, 0], G[2, 1], n2]]])
    V2 = np.concatenate([V, V[used], [[0.6, 0.1, 0.2]]])
    F2 = np.concatenate([F, G])
    area = np.ones(F2.shape[0])
    drop = stacked_copies((V2 - V2.min(axis=0)) / bbox_diagonal(V2), F2, area, 1e-6)
    assert np.flatnonzero(drop).tolist() == [F.shape[0] + 2, F.shape[0] + 3]
    # protected, the piece loses nothing
    protected = np.zeros(V2.shape[0], dtype=bool)
    protected[-1] = True
    assert stacked_copies((V2 - V2.min(axis=0)) / bbox_diagonal(V2), F2, area, 1e-6, protected) is None


@pytest.mark.parametrize("jitter", [3e-6, 1e-5])
@pytest.mark.parametrize("offset", [0.0, 1e-7])
def test_a_drifted_soup_exported_twice_welds_into_one_piece(jitter, offset):
    """A triangle soup whose corners drifted apart (beyond the first weld
    distance), twice in place: the first weld joins each face to its copy
    only, closed two-face pillows that hid every open edge, so the wider
    welds were never tried and the icosphere stayed 1,280 one-face pieces."""
    from tests.mesh_factory import duplicated, unwelded
    V, F = icosphere(3)
    r = clean_mesh(*duplicated(*unwelded(V, F, jitter=jitter), offset=offset))
    alone = clean_mesh(*unwelded(V, F, jitter=jitter))
    assert r.F.shape[0] == F.shape[0] and components(r) == 1
    # the weld the soup alone takes (1e-5 and 1e-4 for these drifts), the copy's faces gone
    assert r.report.weld_distance == alone.report.weld_distance > 1e-6
    assert r.report.n_duplicate_faces == F.shape[0]
    s = topology_summary(r.F, r.V.shape[0])
    assert (s.euler, s.boundary_loops, s.non_manifold_edges) == (2, 0, 0)    # the sphere
