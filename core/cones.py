"""Occluded point factors in closed form: the target's cone of directions minus the occluders' cones.

Seen from a point x, a flat convex polygon T covers the cone of directions inside the planes
through x and its edges, and x's horizon keeps the half-space n . y > 0: on the unit sphere of
directions around x both are caps (great circles). An occluder that lies wholly on x's side of T's
plane blocks exactly the directions of its own cone: a round sphere of centre c and radius r the
small cap u . y > cos(alpha) (u toward c, sin(alpha) = r / |c - x|), a flat convex polygon the
intersection of the great-circle caps through its edges. (Every point of such an occluder has a
height over T's plane between 0 and x's, so a ray from x that meets it does so before T.) The
visible part is therefore

    V = (T and H) minus (C_1 or ... or C_m),

and by inclusion-exclusion F(x -> V) = sum over subsets S of (-1)^|S| F(x -> T and H and C_S),
each term the projected solid angle of an intersection of caps: a contour integral along circular
arcs in closed form (`centre_caps_factor`, arcs clipped as for the sphere patches of `contour`;
Sparrow 1963, Siegel & Howell's contour method: seen from the centre of the unit sphere around x,
the kernel is the projected solid angle of the region it bounds). Only subsets whose bounding
cones meet pairwise can have a non-empty intersection; they are the cliques of the cones'
overlap graph, grown one occluder at a time (Bron & Kerbosch 1973 enumerate the maximal ones the
same way), so a row of m occluders whose cones are apart costs m terms, not 2^m - 1.

This is the exact counterpart of Nishita & Nakamae's clipping (SIGGRAPH 1985) for sphere and
polygon occluders, with the clipping done on the direction sphere: no lines, no tolerance. A
polygon that reaches behind T's plane is first clipped to x's side of it (`clip_below`): a
segment from x to T crosses that plane only at its end on T, so the part behind blocks nothing
(walls standing on a floor, and every touching pair read from float32 data, lean a little
behind each other's planes). Spheres that cut T's plane (their clipped cone is not round),
ellipsoids and disks (their cones are elliptic), cylinders, more than MAX_CONES occluders
(MAX_POLYGON_CONES polygons) and an occluder whose cone meets more than MAX_OVERLAPS others' are
left to the line integrals of
`shadow`.
"""

import numpy as np

from .contour import TWO_PI, arc_ends, circle_frame
from .polygon import point_to_polygon

MAX_CONES = 8  # occluders per query handled by inclusion-exclusion ...
MAX_POLYGON_CONES = 3  # ... of which polygons (their intersections' clipping grows as caps^3) ...
MAX_OVERLAPS = 5  # ... and whose cones each meet at most this many others' (2^5 terms an occluder)
ROUND = 1e-9  # relative spread of an ellipsoid's axes below which it is a sphere
SIDE = 1e-9  # relative tolerance of "on x's side of the target's plane"
DUPLICATE = 1e-10  # caps whose unit normals and offsets agree to this are the same circle
CAPS_BLOCK = 256  # query rows clipped at once by `centre_caps_factor`


def _dot(a, b):
    return np.einsum("...i,...i->...", a, b)


def round_spheres(inverse, offset):
    """Radius of each occluder ellipsoid that is a sphere (NaN where it is not), shape (K, S).

    Parameters
    ----------
    inverse : ndarray, shape (K, S, 3, 3)
        Inverse of each ellipsoid's linear map (`shadow.Blockers.sphere_inverse`).
    offset : ndarray, shape (K, S, 3)
    """
    gram = np.einsum("ksij,kslj->ksil", inverse, inverse)  # inv inv^T = I / r^2 for a sphere
    scale = np.trace(gram, axis1=-2, axis2=-1) / 3.0
    spread = np.abs(gram - scale[..., None, None] * np.eye(3)).max((-2, -1))
    round_ = spread <= ROUND * scale
    return np.where(round_, 1.0 / np.sqrt(np.where(round_, scale, 1.0)), np.nan)


def _polygon_caps(x, vertices):
    """Great-circle caps (normals pointing inward, b = 0) of the cones over convex polygons seen
    from x: shape (..., W, 3); zero rows for repeated vertices.

    Parameters
    ----------
    x : ndarray, shape (..., 3)
    vertices : ndarray, shape (..., W, 3)
    """
    rel = vertices - x[..., None, :]
    normal = np.cross(rel, np.roll(rel, -1, axis=-2))
    inward = _dot(normal, (vertices.mean(-2) - x)[..., None, :])
    return normal * np.where(inward < 0, -1.0, 1.0)[..., None]


