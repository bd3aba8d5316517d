"""What results at any resolution cost: lightmap texels and refined twins (issue 16).

Run from the repository root (Blender as a Python module; not part of the test suite):

    .venv/bin/python -m benchmarks.lightmap_cost [--sizes 64 128 256 1024] [--no-room]
        [--method PAIRS|HIERARCHICAL|AUTO]

1. Lightmap: a one-quad 6 m floor under a sphere (r = 0.6 m, 0.3 m above the floor) and a 1 m
   area light 4 m up, solved once (DRAFT); then lightmaps of each size through the floor's
   UVMap, each stage timed: rasterise + locate (`texels`, `sampling`), the gather
   (`Solution.radiosity_at` at every texel, the core's work) and dilation. Reports seconds per
   million texels of the gather and the peak resident memory of the process. Then the whole
   adaptive bake (what the add-on runs) at 256 and 1024 texels square.
2. Refined twin of a 10 m room: a 10 x 10 x 3 m box seen from inside (one mesh object of six
   quads) with a sphere resting on the floor and a 2 m area light under the ceiling, refined to
   tol 0.05 and minimum edge 0.05 m: time, passes, vertices, triangles, memory.

Writes benchmarks/results/lightmap_cost.md and prints it.
"""

import argparse
import resource
import sys
import time
from pathlib import Path

import bpy
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import addon  # noqa: E402 (the repository's add-on, after its root is on sys.path)
from addon import bake, outputs, pipeline, sampling, texels  # noqa: E402

RESULTS = ROOT / "benchmarks" / "results" / "lightmap_cost.md"


def peak_mb():
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def floor_scene(method="AUTO"):
    bpy.ops.wm.read_homefile(use_empty=True)
    bpy.context.scene.curved_radiosity.method = method
    bpy.ops.mesh.primitive_plane_add(size=6.0)
    floor = bpy.context.active_object
    floor.name = "Floor"
    bpy.ops.mesh.primitive_uv_sphere_add(segments=32, ring_count=16, radius=0.6, location=(0, 0, 0.9))
    bpy.ops.object.light_add(type="AREA", location=(0, 0, 4))
    bpy.context.active_object.data.energy = 300.0
    bpy.context.active_object.data.size = 1.0
    bpy.context.scene.curved_radiosity.quality = "DRAFT"
    return floor


def lightmap_costs(sizes, adaptive_sizes, method="AUTO"):
    """Direct rows (size, texels, locate s, gather s, dilate s, gather s per million texels, peak
    MB) and adaptive rows (size, texels, gathered, seconds, peak MB)."""
    floor_scene(method)
    job = pipeline.prepare(bpy.context)
    start = time.perf_counter()
    pipeline.run(job)
    solve_time = time.perf_counter() - start
    solution = job.solution
    depsgraph = bpy.context.evaluated_depsgraph_get()
    mesh = outputs.read_mesh(bpy.data.objects["Floor"], depsgraph)
    rows = []
    for size in sizes:
        t0 = time.perf_counter()
        texel, triangle, bary, _ = texels.rasterise(mesh.triangle_uv("UVMap"), size, size)
        where = sampling.MeshSurfaces(mesh.world_positions(), mesh.triangles, job.collected.surfaces, "Floor")
        located = where.locate(triangle, bary)
        t1 = time.perf_counter()
        rgb = sampling.gather(solution.core, solution.handles, located)
        t2 = time.perf_counter()
        image = np.zeros((size * size, 3))
        image[texel] = rgb
        covered = np.zeros(size * size, bool)
        covered[texel] = True
        texels.dilate(image.reshape(size, size, 3), covered.reshape(size, size), bake.DILATION)
        t3 = time.perf_counter()
        n = texel.size
        rows.append((size, n, t1 - t0, t2 - t1, t3 - t2, (t2 - t1) / n * 1e6, peak_mb()))
        print(rows[-1], flush=True)
    adaptive = []
    for size in adaptive_sizes:
        request = bake.LightmapRequest("Floor", mesh, "UVMap", size, size)
        start = time.perf_counter()
        _, n, gathered = bake.lightmap_pixels(
            request, solution.core, solution.handles, job.collected.surfaces
        )
        adaptive.append((size, n, gathered, time.perf_counter() - start, peak_mb()))
        print(adaptive[-1], flush=True)
    return solve_time, rows, adaptive


