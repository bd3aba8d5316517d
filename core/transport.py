"""Light transport between elements: form factors of element pairs, their visibility, and gathering.

F(a -> b) = sum_k w_k F(x_k -> b) V(x_k, b): an outer Gauss rule over element a (weights w_k
normalised to sum 1, so closure holds exactly wherever the inner factors are exact) of the
point-to-patch factor F(x -> b), exact for flat, sphere, disk and cylinder elements
(`inner.PointToPatch`) and Gauss or adaptive for the others. The outer rule's order and cell
count follow the pair's distance-to-size ratio and the tolerance: the error of an n-point rule
falls like (size / distance)^(2n).

Visibility V is the kernel-weighted fraction of unblocked rays between Gauss samples of the two
elements, cast only against the occluders in the pair's shaft, refined where a pair is partly
occluded.
"""

import numpy as np

from . import ragged
from .bounds import (
    FULL,
    HIDDEN,
    PARTIAL,
    cannot_block,
    cone_code,
    direction_cone,
    facing_code,
    lengths,
    sample_cells,
    sphere_patch_range,
    unit_vectors,
)
from .checks import RESOLUTION
from .cones import clip_below
from .integrate import children
from .kernel import GRAZING, kernel
from .kinds import GENERIC, POLYGON, RAY_TEST_ORDER, SPHERE
from .sphere_pairs import whole_sphere_factors

NODE_BUDGET = 60_000  # outer nodes (x inner evaluations) per chunk
KEPT_NODES = 2_000_000  # Gauss nodes of one rule kept for all elements at most (else per call)
FINE_NODES = 256  # nodes per element from which a rule asked for a few elements is not kept for all
TEST_BUDGET = 400_000  # ray-occluder tests per chunk
CANDIDATE_BUDGET = 2_000_000  # pair-occluder shaft tests per chunk
NEAR_RATIO = 0.5  # a cell closer than this ratio (size / distance) is split
MAX_ORDER = 6
RAY_SHARE = 10.0  # gathered pairs carrying this times tol of a point's light get their own rays
MAX_RAY_SHARE = 1e-2  # (and at most this share)
MAX_GAUSS_NODES = 100  # exact kinds use their contour integral beyond this many Gauss nodes
NEAR_ORDER = 4  # points per parameter in each outer cell of a near pair
KINK_LEVEL = 1  # pairs in doubt about a horizon are decided on 2^KINK_LEVEL cells per parameter
KINK_MAX_LEVEL = 4  # ... and their outer cells are split at most this many times where it kinks
PLANE_CUT_SLACK = 1e-9  # of a's radius: corners this close to b's plane lie on it (`_plane_cuts`)
KINK_RULE_ERROR = 0.1  # relative error of a kinked pair's fixed rule assumed (measured: up to 4.8 %)
NEAR_RULE_ERROR = 0.5  # ... of a near pair's first rule (measured: up to 35 %, a floor patch under a ball)
NEAR_START = 2  # a near pair integrated again: from this many cells per parameter (`_adaptive_pairs`)
NEAR_MAX_LEVEL = 10  # ... split at most this many times
NEAR_CELLS = 4096  # ... into at most this many open cells per pair
TURN_GAUSS = 0.5 * np.pi  # exact kinds turning further than this (radians) skip far Gauss rules
KINKED_GAUSS_TOL = 1e-3  # below this tol, targets cut by a horizon or silhouette get exact contours
EXACT_GATHER_MAX_TOL = 0.05  # loosest relative tol of a gathered pair's exact shadow


# ---------------------------------------------------------------------------- rules
def rule_order(ratio, tol, max_order=MAX_ORDER):
    """Points per parameter so that ratio^(2n) <= tol / 4, for size/distance ratios < 1."""
    ratio = np.clip(ratio, 1e-12, 0.95)
    n = np.ceil(np.log(0.25 * tol) / (2.0 * np.log(ratio)))
    return np.clip(n, 1, max_order).astype(np.int64)  # (the caller raises it for curved parameters)


def distinct(keys):
    """The distinct values of small non-negative integers, ascending (a count, not a sort)."""
    keys = np.asarray(keys, dtype=np.int64)
    return np.flatnonzero(np.bincount(keys)) if keys.size else keys


def max_splits(tol):
    """Most cells per parameter of an outer rule at this tolerance."""
    return int(np.clip(2 ** np.ceil(np.log2(2.0 * (1e-3 / tol) ** (1.0 / 3.0))), 2, 16))


def element_nodes(elements, index, splits, order):
    """Gauss nodes on elements: splits x splits cells, order x order points in each.

    Parameters
    ----------
    index : ndarray of int, shape (P,)
    splits, order : int

    Returns
    -------
    x : ndarray, shape (P, Q, 3)
        Points (m), Q = (splits * order)^2.
    normal : ndarray, shape (P, Q, 3)
        Unnormalised front normals (area densities).
    w : ndarray, shape (P, Q)
        Parameter weights (times |normal| they integrate area).
    """
    q, count = (splits * order) ** 2, np.size(index)
    fine = q * len(elements) > KEPT_NODES or (q >= FINE_NODES and 4 * count < len(elements))
    if fine and count < len(elements) and not elements.has_nodes(splits, order):
        # (a fine rule over a few of many elements: computed for those only, not kept)
        return elements.nodes_of(index, splits, order)
    x, normal, w = elements.nodes(splits, order)
    return x[index], normal[index], w[index]


# ---------------------------------------------------------------------------- pair form factors
def pair_form_factors(elements, a, b, tol, targets=None):
    """Unoccluded F(a -> b) for element pairs.

    Parameters
    ----------
    elements : Elements
    a, b : ndarray of int, shape (P,)
        Elements of `elements` (outer) and of `targets` (inner).
    tol : float
    targets : Elements, optional
        Where the b elements are (default: `elements`).

    Returns
    -------
    F : ndarray, shape (P,)
    evaluations : int
        Kernel evaluations (each exact inner integral counts its edge terms, see `PointToPatch`).
    """
    targets = elements if targets is None else targets
    F = np.zeros(a.size)
    # a flat a that b's plane cuts: over its part in front of b (behind it F(x -> b) = 0)
    cut = _plane_cuts(elements, targets, a, b)
    evaluations = 0
    if cut.size:
        F[cut], evaluations = _front_part_factors(elements, targets, a[cut], b[cut], tol)
    rest = np.ones(a.size, dtype=bool)
    rest[cut] = False
    near, splits, order = _outer_rules(elements, targets, a, b, tol)
    config = np.where(near, 0, splits * 1000 + order)
    for key in distinct(config[~near & rest]):
        group = np.flatnonzero((config == key) & rest)
        cells, points = int(key // 1000), int(key % 1000)
        F[group], count = _rule(elements, targets, a[group], b[group], cells, points, tol)
        evaluations += count
    group = np.flatnonzero(near & rest)
    if group.size:
        F[group], count = _near_pairs(elements, targets, a[group], b[group], tol)
        evaluations += count
    return F, evaluations


def _plane_cuts(elements, targets, a, b):
    """Pairs of flat polygons whose b's plane passes through a's inside, shape (C,) int.

    Over a, x -> F(x -> b) drops to 0 where x passes behind b: a kink, or a jump of up to 1/2
    where b stands on a (a box's side on the floor patch under it). No outer rule converges
    there (a 16 x 16-cell rule of 4 x 4 points was 2.7 % off for a box's side standing on a floor
    patch, `tests/test_transport.py`), so these pairs are integrated over a's front part
    (`_front_part_factors`), where F(x -> b) is analytic: a's plane, its horizon, is one for all x."""
    sa, sb = elements.solver, targets.solver
    ia, ib = elements.index[a], targets.index[b]
    both = np.flatnonzero(
        (sa.inner.kind[ia] == POLYGON) & (sb.inner.kind[ib] == POLYGON) & elements.flat[a] & targets.flat[b]
    )
    if both.size == 0:
        return both
    heights = _heights(sa.inner.corners[ia[both]], sb, ib[both])
    slack = PLANE_CUT_SLACK * elements.radius[a[both]]
    return both[(heights.min(1) < -slack) & (heights.max(1) > slack)]


def _heights(corners, solver, index):
    """Heights of corners (K, n, 3) above the planes of flat elements `index` (K,) of `solver`
    along their unit normals, shape (K, n)."""
    axis = solver.axis[index] / lengths(solver.axis[index])[:, None]
    return np.einsum("kci,ki->kc", corners - solver.plane_point[index, None], axis)


def _front_part_factors(elements, targets, a, b, tol, allowed=None):
    """F(a -> b) for the pairs of `_plane_cuts`: a's polygon clipped to the front of b's plane
    (`cones.clip_below`), cut into a fan of triangles, each integrated as an element of its own
    (`pair_form_factors`: its edge on b's plane is where a near pair's rule refines; with
    `allowed`, absolute errors (C,): `refined_pair_factors`, each piece to its pair's allowance),
    their factors weighted by their share of a's area. Returns (F (C,), evaluations)."""
    from .elements import Elements  # (core.elements builds on core.formfactor, as this module)
    from .primitives import Quad

    corners = elements.solver.inner.corners[elements.index[a]]
    polygon, _ = clip_below(corners, _heights(corners, targets.solver, targets.index[b]))  # (C, 8, 3)
    # the fan from each polygon's first corner in a's order (corner 0 where it is in front: the
    # last edge's end slot), repeated slots giving empty triangles
    polygon = np.roll(polygon, 1, axis=1)
    fan = np.stack(
        [np.broadcast_to(polygon[:, :1], polygon[:, 1:-1].shape), polygon[:, 1:-1], polygon[:, 2:]], 2
    )
    pair = np.repeat(np.arange(a.size), fan.shape[1])
    triangles = fan.reshape(-1, 3, 3)
    turn = np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0])
    size = np.abs(triangles - triangles[:, :1]).max((1, 2))
    # (a speck, below what float64 places apart at its position, or a sliver: no area to speak
    # of, and no valid quad)
    speck = np.maximum(
        PLANE_CUT_SLACK * elements.radius[a[pair]], 2.0 * RESOLUTION * np.abs(triangles).max((1, 2))
    )
    keep = np.flatnonzero((size > speck) & (lengths(turn) > PLANE_CUT_SLACK * size**2))
    if keep.size == 0:
        return np.zeros(a.size), 0
    # (the clipped corners keep a's order around it: its front, unless a is a flipped side)
    facing = np.einsum("ki,ki->k", turn[keep], elements.solver.axis[elements.index[a[pair[keep]]]]) > 0
    triangles = np.where(facing[:, None, None], triangles[keep], triangles[keep][:, ::-1])
    piece_pair = pair[keep]
    parts = Elements([Quad(*t, t[0]) for t in triangles], elements.owner[a[piece_pair]])  # (p01 = p00)
    pieces = np.arange(len(parts))
    if allowed is None:
        got, evaluations = pair_form_factors(parts, pieces, b[piece_pair], tol, targets)
    else:
        got, evaluations = refined_pair_factors(
            parts, pieces, b[piece_pair], tol, allowed[piece_pair], targets
        )
    return np.bincount(piece_pair, got * parts.area / elements.area[a[piece_pair]], a.size), evaluations


