"""Walk a Blender scene and turn what renders into `Collected` items.

Included: objects visible to the render (not `hide_render`, in a collection that is neither
excluded from the view layer nor hidden from renders) whose "Include in radiosity" toggle
(`Object.curved_radiosity_include`) is on, and the instances they make (collection instances,
particles, geometry-nodes instances: `Depsgraph.object_instances`, each with its own world
matrix).

- Mesh objects become UV spheres or flat polygons; curves, text, metaballs and any object whose
  geometry nodes output a mesh take part through their evaluated mesh, as flat polygons (their
  results go to a mesh twin, like those of NURBS surface objects, which become `NurbsSurface`s);
- area lights become emitting patches, point / spot / sun lights core lights, and the world's
  background a uniform sky (`lights.world_sky`);
- instances receive and cast light (they shade, reflect and emit) but their results are not
  written: their geometry is shared by every instance, and one warning per instancer says so;
- objects that cannot take part (no faces, hair / point clouds / volumes, degenerate geometry,
  a zero scale) are skipped, each with a warning naming it (`Collected.skipped`);
- cameras, empties etc. are ignored.
"""

import numpy as np

from . import adapter, objects, state
from .items import Collected, Target
from .lights import light_spec, world_sky

GEOMETRY_TYPES = {"CURVE", "FONT", "META", "CURVES", "POINTCLOUD", "VOLUME", "GREASEPENCIL", "GPENCIL"}
# types whose evaluated mesh (tessellation, extrusion, polygonisation, geometry nodes) is what renders
MESHED_TYPES = {"MESH", "CURVE", "FONT", "META", "CURVES", "POINTCLOUD", "GREASEPENCIL", "GPENCIL"}
# the depsgraph lists a curve's, text's, metaball's or NURBS surface's own evaluated mesh as an
# instance of the object itself whose persistent id holds only this value past its first entry
# (instances that geometry nodes make count from 0 there)
OWN_GEOMETRY = 2**31 - 1
# what a type renders as when its evaluated geometry has no faces
FACELESS = {
    "CURVE": "a curve without extrusion, bevel or fill",
    "FONT": "text without faces",
    "CURVES": "hair curves",
    "POINTCLOUD": "points",
    "VOLUME": "a volume",
    "GREASEPENCIL": "grease-pencil strokes",
    "GPENCIL": "grease-pencil strokes",
}


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


def included(obj):
    """The object's "Include in radiosity" toggle (on if the add-on's property is missing)."""
    return getattr(obj, "curved_radiosity_include", True)


def candidates(scene, view_layer):
    """Objects of `scene` that take part: rendered, not result twins, toggle on, and not an
    instancer that Cycles hides (`show_instancer_for_render` off)."""
    enabled = render_collections(view_layer)
    return [
        obj
        for obj in scene.objects
        if not state.is_twin(obj)
        and included(obj)
        and renders(obj, enabled)
        and (not obj.is_instancer or obj.show_instancer_for_render)
    ]


def needs_twin(obj):
    """Results go to a mesh twin unless the object's own single-user mesh is what renders."""
    return obj.type != "MESH" or len(obj.modifiers) > 0 or obj.data.users > 1


def collect(scene, view_layer, depsgraph):
    """Convert the scene: its objects, then the instances of those that render.

    Objects that cannot take part are left out; `Collected.skipped` (also in `warnings`) names
    each with the reason.

    Returns
    -------
    Collected
    """
    out = Collected()
    for obj in candidates(scene, view_layer):
        evaluated = obj.evaluated_get(depsgraph)
        _add_or_skip(out, obj, evaluated, adapter.matrix(evaluated), obj.name)
        if "hidden" in (state.saved(obj) or {}) and _may_instance(obj):
            # a hidden object is not evaluated in the viewport: the depsgraph lists no instances
            out.warnings.append(
                f"{obj.name!r} is hidden while its twin shows its results: any instances it makes "
                "(particles, geometry-nodes instances) are left out; clear the results first"
            )
    _add_instances(out, view_layer, depsgraph)
    out.sky, warnings = world_sky(scene.world)
    out.warnings += warnings
    out.warnings = list(dict.fromkeys(out.warnings))  # once each (instances repeat theirs)
    return out


def _may_instance(obj):
    return obj.is_instancer or len(obj.particle_systems) > 0 or any(m.type == "NODES" for m in obj.modifiers)


def _add_or_skip(out, obj, evaluated, M, name, instance=False):
    """Convert one object (or instance) into `out`; a ValueError skips it with a warning."""
    try:
        _add_object(out, obj, evaluated, M, name, instance)
    except ValueError as error:
        message = object_error(name, obj.type, error, M) + ": skipped"
        out.skipped.append(message)
        out.warnings.append(message)


