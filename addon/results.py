"""Radiosity results in the Blender scene: colour attributes, mesh twins, a viewing material.

`write` puts a FLOAT_COLOR POINT attribute `Radiosity` (front-side outgoing radiance,
W / (m^2 sr), linear and unclamped) on each result mesh, and `Radiosity Back` for two-sided
surfaces. A result mesh is the object's own mesh, or a twin: a mesh made from Blender's
evaluated geometry (NURBS tessellation, modifiers applied), named "<object> radiosity", with the
object's transform, in the `Radiosity` collection, while the original is hidden. Result objects
show the "Radiosity View" material (Color Attribute -> Emission, strength 1, the back attribute
on back faces; found by its `VIEW_KEY` tag, never by name) through object-level material-slot
overrides, so mesh data materials are never touched; `show` switches between it and the
original materials, and `clear` restores visibility, material slots and attributes exactly.
Everything needed for that is kept in `state`, including a reference to each replaced
object-level material, so no user material drops to zero users (and out of a saved file)
while results are shown. Writing never changes the user's active or default colour attribute,
so computing twice leaves the scene as computing once.
"""

import bpy

from . import adapter, state

FRONT = "Radiosity"
BACK = "Radiosity Back"
VIEW_MATERIAL = "Radiosity View"
COLLECTION = "Radiosity"
COLLECTION_KEY = "_curved_radiosity_collection"
VIEW_KEY = "_curved_radiosity_view"
# on lightmap images and their view materials (removed by `clear` once unused)
LIGHTMAP_KEY = "_curved_radiosity_lightmap"


class ResultError(RuntimeError):
    """Results cannot be written, e.g. because the scene changed while solving."""


def find_view_material():
    """The add-on's view material (tagged with `VIEW_KEY`), or None; a user's own material
    that happens to be named "Radiosity View" is never taken for it."""
    return next((m for m in bpy.data.materials if m.get(VIEW_KEY)), None)


def view_material():
    """The shared emission-only material that displays the radiance attributes."""
    material = find_view_material()
    if material is not None:
        return material
    material = node_material(VIEW_MATERIAL)
    material[VIEW_KEY] = True
    tree = material.node_tree
    front = tree.nodes.new("ShaderNodeVertexColor")
    front.layer_name = FRONT
    front.location = (0, 0)
    emission_view(tree, front.outputs["Color"])
    return material


def node_material(name):
    """A new material named `name` with an empty node tree."""
    material = bpy.data.materials.new(name)
    if material.node_tree is None:  # Blender < 5.0 (5.0 warns on any use of use_nodes)
        material.use_nodes = True
    material.node_tree.nodes.clear()
    return material


def emission_view(tree, front):
    """Emit colour socket `front` on front faces and the `Radiosity Back` attribute on back faces
    (the nodes after `front`'s own, laid out from x = 0 to the right)."""
    back = tree.nodes.new("ShaderNodeVertexColor")
    back.layer_name = BACK
    geometry = tree.nodes.new("ShaderNodeNewGeometry")
    mix = tree.nodes.new("ShaderNodeMix")
    mix.data_type = "RGBA"
    emission = tree.nodes.new("ShaderNodeEmission")
    emission.inputs["Strength"].default_value = 1.0
    output = tree.nodes.new("ShaderNodeOutputMaterial")
    links = tree.links
    links.new(geometry.outputs["Backfacing"], _socket(mix.inputs, "Factor_Float"))
    links.new(front, _socket(mix.inputs, "A_Color"))
    links.new(back.outputs["Color"], _socket(mix.inputs, "B_Color"))
    links.new(_socket(mix.outputs, "Result_Color"), emission.inputs["Color"])
    links.new(emission.outputs["Emission"], output.inputs["Surface"])
    layout = ((geometry, 0, 300), (back, 0, -300), (mix, 300, 0), (emission, 500, 0), (output, 700, 0))
    for node, x, y in layout:
        node.location = (x, y)


def _socket(sockets, identifier):
    return next(s for s in sockets if s.identifier == identifier)


def has_results():
    return any(state.saved(obj) is not None or state.is_twin(obj) for obj in bpy.data.objects)


def brightest():
    """The largest radiance value (any channel, front or back) written on any result mesh, 0 if none."""
    top = 0.0
    for obj in bpy.data.objects:
        if obj.type != "MESH" or not _holds_results(obj):
            continue
        for name in (FRONT, BACK):
            if name in obj.data.color_attributes:
                top = max(top, float(adapter.read_color_attribute(obj.data, name)[:, :3].max(initial=0.0)))
    return top


# --------------------------------------------------------------------------- material view
def apply_view(obj, material):
    """Show `material` on every slot of `obj` through object-level overrides (saved first).

    Each slot's link and its object-level material (read with the link switched to 'OBJECT',
    also for 'DATA' slots, whose hidden object-level material is then restored as it was) are
    saved; the replaced materials are held by reference (`state.hold_materials`), so none of them
    drops to zero users.
    """
    record = state.saved(obj) or {}
    if "slots" in record:
        return
    added = len(obj.material_slots) == 0
    if added:
        obj.data.materials.append(None)
    links, replaced = [], []
    for slot in obj.material_slots:
        links.append(slot.link)
        slot.link = "OBJECT"
        replaced.append(slot.material)
    state.hold_materials(obj, replaced)
    for slot in obj.material_slots:
        slot.material = material
    record.update(slots=links, added_slot=added)
    state.save(obj, record)


