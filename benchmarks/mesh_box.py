"""The closed box of issue 12 through the add-on: meshes as PolygonMesh (after) vs per-polygon Quads (before).

A 4 m box of six wall meshes, each an n x n grid of quads with inward normals (n = 8: 384
polygons), a UV sphere (recognised as an exact `Sphere`), and an area light under the ceiling.
The scene is built with bpy (Blender as a module), collected and solved by the repository's
add-on package (`addon.collect`, `addon.solve`: the same code the extension runs), once with
`addon.objects.POLYGON_MESHES = True` (one `core.PolygonMesh` per wall) and once with False
(the former mapping, every polygon its own `core.Quad`), in the same run.

Reference: the core alone with each wall as one `core.Quad` of 16 x 16 patches and the sphere
as 8 x 16 patches at tol 1e-4, gathered (`radiosity_at`) at the walls' interior grid vertices
(where the vertex value is the continuous radiosity, not an average across walls). This is a
finer, different discretisation of the same equation, not a Monte Carlo renderer.

Run alone: python -m benchmarks.mesh_box [--n 8] [--tol 1e-3]
"""

import argparse
import resource
import sys
import time

import numpy as np

L = 4.0
SPHERE = ((1.4, 2.2, 1.0), 0.8)
LIGHT = ((2.0, 2.0, L - 0.05), 1.0, 150.0)  # location, size (m), power (W)
WALLS = [  # origin, du, dv with du x dv pointing into the box
    ((0, 0, 0), (L, 0, 0), (0, L, 0)),
    ((0, 0, L), (0, L, 0), (L, 0, 0)),
    ((0, 0, 0), (0, L, 0), (0, 0, L)),
    ((L, 0, 0), (0, 0, L), (0, L, 0)),
    ((0, 0, 0), (0, 0, L), (L, 0, 0)),
    ((0, L, 0), (L, 0, 0), (0, 0, L)),
]


def grid(n, origin, du, dv):
    o, du, dv = (np.asarray(x, dtype=float) for x in (origin, du, dv))
    V = np.array([o + du * i / n + dv * j / n for i in range(n + 1) for j in range(n + 1)])
    F = [
        (i * (n + 1) + j, (i + 1) * (n + 1) + j, (i + 1) * (n + 1) + j + 1, i * (n + 1) + j + 1)
        for i in range(n)
        for j in range(n)
    ]
    return V, F


def build(bpy, n):
    """The box in a fresh Blender scene; returns the wall object names."""
    bpy.ops.wm.read_homefile(use_empty=True)
    grey = bpy.data.materials.new("grey")
    if grey.node_tree is None:
        grey.use_nodes = True
    grey.node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = (0.7, 0.7, 0.7, 1.0)
    names = []
    for k, (o, du, dv) in enumerate(WALLS):
        V, F = grid(n, o, du, dv)
        mesh = bpy.data.meshes.new(f"wall{k}")
        mesh.from_pydata([tuple(v) for v in V], [], F)
        mesh.materials.append(grey)
        obj = bpy.data.objects.new(f"wall{k}", mesh)
        bpy.context.scene.collection.objects.link(obj)
        names.append(obj.name)
    bpy.ops.mesh.primitive_uv_sphere_add(segments=32, ring_count=16, radius=SPHERE[1], location=SPHERE[0])
    bpy.context.active_object.data.materials.append(grey)
    bpy.ops.object.light_add(type="AREA", location=LIGHT[0])
    light = bpy.context.active_object
    light.data.size = LIGHT[1]
    light.data.energy = LIGHT[2]
    bpy.context.view_layer.update()
    return names


