"""Everything Cycles renders takes part: curves, text, metaballs and geometry-nodes output through
their evaluated meshes, instances through the depsgraph; what cannot take part is skipped with a
warning; the `Radiosity` attribute exports to glTF as COLOR_0."""

import json
import subprocess
import sys

import numpy as np
import pytest
from blender_helpers import ROOT, bpy, collect, evaluated_world_positions, material, snapshot

pytestmark = pytest.mark.blender

FAST = dict(tol=1e-2, occlusion=False)


def compute(addon, **settings):
    return addon.pipeline.compute(bpy.context, addon.solve.Settings(**{**FAST, **settings}))


def lit_floor(size=4, subdivisions=5):
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=subdivisions, y_subdivisions=subdivisions, size=size)
    return bpy.context.active_object


def point_light(location=(0, 0, 3), energy=500.0):
    bpy.ops.object.light_add(type="POINT", location=location)
    bpy.context.active_object.data.energy = energy


def radiance(addon, obj):
    return addon.adapter.read_color_attribute(obj.data, "Radiosity")[:, :3]


# occlusion off (for speed) lets the floor see all faces of the closed objects, so rows of rho F
# sum above 1 and the core's kappa is infinite (the solver's bound then treats a zero residual
# as zero, no warning)
def test_curve_text_metaball_and_geometry_nodes_output_are_lit(addon):
    """Each non-mesh object gets a twin whose vertices are Blender's evaluated mesh, lit (finite,
    positive on the faces the light sees); Clear restores the scene exactly."""
    lit_floor()
    bpy.ops.object.text_add(location=(-1.8, -1.8, 0.3))
    bpy.context.active_object.data.body = "I"
    bpy.ops.curve.primitive_bezier_circle_add(radius=0.4, location=(1.2, 1.2, 0.5))
    bpy.context.active_object.name = "Tube"
    tube = bpy.context.active_object.data
    tube.bevel_depth, tube.resolution_u, tube.bevel_resolution = 0.1, 3, 0
    bpy.ops.object.metaball_add(location=(1.2, -1.2, 0.8), radius=0.5)
    bpy.context.active_object.data.resolution = 0.3
    bpy.ops.mesh.primitive_plane_add(location=(-1.2, 1.2, 0.5))
    generated = bpy.context.active_object
    generated.name = "Generated"
    tree = bpy.data.node_groups.new("Cube out", "GeometryNodeTree")
    tree.interface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    cube = tree.nodes.new("GeometryNodeMeshCube")
    cube.inputs["Size"].default_value = (0.4, 0.4, 0.4)
    tree.links.new(cube.outputs["Mesh"], tree.nodes.new("NodeGroupOutput").inputs[0])
    generated.modifiers.new("GN", "NODES").node_group = tree
    point_light()
    names = ("Text", "Tube", "Mball", "Generated")
    before = snapshot()
    collected = collect(addon)
    assert set(names) <= set(collected.targets) and not collected.skipped
    assert all(collected.targets[n].twin for n in names)
    compute(addon)
    for name in names:
        twin = bpy.data.objects[f"{name} radiosity"]
        assert np.allclose(
            evaluated_world_positions(bpy.data.objects[name]), evaluated_world_positions(twin), atol=1e-6
        ), name
        values = radiance(addon, twin)
        assert np.all(np.isfinite(values)) and values.min() >= 0.0 and values.max() > 0.1, name
    assert len(bpy.data.objects["Generated radiosity"].data.vertices) == 8  # the cube, not the plane
    assert bpy.ops.curved_radiosity.clear() == {"FINISHED"}
    assert snapshot() == before


def instanced_blocker():
    """A plane (0.8 m) in an excluded collection, instanced by an empty 1 m above the origin."""
    source = bpy.data.collections.new("Source")
    bpy.context.scene.collection.children.link(source)
    bpy.context.view_layer.layer_collection.children["Source"].exclude = True
    mesh = bpy.data.meshes.new("Blocker")
    mesh.from_pydata([(-0.4, -0.4, 0), (0.4, -0.4, 0), (0.4, 0.4, 0), (-0.4, 0.4, 0)], [], [(0, 1, 2, 3)])
    source.objects.link(bpy.data.objects.new("Blocker", mesh))
    instancer = bpy.data.objects.new("Instancer", None)
    instancer.instance_type, instancer.instance_collection = "COLLECTION", source
    instancer.location = (0.0, 0.0, 1.0)
    bpy.context.scene.collection.objects.link(instancer)
    return instancer


