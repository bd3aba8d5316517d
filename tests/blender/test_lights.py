"""Light conversions checked against Cycles itself.

Conventions (addon/lights.py): strength = colour x energy x 2^exposure
(intern/cycles/blender/light.cpp, `BlenderSync::sync_light`); an area light's radiance is
strength / (pi A) with A its world-space area (x pi/4 for disk/ellipse), or strength / pi without
`normalize` (intern/cycles/scene/light.cpp, `device_update_lights`); point and spot lights have
intensity strength / (4 pi) W/sr; a sun gives irradiance = strength W/m^2. The oracle here is a
Cycles render: an orthographic camera looks down at a small patch of a Diffuse BSDF plane
(albedo rho) at the origin, whose pixels show rho E / pi for the irradiance E there. Our E comes
from the converted light: the area light's core surface integrated numerically, or the
intensity / irradiance formulas.
"""

import numpy as np
import pytest
from blender_helpers import bpy, collect

pytestmark = pytest.mark.blender

RHO = 0.5


def receiver_scene():
    """Black world, a 10 m diffuse plane at z = 0 (albedo RHO), a camera looking down at the origin."""
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.use_denoising = False
    scene.cycles.max_bounces = 1
    scene.view_settings.view_transform = "Standard"
    scene.view_settings.look = "None"
    scene.render.resolution_x = scene.render.resolution_y = 8
    scene.render.image_settings.file_format = "OPEN_EXR"
    scene.world = bpy.data.worlds.new("Black")
    scene.world.color = (0.0, 0.0, 0.0)
    if scene.world.node_tree is not None:
        scene.world.node_tree.nodes["Background"].inputs["Strength"].default_value = 0.0
    bpy.ops.mesh.primitive_plane_add(size=10.0)
    plane = bpy.context.active_object
    mat = bpy.data.materials.new("Diffuse")
    if mat.node_tree is None:  # Blender < 5.0
        mat.use_nodes = True
    tree = mat.node_tree
    tree.nodes.clear()
    diffuse = tree.nodes.new("ShaderNodeBsdfDiffuse")
    diffuse.inputs["Color"].default_value = (RHO, RHO, RHO, 1.0)
    output = tree.nodes.new("ShaderNodeOutputMaterial")
    tree.links.new(diffuse.outputs[0], output.inputs["Surface"])
    plane.data.materials.append(mat)
    plane.curved_radiosity_include = False
    camera = bpy.data.cameras.new("Camera")
    camera.type = "ORTHO"
    camera.ortho_scale = 0.02
    cam = bpy.data.objects.new("Camera", camera)
    cam.location = (0.0, 0.0, 0.3)
    scene.collection.objects.link(cam)
    scene.camera = cam


def rendered_irradiance(tmp_path, samples):
    """Mean pixel RGB x pi / RHO: the irradiance Cycles puts on the plane at the origin."""
    scene = bpy.context.scene
    scene.cycles.samples = samples
    scene.render.filepath = str(tmp_path / "render.exr")
    bpy.ops.render.render(write_still=True)
    image = bpy.data.images.load(scene.render.filepath, check_existing=False)
    pixels = np.empty(len(image.pixels), np.float32)
    image.pixels.foreach_get(pixels)
    return pixels.reshape(-1, 4)[:, :3].mean(0) * np.pi / RHO


def add_light(kind, location=(0.0, 0.0, 1.0), rotation=(0.0, 0.0, 0.0), **settings):
    light = bpy.data.lights.new(kind.title(), kind)
    for name, value in settings.items():
        setattr(light, name, value)
    obj = bpy.data.objects.new(kind.title(), light)
    obj.location, obj.rotation_euler = location, rotation
    bpy.context.scene.collection.objects.link(obj)
    bpy.context.view_layer.update()
    return obj


def irradiance_from_surface(item, point=np.zeros(3), normal=np.array([0.0, 0.0, 1.0]), n=400):
    """E at `point` from an emitting item: sum of L cos cos / r^2 dA (midpoint rule, n x n)."""
    (u0, u1), (v0, v1) = item.surface.domain
    s = (np.arange(n) + 0.5) / n
    u, v = np.meshgrid(u0 + (u1 - u0) * s, v0 + (v1 - v0) * s, indexing="ij")
    P, N = item.surface.evaluate(u, v)
    d = point - P
    r2 = np.einsum("...j,...j", d, d)
    cos_light = np.einsum("...j,...j", N, d) / np.sqrt(r2)  # |N| du dv = dA folded in
    cos_receiver = np.maximum(-d @ normal, 0.0) / np.sqrt(r2)
    weight = np.maximum(cos_light, 0.0) * cos_receiver / r2 * (u1 - u0) * (v1 - v0) / n**2
    return item.material.emission * weight.sum()


