"""A closed room of separate flat quads (issue 12, step 1): visibility cost against occluder count.

A 4 m box whose six walls are n x n grids of quads, each added as its own surface with one patch
(6 n^2 surfaces and occluders), a box-shaped "table" of 5 x k^2 quads inside, and one emitting
quad under the ceiling. `Scene.solve(tol=1e-3)` with occlusion; prints per-stage times and the
BVH counters of `Solution.stats`.

Run alone: python -m benchmarks.quad_room [--n 12]
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
    light = core.Quad((c - 0.4, c - 0.4, L - 0.01), (c - 0.4, c + 0.4, L - 0.01),
                      (c + 0.4, c + 0.4, L - 0.01), (c + 0.4, c - 0.4, L - 0.01))
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


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--n", type=int, default=12)
    parser.add_argument("--k", type=int, default=2)
    parser.add_argument("--threads", type=int, default=None)
    args = parser.parse_args()
    count, total, stats, B = run(args.n, args.k, threads=args.threads)
    times = {k: round(v, 2) for k, v in stats["times"].items()}
    keys = ("elements", "pairs_total", "pairs_culled_facing", "rays", "ray_tests", "pairs_shadow_tested",
            "bvh_nodes", "bvh_primitives")
    print(f"{count} quads: solve {total:.2f} s; times {times}")
    print({k: stats.get(k) for k in keys})
    print(f"mean B {B.mean(0)}; checksum {B.sum():.9f}")
    np.save(f"/tmp/quad_room_{args.n}_{args.k}.npy", B)


if __name__ == "__main__":
    main()
