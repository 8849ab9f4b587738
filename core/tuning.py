"""The constants of the simplification engine (:class:`Tuning`)."""

from dataclasses import dataclass


@dataclass(frozen=True)
class Tuning:
    """Every constant of :func:`core.simplify.simplify` in one place (all
    unit-free). An advanced argument: ``simplify(..., tuning=Tuning(...))``
    (``dataclasses.replace(TUNING, pool_share=0.3)``); the defaults are the
    measured best over the shared meshes (``scripts/bench_simplify.py``)."""

    area_power: float = 0.5          #: face plane weight = area^p * mean area^(1-p)
    boundary_weight: float = 100.0   #: boundary plane weight, times the edge length squared
    feature_weight: float = 3.0      #: crease plane weight, times the edge length squared
    pool_share: float = 0.2          #: at most this share of the candidate edges per pass
    pool_goal_factor: float = 4.0    #: ... and at most this many times the collapses still needed
    #: ... doubled for each careful pass in a row past this many that accepted nothing
    #: (a stuck run refused a fifth of its candidates a pass: see ``_collapse._pool_size``)
    stall_grace: int = 2
    #: a pass that removed less than this share of the faces still needed lets the next
    #: pass's goal bound grow by pool_growth (again after each such pass): near the
    #: target, where most of a small pool is refused, the tail takes a few passes, not dozens
    slow_pass_share: float = 0.25
    pool_growth: float = 4.0
    max_rounds: int = 16             #: selection rounds per pass
    #: a pass on a mesh of more than this many times the target faces is bold: each
    #: selection round is applied before the next, and later rounds may take collapses
    #: next to earlier ones (only the endpoints of applied collapses wait for the next
    #: pass); closer to the target a pass is careful: every collapse's one-ring waits
    bold_above: float = 4.0
    #: ... times at least this many faces: the last few hundred faces of any run go in
    #: careful passes (bold ones there save a few ms, and a less even mesh near a small
    #: target more often leaves only collapses that would fold a face)
    bold_min_target: int = 64
    bold_pool_share: float = 0.35    #: pool_share of a bold pass
    bold_rounds: int = 16            #: selection rounds of a bold pass
    #: a bold pass ends after a round that took fewer than this share of its first
    #: round's collapses (its last rounds took a few each, at the cost of a whole round:
    #: 1M -> 10k in 17 passes instead of 19, the 23 shared cases' geomeans 0.720 / 0.786
    #: -> 0.718 / 0.776, the small-mesh section 5% less CPU)
    bold_round_share: float = 0.125
    #: a bold pass that removed less than this share of the faces makes the rest of the
    #: run careful (on CAD meshes most cheap collapses of a bold round are refused, and
    #: its 16 rounds then cost several careful passes that remove more)
    bold_min_share: float = 0.1
    #: a bold round applies its collapses beside the next round's pick (on two threads)
    #: only with at least this many pool edges left, and compaction spreads its arrays
    #: over the threads only with at least this many faces; below, the hand-offs cost more
    threads_min_edges: int = 20000
    #: once at most this many pool edges are left in a pass, check them all at once
    #: (far fewer small checks; the same check results, but the invalid edges are then
    #: dropped before the picks instead of each taking a round, so the picks, and the
    #: cage, depend on this value: flat grid 100x100 -> 2,000 faces gives four different
    #: cages for 0, 1,024, 4,096 and unbounded)
    check_ahead: int = 1024
    #: ... unless their stars hold more faces than this: then those with big stars (see
    #: hold_star) are checked when picked (a 10k-face cylinder's fan caps: 780 spokes of
    #: 1,400 faces each, checked ahead pass after pass)
    check_ahead_rows: int = 1 << 16
    #: a collapse refused for flipping faces, with at least this many faces around its
    #: ends (a fan's hub), stays refused while one of three of those faces and the ends
    #: are unchanged, instead of being checked again after any change around it (12
    #: extruded star glyphs of 400-face fans, to 500 faces: 1,446 -> 175 passes)
    hold_star: int = 24
    #: ... and such a collapse is first checked on about this many faces around each end
    #: (evenly spread): one turned over refuses it (12 glyphs: 165 -> 100 passes)
    hold_sample: int = 16
    #: ... and from this many faces around its ends a collapse is also refused when it
    #: makes one of the sample's faces a sliver, the sample then holding the faces near the
    #: edge and the least compact ones too (a CAD cap's spokes, each refused for the sliver
    #: it makes beside the rim vertex it merges into: a 10k-face cylinder as tall as wide
    #: took 197 passes to 200 faces, now 35; below, the extra faces cost more than they
    #: save: fandisk's careful passes 7% slower at 24)
    sliver_star: int = 96
    #: ... and from this many such collapses in a pass, each is first tested on the four
    #: faces next to its edge alone (a fan's spokes: most are refused there, for a
    #: fraction of the sample's cost)
    fan_slivers_min: int = 64
    #: ... while that test refuses at least this share of those it tests
    fan_slivers_share: float = 0.25
    face_cache_share: float = 0.75   #: a round re-packs the faces in play below this share
    bands: int = 8                   #: cost bands of the pool (then length bands, then random)
    length_bands: int = 16           #: length bands inside a cost band (shorter edges first)
    #: a pool whose cost bound is below this share of the median total (cost + penalties)
    #: of its valid collapses is a plateau: the cheaper half by total is accepted
    plateau_share: float = 0.01
    flip_cos: float = 0.0            #: reject if a face normal turns by more than acos(flip_cos)
    #: ... or ends farther than acos(ref_cos) from the summed normals of the input it
    #: stands for (-1: off; 0, i.e. 90 degrees, keeps rough scans collapsing; stricter stalls them)
    ref_cos: float = 0.0
    #: ... where the input normals it stands for agree on a side: their sum at least this
    #: share of the sum of their lengths (0: everywhere) ...
    ref_agree: float = 0.0
    #: ... and this share once a run finds no valid collapse short of its target: a thin
    #: plate's rim, its two sides merged, has no side, and holding it there stopped flattened
    #: scans (z x 1e-2, 1e-3) at 2-4x a 50-face target; everywhere from the start, thin parts
    #: of ordinary meshes folded sooner (cow 10%: Hausdorff +38%)
    ref_agree_stuck: float = 0.25
    gamma_hard: float = 0.02         #: reject new triangles less compact than this (and than before)
    gamma_soft: float = 0.3          #: penalise new triangles less compact than this
    compact_weight: float = 1e-5     #: penalty scale: star area * edge length^2 * (1 - g/g_soft)^2
    #: Hausdorff-aware penalty: weight * merged area * (distance of the farther merged
    #: vertex's witness -- its input point farthest from the surface so far -- to the new faces)^2
    haus_weight: float = 0.45
    haus_phase: float = 4.0          #: ... only once the mesh has at most this many times the target faces
    #: a run to a face count takes no collapse whose RMS distance is above this many times
    #: the edge of the target's mean triangle while others in its pass's pool are within it
    #: (0: off; see ``_collapse._collapse_reach``: 1.0 changed the beetle at 2% of its faces,
    #: 0.166 -> 0.187 of Decimate's Hausdorff distance; 2.0 none of the 23 quality cases)
    collapse_reach: float = 2.0
    relocate_iters: int = 2          #: final relocation rounds towards the input (0: off)
    #: inputs up to this many faces also get the backward pull (cage towards the input
    #: surface, which needs an index of the whole input) ...
    relocate_back_max_faces: int = 50000
    relocate_back: float = 0.3       #: ... with this weight (cage area against the input points)
    relocate_back_iters: int = 4     #: ... and this many rounds
    relocate_border_weight: float = 1.0  #: weight of each input border point (a surface sample: 1)
    relocate_samples: int = 20000    #: input vertices as relocation targets: this many ...
    relocate_per_vertex: int = 4     #: ... or this many per cage vertex, whichever is more
    relocate_max_per_vertex: int = 100  #: ... but at most this many per cage vertex (0: no cap)
    relocate_reg: float = 1.0        #: pull of each vertex to its place, relative to its samples
    relocate_max_faces: int = 200000  #: ... only for cages up to this size
    relocate_max_share: float = 0.5  #: ... and at most this share of the input's faces
    relocate_cg_iters: int = 15      #: conjugate-gradient steps per relocation round
    relocate_min_cos: float = 0.2    #: a relocated face turning by more than acos(this) is undone
    #: the relocation stops once a round moves no vertex by more than this share of an edge
    #: (fandisk to 2,000 faces made four rounds of 0.1-0.04% of an edge: 63 -> 34 ms at
    #: 1e-3 for 1e-4; the 23 harness cases' geomeans 0.720 / 0.787 -> 0.720 / 0.786)
    relocate_min_move: float = 1e-3
    #: its closest-point searches walk over the meshes from where the engine merged each
    #: input vertex (then from the last round's answers), at most this many steps a round
    relocate_walk_steps: int = 8
    #: then the cage's farthest places from the input are touched up (:mod:`._touch_up`:
    #: a vertex moved onto the input, an edge flipped, where that lowers the largest
    #: distance around it), for inputs that get the backward pull: at most this many
    #: rounds (0: off) ...
    touch_rounds: int = 3
    #: ... each trying this many of the cage vertices farthest from the input, of the
    #: cage faces farthest from it (flips of their edges, pulls of their corners) and of
    #: the faces nearest the input vertices farthest from the cage (flips); 4 gave the
    #: same geomeans and a jittered rocker-arm at 1.37 of Decimate's Hausdorff distance
    touch_candidates: int = 8
    #: ... among those at least this share of the cage's largest distance (the others'
    #: moves onto the input cost more in mean distance than they save in the largest)
    touch_share: float = 0.9
    #: ... keeping a change only where the largest distance around it falls below this
    #: share of what it was (the 23 quality cases, before the far faces' flips: 1.0 gave
    #: mean / Hausdorff geomeans 0.733 / 0.748, 0.98 0.731 / 0.750, 0.95 0.727 / 0.755)
    touch_gain: float = 0.98
    #: ... and not at all where the cage is nowhere farther from the input than this share
    #: of the diagonal (10 um on a 1 m part): a flat fan of 2,000 needles to 1,000 faces,
    #: 1.8e-6 of the diagonal off, spent 2.4 of 2.6 s trying to lower that
    touch_floor: float = 1e-5
    #: a cage whose every collapse had an error of at most this (a share of the diagonal)
    #: lies on the input (a flat grid, a cube: 4e-8 and 7e-9 of rounding): it is neither
    #: relocated (its vertices moved by 0-2e-10 of the diagonal, for 30-40 ms at 2,000
    #: faces) nor touched up
    free_error: float = 1e-6
    #: preserve_topology=False removes stuck components up to this size (share of the diagonal)
    relax_max_size: float = 0.25
    cap_apex_tries: int = 8          #: ... caps a hole from one of this many rim vertices
    #: the pinholes are capped before the first run when the holed mesh's
    #: :func:`~.pinholes.face_floor` is above this share of the target: the collapse stops a
    #: few percent above that floor (the shared meshes with 0.5-2% of their faces missing
    #: reached targets at 0.91 times it, 16 of 16, and stopped short of 14 of 16 at
    #: 0.99-1.0), and a run that stops short costs a second one (inf: never up front)
    pinhole_floor_share: float = 0.95
    cap_hole_tries: int = 4          #: ... trying this many holes, shortest first, per call
    #: max_error raises the engine's bound in these steps (shares of it), measuring the
    #: cage after each with this many samples
    max_error_steps: tuple = (0.3, 0.5, 0.7, 0.85, 1.0)
    #: ... and the gap between the last step within max_error and the first over it is
    #: halved this many times
    max_error_halvings: int = 3
    max_error_quick_samples: int = 20_000
    #: when every step within the bound by the quick measure is over it by the full one,
    #: the engine runs afresh at half the smallest step's share, a quarter, ... this many
    #: times, each cage fully measured, before the cleaned input itself is returned
    max_error_retries: int = 4
    #: ... and when none of those is within it either, the face count is halved this many
    #: times between the cleaned input's and the target, each cage fully measured
    #: (``simplify._by_face_count``: collapses that all cost nothing, yet move the surface)
    max_error_count_halvings: int = 8
    snap_bits: int = 32              #: coordinates snapped to 2^-snap_bits of the diagonal
    snap_share: float = 1e-12        #: (distance / edge length)^2 below which a position is an endpoint
    compact_share: float = 0.5       #: compact the arrays once live faces are fewer than this share
    sample: int = 1 << 16            #: cost thresholds of larger arrays come from a sample this size
    block: int = 1 << 16             #: elements per block of work on the worker threads
    max_passes: int = 100000


TUNING = Tuning()
