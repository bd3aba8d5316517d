"""A room of about 10,000 mesh polygons through the add-on (issue 12): time and peak memory.

A 6 x 6 x 3 m room whose floor, ceiling and four walls are subdivided grids (`--cells` per metre),
a table and two boxes as subdivided cube meshes, a UV sphere (an exact `Sphere`) and an area
light. Collected and solved by the repository's add-on package (the same code the extension
runs): one `core.PolygonMesh` per object. Prints the polygon and element counts, the stage
times of the solve, the total time of collect + solve + gather and the process's peak RSS.

Run alone: python -m benchmarks.mesh_room [--cells 8] [--tol 1e-2] [--method pairs|hierarchical]
[--no-near-field] [--node-pairs N] [--save radiance.npy] [--keep-faces]
"""

import argparse
import resource
import sys
import time

import numpy as np

W, D, H = 6.0, 6.0, 3.0


def grid(nu, nv, origin, du, dv):
    o, du, dv = (np.asarray(x, dtype=float) for x in (origin, du, dv))
    V = np.array([o + du * i / nu + dv * j / nv for i in range(nu + 1) for j in range(nv + 1)])
    F = [
        (i * (nv + 1) + j, (i + 1) * (nv + 1) + j, (i + 1) * (nv + 1) + j + 1, i * (nv + 1) + j + 1)
        for i in range(nu)
        for j in range(nv)
    ]
    return V, F


def add_mesh(bpy, name, V, F, material):
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata([tuple(v) for v in V], [], F)
    mesh.materials.append(material)
    obj = bpy.data.objects.new(name, mesh)
    bpy.context.scene.collection.objects.link(obj)
    return obj


def build(bpy, cells):
    """The room; returns its polygon count."""
    bpy.ops.wm.read_homefile(use_empty=True)
    grey = bpy.data.materials.new("grey")
    if grey.node_tree is None:
        grey.use_nodes = True
    grey.node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = (0.7, 0.7, 0.7, 1.0)
    grey.use_backface_culling = True  # one-sided (two-sided faces would double the elements)
    n = lambda length: max(1, int(round(cells * length)))  # noqa: E731
    surfaces = [  # origin, du, dv with du x dv into the room
        ("floor", (0, 0, 0), (W, 0, 0), (0, D, 0)),
        ("ceiling", (0, 0, H), (0, D, 0), (W, 0, 0)),
        ("wall_x0", (0, 0, 0), (0, D, 0), (0, 0, H)),
        ("wall_x1", (W, 0, 0), (0, 0, H), (0, D, 0)),
        ("wall_y0", (0, 0, 0), (0, 0, H), (W, 0, 0)),
        ("wall_y1", (0, D, 0), (W, 0, 0), (0, 0, H)),
    ]
    polygons = 0
    for name, o, du, dv in surfaces:
        V, F = grid(n(np.linalg.norm(du)), n(np.linalg.norm(dv)), o, du, dv)
        add_mesh(bpy, name, V, F, grey)
        polygons += len(F)
    for k, (location, scale) in enumerate(
        [
            ((2.0, 3.0, 0.4), (0.9, 0.6, 0.4)),
            ((4.5, 1.5, 0.3), (0.3, 0.3, 0.3)),
            ((4.6, 4.5, 0.5), (0.4, 0.4, 0.5)),
        ]
    ):
        bpy.ops.mesh.primitive_cube_add(location=location, scale=scale)
        obj = bpy.context.active_object
        obj.data.materials.append(grey)
        bpy.ops.object.modifier_add(type="SUBSURF")
        obj.modifiers[-1].levels = 2
        obj.modifiers[-1].subdivision_type = "SIMPLE"
        polygons += 6 * 16
    bpy.ops.mesh.primitive_uv_sphere_add(segments=32, ring_count=16, radius=0.5, location=(1.5, 1.2, 0.5))
    bpy.context.active_object.data.materials.append(grey)
    polygons += 32 * 16
    bpy.ops.object.light_add(type="AREA", location=(W / 2, D / 2, H - 0.05))
    bpy.context.active_object.data.size = 1.0
    bpy.context.active_object.data.energy = 300.0
    bpy.context.view_layer.update()
    return polygons


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--cells", type=float, default=8.0, help="grid cells per metre (8: ~10,000 polygons)")
    parser.add_argument("--tol", type=float, default=1e-2)
    parser.add_argument("--method", default="auto", choices=("auto", "pairs", "hierarchical"))
    parser.add_argument("--no-near-field", action="store_true", help="gather without the near field")
    parser.add_argument("--node-pairs", type=int, help="the near field's NODE_PAIRS (default: the core's)")
    parser.add_argument("--save", help="save every target's vertex radiance (concatenated) to this .npy")
    parser.add_argument("--keep-faces", action="store_true", help="no merging of coplanar faces")
    args = parser.parse_args()
    sys.stdout.reconfigure(line_buffering=True)  # (bpy may end the process without flushing)
    import bpy

    import addon
    from addon.core import nearfield, scene

    if args.node_pairs:
        nearfield.NODE_PAIRS = args.node_pairs
    if args.keep_faces:
        import addon.objects

        addon.objects.MERGE_COPLANAR = False
    if args.no_near_field:
        solution_init = scene.Solution.__init__

        def without_near_field(self, *a, **k):
            solution_init(self, *a, **k)
            self.near_field = False

        scene.Solution.__init__ = without_near_field

    polygons = build(bpy, args.cells)
    start = time.perf_counter()
    context = bpy.context
    collected = addon.collect.collect(context.scene, context.view_layer, context.evaluated_depsgraph_get())
    collected_at = time.perf_counter() - start
    sol = addon.solve.solve(collected, addon.solve.Settings(tol=args.tol, method=args.method))
    total = time.perf_counter() - start
    stats = sol.stats
    times = {k: round(v, 1) for k, v in stats["times"].items()}
    print(
        f"{polygons} polygons, {len(collected.surfaces)} core surfaces, {stats['elements']} elements,"
        f" tol {args.tol}, solver {stats.get('solver')}"
    )
    print(f"collect {collected_at:.1f} s, total {total:.1f} s; stages {times}")
    print(
        f"rays {stats.get('rays')}, bvh nodes {stats.get('bvh_nodes')},"
        f" primitives {stats.get('bvh_primitives')}"
    )
    gather = {k: v for k, v in stats.items() if k.startswith("gather_")}
    print(f"gather (near-field nodes and vertices) {gather}")
    near = {k: v for k, v in stats.items() if k.startswith("near_")}
    print(f"near field {near}")
    if args.save:
        np.save(args.save, np.concatenate([np.ravel(v[0]) for _, v in sorted(sol.radiance.items())]))
    print(
        f"solve memory {stats['memory_bytes'] / 2**20:.0f} MB, peak RSS "
        f"{resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MB"
    )


if __name__ == "__main__":
    main()
