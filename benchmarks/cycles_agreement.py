"""The add-on against Cycles: vertex radiance compared with COMBINED bakes, and both timed.

    .venv/bin/python -m benchmarks.cycles_agreement [--samples N] [--noise 0.002] [--bake-budget S]
        [--scenes NAME ...] [--method PAIRS|HIERARCHICAL|AUTO] [--node-pairs N] [--no-timing] [--dump DIR]
        [--references DIR]

Scenes: the example scenes in blender_scenes/, a closed box with a UV sphere resting on its
floor under an area light (built here, Diffuse BSDF materials), and `mesh_room` (the
2,096-polygon room of `benchmarks.mesh_room`, Diffuse BSDF; not in the default list). For each
mesh object that gets results (NURBS and other twin targets have no mesh of their own to bake:
listed as skipped):

- Cycles bakes COMBINED (outgoing radiance: emission + rho E / pi) to a colour attribute twice,
  seeds 0 and 1, at `--samples` samples, then each object still noisier than `--noise` (0.2 %
  of its level, the noise of the two bakes' mean) again, in groups of like sample counts, at the
  samples that take it there, within `--bake-budget` s per bake (`cycles_bake.converged_bakes`;
  the table lists the samples each object got: a 4-vertex wall at 256 samples carries 2-6 %
  noise); the bakes' difference measures Cycles' noise, and the rms difference from the add-on
  is reported net of it (`cycles_bake.agreement`), with the bias,
  the worst vertex (beyond 3 noise sigmas) and, separately, contact vertices (within 1e-3 of
  the scene's size of another object) and seam vertices (where the object's own faces meet at
  more than 30 degrees), all relative to the object's mean level, in %;
- seam and contact vertices once more against the limit from inside each of the object's planes
  around them (probes 1e-4 of the scene's size inside each face, `limit_probes`, in bakes of
  their own): a render shows the surface next to the seam, and a vertex on a concave seam or
  corner also lies in the other face's plane; per plane only the probes on its visible side
  count (`limit_values`: a floor vertex on the edge of a box resting there has faces under the
  box; Cycles' own vertex bake averages its corners, so it gives half the value beside the box
  there); "limits" is the whole object with those values at its seam and contact vertices;
- UV spheres (exact spheres for the add-on) are shaded smooth before baking, so that Cycles
  uses their vertex normals;
- timing: the add-on's compute (collect, solve, per-vertex gather; not writing results) next
  to a Cycles bake of every compared object at the sample count that gives 1 % noise (from
  the measured noise: N_1% = N (noise / 1 %)^2), run in the same process.

`--references DIR` takes the bakes and limits from an earlier `--dump DIR` of the same scenes
instead of baking (the add-on is re-measured in its own time; the vertices must match):
benchmarks/results/cycles_references/ holds the mesh room's.

Not part of the test suite (it takes minutes); results go to BENCHMARKS.md by hand.
"""

import argparse
import time
from pathlib import Path

import numpy as np

from benchmarks.blender_addon import ROOT, bpy, install_addon  # before anything else imports bpy
from benchmarks.cycles_bake import (
    agreement,
    bake_combined,
    converged_bakes,
    diffuse_material,
    prepare_cycles,
    probe_object,
)

SCENES = ROOT / "blender_scenes"
EXAMPLES = [
    "01_seed_sphere_over_square",
    "02_sphere_in_cube",
    "03_cornell_box",
    "04_nurbs_only",
    "05_stress_many_spheres",
]
CONTACT = 1e-3  # of the scene's size
SEAM_DEGREES = 30.0
# of the scene's size: how far inside a face a limit probe sits (at 1e-3, 3.5 mm in the Cornell
# box, Cycles' radiance at a top corner of its walls was 8 % above the corner's own: no limit)
PROBE_INSET = 1e-4
NOISE = 0.002  # the reference bakes' noise (of their mean, relative to the object's mean level)
BAKE_BUDGET = 300.0  # s per reference bake of one object
VISIBLE_SHARE = 0.5  # probes below this share of their plane's brightest lie on its hidden side


