"""Build the example scenes as .blend files (Blender as a Python module, from the repository root):

    .venv/bin/python blender_scenes/build_scenes.py [--out-dir blender_scenes] [NAME ...]

01_seed_sphere_over_square   an emitting sphere above a grey square (the seed configuration)
02_sphere_in_cube            a grey sphere inside a closed white box lit by a ceiling area light
03_cornell_box               Cornell box: red/green walls, two spheres, a curved NURBS shell, area light
04_nurbs_only                NURBS surfaces only: orders 2, 3 and 4, a concave dish, torus and cylinder
05_stress_many_spheres       12 x 12 UV spheres over a floor, sun and area light

Every scene has a camera and Cycles CPU render settings with few samples (results are viewed
through emission-only materials); `python -m addon.headless blender_scenes/03_cornell_box.blend
--render out.png` lights and renders one.
"""

import argparse
import sys
from pathlib import Path

import bpy
import numpy as np

HERE = Path(__file__).resolve().parent


# --------------------------------------------------------------------------- helpers
def new_scene():
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = 8
    scene.cycles.use_denoising = False
    scene.render.resolution_x, scene.render.resolution_y = 480, 360
    scene.view_settings.view_transform = "Standard"
    scene.world = bpy.data.worlds.new("World")
    scene.world.color = (0.0, 0.0, 0.0)
    if scene.world.node_tree is not None:
        scene.world.node_tree.nodes["Background"].inputs["Color"].default_value = (0.0, 0.0, 0.0, 1.0)
    return scene


def material(name, color=(0.8, 0.8, 0.8), emission=None, strength=0.0):
    """A Principled BSDF material (base colour = diffuse reflectance, optional emission), without
    its specular layer (Specular IOR Level 0), which the radiosity solver cannot represent."""
    mat = bpy.data.materials.get(name) or bpy.data.materials.new(name)
    if mat.node_tree is None:  # Blender < 5.0
        mat.use_nodes = True
    bsdf = mat.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Base Color"].default_value = (*color, 1.0)
    bsdf.inputs["Roughness"].default_value = 1.0
    bsdf.inputs["Specular IOR Level"].default_value = 0.0
    if emission is not None:
        bsdf.inputs["Emission Color"].default_value = (*emission, 1.0)
        bsdf.inputs["Emission Strength"].default_value = strength
    mat.diffuse_color = (*color, 1.0)
    return mat


def assign(obj, mat, name=None):
    obj.data.materials.append(mat)
    if name:
        obj.name = obj.data.name = name
    return obj


def camera(location, target, lens=35.0):
    """A camera at `location` looking at `target`."""
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    cam.data.lens = lens
    cam.location = location
    bpy.context.scene.collection.objects.link(cam)
    direction = np.subtract(target, location)
    cam.rotation_euler = _look_rotation(direction)
    bpy.context.scene.camera = cam
    return cam


def _look_rotation(direction):
    """Euler XYZ angles turning a camera (looking along -Z, up +Y) to look along `direction`."""
    x, y, z = direction / np.linalg.norm(direction)
    return (np.arctan2(np.hypot(x, y), -z), 0.0, np.arctan2(y, x) - np.pi / 2)


def area_light(name, location, size, power, size_y=None, rotation=(0.0, 0.0, 0.0)):
    light = bpy.data.lights.new(name, "AREA")
    light.energy = power
    light.shape = "RECTANGLE" if size_y else "SQUARE"
    light.size = size
    if size_y:
        light.size_y = size_y
    obj = bpy.data.objects.new(name, light)
    obj.location, obj.rotation_euler = location, rotation
    bpy.context.scene.collection.objects.link(obj)
    return obj


def uv_sphere(name, location, radius, mat, segments=32, rings=16):
    bpy.ops.mesh.primitive_uv_sphere_add(
        segments=segments, ring_count=rings, radius=radius, location=location
    )
    return assign(bpy.context.active_object, mat, name)


def plane(name, location, size, mat, rotation=(0.0, 0.0, 0.0)):
    bpy.ops.mesh.primitive_plane_add(size=size, location=location, rotation=rotation)
    return assign(bpy.context.active_object, mat, name)


