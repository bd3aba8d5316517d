"""The add-on's vertex radiance against Cycles COMBINED bakes to vertex colours.

A COMBINED bake stores each vertex's outgoing radiance (emission + rho E / pi for a diffuse
surface), which is what the add-on computes. Materials are Diffuse BSDFs (a Principled BSDF adds
a specular layer the solver leaves out). Two bakes with different seeds measure Cycles' noise;
`benchmarks.cycles_bake.agreement` reports the difference net of that noise.
"""

import numpy as np
import pytest
from blender_helpers import bpy

from benchmarks.cycles_bake import agreement, bake_combined, bake_image, diffuse_material

pytestmark = pytest.mark.blender


def grid(name, size, subdivisions, location=(0.0, 0.0, 0.0), rotation=(0.0, 0.0, 0.0), colour=(0.5,) * 3):
    bpy.ops.mesh.primitive_grid_add(
        x_subdivisions=subdivisions,
        y_subdivisions=subdivisions,
        size=size,
        location=location,
        rotation=rotation,
    )
    obj = bpy.context.active_object
    obj.name = name
    obj.data.materials.append(diffuse_material(bpy, name, colour))
    return obj


def world(colour, strength):
    scene = bpy.context.scene
    scene.world = bpy.data.worlds.new("Sky")
    scene.world.color = colour
    background = scene.world.node_tree.nodes["Background"]
    background.inputs["Color"].default_value = (*colour, 1.0)
    background.inputs["Strength"].default_value = strength
    return scene.world


def ours(addon):
    """The add-on's front radiance per result mesh: {name: (V, 3)}."""
    bpy.context.view_layer.update()
    job = addon.pipeline.prepare(bpy.context)
    addon.pipeline.run(job)
    return {name: front for name, (front, _) in job.solution.radiance.items()}


def ours_and_cycles(addon, objects, samples):
    """{name: (ours (V, 3), bake seed 0, bake seed 1)} for mesh objects (their own vertices)."""
    radiance = ours(addon)
    first = bake_combined(bpy, objects, samples, seed=0)
    second = bake_combined(bpy, objects, samples, seed=1)
    return {o.name: (radiance[o.name], first[o.name], second[o.name]) for o in objects}


def test_world_light_matches_cycles(addon):
    """A floor and a wall under a uniform sky (colour x strength = radiance L): every vertex,
    the wall's foot and the floor's line along the wall included, within 1 % rms of Cycles net of
    its noise, bias within 1 %, with either solver."""
    world((0.6, 0.8, 1.0), 1.5)
    floor = grid("Floor", 2.0, 9)
    wall = grid("Wall", 2.0, 9, location=(-1.0, 0.0, 1.0), rotation=(0.0, np.pi / 2, 0.0))
    results = ours_and_cycles(addon, [floor, wall], 512)
    bpy.context.scene.curved_radiosity.method = "HIERARCHICAL"
    hierarchical = ours(addon)
    for name, (radiance, first, second) in results.items():
        for solver, values in (("pairs", radiance), ("hierarchical", hierarchical[name])):
            report = agreement(values, first, second)
            assert report["noise"] < 0.01, (name, solver, report)
            assert report["rms"] < 0.01 and abs(report["bias"]) < 0.01, (name, solver, report)
    # under the sky alone (no wall) the floor would show rho L = 0.5 x 1.5 x colour: the wall darkens it
    floor_blue = results["Floor"][0][:, 2]
    assert np.all(floor_blue < 0.5 * 1.5 * 1.0 + 1e-9) and floor_blue.min() < 0.8 * 0.75