def closed_box():
    """A closed 2 m box (inward faces, 4 x 4 faces a side), a UV sphere resting on its floor, an
    area light under the ceiling; Diffuse BSDF materials, black world."""
    bpy.ops.wm.read_homefile(use_empty=True)
    scene = bpy.context.scene
    scene.world = bpy.data.worlds.new("Black")
    scene.world.node_tree.nodes["Background"].inputs["Color"].default_value = (0.0, 0.0, 0.0, 1.0)
    bpy.ops.mesh.primitive_cube_add(size=2.0, location=(0.0, 0.0, 1.0))
    box = bpy.context.active_object
    box.name = "Box"
    bpy.ops.object.mode_set(mode="EDIT")
    bpy.ops.mesh.subdivide(number_cuts=3)
    bpy.ops.mesh.flip_normals()
    bpy.ops.object.mode_set(mode="OBJECT")
    box.data.materials.append(diffuse_material(bpy, "Walls", (0.7, 0.7, 0.7)))
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.4, location=(0.2, -0.1, 0.4), segments=32, ring_count=16)
    ball = bpy.context.active_object
    ball.name = "Ball"
    bpy.ops.object.shade_smooth()
    ball.data.materials.append(diffuse_material(bpy, "Ball", (0.6, 0.3, 0.2)))
    light = bpy.data.lights.new("Lamp", "AREA")
    light.size, light.energy = 0.6, 40.0
    lamp = bpy.data.objects.new("Lamp", light)
    lamp.location = (0.0, 0.0, 1.98)
    scene.collection.objects.link(lamp)


def mesh_room():
    """The 2,096-polygon room of `benchmarks.mesh_room` (subdivided walls, three subdivided boxes,
    a UV sphere, an area light), its material a one-sided Diffuse BSDF, black world."""
    from benchmarks import mesh_room as room

    room.build(bpy, 3.0)
    scene = bpy.context.scene
    scene.world = bpy.data.worlds.new("Black")
    scene.world.node_tree.nodes["Background"].inputs["Color"].default_value = (0.0, 0.0, 0.0, 1.0)
    grey = diffuse_material(bpy, "Grey", (0.7, 0.7, 0.7))
    grey.use_backface_culling = True  # (one-sided, as the benchmark's)
    for obj in scene.objects:
        if obj.type == "MESH":
            obj.data.materials.clear()
            obj.data.materials.append(grey)


def world_vertices(obj):
    co = np.empty(len(obj.data.vertices) * 3, np.float32)
    obj.data.vertices.foreach_get("co", co)
    M = np.array(obj.matrix_world)
    return co.reshape(-1, 3).astype(np.float64) @ M[:3, :3].T + M[:3, 3]


def faces_around(mesh):
    """(face normals (F, 3), dict vertex -> faces holding it)."""
    faces_of = {}
    for p in mesh.polygons:
        for v in p.vertices:
            faces_of.setdefault(v, []).append(p.index)
    return np.array([p.normal for p in mesh.polygons]), faces_of


def seam_vertices(obj):
    """Vertices where two of the object's faces meet at more than SEAM_DEGREES, shape (V,) bool."""
    seam = np.zeros(len(obj.data.vertices), dtype=bool)
    normals, faces_of = faces_around(obj.data)
    limit = np.cos(np.radians(SEAM_DEGREES))
    for v, faces in faces_of.items():
        n = normals[faces]
        if len(faces) > 1 and (n @ n.T).min() < limit:
            seam[v] = True
    return seam


