"""Floor patches partly under boxes: their direct light against an independent ray count (issue 15).

The room of `benchmarks.mesh_room` built in the core (no Blender): a 6 x 6 x 3 m room of quads,
the floor in `--patches` x `--patches` patches, three closed boxes resting on it, a ball resting
on it and a 1 m lamp quad facing down 5 cm under the ceiling that does not occlude (as Cycles'
area lights). One bounce (`max_bounces=1`): each floor patch's radiosity is rho times the lamp
light it gathers over its free part, so (B / rho) times the patch's free area is the lamp power
landing on that free part. The reference is our own Monte Carlo, sharing no code with the core:
lambertian rays from the lamp, exact ray tests against the floor plane, the boxes (slabs) and the
ball, hits binned by floor patch. Prints the floor's total and each cut patch's ratio.

Run: python -m benchmarks.covered_patches [--patches 7] [--rays 20000000] [--tol 1e-3]
                                          [--method pairs|hierarchical]
"""

import argparse
import time

import numpy as np

from core import PolygonMesh, Quad, Scene, Sphere

W, D, H = 6.0, 6.0, 3.0
BOXES = [
    ((2.0, 3.0, 0.4), (0.9, 0.6, 0.4)),
    ((4.5, 1.5, 0.3), (0.3, 0.3, 0.3)),
    ((4.6, 4.5, 0.5), (0.4, 0.4, 0.5)),
]
BALL = ((1.5, 1.2, 0.5), 0.5)
LAMP = (W / 2 - 0.5, W / 2 + 0.5, H - 0.05)  # x = y in [a, b] at height z
RHO, EMISSION = 0.7, 10.0


def box_mesh(center, half):
    lo, hi = np.subtract(center, half), np.add(center, half)
    (x0, y0, z0), (x1, y1, z1) = lo, hi
    V = [(x0, y0, z0), (x1, y0, z0), (x1, y1, z0), (x0, y1, z0), (x0, y0, z1), (x1, y0, z1), (x1, y1, z1)]
    V.append((x0, y1, z1))
    F = [(0, 3, 2, 1), (0, 1, 5, 4), (1, 2, 6, 5), (2, 3, 7, 6), (3, 0, 4, 7), (4, 5, 6, 7)]
    return PolygonMesh(np.array(V), F)


def solved_floor(n, tol, method="pairs"):
    """B of the floor's n x n patches (u along x, v along y: patch i * n + j), one bounce."""
    scene = Scene()
    walls = [
        ((0, 0, 0), (W, 0, 0), (W, D, 0), (0, D, 0)),
        ((0, 0, H), (0, D, H), (W, D, H), (W, 0, H)),
        ((0, 0, 0), (0, D, 0), (0, D, H), (0, 0, H)),
        ((W, 0, 0), (W, 0, H), (W, D, H), (W, D, 0)),
        ((0, 0, 0), (0, 0, H), (W, 0, H), (W, 0, 0)),
        ((0, D, 0), (W, D, 0), (W, D, H), (0, D, H)),
    ]
    floor = scene.add(Quad(*walls[0]), reflectance=RHO, patches=(n, n))
    for corners in walls[1:]:
        scene.add(Quad(*corners), reflectance=RHO)
    for center, half in BOXES:
        scene.add(box_mesh(center, half), reflectance=RHO)
    scene.add(Sphere(*BALL), reflectance=RHO)
    a, b, z = LAMP
    scene.add(
        Quad((a, a, z), (a, b, z), (b, b, z), (b, a, z)), reflectance=0.0, emission=EMISSION, occluder=False
    )
    return scene.solve(tol=tol, max_bounces=1, method=method).radiosity(floor)[:, 0]


