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


def snapshot():
    """Everything `clear` must restore: objects, visibility, slots, attributes, collections."""
    view_layer = bpy.context.view_layer
    objects = {}
    for obj in bpy.data.objects:
        slots = []
        for slot in obj.material_slots:
            slots.append((slot.link, slot.material.name if slot.material else None))
        attributes = None
        if obj.type == "MESH":
            mesh = obj.data
            attributes = (
                sorted(a.name for a in mesh.attributes),
                mesh.color_attributes.active_color_name,
                mesh.color_attributes.default_color_name,
                mesh.attributes.active.name if mesh.attributes.active else None,
                tuple(m.name if m else None for m in mesh.materials),
            )
        hidden = obj.hide_get(view_layer=view_layer) if obj.name in view_layer.objects else None
        props = sorted(obj.keys())
        objects[obj.name] = (obj.type, obj.hide_render, obj.hide_viewport, hidden, slots, attributes, props)
    return dict(
        objects=objects,
        meshes=sorted(bpy.data.meshes.keys()),
        materials=sorted(bpy.data.materials.keys()),
        collections=sorted(bpy.data.collections.keys()),
        scene_props=sorted(bpy.context.scene.keys()),
    )