def plane_groups(obj, vertices):
    """For each vertex in `vertices`: its faces grouped by plane (faces whose normals differ by
    more than SEAM_DEGREES lie in different planes), as a list of lists of face indices."""
    normals, faces_of = faces_around(obj.data)
    limit = np.cos(np.radians(SEAM_DEGREES))
    groups = []
    for v in vertices:
        planes = []
        for f in faces_of.get(int(v), []):
            for plane in planes:
                if normals[f] @ normals[plane[0]] >= limit:
                    plane.append(f)
                    break
            else:
                planes.append([f])
        groups.append(planes)
    return groups


def limit_probes(obj, vertices, size):
    """Probes (`cycles_bake.probe_object`) for Cycles' value at each vertex as the limit from
    inside each face around it: per (vertex, face) one probe PROBE_INSET x size from the vertex
    toward that face's centre. Returns (probe object, owner (P,): index into `vertices` of each
    probe, plane (P,): the probe's plane, numbered over all vertices)."""
    mesh = obj.data
    M = np.array(obj.matrix_world)
    world = world_vertices(obj)
    normal_matrix = np.linalg.inv(M[:3, :3]).T
    points, normals, inward, materials, owner, plane_of = [], [], [], [], [], []
    planes = 0
    for k, (v, group) in enumerate(zip(vertices, plane_groups(obj, vertices))):
        for faces in group:
            for f in faces:
                poly = mesh.polygons[f]
                n = normal_matrix @ np.array(poly.normal)
                n /= np.linalg.norm(n)
                d = world[list(poly.vertices)].mean(0) - world[v]
                d -= (d @ n) * n
                d /= np.linalg.norm(d)
                points.append(world[v] + PROBE_INSET * size * d)
                normals.append(n)
                inward.append(d)
                materials.append(poly.material_index)
                owner.append(k)
                plane_of.append(planes)
            planes += 1
    probe = probe_object(
        bpy,
        f"{obj.name} probes",
        points,
        normals,
        inward,
        PROBE_INSET * size,
        [slot.material for slot in obj.material_slots],
        materials,
    )
    return probe, np.array(owner, dtype=np.int64), np.array(plane_of, dtype=np.int64)


def limit_values(bakes, probe, owner, plane, count):
    """Each vertex's limit per bake, list of (count, 3): per plane around it the mean of the
    probes on its visible side (faces at least VISIBLE_SHARE of the plane's brightest probe:
    a floor vertex on the edge of a box resting there has faces under the box), averaged over
    its planes."""
    planes = int(plane.max()) + 1 if plane.size else 0
    plane_owner = np.zeros(planes, dtype=np.int64)
    plane_owner[plane] = owner
    out = []
    for bake in bakes:
        values = bake[probe.name][0::3]  # each probe triangle's first vertex
        brightness = values.sum(1)
        brightest = np.zeros(planes)
        np.maximum.at(brightest, plane, brightness)
        seen = brightness >= VISIBLE_SHARE * brightest[plane]
        per_plane = np.zeros((planes, 3))
        np.add.at(per_plane, plane[seen], values[seen])
        per_plane /= np.maximum(np.bincount(plane[seen], minlength=planes), 1)[:, None]
        total = np.zeros((count, 3))
        np.add.at(total, plane_owner, per_plane)
        out.append(total / np.maximum(np.bincount(plane_owner, minlength=count), 1)[:, None])
    return out


def contact_vertices(obj, others, size):
    """Vertices within CONTACT x size of another object's surface, shape (V,) bool."""
    from mathutils import Vector
    from mathutils.bvhtree import BVHTree

    depsgraph = bpy.context.evaluated_depsgraph_get()
    points = world_vertices(obj)
    near = np.zeros(len(points), dtype=bool)
    for other in others:
        tree = BVHTree.FromObject(other, depsgraph)  # in the object's local frame
        inverse = np.linalg.inv(np.array(other.matrix_world))
        scale = np.abs(np.linalg.det(np.array(other.matrix_world)[:3, :3])) ** (1 / 3)
        local = points @ inverse[:3, :3].T + inverse[:3, 3]
        for k, p in enumerate(local):
            hit = tree.find_nearest(Vector(p), CONTACT * size / max(scale, 1e-12))
            near[k] |= hit[0] is not None
    return near