def test_textured_world_is_averaged_with_a_warning(addon):
    """An environment image of rows 0 (lower half) and 2 (upper half): its solid-angle average 1
    becomes the sky (times the strength), and the warning names the image."""
    sky = world((0.0, 0.0, 0.0), 2.0)
    image = bpy.data.images.new("Halves", 16, 8, float_buffer=True)
    pixels = np.zeros((8, 16, 4), np.float32)
    pixels[4:, :, :3] = 2.0
    pixels[..., 3] = 1.0
    image.pixels.foreach_set(pixels.ravel())
    tree = sky.node_tree
    texture = tree.nodes.new("ShaderNodeTexEnvironment")
    texture.image = image
    tree.links.new(texture.outputs["Color"], tree.nodes["Background"].inputs["Color"])
    grid("Floor", 2.0, 2)
    bpy.context.view_layer.update()
    collected = addon.collect.collect(
        bpy.context.scene, bpy.context.view_layer, bpy.context.evaluated_depsgraph_get()
    )
    assert collected.sky == pytest.approx(np.full(3, 2.0), rel=1e-6)
    assert any("'Halves'" in w and "averaged" in w for w in collected.warnings), collected.warnings
    # a node that cannot be averaged: the socket's colour, and a warning naming the node
    noise = tree.nodes.new("ShaderNodeTexNoise")
    tree.links.new(noise.outputs["Color"], tree.nodes["Background"].inputs["Color"])
    collected = addon.collect.collect(
        bpy.context.scene, bpy.context.view_layer, bpy.context.evaluated_depsgraph_get()
    )
    assert any(noise.name in w and "cannot be averaged" in w for w in collected.warnings), collected.warnings


def shadow_scene(light_kind, **settings):
    """A 3 m floor grid under a black ball (r 0.5 at z 1) and a light above: a penumbra. The ball
    is a UV sphere of 48 x 24 (the add-on takes it as the exact sphere; Cycles renders its
    polygons, whose silhouette is 0.2 % smaller: 0.5 % with 32 x 16, enough to brighten Cycles'
    penumbra by 3 %)."""
    floor = grid("Floor", 3.0, 13, colour=(0.5, 0.5, 0.5))
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.5, location=(0.3, 0.0, 1.0), segments=48, ring_count=24)
    ball = bpy.context.active_object
    ball.data.materials.append(diffuse_material(bpy, "Black", (0.0, 0.0, 0.0)))
    light = bpy.data.lights.new("Light", light_kind)
    for key, value in settings.items():
        setattr(light, key, value)
    obj = bpy.data.objects.new("Light", light)
    obj.location = (0.0, 0.0, 3.0)
    bpy.context.scene.collection.objects.link(obj)
    return floor


@pytest.mark.parametrize(
    "kind, settings",
    [
        ("POINT", dict(energy=300.0, shadow_soft_size=0.4)),
        ("SUN", dict(energy=2.0, angle=np.radians(15.0))),
    ],
    ids=["sphere-light", "sun-angle"],
)
def test_soft_shadow_matches_cycles(addon, kind, settings):
    """A point light's radius (a sphere light) and a sun's angle soften the ball's shadow as in
    Cycles: the floor within 1.5 % rms of Cycles net of noise, the penumbra's vertices (those
    between 5 % and 95 % of the lit value) within 3 %; with the radius or angle set to 0 the same
    vertices would be off by far more (a hard shadow)."""
    floor = shadow_scene(kind, **settings)
    results = ours_and_cycles(addon, [floor], 256)
    radiance, first, second = results["Floor"]
    assert agreement(radiance, first, second)["rms"] < 0.015, agreement(radiance, first, second)
    mean = 0.5 * (first + second).sum(1)
    lit = np.percentile(mean, 95)
    penumbra = (mean > 0.05 * lit) & (mean < 0.95 * lit)
    assert penumbra.sum() >= 8
    report = agreement(radiance, first, second, penumbra)
    assert report["rms"] < 0.03, report
    # the hard-shadow solution disagrees in the penumbra
    light = bpy.data.lights["Light"]
    if kind == "SUN":
        light.angle = 0.0
    else:
        light.shadow_soft_size = 0.0
    hard = ours(addon)["Floor"]
    assert agreement(hard, first, second, penumbra)["rms"] > 3 * report["rms"] + 0.05


