"""Walk a Blender scene and turn what renders into `Collected` items.

Included: objects visible to the render (not `hide_render`, in a collection that is neither
excluded from the view layer nor hidden from renders) whose "Include in radiosity" toggle
(`Object.curved_radiosity_include`) is on. Mesh and NURBS-surface objects become surfaces, area
lights emitting patches, point / spot / sun lights core lights. Other geometry types (curves,
text, metaballs, ...) are errors naming the object; cameras, empties etc. are ignored.
"""

import numpy as np

from . import adapter, objects, state
from .items import Collected, Target
from .lights import light_spec

GEOMETRY_TYPES = {"CURVE", "FONT", "META", "CURVES", "POINTCLOUD", "VOLUME", "GREASEPENCIL", "GPENCIL"}


class CollectError(Exception):
    """The scene cannot be converted; `messages` name each offending object."""

    def __init__(self, messages):
        super().__init__("; ".join(messages))
        self.messages = list(messages)


def render_collections(view_layer):
    """Pointers (`as_pointer()`) of the collections whose objects render in `view_layer`."""
    enabled = set()

    def walk(layer_collection, parent_on):
        on = parent_on and not layer_collection.exclude and not layer_collection.collection.hide_render
        if on:
            enabled.add(layer_collection.collection.as_pointer())
        for child in layer_collection.children:
            walk(child, on)

    walk(view_layer.layer_collection, True)
    return enabled


def renders(obj, enabled):
    """True if `obj` is part of the render (its own toggle as saved before results hid it)."""
    return not state.original_hide_render(obj) and any(
        c.as_pointer() in enabled for c in obj.users_collection
    )


def candidates(scene, view_layer):
    """Objects of `scene` that take part: rendered, not result twins, toggle on."""
    enabled = render_collections(view_layer)
    return [
        obj
        for obj in scene.objects
        if not state.is_twin(obj) and getattr(obj, "curved_radiosity_include", True) and renders(obj, enabled)
    ]


def needs_twin(obj):
    """Results go to a mesh twin unless the object's own single-user mesh is what renders."""
    return obj.type == "SURFACE" or len(obj.modifiers) > 0 or obj.data.users > 1


def collect(scene, view_layer, depsgraph):
    """Convert the scene.

    Returns
    -------
    Collected

    Raises
    ------
    CollectError
        Listing every object that could not be converted.
    """
    out = Collected()
    for obj in candidates(scene, view_layer):
        try:
            _add_object(out, obj, depsgraph)
        except ValueError as error:
            out.errors.append(object_error(obj, error, adapter.matrix(obj.evaluated_get(depsgraph))))
    if out.errors:
        raise CollectError(out.errors)
    return out


def object_error(obj, error, M):
    """The message of `error` raised while converting `obj`, starting with the object's name,
    and saying so when its transform `M` (4, 4) flattens it (a zero scale)."""
    message = str(error)
    name = repr(obj.name)
    if not message.startswith(name):
        message = f"{name}: {message}"
    if obj.type in ("MESH", "SURFACE", "LIGHT") and _is_flattening(M):
        message += " (its scale is zero along an axis: give it a non-zero scale or exclude it)"
    return message


def _is_flattening(M):
    """True if the linear part of M (4, 4) maps some direction to (nearly) zero."""
    singular = np.linalg.svd(M[:3, :3], compute_uv=False)
    return not np.all(np.isfinite(singular)) or singular[-1] <= 1e-12 * max(singular[0], 1e-300)


def _add_object(out, obj, depsgraph):
    evaluated = obj.evaluated_get(depsgraph)
    M = adapter.matrix(evaluated)
    if obj.type == "MESH":
        mesh = evaluated.to_mesh()
        try:
            if len(mesh.polygons) == 0:
                return
            items, warnings = objects.mesh_items(obj, M, mesh, obj.name)
            n_vertices = len(mesh.vertices)
        finally:
            evaluated.to_mesh_clear()
        _add_target(out, obj, items, warnings, n_vertices, needs_twin(obj))
    elif obj.type == "SURFACE":
        items, warnings, n_vertices = objects.nurbs_items(obj, M, obj.name, _world_normals(evaluated, M))
        _add_target(out, obj, items, warnings, n_vertices, True)
    elif obj.type == "LIGHT":
        if obj.data.type == "AREA":
            item, warnings = objects.area_light_item(obj, M)
            out.surfaces.append(item)
        else:
            light, warnings = light_spec(obj, M)
            out.lights.append(light)
        out.warnings += warnings
    elif obj.type in GEOMETRY_TYPES:
        raise ValueError(
            f"{obj.name!r}: objects of type {obj.type} are not supported; convert it to a mesh or "
            "turn off its 'Include in radiosity' toggle"
        )


def _add_target(out, obj, items, warnings, n_vertices, twin):
    if not items:
        return
    two_sided = any(item.material.two_sided for item in items)
    out.targets[obj.name] = Target(obj.name, n_vertices, twin, two_sided)
    out.surfaces += items
    out.warnings += warnings


def _world_normals(evaluated, M):
    """Vertex normals of an object's evaluated tessellation in world space, shape (V, 3), or None."""
    mesh = evaluated.to_mesh()
    try:
        if mesh is None or len(mesh.vertices) == 0:
            return None
        normals = adapter.vertex_normals(mesh)
    finally:
        evaluated.to_mesh_clear()
    return normals @ np.linalg.inv(M[:3, :3])  # normals map by the inverse transpose
