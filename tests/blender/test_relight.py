"""Relight Only: the per-vertex gather is kept and re-applied, not run again (addon/solve.py)."""

import numpy as np
import pytest
from blender_helpers import ROOT, bpy, material

pytestmark = pytest.mark.blender

SEED = ROOT / "blender_scenes" / "01_seed_sphere_over_square.blend"


def radiance(job, name):
    return job.solution.radiance[name][0]


def test_relight_applies_the_kept_gather(addon):
    """A relight after a light and material change gathers no point again (one sparse product)
    and equals a full compute of the changed scene to its tolerance."""
    bpy.ops.wm.open_mainfile(filepath=str(SEED))
    first = addon.pipeline.compute(bpy.context)
    assert first.solution.stats["gather_points"] > 0
    glow = bpy.data.materials["Glow"].node_tree.nodes["Principled BSDF"]
    glow.inputs["Emission Strength"].default_value *= 3.0
    grey = bpy.data.materials["Grey"].node_tree.nodes["Principled BSDF"]
    grey.inputs["Base Color"].default_value = (0.2, 0.6, 0.4, 1.0)
    relit = addon.pipeline.compute(bpy.context, relight=True)
    assert relit.solution.relit
    assert "gather_points" not in relit.solution.stats and "relight_gather" in relit.solution.stats["times"]
    full = addon.pipeline.compute(bpy.context)
    assert not full.solution.relit and full.solution.stats["gather_points"] > 0
    for name in ("Square", "Emitter"):
        a, b = radiance(relit, name), radiance(full, name)
        assert np.abs(a - b).max() <= 5e-3 * np.abs(b).max(), name


def test_relight_lighting_a_black_surface_gathers_again(addon):
    """A surface black at the first compute was left out of the kept factors: when it is given
    a colour, the relight falls back to a full gather (and matches a full compute)."""
    bpy.ops.wm.open_mainfile(filepath=str(SEED))
    bpy.ops.mesh.primitive_plane_add(size=1.0, location=(0.0, 0.0, 3.0), rotation=(np.pi, 0.0, 0.0))
    lid = bpy.context.active_object
    black = material("Black", base=(0.0, 0.0, 0.0))
    black.node_tree.nodes["Principled BSDF"].inputs["Specular IOR Level"].default_value = 0.0
    lid.data.materials.append(black)
    addon.pipeline.compute(bpy.context)
    black.node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = (0.7, 0.7, 0.7, 1.0)
    relit = addon.pipeline.compute(bpy.context, relight=True)
    assert relit.solution.relit and relit.solution.stats["gather_points"] > 0
    full = addon.pipeline.compute(bpy.context)
    assert radiance(relit, "Square") == pytest.approx(radiance(full, "Square"), rel=1e-9)


def point_light(energy, location):
    light = bpy.data.lights.new("Lamp", "POINT")
    light.energy = energy
    lamp = bpy.data.objects.new("Lamp", light)
    lamp.location = location
    bpy.context.scene.collection.objects.link(lamp)
    return light


def base_colour(mat, rgb):
    mat.node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = (*rgb, 1.0)


def no_kept_factors(addon):
    """Vertex radiance of the current scene from a new gather (`radiosity_at`), no factors kept."""
    job = addon.pipeline.prepare(bpy.context)
    session = addon.solve.Session(job.collected)
    sol = session.solve(job.settings)
    return addon.solve.vertex_radiance(sol, session.surface_handles, job.collected)


def worst(a, b, sides=(0, 1)):
    """Largest difference of radiance dicts a and b relative to b's largest value, per target side."""
    return max(
        float(np.abs(a[n][s] - b[n][s]).max()) / max(float(np.abs(b[n][s]).max()), 1e-300)
        for n in b
        for s in sides
        if b[n][s] is not None
    )