def clip_below(polygons, heights):
    """Convex polygons clipped to the half-space of height >= 0 (Sutherland & Hodgman 1974, one
    plane): vertices (..., 2 W, 3), repeated where an edge adds fewer than two, and whether any
    part lies above height 0, shape (...).

    Parameters
    ----------
    polygons : ndarray, shape (..., W, 3)
    heights : ndarray, shape (..., W)
        Each vertex's signed height over the clipping plane.
    """
    a, b = polygons, np.roll(polygons, -1, axis=-2)
    ha, hb = heights, np.roll(heights, -1, axis=-1)
    in_a, in_b = ha >= 0.0, hb >= 0.0
    crossing = in_a != in_b
    share = np.divide(ha, ha - hb, out=np.zeros(ha.shape), where=crossing)
    p = a + share[..., None] * (b - a)
    # per edge a -> b: (b, b) both in, (p, p) leaving, (p, b) entering, nothing both out
    first = np.where(in_a[..., None], np.where(in_b[..., None], b, p), p)
    second = np.where(in_b[..., None], b, p)
    out = np.stack([first, second], -2).reshape(polygons.shape[:-2] + (-1, 3))
    valid = np.repeat(in_a | in_b, 2, axis=-1)
    # an empty slot repeats the vertex before it (cyclically): a zero-length edge, no cap
    slots = np.arange(valid.shape[-1])
    before = np.maximum.accumulate(np.where(valid, slots, -1), axis=-1)
    before = np.where(before < 0, before[..., -1:], before)
    out = np.take_along_axis(out, np.maximum(before, 0)[..., None], -2)
    return out, (heights > 0.0).any(-1)


def cone_visible_factor(x, n, corners, target_normal, blockers):
    """F(x -> visible part of a flat convex polygon) where the closed form applies.

    Parameters
    ----------
    x, n : ndarray, shape (K, 3)
        Points and unit normals.
    corners : ndarray, shape (K, V, 3)
        Target polygons (convex; repeated vertices allowed).
    target_normal : ndarray, shape (K, 3)
        Unit front normals of the targets.
    blockers : shadow.Blockers
        The occluders of each query.

    Returns
    -------
    F : ndarray, shape (K,)
        The visible factor (0 where `done` is False).
    done : ndarray of bool, shape (K,)
        Queries the closed form covers: x in front of the target, no disk or cylinder occluder, every valid
        occluder a round sphere on x's side of the target's plane (touching allowed) or a polygon
        (clipped to that side), at most MAX_CONES of them (MAX_POLYGON_CONES polygons), none whose
        bounding cone meets more than MAX_OVERLAPS others'.
    """

    def base(q):  # the polygon's edge caps and the horizon; Lambert's formula with the horizon
        caps = np.concatenate([_polygon_caps(x[q], corners[q]), n[q][:, None]], 1)
        unoccluded, _ = point_to_polygon(x[q], n[q], corners[q], target_normal[q])
        return caps, np.zeros(caps.shape[:2]), unoccluded

    return _cones_visible(x, n, corners.mean(1), target_normal, blockers, base)


def round_cone_visible_factor(x, n, center, normal, radius, blockers):
    """F(x -> visible part of a whole flat disk seen from a point on its axis), where the closed
    form applies (as `cone_visible_factor`): the disk covers the round cone u . y > cos(beta), u
    toward its centre, tan(beta) = radius / height, a small cap like a sphere occluder's (the
    silhouette disk of a sphere target is seen so: `sphere_target`).

    Parameters
    ----------
    x, n : ndarray, shape (K, 3)
    center, normal : ndarray, shape (K, 3)
        Disk centres and unit front normals (x on the axis, in front).
    radius : ndarray, shape (K,)
    blockers : shadow.Blockers
    """
    to_center = center - x
    height = np.maximum(-_dot(to_center, normal), 0.0)

    def base(q):  # the disk's cap and the horizon; the unoccluded factor is their intersection's
        d = np.maximum(np.linalg.norm(to_center[q], axis=-1), 1e-300)
        caps = np.stack([to_center[q] / d[:, None], n[q]], 1)
        offsets = np.stack([height[q] / np.hypot(height[q], radius[q]), np.zeros(q.size)], 1)
        return caps, offsets, _caps_factor(n[q], caps, offsets)

    return _cones_visible(x, n, center, normal, blockers, base)


