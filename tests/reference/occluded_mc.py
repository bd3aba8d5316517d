"""Independent reference for occluded form factors: randomised quasi-Monte Carlo with exact ray tests.

Shares no code with core/: points are sampled uniformly on parallelogram and triangle patches
(given by corners), segments are tested against spheres (closest point of the segment to the
centre), against triangles (Moeller & Trumbore, J. Graphics Tools 2(1), 1997), against bilinear
patches (the quadratic left after eliminating one parameter), against flat
disk sectors (the segment's crossing of the disk's plane, its distance and angle from the centre)
and against round cylinder patches (the roots of the segment's quadratic across the axis, their
heights and angles) written here from scratch, and the error bar comes from independent random
shifts of a Halton point set (Cranley & Patterson, SIAM J. Numer. Anal. 13:904, 1976): mean of the
shifted estimates and the standard error of that mean.
"""

import numpy as np

_PRIMES = (2, 3, 5, 7, 11, 13)


def halton(count, dims):
    """First `count` points of the Halton sequence in [0, 1)^dims, shape (count, dims)."""
    out = np.zeros((count, dims))
    index = np.arange(1, count + 1)
    for d in range(dims):
        base = _PRIMES[d]
        f, i, value = 1.0, index.copy(), np.zeros(count)
        while np.any(i > 0):
            f /= base
            value += f * (i % base)
            i //= base
        out[:, d] = value
    return out


def parallelogram(corner, edge_u, edge_v, s, t):
    """Points corner + s edge_u + t edge_v, their unit normal (edge_u x edge_v) and area."""
    normal = np.cross(edge_u, edge_v)
    area = np.linalg.norm(normal)
    return corner + s[:, None] * edge_u + t[:, None] * edge_v, normal / area, area


def segment_hits_sphere(p, q, center, radius):
    d = q - p
    t = np.clip(np.einsum("ki,ki->k", center - p, d) / np.einsum("ki,ki->k", d, d), 0.0, 1.0)
    gap = p + t[:, None] * d - center
    return np.einsum("ki,ki->k", gap, gap) < radius * radius


def segment_hits_triangle(p, q, a, b, c):
    d = q - p
    e1, e2 = b - a, c - a
    h = np.cross(d, e2)
    det = h @ e1
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / det
        s = p - a
        u = np.einsum("ki,ki->k", s, h) * inv
        qv = np.cross(s, e1)
        v = np.einsum("ki,ki->k", qv, d) * inv
        t = (qv @ e2) * inv
    return (np.abs(det) > 1e-300) & (u > 0) & (v > 0) & (u + v < 1) & (t > 0) & (t < 1)


def segment_hits_disk(p, q, center, normal, radii, angles=None, start=None):
    """Segments p q crossing the flat sector {center + r (cos a e1 + sin a e2)}: r in radii, a in
    angles (from the unit vector `start` toward normal x start; None: the whole disk)."""
    normal = normal / np.linalg.norm(normal)
    hp, hq = (p - center) @ normal, (q - center) @ normal
    with np.errstate(divide="ignore", invalid="ignore"):
        t = hp / (hp - hq)
    c = p + t[:, None] * (q - p) - center
    r2 = np.einsum("ki,ki->k", c, c)
    hit = (hp * hq < 0) & (r2 <= radii[1] ** 2) & (r2 >= radii[0] ** 2)
    if angles is not None:
        e2 = np.cross(normal, start)
        angle = np.mod(np.arctan2(c @ e2, c @ start) - angles[0], 2 * np.pi)
        hit &= angle <= angles[1] - angles[0]
    return hit