def outer_first(elements, i, j):
    """Whether i is the outer side of each pair (i, j) for `pair_form_factors`, shape (P,) bool:
    the side whose partner has an exact inner integral; between two exact kinds the one that
    does not turn further than TURN_GAUSS (a whole disk lamp is better as the exact inner side
    than under a Gauss rule), then the smaller."""
    exact = elements.solver.exact_inner[elements.solver.slot]
    smaller = elements.radius[i] <= elements.radius[j]
    turns = elements.turning > TURN_GAUSS
    both = np.where(turns[i] != turns[j], turns[j], smaller)
    return np.where(exact[i] != exact[j], exact[j], np.where(exact[i], both, smaller))


def kinked_pairs(elements, a, b, tol):
    """Pairs of `pair_form_factors` (a outer) whose fixed outer rule may be defeated by a kink,
    shape (P,) bool: a horizon (of either side) or the inner side's plane may cross the pair
    (`_smooth_pairs`; near pairs are counted by `rule_errors`). Measured: such a rule was up to
    4.8 % off (KINK_RULE_ERROR bounds it). Flat pairs whose b's plane cuts a are integrated over
    a's front part, where nothing kinks (`_plane_cuts`)."""
    near, _, _ = _outer_rules(elements, elements, a, b, tol)
    kinked = ~near & ~_smooth_pairs(elements, elements, a, b)
    kinked[_plane_cuts(elements, elements, a, b)] = False
    return kinked


def rule_errors(elements, a, b, tol):
    """The relative error assumed of each pair's value from `pair_form_factors` (a outer), shape
    (P,): KINK_RULE_ERROR for kinked pairs (`kinked_pairs`), NEAR_RULE_ERROR for near pairs and
    plane-cut pairs (whose pieces touch b: near pairs), whose first rule stops where two rules
    agree, which they may do early (a floor patch 0.1 m under a ball: 35 % off at tol 1e-3); 0
    for the others, whose a priori rule meets tol. `refined_pair_factors` integrates a pair to a
    given error."""
    near, _, _ = _outer_rules(elements, elements, a, b, tol)
    error = np.where(near, NEAR_RULE_ERROR, np.where(kinked_pairs(elements, a, b, tol), KINK_RULE_ERROR, 0.0))
    error[_plane_cuts(elements, elements, a, b)] = NEAR_RULE_ERROR
    return error