def contact_lightmap(addon, method, size):
    """The floor's lightmap (size x size texels, (size, size, 3)) of a one-quad 4 m floor under a
    ball of radius 0.5 resting at its centre and a 1 m area light of 200 W 3 m up at (0.4, 0.3),
    black world, Diffuse BSDFs of 0.5; floor 8 x 8 and ball 8 x 16 patches, NORMAL quality."""
    bpy.ops.mesh.primitive_plane_add(size=4.0)
    floor = bpy.context.active_object
    floor.name = "Floor"
    floor.data.materials.append(diffuse_material(bpy, "Floor", (0.5, 0.5, 0.5)))
    floor.curved_radiosity_patches = (8, 8)
    floor.curved_radiosity_output = "LIGHTMAP"
    floor.curved_radiosity_lightmap_size = size
    floor.curved_radiosity_lightmap_uv = "UVMap"
    bpy.ops.mesh.primitive_uv_sphere_add(segments=48, ring_count=24, radius=0.5, location=(0, 0, 0.5))
    bpy.ops.object.shade_smooth()
    ball = bpy.context.active_object
    ball.data.materials.append(diffuse_material(bpy, "Ball", (0.5, 0.5, 0.5)))
    ball.curved_radiosity_patches = (8, 16)
    light = bpy.data.lights.new("Lamp", "AREA")
    light.energy, light.size = 200.0, 1.0
    lamp = bpy.data.objects.new("Lamp", light)
    lamp.location = (0.4, 0.3, 3.0)
    bpy.context.scene.collection.objects.link(lamp)
    world((0.0, 0.0, 0.0), 0.0)
    props = bpy.context.scene.curved_radiosity
    props.quality, props.method = "NORMAL", method
    bpy.context.view_layer.update()
    addon.pipeline.compute(bpy.context)
    image = next(i for i in bpy.data.images if i.get(addon.results.LIGHTMAP_KEY) == "Floor")
    pixels = np.empty(size * size * 4, np.float32)
    image.pixels.foreach_get(pixels)
    addon.results.clear(bpy.context.scene)  # the floor's own material again, for Cycles
    return floor, pixels.reshape(size, size, 4)[..., :3].astype(np.float64)


def test_hierarchical_lightmap_resolves_the_contact_shadow(addon):
    """Through the add-on (Solver: Hierarchical, sub-patches where the ball rests on the floor) the
    floor's lightmap near the ball's foot agrees with Cycles' image bake of the same UV map: every
    texel within 0.3 m of the foot within 1 % of the lit floor's level plus 3 noise sigmas. So is
    All Pairs on the same patches, through its near field (`core.nearfield`: measured 0.64 % of
    the lit level at most; before it, up to ~5 % too bright there: the floor saw the ball's lowest
    patches at their means, which include their lit upper parts). The lit floor agrees with both
    within 1 % rms (net of noise)."""
    size = 40  # 0.1 m texels
    radiance = {}
    for method in ("HIERARCHICAL", "PAIRS"):
        bpy.ops.wm.read_homefile(use_empty=True)
        floor, radiance[method] = contact_lightmap(addon, method, size)
    first, second = (bake_image(bpy, floor, size, 1024, seed)[0] for seed in (0, 1))
    mean, noise = 0.5 * (first + second), 0.5 * np.abs(first - second)
    centre = (np.arange(size) + 0.5) / size * 4.0 - 2.0
    x, y = np.meshgrid(centre, centre)  # image rows run along v (y), columns along u (x)
    r = np.hypot(x, y)
    lit_ring = (r > 0.8) & (r < 1.8)
    lit = mean[lit_ring].mean()
    contact = r < 0.3
    assert contact.sum() >= 20
    for method, ours in radiance.items():
        report = agreement(ours[lit_ring], first[lit_ring], second[lit_ring])
        assert report["rms"] < 0.01, (method, report)
    for method, ours in radiance.items():
        error = np.abs(ours - mean)[contact].max(1) / (0.01 * lit + 3 * noise[contact].max(1))
        assert error.max() <= 1.0, (method, error.round(2))