def remove_view(obj):
    """Undo `apply_view`: object-level materials and slot links as they were."""
    record = state.saved(obj)
    if not record or "slots" not in record:
        return
    links = record["slots"]
    for slot, link, material in zip(obj.material_slots, links, state.held_materials(obj, len(links))):
        slot.link = "OBJECT"
        slot.material = material
        slot.link = link
    if record["added_slot"]:
        # the mesh had no materials; clear() also shrinks the object's slots (pop() does not)
        obj.data.materials.clear()
    state.release_materials(obj)
    del record["slots"], record["added_slot"]
    state.save(obj, record)


def show(mode):
    """Display results ('RESULT') or the original materials ('ORIGINAL') on all result meshes."""
    holders = [obj for obj in bpy.data.objects if _holds_results(obj)]
    if not holders:
        return  # nothing to show (and no view material made for nothing)
    material = view_material() if mode == "RESULT" else None
    for obj in holders:
        if material is not None:
            apply_view(obj, own_view(obj) or material)
        else:
            remove_view(obj)


def own_view(obj):
    """The result mesh's own view material (a lightmap's, see `set_own_view`), or None."""
    name = (state.saved(obj) or {}).get("view")
    material = bpy.data.materials.get(name) if name else None
    return material if material is not None and material.get(LIGHTMAP_KEY) else None


def set_own_view(obj, material):
    """Show `material` (a lightmap view) on result mesh `obj` instead of the shared view."""
    remove_view(obj)
    record = state.saved(obj) or {}
    record["view"] = material.name
    state.save(obj, record)
    apply_view(obj, material)


def _holds_results(obj):
    record = state.saved(obj)
    return state.is_twin(obj) or (record is not None and "attributes" in record)


# --------------------------------------------------------------------------- write
def write(scene, view_layer, depsgraph, collected, radiance):
    """Replace previous results with new ones.

    Parameters
    ----------
    scene, view_layer, depsgraph
    collected : Collected
    radiance : dict
        Target name -> (front (N, 3), back (N, 3) or None), see `solve.vertex_radiance`.

    Raises
    ------
    ResultError
        If a target object vanished or its geometry no longer matches.
    """
    _check_targets(collected)
    clear(scene)
    # clearing shows the originals again: evaluate them afresh (a hidden metaball has no mesh)
    depsgraph = bpy.context.evaluated_depsgraph_get()
    material = view_material()
    for name, target in collected.targets.items():
        obj = bpy.data.objects[name]
        holder = _make_twin(scene, view_layer, depsgraph, obj) if target.twin else obj
        front, back = radiance[name]
        write_attributes(holder, front, back)
        apply_view(holder, material)


def _check_targets(collected):
    for name, target in collected.targets.items():
        obj = bpy.data.objects.get(name)
        if obj is None:
            raise ResultError(f"object {name!r} was removed while solving")
        if target.twin:
            continue
        if len(obj.data.vertices) != target.n_vertices:
            raise ResultError(f"object {name!r} changed while solving: results not written")
        mesh = obj.data
        ours = "attributes" in (state.saved(obj) or {})
        if not ours and (FRONT in mesh.attributes or BACK in mesh.attributes):
            # checked before anything is cleared or written, so the scene stays as it was
            raise ResultError(f"mesh {mesh.name!r} of {name!r} already has an attribute named {FRONT!r}")


def _make_twin(scene, view_layer, depsgraph, obj):
    """A mesh object with `obj`'s evaluated geometry and transform; hides `obj` (saved first)."""
    return add_twin(scene, view_layer, obj, bpy.data.meshes.new_from_object(obj.evaluated_get(depsgraph)))


def add_twin(scene, view_layer, obj, mesh):
    """A mesh object showing `mesh` in `obj`'s place (its transform, in the `Radiosity`
    collection); hides `obj`, its visibility saved first (once: a second twin keeps the first
    saved state)."""
    twin = bpy.data.objects.new(f"{obj.name} radiosity", mesh)
    twin.matrix_world = obj.matrix_world.copy()
    twin[state.TWIN_KEY] = obj.name
    _collection(scene).objects.link(twin)
    record = state.saved(obj) or {}
    if "hide_render" not in record:
        hidden = _hidden(obj, view_layer)
        record.update(hide_render=obj.hide_render, hide_viewport=obj.hide_viewport, hidden=hidden)
        state.save(obj, record)
    obj.hide_render = True
    _hide(obj, view_layer, True)
    return twin


def remove_twins(name):
    """Remove the twins of object `name` (and their meshes, once unused)."""
    for twin in [obj for obj in bpy.data.objects if obj.get(state.TWIN_KEY) == name]:
        mesh = twin.data
        bpy.data.objects.remove(twin)
        if mesh.users == 0:
            bpy.data.meshes.remove(mesh)


