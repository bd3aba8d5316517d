"""Writing results back: attributes on the right vertices, twins, the view material, exact clearing.

These tests need no solver: the "radiance" written is each sample's own world position P(u, v)
(plus an offset, to show values above 1 are kept). After writing, every result vertex must carry
its own world position, which checks the whole index chain (UV-sphere layout, polygon corners,
NURBS tessellation grid onto the twin).
"""

import numpy as np
import pytest
from blender_helpers import bpy, collect, material, snapshot, world_positions

pytestmark = pytest.mark.blender

OFFSET = 10.0


def build_scene():
    """A UV sphere, a material-less plane, a cube with a bevel, a NURBS sphere, a shared mesh."""
    bpy.ops.mesh.primitive_uv_sphere_add(segments=16, ring_count=8, location=(0, 0, 1))
    sphere = bpy.context.active_object
    sphere.data.materials.append(material("Red", base=(0.8, 0.1, 0.1)))
    sphere.data.color_attributes.new("Paint", "BYTE_COLOR", "CORNER")
    bpy.ops.mesh.primitive_plane_add(size=6)
    bpy.ops.mesh.primitive_cube_add(location=(3, 0, 1), scale=(0.5, 0.5, 0.5))
    bpy.context.active_object.modifiers.new("Bevel", "BEVEL")
    bpy.ops.surface.primitive_nurbs_surface_sphere_add(location=(-3, 0, 1), rotation=(0.2, 0.3, 0.4))
    bpy.context.active_object.data.materials.append(material("Blue", base=(0.1, 0.1, 0.8)))
    bpy.ops.object.light_add(type="AREA", location=(0, 0, 4))
    bpy.context.view_layer.update()


def position_radiance(collected):
    """Target -> (front, back): each vertex's sampled world position + OFFSET (front), x 2 (back)."""
    out = {}
    for name, target in collected.targets.items():
        front = np.zeros((target.n_vertices, 3))
        for item in (i for i in collected.surfaces if i.target == name):
            if type(item.surface).__name__ == "PolygonMesh":  # samples at its own vertices
                front[item.vertices] = item.surface.vertices[item.vertices] + OFFSET
            else:
                front[item.vertices] = item.surface.evaluate(item.params[:, 0], item.params[:, 1])[0] + OFFSET
        out[name] = (front, 2.0 * front if target.two_sided else None)
    return out


def write(addon, collected, radiance):
    context = bpy.context
    addon.results.write(
        context.scene, context.view_layer, context.evaluated_depsgraph_get(), collected, radiance
    )


def holder(addon, name):
    """The object that holds the results of `name` (itself or its twin)."""
    twins = [o for o in bpy.data.objects if o.get(addon.state.TWIN_KEY) == name]
    return twins[0] if twins else bpy.data.objects[name]


def test_attributes_carry_each_vertex_its_own_value(addon):
    """Front and back FLOAT_COLOR POINT attributes, unclamped, on the vertex each sample maps to."""
    build_scene()
    collected = collect(addon)
    write(addon, collected, position_radiance(collected))
    for name in collected.targets:
        obj = holder(addon, name)
        front = addon.adapter.read_color_attribute(obj.data, addon.results.FRONT)
        back = addon.adapter.read_color_attribute(obj.data, addon.results.BACK)
        attribute = obj.data.color_attributes[addon.results.FRONT]
        assert (attribute.data_type, attribute.domain) == ("FLOAT_COLOR", "POINT")
        expected = world_positions(obj) + OFFSET
        assert np.abs(front[:, :3] - expected).max() < 1e-4 * OFFSET, name
        assert np.abs(back[:, :3] - 2 * expected).max() < 2e-4 * OFFSET, name
        assert np.all(front[:, 3] == 1.0)


def test_twins_stand_in_for_surfaces_and_modified_meshes(addon):
    """NURBS and modified meshes get a twin with the same transform in 'Radiosity'; originals hidden."""
    build_scene()
    collected = collect(addon)
    write(addon, collected, position_radiance(collected))
    for name in ("SurfSphere", "Cube"):
        original, twin = bpy.data.objects[name], holder(addon, name)
        assert twin is not original and twin.name == f"{name} radiosity"
        assert np.allclose(np.array(twin.matrix_world), np.array(original.matrix_world))
        assert twin.users_collection[0].name == "Radiosity"
        assert original.hide_render and original.hide_get()
        assert not twin.hide_render
    assert holder(addon, "Sphere").name == "Sphere" and not bpy.data.objects["Sphere"].hide_render


def test_view_material_and_switch_back(addon):
    """Result meshes show 'Radiosity View' (attribute -> emission); 'Original' shows their materials."""
    build_scene()
    collected = collect(addon)
    write(addon, collected, position_radiance(collected))
    view = bpy.data.materials[addon.results.VIEW_MATERIAL]
    layers = {n.layer_name for n in view.node_tree.nodes if n.bl_idname == "ShaderNodeVertexColor"}
    assert layers == {addon.results.FRONT, addon.results.BACK}
    emission = next(n for n in view.node_tree.nodes if n.bl_idname == "ShaderNodeEmission")
    assert emission.inputs["Strength"].default_value == 1.0
    results = [holder(addon, n) for n in collected.targets]
    assert all(s.material == view for obj in results for s in obj.material_slots)
    bpy.ops.curved_radiosity.show(mode="ORIGINAL")
    assert bpy.data.objects["Sphere"].material_slots[0].material.name == "Red"
    assert holder(addon, "SurfSphere").material_slots[0].material.name == "Blue"
    assert len(bpy.data.objects["Plane"].material_slots) == 0
    bpy.ops.curved_radiosity.show(mode="RESULT")
    assert all(s.material == view for obj in results for s in obj.material_slots)


@pytest.mark.parametrize("show_original_first", [False, True])
def test_clear_restores_everything_exactly(addon, show_original_first):
    """Objects, visibility, slots and links, attributes and their active/default choices, collections."""
    build_scene()
    bpy.data.objects["Plane"].hide_viewport = False
    before = snapshot()
    collected = collect(addon)
    write(addon, collected, position_radiance(collected))
    write(addon, collected, position_radiance(collected))  # a second run replaces the first
    assert len([o for o in bpy.data.objects if addon.state.TWIN_KEY in o]) == 2
    if show_original_first:
        bpy.ops.curved_radiosity.show(mode="ORIGINAL")
    assert snapshot() != before
    bpy.ops.curved_radiosity.clear()
    assert snapshot() == before


def test_existing_attribute_of_the_same_name_is_not_overwritten(addon):
    """A user attribute named "Radiosity" stops the write before anything changes: previous
    results stay as they were, nothing is half written."""
    build_scene()
    collected = collect(addon)
    write(addon, collected, position_radiance(collected))
    bpy.ops.mesh.primitive_cube_add(location=(0, 3, 1))
    bpy.context.active_object.data.color_attributes.new("Radiosity", "FLOAT_COLOR", "POINT")
    before = snapshot()
    collected = collect(addon)
    with pytest.raises(addon.results.ResultError, match="already has an attribute"):
        write(addon, collected, position_radiance(collected))
    assert snapshot() == before


def test_adapter_checks_sizes(addon):
    bpy.ops.mesh.primitive_cube_add()
    mesh = bpy.context.active_object.data
    with pytest.raises(addon.adapter.AttributeMismatchError, match="8 vertices"):
        addon.adapter.write_color_attribute(mesh, "X", np.zeros((7, 3)))