def nurbs_patch(name, grid, mat, order=(4, 4), endpoint=True):
    """A NURBS surface object through a 4 x 4 control grid (4, 4, 3) in world space, weights 1.

    Starts from Blender's NURBS surface primitive (the way to get a 2-D point grid from Python)
    and moves its points; u runs along the grid's first axis.
    """
    bpy.ops.surface.primitive_nurbs_surface_surface_add(location=(0, 0, 0))
    obj = bpy.context.active_object
    (spline,) = obj.data.splines
    assert grid.shape == (spline.point_count_u, spline.point_count_v, 3)
    co = np.concatenate([grid.transpose(1, 0, 2).reshape(-1, 3), np.ones((16, 1))], 1)
    spline.points.foreach_set("co", co.astype(np.float32).ravel())
    spline.use_endpoint_u = spline.use_endpoint_v = endpoint
    spline.order_u, spline.order_v = order
    spline.resolution_u = spline.resolution_v = 6
    return assign(obj, mat, name)


def grid_points(nu, nv, x_range, y_range, height):
    """Control grid (nu, nv, 3) over a rectangle with z = height(x, y)."""
    x, y = np.meshgrid(np.linspace(*x_range, nu), np.linspace(*y_range, nv), indexing="ij")
    return np.stack([x, y, height(x, y)], -1)


def save(path):
    bpy.context.view_layer.update()
    bpy.context.preferences.filepaths.save_version = 0  # no .blend1 backups next to the scenes
    bpy.ops.wm.save_as_mainfile(filepath=str(path), compress=True)


# --------------------------------------------------------------------------- scenes
def seed_sphere_over_square():
    """An emitting sphere (radiance 5) of radius 0.5 at 1.5 m above the centre of a 2 m grey square."""
    new_scene()
    plane("Square", (0, 0, 0), 2.0, material("Grey", (0.5, 0.5, 0.5)))
    uv_sphere("Emitter", (0, 0, 1.5), 0.5, material("Glow", (0.0, 0.0, 0.0), (1.0, 1.0, 1.0), 5.0))
    camera((3.5, -3.5, 3.0), (0, 0, 0.6))


def sphere_in_cube():
    """A grey sphere in a closed 4 m white box (inward faces), lit by a ceiling area light."""
    new_scene()
    bpy.ops.mesh.primitive_cube_add(size=4.0, location=(0, 0, 2))
    box = assign(bpy.context.active_object, material("White", (0.75, 0.75, 0.75)), "Box")
    box.data.flip_normals()
    uv_sphere("Ball", (0.3, 0.2, 1.0), 0.8, material("Grey", (0.5, 0.5, 0.5)))
    area_light("Ceiling", (0, 0, 3.95), 1.0, 60.0)
    camera((1.6, -1.8, 2.6), (0.2, 0.2, 1.0), lens=18.0)


def cornell_box():
    """Cornell box (open front), two spheres and a curved NURBS shell, lit by a ceiling area light."""
    new_scene()
    white, red = material("White", (0.73, 0.73, 0.73)), material("Red", (0.63, 0.06, 0.05))
    green = material("Green", (0.12, 0.45, 0.15))
    plane("Floor", (0, 0, 0), 2.0, white)
    plane("Ceiling", (0, 0, 2), 2.0, white, rotation=(np.pi, 0, 0))
    plane("Back", (0, 1, 1), 2.0, white, rotation=(np.pi / 2, 0, 0))
    plane("Left", (-1, 0, 1), 2.0, red, rotation=(0, np.pi / 2, 0))
    plane("Right", (1, 0, 1), 2.0, green, rotation=(0, -np.pi / 2, 0))
    uv_sphere("Sphere Big", (-0.4, 0.3, 0.35), 0.35, white)
    uv_sphere("Sphere Small", (0.45, -0.3, 0.25), 0.25, material("Mirrorless", (0.6, 0.6, 0.8)))
    # a cylindrical shell (120 degrees of arc) standing behind the small sphere, hollow side to the camera
    angle = np.linspace(-np.pi / 3, np.pi / 3, 4)
    heights = np.linspace(0.05, 1.1, 4)
    shell = np.stack(
        [
            np.broadcast_to(0.35 + 0.5 * np.sin(angle)[:, None], (4, 4)),
            np.broadcast_to(0.6 - 0.5 * np.cos(angle)[:, None] + 0.25, (4, 4)),
            np.broadcast_to(heights[None, :], (4, 4)),
        ],
        -1,
    )
    nurbs_patch("Shell", shell, material("Sand", (0.7, 0.6, 0.4)), order=(3, 2))
    area_light("Lamp", (0, 0, 1.98), 0.5, 25.0)
    camera((0, -3.6, 1.0), (0, 0, 1.0), lens=35.0)


