"""The stages of the collapse engine (core._collapse), each on its own."""

from dataclasses import replace

import numpy as np
import pytest

from core import _collapse as engine
from core._clean import BOUNDARY, twin_table
from core.quadrics import vertex_face_quadrics
from core.tuning import TUNING
from core._relax import close_smallest_hole
from core.clean import clean_mesh
from core.topology import topology_summary
from core._clean import half_edge_ends
from core.simplify import simplify
from tests.mesh_factory import cad_cylinder, icosphere, regular_grid, star_glyphs, tetrahedron


def engine_state(V, F):
    """The engine's State of a clean mesh, as simplify sets it up (no
    crease or boundary planes, nothing locked)."""
    V = np.asarray(V, dtype=np.float64)
    F = np.asarray(F, dtype=np.int64).copy()
    n = V.shape[0]
    QT, _, N = vertex_face_quadrics(V, F, n, TUNING.area_power)
    Nref = np.zeros((n, 4))        # the summed area normals and their lengths
    for c in range(3):
        np.add.at(Nref, F[:, c], np.column_stack([N, np.linalg.norm(N, axis=1)]))
    twin = twin_table(F, n)
    return engine.State(V, F, twin, QT.T, np.zeros(n, dtype=bool), np.zeros(twin.size, dtype=bool), Nref)


def declared_lengths(st):
    n, m = st.V.shape[0], st.F.shape[0]
    size = {"vertex": n, "vertex_t": n, "face": m, "half_edge": 3 * m, "half_edge_t": 3 * m}
    for name in engine._declared():
        a = getattr(st, name)
        if a is None and engine._meta(name)["lazy"]:
            continue
        per = engine._per(name)
        assert (a.shape[1] if per.endswith("_t") else a.shape[0]) == size[per], name


def pool_of(st, tun=TUNING):
    """Every edge of a fresh state as the pass's pool (all recosted)."""
    e = engine._candidate_edges(st)
    engine._recost_cheapest(st, e, e.rep.size, None, True, tun)
    ci = np.flatnonzero(np.isfinite(e.cost) & ~e.stale)
    return engine._choose_pool(st, e, ci, ci.size, tun)


def test_every_declared_array_has_its_length_at_the_start_after_compaction_and_after_appending():
    V, F = icosphere(2)
    st = engine_state(V, F)
    declared_lengths(st)
    stopped, passes = engine.run(st, 40, None, True, None, F.shape[0], TUNING)
    assert stopped == "target" and st.F.shape[0] == 40 and passes > 0
    declared_lengths(st)                      # compact: every array follows the declarations
    assert st.alive.all() and not st.dead_v.any()
    assert np.array_equal(st.parent, np.arange(st.V.shape[0]))
    assert st.F.max() < st.V.shape[0]
    h = np.arange(st.twin.size)
    assert np.array_equal(st.twin[st.twin], h)   # twins pair up, none dangling
    engine.append_faces(st, st.F[:2, ::-1].copy(), st.forig[:2])
    declared_lengths(st)
    assert (st.twin[-6:] == BOUNDARY).all() and st.m_live == st.F.shape[0]


def test_priority_is_unique_cost_band_first_then_shorter_edges():
    rng = np.random.default_rng(0)
    P = 2000
    cost = rng.random(P)
    length2 = rng.random(P)
    a, b = rng.integers(0, 10_000, P), rng.integers(0, 10_000, P)
    key = engine._priority(cost, length2, a, b, TUNING)
    assert np.unique(key).size == P
    bits = int(P - 1).bit_length()
    assert np.array_equal(key & ((1 << bits) - 1), np.arange(P))   # the pool index comes back
    band = engine._bands(cost, TUNING.bands, TUNING.sample)
    lo, hi = np.argmin(cost), np.argmax(cost)
    assert band[lo] < band[hi] and key[lo] < key[hi]
    # equal costs: the shortest band goes first
    flat = engine._priority(np.zeros(P), length2, a, b, TUNING)
    assert flat[np.argmin(length2)] < flat[np.argmax(length2)]


def test_acceptance_bound_is_the_cost_bound_except_on_a_plateau():
    totals = np.array([1.0, 2.0, 3.0, 4.0, 5.0])
    assert engine._acceptance_bound(4.5, totals, TUNING) == 4.5
    assert engine._acceptance_bound(0.0, totals, TUNING) == 3.0          # the cheaper half
    assert engine._acceptance_bound(0.0, np.zeros(0), TUNING) == 0.0