def test_relight_equals_a_full_compute(addon):
    """The kept factors with each vertex's mean of its samples folded in (one merged point per
    vertex and surface; a vertex on a material border sums two) give, after a light and
    material change, what a full compute of the changed scene gives (same factors, same sums,
    the near field's node system solved from another first guess, `NodeSystem.warm_start`:
    within its bound of 1e-5, measured 3e-10; 1e-6), and agree with a new gather that keeps no
    factors (float32 factors and sums: 1e-6).
    A floor and a cube with two materials (border vertices), then a UV sphere on the floor
    (one sample per vertex), fronts only there: the inside of a closed sphere is lit only by
    the gather's own error, and which of its pairs get rays follows the light they carry
    (`pointgather.RAY_SHARE`), so a relight matches it only to about 1e-3 of the outside. The cube
    resting on the floor brings the near field (`core.nearfield`), whose node gathers pick rays
    the same way: there the relight agrees with a full compute within 1e-3 (measured 4.4e-4)."""
    for scene in ("cube", "ball"):
        bpy.ops.wm.read_homefile(use_empty=True)
        bpy.ops.mesh.primitive_plane_add(size=6.0)
        if scene == "cube":
            bpy.ops.mesh.primitive_cube_add(size=1.0, location=(-1.0, 0.0, 0.5))
            red, blue = material("Red", base=(0.8, 0.2, 0.2)), material("Blue", base=(0.2, 0.2, 0.8))
            mesh = bpy.context.active_object.data
            mesh.materials.append(red)
            mesh.materials.append(blue)
            mesh.polygons[0].material_index = mesh.polygons[3].material_index = 1
            changed, sides = red, (0, 1)
        else:
            bpy.ops.mesh.primitive_uv_sphere_add(
                radius=1.0, location=(0.0, 0.0, 1.0), segments=32, ring_count=16
            )
            changed, sides = material("Ball", base=(0.5, 0.5, 0.5)), (0,)
            bpy.context.active_object.data.materials.append(changed)
        light = point_light(300.0, (1.0, -1.0, 3.0))
        addon.pipeline.compute(bpy.context)
        light.energy = 700.0
        base_colour(changed, (0.3, 0.6, 0.9))
        relit = addon.pipeline.compute(bpy.context, relight=True)
        assert relit.solution.relit and "gather_points" not in relit.solution.stats
        full = addon.pipeline.compute(bpy.context)
        assert not full.solution.relit
        # (the cube rests on the floor: the near field's node gathers pick their rays by the
        # light they carry, as the sphere's inside does; measured 4.4e-4 both ways)
        same, fresh = (1e-6, 1e-6) if scene == "ball" else (1e-3, 1e-3)
        assert worst(relit.solution.radiance, full.solution.radiance, sides) <= same, scene
        assert worst(relit.solution.radiance, no_kept_factors(addon), sides) <= fresh, scene


def test_relight_on_the_hierarchical_solver(addon):
    """With *Solver: Hierarchical* a relight re-solves on the kept links and gathers the vertices
    again through them (no kept factors): the same radiance as a full compute of the changed scene,
    to the solve's tolerance (both stop their sweeps within tol of the converged values)."""
    bpy.ops.wm.read_homefile(use_empty=True)
    bpy.ops.mesh.primitive_plane_add(size=6.0)
    bpy.ops.mesh.primitive_uv_sphere_add(radius=1.0, location=(0.0, 0.0, 1.0), segments=32, ring_count=16)
    changed = material("Ball", base=(0.5, 0.5, 0.5))
    bpy.context.active_object.data.materials.append(changed)
    light = point_light(300.0, (1.0, -1.0, 3.0))
    bpy.context.scene.curved_radiosity.method = "HIERARCHICAL"
    first = addon.pipeline.compute(bpy.context)
    assert first.solution.stats["solver"] == "hierarchical"
    light.energy = 700.0
    base_colour(changed, (0.3, 0.6, 0.9))
    relit = addon.pipeline.compute(bpy.context, relight=True)
    assert relit.solution.relit and relit.solution.stats["gather_points"] > 0
    full = addon.pipeline.compute(bpy.context)
    assert not full.solution.relit
    assert worst(relit.solution.radiance, full.solution.radiance, (0,)) <= 2e-3
