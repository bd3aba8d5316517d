"""Our lightmap against a Cycles COMBINED bake through the same UV map (issue 16's acceptance).

Run from the repository root (Blender as a Python module; not part of the test suite):

    .venv/bin/python -m benchmarks.cycles_lightmap [--size 64] [--samples 1024]
        [--method PAIRS|HIERARCHICAL|AUTO]

Scene: a one-quad 4 m floor (Diffuse BSDF 0.5), a sphere of radius 0.5 resting on it (Diffuse
BSDF 0.5), a 1 m square area light of 200 W 3 m up, black world. Cycles bakes COMBINED (= outgoing radiance:
emission + rho * irradiance / pi for a diffuse surface, in W / (m^2 sr)) into a float image through
the floor's UVMap with two seeds; their difference estimates the noise. Ours: the floor's
lightmap through the same map. Reported: rms of (ours - Cycles mean) relative to the mean, the
noise part of it (rms of the seed difference / 2, which is the noise of the mean), and the
difference net of noise sqrt(max(rms^2 - noise^2, 0)); over all texels, away from the image
border (2 texels) and in the contact region (within 0.5 m of the sphere's foot). Times of both.
"""

import argparse
import sys
import time
from pathlib import Path

import bpy
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import addon  # noqa: E402 (the repository's add-on, after its root is on sys.path)
from benchmarks.cycles_bake import bake_image, black_world  # noqa: E402

SIDE = 4.0


def diffuse(name, base):
    """A Diffuse BSDF (Lambertian at roughness 0) of reflectance `base`."""
    material = bpy.data.materials.new(name)
    if material.node_tree is None:
        material.use_nodes = True
    tree = material.node_tree
    tree.nodes.clear()
    bsdf = tree.nodes.new("ShaderNodeBsdfDiffuse")
    bsdf.inputs["Color"].default_value = (base, base, base, 1.0)
    bsdf.inputs["Roughness"].default_value = 0.0
    output = tree.nodes.new("ShaderNodeOutputMaterial")
    tree.links.new(bsdf.outputs["BSDF"], output.inputs["Surface"])
    return material


def build():
    bpy.ops.wm.read_homefile(use_empty=True)
    bpy.ops.mesh.primitive_plane_add(size=SIDE)
    floor = bpy.context.active_object
    floor.name = "Floor"
    floor.data.materials.append(diffuse("Floor", 0.5))
    bpy.ops.mesh.primitive_uv_sphere_add(segments=48, ring_count=24, radius=0.5, location=(0, 0, 0.5))
    bpy.ops.object.shade_smooth()
    bpy.context.active_object.data.materials.append(diffuse("Ball", 0.5))
    bpy.ops.object.light_add(type="AREA", location=(0.4, 0.3, 3.0))
    light = bpy.context.active_object
    light.data.energy = 200.0
    light.data.size = 1.0
    black_world(bpy)  # for both (a new world renders 0.05 grey in Cycles)
    return floor


def ours(floor, size, quality, method):
    floor.curved_radiosity_output = "LIGHTMAP"
    floor.curved_radiosity_lightmap_size = size
    floor.curved_radiosity_lightmap_uv = "UVMap"
    bpy.context.scene.curved_radiosity.quality = quality
    bpy.context.scene.curved_radiosity.method = method
    start = time.perf_counter()
    job = addon.pipeline.compute(bpy.context)
    elapsed = time.perf_counter() - start
    image = next(i for i in bpy.data.images if i.get(addon.results.LIGHTMAP_KEY) == "Floor")
    pixels = np.empty(size * size * 4, np.float32)
    image.pixels.foreach_get(pixels)
    addon.results.clear(bpy.context.scene)
    return pixels.reshape(size, size, 4)[..., :3].astype(np.float64), elapsed, job


