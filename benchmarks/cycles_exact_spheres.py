"""Example 05's balls against Cycles on the shape the add-on lights: exact spheres.

    .venv/bin/python -m benchmarks.cycles_exact_spheres [--samples N] [--segments S]
        [--method PAIRS|HIERARCHICAL|AUTO] [--every K]

The add-on takes a UV sphere as the exact sphere through its vertices (`addon` maps it to
`core.Sphere`); Cycles renders the user's polyhedron (16 x 8 faces in example 05, flat faces up to
1 - cos(pi / 8) = 7.6 % of the radius inside the sphere, with a shadow terminator on the faces
that turn away from a light). To tell how much of the difference between the two is the shape,
the add-on's values at the user's vertices are compared with two Cycles references:

- "polyhedron": Cycles COMBINED vertex bakes of the scene as the user made it (what
  `benchmarks.cycles_agreement` compares with);
- "exact": the same bakes after every ball's mesh is replaced by a UV sphere of S x S/2 faces
  (S a multiple of 16, so its vertices include the user's 16 x 8 ones, matched by position),
  which lies within 1 - cos(pi / S) of the exact sphere.

Every K-th ball (row-major) is baked, two seeds each; all balls are replaced for the exact
reference, so the balls shadow and light each other as exact spheres too. Numbers: rms of ours
minus the bakes' mean net of Cycles' noise, bias and noise, in % of each ball's level
(`cycles_bake.agreement`). Not part of the test suite; results go to BENCHMARKS.md by hand.
"""

import argparse
import time

import numpy as np

from benchmarks.blender_addon import ROOT, bpy, install_addon  # before anything else imports bpy
from benchmarks.cycles_agreement import world_vertices
from benchmarks.cycles_bake import agreement, bake_combined, prepare_cycles

SCENE = ROOT / "blender_scenes" / "05_stress_many_spheres.blend"


def local_vertices(mesh):
    co = np.empty(len(mesh.vertices) * 3)
    mesh.vertices.foreach_get("co", co)
    return co.reshape(-1, 3)


def fine_sphere(name, radius, segments, materials):
    """A smooth-shaded UV sphere mesh of `segments` x `segments / 2` faces about the origin."""
    import bmesh

    bm = bmesh.new()
    bmesh.ops.create_uvsphere(bm, u_segments=segments, v_segments=segments // 2, radius=radius)
    mesh = bpy.data.meshes.new(name)
    bm.to_mesh(mesh)
    bm.free()
    for material in materials:
        mesh.materials.append(material)
    mesh.shade_smooth()
    return mesh


def matched(coarse, fine):
    """Index into `fine` of each `coarse` vertex (nearest), and the largest distance."""
    d2 = ((coarse[:, None, :] - fine[None, :, :]) ** 2).sum(2)
    index = d2.argmin(1)
    return index, float(np.sqrt(d2[np.arange(len(coarse)), index].max()))


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=256, help="Cycles samples per bake (two seeds)")
    parser.add_argument("--segments", type=int, default=64, help="the exact reference's segments")
    parser.add_argument("--method", default="AUTO", choices=["AUTO", "PAIRS", "HIERARCHICAL"], help="solver")
    parser.add_argument("--every", type=int, default=12, help="bake every K-th ball")
    parser.add_argument("--save", default=None, help="write ours, the bakes and the vertices to this .npz")
    args = parser.parse_args(argv)
    if args.segments % 16:
        raise SystemExit("--segments must be a multiple of 16 (its vertices include the 16 x 8 ones)")
    addon = install_addon()
    bpy.ops.wm.open_mainfile(filepath=str(SCENE))
    scene = bpy.context.scene
    prepare_cycles(scene, args.samples)
    scene.curved_radiosity.method = args.method
    names = sorted(o.name for o in scene.objects if o.type == "MESH" and o.name.startswith("Ball"))
    balls = [scene.objects[name] for name in names]
    for obj in balls:
        obj.data.shade_smooth()  # Cycles uses the vertex normals, as the add-on does
    start = time.perf_counter()
    job = addon.pipeline.prepare(bpy.context)
    addon.pipeline.run(job)
    ours_time = time.perf_counter() - start
    ours = {obj.name: job.solution.radiance[obj.name][0] for obj in balls}
    chosen = balls[:: args.every]
    start = time.perf_counter()
    coarse = [bake_combined(bpy, chosen, args.samples, seed) for seed in (0, 1)]
    coarse_time = time.perf_counter() - start
    # every ball becomes a fine UV sphere with the same object transform and materials
    index, gap = {}, 0.0
    for obj in balls:
        old = obj.data
        radius = float(np.linalg.norm(local_vertices(old), axis=1).max())
        new = fine_sphere(f"{obj.name} fine", radius, args.segments, list(old.materials))
        index[obj.name], distance = matched(local_vertices(old), local_vertices(new))
        gap = max(gap, distance / radius)
        obj.data = new
    start = time.perf_counter()
    fine = [bake_combined(bpy, chosen, args.samples, seed) for seed in (0, 1)]
    fine_time = time.perf_counter() - start
    print(
        f"{len(balls)} balls, {len(chosen)} baked, method {args.method} ({job.settings.method}), "
        f"ours {ours_time:.1f} s; Cycles {args.samples} samples x 2: polyhedra {coarse_time:.1f} s, "
        f"{args.segments}-segment spheres {fine_time:.1f} s; largest vertex match distance "
        f"{gap:.1e} of the radius"
    )
    print()
    print("| ball | vertices | polyhedron: rms net, bias, noise % | exact: rms net, bias, noise % |")
    print("|---|---|---|---|")
    summary = {"polyhedron": [], "exact": []}
    for obj in chosen:
        a = agreement(ours[obj.name], coarse[0][obj.name], coarse[1][obj.name])
        b = agreement(ours[obj.name], *(f[obj.name][index[obj.name]] for f in fine))
        summary["polyhedron"].append(a["rms"])
        summary["exact"].append(b["rms"])
        cells = [", ".join(f"{100 * r[k]:.2f}" for k in ("rms", "bias", "noise")) for r in (a, b)]
        print(f"| {obj.name} | {a['vertices']} | {cells[0]} | {cells[1]} |")
    if args.save:
        arrays = {}
        for obj in chosen:
            arrays[f"{obj.name}/ours"] = ours[obj.name]
            arrays[f"{obj.name}/vertices"] = world_vertices(obj)[index[obj.name]]  # (fine mesh now)
            for k in (0, 1):
                arrays[f"{obj.name}/polyhedron{k}"] = coarse[k][obj.name]
                arrays[f"{obj.name}/exact{k}"] = fine[k][obj.name][index[obj.name]]
        np.savez(args.save, **arrays)
    print()
    for label, values in summary.items():
        values = 100 * np.asarray(values)
        print(
            f"{label}: rms net % over the baked balls: min {values.min():.2f}, "
            f"median {np.median(values):.2f}, max {values.max():.2f}"
        )


if __name__ == "__main__":
    main()