def object_error(name, kind, error, M):
    """The message of `error` raised while converting object `name` of type `kind`, starting
    with the name, and saying so when its transform `M` (4, 4) flattens it (a zero scale)."""
    message = str(error)
    if not message.startswith(repr(name)):
        message = f"{name!r}: {message}"
    if kind in {"MESH", "SURFACE", "LIGHT"} | GEOMETRY_TYPES and _is_flattening(M):
        message += " (its scale is zero along an axis: give it a non-zero scale or exclude it)"
    return message


def _is_flattening(M):
    """True if the linear part of M (4, 4) maps some direction to (nearly) zero."""
    singular = np.linalg.svd(M[:3, :3], compute_uv=False)
    return not np.all(np.isfinite(singular)) or singular[-1] <= 1e-12 * max(singular[0], 1e-300)


def _add_object(out, obj, evaluated, M, name, instance):
    """Items of one object (`obj` gives materials and settings, `evaluated` the geometry, `M`
    the world matrix); an instance (`instance`) gets no result target, its items are renamed."""
    start = (len(out.surfaces), len(out.lights))
    if obj.type in MESHED_TYPES or obj.type == "VOLUME":
        _add_mesh(out, obj, evaluated, M, name, instance)
    elif obj.type == "SURFACE":
        items, warnings, n_vertices = objects.nurbs_items(obj, M, name, _world_normals(evaluated, M))
        _add_target(out, name, items, warnings, n_vertices, True, instance)
    elif obj.type == "LIGHT":
        if obj.data.type == "AREA":
            item, warnings = objects.area_light_item(obj, M)
            out.surfaces.append(item)
        else:
            light, warnings = light_spec(obj, M)
            out.lights.append(light)
        out.warnings += warnings
    if instance:
        for item in out.surfaces[start[0] :]:
            item.name = f"{name}/{item.name}"
        for light in out.lights[start[1] :]:
            light.name = f"{name}/{light.name}"


def _add_mesh(out, obj, evaluated, M, name, instance):
    """A mesh, or a curve, text, metaball, ... through its evaluated mesh."""
    mesh = evaluated.to_mesh() if obj.type != "VOLUME" else None
    try:
        if mesh is None or len(mesh.polygons) == 0:
            # an edge-only mesh or a metaball other than its family's first renders nothing;
            # other types render something that has no faces here
            if obj.type in FACELESS:
                raise ValueError(f"it renders as {FACELESS[obj.type]}, which has no faces to light")
            return
        items, warnings = objects.mesh_items(obj, M, mesh, name)
        n_vertices = len(mesh.vertices)
    finally:
        if mesh is not None:
            evaluated.to_mesh_clear()
    _add_target(out, name, items, warnings, n_vertices, needs_twin(obj), instance)


def _add_target(out, name, items, warnings, n_vertices, twin, instance):
    if not items:
        return
    if instance:
        for item in items:
            item.target = None
    else:
        two_sided = any(item.material.two_sided for item in items)
        out.targets[name] = Target(name, n_vertices, twin, two_sided)
    out.surfaces += items
    out.warnings += warnings


def _add_instances(out, view_layer, depsgraph):
    """The instances made by rendered instancers, each with its world matrix; one warning per
    instancer that its instances' results are not written."""
    enabled = render_collections(view_layer)
    counts = {}
    for instance in depsgraph.object_instances:
        if not instance.is_instance or instance.parent is None:
            continue
        parent = instance.parent.original
        evaluated = instance.object
        source = evaluated.original  # a geometry-nodes instance's is the instancer itself
        if state.is_twin(parent) or not included(parent) or not renders(parent, enabled):
            continue
        if source is parent and all(i == OWN_GEOMETRY for i in instance.persistent_id[1:]):
            continue  # the object's own evaluated mesh, already taken through `to_mesh`
        if source is not parent and (not included(source) or source.hide_render):
            continue
        if evaluated.type not in MESHED_TYPES | {"SURFACE", "LIGHT"}:
            continue
        k = counts.get(parent.name, 0)
        counts[parent.name] = k + 1
        M = np.array(instance.matrix_world, dtype=np.float64)
        _add_or_skip(out, evaluated, evaluated, M, f"{parent.name} instance {k}", instance=True)
    for name, count in counts.items():
        target = out.targets.get(name)
        twinned = target is not None and target.twin
        hidden = " (and they are hidden with it while its twin shows its results)" if twinned else ""
        out.warnings.append(
            f"{name!r}: its {count} instance(s) receive and cast light, but results are not written "
            f"on instances (their data is shared){hidden}; make them real (Object > Apply > Make "
            "Instances Real) to see theirs"
        )


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
