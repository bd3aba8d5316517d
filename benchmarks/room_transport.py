"""Point radiosity in a furnished room against an independent path tracer (issues 15 / 13 / 11).

Run: python -m benchmarks.room_transport [--paths N] [--grids 4,8] [--hierarchical]
(prints markdown; not part of the test suite: about 20 minutes with --hierarchical)

The room of `benchmarks.mesh_room` (6 x 6 x 3 m, rho 0.7, a 1 m square lamp of 300 W 5 cm under
the ceiling, three boxes and a ball on the floor), built from core surfaces: the inside of the
room as six quads of m x m patches, the boxes as quads (patches about the room's size), the ball
as an exact `Sphere`, the lamp as an emitting quad that casts no shadow (a Cycles light). Three
variants: the empty room, the furnished room, and the furnished room with the boxes black and
lifted 5 cm (no contact, all their effect is the light they block). Each is solved at tol 1e-3
on the all-pairs path for every m of --grids (and, with --hierarchical, on the hierarchical path
with `light_levels`=2 at the first m), and `radiosity_at` at 24 points on the ceiling, floor and
walls (none at a seam or contact) is compared with `tests.reference.room_paths` (path tracing
with exact ray tests, its own error bar) as ours / reference per surface: mean, min and max.
"""

import argparse
import time

import numpy as np

import core
from tests.reference import room_paths

SIZE, RHO = (6.0, 6.0, 3.0), 0.7
LAMP = ((3.0, 3.0, 2.95), (1.0, 1.0), 300.0 / np.pi)  # 300 W over 1 m^2: L = P / (pi A)
BOXES = [
    ((2.0, 3.0, 0.4), (0.9, 0.6, 0.4)),
    ((4.5, 1.5, 0.3), (0.3, 0.3, 0.3)),
    ((4.6, 4.5, 0.5), (0.4, 0.4, 0.5)),
]
BALL = ((1.5, 1.2, 0.5), 0.5)
# (origin, du, dv) with du x dv into the room (`Quad`'s front: (p1 - p0) x (p3 - p0))
WALLS = {
    "floor": ((0, 0, 0), (6, 0, 0), (0, 6, 0)),
    "ceiling": ((0, 0, 3), (0, 6, 0), (6, 0, 0)),
    "wall_x0": ((0, 0, 0), (0, 6, 0), (0, 0, 3)),
    "wall_x1": ((6, 0, 0), (0, 0, 3), (0, 6, 0)),
    "wall_y0": ((0, 0, 0), (0, 0, 3), (6, 0, 0)),
    "wall_y1": ((0, 6, 0), (6, 0, 0), (0, 0, 3)),
}
POINTS = {  # away from seams, contacts and the furniture's footprints
    "ceiling": [(x, y, 3.0) for x in (1.0, 3.0, 5.0) for y in (1.0, 3.0, 5.0)] + [(0.4, 2.2, 3.0)],
    "floor": [(1.0, 5.0, 0), (3.0, 1.0, 0), (5.5, 3.0, 0), (3.0, 5.2, 0), (0.5, 0.5, 0), (5.5, 5.5, 0)],
    "wall_x0": [(0, 3.0, 1.5), (0, 1.0, 2.5)],
    "wall_x1": [(6, 3.0, 1.5), (6, 5.0, 0.5)],
    "wall_y0": [(3.0, 0, 1.5), (1.0, 0, 0.5)],
    "wall_y1": [(3.0, 6, 1.5), (5.0, 6, 2.5)],
}
VARIANTS = {
    "empty": dict(furniture=False, lift=0.0, box_rho=RHO),
    "furnished": dict(furniture=True, lift=0.0, box_rho=RHO),
    "black boxes lifted 5 cm": dict(furniture=True, lift=0.05, box_rho=0.0),
}


def _frame(name):
    return tuple(np.asarray(a, dtype=float) for a in WALLS[name])


def _normal(name):
    _, du, dv = _frame(name)
    normal = np.cross(du, dv)
    return normal / np.linalg.norm(normal)


def _quad(o, du, dv):
    return core.Quad(o, o + du, o + du + dv, o + dv)


def boxes(variant):
    """(low, high, reflectance) of each box of a variant."""
    if not variant["furniture"]:
        return []
    lift = np.array([0.0, 0.0, variant["lift"]])
    return [(np.subtract(c, s) + lift, np.add(c, s) + lift, variant["box_rho"]) for c, s in BOXES]