def _cones_visible(x, n, origin, target_normal, blockers, base):
    """The closed form past spheres and polygons, given the target's caps (`base(q)` -> cap normals
    (Q, J, 3), offsets (Q, J) and the unoccluded factor (Q,) of queries q, the horizon among the
    caps) and its plane (a point `origin` and unit normal, each (K, 3)): (F, done) as
    `cone_visible_factor`."""
    K = len(x)
    h = _dot(x - origin, target_normal)
    # (a disk's cone is elliptic, a cylinder's is no cone: lines)
    done = (h > 0.0) & ~blockers.disks.valid.any(1) & ~blockers.cylinders.valid.any(1)
    # ---- spheres: round, x outside, wholly on x's side of the target's plane
    S = blockers.sphere_valid.shape[1]
    if S:
        radius = round_spheres(blockers.sphere_inverse, blockers.sphere_offset)
        center = blockers.sphere_offset
        to_center = center - x[:, None]
        distance = np.linalg.norm(to_center, axis=-1)
        height = _dot(center - origin[:, None], target_normal[:, None])
        sphere_ok = np.isfinite(radius) & (distance > radius) & (height >= radius * (1.0 - SIDE))
        done &= np.all(sphere_ok | ~blockers.sphere_valid, axis=1)
    # ---- polygons: every vertex on x's side of the plane (touching allowed); x off their plane
    P = blockers.polygon_valid.shape[1]
    polygon_live = blockers.polygon_valid.copy()
    if P:
        poly = blockers.polygons
        reach = np.linalg.norm(poly - x[:, None, None], axis=-1).max(-1)
        plane = np.cross(poly[:, :, 1] - poly[:, :, 0], poly[:, :, 2] - poly[:, :, 0])
        plane += np.cross(poly[:, :, 2] - poly[:, :, 0], poly[:, :, -1] - poly[:, :, 0])
        offset = _dot(plane, x[:, None] - poly[:, :, 0])
        # x in the occluder's plane: its cone has no interior, it blocks nothing
        polygon_live &= np.abs(offset) > 1e-12 * np.linalg.norm(plane, axis=-1) * reach
        # the part of an occluder behind the target's plane blocks no segment from x to the
        # target (each crosses that plane only at its target end): clipped away, exactly
        heights = _dot(poly - origin[:, None, None], target_normal[:, None, None])
        if np.any((heights < 0.0) & polygon_live[..., None]):
            poly, in_front = clip_below(poly, heights)
            polygon_live &= in_front
    polygons = polygon_live.sum(1) if P else 0
    done &= (blockers.sphere_valid.sum(1) if S else 0) + polygons <= MAX_CONES
    done &= polygons <= MAX_POLYGON_CONES
    F = np.zeros(K)
    q = np.flatnonzero(done)
    if q.size == 0:
        return F, done
    # ---- caps on the unit sphere around x: target edges and horizon (base), then the occluders'
    xq, nq = x[q], n[q]
    base_a, base_b, unoccluded = base(q)  # (Q, J, 3), (Q, J), (Q,)
    # one slot per occluder (spheres, then polygons): its caps, and its bounding cone
    caps_a, caps_b, axes, halves, live = [], [], [], [], []
    if S:
        d = np.maximum(distance[q], 1e-300)
        unit = to_center[q] / d[..., None]
        sin_alpha = np.clip(np.nan_to_num(radius[q]) / d, 0.0, 1.0)
        for k in range(S):
            caps_a.append(unit[:, k, None])
            caps_b.append(np.sqrt(1.0 - sin_alpha[:, k, None] ** 2))
            axes.append(unit[:, k])
            halves.append(np.arcsin(sin_alpha[:, k]))
            live.append(blockers.sphere_valid[q, k])
    if P:
        poly = poly[q]
        caps = _polygon_caps(xq[:, None], poly)
        axis = poly.mean(2) - xq[:, None]
        axis /= np.maximum(np.linalg.norm(axis, axis=-1, keepdims=True), 1e-300)
        rel = poly - xq[:, None, None]
        rel /= np.maximum(np.linalg.norm(rel, axis=-1, keepdims=True), 1e-300)
        spread = np.arccos(np.clip(_dot(rel, axis[:, :, None]).min(-1), -1.0, 1.0))
        for k in range(P):
            caps_a.append(caps[:, k])
            caps_b.append(np.zeros(caps.shape[:1] + caps.shape[2:3]))
            axes.append(axis[:, k])
            halves.append(spread[:, k])
            live.append(polygon_live[q, k])
    # pairs of occluders whose bounding cones meet: rows where one meets more than MAX_OVERLAPS
    # others' are left to the line integrals (inclusion-exclusion would need up to 2^L terms)
    L = len(live)
    meets = np.zeros((q.size, L, L), dtype=bool)
    for k in range(L):
        for m in range(k):
            gap = np.arccos(np.clip(_dot(axes[m], axes[k]), -1.0, 1.0))
            meets[:, k, m] = meets[:, m, k] = live[m] & live[k] & (gap <= halves[m] + halves[k] + 1e-12)
    crowded = meets.sum(2).max(1, initial=0) > MAX_OVERLAPS
    done[q[crowded]] = False
    # the unoccluded term (the empty subset)
    total = unoccluded.copy()
    base_norm = np.maximum(np.linalg.norm(base_a, axis=-1), 1e-300)
    base_unit = base_a / base_norm[..., None]
    reach = np.arccos(np.clip(base_b / base_norm, -1.0, 1.0))  # each base cap's angular radius
    # base caps that may cut each occluder's cone; one that holds the whole cone holds any
    # intersection with it, and drops out of that term
    apart = [np.arccos(np.clip(np.einsum("kji,ki->kj", base_unit, axes[m]), -1.0, 1.0)) for m in range(L)]
    cuts = [apart[m] + halves[m][:, None] > reach - 1e-12 for m in range(L)]
    # an occluder whose cone lies wholly outside one base cap meets none of the target's
    # directions: every term with it is empty (a sphere beside the target, seen from most points
    # of a pair whose shaft it only grazes)
    for m in range(L):
        live[m] = live[m] & ~np.any(apart[m] - halves[m][:, None] > reach + 1e-9, axis=1)
    # the other terms: subsets whose bounding cones meet pairwise (any other intersection is
    # empty), grown one occluder at a time (a clique search: only rows where a subset can be
    # non-empty are carried to its supersets)
    stack = [((), np.flatnonzero(~crowded))]
    while stack:
        members, rows = stack.pop()
        for k in range(members[-1] + 1 if members else 0, L):
            grown = rows[live[k][rows]]
            for m in members:
                grown = grown[meets[grown, m, k]]
            if grown.size == 0:
                continue
            chosen = members + (k,)
            needed = np.logical_and.reduce([cuts[m][grown] for m in chosen])
            a = [np.where(needed[..., None], base_a[grown], 0.0)] + [caps_a[m][grown] for m in chosen]
            b = [base_b[grown]] + [caps_b[m][grown] for m in chosen]
            value = _caps_factor(nq[grown], np.concatenate(a, 1), np.concatenate(b, 1))
            total[grown] += (-1.0 if len(chosen) % 2 else 1.0) * value
            stack.append((chosen, grown))
    # what is left below the subtraction's rounding is nothing (a target wholly hidden)
    F[q] = np.where(total > 64.0 * np.finfo(float).eps * unoccluded, total, 0.0)
    F[q[crowded]] = 0.0
    return F, done


