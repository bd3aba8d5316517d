"""Helpers shared by the Blender tests (import after conftest.py has set BLENDER_USER_RESOURCES)."""

from pathlib import Path

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

ROOT = Path(__file__).resolve().parents[2]
MODULE = "bl_ext.user_default.curved_radiosity"


def positions(mesh):
    """Vertex positions of a bpy mesh, shape (N, 3)."""
    co = np.empty(len(mesh.vertices) * 3, np.float32)
    mesh.vertices.foreach_get("co", co)
    return co.reshape(-1, 3).astype(np.float64)


def world_positions(obj):
    """World-space vertex positions of a mesh object (its own mesh), shape (N, 3)."""
    M = np.array(obj.matrix_world)
    return positions(obj.data) @ M[:3, :3].T + M[:3, 3]


def evaluated_world_positions(obj):
    """World-space vertices of Blender's evaluated mesh of any object, shape (N, 3)."""
    depsgraph = bpy.context.evaluated_depsgraph_get()
    evaluated = obj.evaluated_get(depsgraph)
    mesh = evaluated.to_mesh()
    try:
        local = positions(mesh)
    finally:
        evaluated.to_mesh_clear()
    M = np.array(evaluated.matrix_world)
    return local @ M[:3, :3].T + M[:3, 3]


def collect(addon):
    """`collect.collect` on the current scene."""
    context = bpy.context
    return addon.collect.collect(context.scene, context.view_layer, context.evaluated_depsgraph_get())


def items_of(addon, obj):
    """The collected items whose result target is `obj`."""
    return [i for i in collect(addon).surfaces if i.target == obj.name]


def polygon_mesh(name, verts, faces, **transform):
    """A mesh object from vertex and face lists, linked to the scene."""
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata(verts, [], faces)
    obj = bpy.data.objects.new(name, mesh)
    bpy.context.scene.collection.objects.link(obj)
    for key, value in transform.items():
        setattr(obj, key, value)
    bpy.context.view_layer.update()
    return obj


def material(name, base=(0.8, 0.8, 0.8), emission=(0.0, 0.0, 0.0), strength=0.0, culling=False):
    """A Principled BSDF material."""
    mat = bpy.data.materials.new(name)
    if mat.node_tree is None:  # Blender < 5.0 (5.0 warns on any use of use_nodes)
        mat.use_nodes = True
    bsdf = mat.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Base Color"].default_value = (*base, 1.0)
    bsdf.inputs["Emission Color"].default_value = (*emission, 1.0)
    bsdf.inputs["Emission Strength"].default_value = strength
    mat.use_backface_culling = culling
    return mat


# attribute data type -> (foreach property, values per element); other types compare by size
ATTRIBUTE_FIELDS = {
    "FLOAT": ("value", 1),
    "INT": ("value", 1),
    "INT8": ("value", 1),
    "BOOLEAN": ("value", 1),
    "FLOAT2": ("vector", 2),
    "INT32_2D": ("value", 2),
    "FLOAT_VECTOR": ("vector", 3),
    "FLOAT_COLOR": ("color", 4),
    "BYTE_COLOR": ("color", 4),
    "QUATERNION": ("value", 4),
}


def attribute_data(attribute):
    """An attribute's values as bytes (exact comparison), or its size for unlisted types."""
    field = ATTRIBUTE_FIELDS.get(attribute.data_type)
    if field is None:
        return len(attribute.data)
    prop, width = field
    dtype = np.bool_ if attribute.data_type == "BOOLEAN" else np.float64
    if attribute.data_type in ("INT", "INT8", "INT32_2D"):
        dtype = np.int64
    buffer = np.zeros(len(attribute.data) * width, dtype=dtype)
    attribute.data.foreach_get(prop, buffer)
    return buffer.tobytes()


def material_slots(obj):
    """(link, object-level material, data-level material) per slot.

    The object-level material of a DATA slot is hidden from `slot.material`; it is read by
    switching the link to OBJECT and back (a flag, nothing else changes).
    """
    out = []
    data_materials = obj.data.materials if obj.data is not None and hasattr(obj.data, "materials") else []
    for index, slot in enumerate(obj.material_slots):
        link = slot.link
        slot.link = "OBJECT"
        object_material = slot.material.name if slot.material else None
        slot.link = link
        data_material = data_materials[index] if index < len(data_materials) else None
        out.append((link, object_material, data_material.name if data_material else None))
    return out


def mesh_snapshot(mesh):
    """A mesh's attributes with their data, attribute choices and materials."""
    colours = mesh.color_attributes
    return dict(
        attributes={a.name: (a.domain, a.data_type, attribute_data(a)) for a in mesh.attributes},
        active_color=colours.active_color_name,
        default_color=colours.default_color_name,
        active=mesh.attributes.active.name if mesh.attributes.active else None,
        materials=tuple(m.name if m else None for m in mesh.materials),
        users=mesh.users,
        uv=(
            mesh.uv_layers.active.name if mesh.uv_layers.active else None,
            tuple((layer.name, layer.active_render) for layer in mesh.uv_layers),
        ),
    )


def snapshot():
    """Everything that computing and clearing must leave as it was: objects (type, visibility,
    transform, material slots with both link levels, custom properties), every mesh's attributes
    with their data and attribute choices (UV maps too), materials and images with their user
    counts, collections with their objects and children, and the scene's custom properties."""
    view_layer = bpy.context.view_layer
    objects = {}
    for obj in bpy.data.objects:
        hidden = obj.hide_get(view_layer=view_layer) if obj.name in view_layer.objects else None
        objects[obj.name] = dict(
            type=obj.type,
            data=obj.data.name if obj.data else None,
            visibility=(obj.hide_render, obj.hide_viewport, hidden),
            matrix=tuple(tuple(row) for row in obj.matrix_world),
            slots=material_slots(obj),
            props=sorted(obj.keys()),
            collections=sorted(c.name for c in obj.users_collection),
        )
    return dict(
        objects=objects,
        meshes={mesh.name: mesh_snapshot(mesh) for mesh in bpy.data.meshes},
        materials={m.name: (m.users, m.use_fake_user) for m in bpy.data.materials},
        images={i.name: (i.users, tuple(i.size), i.source) for i in bpy.data.images},
        collections={
            c.name: (sorted(o.name for o in c.objects), sorted(ch.name for ch in c.children))
            for c in bpy.data.collections
        },
        scene_props=sorted(bpy.context.scene.keys()),
    )