def box_faces(lo, hi):
    """The six outward quads of a box (a resting box's bottom lies on the floor, as a Blender cube's
    does: the floor patches under it then take the mean of their free part, `coverage`)."""
    for axis in range(3):
        a, b = (axis + 1) % 3, (axis + 2) % 3
        for side in (-1.0, 1.0):
            o = lo.copy()
            o[axis] = hi[axis] if side > 0 else lo[axis]
            du, dv = np.zeros(3), np.zeros(3)
            du[a], dv[b] = hi[a] - lo[a], hi[b] - lo[b]
            if np.cross(du, dv)[axis] * side < 0:
                du, dv = dv, du
            yield _quad(o, du, dv), (max(1, round(np.linalg.norm(du))), max(1, round(np.linalg.norm(dv))))


def core_scene(variant, m):
    """The variant as a core.Scene with m x m patches on each side of the room; handles by name."""
    scene, handles = core.Scene(), {}
    for name in WALLS:
        handles[name] = scene.add(_quad(*_frame(name)), reflectance=RHO, patches=(m, m))
    for lo, hi, rho in boxes(variant):
        for quad, grid in box_faces(lo, hi):
            scene.add(quad, reflectance=rho, patches=grid)
    if variant["furniture"]:
        scene.add(core.Sphere(*BALL), reflectance=RHO, patches=(4, 8))
    (cx, cy, cz), (sx, sy), radiance = LAMP
    lamp = _quad(np.array([cx - sx / 2, cy - sy / 2, cz]), np.array([0.0, sy, 0.0]), np.array([sx, 0.0, 0.0]))
    scene.add(lamp, emission=np.pi * radiance, reflectance=0.0, occluder=False)
    return scene, handles


def reference(variant, paths, seed=1, points=POINTS):
    """Path-traced radiance at `points` (dict name -> list of points on that side): dict name ->
    (mean (k,), error (k,))."""
    room = room_paths.Room(SIZE, RHO, LAMP, boxes(variant), [BALL + (RHO,)] if variant["furniture"] else [])
    x = np.array([p for name in points for p in points[name]], dtype=float)
    n = np.array([_normal(name) for name in points for _ in points[name]])
    mean, error = room_paths.radiance(room, x, n, RHO, paths, seed)
    out, k = {}, 0
    for name in points:
        out[name] = mean[k : k + len(points[name])], error[k : k + len(points[name])]
        k += len(points[name])
    return out


def ours(solution, handles, points=POINTS):
    """Radiance from `radiosity_at` at `points` (channel 0; the scene is grey)."""
    out = {}
    for name, on_side in points.items():
        o, du, dv = _frame(name)
        rel = np.asarray(on_side, dtype=float) - o
        u, v = rel @ du / (du @ du), rel @ dv / (dv @ dv)
        out[name] = solution.radiosity_at(handles[name], u, v)[:, 0] / np.pi
    return out


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--paths", type=int, default=1_000_000, help="paths per point")
    parser.add_argument("--grids", default="4,8")
    parser.add_argument("--hierarchical", action="store_true")
    parser.add_argument("--variants", default=",".join(VARIANTS), help="comma-separated names")
    args = parser.parse_args()
    grids = [int(g) for g in args.grids.split(",")]
    lines = [
        "| variant | path | patches per side | solve + gather (s) | ceiling: ours / ref mean (min … max) "
        "| floor | walls | ref. error (max, relative) |",
        "|---|---|---|---|---|---|---|---|",
    ]
    runs = [("pairs", m, {}) for m in grids]
    if args.hierarchical:
        runs.append(("hierarchical", grids[0], dict(method="hierarchical", light_levels=2)))
    for label in args.variants.split(","):
        variant = VARIANTS[label]
        ref = reference(variant, args.paths)
        bar = max(float(np.max(e / m)) for m, e in ref.values())
        for path, m, extra in runs:
            scene, handles = core_scene(variant, m)
            start = time.perf_counter()
            got = ours(scene.solve(tol=1e-3, **extra), handles)
            seconds = time.perf_counter() - start
            cells = []
            for group in ("ceiling", "floor", "wall"):
                ratio = np.concatenate([got[k] / ref[k][0] for k in POINTS if k.startswith(group)])
                cells.append(f"{ratio.mean():.4f} ({ratio.min():.4f} … {ratio.max():.4f})")
            lines.append(
                f"| {label} | {path} | {m} | {seconds:.1f} | " + " | ".join(cells) + f" | {bar:.1e} |"
            )
            print(lines[-1], flush=True)
    print("\n".join(lines))


if __name__ == "__main__":
    main()