def refined_pair_factors(elements, a, b, tol, allowed, targets=None):
    """F(a -> b) for pairs in doubt (`rule_errors`), each to an absolute error `allowed` (P,):
    near pairs by adaptive cubature (`_near_pairs_to`), plane-cut pairs over their front part's
    pieces likewise, kinked pairs on the fixed rule's cells refined where x -> F(x -> b) kinks
    (`_kinked_pairs`); two whole spheres apart by their axisymmetric integral (`sphere_pairs`).
    `targets` as in `pair_form_factors`. Returns (F (P,), evaluations)."""
    targets = elements if targets is None else targets
    F = np.zeros(a.size)
    ia, ib = elements.index[a], targets.index[b]
    inner_a, inner_b = elements.solver.inner, targets.solver.inner
    r1, r2 = inner_a.sphere_radius[ia], inner_b.sphere_radius[ib]
    d = lengths(inner_a.sphere_center[ia] - inner_b.sphere_center[ib])
    balls = np.flatnonzero(inner_a.whole_sphere[ia] & inner_b.whole_sphere[ib] & (d > r1 + r2))
    evaluations = 0
    if balls.size:
        F[balls], _, evaluations = whole_sphere_factors(r1[balls], r2[balls], d[balls], allowed[balls])
    rest = np.ones(a.size, dtype=bool)
    rest[balls] = False
    cut = np.setdiff1d(_plane_cuts(elements, targets, a, b), balls)
    if cut.size:
        F[cut], count = _front_part_factors(elements, targets, a[cut], b[cut], tol, allowed[cut])
        evaluations += count
    rest[cut] = False
    near, splits, order = _outer_rules(elements, targets, a, b, tol)
    group = np.flatnonzero(rest & near)
    if group.size:
        F[group], count = _near_pairs_to(elements, targets, a[group], b[group], tol, allowed[group])
        evaluations += count
    rest &= ~near
    config = splits * 1000 + order
    for key in distinct(config[rest]):
        group = np.flatnonzero(rest & (config == key))
        cells, points = int(key // 1000), int(key % 1000)
        F[group], count = _kinked_pairs(
            elements, targets, a[group], b[group], cells, points, tol, allowed[group]
        )
        evaluations += count
    return F, evaluations


def _outer_rules(elements, targets, a, b, tol):
    """Which pairs are near (their size above NEAR_RATIO times their gap), and the others'
    outer rule: cells per parameter and points per cell, each shape (P,)."""
    distance = lengths(elements.center[a] - targets.center[b])
    room = distance - targets.radius[b]
    near = room <= NEAR_RATIO * elements.radius[a]
    ratio = np.where(near, np.inf, elements.radius[a] / np.where(near, 1.0, room))
    splits = np.clip(np.ceil(ratio / NEAR_RATIO), 1, max_splits(tol))
    needed = elements.orders(tol)[a]
    order = np.maximum(rule_order(ratio / splits, tol), (needed + splits - 1) // splits)
    return near, splits.astype(np.int64), order.astype(np.int64)


def _smooth_pairs(elements, targets, a, b):
    """Pairs over which F(x -> b) is analytic in x by bounds, shape (P,): over every outer and
    inner point, n_x . (y - x) and n_y . (x - y) keep their signs (no horizon of either side
    crosses the other; the inner integral clips exactly, but a factor is not analytic where its
    clipping starts; a whole ellipsoid b clips at its silhouette, smoothly). Decided on the whole
    elements (`bounds.cone_code`, a flat element's plane, two flat polygons' corners exactly),
    then on KINK_LEVEL cells of the pairs left in doubt."""
    sa, sb = elements.solver, targets.solver
    ia, ib = elements.index[a], targets.index[b]
    smooth = np.ones(a.size, dtype=bool)
    # (the whole outside of an ellipsoid as b: its own side clips at its silhouette, a smooth
    # curve moving smoothly with x, so only a's horizon can kink F(x -> b))
    body = targets.whole_body[b]
    for side, ((s1, i1), (s2, i2)) in enumerate((((sa, ia), (sb, ib)), ((sb, ib), (sa, ia)))):
        code = _side_code(s1, i1, s2.center[i2], s2.radius[i2])
        if side == 1:
            code[body] = FULL
        # two flat polygons: the other's corners decide exactly (touching the plane is no kink)
        both = np.flatnonzero((s1.inner.kind[i1] == POLYGON) & (s2.inner.kind[i2] == POLYGON))
        if both.size:
            corners = s2.inner.corners[i2[both]] - s1.plane_point[i1[both], None]
            heights = np.einsum("kci,ki->kc", corners, s1.axis[i1[both]])
            slack = 1e-12 * lengths(corners).max(1)
            crossing = (heights.min(1) < -slack) & (heights.max(1) > slack)
            code[both] = np.where(crossing, PARTIAL, FULL)
        doubt = np.flatnonzero(code == PARTIAL)
        if doubt.size:
            smooth[doubt] &= _cells_agree(s1, i1[doubt], s2, i2[doubt])
    return smooth


def _side_code(s1, i1, center, radius):
    """Sign of n_x . (y - x) for x on elements i1 of solver s1 and y in balls: `bounds` codes."""
    direction, spread, distance = direction_cone(s1.center[i1], center, s1.radius[i1] + radius)
    code = cone_code(s1.axis[i1], s1.half_angle[i1], direction, spread)
    height = np.einsum("ki,ki->k", s1.axis[i1], center - s1.plane_point[i1])
    flat_code = facing_code(height, radius + 1e-12 * (distance + radius))
    return np.where(s1.flat[i1], flat_code, code)


def _cells_agree(s1, i1, s2, i2):
    """Whether n_x . (y - x) keeps one sign over the pairs by cell bounds, shape (K,): a curved
    s1 element by its cells (normal cones) against the other's ball, a flat one by its plane
    against the other's cells (balls); all FULL or all HIDDEN."""
    agree = np.empty(i1.size, dtype=bool)
    rows = np.flatnonzero(~s1.flat[i1])
    if rows.size:  # the cells' normal cones against the other's ball
        agree[rows] = _sides_agree(s1, i1[rows], s2.center[i2[rows]], s2.radius[i2[rows]])
    rows = np.flatnonzero(s1.flat[i1])
    if rows.size:  # the plane against the other's cells
        rep, level, ii, jj = _kink_cells(rows.size)
        center, radius, _, _, _ = s2.pyramid.bounds(i2[rows][rep], level, level, ii, jj)
        height = np.einsum("ki,ki->k", s1.axis[i1[rows][rep]], center - s1.plane_point[i1[rows][rep]])
        code = facing_code(height, radius + 1e-12 * radius).reshape(rows.size, -1)
        agree[rows] = np.all(code == FULL, 1) | np.all(code == HIDDEN, 1)
    return agree


def _sides_agree(s, index, center, radius):
    """Whether n_y . (x - y) keeps one sign for y on elements `index` of solver s and x in balls
    (center (K, 3), radius (K,)), shape (K,): by their KINK_LEVEL cells' normal cones
    (`_cones_agree`), and a round sphere's patch exactly (`_sphere_one_side`)."""
    agree = _cones_agree(s, index, center, radius)
    k = np.flatnonzero(s.inner.kind[index] == SPHERE)
    agree[k] |= _sphere_one_side(s.inner, index[k], s.set.boxes[index[k]], center[k], radius[k])
    return agree


def _cones_agree(s, index, center, radius):
    """Whether n_y . (x - y) keeps one sign for y on the KINK_LEVEL cells of elements `index` of
    solver s (their normal cones) and x in balls (center (K, 3), radius (K,)), shape (K,): all
    FULL or all HIDDEN."""
    rep, level, ii, jj = _kink_cells(index.size)
    c, r, axis, half, _ = s.pyramid.bounds(index[rep], level, level, ii, jj)
    direction, spread, _ = direction_cone(c, center[rep], radius[rep] + r)
    code = cone_code(axis, half, direction, spread).reshape(index.size, -1)
    return np.all(code == FULL, 1) | np.all(code == HIDDEN, 1)


def _kink_cells(K):
    """The 2^KINK_LEVEL x 2^KINK_LEVEL cells of K elements: row of each cell, shape (K C,), and
    its level and indices as `bounds.Pyramid.bounds` takes them."""
    n = 1 << KINK_LEVEL
    ci, cj = (g.ravel() for g in np.meshgrid(np.arange(n), np.arange(n), indexing="ij"))
    rep = np.repeat(np.arange(K), ci.size)
    return rep, np.full(rep.size, KINK_LEVEL), np.tile(ci, K), np.tile(cj, K)


def _kinked_pairs(elements, targets, a, b, splits, order, tol, allowed):
    """Pairs whose outer integrand may have a kink: the pair's rule (splits x splits cells of
    order x order points) is kept on the cells that bounds prove smooth (`_smooth_cells`); each
    other cell is compared with its four children's rules and split where they differ by more
    than its share (by area) of the pair's allowed error (`allowed`, absolute in F, never below
    tol |F|), at most KINK_MAX_LEVEL times, its smooth children kept as they are, so the
    refinement follows the kink's curve instead of doubling the whole rule."""
    P = a.size
    pair = np.repeat(np.arange(P), splits * splits)
    cells = elements.grid_cells(a, splits)
    value, area, evaluations = _cell_integrals(elements, targets, a[pair], b[pair], cells, order, tol)
    total = np.bincount(pair, area, P)
    smooth = _smooth_cells(elements, targets, a[pair], b[pair], cells)
    done = np.bincount(pair[smooth], value[smooth], P).astype(np.float64)  # (int when none)
    cells, pair, value = cells[~smooth], pair[~smooth], value[~smooth]
    level = 0
    while pair.size:
        kids, kid_pair = children(cells), np.repeat(pair, 4)
        v, w, count = _cell_integrals(elements, targets, a[kid_pair], b[kid_pair], kids, order, tol)
        evaluations += count
        child_value, child_area = v.reshape(-1, 4).sum(1), w.reshape(-1, 4).sum(1)
        F = (done + np.bincount(pair, child_value, P)) / np.maximum(total, 1e-300)
        allow = np.maximum(allowed[pair], tol * np.abs(F[pair])) * child_area
        final = (np.abs(child_value - value) <= allow) | (level + 1 >= KINK_MAX_LEVEL)
        # a cell whose rules saw nothing of b, or whose children's rule differs from its own by
        # half of it or more, may see a sliver of b that neither resolves (its horizon sweeps a
        # corner of b): their difference says nothing yet, split on, down to KINK_MAX_LEVEL
        settled = (np.abs(child_value - value) < 0.5 * np.abs(child_value)) | (value == child_value)
        final &= (settled & (value != 0.0)) | (level + 1 >= KINK_MAX_LEVEL)
        done += np.bincount(pair[final], child_value[final], P)
        open_kids = np.flatnonzero(np.repeat(~final, 4))
        smooth = _smooth_cells(
            elements, targets, a[kid_pair[open_kids]], b[kid_pair[open_kids]], kids[open_kids]
        )
        done += np.bincount(kid_pair[open_kids[smooth]], v[open_kids[smooth]], P)
        keep = open_kids[~smooth]
        cells, pair, value = kids[keep], kid_pair[keep], v[keep]
        level += 1
    return done / np.maximum(total, 1e-300), evaluations


def _smooth_cells(elements, targets, a, b, cells):
    """Source cells over which x -> F(x -> b) is analytic by bounds, shape (C,): a curved
    source's horizon (its cell's normal cone) keeps b (a flat polygon: each of its corners) on one
    side, and b's plane (flat) or its KINK_LEVEL cells' normal cones (curved) keep the cell on one
    side (a whole ellipsoid b clips at its silhouette, smoothly). (A flat source's horizon is one
    plane for all its points: the part of b above it does not move.)"""
    smooth = np.ones(len(cells), dtype=bool)
    if smooth.size == 0:
        return smooth
    sa, sb = elements.solver, targets.solver
    ia, ib = elements.index[a], targets.index[b]
    center, radius, axis, half = sample_cells(sa.set, ia, cells, 2)
    curved = ~sa.flat[ia]
    polygon = sb.inner.kind[ib] == POLYGON
    k = np.flatnonzero(curved & ~polygon)
    if k.size:
        direction, spread, _ = direction_cone(center[k], sb.center[ib[k]], radius[k] + sb.radius[ib[k]])
        smooth[k] = cone_code(axis[k], half[k], direction, spread) != PARTIAL
        k = k[(sa.inner.kind[ia[k]] == SPHERE) & ~smooth[k]]  # (a round sphere's cell exactly)
        smooth[k] = _sphere_one_side(sa.inner, ia[k], cells[k], sb.center[ib[k]], sb.radius[ib[k]])
    # a polygon cut by the horizon is a polygon whose corners move smoothly with x: F is analytic
    # unless the horizon sweeps one of b's corners
    # (a round sphere's cell exactly: n . (p - x) has the sign of q . p - 1 in its unit-sphere
    # coordinates, a linear function of q over the cell, `bounds.sphere_patch_range`)
    round_cell = curved & polygon & (sa.inner.kind[ia] == SPHERE)
    k = np.flatnonzero(curved & polygon & ~round_cell)
    for c in range(4) if k.size else ():
        corner = sb.inner.corners[ib[k], c]
        direction, spread, _ = direction_cone(center[k], corner, radius[k])
        smooth[k] &= cone_code(axis[k], half[k], direction, spread) != PARTIAL
    k = np.flatnonzero(round_cell)
    for c in range(4) if k.size else ():
        corner = sb.inner.corners[ib[k], c] - sa.inner.origin[ia[k]]
        local = np.einsum("kij,kj->ki", sa.inner.local_from_world[ia[k]], corner)
        low, high = sphere_patch_range(local, cells[k])
        smooth[k] &= (low >= 1.0) | (high <= 1.0)
    flat = np.flatnonzero(smooth & sb.flat[ib])
    if flat.size:
        k = flat
        height = np.einsum("ki,ki->k", sb.axis[ib[k]], center[k] - sb.plane_point[ib[k]])
        smooth[k] = facing_code(height, radius[k] * (1.0 + 1e-12)) != PARTIAL
    bent = np.flatnonzero(smooth & ~sb.flat[ib] & ~targets.whole_body[b])
    if bent.size:
        smooth[bent] = _sides_agree(sb, ib[bent], center[bent], radius[bent])
    return smooth


def _sphere_one_side(inner, index, box, center, radius):
    """Whether n_y . (x - y) keeps one sign for y on round sphere patches (elements `index` of
    `inner`, parameter boxes `box` (K, 4)) and x in balls (center (K, 3), radius (K,)), shape
    (K,), exactly rather than by normal cones (`_cones_agree`): in the sphere's unit
    coordinates y = q and n_y . (x - y) has the sign of q . l - 1 (l = x in those coordinates;
    the opposite sign for an inward patch), and over the patch and the ball q . l lies within
    `bounds.sphere_patch_range` at the ball's centre widened by the ball's radius there. (A
    floor cell under a resting ball and a patch of its upper half: every point of the cell is
    behind the patch's horizon, F = 0 on the whole cell, where the cones cannot tell and the
    refinement used to split it down to KINK_MAX_LEVEL: 47,119 evaluations, 1 s for a pair.)"""
    M = inner.local_from_world[index]
    local = np.einsum("kij,kj->ki", M, center - inner.origin[index])
    reach = radius * np.linalg.norm(M, ord=2, axis=(1, 2))
    low, high = sphere_patch_range(local, box)
    return (high + reach <= 1.0) | (low - reach >= 1.0)


def _cell_integrals(elements, targets, a, b, cells, order, tol):
    """Over parameter cells of elements a: sum_k w_k |n_k| F(x_k -> b) and the cells' areas by
    the same rule, shapes (C,), and the evaluations spent (in chunks of NODE_BUDGET points)."""
    value, area = np.zeros(len(cells)), np.zeros(len(cells))
    evaluations = 0
    step = max(1, NODE_BUDGET // (order * order))
    for start in range(0, len(cells), step):
        part = slice(start, start + step)
        x, normal, w = elements.cell_nodes(a[part], cells[part], order)
        n1, length = unit_vectors(normal)
        weight = w * length
        q = x.shape[1]
        target = np.repeat(b[part], q)
        inner, count = point_to_element(targets, x.reshape(-1, 3), n1.reshape(-1, 3), target, tol)
        value[part], area[part] = (weight * inner.reshape(-1, q)).sum(1), weight.sum(1)
        evaluations += count
    return value, area, evaluations


def _rule(elements, targets, a, b, splits, order, tol):
    """One outer rule (splits x splits cells of order x order points) per pair, in chunks."""
    F = np.zeros(a.size)
    evaluations = 0
    step = max(1, NODE_BUDGET // (splits * splits * order * order))
    for start in range(0, a.size, step):
        sel = slice(start, start + step)
        F[sel], count = _outer_inner(elements, targets, a[sel], b[sel], splits, order, tol)
        evaluations += count
    return F, evaluations


def _near_pairs(elements, targets, a, b, tol):
    """Pairs closer than their size: outer cells doubled per parameter until two successive
    rules agree to tol (relative, with an absolute floor of tol / 1000)."""
    previous, evaluations = _rule(elements, targets, a, b, 1, NEAR_ORDER, tol)
    F = previous.copy()
    active = np.arange(a.size)
    splits = 1
    while active.size and splits < max_splits(tol):
        splits *= 2
        current, count = _rule(elements, targets, a[active], b[active], splits, NEAR_ORDER, tol)
        evaluations += count
        F[active] = current
        converged = np.abs(current - previous[active]) <= tol * (np.abs(current) + 1e-3)
        previous[active] = current
        active = active[~converged]
    return F, evaluations


def _near_pairs_to(elements, targets, a, b, tol, allowed):
    """Pairs closer than their size, each to an absolute error `allowed` (P,) (`_adaptive_pairs`).
    A flat polygon a and a curved exact kind b (a floor patch under a ball resting over it) are
    integrated the other way round and turned back by reciprocity: each outer point then pays the
    cheapest exact inner integral, and the kernel's peak is no sharper over b than over a (the 70
    floor-ball pairs of a 16-ball scene: 3.2 s so, 24 s the given way round). Returns (F (P,),
    evaluations)."""
    exact = targets.solver.exact_inner[targets.solver.slot]
    swap = elements.straight[a] & ~targets.straight[b] & exact[b]
    F = np.zeros(a.size)
    keep = ~swap
    F[keep], evaluations = _adaptive_pairs(elements, targets, a[keep], b[keep], tol, allowed[keep])
    if swap.any():
        scale = targets.area[b[swap]] / elements.area[a[swap]]
        back, count = _adaptive_pairs(targets, elements, b[swap], a[swap], tol, allowed[swap] / scale)
        F[swap] = back * scale
        evaluations += count
    return F, evaluations


def _adaptive_pairs(elements, targets, a, b, tol, allowed):
    """Near pairs by adaptive cubature over a's parameter cells (a Gauss rule of NEAR_ORDER^2
    points each) from NEAR_START^2 cells, each pair to an absolute error `allowed` (P,) (never
    below tol |F|). Returns (F (P,), evaluations).

    Each round compares every open cell's rule with its four children's; the difference is the
    cell's error estimate. The cells of smallest estimate are kept (their children's sum) while
    their estimates, added to those kept before, stay within half of what is left of the pair's
    allowance, and the others are split (greedy global subdivision: the work goes where the error
    is, not spread evenly by area). A cell whose children's rule differs from its own by half of
    it or more, or that saw nothing of b, may see a sliver neither resolves: it is split in any
    case (as `_kinked_pairs` does). At most NEAR_MAX_LEVEL splits and NEAR_CELLS open cells per
    pair (beyond: the children are kept).

    The refinement follows the lines and corners where F(x -> b) is singular (a seam: b's edge on
    a's side; the end of a contact along a's edge; a ball resting close over a floor patch), where
    doubling the rule of the whole element until two rules agreed stopped early (BENCHMARKS.md,
    "Near pairs whose two rules agree early")."""
    P = a.size
    pair = np.repeat(np.arange(P), NEAR_START**2)
    cells = elements.grid_cells(a, NEAR_START)
    value, area, evaluations = _cell_integrals(elements, targets, a[pair], b[pair], cells, NEAR_ORDER, tol)
    total = np.bincount(pair, area, P)
    estimate = np.bincount(pair, value, P)  # each pair's sum over its finest cells
    done, spent = np.zeros(P), np.zeros(P)
    level = 0
    while pair.size:
        kids, kid_pair = children(cells), np.repeat(pair, 4)
        v, _, count = _cell_integrals(elements, targets, a[kid_pair], b[kid_pair], kids, NEAR_ORDER, tol)
        evaluations += count
        child_value = v.reshape(-1, 4).sum(1)
        estimate += np.bincount(pair, child_value - value, P)
        error = np.abs(child_value - value)
        settled = (error < 0.5 * np.abs(child_value)) | (value == child_value)
        # (in units of the pairs' cell sums: F times a's area by the rule)
        budget = np.maximum(allowed, tol * np.abs(estimate) / np.maximum(total, 1e-300)) * total
        room = 0.5 * np.maximum(budget - spent, 0.0)
        # within each pair, settled cells of smallest error first: kept while they fit the room
        order = np.lexsort((np.where(settled, error, np.inf), pair))
        ranked = np.where(settled[order], error[order], 0.0)
        running = np.cumsum(ranked)
        start = np.r_[True, pair[order][1:] != pair[order][:-1]]
        head = np.maximum.accumulate(np.where(start, np.arange(pair.size), 0))
        within = running - running[head] + ranked[head]
        final = np.zeros(pair.size, dtype=bool)
        final[order] = settled[order] & (within <= room[pair[order]])
        final |= level + 1 >= NEAR_MAX_LEVEL
        final |= np.bincount(pair[~final], minlength=P)[pair] * 4 > NEAR_CELLS
        done += np.bincount(pair[final], child_value[final], P)
        spent += np.bincount(pair[final], error[final], P)
        keep = np.flatnonzero(np.repeat(~final, 4))
        cells, pair, value = kids[keep], kid_pair[keep], v[keep]
        level += 1
    return done / np.maximum(total, 1e-300), evaluations


def _outer_inner(elements, targets, a, b, splits, order, tol):
    """sum_k w_k F(x_k -> b) over one outer rule per pair."""
    x, normal, w = element_nodes(elements, a, splits, order)
    n1, length = unit_vectors(normal)
    weight = w * length
    total = weight.sum(1)
    weight = np.divide(weight, total[:, None], out=np.zeros_like(weight), where=total[:, None] > 0)
    q = x.shape[1]
    target = np.repeat(b, q)
    inner, count = point_to_element(targets, x.reshape(-1, 3), n1.reshape(-1, 3), target, tol)
    return (weight * inner.reshape(-1, q)).sum(1), count


def point_to_element(elements, x, n, b, tol, exact_polygons=True):
    """F(dA(x) -> element b) at points with unit normals n, shape (K,).

    Near targets: exact contour integrals for flat, sphere, disk and cylinder elements; Gauss
    rules on cells that shrink with the distance for others (NURBS, ellipsoids). Far targets
    (size below NEAR_RATIO times the distance): a Gauss rule whose order follows the ratio and
    tol, on 4 x 4 cells where the point's horizon or the target's silhouette may cut the target.
    Flat polygons are always exact (cheap, and it makes closure exact).
    """
    F = np.zeros(len(x))
    evaluations = 0
    inner = elements.solver.inner
    row = elements.index[b]
    distance = lengths(x - elements.center[b])
    ratio = np.divide(elements.radius[b], distance, out=np.full(len(x), np.inf), where=distance > 0)
    generic = inner.kind[row] == GENERIC
    # far targets wholly above x's horizon and wholly facing x have a smooth integrand: a Gauss
    # rule; flat polygons keep their cheap exact integral (which makes closure exact)
    polygon = inner.kind[row] == POLYGON
    gauss = ratio < NEAR_RATIO
    smooth = np.ones(len(x), dtype=bool)
    hidden = np.zeros(len(x), dtype=bool)
    if gauss.any():
        height = np.einsum("ki,ki->k", elements.center[b] - x, n) - elements.radius[b]
        direction, spread, _ = direction_cone(elements.center[b], x, elements.radius[b])
        cone = cone_code(elements.solver.axis[row], elements.solver.half_angle[row], direction, spread)
        smooth = (height > 0) & (cone == FULL)
        # bounds are loose at horizons and silhouettes; polygons and spheres decide exactly, and
        # those wholly hidden (behind the horizon or facing away) contribute exactly zero
        for kind, facing in ((POLYGON, _polygon_facing), (SPHERE, _sphere_facing)):
            sel = np.flatnonzero(gauss & ~smooth & (inner.kind[row] == kind))
            if sel.size:
                code = facing(inner, x[sel], n[sel], row[sel])
                smooth[sel] = code == FULL
                hidden[sel] = code == HIDDEN
        gauss &= ~hidden
    # polygons: exact unless a one- or two-point rule is accurate enough (and allowed)
    cheap = (not exact_polygons) & smooth & (rule_order(ratio, tol) <= 2)
    gauss &= ~polygon | cheap
    # a horizon or silhouette crossing the target (a kink): 4 x 4 cells of the rule instead of one
    splits = np.where(smooth, 1, 4)
    needed = elements.orders(tol)[b]
    order = np.maximum(rule_order(ratio / splits, tol), (needed + splits - 1) // splits)
    # (on curved targets the kernel's own variation adds to the distance-based error: one or two
    # points more, measured against the exact contours in tests/test_transport.py)
    order += (~elements.flat[b] & smooth) * (1 + (tol < 1e-4))
    # a contour integral costs about as much as MAX_GAUSS_NODES kernel evaluations; where a horizon
    # or silhouette cuts the target (a kink), Gauss cells err by ~1e-2 of the pair's (small) factor:
    # exact kinds take their contour unless tol is loose
    gauss &= generic | ((splits * order) ** 2 <= MAX_GAUSS_NODES)
    gauss &= generic | smooth | (tol >= KINKED_GAUSS_TOL)
    # along a parameter that turns through more than TURN_GAUSS (a whole disk lamp, a sphere or
    # cylinder of few patches) the kernel has harmonics the distance-based order misses (a floor
    # point under a whole disk was 2.9e-4 off at tol 1e-4, 7e-6 at 1e-8): exact kinds take
    # their contour there
    gauss &= generic | (elements.turning[b] <= TURN_GAUSS)
    key = splits * 1000 + order
    for value in distinct(key[gauss]):
        sel = np.flatnonzero(gauss & (key == value))
        y, normal, w = element_nodes(elements, b[sel], int(value // 1000), int(value % 1000))
        F[sel] = point_rule(x[sel], n[sel], y, normal, w)
        evaluations += w.size
    # near generic targets (NURBS, ellipsoids, twisted quads): Gauss on cells shrinking with the
    # distance (the adaptive inner integral of `form_factor` is too slow for scenes)
    near_generic = ~gauss & generic & ~hidden
    splits = np.clip(2 ** np.ceil(np.log2(np.maximum(ratio / NEAR_RATIO, 1.0))), 2, max_splits(tol))
    splits = splits.astype(np.int64)
    order = np.maximum(NEAR_ORDER, (elements.orders(tol)[b] + splits - 1) // splits)
    key = splits * 1000 + order
    for value in distinct(key[near_generic]):
        sel = np.flatnonzero(near_generic & (key == value))
        s, m = int(value // 1000), int(value % 1000)
        for start in range(0, sel.size, max(1, NODE_BUDGET // (s * s * m * m))):
            part = sel[start : start + max(1, NODE_BUDGET // (s * s * m * m))]
            y, normal, w = element_nodes(elements, b[part], s, m)
            F[part] = point_rule(x[part], n[part], y, normal, w)
            evaluations += w.size
    sel = np.flatnonzero(~gauss & ~generic & ~hidden)
    if sel.size:
        tolerance = np.zeros(sel.size)  # exact kinds: contour integrals, no tolerance needed
        values, _, count = inner(x[sel], n[sel], row[sel], tolerance)
        F[sel] = values
        evaluations += count
    return F, evaluations


def _polygon_facing(inner, x, n, row):
    """FULL where flat polygons lie wholly above the points' horizons with their fronts toward
    the points (the kernel has no kink on them), HIDDEN where wholly below a horizon or behind
    the points, PARTIAL elsewhere; shape (K,)."""
    corners = inner.corners[row]  # (K, 4, 3)
    height = np.einsum("kci,ki->kc", corners - x[:, None], n)
    front = np.einsum("ki,ki->k", x - corners[:, 0], inner.front[row]) > 0.0
    code = np.where(height.min(1) >= 0.0, FULL, PARTIAL)
    return np.where(~front | (height.max(1) <= 0.0), HIDDEN, code)


def _sphere_facing(inner, x, n, row):
    """The same for patches of spheres (under similarity maps), from the extremes of linear
    functions over the patch (`bounds.sphere_patch_range`), shape (K,)."""
    to_local = inner.local_from_world[row]
    local_x = np.einsum("kij,kj->ki", to_local, x - inner.origin[row])
    local_n, _ = unit_vectors(np.einsum("kij,kj->ki", to_local, n))
    box = inner.surfaces.boxes[row]
    # above the horizon where (p - x) . n >= 0 on the whole patch, below where <= 0
    low, high = sphere_patch_range(local_n, box)
    level = np.einsum("ki,ki->k", local_x, local_n)
    above, below = low >= level, high <= level
    # front toward x: p . x > 1 on the patch (outside), p . x < 1 (inside)
    least, most = sphere_patch_range(local_x, box)
    inward = inner.inward[row]
    facing = np.where(inward, most < 1.0, least > 1.0)
    away = np.where(inward, least >= 1.0, most <= 1.0)
    return np.where(below | away, HIDDEN, np.where(above & facing, FULL, PARTIAL))


def point_rule(x, n, y, normal, w):
    """sum_q w_q K(x, n; y_q, normal_q): a Gauss rule of the point-to-patch kernel, shape (K,).

    The kernel of `kernel.kernel` for unit normals n at the points (one length fewer to take).

    Parameters
    ----------
    x, n : ndarray, shape (K, 3)
        Points (m) and unit normals.
    y, normal : ndarray, shape (K, Q, 3)
        Nodes on the target and their unnormalised front normals.
    w : ndarray, shape (K, Q)
        Parameter weights.
    """
    # component by component: cheaper than reductions over a trailing axis of length 3
    ex, ey, ez = (y[..., i] - x[:, i, None] for i in range(3))
    nx, ny, nz = normal[..., 0], normal[..., 1], normal[..., 2]
    L2 = ex * ex + ey * ey + ez * ez
    L = np.sqrt(L2)
    c1 = ex * n[:, 0, None] + ey * n[:, 1, None] + ez * n[:, 2, None]
    c2 = -(ex * nx + ey * ny + ez * nz)
    len2 = np.sqrt(nx * nx + ny * ny + nz * nz)
    facing = (c1 > GRAZING * L) & (c2 > GRAZING * len2 * L) & (L2 > 0.0)
    value = np.where(facing, c1 * c2 / np.where(facing, np.pi * L2 * L2, 1.0), 0.0)
    return np.einsum("kq,kq->k", value, w)


# ---------------------------------------------------------------------------- shafts
class ShaftTest:
    """Which occluders may block segments between two elements (or a point and an element).

    An occluder is a candidate for a pair only if its box meets the pair's common box, its
    bounding ball meets the capsule around the segment between the elements' centres, it is not
    a plane with both elements on one side, it is not the convex surface either element lies on
    (rays leaving a convex surface never meet it again: spheres, flat patches, meshes around a
    convex solid), and it is not a mesh around a convex room holding both ends (in front of every
    one of its planes: `mesh.PolygonMesh.front_hull`).

    The box and capsule tests are answered by the occluders' bounding volume hierarchy
    (`occlusion.Occluders.bvh`, `bvh.BVH.shaft_candidates`: O(log M) nodes per query instead of
    all M occluders); the plane and own-surface rules are then applied to the sparse
    (query, occluder) pairs it returns.

    An occluder that covers part of an element (a box resting on a floor patch: `coverage`) is a
    candidate of every pair of that element: segments from the covered part start inside it and
    are blocked whichever way they go, also toward elements that no shaft test would put it
    between. (Without it, a floor patch a fifth under a box saw the ceiling, the walls and a ball
    beside the box from under the box too: its visibilities added up to 0.88 instead of 0.8 and its
    radiosity, the mean over its free part, came out 10 % dark; in a 6 m room with three boxes on
    0.86 m floor patches the floor's direct light was 1.75 % short of a ray-traced reference.)

    Parameters
    ----------
    elements : Elements
    occluders : occlusion.Occluders
    occluder_object : ndarray of int, shape (M,)
        Scene object of each occluder.
    coverage : coverage.Coverage, optional
        What other objects cover of each element.
    """

    def __init__(self, elements, occluders, occluder_object, coverage=None):
        self.elements = elements
        self.occ = occluders
        self.object = np.asarray(occluder_object, dtype=np.int64)
        self.M = len(self.object)
        self.coverage = coverage
        self.planar = np.flatnonzero(occluders.planar) if self.M else np.zeros(0, dtype=np.int64)
        self.hull_meshes = [m for m in range(self.M) if occluders.hull[m] is not None]
        self.eps = 1e-9 * occluders.scale if self.M else 0.0

    def candidates(self, a, b):
        """Candidate occluders of element pairs, as a boolean matrix of shape (P, M)."""
        e = self.elements
        if self.M == 0:
            return np.zeros((a.size, 0), dtype=bool)
        lo = np.minimum(e.box_min[a], e.box_min[b])
        hi = np.maximum(e.box_max[a], e.box_max[b])
        radius = np.maximum(e.radius[a], e.radius[b])

        def heights(k, m):
            return self._element_heights(a[k], m), self._element_heights(b[k], m)

        def own(k, m):
            return self._own_pairs(e.owner[a[k]], e.outward[a[k]], m) | self._own_pairs(
                e.owner[b[k]], e.outward[b[k]], m
            )

        ends = (e.box_min[a], e.box_max[a], e.box_min[b], e.box_max[b])
        mask = self._mask(lo, hi, e.center[a], e.center[b], radius, heights, own, ends)
        for end in (a, b):
            k, m = self._covering(end)
            keep = ~own(k, m)
            mask[k[keep], m[keep]] = True
        return mask

    def _covering(self, element):
        """(query (C,), occluder (C,)): the occluders covering part of each queried element."""
        if self.coverage is None:
            return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
        return self.coverage.occluders_of(element)

    def free_nodes(self, x, element):
        """Whether points x (P, Q, 3) on elements (P,) lie outside the elements' covered parts
        (`coverage.Coverage.covers`), shape (P, Q) bool."""
        if self.coverage is None:
            return np.ones(x.shape[:2], dtype=bool)
        return ~self.coverage.covers(x, element)

    def own(self, a, b):
        """(P, M): the occluder is the convex surface element a or b lies on, which segments between
        them leave outward and never meet again (a fact, not a culling rule)."""
        e = self.elements
        return self._own(e.owner[a], e.outward[a]) | self._own(e.owner[b], e.outward[b])

    def point_candidates(self, x, owner, outward, b, home=None):
        """Candidate occluders for segments from points x (on object `owner`) to elements b, (K, M).

        With `home` (K,), the element each point lies on, only the candidates of the element
        pairs (home, b) are tested (a segment from a point of home to one of b lies in their
        pair's shaft), once per distinct pair, instead of a descent of the hierarchy per point
        (a point outside its home's bounding ball is tested against every occluder). An occluder
        whose ball cannot meet the cone from x to b's ball (`bounds.cannot_block`) is dropped.
        """
        e = self.elements
        if self.M == 0:
            return np.zeros((len(x), 0), dtype=bool)
        within = None
        if home is not None:
            pairs, inverse = np.unique(home * len(e.center) + b, return_inverse=True)
            within = self.candidates(pairs // len(e.center), pairs % len(e.center))[inverse]
            within[lengths(x - e.center[home]) > e.radius[home] * (1.0 + 1e-9)] = True
        lo = np.minimum(x, e.box_min[b])
        hi = np.maximum(x, e.box_max[b])

        def heights(k, m):
            h = self._point_heights(x[k], m)
            return (h, h), self._element_heights(b[k], m)

        def own(k, m):
            own_start = self._own_pairs(owner[k], outward[k], m)
            return own_start | self._own_pairs(e.owner[b[k]], e.outward[b[k]], m)

        ends = (x, x, e.box_min[b], e.box_max[b])
        mask = self._mask(lo, hi, x, e.center[b], e.radius[b], heights, own, ends, within)
        # the capsule holds the pair's segments as far from x as from b; they lie in the cone from
        # x to b's ball, which a nearby occluder beside x often misses (a floor point between
        # balls resting on it: 8.8 candidate occluders per ray of example 05's near field before
        # this, 5.4 after)
        k, m = np.nonzero(mask)
        if k.size:
            bvh = self.occ.bvh
            out = cannot_block(x[k], e.center[b[k]], e.radius[b[k]], bvh.center[m], bvh.radius[m])
            mask[k[out], m[out]] = False
        return mask

    def segment_candidates(self, p, q, radius, owner, outward):
        """Candidate occluders of segments from points p (on object `owner`, -1 for none) to
        balls (q, radius), shape (K, M)."""
        if self.M == 0:
            return np.zeros((len(p), 0), dtype=bool)
        lo = np.minimum(p, q - radius[:, None])
        hi = np.maximum(p, q + radius[:, None])

        def heights(k, m):
            hp, hq = self._point_heights(p[k], m), self._point_heights(q[k], m)
            return (hp, hp), (hq - radius[k], hq + radius[k])

        def own(k, m):
            return self._own_pairs(owner[k], outward[k], m)

        ends = (p, p, q - radius[:, None], q + radius[:, None])
        return self._mask(lo, hi, p, q, radius, heights, own, ends)

    def _mask(self, lo, hi, p, q, radius, heights, own, ends, within=None):
        """Dense (K, M) candidates: the BVH's box-and-capsule pairs (or those of `within`, a
        (K, M) superset, that pass the same test), less own surfaces and planes with both ends
        on one side.

        heights(k, m) -> ((low, high) of end 1, (low, high) of end 2) over the planes of planar
        occluders m for queries k (arrays of shape (C,)); own(k, m) -> bool (C,); ends: boxes
        (lo1, hi1, lo2, hi2) holding the two ends, (K, 3) each, for the BVH's node-level plane test
        (coplanar groups of occluders, e.g. a wall of quads, are dropped at once).
        """
        K = lo.shape[0]
        if within is None:
            k, m = self.occ.bvh.shaft_candidates(lo, hi, p, q, radius, ends=ends, plane_eps=self.eps)
        else:
            k, m = np.nonzero(within)
            hit = self.occ.bvh.shaft_pairs(k, m, lo, hi, p, q, radius)
            k, m = k[hit], m[hit]
        keep = ~own(k, m)
        planar = np.flatnonzero(keep & self.occ.planar[m])
        if planar.size:
            (low1, high1), (low2, high2) = heights(k[planar], m[planar])
            above = (low1 >= -self.eps) & (low2 >= -self.eps)
            below = (high1 <= self.eps) & (high2 <= self.eps)
            keep[planar[above | below]] = False
        # a mesh around a convex room: both ends inside the room (in front of all its planes)
        for mesh in self.hull_meshes:
            sel = np.flatnonzero(keep & (m == mesh))
            if sel.size:
                normal, offset = self.occ.hull[mesh]
                inside = np.ones(sel.size, dtype=bool)
                for low, high in ((ends[0], ends[1]), (ends[2], ends[3])):
                    centre, half = 0.5 * (low[k[sel]] + high[k[sel]]), 0.5 * (high[k[sel]] - low[k[sel]])
                    least = centre @ normal.T - half @ np.abs(normal).T - offset[None]
                    inside &= least.min(1) >= -self.eps
                keep[sel[inside]] = False
        mask = np.zeros((K, self.M), dtype=bool)
        mask[k[keep], m[keep]] = True
        return mask

    def _element_heights(self, index, m):
        """Least and greatest heights of elements' boxes over the planes of occluders m, (C,) each."""
        normal = self.occ.plane_normal[m]
        return self.elements.heights(index, normal * self.occ.plane_offset[m][:, None], normal)

    def _point_heights(self, x, m):
        """Heights of points x (C, 3) over the planes of occluders m (C,)."""
        return np.einsum("ki,ki->k", x, self.occ.plane_normal[m]) - self.occ.plane_offset[m]

    def _own(self, owner, outward):
        """(K, M): the occluder is the convex surface the segment starts on, leaving it outward
        (or through its plane): such a segment never meets that surface again."""
        leaves = self.occ.planar[None] | outward[:, None]
        return self.occ.convex[None] & (self.object[None] == owner[:, None]) & leaves

    def _own_pairs(self, owner, outward, m):
        """`_own` for explicit (segment, occluder) pairs: owner, outward and m of shape (C,)."""
        leaves = self.occ.planar[m] | outward
        return self.occ.convex[m] & (self.object[m] == owner) & leaves


def blocked_rays(occluders, origins, ends, candidates, ray_pair):
    """Whether each segment is blocked by any candidate occluder of its pair.

    The candidates are tested kind by kind in `kinds.RAY_TEST_ORDER`, cheapest first, each only
    on the segments no earlier one blocked (the answer is the same; in the Cornell example a
    quarter of the segments sent to the NURBS shell's proxy were already blocked by a sphere or
    a wall).

    Parameters
    ----------
    origins, ends : ndarray, shape (R, 3)
    candidates : ndarray of bool, shape (P, M)
    ray_pair : ndarray of int, shape (R,)
        Pair (row of `candidates`) of each ray.

    Returns
    -------
    blocked : ndarray of bool, shape (R,)
    tests : int
        (segment, occluder) tests made.
    """
    blocked = np.zeros(len(origins), dtype=bool)
    pair_of_test, occluder = np.nonzero(candidates)
    if pair_of_test.size == 0:
        return blocked, 0
    # expand rays x candidate occluders of their pair
    per_pair = candidates.sum(1)
    ray, entry = ragged.expand(ragged.starts(per_pair)[ray_pair], per_pair[ray_pair])
    which = occluder[entry]
    phases = [np.isin(occluders.kind[which], kinds) for kinds in RAY_TEST_ORDER]
    phases[0] |= ~np.logical_or.reduce(phases)  # (a kind not listed: with the first)
    tests = 0
    for phase in phases:
        todo = np.flatnonzero(phase & ~blocked[ray])
        tests += todo.size
        for s in range(0, todo.size, TEST_BUDGET):
            part = todo[s : s + TEST_BUDGET]
            hit = occluders.blocked(origins[ray[part]], ends[ray[part]], which[part])
            blocked[ray[part[hit]]] = True
    return blocked, tests


# ---------------------------------------------------------------------------- visibility
EXACT_MAX_LEVEL = 7  # an exact pair visibility's outer cells are split at most this many times
SHADOW_EDGE_DECAY = 1.0 / 8.0  # ... a partly shadowed cell's difference: at least this of its parent's
DARK_PROOF_LEVEL = 3  # ... and a dark cell is split until proven dark down to this level
FREE_PROOF_LEVEL = 2  # ... and a cell that sees no shadow is split until proven clear down to this level
DARK_NOISE = 1e-12  # a cell seeing at most this fraction of its unoccluded light counts as dark


def exact_pairs(exact, shafts, a, b):
    """Which element pairs `exact_pair_visibility` can make exact, and how it orients them.

    Returns
    -------
    capable : ndarray of bool, shape (P,)
        The inner side an exact target and every occluder left in the shaft an exact kind
        (pairs with an empty shaft included: their V is 1).
    src, dst : ndarray of int, shape (P,)
        Outer and inner side (the inner one an exact target, a flat polygon preferred: the
        closed form of `cones`).
    candidates : ndarray of bool, shape (P, M)
        Occluders that may block a segment of the pair.
    """
    candidates = exact.clear(a, b, shafts.candidates(a, b))
    # (no views: pairs with a twisted quad in their shaft keep rays; their exact visibility cost
    # 3x the rays' time at tol 1e-3 and 130x at 1e-4 in a lamp-floor scene: BENCHMARKS.md)
    exact_a, exact_b = exact.exact(a, candidates), exact.exact(b, candidates)
    turn = exact_a & (~exact_b | (exact.polygon_target[a] & ~exact.polygon_target[b]))
    src, dst = np.where(turn, b, a), np.where(turn, a, b)
    capable = exact.exact(dst, candidates) | ~candidates.any(1)
    return capable, src, dst, candidates


def exact_pair_visibility(elements, exact, shafts, a, b, tol, absolute=None):
    """Visibility of element pairs from exact shadows where `exact` covers them, NaN elsewhere.

    V(a, b) = sum_k w_k F_vis(x_k -> b) / sum_k w_k F(x_k -> b) over an outer Gauss rule on a
    (the inner side b must be an exact target; pairs with only a exact are turned round, which
    reciprocity allows for V), refined cell by cell over a where a cell's rule and its four
    children's disagree (`_refined_visibility`).

    Parameters
    ----------
    exact : occluded.ExactShadows
    shafts : ShaftTest
    a, b : ndarray of int, shape (P,)
    tol : float or ndarray, shape (P,)
        Relative accuracy of each pair's V (of max(V, 1e-3)): cells are final where a rule and its
        children's agree to 3 tol times their share (the finer rule's error is about a third of
        their difference at second order).
    absolute : ndarray, shape (P,), optional
        Instead, the error allowed in each V (cells agree to 3 times it, by their share), never
        taken below half tol times V.

    Returns
    -------
    V : ndarray, shape (P,)
        NaN where the pair is not exact (a target or a candidate occluder not covered).
    lines : int
    """
    V = np.full(a.size, np.nan)
    capable, src, dst, candidates = exact_pairs(exact, shafts, a, b)
    V[~candidates.any(1)] = 1.0  # nothing in the shaft
    ok = np.flatnonzero(capable & candidates.any(1))
    lines = 0
    if ok.size == 0:
        return V, lines
    src, dst, candidates = src[ok], dst[ok], candidates[ok]
    tol = np.broadcast_to(np.asarray(tol, dtype=np.float64), a.shape)[ok]
    allowed = None if absolute is None else np.asarray(absolute, dtype=np.float64)[ok]
    e = elements
    distance = lengths(e.center[src] - e.center[dst])
    ratio = e.radius[src] / np.maximum(distance - e.radius[dst], 1e-300)
    # each pair's outer rule order from its own distance-to-size ratio (far pairs: 2 x 2 points)
    order = np.clip(rule_order(np.minimum(ratio, 0.95), tol), 2, 4)
    result = np.full(ok.size, np.nan)
    for value in distinct(order):
        group = np.flatnonzero(order == value)
        result[group], count = _refined_visibility(
            e,
            exact,
            src[group],
            dst[group],
            candidates[group],
            tol[group],
            None if allowed is None else allowed[group],
            int(value),
        )
        lines += count
    V[ok] = np.clip(result, 0.0, 1.0)
    return V, lines


def _refined_visibility(e, exact, src, dst, candidates, tol, allowed, order):
    """`exact_pair_visibility`'s outer integral over the source, refined cell by cell.

    Each cell's rule (order x order points) is compared with the sum over its four children;
    a cell whose difference exceeds its share (by parameter area) of three times the pair's
    allowance is split, down to EXACT_MAX_LEVEL, so refinement goes where the visibility changes
    (a penumbra, the sliver a patch sees of an emitter), not over the whole pair. The allowance
    is `allowed` (absolute, in V) but never below half tol times V itself (the pair's own light
    to half tol: what a row whose first, sampled solve was dark needs), or without `allowed`
    tol relative to max(V, 1e-3). Returns (V (P,), lines).

    A cell that some of its points see partly shadowed may hold a shadow's edge between them,
    where a rule and its children's can agree by chance: its difference is taken as at least
    SHADOW_EDGE_DECAY times its parent's (its share of it), and the whole element is never
    final (a sphere's shadow on a 2.7 m floor patch agreed at the element's quarter cells,
    0.07 % off at tol 1e-4, 7.5 tol; BENCHMARKS.md "Shadow edges between a rule's points").
    """
    P = src.size
    pair = np.arange(P)
    boxes = e.boxes_of(src)
    level = np.zeros(P, dtype=np.int64)
    seen, total, lines = _cell_sums(e, exact, src, dst, candidates, tol, boxes, order)
    parent_difference = np.full(P, np.inf)  # (the element itself: none, never final if shadowed)
    done_seen, done_total = np.zeros(P), np.zeros(P)
    while pair.size:
        kids = children(boxes)
        kid_pair = np.repeat(pair, 4)
        s, t, count = _cell_sums(
            e, exact, src[kid_pair], dst[kid_pair], candidates[kid_pair], tol[kid_pair], kids, order
        )
        lines += count
        child_seen, child_total = s.reshape(-1, 4).sum(1), t.reshape(-1, 4).sum(1)
        # each pair's current estimate: finished cells and the children of the open ones
        pair_seen = done_seen + np.bincount(pair, child_seen, P)
        pair_total = done_total + np.bincount(pair, child_total, P)
        V = np.divide(pair_seen, pair_total, out=np.ones(P), where=pair_total > 0)
        if allowed is None:
            allow = tol * np.maximum(V, 1e-3)
        else:
            allow = np.maximum(allowed, 0.5 * tol * V)
        share = 3.0 * allow[pair] * pair_total[pair] * 0.25 ** level.astype(np.float64)
        difference = np.abs(child_seen - seen)
        # (rounding noise of the closed forms counts as unshadowed, as DARK_NOISE counts as dark)
        shadowed = (seen < (1.0 - DARK_NOISE) * total) | (child_seen < (1.0 - DARK_NOISE) * child_total)
        estimate = np.where(
            shadowed, np.maximum(difference, SHADOW_EDGE_DECAY * parent_difference), difference
        )
        final = (estimate <= share) | (level + 1 >= EXACT_MAX_LEVEL)
        # a cell whose rules see nothing may still hold a sliver of the target: where a sphere
        # could prove it (`ExactShadows.hides_cells`), it is dark only once one sphere hides the
        # whole target from it (refined down to DARK_PROOF_LEVEL until then)
        # (rounding noise of the closed forms, ~1e-16 of the cell's unoccluded light, counts as 0)
        noise = DARK_NOISE * child_total
        dark = np.flatnonzero(final & (seen <= noise) & (child_seen <= noise) & (level < DARK_PROOF_LEVEL))
        if dark.size:
            points, margin = e.cell_hulls(src[pair[dark]], boxes[dark])
            provable, hidden = exact.hides_cells(points, margin, dst[pair[dark]], candidates[pair[dark]])
            final[dark[provable & ~hidden]] = False
        # a cell whose rules see no shadow may still hold a small one between their points: it
        # is final only once no occluder can reach its segments (`ExactShadows.clears_cells`),
        # split down to FREE_PROOF_LEVEL until then
        unseen = np.flatnonzero(final & ~shadowed & (level < FREE_PROOF_LEVEL))
        if unseen.size:
            points, margin = e.cell_hulls(src[pair[unseen]], boxes[unseen])
            clear = exact.clears_cells(points, margin, dst[pair[unseen]], candidates[pair[unseen]])
            final[unseen[~clear]] = False
        done_seen += np.bincount(pair[final], child_seen[final], P)
        done_total += np.bincount(pair[final], child_total[final], P)
        open_kids = np.repeat(~final, 4)
        pair, boxes = kid_pair[open_kids], kids[open_kids]
        level = np.repeat(level + 1, 4)[open_kids]
        seen, total = s[open_kids], t[open_kids]
        parent_difference = np.repeat(0.25 * difference, 4)[open_kids]  # (a child's share)
    return np.divide(done_seen, done_total, out=np.ones(P), where=done_total > 0), lines


def _cell_sums(e, exact, src, dst, candidates, tol, boxes, order):
    """Visible and unoccluded sums of the outer rule over source cells, shapes (C,), (C,), and
    the lines spent: sum_k w_k F_vis(x_k -> dst) and sum_k w_k F(x_k -> dst)."""
    x, normal, w = e.cell_nodes(src, boxes, order)
    n1, length = unit_vectors(normal)
    weight = w * length
    C, q = x.shape[:2]
    if C == 0:
        return np.zeros(0), np.zeros(0), 0
    X, N = x.reshape(-1, 3), n1.reshape(-1, 3)
    target = np.repeat(dst, q)
    point_tol = np.repeat(tol, q)
    unoccluded, _ = point_to_element(e, X, N, target, point_tol.min())
    blocking = np.repeat(candidates, q, axis=0)
    visible, free, lines = exact.visible(X, N, target, blocking, point_tol)
    visible = np.where(free, unoccluded, visible)
    return (weight * visible.reshape(C, q)).sum(1), (weight * unoccluded.reshape(C, q)).sum(1), lines


def pair_visibility(elements, occluders, shafts, a, b, tol, weight=None):
    """Kernel-weighted unblocked fraction of element pairs, refined where partly occluded.

    Parameters
    ----------
    a, b : ndarray of int, shape (P,)
    shafts : ShaftTest
    weight : ndarray, shape (P,), optional
        The larger of F(a -> b) and F(b -> a): partly occluded pairs are refined only where
        weight * 0.1 exceeds tol (elsewhere the visibility error is below tol in B).

    Returns
    -------
    V : ndarray, shape (P,)
    counts : dict
        "rays" (segments cast), "tests" (segment-occluder tests), "shadowed" (pairs with an
        occluder in their shaft: the others cast no rays).
    free : ndarray of bool, shape (P,)
        Pairs with no candidate occluder in their shaft (nothing can block any segment between
        them: V = 1 exactly, also from any point of either element).
    """
    V = np.ones(a.size)
    free = np.ones(a.size, dtype=bool)
    counts = dict(rays=0, tests=0, shadowed=0)
    chunk = max(256, CANDIDATE_BUDGET // max(shafts.M, 1))
    orders = (2, 4) + ((8,) if tol < 1e-3 else ()) + ((16,) if tol < 1e-5 else ())
    for start in range(0, a.size, chunk):
        rows = np.arange(start, min(start + chunk, a.size))
        candidates = shafts.candidates(a[rows], b[rows])
        todo = np.flatnonzero(candidates.any(1))
        free[rows[todo]] = False
        counts["shadowed"] += todo.size
        for n in orders:
            if todo.size == 0:
                break
            width = max(1, int(candidates[todo].sum(1).max()))
            step = max(1, TEST_BUDGET // (n**4 * width))
            partial = []
            for s in range(0, todo.size, step):
                sel = todo[s : s + step]
                p = rows[sel]
                v, r, t = _visibility_rule(elements, occluders, shafts, a[p], b[p], candidates[sel], n)
                V[p] = v
                counts["rays"] += r
                counts["tests"] += t
                partial.append(sel[((v > 0.0) & (v < 1.0)) | np.isnan(v)])
            todo = np.concatenate(partial)
            if n == orders[0]:
                # a patch's view of itself is blocked only where it folds through itself, which the
                # first rule's few segments seldom cross: self pairs with a candidate (their own
                # surface, not convex) always take the next rule (a Blender NURBS Surface cyclic in u
                # and v passed its 2 x 2 rule unblocked and summed to 1.9)
                own = np.flatnonzero((a[rows] == b[rows]) & candidates.any(1))
                todo = np.union1d(todo, own)
            if weight is not None:
                todo = todo[0.1 * weight[rows[todo]] > tol]
    # (an end whose nodes all lie under its covering object even at the finest rule: its free
    # part, a sliver, is taken as unblocked; its share of the factor is small)
    return np.where(np.isnan(V), 1.0, V) * free_share(elements, shafts, a, b), counts, free


# nodes per parameter on a partly covered element for the kernel's means over its parts
# (`free_share`): as splits x order, 8 x 8
SHARE_SPLITS, SHARE_ORDER = 4, 2


def free_share(elements, shafts, a, b, first_only=False):
    """The share of the pairs' unoccluded factor that the free parts of elements a and b exchange
    (parts covered by another object, `coverage`, exchange nothing), shape (P,): per covered end
    f m_free / (f m_free + (1 - f) m_covered), with f its free fraction and m the kernel's means
    over its free and covered nodes (SHARE_SPLITS x SHARE_ORDER nodes per parameter, toward 2 x 2
    of the other end): f where the kernel is even, exactly 1 toward a covering box's own faces
    (the kernel is zero under it); 1 for pairs with no covered end. With `first_only`, a's share
    alone (what a point on a's free part reuses of the pair's visibility: `Scene` gathers).

    Pair visibilities are sampled over the free parts (`_visibility_rule`) and scaled by it: a
    box covering a fifth of a floor patch takes a fifth of what the patch sees, wherever the
    shaft tests put the box (even where a 2 x 2 rule has no node under it)."""
    share = np.ones(a.size)
    coverage = shafts.coverage
    if coverage is None or coverage.element.size == 0:
        return share
    for end, other in ((a, b),) if first_only else ((a, b), (b, a)):
        sel = np.flatnonzero(np.isin(end, coverage.element))
        if sel.size == 0:
            continue
        x, nx, wx = element_nodes(elements, end[sel], SHARE_SPLITS, SHARE_ORDER)
        y, ny, wy = element_nodes(elements, other[sel], 1, 2)
        K = (kernel(x[:, :, None], nx[:, :, None], y[:, None], ny[:, None]) * wy[:, None, :]).sum(2)
        free = shafts.free_nodes(x, end[sel])
        # the kernel's mean over each part from its nodes, weighted by the parts' exact areas (a
        # node count would put a footprint's edge at a node spacing: a fifth covered read as a
        # quarter on 8 x 8 nodes); a part without nodes takes the other's mean, but a free sliver
        # between the nodes takes all of a kernel that is zero on the covered nodes (the foot of
        # the covering box's own face: the pair's factor lies on the sliver)
        mean_free, mean_covered = (_part_mean(wx, K, part) for part in (free, ~free))
        mean_free = np.where(np.isnan(mean_free), np.where(mean_covered > 0, mean_covered, 1.0), mean_free)
        mean_covered = np.where(np.isnan(mean_covered), mean_free, mean_covered)
        f = coverage.free[end[sel]]
        whole = f * mean_free + (1.0 - f) * mean_covered
        share[sel] *= np.divide(f * mean_free, whole, out=f.copy(), where=whole > 0)
    return share


def _part_mean(w, K, part):
    """Mean of K (S, Q) over the nodes in `part` (S, Q) with weights w (S, Q), NaN where none."""
    total = np.where(part, w, 0.0).sum(1)
    return np.divide((np.where(part, w, 0.0) * K).sum(1), total, out=np.full(len(w), np.nan), where=total > 0)


def _visibility_rule(elements, occluders, shafts, a, b, candidates, n):
    """Kernel-weighted unblocked fraction of n x n nodes on each of the pairs' elements, over the
    nodes outside the elements' covered parts (`ShaftTest.free_nodes`), shape (P,); NaN where
    every node of an end is covered (a sliver beside a box: a finer rule may find its free part)."""
    xa, na, wa = element_nodes(elements, a, 1, n)
    xb, nb, wb = element_nodes(elements, b, 1, n)
    weight = kernel(xa[:, :, None], na[:, :, None], xb[:, None], nb[:, None])
    weight *= wa[:, :, None] * wb[:, None, :]
    free = shafts.free_nodes(xa, a)[:, :, None] & shafts.free_nodes(xb, b)[:, None, :]
    weight *= free
    P, q = a.size, xa.shape[1]
    origins = np.broadcast_to(xa[:, :, None], (P, q, q, 3)).reshape(-1, 3)
    ends = np.broadcast_to(xb[:, None], (P, q, q, 3)).reshape(-1, 3)
    ray_pair = np.repeat(np.arange(P), q * q)
    blocked, tests = blocked_rays(occluders, origins, ends, candidates, ray_pair)
    V = unblocked_fraction(weight.reshape(P, -1), blocked.reshape(P, -1))
    V[~free.reshape(P, -1).any(1)] = np.nan
    return V, P * q * q, tests


def unblocked_fraction(weight, blocked):
    """Kernel-weighted fraction of unblocked samples per row, shape (P,).

    Rows whose samples all have zero weight (they miss each other's fronts) get the plain
    fraction of unblocked samples.
    """
    total = weight.sum(1)
    fraction = 1.0 - blocked.mean(1)
    return np.divide(np.where(blocked, 0.0, weight).sum(1), total, out=fraction, where=total > 0)


# ---------------------------------------------------------------------------- gathering
def gather(
    elements,
    occluders,
    shafts,
    x,
    n,
    query,
    B,
    targets,
    tol,
    home=None,
    known=None,
    emitters=None,
    exact=None,
    keep=False,
):
    """sum_j F(x -> j) V(x, j) B_j at points: the light arriving at x from all elements.

    Rays are cast for the pairs that carry at least RAY_SHARE * tol (at most MAX_RAY_SHARE) of
    the light arriving at their point (emitters, lit neighbours: where shadows show) and for
    those whose element pair (home element of x, j) is partly blocked; the dim rest reuses that
    pair's visibility from the solve when it is known, and pairs whose shaft was empty need none.

    Parameters
    ----------
    x, n : ndarray, shape (K, 3)
        Points (m) and unit front normals.
    query : dict
        The points' surface: "owner" (object), "geometry" (element geometry number), "outward".
    B : ndarray, shape (N, 3)
        Element radiosities.
    targets : ndarray of int
        Elements that carry light (B != 0).
    home : ndarray of int, shape (K,), optional
        Element containing each point.
    known : object, optional
        What the solve knows of element pairs: `known_visibility(home, j)` -> V (NaN where
        unknown), `known_free(home, j)` -> bool (nothing in the pair's shaft: a point of
        `home` sees j unblocked) and `known_sealed(home, j)` -> bool (a closed occluding shell
        between them: the pair is skipped).
    emitters : ndarray of bool, shape (N,), optional
        Emitting elements: always traced (their shadows are the sharpest).
    exact : occluded.ExactShadows, optional
        Traced pairs whose target and candidate occluders it covers get their exact visible
        factor instead of rays.

    keep : bool
        Also return the factors F(x -> j) V(x, j) (`gathered`).

    Returns
    -------
    arriving : ndarray, shape (K, 3)
    counts : dict
        "evaluations", "rays", "tests", "pairs", "lines" (of exact shadows, `shadow`).
    factors : (points (P,), elements (P,), F V (P,)), only with `keep`
    """
    e = elements
    arriving = np.zeros((len(x), 3))
    counts = dict(evaluations=0, rays=0, tests=0, pairs=0, lines=0)
    kept = []
    empty = (np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0))
    if targets.size == 0 or len(x) == 0:
        return (arriving, counts, empty) if keep else (arriving, counts)
    M = shafts.M if shafts is not None else 0
    chunk = max(1, min(200_000, CANDIDATE_BUDGET // max(M, 1)) // targets.size)
    for s in range(0, len(x), chunk):
        part = slice(s, s + chunk)
        k, j = _facing_pairs(e, x[part], n[part], query, targets)
        k_global = k + s
        if known is not None and home is not None and k.size:
            # (a point inside a closed occluding shell sees nothing outside it, nor a point
            # outside it the shell's inside)
            open_ = ~known.known_sealed(home[k_global], j)
            k, j, k_global = k[open_], j[open_], k_global[open_]
        if k.size == 0:
            continue
        F, ev = _point_factors(e, x[k_global], n[k_global], j, tol)
        counts["evaluations"] += ev
        counts["pairs"] += k.size
        if shafts is not None and shafts.M:
            traced = _gather_visibility(
                e,
                occluders,
                shafts,
                x,
                n,
                query,
                B,
                tol,
                home,
                known,
                emitters,
                k_global,
                j,
                F,
                counts,
                exact,
            )
            F = F * traced
        if keep:
            kept.append((k_global, j, F))
        for channel in range(3):
            arriving[:, channel] += np.bincount(k_global, weights=F * B[j, channel], minlength=len(x))
    if not keep:
        return arriving, counts
    if not kept:
        return arriving, counts, empty
    return arriving, counts, tuple(np.concatenate(part) for part in zip(*kept))


def _gather_visibility(
    e, occluders, shafts, x, n, query, B, tol, home, known, emitters, k, j, F, counts, exact
):
    """V for the (point, element) pairs k, j: exact or rays where they matter, the pair's V elsewhere."""
    V = np.ones(k.size)
    share = F * np.abs(B[j]).max(1)  # (B may be net of a sky: `Solution.radiosity_at`)
    total = np.bincount(k, weights=share, minlength=len(x))
    rays = share >= min(RAY_SHARE * tol, MAX_RAY_SHARE) * total[k]
    if emitters is not None:
        rays |= emitters[j]
    if known is not None and home is not None:
        # a point inside its home's bounding ball lies in every shaft of the home's pairs, so a
        # pair with an empty shaft leaves the point's segments free (V = 1, no rays)
        inside = lengths(x[k] - e.center[home[k]]) <= e.radius[home[k]] * (1.0 + 1e-9)
        free = inside & known.known_free(home[k], j)
        rays &= ~free
        reuse = np.flatnonzero(~rays & ~free)
        V[reuse] = known.known_visibility(home[k[reuse]], j[reuse])
        # an element pair whose shaft held an occluder says little about one point of its element,
        # whatever its sampled V: a point under a box resting on the floor sees none of what its
        # floor patch sees, even of a patch it barely covers (V = 1), and a point just outside the
        # box sees what a patch mostly under it does not (V = 0). Rays there, the largest shares
        # first, until what is left of the point's reused light adds up to at most tol of it (each
        # reused pair's V is off by at most 1: its share bounds it)
        rays[reuse[_beyond_budget(k[reuse], share[reuse], tol * total)]] = True
        rays[reuse[np.isnan(V[reuse])]] = True
    sel = np.flatnonzero(rays)
    if sel.size:
        p, q = k[sel], j[sel]
        # exact shadows where target and occluders allow, for emitters only: direct light has the
        # sharpest shadows; indirect pairs keep rays (exact for them costs ~10x more lines than it
        # improves); a pair carrying the share f of the point's light needs tol / f of its value
        fraction = share[sel] / np.maximum(total[p], 1e-300)
        local = np.clip(tol / np.maximum(fraction, 1e-12), tol, EXACT_GATHER_MAX_TOL)
        V[sel], c = point_visibility(
            e,
            occluders,
            shafts,
            exact,
            x[p],
            n[p],
            dict(
                owner=np.full(sel.size, query["owner"]),
                outward=np.full(sel.size, query["outward"]),
                home=home[p] if home is not None else None,
            ),
            q,
            F[sel],
            tol,
            exact_tol=local,
            exact_allowed=emitters[q] if emitters is not None else None,
        )
        for key in ("rays", "tests", "lines"):
            counts[key] += c[key]
    return V


def _beyond_budget(point, share, budget):
    """Which of the items (point (P,), share (P,)) fall outside each point's budget (shape (Q,))
    when its smallest shares are kept first: keeping the rest would add up past the budget,
    shape (P,) bool."""
    order = np.lexsort((share, point))
    point, ordered = point[order], share[order]
    running = np.cumsum(ordered)
    first = np.searchsorted(point, point)  # (sorted by point: its first item)
    before = np.where(first > 0, running[first - 1], 0.0)
    out = np.zeros(point.size, dtype=bool)
    out[order] = running - before > budget[point]
    return out


def nudged(elements, x, n, j):
    """Points x moved off their surface along their unit normals n by 1e-9 of element j's size
    plus distance, shape (K, 3): the edge terms of the contour integrals stay finite at points on
    a border (every point factor of a gather is taken there)."""
    return x + (1e-9 * (elements.radius[j] + lengths(x - elements.center[j])))[:, None] * n


def point_visibility(
    elements, occluders, shafts, exact, x, n, start, j, F, tol, exact_tol=None, exact_allowed=None
):
    """V(x, j): the fraction of F(x -> j) that points x see past the occluders, shape (K,).

    Exact visible factors (`occluded.ExactShadows.visible`, at the points `nudged` as F is) where
    the target and every candidate occluder allow, rays (`_point_visibility`: 2 x 2 per target,
    refined where partial) elsewhere.

    Parameters
    ----------
    exact : occluded.ExactShadows or None
    x, n : ndarray, shape (K, 3)
        Points on their surface and unit normals.
    start : dict of ndarray, shape (K,) each
        Where the points lie: "owner", the scene object (its own convex surface cannot block
        them), "outward", whether on the outside of a convex surface, and optionally "home",
        the element (its pairs' shafts then hold the candidates: `ShaftTest.point_candidates`).
    j : ndarray of int, shape (K,)
        Target elements.
    F : ndarray, shape (K,)
        The unoccluded F(x -> j) (the exact visible factor is divided by it).
    tol : float
    exact_tol : ndarray, shape (K,), optional
        Tolerance of each exact query (default tol).
    exact_allowed : ndarray of bool, shape (K,), optional
        The queries that may take exact shadows (default all).

    Returns
    -------
    V : ndarray, shape (K,)
    counts : dict
        "rays", "tests", "lines".
    """
    V = np.ones(len(x))
    counts = dict(rays=0, tests=0, lines=0)
    if shafts is None or shafts.M == 0 or len(x) == 0:
        return V, counts
    candidates = shafts.point_candidates(x, start["owner"], start["outward"], j, start.get("home"))
    todo = candidates.any(1)
    if exact is not None:
        may = todo if exact_allowed is None else todo & exact_allowed
        use = np.flatnonzero(may & exact.exact(j, candidates, x))
        if use.size:
            local = tol if exact_tol is None else exact_tol[use]
            p = nudged(elements, x[use], n[use], j[use])
            visible, free, lines = exact.visible(p, n[use], j[use], candidates[use], local)
            ratio = np.divide(visible, F[use], out=np.zeros(use.size), where=F[use] > 0)
            V[use] = np.where(free, 1.0, ratio)
            counts["lines"] += lines
            todo[use] = False
    sel = np.flatnonzero(todo)
    if sel.size:
        V[sel], counts["rays"], counts["tests"] = _point_visibility(
            elements, occluders, x[sel], n[sel], j[sel], candidates[sel], tol, shafts
        )
    return V, counts


def _facing_pairs(e, x, n, query, targets):
    """(point, element) pairs that can exchange light: both face each other by bounds."""
    c, r = e.center[targets], e.radius[targets]
    toward = c[None] - x[:, None]  # (K, T, 3)
    distance = lengths(toward)
    ok = np.einsum("kti,ki->kt", toward, n) + r[None] > 0.0
    # the element's front must face the point: exactly by its plane for flat elements, by its
    # normal cone and the cone of directions to the point for curved ones
    axis = e.solver.axis[e.index[targets]]
    flat = e.flat[targets]
    columns = np.flatnonzero(flat)
    if columns.size:
        point = e.solver.plane_point[e.index[targets[columns]]]
        height = np.einsum("kti,ti->kt", x[:, None] - point[None], axis[columns])
        ok[:, columns] &= height > 1e-9 * (r[None, columns] + distance[:, columns])
    columns = np.flatnonzero(~flat)
    if columns.size:
        half = e.solver.half_angle[e.index[targets[columns]]]
        d = distance[:, columns]
        safe = np.where(d > 0, d, 1.0)
        cos_angle = np.einsum("kti,ti->kt", -toward[:, columns], axis[columns]) / safe
        ratio = np.divide(r[None, columns], d, out=np.ones_like(d), where=d > 0)
        spread = np.arcsin(np.clip(ratio, 0, 1))
        angle = np.arccos(np.clip(cos_angle, -1.0, 1.0))
        ok[:, columns] &= angle - spread - half[None] < 0.5 * np.pi
    same = (e.geometry[targets] == query["geometry"]) & e.convex[targets]
    ok &= ~(same & (query["outward"] | e.outward[targets]))[None]
    k, t = np.nonzero(ok)
    return k, targets[t]


def _point_factors(e, x, n, j, tol):
    """F(x -> j), points nudged off their surface by 1e-9 of the element size (edge terms)."""
    return point_to_element(e, nudged(e, x, n, j), n, j, tol, exact_polygons=False)


def _point_visibility(e, occluders, x, n, j, candidates, tol, shafts=None):
    """Kernel-weighted unblocked fraction of point-to-element pairs: 2 x 2 rays, refined if partial.
    Nodes on a target's covered part (`ShaftTest.free_nodes`) count as blocked: that part sends
    nothing (a pair's visibility holds the same share, `free_share`)."""
    V = np.ones(len(x))
    rays = tests = 0
    todo = np.flatnonzero(candidates.any(1))
    for m in (2, 4) + ((8,) if tol < 1e-3 else ()) + ((16,) if tol < 1e-5 else ()):
        if todo.size == 0:
            break
        y, normal, w = element_nodes(e, j[todo], 1, m)
        weight = kernel(x[todo, None], n[todo, None], y, normal) * w
        q = y.shape[1]
        origins = np.repeat(x[todo], q, axis=0)
        ray_pair = np.repeat(np.arange(todo.size), q)
        blocked, t = blocked_rays(occluders, origins, y.reshape(-1, 3), candidates[todo], ray_pair)
        blocked = blocked.reshape(-1, q)
        if shafts is not None:
            blocked |= ~shafts.free_nodes(y, j[todo])
        v = unblocked_fraction(weight, blocked)
        V[todo] = v
        rays += todo.size * q
        tests += t
        todo = todo[(v > 0.0) & (v < 1.0)]
    return V, rays, tests