def compare(mine, first, second, mask):
    mean = 0.5 * (first + second)
    scale = mean[mask].mean()
    rms = np.sqrt(np.mean((mine - mean)[mask] ** 2)) / scale
    noise = np.sqrt(np.mean((first - second)[mask] ** 2)) / 2.0 / scale
    return rms, noise, np.sqrt(max(rms**2 - noise**2, 0.0))


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=64)
    parser.add_argument("--samples", type=int, default=1024)
    parser.add_argument("--quality", default="NORMAL", choices=["DRAFT", "NORMAL", "HIGH"])
    parser.add_argument("--ball-patches", type=int, nargs=2, default=(0, 0), help="sphere patch grid")
    parser.add_argument("--method", default="AUTO", choices=["AUTO", "PAIRS", "HIERARCHICAL"], help="solver")
    args = parser.parse_args(argv)
    addon.register()
    floor = build()
    bpy.data.objects["Sphere"].curved_radiosity_patches = args.ball_patches
    mine, t_ours, job = ours(floor, args.size, args.quality, args.method)
    first, t1 = bake_image(bpy, floor, args.size, args.samples, 1)
    second, t2 = bake_image(bpy, floor, args.size, args.samples, 2)
    n = args.size
    centre = (np.arange(n) + 0.5) / n * SIDE - SIDE / 2
    x, y = np.meshgrid(centre, centre)
    every = np.ones((n, n), bool)
    inner = np.zeros((n, n), bool)
    inner[2:-2, 2:-2] = True
    contact = np.hypot(x, y) < 0.5
    lines = [
        "# Lightmap against a Cycles COMBINED bake (benchmarks/cycles_lightmap.py)",
        "",
        f"{n} x {n} texels, Cycles {args.samples} samples per seed, ours at {args.quality}, solver "
        f"{args.method} (ran: {job.settings.method}; sphere patches {tuple(args.ball_patches)}, "
        "0 = automatic): "
        f"ours {t_ours:.1f} s (solve + lightmap), Cycles bakes {t1:.1f} s and {t2:.1f} s.",
        "",
        "| region | rms(ours - Cycles) | Cycles noise of the mean | net of noise |",
        "|---|---|---|---|",
    ]
    for name, mask in (
        ("all texels", every),
        ("2 texels from the border", inner),
        ("contact, r < 0.5 m", contact),
    ):
        rms, noise, net = compare(mine, first, second, mask)
        lines.append(f"| {name} | {100 * rms:.2f} % | {100 * noise:.2f} % | {100 * net:.2f} % |")
    mean = 0.5 * (first + second)
    ratio = mine[inner].mean() / mean[inner].mean()
    lines += ["", f"mean ratio ours / Cycles (inner texels): {ratio:.4f}", ""]
    # Cycles at the sample count that gives 1 % noise (as benchmarks.cycles_agreement counts it),
    # timed in this run
    noise = compare(mine, first, second, every)[1]
    samples_1 = max(1, int(np.ceil(args.samples * (noise / 0.01) ** 2)))
    _, t_1 = bake_image(bpy, floor, args.size, samples_1, 3)
    lines += [f"Cycles at 1 % noise: {samples_1} samples, bake {t_1:.2f} s (ours {t_ours:.1f} s)", ""]
    # radial profile from the sphere's foot: where the two differ
    r = np.hypot(x, y)
    lines += ["| r (m) | ours | Cycles | ours / Cycles |", "|---|---|---|---|"]
    for lo, hi in (
        (0.0, 0.1),
        (0.1, 0.2),
        (0.2, 0.3),
        (0.3, 0.5),
        (0.5, 0.8),
        (0.8, 1.2),
        (1.2, 1.6),
        (1.6, 2.0),
    ):
        band = inner & (r >= lo) & (r < hi)
        if band.any():
            a, b = mine[band].mean(), mean[band].mean()
            lines.append(f"| {lo:.1f}-{hi:.1f} | {a:.4f} | {b:.4f} | {a / b:.4f} |")
    text = "\n".join(lines) + "\n"
    suffix = "" if tuple(args.ball_patches) == (0, 0) else "_{}x{}".format(*args.ball_patches)
    suffix += "" if args.method == "PAIRS" else "_" + args.method.lower()
    (ROOT / "benchmarks" / "results" / f"cycles_lightmap{suffix}.md").write_text(text)
    print(text)


if __name__ == "__main__":
    main()
