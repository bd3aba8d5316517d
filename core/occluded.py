"""Form factors with third-body occlusion: F(src -> the part of dst that each point of src sees).

F(1 -> 2) = 1/A1 * integral over patch 1 of F_vis(dA1 -> patch 2) dA1, with the inner visible
factor from `shadow.visible_factor` (exact breaks, closed-form line integrals, to tol) on a flat
inner patch, and the outer integral global-adaptive over dyadic cells of patch 1: each cell's
tensor Gauss rule is compared with its four children's, and the cell with the largest difference
is split until the differences sum to tol times the value. F_vis(x) has kinks where x crosses an
umbra or penumbra boundary; the bisection finds them.

Supported (exact): inner patches that are flat quads, triangles or circular disk patches, or the
outside of a round sphere or sphere patch (its silhouette disk from each point stands for it, cut
to the patch: `sphere_target`);
either side may be the inner one (A1 F12 = A2 F21); occluders that are whole spheres or ellipsoids, flat quads
or triangles, circular disk patches (whole disks, annuli, sectors) and round cylinder patches
(lateral surfaces, any angle and height span), and twisted (bilinear) quads seen without a fold
from every point of the outer patch: from such a point two triangles are a twisted quad's exact
shadow (`bilinear`; a point that sees its silhouette raises a ValueError). Other occluder kinds
raise a ValueError naming them.

In scenes (`ExactShadows`), polygon meshes of up to MESH_PIECES flat pieces occlude exactly too:
the pieces in each query's shaft come from a BVH over all pieces, and an edge between two of them
that the query's point sees from the same side adds no break (only silhouettes do).
"""

import numpy as np

from . import ragged
from .bilinear import (
    bilinear_corners,
    fold_free,
    inside_tetrahedron,
    plane_side,
    point_triangles,
    triangle_pairs,
)
from .bounds import cone_angles, cones_apart
from .bvh import BVH
from .integrate import cell_nodes, children
from .kinds import CYLINDER, DISK, POLYGON
from .primitives import QuadGeometry
from .shadow import Blockers, Cylinders, Disks, FlatTargets, SectorTargets, visible_factor
from .sphere_target import (
    INSIDE,
    SpherePatchTargets,
    band_distance,
    disk_distance,
    ellipsoid_distance,
    polygon_distance,
    round_sphere,
    silhouette_disks,
    silhouette_planes,
    sphere_patch,
)
from .surface import Surface

OUTER_ORDER = 4  # Gauss points per parameter in each outer cell
START_SPLITS = 2  # outer cells per parameter to start from, at least
START_TURN = 0.25 * np.pi  # ... and at most this turn of the normal (rad) within a first cell
START_GRID = 17  # samples per parameter that measure the turn
MAX_START_SPLITS = 8  # (a whole turn; a wavy patch's first cells stay well inside MAX_CELLS)
MAX_CELLS = 4096  # outer cells refined at most (a budget: past it the estimate says what it reached)
MAX_OCCLUDERS = 6  # candidate occluders of a scene query up to which its shadow is exact (a
# polygon mesh counts as one: its flat pieces' shadows are merged along each line by one sort)
# polygon meshes of up to MESH_PIECES flat pieces occlude exactly, of any shape; larger ones keep
# rays (a line's cost grows with the pieces in its query's shaft; `benchmarks.mesh_shadows`: a
# 48-piece ball costs 21x the rays' time)
MESH_PIECES = 64
PLANE_SLACK = 1e-9  # relative distance within which a mesh piece lies in a plane (`mesh_pieces`)
CUT_BLOCK = 1 << 22  # (sphere target, occluder) ball tests at once (`ExactShadows._cuts`)
HULL_STEPS = 128  # pairwise Frank-Wolfe steps toward a cell's hull at most (`_clear_of_hull`)


def flat_polygon(surface):
    """Corners (4, 3) and unit front normal (3,) of a flat quad or triangle patch, else None."""
    geometry = surface.geometry
    if geometry.exact_kind(surface.domain) != POLYGON:
        return None
    corners = geometry.box_corners(surface.domain)
    (u0, u1), (v0, v1) = surface.domain
    _, normal = surface.evaluate(0.5 * (u0 + u1), 0.5 * (v0 + v1))
    return corners, normal / np.linalg.norm(normal)


def flat_sector(surface):
    """(center, normal, e1, radii, angles) of a circular disk patch (an annular sector), else None.

    Angles are measured from e1 toward normal x e1.
    """
    geometry = surface.geometry
    if geometry.exact_kind(surface.domain) != DISK:
        return None
    scale = geometry.similarity_scale
    (u0, u1), (v0, v1) = surface.domain
    _, normal = surface.evaluate(0.5 * (u0 + u1), 0.5 * (v0 + v1))
    normal = normal / np.linalg.norm(normal)
    e1 = geometry.linear[:, 0] / scale
    e2 = geometry.linear[:, 1] / scale
    angles = (v0, v1) if np.cross(normal, e1) @ e2 > 0 else (-v1, -v0)
    return geometry.offset, normal, e1, (scale * u0, scale * u1), angles


def _flat_targets(surface, count):
    """`count` copies of a flat patch as shadow targets (FlatTargets or SectorTargets), else None."""
    polygon = flat_polygon(surface)
    if polygon is not None:
        corners, normal = polygon
        return FlatTargets(np.broadcast_to(corners, (count, 4, 3)), np.broadcast_to(normal, (count, 3)))
    sector = flat_sector(surface)
    if sector is not None:
        return SectorTargets(*(np.broadcast_to(np.asarray(a, float), (count, np.size(a))) for a in sector))
    return None


def whole_ellipsoid(surface):
    """(linear, offset) of a whole sphere or ellipsoid, else None."""
    geometry = surface.geometry
    if geometry.whole_ellipsoid(surface.domain):
        return geometry.linear, geometry.offset
    return None


def round_cylinder(surface):
    """(center, axis, e1, radius, angles, heights) of a round cylinder patch, else None: the base
    centre, unit axis, the unit direction of angle 0, the radius, (a0, a1) measured from e1 toward
    axis x e1, and (s0, s1) the patch's axial distances from the base centre (m)."""
    geometry = surface.geometry
    if geometry.exact_kind(surface.domain) != CYLINDER:
        return None
    a, b, c = geometry.linear.T
    radius, length = np.linalg.norm(a), np.linalg.norm(c)
    axis, e1 = c / length, a / radius
    (u0, u1), (v0, v1) = surface.domain
    angles = (u0, u1) if np.cross(axis, e1) @ b > 0 else (-u1, -u0)
    return geometry.offset, axis, e1, radius, angles, (length * v0, length * v1)


# occluder kinds with exact shadows: how each is read from a surface, its fields' widths, and a
# lower bound of the distance from points to it (fields stacked per point: `distance(p, *fields)`)
SHAPES = {
    "sphere": (whole_ellipsoid, None, lambda p, linear, offset: ellipsoid_distance(p, linear, offset)),
    "polygon": (
        lambda surface: None if (p := flat_polygon(surface)) is None else p[0],
        None,
        polygon_distance,
    ),
    "disk": (
        flat_sector,
        (3, 3, 3, 2, 2),
        lambda p, c, n, e1, radii, angles: disk_distance(p, c, n, radii[:, 1]),
    ),
    "cylinder": (
        round_cylinder,
        (3, 3, 3, 1, 2, 2),
        lambda p, c, axis, e1, radius, angles, heights: band_distance(p, c, axis, radius, heights),
    ),
}