def through_addon(bpy, addon, polygon_meshes, tol):
    """(seconds, radiance per target, stats) of collect + solve + gather through the add-on."""
    addon.objects.POLYGON_MESHES = polygon_meshes
    try:
        start = time.perf_counter()
        context = bpy.context
        collected = addon.collect.collect(
            context.scene, context.view_layer, context.evaluated_depsgraph_get()
        )
        sol = addon.solve.solve(collected, addon.solve.Settings(tol=tol))
        seconds = time.perf_counter() - start
    finally:
        addon.objects.POLYGON_MESHES = True
    return seconds, sol.radiance, sol.stats, len(collected.surfaces)


def reference(n, core, radiance_scale):
    """Reference radiosity at the interior grid vertices of every wall, shape (6, (n-1)^2, 3)."""
    scene = core.Scene()
    walls = []
    for o, du, dv in WALLS:
        o, du, dv = (np.asarray(x, dtype=float) for x in (o, du, dv))
        walls.append(scene.add(core.Quad(o, o + du, o + du + dv, o + dv), reflectance=0.7, patches=(16, 16)))
    scene.add(core.Sphere(*SPHERE), reflectance=0.7, patches=(8, 16))
    (x, y, z), size, _ = LIGHT
    h = size / 2
    lamp = core.Quad((x - h, y - h, z), (x - h, y + h, z), (x + h, y + h, z), (x + h, y - h, z))
    scene.add(lamp, emission=radiance_scale, reflectance=0.0, occluder=False, patches=(2, 2))
    sol = scene.solve(tol=1e-4)
    s = np.arange(1, n) / n
    u, v = (a.ravel() for a in np.meshgrid(s, s, indexing="ij"))
    return np.stack([sol.radiosity_at(w, u, v) for w in walls]), sol.stats


def interior(radiance, names, n):
    """The add-on's vertex radiance at the walls' interior vertices, shape (6, (n-1)^2, 3)."""
    i, j = (a.ravel() for a in np.meshgrid(np.arange(1, n), np.arange(1, n), indexing="ij"))
    return np.stack([radiance[name][0][i * (n + 1) + j] for name in names])


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--n", type=int, default=8)
    parser.add_argument("--tol", type=float, default=1e-3)
    parser.add_argument("--skip-before", action="store_true")
    parser.add_argument("--skip-after", action="store_true")
    parser.add_argument("--no-reference", action="store_true")
    args = parser.parse_args()
    sys.stdout.reconfigure(line_buffering=True)  # (bpy may end the process without flushing)
    import bpy

    import addon

    core = addon.core
    names = build(bpy, args.n)
    runs = {}
    for label, flag in (("after (PolygonMesh)", True), ("before (per-polygon Quads)", False)):
        if (flag is False and args.skip_before) or (flag is True and args.skip_after):
            continue
        seconds, radiance, stats, items = through_addon(bpy, addon, flag, args.tol)
        runs[label] = (seconds, radiance, stats, items)
        times = {k: round(v, 2) for k, v in stats["times"].items()}
        print(
            f"{label}: {seconds:.2f} s, {items} core surfaces, {stats['elements']} elements, "
            f"rays {stats.get('rays')}, bvh nodes {stats.get('bvh_nodes')}, times {times}"
        )
    # the area light's radiance as the add-on computes it: power / (pi * area) per channel
    emitted = LIGHT[2] / (np.pi * LIGHT[1] ** 2)
    if args.no_reference:
        return
    ref, ref_stats = reference(args.n, core, emitted)
    print(f"reference: {ref_stats['elements']} elements, mean interior wall radiance {ref.mean():.5f}")
    for label, (seconds, radiance, _, _) in runs.items():
        got = interior(radiance, names, args.n)
        rel = np.abs(got - ref) / ref.max()
        print(
            f"{label}: vs reference max |diff| / max {rel.max():.4f}, mean {rel.mean():.5f}; "
            f"mean ratio {got.mean() / ref.mean():.4f}"
        )
    if len(runs) == 2:
        (a, *_), (b, *_) = runs.values()
        print(f"speed-up after vs before: {b / a:.1f}x")
    print(f"peak RSS {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MB")


if __name__ == "__main__":
    main()