def test_collection_instances_cast_shadows_and_emit(addon):
    """An instanced plane between a point light and the floor darkens the floor vertex below it
    (exact shadows); made emissive, with the light off, it lights the floor; the warning names
    the instancer and says results are not written on instances."""
    floor = lit_floor(subdivisions=5)
    middle = np.argmin(np.linalg.norm(evaluated_world_positions(floor), axis=1))
    point_light(location=(0, 0, 3))
    instancer = instanced_blocker()
    collected = collect(addon)
    mine = [i for i in collected.surfaces if i.name.startswith("Instancer instance 0/")]
    assert len(mine) == 1 and mine[0].target is None
    corners = mine[0].surface.vertices  # (a PolygonMesh)
    assert np.allclose(corners[:, 2], 1.0)  # at the instance's world matrix
    warning = next(w for w in collected.warnings if "'Instancer'" in w)
    assert "not written on instances" in warning
    compute(addon, occlusion=True)
    shadowed = radiance(addon, floor)[middle]
    bpy.ops.curved_radiosity.clear()
    instancer.curved_radiosity_include = False
    compute(addon, occlusion=True)
    open_floor = radiance(addon, floor)[middle]
    assert np.all(shadowed < 0.2 * open_floor), (shadowed, open_floor)
    bpy.ops.curved_radiosity.clear()
    instancer.curved_radiosity_include = True
    bpy.data.objects["Point"].data.energy = 0.0
    bpy.data.objects["Blocker"].data.materials.append(material("Glow", emission=(1, 1, 1), strength=5.0))
    compute(addon)
    assert radiance(addon, floor)[middle].min() > 0.1


def test_geometry_nodes_instances_take_part(addon):
    """Instance on Points: one item set per instance at its own place, none with a result target."""
    bpy.ops.mesh.primitive_plane_add(size=2, location=(0, 0, 1))
    plane = bpy.context.active_object
    tree = bpy.data.node_groups.new("Scatter", "GeometryNodeTree")
    tree.interface.new_socket("Geometry", in_out="INPUT", socket_type="NodeSocketGeometry")
    tree.interface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    scatter = tree.nodes.new("GeometryNodeInstanceOnPoints")
    box = tree.nodes.new("GeometryNodeMeshCube")
    box.inputs["Size"].default_value = (0.2, 0.2, 0.2)
    tree.links.new(tree.nodes.new("NodeGroupInput").outputs[0], scatter.inputs["Points"])
    tree.links.new(box.outputs["Mesh"], scatter.inputs["Instance"])
    tree.links.new(scatter.outputs[0], tree.nodes.new("NodeGroupOutput").inputs[0])
    plane.modifiers.new("GN", "NODES").node_group = tree
    collected = collect(addon)
    for k in range(4):
        pieces = [i for i in collected.surfaces if i.name.startswith(f"Plane instance {k}/")]
        assert len(pieces) == 1 and pieces[0].surface.face_count == 6 and pieces[0].target is None
    centres = [
        next(
            i for i in collected.surfaces if i.name.startswith(f"Plane instance {k}/")
        ).surface.vertices.mean(0)
        for k in range(4)
    ]
    assert np.allclose(sorted(np.abs(c[:2]).tolist() for c in centres), [[1, 1]] * 4, atol=1e-6)
    assert any("'Plane'" in w and "4 instance(s)" in w for w in collected.warnings)


def test_objects_that_cannot_take_part_are_skipped_by_name(addon):
    """A curve with no faces and a zero-scaled sphere are skipped with warnings naming them; the
    rest is lit; with nothing else to light the refusal names them too."""
    floor = lit_floor(subdivisions=2)
    bpy.ops.curve.primitive_bezier_circle_add(location=(0, 0, 1))
    bpy.context.active_object.name = "Ring"
    bpy.ops.mesh.primitive_uv_sphere_add(location=(0, 0, 2))
    bpy.context.active_object.name = "Squashed"
    bpy.context.active_object.scale = (0.0, 0.0, 0.0)
    point_light()
    assert bpy.ops.curved_radiosity.compute() == {"FINISHED"}
    assert radiance(addon, floor).max() > 0.0
    skipped = collect(addon).skipped
    assert len(skipped) == 2
    assert any("'Ring'" in s and "no faces" in s for s in skipped)
    assert any("'Squashed'" in s and "scale is zero" in s for s in skipped)
    bpy.ops.curved_radiosity.clear()
    bpy.data.objects.remove(floor)
    with pytest.raises(addon.pipeline.PipelineError, match="nothing to light.*'Ring'.*'Squashed'"):
        compute(addon)