def nurbs_only():
    """NURBS surfaces only: a bilinear floor (order 2), a concave dish (order 3), a bump (order 4),
    a NURBS sphere, torus and cylinder, under an area light."""
    new_scene()
    floor = grid_points(4, 4, (-3, 3), (-3, 3), lambda x, y: 0 * x)
    nurbs_patch("Floor", floor, material("Floor", (0.6, 0.6, 0.6)), order=(2, 2))
    dish = grid_points(4, 4, (-2.4, -0.4), (-1, 1), lambda x, y: 0.05 + 0.5 * ((x + 1.4) ** 2 + y**2))
    nurbs_patch("Dish", dish, material("Dish", (0.8, 0.5, 0.3)), order=(3, 3))
    bump = grid_points(
        4, 4, (0.5, 2.5), (-2.5, -0.5), lambda x, y: 0.02 + 0.6 * np.exp(-((x - 1.5) ** 2 + (y + 1.5) ** 2))
    )
    nurbs_patch("Bump", bump, material("Bump", (0.3, 0.6, 0.8)), order=(4, 4))
    bpy.ops.surface.primitive_nurbs_surface_sphere_add(radius=0.6, location=(1.5, 1.2, 0.8))
    assign(bpy.context.active_object, material("Sphere", (0.8, 0.8, 0.8)), "NurbsSphere")
    bpy.ops.surface.primitive_nurbs_surface_torus_add(location=(-1.2, 1.8, 0.3), scale=(0.6, 0.6, 0.6))
    assign(bpy.context.active_object, material("Torus", (0.7, 0.7, 0.3)), "Torus")
    bpy.ops.surface.primitive_nurbs_surface_cylinder_add(radius=0.4, location=(0.2, 2.2, 0.5))
    assign(bpy.context.active_object, material("Cylinder", (0.5, 0.8, 0.5)), "Cylinder")
    area_light("Lamp", (0, 0, 3.5), 1.5, 150.0)
    camera((5.5, -6.0, 4.5), (0, 0, 0.4), lens=32.0)


def stress_many_spheres(count=12):
    """count x count UV spheres (16 x 8) over a floor, lit by a sun and an area light."""
    new_scene()
    plane("Floor", (0, 0, 0), 2.0 * count, material("Floor", (0.6, 0.6, 0.6)))
    colours = [
        material(f"Ball {k}", c) for k, c in enumerate([(0.8, 0.2, 0.2), (0.2, 0.7, 0.3), (0.2, 0.3, 0.8)])
    ]
    offsets = np.arange(count) * 2.0 - (count - 1)
    for i, x in enumerate(offsets):
        for j, y in enumerate(offsets):
            uv_sphere(f"Ball {i:02d} {j:02d}", (x, y, 0.6), 0.5, colours[(i + j) % 3], segments=16, rings=8)
    sun = bpy.data.objects.new("Sun", bpy.data.lights.new("Sun", "SUN"))
    sun.data.energy = 1.0
    sun.rotation_euler = (0.6, 0.2, 0.4)
    bpy.context.scene.collection.objects.link(sun)
    area_light("Lamp", (0, 0, 8), 4.0, 400.0)
    camera((count * 1.3, -count * 1.6, count * 1.1), (0, 0, 0), lens=30.0)


SCENES = {
    "01_seed_sphere_over_square": seed_sphere_over_square,
    "02_sphere_in_cube": sphere_in_cube,
    "03_cornell_box": cornell_box,
    "04_nurbs_only": nurbs_only,
    "05_stress_many_spheres": stress_many_spheres,
}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("names", nargs="*", help=f"scenes to build (default: all of {', '.join(SCENES)})")
    parser.add_argument("--out-dir", type=Path, default=HERE)
    args = parser.parse_args(argv)
    unknown = set(args.names) - set(SCENES)
    if unknown:
        parser.error(f"unknown scene(s): {', '.join(sorted(unknown))}")
    args.out_dir.mkdir(parents=True, exist_ok=True)
    for name in args.names or SCENES:
        SCENES[name]()
        save(args.out_dir / f"{name}.blend")
        print(args.out_dir / f"{name}.blend")
    return 0


if __name__ == "__main__":
    sys.exit(main())
