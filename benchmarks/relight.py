"""Relight Only in the add-on on a 10,000-vertex scene: kept gather factors vs a new gather.

    .venv/bin/python -m benchmarks.relight

A UV sphere of 128 x 80 (10,114 vertices) resting on a floor, a point light; a full compute,
then "Relight Only" after the light's power and the sphere's colour change, `RELIGHTS` times
in each of three series (`SERIES`: the blue channel changes, all three change, none does).
Reported: the full compute, and per series the median and least time of the core's re-solve, the kept
gather's product (`core.GatherFactors`, `Solution.radiosity_from`), the pairs across a horizon
integrated again (`refine_kinks`; how many, relight by relight) and the whole relight
(collect, solve, product, writing the attribute), and that less the re-solve (the re-solve's
small LU is where a loaded machine's OpenBLAS threads wait longest); and the worst difference of
the last relight's fronts (after the last series) from a full compute of the changed scene
(which keeps factors too) and from a gather that keeps none (`Solution.radiosity_at`).
"""

import time

import numpy as np

from benchmarks.blender_addon import bpy, install_addon  # before anything else imports bpy


def build():
    bpy.ops.wm.read_homefile(use_empty=True)
    bpy.ops.mesh.primitive_plane_add(size=6.0)
    bpy.ops.mesh.primitive_uv_sphere_add(radius=1.0, location=(0.0, 0.0, 1.0), segments=128, ring_count=80)
    ball = bpy.context.active_object
    mat = bpy.data.materials.new("Ball")
    ball.data.materials.append(mat)
    light = bpy.data.lights.new("Lamp", "POINT")
    light.energy = 500.0
    lamp = bpy.data.objects.new("Lamp", light)
    lamp.location = (1.5, -1.0, 4.0)
    bpy.context.scene.collection.objects.link(lamp)
    return ball, light, mat


RELIGHTS = 7  # relights timed per series (medians: the machine is shared)


def series(addon, light, base, change):
    """Time RELIGHTS relights, relight k after `change(k)` -> (energy, colour); returns the last
    job and per stage the times (s), and the pairs integrated again per relight."""
    times = {name: [] for name in ("solve", "gather", "kinked", "whole", "rest")}
    integrated = []
    for k in range(RELIGHTS):
        light.energy, base.default_value = change(k)
        start = time.perf_counter()
        job = addon.pipeline.compute(bpy.context, relight=True)
        times["whole"].append(time.perf_counter() - start)
        stages = job.solution.stats["times"]
        assert job.solution.relit and "relight_gather" in stages
        times["solve"].append(stages.get("solve", 0.0))
        times["gather"].append(stages["relight_gather"])
        times["kinked"].append(stages.get("kinked form factors", 0.0))
        times["rest"].append(times["whole"][-1] - times["solve"][-1])
        integrated.append(job.solution.stats.get("pairs_kinked", 0))
    return job, times, integrated


# relight k of each series: the light's power and the ball's colour (the near field's node solve
# sweeps only the colour channels whose reflectance changed: `nearfield.NodeSystem.solve`)
SERIES = (
    (
        "power and blue",
        lambda k: (800.0 - 50.0 * (RELIGHTS - 1 - k), (0.3, 0.6, 0.9 - 0.05 * (RELIGHTS - 1 - k), 1.0)),
    ),
    ("power and hue", lambda k: (500.0 + 40.0 * k, (0.2 + 0.1 * k, 0.8 - 0.05 * k, 0.5 + 0.04 * k, 1.0))),
    ("power only", lambda k: (300.0 + 60.0 * k, (0.8, 0.5, 0.6, 1.0))),
)


def main():
    addon = install_addon()
    ball, light, mat = build()
    vertices = len(ball.data.vertices) + 4
    start = time.perf_counter()
    addon.pipeline.compute(bpy.context)
    full = time.perf_counter() - start
    base = mat.node_tree.nodes["Principled BSDF"].inputs["Base Color"]
    measured = [(name, *series(addon, light, base, change)) for name, change in SERIES]
    job = measured[-1][1]
    again = addon.pipeline.compute(bpy.context)
    # a gather that keeps no factors (`Solution.radiosity_at`): float32 factors and sums apart
    prepared = addon.pipeline.prepare(bpy.context)
    session = addon.solve.Session(prepared.collected)
    sol = session.solve(prepared.settings)
    fresh = addon.solve.vertex_radiance(sol, session.surface_handles, prepared.collected)
    diff, diff_fresh = (
        max(
            float(np.abs(job.solution.radiance[n][0] - other[n][0]).max()) / float(np.abs(other[n][0]).max())
            for n in job.solution.radiance
        )
        for other in (again.solution.radiance, fresh)
    )
    print(f"vertices                  {vertices}")
    print(f"full compute              {full:8.2f} s")
    print(f"relights timed            {RELIGHTS:8d}    per series (median, min)")
    labels = (
        ("core re-solve", "solve"),
        ("kept gather", "gather"),
        ("kinked pairs", "kinked"),
        ("whole add-on run", "whole"),
        ("whole - re-solve", "rest"),
    )
    for name, _, times, integrated in measured:
        print(f"series: {name}")
        for label, key in labels:
            t = times[key]
            print(f"relight: {label:16s} {1e3 * np.median(t):8.1f} ms {1e3 * min(t):6.1f} ms")
        print(f"kinked pairs integrated again, relight by relight: {integrated}")
    print(f"relight vs full compute   {diff:.2e} (max relative, fronts, after the last series)")
    print(f"relight vs no kept gather {diff_fresh:.2e} (max relative, fronts)")


if __name__ == "__main__":
    main()
