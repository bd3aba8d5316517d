"""What takes part: render visibility, the per-object toggle, unsupported objects, result targets."""

import pytest
from blender_helpers import bpy, collect, material

pytestmark = pytest.mark.blender


def names(collected):
    return set(collected.targets)


def test_hidden_from_render_and_toggle_off_are_skipped(addon):
    """hide_render, the 'Include in Radiosity' toggle and collections off for render all leave objects out."""
    bpy.ops.mesh.primitive_cube_add()
    bpy.ops.mesh.primitive_cube_add(location=(3, 0, 0))
    bpy.context.active_object.hide_render = True
    bpy.ops.mesh.primitive_cube_add(location=(6, 0, 0))
    bpy.context.active_object.curved_radiosity_include = False
    hidden = bpy.data.collections.new("Hidden")
    bpy.context.scene.collection.children.link(hidden)
    hidden.hide_render = True
    excluded = bpy.data.collections.new("Excluded")
    bpy.context.scene.collection.children.link(excluded)
    bpy.context.view_layer.layer_collection.children["Excluded"].exclude = True
    for collection, x in ((hidden, 9), (excluded, 12)):
        obj = bpy.data.objects.new(collection.name + "Cube", bpy.data.meshes["Cube"])
        obj.location.x = x
        collection.objects.link(obj)
    assert names(collect(addon)) == {"Cube"}


def test_faceless_objects_are_skipped_by_name(addon):
    """Text takes part through its evaluated mesh; a curve with no faces is skipped with a warning
    naming it; switching its toggle off leaves it out silently."""
    bpy.ops.object.text_add()
    bpy.context.active_object.name = "Caption"
    bpy.ops.curve.primitive_bezier_circle_add()
    bpy.context.active_object.name = "Ring"
    collected = collect(addon)
    assert names(collected) == {"Caption"}
    assert len(collected.skipped) == 1 and "'Ring'" in collected.skipped[0]
    assert collected.skipped[0] in collected.warnings
    bpy.data.objects["Ring"].curved_radiosity_include = False
    assert not collect(addon).skipped


def test_cameras_empties_are_ignored(addon):
    bpy.ops.object.camera_add()
    bpy.ops.object.empty_add()
    collected = collect(addon)
    assert not collected.targets and not collected.surfaces and not collected.lights


def test_twin_needed_for_modifiers_shared_meshes_and_surfaces(addon):
    """Own mesh for plain meshes; a twin for NURBS, modifiers or mesh data shared by two objects."""
    bpy.ops.mesh.primitive_cube_add()
    bpy.ops.mesh.primitive_cube_add(location=(3, 0, 0))
    bpy.context.active_object.modifiers.new("Bevel", "BEVEL")
    bpy.ops.mesh.primitive_plane_add(location=(6, 0, 0))
    shared = bpy.context.active_object
    other = bpy.data.objects.new("SharedToo", shared.data)
    other.location.x = 9
    bpy.context.scene.collection.objects.link(other)
    bpy.ops.surface.primitive_nurbs_surface_sphere_add(location=(0, 4, 0))
    targets = collect(addon).targets
    assert {n: t.twin for n, t in targets.items()} == {
        "Cube": False,
        "Cube.001": True,
        "Plane": True,
        "SharedToo": True,
        "SurfSphere": True,
    }
    assert targets["Cube.001"].n_vertices > 8  # the bevelled, evaluated mesh


def test_per_polygon_materials_and_patch_setting(addon):
    """Each material's polygons are one PolygonMesh item with that material; the object's patch
    setting reaches every item."""
    bpy.ops.mesh.primitive_cube_add()
    cube = bpy.context.active_object
    cube.data.materials.append(material("Grey", base=(0.5, 0.5, 0.5)))
    cube.data.materials.append(material("Lamp", emission=(1.0, 1.0, 1.0), strength=5.0))
    cube.data.polygons[2].material_index = 1
    cube.curved_radiosity_patches = (3, 2)
    collected = collect(addon)
    emitting = [i for i in collected.surfaces if i.material.emission.any()]
    assert len(emitting) == 1 and emitting[0].name == "Cube[material 1]"
    assert emitting[0].surface.face_count == 1 and emitting[0].surface.area() == pytest.approx(4.0)
    assert all(i.patches == (3, 2) for i in collected.surfaces)
    assert collected.has_emitters()


def test_emitters(addon):
    """Only lights with power or emissive materials count as emitters."""
    bpy.ops.mesh.primitive_cube_add()
    assert not collect(addon).has_emitters()
    bpy.ops.object.light_add(type="POINT", location=(0, 0, 3))
    assert collect(addon).has_emitters()
    bpy.context.active_object.data.energy = 0.0
    assert not collect(addon).has_emitters()


def test_nurbs_front_is_the_side_blender_shades_as_front(addon):
    """A NURBS surface's core front (dP/du x dP/dv, possibly flipped) points along the normals of
    Blender's own tessellation, so the front/back colour attributes land on the right faces."""
    import numpy as np

    bpy.ops.surface.primitive_nurbs_surface_sphere_add(radius=0.6, location=(1.0, 0.5, 0.8))
    obj = bpy.context.active_object
    item = collect(addon).surfaces[0]
    evaluated = obj.evaluated_get(bpy.context.evaluated_depsgraph_get())
    mesh = evaluated.to_mesh()
    normals = np.array([n.vector[:] for n in mesh.vertex_normals])
    evaluated.to_mesh_clear()
    _, ours = item.surface.evaluate(item.params[:, 0], item.params[:, 1])
    agree = np.einsum("ki,ki->k", ours, normals[item.vertices]) > 0
    assert agree.mean() > 0.9
    # Blender's sphere primitive shades its outside as front: ours is the outside too
    x, _ = item.surface.evaluate(item.params[:, 0], item.params[:, 1])
    outward = np.einsum("ki,ki->k", ours, x - np.array([1.0, 0.5, 0.8])) > 0
    assert outward.mean() > 0.9
