"""A closed room of separate flat quads (issue 12, step 1): visibility cost against occluder count.

A 4 m box whose six walls are n x n grids of quads, each added as its own surface with one patch
(6 n^2 surfaces and occluders), a box-shaped "table" of 5 x k^2 quads inside, and one emitting
quad under the ceiling. `Scene.solve(tol=1e-3)` with occlusion; prints per-stage times and the
BVH counters of `Solution.stats`.

With --shafts: the candidate occluders of every live pair of the room, timed in the same run
through `visibility.ShaftTest` (the BVH) and through the former dense rule (every pair against
every occluder: box, capsule, planes, own surface), and checked equal.

Run alone: python -m benchmarks.quad_room [--n 12] [--shafts]
"""

import argparse
import time

import numpy as np

import core


def grid_quads(origin, du, dv, n):
    """n x n quads of the parallelogram origin + s du + t dv (front = du x dv)."""
    o, du, dv = (np.asarray(x, dtype=float) for x in (origin, du, dv))
    quads = []
    for i in range(n):
        for j in range(n):
            p00 = o + du * i / n + dv * j / n
            quads.append(core.Quad(p00, p00 + du / n, p00 + (du + dv) / n, p00 + dv / n))
    return quads


def room(n, k=2, L=4.0):
    """[(Quad, reflectance, emission)] of the room: walls facing inward, a table, a light."""
    walls = [
        ((0, 0, 0), (L, 0, 0), (0, L, 0)),  # floor, +z
        ((0, 0, L), (0, L, 0), (L, 0, 0)),  # ceiling, -z
        ((0, 0, 0), (0, L, 0), (0, 0, L)),  # x = 0, +x
        ((L, 0, 0), (0, 0, L), (0, L, 0)),  # x = L, -x
        ((0, 0, 0), (0, 0, L), (L, 0, 0)),  # y = 0, +y
        ((0, L, 0), (L, 0, 0), (0, 0, L)),  # y = L, -y
    ]
    items = [(q, 0.6, 0.0) for o, du, dv in walls for q in grid_quads(o, du, dv, n)]
    # a table: a closed box (outward fronts) without its bottom
    a, b, h = 1.2, 2.4, 1.0
    box = [
        ((a, a, h), (b - a, 0, 0), (0, b - a, 0)),  # top, +z
        ((a, a, 0), (b - a, 0, 0), (0, 0, h)),  # y = a, -y
        ((a, b, 0), (0, 0, h), (b - a, 0, 0)),  # y = b, +y
        ((a, a, 0), (0, 0, h), (0, b - a, 0)),  # x = a, -x
        ((b, a, 0), (0, b - a, 0), (0, 0, h)),  # x = b, +x
    ]
    items += [(q, 0.5, 0.0) for o, du, dv in box for q in grid_quads(o, du, dv, k)]
    c = L / 2
    light = core.Quad(
        (c - 0.4, c - 0.4, L - 0.01),
        (c - 0.4, c + 0.4, L - 0.01),
        (c + 0.4, c + 0.4, L - 0.01),
        (c + 0.4, c - 0.4, L - 0.01),
    )
    return items, light


def run(n, k=2, tol=1e-3, threads=None):
    items, light = room(n, k)
    scene = core.Scene()
    for q, rho, e in items:
        scene.add(q, reflectance=rho, emission=e, patches=(1, 1))
    lamp = scene.add(light, reflectance=0.0, emission=10.0, patches=(1, 1), occluder=False)
    start = time.perf_counter()
    sol = scene.solve(tol=tol, threads=threads)
    total = time.perf_counter() - start
    B = np.concatenate([sol.radiosity(h) for h in range(lamp)])
    return len(items), total, sol.stats, B