def scene_size():
    points = [world_vertices(o) for o in bpy.context.scene.objects if o.type == "MESH"]
    points = np.concatenate(points)
    return float(np.linalg.norm(points.max(0) - points.min(0)))


def compare_scene(
    addon, name, samples, reference=(NOISE, BAKE_BUDGET), timing_bake=True, dump=None, stored=None
):
    """Rows of the table for the current scene, and the timing row (without the 1 %-noise bake
    unless `timing_bake`); the reference bakes start at `samples` and go on to `reference` =
    (noise, seconds per bake: `cycles_bake.converged_bakes`); with `dump` (a folder), each
    object's vertices, values and masks go to `<dump>/<scene>.<object>.npz` as well; with `stored`
    (a folder of such files from an earlier run of the same scene), its bakes and limits are the
    references and nothing is baked (Cycles' values do not depend on the add-on's code)."""
    bpy.context.view_layer.update()
    start = time.perf_counter()
    job = addon.pipeline.prepare(bpy.context)
    # the add-on takes a UV sphere as the exact sphere: Cycles gets its smooth normals (a flat-
    # shaded sphere's vertices would average its faces' normals instead)
    spheres = {i.target for i in job.collected.surfaces if type(i.surface).__name__ == "Sphere"}
    for name_ in spheres:
        obj = bpy.data.objects.get(name_)
        if obj is not None and obj.type == "MESH":
            obj.data.shade_smooth()
    addon.pipeline.run(job)
    ours_time = time.perf_counter() - start
    targets = job.collected.targets
    meshes = [bpy.data.objects[t] for t, target in targets.items() if not target.twin]
    skipped = [t for t, target in targets.items() if target.twin]
    if not meshes:
        return [], dict(scene=name, ours=ours_time, skipped=skipped)
    size = scene_size()
    others = {
        obj.name: [o for o in bpy.context.scene.objects if o.type == "MESH" and o is not obj]
        for obj in meshes
    }
    seams = {obj.name: seam_vertices(obj) for obj in meshes}
    contacts = {obj.name: contact_vertices(obj, others[obj.name], size) for obj in meshes}
    # seam and contact vertices (where this object's faces, or another object, meet it) are
    # judged again against the limit from inside each of this object's faces around them
    edges = {name_: seams[name_] | contacts[name_] for name_ in seams}
    probes = {
        obj.name: limit_probes(obj, np.flatnonzero(edges[obj.name]), size)
        for obj in meshes
        if edges[obj.name].any()
    }
    if stored is not None:
        first, second, counts, stored_limits = stored_bakes(stored, name, meshes)
        bake_time, timing_bake, probes, probe_bakes = float("nan"), False, {}, []
    else:
        first, second, counts, bake_time = converged_bakes(bpy, meshes, samples, *reference)
        # the probes in bakes of their own (they are invisible to the meshes' rays)
        probe_objects = [p for p, _, _ in probes.values()]
        probe_bakes = converged_bakes(bpy, probe_objects, samples, *reference)[:2] if probes else []
    rows, for_one_percent = [], []
    for obj in meshes:
        ours = job.solution.radiance[obj.name][0]
        contact, seam, edge = contacts[obj.name], seams[obj.name], edges[obj.name]
        whole = agreement(ours, first[obj.name], second[obj.name])
        # the same with each seam vertex's bake replaced by the mean over its planes of the
        # limit from inside each (`limit_probes`)
        limits = [first[obj.name].copy(), second[obj.name].copy()]
        if stored is not None:
            limits = list(stored_limits[obj.name])
        elif obj.name in probes:
            probe, owner, plane = probes[obj.name]
            for k, value in enumerate(limit_values(probe_bakes, probe, owner, plane, int(edge.sum()))):
                limits[k][edge] = value
        limit = agreement(ours, *limits)
        level = 0.5 * (first[obj.name] + second[obj.name]).sum(1)
        # a part's numbers relative to the whole object's level (a dark corner's own level is small)
        parts = {}
        vertex_bakes = (first[obj.name], second[obj.name])
        for label, mask, bakes in (
            ("contact", contact, vertex_bakes),
            ("seam", seam, vertex_bakes),
            ("seam_limit", edge, limits),
        ):
            report = agreement(ours, *bakes, mask)
            if report["vertices"]:
                part_scale = np.abs(level[mask]).mean() / max(np.abs(level).mean(), 1e-300)
                report = {
                    k: (v * part_scale if k in ("rms", "bias", "worst") else v) for k, v in report.items()
                }
            parts[label] = report
        rows.append(
            dict(scene=name, object=obj.name, samples=counts[obj.name], whole=whole, limit=limit, **parts)
        )
        if dump is not None:
            Path(dump).mkdir(parents=True, exist_ok=True)
            np.savez(
                Path(dump) / f"{name}.{obj.name}.npz",
                vertices=world_vertices(obj),
                ours=ours,
                cycles=np.stack([first[obj.name], second[obj.name]]),
                limits=np.stack(limits),
                contact=contact,
                seam=seam,
                samples=counts[obj.name],
            )
        # the samples that give 1 % noise, from this object's noise at its own count
        for_one_percent.append(counts[obj.name] * (whole["noise"] / 0.01) ** 2)
    for probe, _, _ in probes.values():
        bpy.data.objects.remove(probe)
    # the sample count giving 1 % noise on every object, timed in this run
    samples_1 = max(int(np.ceil(max(for_one_percent))), 1)
    worst_noise = 0.01 * np.sqrt(samples_1 / samples)  # (every object's noise at `samples`, at most)
    start = time.perf_counter()
    if timing_bake:
        bake_combined(bpy, meshes, samples_1, seed=2)
    cycles_1 = time.perf_counter() - start if timing_bake else float("nan")
    timing = dict(
        scene=name,
        ours=ours_time,
        samples=samples,
        bake=bake_time,
        noise=worst_noise,
        samples_1=samples_1,
        cycles_1=cycles_1,
        skipped=skipped,
    )
    if stored is not None:  # (no bakes in this run: nothing of Cycles' is timed)
        timing.update(samples="stored", noise=float("nan"), samples_1="-")
    return rows, timing