def occluder_shape(surface):
    """(kind, fields) of an occluder with an exact shadow (a key of SHAPES), else (None, None)."""
    for kind, (read, *_) in SHAPES.items():
        fields = read(surface)
        if fields is not None:
            return kind, fields
    return None, None


def blockers_from_surfaces(occluders, count, skip=()):
    """`Blockers` holding the same occluder list for `count` queries.

    Parameters
    ----------
    occluders : sequence of Surface
    count : int
    skip : sequence of Surface
        Surfaces left out (the pair's own patches).

    Raises
    ------
    ValueError
        An occluder that is not a surface, or of a kind without an exact shadow yet.
    """
    found = {kind: [] for kind in SHAPES}
    for k, surface in enumerate(occluders):
        if not isinstance(surface, Surface):
            raise ValueError(f"occluders[{k}] must be a core surface, got {surface!r}")
        if any(surface is s for s in skip) or bilinear_corners(surface) is not None:
            continue  # (twisted quads: `bilinear.point_triangles` per query)
        kind, fields = occluder_shape(surface)
        if kind is None:
            raise ValueError(
                f"occluders[{k}] ({surface!r}) has no exact shadow yet: occluders must be whole spheres or "
                "ellipsoids, flat or twisted quads, triangles, circular disk patches or round cylinder "
                "patches"
            )
        found[kind].append(fields)

    def stacked(kind):  # each field of the kind's occluders, broadcast to every query: (count, N, ...)
        items, widths = found[kind], SHAPES[kind][1]
        fields = [
            np.array([item[i] for item in items], dtype=float).reshape(len(items), w)
            for i, w in enumerate(widths)
        ]
        fields = [f[:, 0] if w == 1 else f for f, w in zip(fields, widths)]
        return [np.broadcast_to(f, (count,) + f.shape) for f in fields] + [np.ones((count, len(items)), bool)]

    spheres, polygons = found["sphere"], found["polygon"]
    S, P = len(spheres), len(polygons)
    linear = np.array([s[0] for s in spheres]).reshape(S, 3, 3)
    offset = np.array([s[1] for s in spheres]).reshape(S, 3)
    corners = np.array(polygons).reshape(P, 4, 3)
    return Blockers(
        np.broadcast_to(linear, (count, S, 3, 3)),
        np.broadcast_to(offset, (count, S, 3)),
        np.ones((count, S), dtype=bool),
        np.broadcast_to(corners, (count, P, 4, 3)),
        np.ones((count, P), dtype=bool),
        disks=Disks(*stacked("disk")),
        cylinders=Cylinders(*stacked("cylinder")),
    )


def _inner_shape(surface):
    """(rank, sphere, patch) of a patch as the inner side of an occluded pair: rank 0 flat, 1 the
    outside of a whole round sphere, 2 of a round sphere patch (`sphere_patch`), 3 none of these;
    sphere = (center, radius) of the sphere (ranks 1 and 2), patch = (local, box) (rank 2)."""
    if _flat_targets(surface, 1) is not None:
        return 0, None, None
    whole = round_sphere(surface)
    if whole is not None:
        return 1, whole, None
    part = sphere_patch(surface)
    if part is not None:
        return 2, part[:2], part[2:]
    return 3, None, None


def _targets(surface, sphere, patch, x):
    """Shadow targets of the inner patch `surface` seen from points x (K, 3): a flat patch as it
    is, or, with `sphere` = (center, radius) of a sphere seen from outside, its silhouette disk
    from each point (`sphere_target`), cut to the patch where `patch` = (local, box) is given."""
    if sphere is None:
        return _flat_targets(surface, len(x))
    center, radius = np.broadcast_to(sphere[0], np.shape(x)), np.full(len(x), sphere[1])
    if patch is None:
        return silhouette_disks(x, center, radius)
    local, box = (np.broadcast_to(a, (len(x),) + a.shape) for a in patch)
    return SpherePatchTargets(x, center, radius, local, box)


def _check_clear_of_sphere(sphere, occluders, skip, name):
    """ValueError if an occluder reaches inside the sphere (center, radius) of the patch `name`
    (its silhouette disk would then not stand for it)."""
    center, radius = sphere
    for k, surface in enumerate(occluders):
        if any(surface is s for s in skip):
            continue
        quad = bilinear_corners(surface)
        if quad is not None:  # (it lies in its corners' tetrahedron)
            distance = tetrahedron_distance(center[None], quad[None])[0]
        else:
            kind, fields = occluder_shape(surface)
            parts = fields if isinstance(fields, tuple) else (fields,)  # (a polygon's corners alone)
            stacked = [np.asarray(f, dtype=float)[None] for f in parts]
            distance = SHAPES[kind][2](center[None], *stacked)[0]
        if distance < (1.0 - INSIDE) * radius:
            raise ValueError(
                f"occluders[{k}] ({surface!r}) reaches inside {name} (a whole sphere): occluders must "
                "not cut the pair"
            )


def tetrahedron_distance(p, corners):
    """Distance from points p (C, 3) to the tetrahedra of four corners (C, 4, 3), shape (C,)
    (0 inside): the least over its four faces."""
    faces = corners[:, [[1, 2, 3, 1], [0, 3, 2, 0], [0, 1, 3, 0], [0, 2, 1, 0]]]  # (C, 4, 4, 3)
    to_faces = polygon_distance(np.repeat(p, 4, 0), faces.reshape(-1, 4, 3)).reshape(-1, 4).min(1)
    return np.where(inside_tetrahedron(p, corners), 0.0, to_faces)


def _check_twisted_clear_of_plane(inner, twisted, occluders):
    """ValueError if a twisted quad's corner tetrahedron (`bilinear`: where its exact shadow
    holds, segments must end outside it) reaches the plane of the flat inner patch (or behind)."""
    target = _flat_targets(inner, 1)
    if target is None:
        return
    for k, quad in twisted:
        if plane_side(quad[None], target.origin[:1], target.normal[:1])[0] == 0:
            raise ValueError(
                f"occluders[{k}] ({occluders[k]!r}), a twisted quad, reaches the plane of the inner "
                "patch: its exact shadow needs the plane clear of its corners' tetrahedron"
            )


def _check_outside(points, occluders, name):
    """ValueError if a whole sphere or ellipsoid occluder holds points of the patch `name`."""
    for k, surface in enumerate(occluders):
        ellipsoid = whole_ellipsoid(surface) if isinstance(surface, Surface) else None
        if ellipsoid is None:
            continue
        linear, offset = ellipsoid
        local = (points - offset) @ np.linalg.inv(linear).T
        if np.any(np.einsum("ki,ki->k", local, local) < 1.0 - 1e-12):
            raise ValueError(
                f"occluders[{k}] ({surface!r}) intersects {name}: occluders must not cut the pair"
            )