def _caps_factor(n, a, b):
    """F from the centre of the unit sphere to the intersection of caps a . y > b, shape (Q,).

    Parameters
    ----------
    n : ndarray, shape (Q, 3)
        Unit normals at the centre.
    a : ndarray, shape (Q, J, 3)
        Cap normals (zero rows: no cap).
    b : ndarray, shape (Q, J)
    """
    norm = np.linalg.norm(a, axis=-1)
    active = (norm > 0.0) & (b > -norm * (1 - 1e-14))  # caps that hold the whole sphere drop out
    empty = (active & (b >= norm * (1 - 1e-14))).any(1)
    # the same circle twice (the plane through x and an edge two polygons share) would clip its
    # own arcs by rounding: one of equal caps is kept; opposite caps leave nothing
    unit = a / np.where(norm > 0, norm, 1.0)[..., None]
    offset = b / np.where(norm > 0, norm, 1.0)
    both = active[:, :, None] & active[:, None, :]
    same = both & (np.abs(offset[:, :, None] - offset[:, None]) <= DUPLICATE)
    opposite = both & (np.abs(offset[:, :, None] + offset[:, None]) <= DUPLICATE)
    for k in range(3):  # (component by component: a reduction over a length-3 axis is slow)
        c = unit[:, :, k]
        same &= np.abs(c[:, :, None] - c[:, None]) <= DUPLICATE
        opposite &= np.abs(c[:, :, None] + c[:, None]) <= DUPLICATE
    active &= ~np.any(np.tril(same, -1), axis=2)  # (a cap equal to an earlier one)
    empty |= opposite.any((1, 2))
    # rows by their number of caps (the clipping's cost grows as its cube), caps first in each row
    count = active.sum(1)
    order = np.argsort(~active, axis=1, kind="stable")
    a = np.take_along_axis(a, order[..., None], 1)
    b = np.take_along_axis(b, order, 1)
    norm = np.take_along_axis(norm, order, 1)
    value = np.zeros(len(n))
    for J in np.unique(count[~empty & (count > 0)]):
        rows = np.flatnonzero((count == J) & ~empty)
        value[rows] = centre_caps_factor(
            n[rows], a[rows, :J] / norm[rows, :J, None], b[rows, :J] / norm[rows, :J]
        )
    return value