def stored_bakes(folder, name, meshes):
    """The bakes, sample counts and limits of `meshes` stored by an earlier `--dump` run of scene
    `name` (`compare_scene`), after checking that each object's vertices are those stored."""
    first, second, counts, limits = {}, {}, {}, {}
    for obj in meshes:
        path = Path(folder) / f"{name}.{obj.name}.npz"
        if not path.exists():
            raise SystemExit(f"no stored references for {obj.name!r} of {name}: {path} is missing")
        data = np.load(path)
        if data["vertices"].shape != (len(obj.data.vertices), 3) or not np.allclose(
            data["vertices"], world_vertices(obj), atol=1e-6
        ):
            raise SystemExit(f"{path} holds other vertices than {obj.name!r} of {name} has now")
        first[obj.name], second[obj.name] = data["cycles"]
        counts[obj.name] = int(data["samples"]) if "samples" in data.files else 0
        limits[obj.name] = tuple(data["limits"])
    return first, second, counts, limits


def percent(value):
    return "-" if not np.isfinite(value) else f"{100 * value:.2f}"


def table(rows, timings):
    lines = [
        "| scene | object | vertices | samples | rms net % | bias % | worst % | noise % "
        "| contact: n, rms %, bias % | seam: n, rms %, bias % | limits: rms net %, bias % "
        "| seam/contact vs limit: rms %, bias % |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        w, c, s, lim, sl = r["whole"], r["contact"], r["seam"], r["limit"], r["seam_limit"]
        lines.append(
            f"| {r['scene']} | {r['object']} | {w['vertices']} | {r['samples']} | {percent(w['rms'])} "
            f"| {percent(w['bias'])} "
            f"| {percent(w['worst'])} | {percent(w['noise'])} "
            f"| {c['vertices']}, {percent(c['rms'])}, {percent(c['bias'])} "
            f"| {s['vertices']}, {percent(s['rms'])}, {percent(s['bias'])} "
            f"| {percent(lim['rms'])}, {percent(lim['bias'])} | {percent(sl['rms'])}, {percent(sl['bias'])} |"
        )
    lines += [
        "",
        "| scene | add-on (s) | Cycles samples / noise % / bake (s) | Cycles at 1 % noise: samples, bake (s) "
        "| not compared |",
        "|---|---|---|---|---|",
    ]
    for t in timings:
        if "samples" not in t:
            lines.append(f"| {t['scene']} | {t['ours']:.1f} | - | - | {', '.join(t['skipped'])} |")
            continue
        lines.append(
            f"| {t['scene']} | {t['ours']:.1f} | {t['samples']} / {percent(t['noise'])} / {t['bake']:.1f} "
            f"| {t['samples_1']}, {t['cycles_1']:.1f} | {', '.join(t['skipped']) or '-'} |"
        )
    return "\n".join(lines)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=256, help="Cycles samples per first bake (two seeds)")
    parser.add_argument("--noise", type=float, default=NOISE, help="reference bakes' noise (relative)")
    parser.add_argument("--bake-budget", type=float, default=BAKE_BUDGET, help="s per reference bake")
    parser.add_argument("--scenes", nargs="*", default=None, help="example scene names and/or closed_box")
    parser.add_argument("--method", default="PAIRS", choices=["AUTO", "PAIRS", "HIERARCHICAL"], help="solver")
    parser.add_argument("--node-pairs", type=int, help="the near field's NODE_PAIRS (default: the core's)")
    parser.add_argument("--no-timing", action="store_true", help="skip the bake at 1 %% noise (its time)")
    parser.add_argument("--dump", help="a folder for each object's per-vertex values (.npz)")
    parser.add_argument("--keep-faces", action="store_true", help="no merging of a mesh's coplanar faces")
    parser.add_argument("--patch-size", type=float, help="the core's AUTO_PATCH_SIZE (default: the core's)")
    parser.add_argument("--quality", default="NORMAL", help="the add-on's quality preset")
    parser.add_argument(
        "--references",
        help="a --dump folder of an earlier run: its Cycles bakes are the references (no baking)",
    )
    args = parser.parse_args(argv)
    names = args.scenes or ["closed_box"] + EXAMPLES
    addon = install_addon()
    if args.node_pairs:
        addon.core.nearfield.NODE_PAIRS = args.node_pairs
    if args.keep_faces:
        addon.objects.MERGE_COPLANAR = False
    if args.patch_size:
        addon.core.scene.AUTO_PATCH_SIZE = args.patch_size
    rows, timings = [], []
    for name in names:
        if name == "closed_box":
            closed_box()
        elif name == "mesh_room":
            mesh_room()
        else:
            bpy.ops.wm.open_mainfile(filepath=str(SCENES / f"{name}.blend"))
        prepare_cycles(bpy.context.scene, args.samples)
        bpy.context.scene.curved_radiosity.method = args.method
        bpy.context.scene.curved_radiosity.quality = args.quality
        start = time.perf_counter()
        reference = (args.noise, args.bake_budget)
        scene_rows, timing = compare_scene(
            addon, name, args.samples, reference, not args.no_timing, args.dump, args.references
        )
        rows += scene_rows
        timings.append(timing)
        print(f"{name}: {time.perf_counter() - start:.1f} s", flush=True)
        print(table(scene_rows, [timing]), flush=True)  # (each scene as it is done)
    print(table(rows, timings))


if __name__ == "__main__":
    main()