def _start_cells(surface):
    """The outer integral's first cells (C, 4): START_SPLITS per parameter, more (up to
    MAX_START_SPLITS) where the patch's normal turns by more than START_TURN along it (sampled on
    a START_GRID grid).

    Starting from a whole cylinder's 2 x 2 cells, the cells' 4 x 4 rules and their children's
    agreed by chance to 5e-5 while both were 2e-3 off (a half disk seen past a sphere)."""
    (u0, u1), (v0, v1) = surface.domain
    s = np.linspace(0.0, 1.0, START_GRID)
    _, N = surface.evaluate(u0 + (u1 - u0) * s[:, None], v0 + (v1 - v0) * s[None, :])
    unit = N / np.maximum(np.linalg.norm(N, axis=-1, keepdims=True), 1e-300)
    counts = []
    for axis in (0, 1):  # the largest total turn of the normal along u (rows), then v
        a, b = (unit[:-1], unit[1:]) if axis == 0 else (unit[:, :-1], unit[:, 1:])
        turn = np.arccos(np.clip(np.einsum("abi,abi->ab", a, b), -1.0, 1.0)).sum(axis).max()
        counts.append(int(np.clip(np.ceil(turn / START_TURN), START_SPLITS, MAX_START_SPLITS)))
    edges_u = np.linspace(u0, u1, counts[0] + 1)
    edges_v = np.linspace(v0, v1, counts[1] + 1)
    i, j = np.meshgrid(np.arange(counts[0]), np.arange(counts[1]), indexing="ij")
    i, j = i.ravel(), j.ravel()
    return np.stack([edges_u[i], edges_u[i + 1], edges_v[j], edges_v[j + 1]], 1)


def occluded_form_factor(src, dst, occluders, tol):
    """F(src -> dst) with occlusion by `occluders`, its error estimate and the lines integrated.

    Returns
    -------
    value, error : float
    lines : int

    Raises
    ------
    ValueError
        Neither patch is flat (no exact inner side yet), an occluder of an unsupported kind, or an
        occluder that cuts the pair.
    """
    # the inner side: a flat patch if either is one, else a whole sphere seen from outside, else
    # the outside of a round sphere patch
    shapes = [_inner_shape(s) for s in (dst, src)]
    if shapes[0][0] < 3 and shapes[0][0] <= shapes[1][0]:
        outer, inner, (_, inner_sphere, patch), ratio = src, dst, shapes[0], 1.0
    elif shapes[1][0] < 3:
        outer, inner, (_, inner_sphere, patch), ratio = dst, src, shapes[1], dst.area() / src.area()
    else:
        raise ValueError(
            "occluded form factors need one side that is a flat quad, triangle or circular disk patch, or "
            f"the outside of a round sphere or sphere patch, for now; got {src!r} and {dst!r}"
        )
    blockers_one = blockers_from_surfaces(occluders, 1, skip=(src, dst))
    twisted = [
        (k, quad)
        for k, s in enumerate(occluders)
        if not any(s is p for p in (src, dst)) and (quad := bilinear_corners(s)) is not None
    ]
    quads = np.array([quad for _, quad in twisted]).reshape(-1, 4, 3)
    if inner_sphere is not None:
        _check_clear_of_sphere(inner_sphere, occluders, (src, dst), "the inner patch")
    else:
        _check_twisted_clear_of_plane(inner, twisted, occluders)
    (a0, a1), (b0, b1) = inner.domain
    grid = np.linspace(0.0, 1.0, 9)
    probe, _ = inner.evaluate(a0 + (a1 - a0) * grid[:, None], b0 + (b1 - b0) * grid[None, :])
    _check_outside(probe.reshape(-1, 3), occluders, "the inner patch")

    boxes = _start_cells(outer)
    lines = 0

    def integrate(cells):
        """Outer Gauss rule of each cell: sum_q w_q |N_q| F_vis(x_q -> inner), shape (C,)."""
        nonlocal lines
        u, v, w = cell_nodes(cells, OUTER_ORDER)
        x, N = outer.evaluate(u.ravel(), v.ravel())
        length = np.linalg.norm(N, axis=-1)
        ok = length > 0
        unit = np.divide(N, length[:, None], out=np.zeros_like(N), where=ok[:, None])
        _check_outside(x, occluders, "the outer patch")
        K = len(x)
        targets = _targets(inner, inner_sphere, patch, x)
        blockers = blockers_one.take(np.zeros(K, dtype=np.int64))
        if len(quads):
            polygons, edges, folded = point_triangles(x, quads)
            if folded.any():
                raise ValueError(
                    f"a twisted quad occluder ({', '.join(f'occluders[{k}]' for k, _ in twisted)}) shows a "
                    f"fold (its silhouette) to points of {'dst' if outer is dst else 'src'} (e.g. at "
                    f"{np.round(x[np.argmax(folded)], 6).tolist()}), or they lie within its corners' "
                    "tetrahedron: no exact shadow for that yet"
                )
            blockers = blockers.with_polygons(polygons, np.ones(polygons.shape[:2], bool), edges)
        F, err, count = visible_factor(x, unit, targets, blockers, 0.1 * tol)
        lines += count
        weight = w.ravel() * length
        return (weight * F).reshape(cells.shape[0], -1).sum(1), (weight * err).reshape(
            cells.shape[0], -1
        ).sum(1)

    # global adaptive: every round splits the cells whose parent-children differences make up
    # the larger half of the total, until the total is below tol times the value
    values, _ = integrate(boxes)
    kids = children(boxes)
    kid_values, kid_errors = integrate(kids)
    cells_used = 5 * len(boxes)
    while True:
        refined = kid_values.reshape(-1, 4).sum(1)
        diff = np.abs(refined - values) + kid_errors.reshape(-1, 4).sum(1)
        total_value = refined.sum()
        total_error = diff.sum()
        if total_error <= 0.5 * tol * abs(total_value) or total_error <= 1e-15 * outer.area():
            break
        order = np.argsort(diff)[::-1]
        share = np.cumsum(diff[order])
        split = order[: max(1, int(np.searchsorted(share, 0.5 * total_error)) + 1)]
        if cells_used + 20 * split.size > MAX_CELLS:
            break  # out of budget: the error estimate says what was reached
        keep = np.ones(len(boxes), dtype=bool)
        keep[split] = False
        parents = kids.reshape(-1, 4, 4)[split].reshape(-1, 4)
        new_kids = children(parents)
        new_values, new_errors = integrate(new_kids)
        cells_used += len(new_kids)
        boxes = np.concatenate([boxes[keep], parents])
        values = np.concatenate([values[keep], kid_values.reshape(-1, 4)[split].ravel()])
        kids = np.concatenate([kids.reshape(-1, 4, 4)[keep].reshape(-1, 4), new_kids])
        kid_values = np.concatenate([kid_values.reshape(-1, 4)[keep].ravel(), new_values])
        kid_errors = np.concatenate([kid_errors.reshape(-1, 4)[keep].ravel(), new_errors])
    accepted_value, accepted_error = total_value, total_error
    area = outer.area()
    value = accepted_value / area * ratio
    error = accepted_error / area * ratio
    return float(max(value, 0.0)), float(error), lines