def counted(n, rays, seed=1):
    """Share of the lamp's power first landing on each floor patch, shape (n * n,), and the
    number of rays."""
    rng = np.random.default_rng(seed)
    a, b, z = LAMP
    counts = np.zeros(n * n)
    chunk = 1_000_000
    for _ in range(rays // chunk):
        o = np.stack([rng.uniform(a, b, chunk), rng.uniform(a, b, chunk), np.full(chunk, z)], 1)
        r1, r2 = rng.random(chunk), rng.random(chunk)
        s, phi = np.sqrt(r1), 2 * np.pi * r2
        d = np.stack([s * np.cos(phi), s * np.sin(phi), -np.sqrt(1 - r1)], 1)  # cosine-weighted, down
        t_floor = -o[:, 2] / d[:, 2]
        hit = np.ones(chunk, dtype=bool)
        with np.errstate(divide="ignore", invalid="ignore"):
            for center, half in BOXES:
                lo, hi = np.subtract(center, half), np.add(center, half)
                t1, t2 = (lo - o) / d, (hi - o) / d
                near, far = np.nanmax(np.minimum(t1, t2), 1), np.nanmin(np.maximum(t1, t2), 1)
                hit &= ~((near <= far) & (near > 0) & (near < t_floor))
        c, r = np.array(BALL[0]), BALL[1]
        oc = o - c
        half_b = np.einsum("ki,ki->k", oc, d)
        disc = half_b**2 - (np.einsum("ki,ki->k", oc, oc) - r * r)
        t_ball = -half_b - np.sqrt(np.maximum(disc, 0.0))
        hit &= ~((disc > 0) & (t_ball > 0) & (t_ball < t_floor))
        p = o[hit] + t_floor[hit, None] * d[hit]
        inside = np.all((p[:, :2] >= 0) & (p[:, :2] < W), axis=1)  # (walls stop the rest first)
        cell = np.floor(p[inside, :2] / (W / n)).astype(int)
        np.add.at(counts, cell[:, 0] * n + cell[:, 1], 1.0)
    return counts / (rays // chunk * chunk), rays // chunk * chunk


def free_fractions(n):
    """Each floor patch's area outside the boxes' footprints, as a fraction, shape (n * n,)."""
    size = W / n
    x0, y0 = np.repeat(np.arange(n) * size, n), np.tile(np.arange(n) * size, n)
    covered = np.zeros(n * n)
    for center, half in BOXES:
        lo, hi = np.subtract(center, half), np.add(center, half)
        ox = np.clip(np.minimum(x0 + size, hi[0]) - np.maximum(x0, lo[0]), 0, None)
        oy = np.clip(np.minimum(y0 + size, hi[1]) - np.maximum(y0, lo[1]), 0, None)
        covered += ox * oy
    return 1.0 - covered / size**2


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--patches", type=int, default=7, help="floor patches per side (7: 0.86 m)")
    parser.add_argument("--rays", type=int, default=20_000_000)
    parser.add_argument("--tol", type=float, default=1e-3)
    parser.add_argument("--method", choices=("pairs", "hierarchical"), default="pairs")
    args = parser.parse_args()
    n = args.patches
    start = time.perf_counter()
    B = solved_floor(n, args.tol, args.method)
    seconds = time.perf_counter() - start
    free = free_fractions(n)
    a, b, _ = LAMP
    ours = B / RHO * free * (W / n) ** 2 / (EMISSION * (b - a) ** 2)
    share, rays = counted(n, args.rays)
    print(f"{n} x {n} floor patches, tol {args.tol}, method {args.method} ({seconds:.1f} s), {rays} rays")
    error, off = np.sqrt(share.sum() / rays), ours.sum() / share.sum() - 1
    print(f"floor: core {ours.sum():.5f}, count {share.sum():.5f} +- {error:.5f} ({off:+.2%})")
    print("| patch | free | core | count | ratio |")
    print("|---|---|---|---|---|")
    for k in np.flatnonzero((free > 0) & (free < 1)):
        ratio = ours[k] / share[k] if share[k] > 0 else np.nan
        print(f"| {k} | {free[k]:.3f} | {ours[k]:.5f} | {share[k]:.5f} | {ratio:.4f} |")


if __name__ == "__main__":
    main()