def test_independent_picks_have_disjoint_stars_that_are_exactly_the_faces_around_both_ends():
    V, F = icosphere(3)
    st = engine_state(V, F)
    pool = pool_of(st)
    scratch = engine._scratch(st.V.shape[0], pool.key.size)
    sel, rest, star, kf, faces = engine._pick_independent(st, pool, np.arange(pool.key.size), None, TUNING,
                                                         scratch)
    def put_back():
        return all((a == engine._BIG).all() for a in scratch[:2]) and (scratch[2] == -1).all()

    assert put_back()                                            # put back for the next round
    again = engine._pick_independent(st, pool, rest, faces, TUNING, scratch)   # a smaller put-back
    assert again[0].size > 0 and put_back()
    assert sel.size > 0 and np.intersect1d(sel, rest).size == 0 and sel.size + rest.size == pool.key.size
    assert np.unique(star).size == star.size                     # disjoint
    for k in range(0, sel.size, max(1, sel.size // 25)):
        a, b = pool.A[sel[k]], pool.B[sel[k]]
        around = np.flatnonzero((st.F == a).any(axis=1) | (st.F == b).any(axis=1))
        assert np.array_equal(np.sort(star[kf == k]), around)
    # and the smallest key of all is always chosen
    assert np.argmin(pool.key) in sel


def test_whole_stars_are_the_faces_around_both_ends_in_ascending_order_even_where_they_overlap():
    V, F = icosphere(2)
    st = engine_state(V, F)
    pool = pool_of(st)
    star, kf = engine._whole_stars(st.F, np.arange(F.shape[0]), pool.A, pool.B)
    assert np.all(np.diff(kf) >= 0)
    for k in range(pool.key.size):
        a, b = pool.A[k], pool.B[k]
        around = np.flatnonzero((st.F == a).any(axis=1) | (st.F == b).any(axis=1))
        assert np.array_equal(star[kf == k], around)           # ascending, each face once


@pytest.mark.parametrize("bend", [None, np.cos(np.radians(100.0))])
def test_checking_ahead_gives_the_same_bits_as_checking_each_round_and_no_refused_edge_takes_a_round(
        bend, monkeypatch):
    V, F = icosphere(3)
    rng = np.random.default_rng(3)
    V = V * (1.0 + 0.6 * rng.random((V.shape[0], 1)))        # spiky: some collapses fail their checks
    st = engine_state(V, F)
    pool = pool_of(st)
    active = np.arange(pool.key.size)
    ahead = engine._CheckedAhead.of(st, pool, active, None, TUNING, True, bend)
    scratch = engine._scratch(st.V.shape[0], pool.key.size)
    sel, _, star, kf, _ = engine._pick_independent(st, pool, active, None, TUNING, scratch)
    now = engine._check(st, pool.A[sel], pool.B[sel], pool.XT[:, sel], pool.interior[sel], star, kf, TUNING,
                        True, bend)
    got = ahead.results(sel)
    assert not now.ok.all() and now.ok.any()
    for x, y in zip((got.ok, got.pen, got.wit, got.bent), (now.ok, now.pen, now.wit, now.bent)):
        assert np.array_equal(x, y)                            # bit for bit
    order_now, order_got = np.lexsort(now.rows[:2]), np.lexsort(got.rows[:2])
    for x, y in zip(got.rows, now.rows):
        assert np.array_equal(x[order_got], y[order_now])      # the same star rows
    # checked ahead, the edges found invalid are refused before the picks: no
    # round picks one (it would keep every valid collapse around it waiting)
    judged = []
    judge = engine._judge

    def spy(st, pool, sel, c, passes, tun):
        judged.append((tun.check_ahead, c.ok.copy()))
        return judge(st, pool, sel, c, passes, tun)
    monkeypatch.setattr(engine, "_judge", spy)
    for check_ahead in (0, 10**9):                             # never, always (careful passes only)
        st = engine_state(V, F)
        tun = replace(TUNING, check_ahead=check_ahead, bold_above=1e9)
        stop, _ = engine.run(st, 60, None, True, None, F.shape[0], tun, bend)
        live = st.F[st.alive]
        # (with the dihedral bound the spiky sphere stops above 60 faces, for that reason)
        assert (stop, live.shape[0] <= 60) in ((("target", True),) if bend is None else
                                               (("target", True), ("max_dihedral", False)))
        assert topology_summary(live, st.V.shape[0]).non_manifold_edges == 0
    never = np.concatenate([ok for ahead, ok in judged if ahead == 0])
    always = np.concatenate([ok for ahead, ok in judged if ahead > 0])
    assert not never.all() and always.all()


def test_a_partial_check_ahead_gives_the_same_bits_as_checking_each_round():
    # past Tuning.check_ahead_rows, the edges with big stars (a fan's spokes) are left
    # out of the check ahead and checked when picked: the picked edges' results, some
    # from the check ahead and some checked then, are the bits of checking them all
    Vs, Fs = star_glyphs(count=1, spikes=50)
    Vi, Fi = icosphere(2)
    V = np.vstack([Vs, Vi + [5.0, 0.0, 0.0]])
    F = np.vstack([Fs, Fi + Vs.shape[0]])
    V = V * (1.0 + 0.3 * np.random.default_rng(5).random((V.shape[0], 1)))   # some refusals
    st = engine_state(V, F)
    pool = pool_of(st)
    active = np.arange(pool.key.size)
    faces_at = np.bincount(st.F.ravel(), minlength=st.V.shape[0])
    around = faces_at[pool.A] + faces_at[pool.B]
    big = around >= TUNING.hold_star
    assert big.any() and not big.all()
    tun = replace(TUNING, check_ahead_rows=0)
    first = engine._ahead_of(active, around, tun)
    assert np.array_equal(first, active[~big])
    assert np.array_equal(engine._ahead_of(active, around, TUNING), active)
    ahead = engine._CheckedAhead.of(st, pool, first, None, tun, True, None, partial=True)
    scratch = engine._scratch(st.V.shape[0], pool.key.size)
    sel, _, star, kf, _ = engine._pick_independent(st, pool, active, None, tun, scratch)
    assert big[sel].any() and not big[sel].all()
    got = engine._checked(st, pool, sel, star, kf, ahead, tun, True, None)
    now = engine._check(st, pool.A[sel], pool.B[sel], pool.XT[:, sel], pool.interior[sel], star,
                        kf, tun, True, None, quick=False)
    assert not now.ok.all() and now.ok.any()
    for x, y in zip((got.ok, got.pen, got.wit, got.bent, got.flip),
                    (now.ok, now.pen, now.wit, now.bent, now.flip)):
        assert np.array_equal(x, y)                            # bit for bit
    assert np.all(np.diff(got.rows[1]) >= 0)                   # rows by collapse
    order_now, order_got = np.lexsort(now.rows[:2]), np.lexsort(got.rows[:2])
    for x, y in zip(got.rows, now.rows):
        assert np.array_equal(x[order_got], y[order_now])      # the same star rows
    # the edges it did not check are kept for their picks
    assert np.array_equal(engine._drop_invalid(st, pool, ahead, active[big], 1), active[big])


def test_link_condition_refuses_the_last_tetrahedron_and_allows_a_sphere():
    V, F = tetrahedron()
    st = engine_state(V, F)
    pool = pool_of(st)
    sel, _, star, kf, _ = engine._pick_independent(st, pool, np.arange(pool.key.size), None, TUNING,
                                                         engine._scratch(st.V.shape[0], pool.key.size))
    s = engine._star_of(st.F, pool.A[sel], pool.B[sel], star, kf)
    assert not engine._link_condition(st, s, pool.interior[sel]).any()
    V, F = icosphere(2)
    st = engine_state(V, F)
    pool = pool_of(st)
    sel, _, star, kf, _ = engine._pick_independent(st, pool, np.arange(pool.key.size), None, TUNING,
                                                         engine._scratch(st.V.shape[0], pool.key.size))
    s = engine._star_of(st.F, pool.A[sel], pool.B[sel], star, kf)
    assert engine._link_condition(st, s, pool.interior[sel]).all()


def test_link_condition_refuses_an_edge_between_two_borders():
    # a strip one face wide: every interior edge joins two border vertices, and
    # a border edge whose faces have both other edges on the border is an ear
    V, F = regular_grid(6, 1)
    st = engine_state(V, F)
    e = engine._candidate_edges(st)
    engine._recost_cheapest(st, e, e.rep.size, None, True, TUNING)
    interior = st.twin[e.rep] >= 0
    # the recost marks interior edges between two border vertices invalid
    assert np.isinf(e.cost[interior]).all()


def test_trim_keeps_the_cheapest_collapses_the_target_needs():
    V, F = icosphere(2)
    st = engine_state(V, F)
    pool = pool_of(st)
    acc, touched = engine._check_rounds(st, pool, 1, False, None, TUNING)
    m = st.F.shape[0]
    need = 10
    kept = engine._trim_to_target(pool, acc, m, m - need)
    removed = np.where(pool.interior[kept.idx], 2, 1).sum()
    assert need <= removed <= need + 1
    assert pool.cost[kept.idx].max() <= np.sort(pool.cost[acc.idx])[kept.idx.size - 1]
    assert engine._trim_to_target(pool, acc, m, None) is acc
    assert touched[pool.A[acc.idx]].all() and touched[pool.B[acc.idx]].all()


def test_compaction_renumbers_faces_and_survivors():
    V, F = icosphere(2)
    st = engine_state(V, F)
    pool = pool_of(st)
    acc, _ = engine._check_rounds(st, pool, 1, False, None, TUNING)
    i = acc.idx
    A, B = pool.A[i], pool.B[i]
    engine._apply(st, A, B, pool.XT[:, i], acc.rows)
    before = engine.survivors(st)
    assert np.array_equal(before[B], A)                 # the removed ends follow their survivors
    pos = st.V[before].copy()
    engine.compact(st)
    declared_lengths(st)
    after = st.cur_of_clean
    assert np.array_equal(st.V[after], pos)             # same positions, new numbering
    assert st.F.shape[0] == F.shape[0] - 2 * int(pool.interior[i].sum())


@pytest.mark.parametrize("k", [1, 1000, 200_000])
def test_sampled_kth_smallest_is_never_far_below(k):
    x = np.random.default_rng(1).random(1_000_000)
    v = engine._kth_smallest(x, k, TUNING.sample)
    rank = int(np.count_nonzero(x < v))
    assert k - 5 * np.sqrt(k + 1) <= rank <= k + 0.005 * x.size


def star_around(st, a, b):
    """Every live face around ``a`` or ``b``, ascending."""
    return np.flatnonzero(st.alive & ((st.F == a).any(axis=1) | (st.F == b).any(axis=1)))


def test_a_bold_pass_is_its_collapses_applied_one_at_a_time_each_valid_on_the_mesh_as_it_is(monkeypatch):
    # a bold pass applies round after round; later rounds take collapses next to
    # earlier ones. Replayed one collapse at a time, each checked alone on the mesh
    # as the collapses before it left it, every one is valid and the meshes agree.
    V, F = icosphere(4)
    rng = np.random.default_rng(5)
    V = V * (1.0 + 0.05 * rng.random((V.shape[0], 1)))        # bumpy: costs differ, some checks fail
    st = engine_state(V, F)
    pool = pool_of(st, replace(TUNING, pool_share=TUNING.bold_pool_share))
    rounds = []
    real = engine._apply_accepted
    monkeypatch.setattr(engine, "_apply_accepted",
                        lambda st_, pool_, acc, p: (rounds.append(acc.idx.copy()), real(st_, pool_, acc, p)))
    done = engine._bold_rounds(st, pool, 1, False, None, TUNING, None)
    assert done == sum(r.size for r in rounds) and len(rounds) >= 3
    merged = np.concatenate([np.concatenate([pool.A[r], pool.B[r]]) for r in rounds])
    assert np.unique(merged).size == merged.size                 # an end merges once per pass
    ref = engine_state(V, F)
    next_to_earlier = 0
    for i, r in enumerate(rounds):
        earlier = pool.A[np.concatenate(rounds[:i])] if i else np.zeros(0, dtype=np.int64)
        for k in r:
            star = star_around(ref, pool.A[k], pool.B[k])
            next_to_earlier += bool(np.isin(ref.F[star], earlier).any())
            c = engine._check(ref, pool.A[[k]], pool.B[[k]], pool.XT[:, [k]], pool.interior[[k]], star,
                              np.zeros(star.size, dtype=np.int64), TUNING, False)
            assert c.ok[0]
            engine._apply(ref, pool.A[[k]], pool.B[[k]], pool.XT[:, [k]], c.rows)
    assert np.array_equal(ref.alive, st.alive) and np.array_equal(ref.F[ref.alive], st.F[st.alive])
    assert np.array_equal(ref.V, st.V) and np.array_equal(ref.twin, st.twin)
    assert next_to_earlier > 0.1 * sum(r.size for r in rounds[1:])   # the pass went where a careful one stops


def test_a_bold_pass_ends_after_a_round_under_its_share_of_the_first(monkeypatch):
    # Tuning.bold_round_share: every round but the last took at least that share of
    # the first round's collapses; the last is the first under it (or round
    # bold_rounds, or no edge left). Without the share the same pass runs longer.
    V, F = icosphere(4)
    V = V * (1.0 + 0.05 * np.random.default_rng(5).random((V.shape[0], 1)))
    real = engine._apply_accepted
    counts = {}
    for share in (0.0, 0.5):
        st = engine_state(V, F)
        tun = replace(TUNING, bold_round_share=share)
        pool = pool_of(st, replace(tun, pool_share=tun.bold_pool_share))
        took = counts[share] = []
        monkeypatch.setattr(engine, "_apply_accepted",
                            lambda st_, pool_, acc, p, took=took: (took.append(acc.idx.size),
                                                               real(st_, pool_, acc, p)))
        assert engine._bold_rounds(st, pool, 1, False, None, tun, None) == sum(took)
        assert all(t >= share * took[0] for t in took[:-1])
    half = counts[0.5]
    assert half[-1] < 0.5 * half[0] and len(half) < TUNING.bold_rounds
    assert len(counts[0.0]) > len(half) and counts[0.0][:len(half)] == half


def test_holes_are_capped_shortest_first_and_the_mesh_stays_closed_and_manifold():
    # a sphere with a wide hole and a small one: the small rim is capped first
    V, F = icosphere(3)
    C = V[F].mean(axis=1)
    c = clean_mesh(V, F[(C[:, 2] < 0.7) & ~((C[:, 0] > 0.93) & (np.abs(C[:, 2]) < 0.2))])
    st = engine_state(c.V, c.F)
    before = topology_summary(st.F, st.V.shape[0])
    assert before.boundary_loops == 2
    added = close_smallest_hole(st, TUNING)
    after = topology_summary(st.F, st.V.shape[0])
    assert added > 0 and after.boundary_loops == 1
    assert after.boundary_edges > before.boundary_edges - after.boundary_edges   # the wide rim is left
    assert close_smallest_hole(st, TUNING) > 0
    closed = topology_summary(st.F, st.V.shape[0])
    assert (closed.boundary_loops, closed.euler, closed.non_manifold_edges) == (0, 2, 0)
    h = np.arange(st.twin.size)
    assert np.array_equal(st.twin[st.twin], h)               # every half-edge has its twin


def test_pool_size_after_hundreds_of_slow_passes():
    """Each slow pass multiplies the goal bound's growth by pool_growth: after
    about 512 of them (12 extruded star-shaped glyphs, whose cheapest edges
    are fan spokes that would fold) it is inf, and the pool size was
    int(inf): OverflowError out of simplify. Now the share of the candidates
    bounds it, as any growth past it does."""
    ne, m, target = 5000, 19200, 500
    share = int(np.ceil(TUNING.pool_share * ne))
    for grow in (TUNING.pool_growth ** 40, 1e300, np.inf):
        assert engine._pool_size(ne, m, target, TUNING, grow=grow) == share
    # the goal bound as before where it binds
    assert engine._pool_size(ne, m, m - 10, TUNING) == int(np.ceil(TUNING.pool_goal_factor * 5)) + 1


def test_a_stalled_run_widens_its_pool_past_the_grace():
    """Careful passes in a row that accepted nothing double the pool's share
    past ``Tuning.stall_grace`` (up to every candidate): a stuck run refused a
    fifth of its candidates a pass, and a messy homer took 10,370 passes."""
    ne, m = 3384, 3300
    base = int(np.ceil(TUNING.pool_share * ne))
    sizes = [engine._pool_size(ne, m, None, TUNING, stalled=k) for k in range(8)]
    g = TUNING.stall_grace
    assert sizes[:g + 1] == [base] * (g + 1)
    assert sizes[g + 1] == int(np.ceil(2 * TUNING.pool_share * ne))
    assert sizes[g + 2] == int(np.ceil(4 * TUNING.pool_share * ne)) and sizes[-1] == ne
    # the goal bound still caps it near a target
    assert engine._pool_size(ne, m, m - 10, TUNING, stalled=6) == \
        int(np.ceil(TUNING.pool_goal_factor * 5)) + 1


@pytest.mark.parametrize("grace", [2, 10**6])
def test_a_stuck_rocker_arm_with_sheets_and_pinholes_takes_fewer_passes(grace):
    # the rocker-arm with nine double-sided sheets and 10% pinholes asked for 4 faces
    # (preserve_topology off) stops short; with the pool widened past the grace it takes
    # 75 passes, 146 without (the same cage size)
    from tests.mesh_factory import load_shared, with_pinholes, with_sheets
    V, F = with_pinholes(*with_sheets(*load_shared("rocker-arm.obj"), k=9, seed=51), share=0.1,
                         seed=53)
    r = simplify(V, F, target_faces=4, preserve_topology=False,
                 tuning=replace(TUNING, stall_grace=grace))
    assert r.stopped_because == "no_valid_collapse" and r.F.shape[0] > 4
    assert (r.n_passes < 100) == (grace == 2)


def checked_whole_invalid(st, hs):
    """Check the collapses of the remembered edges ``hs`` (representative
    half-edges) whole on the mesh as it is, at their cached places, assert
    that none is valid, and return the collapse of each star row."""
    u, w = half_edge_ends(st.F, hs)
    A, B = np.where(st.swap[hs], w, u), np.where(st.swap[hs], u, w)
    star, kf = engine._whole_stars(st.F, np.flatnonzero(st.alive), A, B)
    c = engine._check(st, A, B, st.c_x[:, hs], st.twin[hs] >= 0, star, kf, TUNING)
    assert not c.ok.any()
    return kf


def test_a_held_refusal_would_be_refused_again_and_a_fans_spokes_are_held(monkeypatch):
    # _still_flips keeps a big star's refusal while one of the faces it flipped and
    # its ends are unchanged: checked again on the mesh as it is, every held
    # collapse is still invalid (the same place, the same face turned over).
    V, F = star_glyphs(count=1, spikes=100)
    real = engine._still_flips
    held = []

    def spy(st, h, U, W, since):
        out = real(st, h, U, W, since)
        hs = h[out]
        if hs.size:
            kf = checked_whole_invalid(st, hs)
            held.append(int(np.median(np.bincount(kf, minlength=hs.size))))
        return out

    monkeypatch.setattr(engine, "_still_flips", spy)
    res = simplify(V, F, target_faces=40)
    assert res.F.shape[0] == 40
    assert len(held) > 5 and max(held) > 100          # the hubs' spokes, pass after pass


def test_a_held_sliver_refusal_would_be_refused_again_and_a_caps_spokes_are_held(monkeypatch):
    # _still_slivers keeps the refusal of a cap's spoke while the sliver it makes,
    # its ends and the faces around them are unchanged: checked again whole on the
    # mesh as it is, every held collapse is still invalid, and the spokes are held
    # pass after pass (not sampled again after each collapse on the rim)
    V, F = cad_cylinder(500, height=1.0)
    real = engine._still_slivers
    held = []

    def spy(st, h, U, W, since, already):
        out = real(st, h, U, W, since, already)
        hs = h[out]
        if hs.size:
            checked_whole_invalid(st, hs)
            held.append(hs.size)
        return out

    monkeypatch.setattr(engine, "_still_slivers", spy)
    res = simplify(V, F, target_faces=200)
    t = topology_summary(res.F, res.V.shape[0])
    assert res.F.shape[0] == 200 and t.euler == 2 and t.boundary_edges == 0
    assert t.non_manifold_edges == 0 and t.non_manifold_vertices == 0
    assert len(held) > 5 and max(held) > 100


def dropped_before_the_picks(V, F):
    """A fresh engine state of ``(V, F)``, its first pool, and the pool
    edges :func:`_drop_quick_refusals` refuses on their samples (every pool
    edge active, in pass 1)."""
    st = engine_state(V, F)
    pool = pool_of(st)
    active = np.arange(pool.key.size)
    faces_at = np.bincount(st.F.ravel(), minlength=st.V.shape[0])
    kept = engine._drop_quick_refusals(st, pool, active, 1, TUNING,
                                       faces_at[pool.A] + faces_at[pool.B])
    return st, pool, np.setdiff1d(active, kept)


def test_a_sliver_witness_is_a_face_the_collapse_makes_that_thin():
    # the face remembered with a sliver refusal, its corner moved to the collapse's
    # place, has exactly the compactness remembered, below the sliver bound
    V, F = cad_cylinder(500, height=1.0)
    st, pool, gone = dropped_before_the_picks(V, F)
    h = pool.h[gone]
    face = st.blk_sliver[h]
    assert (face >= 0).sum() >= 1000                     # the caps' spokes
    for k in np.flatnonzero(face >= 0)[::97]:
        e = gone[k]
        T = st.V[st.F[face[k]]].copy()
        T[np.isin(st.F[face[k]], [pool.A[e], pool.B[e]])] = pool.XT[:, e]
        after = compactness_of(T, np.array([[0, 1, 2]]))[0]
        assert after == st.blk_sliver_c[h[k]] and after < TUNING.gamma_hard


def test_compaction_renumbers_the_remembered_flipped_faces_and_forgets_removed_ones():
    V, F = icosphere(2)
    st = engine_state(V, F)
    assert st.blk_face is None                                     # made on first use
    engine._rows_of(st, "blk_face")[:, 0:3] = [[0, 5, -1], [7, 3, 9], [1, 2, 6]]     # face 0's half-edges
    st.blk_face[:, 6:9] = 5                                        # face 2's
    engine._rows_of(st, "blk_sliver")[0:3] = [2, 1, 5]             # (and the slivers')
    st.alive[[1, 5]] = False                                       # faces 1 and 5 go
    engine.compact(st)
    assert st.blk_face[:, 0:3].tolist() == [[0, -1, -1], [5, 2, 7], [-1, 1, 4]]
    assert (st.blk_face[:, 3:6] == -1).all()                       # face 2 is face 1 now
    assert st.blk_sliver[0:3].tolist() == [1, -1, -1]             # face 2 is face 1 now
    declared_lengths(st)


def half_edge_of(F, a, b):
    """A half-edge of the edge (a, b) of the faces ``F``."""
    U, W = half_edge_ends(F)
    return int(np.flatnonzero(((U == a) & (W == b)) | ((U == b) & (W == a)))[0])


def compactness_of(V, F):
    """Each face's compactness, as the engine measures it."""
    P = V[F]
    N = np.cross(P[:, 1] - P[:, 0], P[:, 2] - P[:, 0])
    sq = sum(((P[:, (c + 1) % 3] - P[:, c]) ** 2).sum(axis=1) for c in range(3))
    return engine.compactness(np.linalg.norm(N, axis=1), sq)


def test_sampled_stars_are_faces_around_the_ends_evenly_spread_and_all_of_a_small_one():
    V, F = star_glyphs(count=1, spikes=50)              # hubs of 100 faces
    st = engine_state(V, F)
    hub, rim = 2 * 100, np.array([0, 1, 7])
    A, B = np.full(3, hub), rim
    star, kf = engine._sampled_stars(st, A, B, 16)
    for k in range(3):
        mine = star[kf == k]
        around = (st.F[mine] == A[k]).any(axis=1) | (st.F[mine] == B[k]).any(axis=1)
        assert around.all()
        of_hub = np.flatnonzero((st.F == hub).any(axis=1))
        hub_rows = mine[(st.F[mine] == hub).any(axis=1)]
        assert 16 <= np.unique(hub_rows).size <= 19 and np.ptp(hub_rows) > 0.8 * np.ptp(of_hub)   # (+ the rim's)
        of_rim = np.flatnonzero((st.F == B[k]).any(axis=1))
        assert set(of_rim) <= set(mine)                  # the rim vertex's few faces: every one


def test_sliver_samples_are_near_the_edge_and_the_least_compact_around_the_ends():
    V, F = star_glyphs(count=1, spikes=50)              # hubs of 100 faces
    st = engine_state(V, F)
    hub, rim = 2 * 100, np.array([0, 1, 7])
    A, B = np.full(3, hub), rim
    h = np.array([half_edge_of(st.F, hub, r) for r in rim])
    star, kf, least = engine._sliver_samples(st, h, A, B, 16)
    g = compactness_of(V, F)
    of_hub = np.flatnonzero((st.F == hub).any(axis=1))
    for k in range(3):
        mine = star[kf == k]
        around = (st.F[mine] == A[k]).any(axis=1) | (st.F[mine] == B[k]).any(axis=1)
        assert around.all()
        # the hub's faces within 8 steps of the edge's either way (the fan's order is
        # its faces' order: face i of the cap holds rim vertices i and i + 1)
        c = int(np.flatnonzero(of_hub == h[k] // 3)[0])
        assert set(of_hub[(c + np.arange(-9, 10)) % of_hub.size]) <= set(mine)
        for v in (hub, B[k]):                            # and the 4 least compact around each end
            at = np.flatnonzero((st.F == v).any(axis=1))
            assert set(at[np.argsort(g[at], kind="stable")[:4]]) <= set(mine)
    # the least compactness around each end, as the whole check measures it
    for i, v in enumerate(np.concatenate([A, B])):
        assert least[i] == g[(st.F == v).any(axis=1)].min()


def test_least_compactness_is_the_sorted_listings_least_with_no_sort():
    # the remembered sliver refusals ask only for the least compact face around each
    # end: the same values, bit for bit, as the sorted listing's, 1 around a vertex
    # with no live face (a collapsed one's), and for ends given twice
    V, F = star_glyphs(count=2, spikes=30)
    st = engine_state(V, F)
    rng = np.random.default_rng(3)
    st.alive[rng.choice(F.shape[0], 20, replace=False)] = False
    lonely = 5
    st.alive[(st.F == lonely).any(axis=1)] = False
    A = np.concatenate([rng.integers(0, V.shape[0], 40), [lonely, 60, 60]])
    B = np.concatenate([rng.integers(0, V.shape[0], 40), [60, lonely, 60]])
    least = engine._least_compactness(st, A, B)
    assert least.tobytes() == engine._least_compact_around(st, A, B, 0).least.tobytes()
    g = compactness_of(V, F)
    for i, v in enumerate(np.concatenate([A, B])):
        at = st.alive & (st.F == v).any(axis=1)
        assert least[i] == (g[at].min() if at.any() else 1.0)


def test_sliver_refusals_on_a_sample_are_refusals_of_the_whole_check():
    # a CAD cylinder as tall as it is wide: its spokes cost nothing (the caps are flat)
    # and each makes a sliver beside the rim vertex it merges into. Refused on a sample
    # before the picks, they are refused by the whole check too (the run took 197
    # passes to 200 faces, one spoke a round; 35 now)
    V, F = cad_cylinder(500, height=1.0)
    st, pool, gone = dropped_before_the_picks(V, F)
    spokes = np.flatnonzero(np.isin(pool.A, [1000, 1001]) | np.isin(pool.B, [1000, 1001]))
    assert set(spokes) <= set(gone)                      # every spoke of both caps
    star, kf = engine._whole_stars(st.F, np.arange(st.F.shape[0]), pool.A[gone], pool.B[gone])
    c = engine._check_blocks(st, pool.A[gone], pool.B[gone], pool.XT[:, gone],
                             pool.interior[gone], star, kf, TUNING, True, None)
    assert not c.ok.any()
    res = simplify(V, F, target_faces=200)
    assert res.F.shape[0] == 200 and res.n_passes <= 50


def test_fan_slivers_are_found_next_to_the_edge_and_refused_by_the_whole_check_too():
    # the spokes of a CAD cylinder's caps (each end of one has more than sliver_star
    # faces around it) are refused on the four faces next to each spoke alone: every
    # spoke of both caps, each refusal one the whole check makes, its sliver face
    # remembered; the other pool edges are left to the sampled and whole checks
    V, F = cad_cylinder(500, height=1.0)
    st = engine_state(V, F)
    pool = pool_of(st)
    active = np.arange(pool.key.size)
    faces_at = np.bincount(st.F.ravel(), minlength=st.V.shape[0])
    around = faces_at[pool.A] + faces_at[pool.B]
    kept = engine._drop_fan_slivers(st, pool, active, 1, TUNING, around)
    gone = np.setdiff1d(active, kept)
    spokes = np.flatnonzero(np.isin(pool.A, [1000, 1001]) | np.isin(pool.B, [1000, 1001]))
    assert set(spokes) == set(gone) and spokes.size >= TUNING.fan_slivers_min
    assert set(kept) == set(np.flatnonzero(around < TUNING.sliver_star))
    star, kf = engine._whole_stars(st.F, np.arange(st.F.shape[0]), pool.A[gone], pool.B[gone])
    c = engine._check_blocks(st, pool.A[gone], pool.B[gone], pool.XT[:, gone],
                             pool.interior[gone], star, kf, TUNING, True, None)
    assert not c.ok.any()
    assert np.isinf(st.c_blk[pool.h[gone]]).all() and (st.blk_sliver[pool.h[gone]] >= 0).all()
    # fewer such collapses than fan_slivers_min: left to the sample
    few = replace(TUNING, fan_slivers_min=spokes.size + 1)
    st = engine_state(V, F)
    assert engine._drop_fan_slivers(st, pool_of(st), active, 1, few, around).size == active.size


def test_the_fan_sliver_test_stops_where_it_refuses_too_few(monkeypatch):
    # a star glyph's spokes fold faces away from their edge and make no sliver next to
    # it: the test refuses fewer than fan_slivers_share of them, and the run stops
    # making it (the next call tests nothing); a cylinder's caps keep it on
    V, F = star_glyphs(count=3, spikes=200)
    st = engine_state(V, F)
    pool = pool_of(st)
    active = np.arange(pool.key.size)
    faces_at = np.bincount(st.F.ravel(), minlength=st.V.shape[0])
    around = faces_at[pool.A] + faces_at[pool.B]
    assert (around >= TUNING.sliver_star).sum() >= TUNING.fan_slivers_min
    kept = engine._drop_fan_slivers(st, pool, active, 1, TUNING, around)
    assert kept.size > (1 - TUNING.fan_slivers_share) * active.size and not st.fan_slivers
    calls = []
    real = engine._fans_near
    monkeypatch.setattr(engine, "_fans_near", lambda *a: calls.append(1) or real(*a))
    assert engine._drop_fan_slivers(st, pool, kept, 2, TUNING, around[kept]).size == kept.size
    assert not calls
    V, F = cad_cylinder(500, height=1.0)
    st = engine_state(V, F)
    pool = pool_of(st)
    faces_at = np.bincount(st.F.ravel(), minlength=st.V.shape[0])
    engine._drop_fan_slivers(st, pool, np.arange(pool.key.size), 1, TUNING,
                             faces_at[pool.A] + faces_at[pool.B])
    assert st.fan_slivers


def test_quick_refusals_are_refusals_of_the_whole_check():
    # a fan's spokes refused on a sample of the fan are refused by the whole check
    V, F = star_glyphs(count=1, spikes=100)
    st, pool, gone = dropped_before_the_picks(V, F)
    assert gone.size > 300                               # most of the 400 spokes
    star, kf = engine._whole_stars(st.F, np.arange(st.F.shape[0]), pool.A[gone], pool.B[gone])
    c = engine._check_blocks(st, pool.A[gone], pool.B[gone], pool.XT[:, gone], pool.interior[gone], star, kf,
                             TUNING, True, None)
    assert not c.ok.any()
    assert np.isinf(st.c_blk[pool.h[gone]]).all() and (st.blk_face[:, pool.h[gone]] >= 0).all()