class ExactShadows:
    """Exact occluded point-to-element factors for a scene's elements and occluders.

    Elements that are flat quads, triangles or circular disk patches, or the outsides of whole round
    spheres (through their silhouette disks, for queries none of whose candidate occluders reaches
    inside the sphere: `sphere_target`), can be exact targets, and for gathered points (`exact`
    with points) the outsides of round sphere patches (their disks cut to the patch); occluders
    that are whole spheres or ellipsoids, flat quads or triangles, circular disk patches or round
    cylinder patches cast exact shadows, and twisted quads for gathered points that see them
    unfolded (`exact`). A (point, element)
    query is exact when its target can be and every candidate occluder of it can.

    Parameters
    ----------
    elements : sequence of Surface, length N
        One patch per element.
    occluders : sequence of Surface, length M
    """

    def __init__(self, elements, occluders):
        N, M = len(elements), len(occluders)
        self.polygon_target = np.zeros(N, dtype=bool)
        self.sector_target = np.zeros(N, dtype=bool)
        self.corners = np.zeros((N, 4, 3))
        self.normal = np.zeros((N, 3))
        self.center = np.zeros((N, 3))
        self.e1 = np.zeros((N, 3))
        self.radii = np.zeros((N, 2))
        self.angles = np.zeros((N, 2))
        flat = QuadGeometry.flat_patches(elements)
        if flat:  # (as `flat_polygon`, all at once)
            corners, normal = QuadGeometry.patch_frames([elements[k] for k in flat])
            self.polygon_target[flat] = True
            self.corners[flat] = corners
            self.normal[flat] = normal / np.linalg.norm(normal, axis=1)[:, None]
        for k, surface in enumerate(elements):
            sector = flat_sector(surface) if not self.polygon_target[k] else None
            if sector is not None:
                self.sector_target[k] = True
                self.center[k], self.normal[k], self.e1[k], self.radii[k], self.angles[k] = sector
        # whole spheres seen from outside: their silhouette disk from each point (`sphere_target`);
        # sphere patches: that disk cut to the patch (`SpherePatchTargets`), in gathers only
        self.sphere_target = np.zeros(N, dtype=bool)
        self.patch_target = np.zeros(N, dtype=bool)
        self.patch_local, self.patch_box = np.zeros((N, 3, 3)), np.zeros((N, 4))
        sphere_center, sphere_radius = np.zeros((N, 3)), np.zeros(N)
        for k, surface in enumerate(elements):
            if self.polygon_target[k] or self.sector_target[k]:
                continue
            sphere = round_sphere(surface)
            part = sphere_patch(surface) if sphere is None else None
            if part is not None:
                sphere = part[:2]
                self.patch_target[k] = True
                self.patch_local[k], self.patch_box[k] = part[2:]
            if sphere is not None:
                self.sphere_target[k] = True
                sphere_center[k], sphere_radius[k] = sphere
        self.target = self.polygon_target | self.sector_target | self.sphere_target
        # bounding balls: targets (polygon corners, sector's disk, the sphere) and occluders
        self.target_center = np.select(
            [self.sector_target[:, None], self.sphere_target[:, None]],
            [self.center, sphere_center],
            self.corners.mean(1),
        )
        spread = np.linalg.norm(self.corners - self.corners.mean(1)[:, None], axis=-1).max(1)
        self.target_radius = np.select(
            [self.sector_target, self.sphere_target], [self.radii[:, 1], sphere_radius], spread
        )
        self.sphere = np.zeros(M, dtype=bool)
        self.polygon = np.zeros(M, dtype=bool)
        self.linear = np.zeros((M, 3, 3))
        self.offset = np.zeros((M, 3))
        self.polygon_corners = np.zeros((M, 4, 3))
        self.mesh = np.zeros(M, dtype=bool)
        self.twisted = np.zeros(M, dtype=bool)  # twisted quads (`bilinear`): two triangles a query
        self.twisted_corners = np.zeros((M, 4, 3))
        self.disk = np.zeros(M, dtype=bool)
        self.disk_frame = [np.zeros((M, w)) for w in SHAPES["disk"][1]]
        self.cylinder = np.zeros(M, dtype=bool)
        self.cylinder_frame = [np.zeros((M,) + ((w,) if w > 1 else ())) for w in SHAPES["cylinder"][1]]
        pieces, piece_of = [np.zeros((0, 4, 3))], [np.zeros(0, np.int64)]
        self.mesh_orientation = np.zeros(M, dtype=np.int64)  # `PolygonMesh.orientation` (0: none)
        # meshes exact as their facets only (too many pieces of their own): exact in gathers,
        # not in element pairs (a subdivided box's lamp pairs took 75 s at tol 1e-3 in the mesh
        # room, and the gathered points carry the shadow's detail)
        self.gather_only = np.zeros(M, dtype=bool)
        self.mesh_first = np.zeros(M, dtype=np.int64)  # the mesh's pieces: a contiguous run
        self.mesh_pieces_count = np.zeros(M, dtype=np.int64)
        neighbours = [np.zeros((0, 4), np.int64)]
        mesh_center, mesh_radius = {}, {}
        for m, surface in enumerate(occluders):
            if not isinstance(surface, Surface):
                # a polygon mesh: its flat pieces are polygon occluders (a closed convex solid's:
                # its facets, `PolygonMesh.solid_facets`)
                facets = surface.solid_facets() if hasattr(surface, "solid_facets") else None
                if facets is not None:
                    self.gather_only[m] = len(surface.piece_corners) > MESH_PIECES
                    surface = facets
                corners = getattr(surface, "piece_corners", None)
                if corners is not None and 0 < len(corners) <= MESH_PIECES:
                    self.mesh[m] = True
                    across = surface.piece_neighbours
                    self.mesh_orientation[m] = surface.orientation
                    self.mesh_first[m], self.mesh_pieces_count[m] = sum(map(len, pieces)), len(corners)
                    neighbours.append(np.where(across >= 0, across + self.mesh_first[m], -1))
                    pieces.append(corners)
                    piece_of.append(np.full(len(corners), m))
                    flat = corners.reshape(-1, 3)
                    mesh_center[m] = 0.5 * (flat.min(0) + flat.max(0))
                    mesh_radius[m] = np.linalg.norm(flat - mesh_center[m], axis=1).max()
                continue
            quad = bilinear_corners(surface)
            if quad is not None:
                self.twisted[m] = True
                self.twisted_corners[m] = quad
                continue
            kind, fields = occluder_shape(surface)
            if kind == "sphere":
                self.sphere[m] = True
                self.linear[m], self.offset[m] = fields
            elif kind == "polygon":
                self.polygon[m] = True
                self.polygon_corners[m] = fields
            elif kind in ("disk", "cylinder"):
                getattr(self, kind)[m] = True
                for array, value in zip(getattr(self, kind + "_frame"), fields):
                    array[m] = value
        self.exact_occluder = self.sphere | self.polygon | self.mesh | self.twisted
        self.exact_occluder |= self.disk | self.cylinder
        # the meshes' pieces: corners (Q, 4, 3), mesh, front normal, bounding ball
        self.piece_corners = np.concatenate(pieces)
        self.piece_of = np.concatenate(piece_of)
        self.piece_neighbours = np.concatenate(neighbours)  # (Q, 4): the piece across each edge, -1 none
        self._piece_bvh = None
        C = self.piece_corners
        self.piece_normal = np.cross(C[:, 2] - C[:, 0], C[:, 3] - C[:, 1])
        self.piece_center = C.mean(1)
        self.piece_radius = (
            np.linalg.norm(C - self.piece_center[:, None], axis=-1).max(1) if len(C) else np.zeros(0)
        )
        sizes = np.linalg.svd(self.linear, compute_uv=False) if M else np.zeros((0, 3))
        self.inverse = np.linalg.inv(np.where(self.sphere[:, None, None], self.linear, np.eye(3)))
        polygon_center = self.polygon_corners.mean(1)
        polygon_radius = np.linalg.norm(self.polygon_corners - polygon_center[:, None], axis=-1).max(1)
        for m in mesh_center:  # a mesh's ball holds its pieces' corners
            polygon_center[m], polygon_radius[m] = mesh_center[m], mesh_radius[m]
        # a twisted quad's ball holds its corners (its hull)
        twisted = self.twisted_corners[self.twisted]
        polygon_center[self.twisted] = center = twisted.mean(1)
        polygon_radius[self.twisted] = np.linalg.norm(twisted - center[:, None], axis=-1).max(1, initial=0.0)
        # a cylinder patch's ball: round its axial span's midpoint
        center, axis, _, radius, _, heights = self.cylinder_frame
        half = 0.5 * (heights[:, 1] - heights[:, 0])
        cylinder_center = center + 0.5 * (heights[:, 0] + heights[:, 1])[:, None] * axis
        self.occluder_center = np.select(
            [self.sphere[:, None], self.disk[:, None], self.cylinder[:, None]],
            [self.offset, self.disk_frame[0], cylinder_center],
            polygon_center,
        )
        self.occluder_radius = np.select(
            [self.sphere, self.disk, self.cylinder],
            [sizes.max(1) if M else np.zeros(0), self.disk_frame[3][:, 1], np.hypot(radius, half)],
            polygon_radius,
        )
        # true spheres (not ellipsoids) can be proved to hide a target wholly
        self.round = self.sphere & (sizes.max(1) - sizes.min(1) <= 1e-12 * sizes.max(1) if M else False)
        # the (sphere target, occluder) pairs where the occluder reaches inside the sphere (its disk
        # does not stand for it there), as sorted keys element * M + occluder
        self.cut_keys = self._cuts(np.flatnonzero(self.sphere_target))

    def _cuts(self, spheres):
        """Keys element * M + occluder of the exact occluders that reach inside the sphere targets
        `spheres` (S,), sorted (conservatively: by lower bounds of their distance to the centre; a
        mesh by its pieces). Bounding balls first, CUT_BLOCK entries at a time."""
        M = len(self.exact_occluder)
        found = [np.zeros(0, dtype=np.int64)]
        step = max(1, CUT_BLOCK // max(M, 1))
        for start in range(0, spheres.size if M else 0, step):
            block = spheres[start : start + step]
            gap = np.linalg.norm(self.target_center[block][:, None] - self.occluder_center[None], axis=-1)
            reach = self.target_radius[block][:, None] + self.occluder_radius[None]
            s, m = np.nonzero(self.exact_occluder[None] & (gap < reach))
            if s.size:
                cut = self._reaches_inside(block[s], m)
                found.append(block[s[cut]] * M + m[cut])
        return np.sort(np.concatenate(found))

    def _reaches_inside(self, k, m):
        """Whether exact occluders m reach inside sphere targets k (each (C,)), shape (C,) bool."""
        center, radius = self.target_center[k], self.target_radius[k]
        distance = np.full(k.size, np.inf)
        for kind, mask, fields in (
            ("sphere", self.sphere, (self.linear, self.offset)),
            ("polygon", self.polygon, (self.polygon_corners,)),
            ("disk", self.disk, self.disk_frame),
            ("cylinder", self.cylinder, self.cylinder_frame),
        ):
            sel = np.flatnonzero(mask[m])
            if sel.size:
                distance[sel] = SHAPES[kind][2](center[sel], *(f[m[sel]] for f in fields))
        sel = np.flatnonzero(self.twisted[m])
        if sel.size:  # (a twisted quad lies in its corners' tetrahedron)
            distance[sel] = tetrahedron_distance(center[sel], self.twisted_corners[m[sel]])
        sel = np.flatnonzero(self.mesh[m])
        if sel.size:  # every piece of each mesh
            owner, piece = self._pieces_of(m[sel])
            to_piece = polygon_distance(center[sel][owner], self.piece_corners[piece])
            nearest = np.full(sel.size, np.inf)
            np.minimum.at(nearest, owner, to_piece)
            distance[sel] = nearest
        return distance < (1.0 - INSIDE) * radius

    def exact(self, j, candidates, points=None):
        """Which queries (target elements j, candidate occluders (K, M)) are exact, shape (K,):
        the target and every candidate covered, at most MAX_OCCLUDERS candidates (a mesh
        counting as one; the curved kinds' classification loops over them), and of a sphere
        target no candidate reaching inside it.

        A twisted quad candidate needs the query's point (`points`, (K, 3): a gather's): it is
        exact when the point sees it unfolded, from outside its corners' tetrahedron (`bilinear`),
        and the tetrahedron lies on the point's side of a flat target's plane (of a sphere
        target, outside the sphere: `cut_keys`). Without points (element pairs) it is not, nor
        a mesh exact as its facets only (`gather_only`), nor a sphere patch target."""
        covered = ~np.any(candidates & ~self.exact_occluder[None], axis=1)
        ok = self.target[j] & covered & (candidates.sum(1) <= MAX_OCCLUDERS)
        if points is None:
            # (element pairs toward sphere patches keep rays: a patch's lines cost ~10x a whole
            # sphere's closed form, and the gathered points carry the shadow's detail)
            ok &= ~np.any(candidates & self.gather_only[None], axis=1) & ~self.patch_target[j]
        twisted = candidates & self.twisted[None]
        rows = np.flatnonzero(ok & twisted.any(1))
        if rows.size:
            if points is None:
                ok[rows] = False
            else:
                q, m = np.nonzero(twisted[rows])
                q = rows[q]
                ok[q[~self._twisted_clear(points[q], j[q], m)]] = False
        if self.cut_keys.size:
            q, m = np.nonzero(candidates & self.sphere_target[j][:, None])
            key = j[q] * candidates.shape[1] + m
            at = np.minimum(np.searchsorted(self.cut_keys, key), self.cut_keys.size - 1)
            ok[q[self.cut_keys[at] == key]] = False
        return ok

    def _twisted_clear(self, x, j, m):
        """`exact`'s test of twisted quads m (C,) seen from points x (C, 3) toward targets j (C,)."""
        corners = self.twisted_corners[m]
        ok = fold_free(x, corners)
        flat = np.flatnonzero(self.polygon_target[j] | self.sector_target[j])
        if flat.size:
            t = j[flat]
            normal, point = self.normal[t], self.target_center[t]
            side = plane_side(corners[flat], point, normal)
            ok[flat] &= (side != 0) & (side == np.sign(np.einsum("ci,ci->c", x[flat] - point, normal)))
        return ok

    def target_planes(self, x, j):
        """(point, unit normal) of each query's target plane, shapes (K, 3): a flat target's own, a
        sphere target's silhouette disk's plane from x."""
        point, normal = self.target_center[j].copy(), self.normal[j].copy()
        sphere = np.flatnonzero(self.sphere_target[j])
        if sphere.size:
            q = j[sphere]
            point[sphere], normal[sphere] = silhouette_planes(
                x[sphere], self.target_center[q], self.target_radius[q]
            )
        return point, normal

    def clear(self, a, b, candidates):
        """`candidates` (K, M) of element pairs (a, b), without the occluders that a plane of the
        convex hull of two flat patches separates from the pair (their bounding balls lie wholly
        beyond a face of the hull: no segment between the patches can meet them).

        The hull's faces are among the planes through an edge of one patch and a corner of the
        other, and the patches' own planes; a plane is a face when all eight corners lie on one
        side of it (shaft culling, Haines & Wallace 1994, with the exact hull of two polygons).
        Only occluders of the exact kinds (whose balls are known here) are dropped.
        """
        flat = np.flatnonzero(self.polygon_target[a] & self.polygon_target[b] & candidates.any(1))
        if flat.size == 0:
            return candidates
        A, B = self.corners[a[flat]], self.corners[b[flat]]  # (F, 4, 3)
        points = np.concatenate([A, B], 1)  # (F, 8, 3)
        planes = []
        for P, Q in ((A, B), (B, A)):
            edge = np.roll(P, -1, axis=1) - P  # (F, 4, 3)
            normal = np.cross(edge[:, :, None], Q[:, None] - P[:, :, None])  # (F, 4, 4, 3)
            planes.append((normal.reshape(len(flat), -1, 3), np.repeat(P, 4, axis=1)))
            own = np.cross(P[:, 1] - P[:, 0], P[:, 2] - P[:, 0]) + np.cross(
                P[:, 2] - P[:, 0], P[:, 3] - P[:, 0]
            )
            planes.append((own[:, None], P[:, :1]))
        normal = np.concatenate([p[0] for p in planes], 1)  # (F, 34, 3)
        origin = np.concatenate([p[1] for p in planes], 1)
        length = np.linalg.norm(normal, axis=-1)
        unit = normal / np.maximum(length, 1e-300)[..., None]
        side = np.einsum("fpi,fki->fpk", unit, points) - np.einsum("fpi,fpi->fp", unit, origin)[..., None]
        scale = np.linalg.norm(points - points.mean(1, keepdims=True), axis=-1).max(1)[:, None]
        slack = 1e-12 * scale
        below, above = np.all(side <= slack[..., None], -1), np.all(side >= -slack[..., None], -1)
        face = (length > 1e-300) & (below | above)
        unit = np.where(above[..., None], -unit, unit)  # the hull on the negative side
        offset = np.einsum("fpi,fpi->fp", unit, origin)
        row, m = np.nonzero(candidates[flat])
        # (only occluders with a known ball: the others keep their candidacy)
        known = self.exact_occluder[m]
        row, m = row[known], m[known]
        beyond = np.einsum("rpi,ri->rp", unit[row], self.occluder_center[m]) - offset[row]
        separated = np.any(face[row] & (beyond >= self.occluder_radius[m][:, None] + slack[row]), 1)
        out = candidates.copy()
        out[flat[row[separated]], m[separated]] = False
        return out

    def visible(self, x, n, j, candidates, tol):
        """F(x -> visible part of element j) for exact queries, shape (K,), where no occluder casts a
        shadow (`free`, shape (K,): F is then not computed), and the lines spent.

        Parameters
        ----------
        x, n : ndarray, shape (K, 3)
            Points and unit normals.
        j : ndarray of int, shape (K,)
        candidates : ndarray of bool, shape (K, M)
            The occluders that may block each query (all of them exact kinds).
        """
        F = np.zeros(len(x))
        free, candidates = self._classify(x, j, candidates)
        hidden = ~free & ~candidates.any(1)
        row, piece, edges = self.mesh_pieces(x, j, candidates)
        candidates = candidates & ~self.mesh[None]
        shaded = np.zeros(len(x), dtype=bool)
        shaded[row] = True
        free = ~hidden & ~candidates.any(1) & ~shaded
        lines = 0
        for kind in (
            self.polygon_target,
            self.sector_target,
            self.sphere_target & ~self.patch_target,
            self.patch_target,
        ):
            sel = np.flatnonzero(kind[j] & (candidates.any(1) | shaded))
            if sel.size == 0:
                continue
            q = j[sel]
            if kind is self.polygon_target:
                targets = FlatTargets(self.corners[q], self.normal[q])
            elif kind is self.sector_target:
                targets = SectorTargets(
                    self.center[q], self.normal[q], self.e1[q], self.radii[q], self.angles[q]
                )
            elif kind is self.patch_target:
                targets = SpherePatchTargets(
                    x[sel],
                    self.target_center[q],
                    self.target_radius[q],
                    self.patch_local[q],
                    self.patch_box[q],
                )
            else:
                targets = silhouette_disks(x[sel], self.target_center[q], self.target_radius[q])
            spheres = candidates[sel][:, : len(self.sphere)] & self.sphere[None]
            linear, sphere_valid = _padded(spheres, self.linear, fill=np.eye(3))  # (invertible padding)
            inverse, _ = _padded(spheres, self.inverse, fill=np.eye(3))
            offset, _ = _padded(spheres, self.offset)
            # flat polygon occluders, then the mesh pieces of these queries
            flat_row, flat = np.nonzero(candidates[sel] & self.polygon[None])
            at = np.minimum(np.searchsorted(sel, row), sel.size - 1)
            mine = sel[at] == row
            # twisted quads: the two triangles each point sees as their shadow (`bilinear`)
            twisted_row, twisted = np.nonzero(candidates[sel] & self.twisted[None])
            triangles, triangle_edges = triangle_pairs(x[sel][twisted_row], self.twisted_corners[twisted])
            polygon_row = np.concatenate([flat_row, at[mine], np.repeat(twisted_row, 2)])
            corners, polygon_valid = _padded_rows(
                sel.size,
                polygon_row,
                np.concatenate(
                    [
                        self.polygon_corners[flat],
                        self.piece_corners[piece[mine]],
                        triangles.reshape(-1, 4, 3),
                    ]
                ),
            )
            polygon_edges, _ = _padded_rows(
                sel.size,
                polygon_row,
                np.concatenate(
                    [np.ones((flat.size, 4), dtype=bool), edges[mine], triangle_edges.reshape(-1, 4)]
                ),
                False,
            )
            disks_of = candidates[sel][:, : len(self.disk)] & self.disk[None]
            frame = [_padded(disks_of, array)[0] for array in self.disk_frame]
            disks = Disks(*frame, _padded(disks_of, self.disk_frame[3])[1])
            cylinders_of = candidates[sel][:, : len(self.cylinder)] & self.cylinder[None]
            frame = [_padded(cylinders_of, array)[0] for array in self.cylinder_frame]
            cylinders = Cylinders(*frame, _padded(cylinders_of, self.cylinder_frame[3])[1])
            blockers = Blockers(
                linear,
                offset,
                sphere_valid,
                corners,
                polygon_valid,
                sphere_inverse=inverse,
                disks=disks,
                cylinders=cylinders,
                polygon_edges=polygon_edges,
            )
            F[sel], _, count = visible_factor(
                x[sel], n[sel], targets, blockers, np.broadcast_to(tol, len(x))[sel]
            )
            lines += count
        return F, free, lines

    @property
    def piece_bvh(self):
        """A `bvh.BVH` over the meshes' pieces (object id: the mesh), built on first use."""
        if self._piece_bvh is None:
            self._piece_bvh = BVH.from_primitives(quads=self.piece_corners, object_id=self.piece_of)
        return self._piece_bvh

    def mesh_pieces(self, x, j, candidates):
        """The mesh pieces that may cast a shadow of each query, as pairs (row, piece), each shape
        (C,), sorted by row, and which edges of each piece may bound the union of the query's
        shadows, shape (C, 4) bool.

        The pieces are those of a candidate mesh whose bounding ball meets the capsule around the
        segment from x to the target's ball centre, of the target's radius (it holds the cone from x
        to the target: `bvh.BVH.shaft_candidates`), whose cone from x meets the target's, less pieces
        in or behind the target's plane and pieces whose plane holds x. Of a closed mesh (every edge
        shared by two consistently oriented pieces) only the pieces on one side count: a segment from
        x that crosses the mesh first enters the region it bounds if x is outside (winding number 0),
        or leaves it if inside, so the pieces x sees from the front if the fronts face x's side of the
        boundary (`mesh_orientation`: +1 fronts facing out), from the back otherwise.

        An edge between two of a query's pieces that x sees from the same side lies inside the union
        of their shadows (their cones lie on either side of its plane through x), so its trace, and a
        corner all of whose edges are such, is no break of the shadow across lines: only silhouette
        edges (between pieces seen from opposite sides, or with no such neighbour) are.
        """
        none = np.zeros(0, dtype=np.int64)
        meshes = np.flatnonzero(np.any(candidates & self.mesh[None], 1))
        if meshes.size == 0:
            return none, none, np.zeros((0, 4), dtype=bool)
        xm, center, radius = x[meshes], self.target_center[j[meshes]], self.target_radius[j[meshes]]
        lo = np.minimum(xm, center - radius[:, None])
        hi = np.maximum(xm, center + radius[:, None])
        k, p = self.piece_bvh.shaft_candidates(lo, hi, xm, center, radius)
        k = meshes[k]
        keep = candidates[k, self.piece_of[p]]
        k, p = k[keep], p[keep]
        # a piece in or behind the target's plane blocks nothing on it (a target that is part of a
        # piece is not shadowed by that piece's rounding), nor one whose plane holds x (the piece x
        # lies on): both within PLANE_SLACK of the sizes involved
        plane_point, plane_normal = self.target_planes(x[k], j[k])
        heights = np.einsum("kci,ki->kc", self.piece_corners[p] - plane_point[:, None], plane_normal)
        behind = heights.max(1) <= PLANE_SLACK * (self.target_radius[j[k]] + self.piece_radius[p])
        length = np.linalg.norm(self.piece_normal[p], axis=1)
        lift = np.einsum("ki,ki->k", x[k] - self.piece_center[p], self.piece_normal[p])
        holds_x = np.abs(lift) <= PLANE_SLACK * self.piece_radius[p] * length
        k, p = k[~behind & ~holds_x], p[~behind & ~holds_x]
        facing = np.einsum("ki,ki->k", x[k] - self.piece_center[p], self.piece_normal[p]) > 0.0
        # a closed mesh: a segment from x that crosses it first enters the region it bounds if x is
        # outside (winding number 0), leaves it if inside (winding number = the orientation: +1 for
        # fronts facing out); only the pieces x sees from that side count
        key, group = np.unique(k * len(self.mesh) + self.piece_of[p], return_inverse=True)
        orientation = self.mesh_orientation[key % len(self.mesh)]
        closed = orientation != 0
        inside = np.full(key.size, 0.5)  # (open meshes, and x on a closed one: every piece counts)
        inside[closed] = orientation[closed] * self._winding(
            x[key[closed] // len(self.mesh)], key[closed] % len(self.mesh)
        )
        fronts = np.where(
            np.abs(inside) < 0.25, orientation, np.where(np.abs(inside - 1.0) < 0.25, -orientation, 0)
        )
        fronts = fronts[group]  # +1: the pieces x sees from the front, -1: from the back, 0: all
        keep = (fronts == 0) | ((fronts > 0) == facing)
        k, p, facing = k[keep], p[keep], facing[keep]
        keep = ~cones_apart(
            x[k],
            self.target_center[j[k]],
            self.target_radius[j[k]],
            self.piece_center[p],
            self.piece_radius[p],
        )
        k, p, facing = k[keep], p[keep], facing[keep]
        # silhouettes: an edge is interior where its neighbour is a piece of the same query seen from
        # the same side
        Q = len(self.piece_corners)
        key = k * Q + p  # sorted (k, then p)
        across = self.piece_neighbours[p]  # (C, 4)
        wanted = k[:, None] * Q + across
        at = np.minimum(np.searchsorted(key, wanted), max(key.size - 1, 0))
        interior = (across >= 0) & (key[at] == wanted) & (facing[at] == facing[:, None])
        return k, p, ~interior

    def _pieces_of(self, m):
        """Every piece of the meshes m (C,), as pairs (owner: index into m, piece), each shape (T,)."""
        return ragged.expand(self.mesh_first[m], self.mesh_pieces_count[m])

    def _winding(self, x, m):
        """Winding numbers of closed meshes m about points x, each shape (C,): the solid angle their
        pieces subtend, over 4 pi (the triangles (0, 1, 2) and (0, 2, 3) of each piece; Van Oosterom
        & Strackee, "The solid angle of a plane triangle", IEEE Trans. Biomed. Eng. 30(2), 1983)."""
        owner, piece = self._pieces_of(m)
        C = self.piece_corners[piece] - x[owner][:, None]  # (T, 4, 3)
        total = np.zeros(owner.size)
        for a, b, c in ((0, 1, 2), (0, 2, 3)):
            A, B, D = C[:, a], C[:, b], C[:, c]
            la, lb, ld = (np.linalg.norm(v, axis=1) for v in (A, B, D))
            num = np.einsum("ti,ti->t", A, np.cross(B, D))
            den = la * lb * ld + np.einsum("ti,ti->t", A, B) * ld + np.einsum("ti,ti->t", A, D) * lb
            den += np.einsum("ti,ti->t", B, D) * la
            total += 2.0 * np.arctan2(num, den)
        return np.bincount(owner, total, len(m)) / (4.0 * np.pi)

    def hides_cells(self, points, margin, j, candidates):
        """Whether one round sphere among `candidates` (C, M) blocks every segment from a cell
        (within `margin` (C,) of the convex hull of `points` (C, H, 3)) to the flat polygon
        target j (C,): (provable, hidden), each shape (C,); provable marks the queries this test
        applies to (a polygon target and a round sphere among the candidates).

        A convex body that meets the segments p1 q and p2 q meets every segment p q with p
        between p1 and p2 (the chord between the two meeting points crosses p q inside the
        triangle p1 p2 q), so by induction it blocks every segment between two convex hulls once
        it blocks the segments between their vertices. The sphere shrunk by the margin is tested
        that way: a segment's distance to its centre moves by at most the larger shift of its
        ends."""
        out = np.zeros(len(points), dtype=bool)
        provable = self.polygon_target[j] & np.any(candidates & self.round[None], 1)
        rows = np.flatnonzero(provable)
        if rows.size == 0:
            return provable, out
        q, m = np.nonzero(candidates[rows] & self.round[None])
        a = points[rows[q]][:, :, None]  # (Q, H, 1, 3)
        d = self.corners[j[rows[q]]][:, None] - a  # (Q, H, 4, 3)
        o = self.occluder_center[m][:, None, None]
        along = np.einsum("qhci,qhci->qhc", o - a, d)
        t = np.clip(along / np.maximum(np.einsum("qhci,qhci->qhc", d, d), 1e-300), 0.0, 1.0)
        gap = np.linalg.norm(a + t[..., None] * d - o, axis=-1)
        inside = self.occluder_radius[m] * (1.0 - 1e-9) - margin[rows[q]]
        hides = np.all(gap < inside[:, None, None], (1, 2))
        out[rows[q[hides]]] = True
        return provable, out

    def clears_cells(self, points, margin, j, candidates):
        """Whether no occluder among `candidates` (C, M) can meet a segment from a cell (within
        `margin` (C,) of the convex hull of `points` (C, H, 3)) to target j (C,), shape (C,):
        every candidate's bounding ball lies beyond a plane that has the cell and the target on
        its other side (`_clear_of_hull`; a polygon target by its corners, others by their
        bounding balls)."""
        clear = np.ones(len(points), dtype=bool)
        q, m = np.nonzero(candidates)
        if q.size == 0:
            return clear
        jq = j[q]
        H = points.shape[1]
        polygon = self.polygon_target[jq]
        target = np.where(polygon[:, None, None], self.corners[jq], self.target_center[jq][:, None])
        spread = np.where(polygon[:, None], 0.0, self.target_radius[jq][:, None])
        hull = np.concatenate([points[q], target], 1)
        grown = np.concatenate([np.repeat(margin[q][:, None], H, 1), np.broadcast_to(spread, (q.size, 4))], 1)
        apart = _clear_of_hull(self.occluder_center[m], self.occluder_radius[m], hull, grown)
        clear[q[~apart]] = False
        return clear

    def _classify(self, x, j, candidates):
        """Cones of directions from x (bounding balls): occluders whose cone misses the target's
        cast no shadow on it (dropped from `candidates`); a round sphere whose cone holds the
        target's, nearer than the target, hides it wholly. Returns (free, candidates): free
        (K,) marks queries with no shadow left; hidden queries keep no candidates and F = 0."""
        q, m = np.nonzero(candidates)
        rt, ro = self.target_radius[j[q]], self.occluder_radius[m]
        alpha, beta, gamma, wide = cone_angles(
            x[q], self.target_center[j[q]], rt, self.occluder_center[m], ro
        )
        dt = np.linalg.norm(self.target_center[j[q]] - x[q], axis=1)
        do = np.linalg.norm(self.occluder_center[m] - x[q], axis=1)
        misses = ~wide & (gamma > alpha + beta + 1e-9)
        hides = ~wide & self.round[m] & (gamma + beta < alpha - 1e-9) & (dt - rt > do)
        hidden = np.zeros(len(x), dtype=bool)
        hidden[q[hides]] = True
        candidates = candidates.copy()
        candidates[q[misses], m[misses]] = False
        candidates[hidden] = False
        free = ~candidates.any(1) & ~hidden
        return free, candidates


def _padded(mask, array, fill=0.0):
    """Each row's selected entries of `array` (M, ...), padded to the longest row: (K, W, ...),
    `fill` where a row has fewer, and the validity mask (K, W)."""
    row, col = np.nonzero(mask)
    return _padded_rows(len(mask), row, array[col], fill)


def _padded_rows(K, row, values, fill=0.0):
    """`values` (C, ...) grouped by `row` (C,) into rows 0 .. K - 1 (in their order within a row),
    padded to the longest row: (K, W, ...), `fill` where a row has fewer, and the validity mask
    (K, W)."""
    order = np.argsort(row, kind="stable")
    row = row[order]
    count = np.bincount(row, minlength=K)
    W = int(count.max()) if K else 0
    slot = ragged.local(count)
    padded = np.empty((K, W) + values.shape[1:], dtype=values.dtype)
    padded[:] = fill
    padded[row, slot] = values[order]
    valid = np.zeros((K, W), dtype=bool)
    valid[row, slot] = True
    return padded, valid


def _clear_of_hull(centre, radius, hull, grown, steps=HULL_STEPS):
    """Whether balls (centre (K, 3), radius (K,)) lie wholly beyond a plane that leaves the
    balls of radius `grown` (K, V) about the points `hull` (K, V, 3) on its other side, shape
    (K,). For any unit n, min_i n . (centre - p_i) - grown_i bounds the centre's distance to the
    hull of those balls from below; n is taken from the centre to the iterates y = sum_i l_i p_i
    of the pairwise Frank-Wolfe method for the hull's nearest point (weight moved from the worst
    point in use to the best one, exact line search; linear convergence on a polytope: Lacoste-
    Julien & Jaggi, "On the global linear convergence of Frank-Wolfe optimization variants", NIPS
    2015), the best bound kept. A row stops once proven, or once a point of the hull of balls
    (the ball of radius sum_i l_i grown_i about y lies in it) is within `radius` of the centre.

    (The plain method, 8 steps, left 88 % of the open cube's cells beside the sphere's shadow
    unproven, each then split twice more: BENCHMARKS.md "Cells proven clear".)"""
    best = np.full(len(centre), -np.inf)
    rows = np.arange(len(centre))
    weight = np.full(hull.shape[:2], 1.0 / hull.shape[1])
    y = hull.mean(1)
    limit = radius
    for _ in range(steps):
        to = centre - y
        distance = np.linalg.norm(to, axis=1)
        n = to / np.maximum(distance, 1e-300)[:, None]
        reach = np.einsum("ki,kvi->kv", n, centre[:, None] - hull) - grown
        bound = np.maximum(best[rows], reach.min(1))
        best[rows] = bound
        open_ = (bound <= limit) & (distance - np.einsum("kv,kv->k", weight, grown) > limit)
        if not open_.all():
            rows, centre, limit = rows[open_], centre[open_], limit[open_]
            hull, grown, weight, y = hull[open_], grown[open_], weight[open_], y[open_]
            if rows.size == 0:
                break
        k = np.arange(rows.size)
        slope = np.einsum("kvi,ki->kv", hull, y - centre)
        to_best = slope.argmin(1)
        from_worst = np.where(weight > 0.0, slope, -np.inf).argmax(1)
        d = hull[k, to_best] - hull[k, from_worst]
        step = np.clip(
            np.einsum("ki,ki->k", centre - y, d) / np.maximum(np.einsum("ki,ki->k", d, d), 1e-300),
            0.0,
            weight[k, from_worst],
        )
        weight[k, to_best] += step
        weight[k, from_worst] -= step
        y = y + step[:, None] * d
    return best > radius