def holder(name):
    """The object that shows the results of object `name`: its twin if it has one, else itself."""
    twins = [obj for obj in bpy.data.objects if obj.get(state.TWIN_KEY) == name]
    return twins[0] if twins else bpy.data.objects.get(name)


def _collection(scene):
    """The collection holding twins (created once per scene, name kept on the scene)."""
    name = scene.get(COLLECTION_KEY)
    collection = bpy.data.collections.get(name) if name else None
    if collection is None:
        collection = bpy.data.collections.new(COLLECTION)
        scene.collection.children.link(collection)
        scene[COLLECTION_KEY] = collection.name
    return collection


def _hidden(obj, view_layer):
    try:
        return obj.hide_get(view_layer=view_layer)
    except RuntimeError:
        return False


def _hide(obj, view_layer, value):
    try:
        obj.hide_set(value, view_layer=view_layer)
    except RuntimeError:
        pass


def write_attributes(obj, front, back):
    """Write the radiance attributes, saving the mesh's attribute choices first."""
    mesh = obj.data
    record = state.saved(obj) or {}
    if "attributes" not in record:
        colours = mesh.color_attributes
        active = mesh.attributes.active
        record["attributes"] = dict(
            active=active.name if active else "",
            active_color=colours.active_color_name,
            default_color=colours.default_color_name,
        )
        state.save(obj, record)
    adapter.write_color_attribute(mesh, FRONT, front)
    if back is not None:
        adapter.write_color_attribute(mesh, BACK, back)
    # Blender makes a new colour attribute active when there was none (and only then): put
    # the user's choices back, so results never change them and a second run equals the first
    _set_choices(mesh, record["attributes"])


# --------------------------------------------------------------------------- clear
def clear(scene):
    """Remove all results and restore the objects exactly; returns how many were restored."""
    for twin in [obj for obj in bpy.data.objects if state.is_twin(obj)]:
        mesh = twin.data
        bpy.data.objects.remove(twin)
        if mesh.users == 0:
            bpy.data.meshes.remove(mesh)
    restored = 0
    for obj in bpy.data.objects:
        record = state.saved(obj)
        if record is None:
            continue
        remove_view(obj)
        if "uv" in record:
            _restore_uv(obj.data, record["uv"])
        if "attributes" in record:
            _restore_attributes(obj.data, record["attributes"])
        if "hide_render" in record:
            obj.hide_render = record["hide_render"]
            obj.hide_viewport = record["hide_viewport"]
            _hide(obj, bpy.context.view_layer, record["hidden"])
        state.forget(obj)
        restored += 1
    _remove_collection(scene)
    material = find_view_material()
    if material is not None and material.users == 0:
        bpy.data.materials.remove(material)
    for material in [m for m in bpy.data.materials if m.get(LIGHTMAP_KEY)]:
        if material.users == 0:
            bpy.data.materials.remove(material)
    for image in [i for i in bpy.data.images if i.get(LIGHTMAP_KEY)]:
        if image.users == 0:
            bpy.data.images.remove(image)
    return restored


def save_uv(obj, name):
    """Record that UV map `name` was added to `obj`'s own mesh, with the mesh's UV choices
    before (active and active-render map names), so `clear` removes it and restores them."""
    mesh = obj.data
    record = state.saved(obj) or {}
    if "uv" not in record:
        layers = mesh.uv_layers
        active = layers.active.name if layers.active else ""
        render = next((layer.name for layer in layers if layer.active_render), "")
        record["uv"] = dict(name=name, active=active, render=render)
        state.save(obj, record)


def _restore_uv(mesh, saved):
    layer = mesh.uv_layers.get(saved["name"])
    if layer is not None:
        mesh.uv_layers.remove(layer)
    if saved["active"] in mesh.uv_layers:
        mesh.uv_layers.active = mesh.uv_layers[saved["active"]]
    if saved["render"] in mesh.uv_layers:
        mesh.uv_layers[saved["render"]].active_render = True


def _restore_attributes(mesh, saved):
    for name in (FRONT, BACK):
        attribute = mesh.color_attributes.get(name)
        if attribute is not None:
            mesh.color_attributes.remove(attribute)
    _set_choices(mesh, saved)


def _set_choices(mesh, saved):
    """Active / default colour attribute and active attribute as in `saved` ("" = none); a name
    that no longer exists (the user removed it meanwhile) is left alone."""
    colours = mesh.color_attributes
    for key, prop in (("active_color", "active_color_name"), ("default_color", "default_color_name")):
        name = saved[key]
        if name == "" or name in colours:
            setattr(colours, prop, name)
    name = saved["active"]
    if name == "":
        mesh.attributes.active = None
    elif name in mesh.attributes:
        mesh.attributes.active = mesh.attributes[name]


def _remove_collection(scene):
    for sc in bpy.data.scenes:
        name = sc.get(COLLECTION_KEY)
        if name is None:
            continue
        collection = bpy.data.collections.get(name)
        if collection is not None and len(collection.all_objects) == 0:
            bpy.data.collections.remove(collection)
        del sc[COLLECTION_KEY]
