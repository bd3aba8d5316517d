"""Light transport between elements: form factors of element pairs and of points to elements.

F(a -> b) = sum_k w_k F(x_k -> b) V(x_k, b): an outer Gauss rule over element a (weights w_k
normalised to sum 1, so closure holds exactly wherever the inner factors are exact) of the
point-to-patch factor F(x -> b), exact for flat, sphere, disk and cylinder elements
(`inner.PointToPatch`) and Gauss or adaptive for the others. The outer rule's order and cell
count follow the pair's distance-to-size ratio and the tolerance: the error of an n-point rule
falls like (size / distance)^(2n).

What blocks a pair and how much of it sees past its occluders is `visibility`'s; gathering light
at points is `pointgather`'s.
"""

import numpy as np

from .bounds import (
    FULL,
    HIDDEN,
    PARTIAL,
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
from .kernel import GRAZING
from .kinds import GENERIC, POLYGON, SPHERE
from .sphere_pairs import whole_sphere_factors

NODE_BUDGET = 60_000  # outer nodes (x inner evaluations) per chunk
KEPT_NODES = 2_000_000  # Gauss nodes of one rule kept for all elements at most (else per call)
FINE_NODES = 256  # nodes per element from which a rule asked for a few elements is not kept for all
NEAR_RATIO = 0.5  # a cell closer than this ratio (size / distance) is split
MAX_ORDER = 6
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
    # (np.take: fancy indexing of rows costs up to four times as much for small rules)
    return tuple(np.take(a, index, axis=0) for a in (x, normal, w))


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