def dense_candidates(e, occ, objects, a, b):
    """The former ShaftTest rule over every (pair, occluder), as a dense (P, M) matrix."""
    lo = np.minimum(e.box_min[a], e.box_min[b])
    hi = np.maximum(e.box_max[a], e.box_max[b])
    radius = np.maximum(e.radius[a], e.radius[b])
    mask = np.all((occ.box_min[None] <= hi[:, None]) & (occ.box_max[None] >= lo[:, None]), axis=-1)
    p, q = e.center[a], e.center[b]
    d = q - p
    dd = np.einsum("ki,ki->k", d, d)[:, None]
    t = np.einsum("kmi,ki->km", occ.center[None] - p[:, None], d)
    t = np.clip(np.divide(t, dd, out=np.zeros_like(t), where=dd > 0), 0, 1)
    closest = p[:, None] + t[..., None] * d[:, None]
    mask &= np.linalg.norm(occ.center[None] - closest, axis=-1) <= occ.radius[None] + radius[:, None]
    eps = 1e-9 * occ.scale
    planar = np.flatnonzero(occ.planar)
    normal, offset = occ.plane_normal[planar], occ.plane_offset[planar]
    la, ha = heights_all(e, a, normal, offset)
    lb, hb = heights_all(e, b, normal, offset)
    mask[:, planar] &= ~(((la >= -eps) & (lb >= -eps)) | ((ha <= eps) & (hb <= eps)))
    for side in (a, b):
        leaves = occ.planar[None] | e.outward[side][:, None]
        mask &= ~(occ.convex[None] & (objects[None] == e.owner[side][:, None]) & leaves)
    return mask


def heights_all(e, index, normal, offset):
    """Least and greatest heights of elements' boxes over planes, (K, M') each."""
    lo, hi = e.box_min[index], e.box_max[index]
    middle = 0.5 * (lo + hi) @ normal.T - offset[None]
    reach = 0.5 * (hi - lo) @ np.abs(normal).T
    return middle - reach, middle + reach


def compare_shafts(n, k):
    """Seconds of the BVH and the dense rule over all live pairs, and whether they agree."""
    from core.elements import Elements
    from core.occlusion import Occluders
    from core.visibility import ShaftTest

    items, _ = room(n, k)
    surfaces = [q for q, _, _ in items]
    e = Elements(surfaces, np.arange(len(surfaces)))
    occ = Occluders(surfaces)
    objects = np.arange(len(surfaces))
    shafts = ShaftTest(e, occ, objects)
    N = len(e)
    i, j = np.triu_indices(N)
    live = e.live(i, j)
    i, j = i[live], j[live]
    chunk = max(256, 2_000_000 // N)
    times, found, agree = {"bvh": 0.0, "dense": 0.0}, 0, True
    for s in range(0, i.size, chunk):
        a, b = i[s : s + chunk], j[s : s + chunk]
        start = time.perf_counter()
        got = shafts.candidates(a, b)
        times["bvh"] += time.perf_counter() - start
        start = time.perf_counter()
        want = dense_candidates(e, occ, objects, a, b)
        times["dense"] += time.perf_counter() - start
        agree &= bool(np.array_equal(got, want))
        found += int(got.sum())
    return i.size, times, found, agree, occ.bvh.totals


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--n", type=int, default=12)
    parser.add_argument("--k", type=int, default=2)
    parser.add_argument("--threads", type=int, default=None)
    parser.add_argument("--shafts", action="store_true", help="time the candidate queries only")
    args = parser.parse_args()
    if args.shafts:
        pairs, times, found, agree, totals = compare_shafts(args.n, args.k)
        print(
            f"{pairs} live pairs: BVH {times['bvh']:.2f} s, dense {times['dense']:.2f} s "
            f"({times['dense'] / times['bvh']:.1f}x); {found} candidates; equal: {agree}; BVH {totals}"
        )
        return
    count, total, stats, B = run(args.n, args.k, threads=args.threads)
    times = {k: round(v, 2) for k, v in stats["times"].items()}
    keys = (
        "elements",
        "pairs_total",
        "pairs_culled_facing",
        "rays",
        "ray_tests",
        "pairs_shadow_tested",
        "bvh_nodes",
        "bvh_primitives",
    )
    print(f"{count} quads: solve {total:.2f} s; times {times}")
    print({k: stats.get(k) for k in keys})
    print(f"mean B {B.mean(0)}; checksum {B.sum():.9f}")
    np.save(f"/tmp/quad_room_{args.n}_{args.k}.npy", B)


if __name__ == "__main__":
    main()