def test_radiosity_exports_to_gltf_as_color_0(addon, tmp_path):
    """Blender's glTF exporter writes the `Radiosity` attribute as the primitive's COLOR_0; each
    exported vertex's colour equals the attribute at the mesh vertex with that position."""
    floor = lit_floor(subdivisions=3)
    point_light(energy=300.0)
    compute(addon)
    values = radiance(addon, floor)
    path = tmp_path / "lit.gltf"
    bpy.ops.export_scene.gltf(
        filepath=str(path),
        export_format="GLTF_SEPARATE",
        export_vertex_color="NAME",
        export_vertex_color_name="Radiosity",
        export_lights=False,
    )
    gltf = json.loads(path.read_text())
    (mesh,) = [m for m in gltf["meshes"] if m["name"] == floor.data.name]
    primitive = mesh["primitives"][0]
    assert "COLOR_0" in primitive["attributes"], primitive["attributes"]

    def accessor(index):
        acc = gltf["accessors"][index]
        view = gltf["bufferViews"][acc["bufferView"]]
        data = (tmp_path / gltf["buffers"][view["buffer"]]["uri"]).read_bytes()
        # FLOAT, or (Blender's exporter for colours) normalised UNSIGNED_SHORT
        dtype, scale = {5126: (np.float32, 1.0), 5123: (np.uint16, 65535.0)}[acc["componentType"]]
        width = {"VEC3": 3, "VEC4": 4}[acc["type"]]
        size = np.dtype(dtype).itemsize
        start = view.get("byteOffset", 0) + acc.get("byteOffset", 0)
        stride = view.get("byteStride", size * width) // size
        flat = np.frombuffer(data, dtype, acc["count"] * stride, start).reshape(-1, stride)
        return flat[:, :width].astype(np.float64) / scale

    colours = accessor(primitive["attributes"]["COLOR_0"])[:, :3]
    exported = accessor(primitive["attributes"]["POSITION"])
    world = evaluated_world_positions(floor)
    blender = np.column_stack([exported[:, 0], -exported[:, 2], exported[:, 1]])  # glTF is Y-up
    nearest = np.argmin(np.linalg.norm(blender[:, None] - world[None], axis=2), axis=1)
    assert np.allclose(blender, world[nearest], atol=1e-6)
    # the exporter stores colours as 16-bit fractions: within [0, 1] they match to 1/65535
    assert 0.05 < values.max() < 1.0
    assert np.allclose(colours, values[nearest], rtol=0, atol=1.0 / 65535), (colours.max(), values.max())


def test_headless_gltf_export(tmp_path):
    """`python -m addon.headless --gltf`: every exported mesh has COLOR_0; a text object goes out
    as its lit twin only (its hidden original is not exported twice); radiance above 1 is
    reported as clamped on stderr."""
    bpy.ops.wm.read_homefile(use_empty=True)
    lit_floor(subdivisions=2)
    bpy.ops.object.text_add(location=(-0.5, -0.5, 0.5))
    bpy.context.active_object.data.body = "I"
    point_light(energy=5000.0)
    scene = tmp_path / "text.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(scene), copy=True)
    out = tmp_path / "lit.gltf"
    command = [sys.executable, "-m", "addon.headless", str(scene), "--quality", "DRAFT", "--gltf", str(out)]
    done = subprocess.run(command, capture_output=True, text=True, cwd=ROOT, timeout=300)
    assert done.returncode == 0, done.stderr
    gltf = json.loads(out.read_text())
    names = sorted(node["name"] for node in gltf["nodes"] if "mesh" in node)
    assert names == ["Grid", "Text radiosity"], names
    assert all("COLOR_0" in p["attributes"] for m in gltf["meshes"] for p in m["primitives"])
    assert any(line.startswith("warning: glTF") and "clamped" in line for line in done.stderr.splitlines())


def test_particle_instances_and_a_twinned_instancer(addon):
    """Particles instancing a cube take part (no result target, at their own places); the
    emitter's results go to a twin, which hides its instances, so the warning says so, and a
    second run while results are shown says the instances are left out."""
    bpy.ops.mesh.primitive_cube_add(size=0.2, location=(0, 0, -5))
    grain = bpy.context.active_object
    grain.name = "Grain"
    floor = lit_floor(subdivisions=2)
    floor.modifiers.new("Particles", "PARTICLE_SYSTEM")
    settings = floor.particle_systems[0].settings
    settings.count, settings.frame_start, settings.frame_end = 3, 1, 1
    settings.render_type, settings.instance_object = "OBJECT", grain
    settings.physics_type = "NO"
    settings.particle_size = 1.0
    point_light()
    collected = collect(addon)
    grains = {i.name.split("/")[0] for i in collected.surfaces if i.name.startswith("Grid instance")}
    assert len(grains) == 3
    assert all(i.target is None for i in collected.surfaces if i.name.startswith("Grid instance"))
    assert not collected.targets["Grain"].twin and collected.targets["Grid"].twin
    assert any("'Grid'" in w and "hidden with it" in w for w in collected.warnings)
    compute(addon, occlusion=True)
    assert any("left out" in w for w in collect(addon).warnings)