def segment_hits_cylinder(p, q, center, axis, radius, heights, angles=None, start=None):
    """Segments p q meeting the lateral surface {center + s axis + radius (cos a e1 + sin a e2)}:
    s in heights, a in angles (from the unit vector `start` toward axis x start; None: all)."""
    axis = axis / np.linalg.norm(axis)
    d, a = q - p, p - center
    d_across = d - np.outer(d @ axis, axis)
    a_across = a - np.outer(a @ axis, axis)
    A = np.einsum("ki,ki->k", d_across, d_across)
    B = 2.0 * np.einsum("ki,ki->k", a_across, d_across)
    C = np.einsum("ki,ki->k", a_across, a_across) - radius * radius
    disc = B * B - 4.0 * A * C
    hit = np.zeros(len(p), dtype=bool)
    with np.errstate(divide="ignore", invalid="ignore"):
        for sign in (-1.0, 1.0):
            t = (-B + sign * np.sqrt(np.maximum(disc, 0.0))) / (2.0 * A)
            point = a + t[:, None] * d
            s = point @ axis
            ok = (disc >= 0) & (t > 0) & (t < 1) & (s >= heights[0]) & (s <= heights[1])
            if angles is not None:
                e2 = np.cross(axis, start)
                angle = np.mod(np.arctan2(point @ e2, point @ start) - angles[0], 2 * np.pi)
                ok &= angle <= angles[1] - angles[0]
            hit |= ok
    return hit