@pytest.mark.parametrize(
    "settings, scale",
    [
        (dict(shape="SQUARE", size=1.0), (1.0, 1.0, 1.0)),
        (dict(shape="RECTANGLE", size=2.0, size_y=0.5), (1.0, 1.0, 1.0)),
        (dict(shape="DISK", size=1.0), (1.0, 1.0, 1.0)),
        (dict(shape="ELLIPSE", size=2.0, size_y=0.5), (0.8, 1.5, 1.0)),
        (dict(shape="RECTANGLE", size=1.0, size_y=0.5, normalize=False), (1.0, 2.0, 1.0)),
    ],
    ids=["square", "rectangle", "disk", "scaled-ellipse", "rectangle-not-normalized"],
)
def test_area_light_matches_cycles(addon, tmp_path, settings, scale):
    """Area light (power 40 W, colour (1, .5, .25), at 1 m facing down): radiance P / (pi A)."""
    receiver_scene()
    obj = add_light("AREA", energy=40.0, color=(1.0, 0.5, 0.25), **settings)
    obj.scale = scale
    bpy.context.view_layer.update()
    (item,) = [i for i in collect(addon).surfaces if i.name == obj.name]
    assert not item.occluder and not item.material.two_sided and item.target is None
    normal = item.surface.evaluate(np.array(0.5 * sum(item.surface.domain[0])), np.array(0.1))[1]
    assert normal[2] < 0.0  # emits along the light's -Z
    ours = irradiance_from_surface(item)
    assert rendered_irradiance(tmp_path, 1024) == pytest.approx(ours, rel=0.01)


@pytest.mark.parametrize("kind", ["POINT", "SPOT"])
def test_point_and_spot_intensity_matches_cycles(addon, tmp_path, kind):
    """Point / spot light of power 100 W at 2 m above: intensity P / (4 pi), E = I / h^2 below it."""
    receiver_scene()
    extra = dict(spot_size=np.radians(60.0), spot_blend=0.2) if kind == "SPOT" else {}
    obj = add_light(kind, location=(0.0, 0.0, 2.0), energy=100.0, shadow_soft_size=0.0, **extra)
    (light,) = collect(addon).lights
    assert light.name == obj.name and light.kind == kind.lower()
    intensity = light.params["intensity"]
    assert intensity == pytest.approx(np.full(3, 100.0 / (4 * np.pi)))
    assert np.allclose(light.params["position"], (0.0, 0.0, 2.0))
    if kind == "SPOT":
        assert np.allclose(light.params["direction"], (0.0, 0.0, -1.0))
        assert light.params["spot_size"] == pytest.approx(np.radians(60.0))
    assert rendered_irradiance(tmp_path, 16) == pytest.approx(intensity / 4.0, rel=2e-3)


def test_sun_irradiance_matches_cycles(addon, tmp_path):
    """Sun of strength 3 tilted 30 degrees: irradiance 3 on a plane facing it, 3 cos 30 on the ground."""
    receiver_scene()
    add_light("SUN", rotation=(np.radians(30.0), 0.0, 0.0), energy=3.0, angle=0.0)
    (light,) = collect(addon).lights
    direction = light.params["direction"]
    assert light.params["irradiance"] == pytest.approx(np.full(3, 3.0))
    assert np.linalg.norm(direction) == pytest.approx(1.0) and direction[2] < 0
    expected = light.params["irradiance"] * -direction[2]
    assert expected[0] == pytest.approx(3.0 * np.cos(np.radians(30.0)))
    assert rendered_irradiance(tmp_path, 16) == pytest.approx(expected, rel=2e-3)


def test_colour_exposure_and_temperature(addon, tmp_path):
    """Strength = colour x blackbody colour x energy x 2^exposure, channel by channel (Cycles render)."""
    receiver_scene()
    obj = add_light("POINT", energy=50.0, color=(1.0, 0.5, 0.25), exposure=1.0, shadow_soft_size=0.0)
    obj.data.use_temperature = True
    obj.data.temperature = 4000.0
    (light,) = collect(addon).lights
    expected = np.array((1.0, 0.5, 0.25)) * np.array(obj.data.temperature_color) * 100.0 / (4 * np.pi)
    assert light.params["intensity"] == pytest.approx(expected, rel=1e-6)
    assert rendered_irradiance(tmp_path, 16) == pytest.approx(expected, rel=2e-3)


def test_formulas(addon):
    """The conversion functions on their own."""
    lights = addon.lights
    power = lights.light_power((1.0, 0.5, 0.0), 10.0, exposure=2.0)
    assert power.tolist() == [40.0, 20.0, 0.0]
    assert lights.area_radiance(power, 2.0) == pytest.approx(power / (2 * np.pi))
    assert lights.area_radiance(power, 2.0, normalize=False) == pytest.approx(power / np.pi)
    assert lights.point_intensity(power) == pytest.approx(power / (4 * np.pi))
    disk = lights.area_surface("DISK", 2.0, 5.0, np.eye(4))
    assert disk.area() == pytest.approx(np.pi)
    ellipse = lights.area_surface("ELLIPSE", 2.0, 0.5, np.diag([3.0, 1.0, 1.0, 1.0]))
    assert ellipse.area() == pytest.approx(np.pi * 3.0 * 0.25, rel=1e-9)