def centre_caps_factor(n, axis, offset):
    """F from the centre of the unit sphere (unit normal n) to the intersection of the caps
    axis_j . y > offset_j (every cap active, |offset_j| < 1), shape (Q,).

    The boundary runs along the circles y(t) = b a + rho (cos t e1 + sin t e2), rho = sqrt(1 - b^2),
    e1 x e2 = a, where the other caps hold it (`contour.arc_ends`). Seen from the centre |y| = 1
    and n . (y x y') = rho^2 n.a - b rho (cos t n.e1 + sin t n.e2), so each arc contributes
    rho^2 n.a (t1 - t0) - b rho [n.e1 (sin t1 - sin t0) - n.e2 (cos t1 - cos t0)], and
    F = (sum over arcs) / (2 pi) (the region is seen from inside the sphere; `contour`).
    Rows go CAPS_BLOCK at a time (the (Q, J, 2 J + 2) temporaries stay in cache).

    Parameters
    ----------
    n : ndarray, shape (Q, 3)
    axis : ndarray, shape (Q, J, 3)
        Unit cap normals.
    offset : ndarray, shape (Q, J)
    """
    out = np.empty(len(n))
    for k in range(0, len(n), CAPS_BLOCK):
        block = slice(k, k + CAPS_BLOCK)
        out[block] = _centre_caps_block(n[block], axis[block], offset[block])
    return out


def _centre_caps_block(n, axis, offset):
    J = axis.shape[1]
    rho = np.sqrt(np.maximum(1.0 - offset**2, 0.0))
    e1, e2 = circle_frame(axis)
    frames = np.concatenate([axis, e1, e2], 1)  # (Q, 3 J, 3)
    along = np.matmul(frames, axis.transpose(0, 2, 1))  # a_k . a_j, e1_k . a_j, e2_k . a_j
    # constraint j along circle k: a_j . (b_k a_k + rho_k (cos t e1_k + sin t e2_k)) - b_j
    P = offset[:, :, None] * along[:, :J] - offset[:, None, :]
    Q = rho[..., None] * along[:, J : 2 * J]
    S = rho[..., None] * along[:, 2 * J :]
    others = np.broadcast_to(~np.eye(J, dtype=bool), P.shape)
    t, cos_t, sin_t, keep = arc_ends(P, Q, S, others)  # (Q, J, 2 J + 2), keep (Q, J, 2 J + 1)
    kept = keep.astype(np.float64)
    dt, ds, dc = (np.einsum("kji,kji->kj", kept, np.diff(x, axis=-1)) for x in (t, sin_t, cos_t))
    na, n1, n2 = np.split(np.matmul(frames, n[:, :, None])[..., 0], 3, axis=1)
    arcs = rho * rho * na * dt - offset * rho * (n1 * ds - n2 * dc)
    return arcs.sum(1) / TWO_PI