def room_scene():
    bpy.ops.wm.read_homefile(use_empty=True)
    bpy.ops.mesh.primitive_cube_add(size=1.0, location=(0, 0, 1.5), scale=(10, 10, 3))
    room = bpy.context.active_object
    room.name = "Room"
    bpy.ops.object.mode_set(mode="EDIT")
    bpy.ops.mesh.select_all(action="SELECT")
    bpy.ops.mesh.flip_normals()  # seen from inside
    bpy.ops.object.mode_set(mode="OBJECT")
    bpy.ops.object.transform_apply(scale=True)
    bpy.ops.mesh.primitive_uv_sphere_add(segments=32, ring_count=16, radius=0.8, location=(1.5, 1.0, 0.8))
    bpy.ops.object.light_add(type="AREA", location=(0, 0, 2.95))
    bpy.context.active_object.data.energy = 1500.0
    bpy.context.active_object.data.size = 2.0
    bpy.context.scene.curved_radiosity.quality = "DRAFT"
    room.curved_radiosity_output = "REFINED"
    room.curved_radiosity_refine_tol = 0.05
    room.curved_radiosity_refine_min_edge = 0.05
    return room


def room_cost():
    room_scene()
    start = time.perf_counter()
    job = pipeline.compute(bpy.context)
    total = time.perf_counter() - start
    refined = job.requests.refined[0].result
    return dict(
        solve=job.times["solve"],
        refine=job.times["bake"],
        total=total,
        passes=refined.passes,
        vertices=len(refined.positions),
        triangles=len(refined.triangles),
        budget=refined.budget_reached,
        peak=peak_mb(),
    )


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="*", default=[64, 128, 256], help="every texel gathered")
    parser.add_argument(
        "--adaptive-sizes", type=int, nargs="*", default=[256, 1024], help="adaptive, tol 0.01"
    )
    parser.add_argument("--no-room", action="store_true")
    parser.add_argument("--method", default="AUTO", choices=["AUTO", "PAIRS", "HIERARCHICAL"], help="solver")
    args = parser.parse_args(argv)
    addon.register()
    lines = ["# Lightmap and refined-twin cost (benchmarks/lightmap_cost.py)", ""]
    solve_time, rows, adaptive = lightmap_costs(args.sizes, args.adaptive_sizes, args.method)
    lines += [
        f"One-quad floor, sphere, area light (DRAFT, solver {args.method}): solve {solve_time:.1f} s.",
        "",
        "| size | texels | rasterise + locate (s) | gather (s) | dilate (s) | gather s / 10^6 texels "
        "| peak RSS (MB) |",
        "|---|---|---|---|---|---|---|",
    ]
    lines += [
        f"| {r[0]} | {r[1]} | {r[2]:.2f} | {r[3]:.1f} | {r[4]:.2f} | {r[5]:.0f} | {r[6]:.0f} |" for r in rows
    ]
    lines += [
        "",
        "Adaptive (`addon/adaptive_lightmap.py`, tol 0.01, 8 x 8 cells), the whole bake (rasterise, "
        "locate, gather, dilate):",
        "",
        "| size | texels | gathered | time (s) | peak RSS (MB) |",
        "|---|---|---|---|---|",
    ]
    lines += [
        f"| {size} | {n} | {g} ({100 * g / n:.1f} %) | {t:.1f} | {mb:.0f} |" for size, n, g, t, mb in adaptive
    ]
    if not args.no_room:
        room = room_cost()
        print(room, flush=True)
        lines += [
            "",
            "Refined twin of a 10 x 10 x 3 m room (6 quads) with a sphere and a 2 m area light, tol 0.05, "
            "min edge 0.05 m (DRAFT):",
            "",
            f"solve {room['solve']:.1f} s, refine {room['refine']:.1f} s ({room['passes']} passes), "
            f"{room['vertices']} vertices, {room['triangles']} triangles, budget reached: {room['budget']}, "
            f"peak RSS {room['peak']:.0f} MB.",
        ]
    text = "\n".join(lines) + "\n"
    suffix = "" if args.method == "PAIRS" else "_" + args.method.lower()
    RESULTS.with_name(RESULTS.stem + suffix + RESULTS.suffix).write_text(text)
    print(text)


if __name__ == "__main__":
    main()