def segment_hits_bilinear(p, q, p00, p10, p11, p01):
    """Segments p q crossing the bilinear patch P(u, v) = (1-u)(1-v) p00 + u(1-v) p10 + uv p11
    + (1-u)v p01 at t in (1e-12, 1 - 1e-12): the line's two coordinates across its direction give
    two bilinear equations in (u, v); eliminating v leaves a quadratic in u (each real root in
    [0, 1] is checked for v in [0, 1] and t along the segment)."""
    d = q - p
    # two unit vectors across each segment's direction
    along_x = np.abs(d[:, :1]) >= 0.6 * np.linalg.norm(d, axis=1)[:, None]
    helper = np.where(along_x, [[0.0, 1.0, 0.0]], [[1.0, 0.0, 0.0]])
    e1 = np.cross(d, helper)
    e1 /= np.linalg.norm(e1, axis=1)[:, None]
    e2 = np.cross(d, e1)
    e2 /= np.linalg.norm(e2, axis=1)[:, None]
    a, b, c = p10 - p00, p01 - p00, p11 - p10 - p01 + p00
    coef = []  # (A + B u + C v + D u v = 0) across e1 and e2
    for e in (e1, e2):
        coef.append((((p00 - p) * e).sum(1), e @ a, e @ b, e @ c))
    (A1, B1, C1, D1), (A2, B2, C2, D2) = coef
    qa = B2 * D1 - D2 * B1
    qb = A2 * D1 + B2 * C1 - C2 * B1 - D2 * A1
    qc = A2 * C1 - C2 * A1
    hit = np.zeros(len(p), dtype=bool)
    disc = qb * qb - 4 * qa * qc
    linear = np.abs(qa) <= 1e-14 * (np.abs(qb) + np.abs(qc) + 1e-300)
    sq = np.sqrt(np.maximum(disc, 0.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        roots = [
            np.where(linear, -qc / qb, (-qb + sq) / (2 * qa)),
            np.where(linear, np.nan, (-qb - sq) / (2 * qa)),
        ]
    for u in roots:
        ok = np.isfinite(u) & (disc >= 0) & (u >= 0) & (u <= 1)
        with np.errstate(divide="ignore", invalid="ignore"):
            den1, den2 = C1 + D1 * u, C2 + D2 * u
            v = np.where(np.abs(den1) >= np.abs(den2), -(A1 + B1 * u) / den1, -(A2 + B2 * u) / den2)
        ok &= np.isfinite(v) & (v >= 0) & (v <= 1)
        u_, v_ = np.where(ok, u, 0)[:, None], np.where(ok, v, 0)[:, None]
        point = p00 + u_ * a + v_ * b + u_ * v_ * c
        t = ((point - p) * d).sum(1) / (d * d).sum(1)
        hit |= ok & (t > 1e-12) & (t < 1 - 1e-12)
    return hit


def blocked(p, q, spheres, triangles, disks=(), cylinders=(), bilinears=()):
    """Segments p q meeting any sphere (center, radius), triangle (a, b, c), disk sector
    (center, normal, radii[, angles, start]), cylinder patch (center, axis, radius, heights[,
    angles, start]) or bilinear patch (p00, p10, p11, p01), shape (K,) bool."""
    hit = np.zeros(len(p), dtype=bool)
    for quad in bilinears:
        hit |= segment_hits_bilinear(p, q, *(np.asarray(v, float) for v in quad))
    for center, radius in spheres:
        hit |= segment_hits_sphere(p, q, np.asarray(center, float), float(radius))
    for a, b, c in triangles:
        hit |= segment_hits_triangle(p, q, *(np.asarray(v, float) for v in (a, b, c)))
    for disk in disks:
        hit |= segment_hits_disk(p, q, *(None if v is None else np.asarray(v, float) for v in disk))
    for cylinder in cylinders:
        hit |= segment_hits_cylinder(p, q, *(None if v is None else np.asarray(v, float) for v in cylinder))
    return hit


def point_factor(
    x, n, target, spheres=(), triangles=(), count=1 << 18, shifts=8, seed=1, disks=(), cylinders=()
):
    """F(dA(x) -> parallelogram target) with occlusion: (mean, standard error).

    target = (corner, edge_u, edge_v); its front is edge_u x edge_v.
    """
    rng = np.random.default_rng(seed)
    base = halton(count, 2)
    estimates = []
    for _ in range(shifts):
        s, t = ((base + rng.random(2)) % 1.0).T
        y, ny, area = parallelogram(*(np.asarray(v, float) for v in target), s, t)
        r = y - x
        r2 = np.einsum("ki,ki->k", r, r)
        c1 = np.maximum(r @ n, 0.0)
        c2 = np.maximum(-(r @ ny), 0.0)
        value = c1 * c2 / (np.pi * r2 * r2) * area
        value[blocked(np.broadcast_to(x, y.shape), y, spheres, triangles, disks, cylinders)] = 0.0
        estimates.append(value.mean())
    estimates = np.array(estimates)
    return estimates.mean(), estimates.std(ddof=1) / np.sqrt(shifts)


def pair_factor(
    source,
    target,
    spheres=(),
    triangles=(),
    count=1 << 20,
    shifts=8,
    seed=2,
    disks=(),
    cylinders=(),
    bilinears=(),
):
    """F(source -> target) between parallelograms with occlusion: (mean, standard error)."""
    rng = np.random.default_rng(seed)
    base = halton(count, 4)
    estimates = []
    for _ in range(shifts):
        z = (base + rng.random(4)) % 1.0
        x, nx, _ = parallelogram(*(np.asarray(v, float) for v in source), z[:, 0], z[:, 1])
        y, ny, area = parallelogram(*(np.asarray(v, float) for v in target), z[:, 2], z[:, 3])
        r = y - x
        r2 = np.einsum("ki,ki->k", r, r)
        c1 = np.maximum(np.einsum("ki,i->k", r, nx), 0.0)
        c2 = np.maximum(-np.einsum("ki,i->k", r, ny), 0.0)
        value = c1 * c2 / (np.pi * r2 * r2) * area
        value[blocked(x, y, spheres, triangles, disks, cylinders, bilinears)] = 0.0
        estimates.append(value.mean())
    estimates = np.array(estimates)
    return estimates.mean(), estimates.std(ddof=1) / np.sqrt(shifts)


def disk_point_factor(x, center, radius, sphere, count=1 << 16, shifts=8, seed=3):
    """F(dA(x) facing +z -> a horizontal disk facing -z) past a sphere: (mean, standard error)."""
    rng = np.random.default_rng(seed)
    base = halton(count, 2)
    estimates = []
    for _ in range(shifts):
        s, t = ((base + rng.random(2)) % 1.0).T
        rr, phi = radius * np.sqrt(s), 2 * np.pi * t  # uniform in area
        y = np.column_stack(
            [center[0] + rr * np.cos(phi), center[1] + rr * np.sin(phi), np.full(count, center[2])]
        )
        r = y - x
        r2 = np.einsum("ki,ki->k", r, r)
        value = r[:, 2] * r[:, 2] / (np.pi * r2 * r2) * np.pi * radius * radius
        value[
            segment_hits_sphere(np.broadcast_to(x, y.shape), y, np.asarray(sphere[0], float), sphere[1])
        ] = 0.0
        estimates.append(value.mean())
    estimates = np.array(estimates)
    return estimates.mean(), estimates.std(ddof=1) / np.sqrt(shifts)


def disk_pair_factor(source, center, radius, spheres, count=1 << 18, shifts=8, seed=4):
    """F(parallelogram source facing +z -> a horizontal disk facing -z) past spheres: (mean,
    standard error). Uniform points on both (Halton in 4 dimensions, randomly shifted)."""
    rng = np.random.default_rng(seed)
    base = halton(count, 4)
    center = np.asarray(center, float)
    estimates = []
    for _ in range(shifts):
        z = (base + rng.random(4)) % 1.0
        x, nx, _ = parallelogram(*(np.asarray(v, float) for v in source), z[:, 0], z[:, 1])
        rr, phi = radius * np.sqrt(z[:, 2]), 2 * np.pi * z[:, 3]
        y = np.column_stack(
            [center[0] + rr * np.cos(phi), center[1] + rr * np.sin(phi), np.full(count, center[2])]
        )
        r = y - x
        r2 = np.einsum("ki,ki->k", r, r)
        c1 = np.maximum(r @ nx, 0.0)
        c2 = np.maximum(r[:, 2], 0.0)  # the disk faces -z: cos = (x - y) . (-z)
        value = c1 * c2 / (np.pi * r2 * r2) * np.pi * radius * radius
        value[blocked(x, y, spheres, ())] = 0.0
        estimates.append(value.mean())
    estimates = np.array(estimates)
    return estimates.mean(), estimates.std(ddof=1) / np.sqrt(shifts)


def cap_points(center, radius, axis, low, s, t):
    """Points uniform in area on the cap of a sphere where the outward normal n has n . axis >= low
    (the height n . axis is uniform in [low, 1], Archimedes), their unit normals and the cap's area."""
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    helper = np.array([1.0, 0.0, 0.0]) if abs(axis[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = np.cross(axis, helper)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(axis, e1)
    h = low + (1.0 - low) * s
    rho, phi = np.sqrt(np.maximum(1.0 - h * h, 0.0)), 2.0 * np.pi * t
    n = (rho * np.cos(phi))[:, None] * e1 + (rho * np.sin(phi))[:, None] * e2 + h[:, None] * axis
    return np.asarray(center, float) + radius * n, n, 2.0 * np.pi * radius * radius * (1.0 - low)


def sphere_pair_factor(
    source, target, spheres=(), triangles=(), count=1 << 20, shifts=8, seed=5, disks=(), cylinders=()
):
    """F(outside of sphere source -> outside of sphere target) with occlusion, spheres given as
    (center, radius): (mean, standard error). Uniform points on the caps of each sphere that can
    face the other (Halton in 4 dimensions, randomly shifted).

    With u the unit vector from the source's centre to the target's and d their distance, a
    source point x (normal n) faces some target point only if d n . u + r_t > r_s, and a target
    point only if -d n . u + r_s > r_t: the caps sampled hold every pair with a nonzero kernel.
    The spheres themselves need no ray test (a segment between points of two disjoint spheres
    whose fronts face it leaves each sphere outward).
    """
    (ca, ra), (cb, rb) = source, target
    u = np.asarray(cb, float) - np.asarray(ca, float)
    d = np.linalg.norm(u)
    low_a = np.clip((ra - rb) / d, -1.0, 1.0)
    low_b = np.clip((rb - ra) / d, -1.0, 1.0)
    rng = np.random.default_rng(seed)
    base = halton(count, 4)
    estimates = []
    for _ in range(shifts):
        z = (base + rng.random(4)) % 1.0
        x, nx, cap_a = cap_points(ca, ra, u, low_a, z[:, 0], z[:, 1])
        y, ny, cap_b = cap_points(cb, rb, -u, low_b, z[:, 2], z[:, 3])
        r = y - x
        r2 = np.einsum("ki,ki->k", r, r)
        c1 = np.maximum(np.einsum("ki,ki->k", r, nx), 0.0)
        c2 = np.maximum(-np.einsum("ki,ki->k", r, ny), 0.0)
        value = c1 * c2 / (np.pi * r2 * r2) * cap_b * cap_a / (4.0 * np.pi * ra * ra)
        value[blocked(x, y, spheres, triangles, disks, cylinders)] = 0.0
        estimates.append(value.mean())
    estimates = np.array(estimates)
    return estimates.mean(), estimates.std(ddof=1) / np.sqrt(shifts)


def sphere_point_factor(x, n, target, spheres=(), triangles=(), count=1 << 18, shifts=8, seed=6):
    """F(dA(x) with unit normal n -> the outside of sphere target (center, radius)) with occlusion:
    (mean, standard error). Uniform points on the cap of the target that x can see (n_y . (x - c) >=
    r: the rest faces away from x), Halton in 2 dimensions, randomly shifted."""
    center, radius = np.asarray(target[0], float), float(target[1])
    d = np.linalg.norm(np.asarray(x, float) - center)

    def sample(s, t):
        return cap_points(center, radius, np.asarray(x, float) - center, radius / d, s, t)

    return _point_estimate(x, n, sample, spheres, triangles, count, shifts, seed)


def _point_estimate(x, n, sample, spheres, triangles, count, shifts, seed):
    """F(dA(x) with unit normal n -> the points `sample(s, t)` gives (points, unit normals, area)
    for s, t uniform in [0, 1)) with occlusion: (mean, standard error) over `shifts` randomly
    shifted Halton sets of `count` points."""
    rng = np.random.default_rng(seed)
    base = halton(count, 2)
    estimates = []
    for _ in range(shifts):
        s, t = ((base + rng.random(2)) % 1.0).T
        y, ny, area = sample(s, t)
        r = y - x
        r2 = np.einsum("ki,ki->k", r, r)
        c1 = np.maximum(r @ n, 0.0)
        c2 = np.maximum(-np.einsum("ki,ki->k", r, ny), 0.0)
        value = c1 * c2 / (np.pi * r2 * r2) * area
        value[blocked(np.broadcast_to(x, y.shape), y, spheres, triangles)] = 0.0
        estimates.append(value.mean())
    estimates = np.array(estimates)
    return estimates.mean(), estimates.std(ddof=1) / np.sqrt(shifts)


def sphere_patch_points(center, radius, box, s, t):
    """Points uniform in area on a sphere patch u in [u0, u1] (polar angle from +z), v in [v0, v1]
    (azimuth from +x), box = (u0, u1, v0, v1) (cos u uniform, Archimedes), their outward unit
    normals and the patch's area."""
    u0, u1, v0, v1 = box
    cu = np.cos(u0) + (np.cos(u1) - np.cos(u0)) * s
    v = v0 + (v1 - v0) * t
    su = np.sqrt(np.maximum(1.0 - cu * cu, 0.0))
    n = np.stack([su * np.cos(v), su * np.sin(v), cu], 1)
    area = radius * radius * (np.cos(u0) - np.cos(u1)) * (v1 - v0)
    return np.asarray(center, float) + radius * n, n, area


def sphere_patch_point_factor(x, n, target, spheres=(), triangles=(), count=1 << 20, shifts=8, seed=7):
    """F(dA(x) with unit normal n -> the outside of sphere patch target (center, radius, box)) with
    occlusion: (mean, standard error). Uniform points on the patch (`sphere_patch_points`); a
    point facing away from x counts 0 (on a sphere seen from outside no front point is hidden by
    the sphere itself)."""
    return _point_estimate(
        x, n, lambda s, t: sphere_patch_points(*target, s, t), spheres, triangles, count, shifts, seed
    )


def sphere_patch_pair_factor(source, target, spheres=(), triangles=(), count=1 << 20, shifts=8, seed=8):
    """F(sphere patch source -> sphere patch target), each (center, radius, box), with occlusion:
    (mean, standard error). Uniform points on both (Halton in 4 dimensions, randomly shifted);
    the two spheres must be apart (a segment between front points then leaves each outward)."""
    rng = np.random.default_rng(seed)
    base = halton(count, 4)
    estimates = []
    for _ in range(shifts):
        z = (base + rng.random(4)) % 1.0
        x, nx, _ = sphere_patch_points(*source, z[:, 0], z[:, 1])
        y, ny, area = sphere_patch_points(*target, z[:, 2], z[:, 3])
        r = y - x
        r2 = np.einsum("ki,ki->k", r, r)
        c1 = np.maximum(np.einsum("ki,ki->k", r, nx), 0.0)
        c2 = np.maximum(-np.einsum("ki,ki->k", r, ny), 0.0)
        value = c1 * c2 / (np.pi * r2 * r2) * area
        value[blocked(x, y, spheres, triangles)] = 0.0
        estimates.append(value.mean())
    estimates = np.array(estimates)
    return estimates.mean(), estimates.std(ddof=1) / np.sqrt(shifts)
