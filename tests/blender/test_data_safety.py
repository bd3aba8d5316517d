"""No order of compute, show, clear, save and reopen loses or changes user data.

The scene holds what has gone wrong before: a material whose only user is an object-level
(link='OBJECT') slot, which dropped to zero users while results were shown and was then not saved
in the .blend; a material-less mesh whose active colour attribute a second compute emptied; a
DATA slot (whose hidden object-level material must stay empty); a UV sphere with a painted
corner attribute; a NURBS surface and a modified mesh (twins). `snapshot()` compares objects,
slots on both link levels, every mesh attribute with its data and the attribute choices, material
user counts and collections exactly.
"""

import numpy as np
import pytest
from blender_helpers import bpy, material, snapshot

pytestmark = pytest.mark.blender


def paint(mesh, name, data_type, domain, seed):
    """A colour attribute filled with seeded random colours."""
    attribute = mesh.color_attributes.new(name, data_type, domain)
    values = np.random.default_rng(seed).random(len(attribute.data) * 4).astype(np.float32)
    attribute.data.foreach_set("color", values)
    return attribute


def build_scene():
    bpy.ops.mesh.primitive_plane_add(size=6)
    floor = bpy.context.active_object
    floor.name = "Floor"  # material-less, painted, its own attribute choices
    paint(floor.data, "Dirt", "BYTE_COLOR", "CORNER", 1)
    paint(floor.data, "Wet", "FLOAT_COLOR", "POINT", 2)
    floor.data.color_attributes.active_color_name = "Dirt"
    floor.data.color_attributes.default_color_name = "Wet"

    bpy.ops.mesh.primitive_plane_add(size=2, location=(0, 0, 3), rotation=(np.pi, 0, 0))
    bpy.context.active_object.name = "Bare"  # material-less, no colour attribute at all

    bpy.ops.mesh.primitive_cube_add(location=(2, 0, 0.5), scale=(0.5, 0.5, 0.5))
    box = bpy.context.active_object
    box.name = "Box"
    box.data.materials.append(material("BoxData", base=(0.2, 0.8, 0.2)))
    box.material_slots[0].link = "OBJECT"
    box.material_slots[0].material = material("BoxOwn", base=(0.8, 0.2, 0.2))  # its only user

    bpy.ops.mesh.primitive_uv_sphere_add(segments=16, ring_count=8, radius=0.5, location=(-2, 0, 1))
    ball = bpy.context.active_object
    ball.name = "Ball"
    ball.data.materials.append(material("BallData", base=(0.7, 0.7, 0.2)))  # a DATA slot
    paint(ball.data, "Paint", "BYTE_COLOR", "CORNER", 3)

    bpy.ops.mesh.primitive_cube_add(location=(0, 2, 0.5), scale=(0.4, 0.4, 0.4))
    bevelled = bpy.context.active_object
    bevelled.name = "Bevelled"
    bevelled.modifiers.new("Bevel", "BEVEL")
    bevelled.data.materials.append(None)
    bevelled.material_slots[0].link = "OBJECT"
    bevelled.material_slots[0].material = material("BevelOwn")  # only user, on an object with a twin

    bpy.ops.surface.primitive_nurbs_surface_surface_add(radius=0.5, location=(0, -2, 1))
    shell = bpy.context.active_object
    shell.name = "Shell"
    shell.data.materials.append(material("ShellData", base=(0.3, 0.3, 0.9)))

    bpy.ops.object.light_add(type="AREA", location=(0, 0, 4))
    bpy.context.active_object.data.energy = 200.0
    bpy.ops.object.light_add(type="POINT", location=(1, 1, 3))
    bpy.context.active_object.data.energy = 300.0
    bpy.context.scene.curved_radiosity.quality = "DRAFT"
    bpy.context.view_layer.update()


def reopen(path):
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    bpy.ops.wm.open_mainfile(filepath=str(path))


def compute():
    assert bpy.ops.curved_radiosity.compute() == {"FINISHED"}


ORDERS = {
    "compute-save-reopen-clear": "c r x",
    "compute-compute-clear": "c c x",
    "compute-save-reopen-compute-clear": "c r c x",
    "compute-original-save-reopen-clear": "c o r x",
    "compute-save-reopen-original-result-save-reopen-clear": "c r o v r x",
    "compute-clear-compute-save-reopen-clear": "c x c r x",
}


@pytest.mark.parametrize("order", ORDERS.values(), ids=ORDERS.keys())
def test_no_order_loses_or_changes_user_data(addon, tmp_path, order):
    """After any sequence ending in Clear, the scene equals the one before the first compute."""
    build_scene()
    before = snapshot()
    saved = tmp_path / "before.blend"
    reopen(saved)
    assert snapshot() == before  # the snapshot itself survives a save and reopen
    steps = {
        "c": compute,
        "x": lambda: bpy.ops.curved_radiosity.clear(),
        "o": lambda: bpy.ops.curved_radiosity.show(mode="ORIGINAL"),
        "v": lambda: bpy.ops.curved_radiosity.show(mode="RESULT"),
        "r": lambda: reopen(tmp_path / "during.blend"),
    }
    for step in order.split():
        steps[step]()
    assert snapshot() == before


def test_object_material_survives_a_save_while_results_are_shown(addon, tmp_path):
    """The object-level material keeps a user while the view material replaces it, so the saved
    file still holds it and Clear puts it back in its slot (this was an empty slot before)."""
    build_scene()
    compute()
    assert bpy.data.objects["Box"].material_slots[0].material.name == "Radiosity View"
    assert bpy.data.materials["BoxOwn"].users >= 1
    reopen(tmp_path / "lit.blend")
    assert "BoxOwn" in bpy.data.materials and "BevelOwn" in bpy.data.materials
    bpy.ops.curved_radiosity.clear()
    assert bpy.data.objects["Box"].material_slots[0].material.name == "BoxOwn"
    assert bpy.data.objects["Bevelled"].material_slots[0].material.name == "BevelOwn"


def test_renamed_material_is_restored(addon):
    """Slots are restored by reference, not by name: a material renamed meanwhile comes back."""
    build_scene()
    compute()
    bpy.data.materials["BoxOwn"].name = "Brick"
    bpy.ops.curved_radiosity.clear()
    assert bpy.data.objects["Box"].material_slots[0].material.name == "Brick"


def test_compute_is_idempotent(addon, tmp_path):
    """A second compute leaves the scene exactly as the first did (attribute data included), also
    after a save and reopen (the materials under the view are read back from the held ones), and
    results never change the user's active or default colour attribute."""
    build_scene()
    floor = bpy.data.objects["Floor"].data
    choices = (floor.color_attributes.active_color_name, floor.color_attributes.default_color_name)
    compute()
    once = snapshot()
    assert (floor.color_attributes.active_color_name, floor.color_attributes.default_color_name) == choices
    bare = bpy.data.objects["Bare"].data.color_attributes
    assert (bare.active_color_name, bare.default_color_name) == ("", "")
    compute()
    assert snapshot() == once
    reopen(tmp_path / "lit.blend")
    compute()
    assert results_and_user_data(snapshot()) == results_and_user_data(once)


def results_and_user_data(state):
    """A snapshot without the twins' copies of Blender's evaluated attributes: re-evaluating the
    bevel modifier after a reload moves its UVs by ~3e-8 (Blender's float rounding, not ours);
    the twins' radiance attributes and everything of the user's are kept."""
    twins = {o["data"] for o in state["objects"].values() if addon_key(o)}
    meshes = {}
    for name, mesh in state["meshes"].items():
        if name in twins:
            attributes = {k: v for k, v in mesh["attributes"].items() if k.startswith("Radiosity")}
            mesh = dict(mesh, attributes=attributes)
        meshes[name] = mesh
    return dict(state, meshes=meshes)


def addon_key(obj_state):
    return "_curved_radiosity_twin_of" in obj_state["props"]


def test_users_own_material_named_like_the_view_is_left_alone(addon):
    """A user material called "Radiosity View" is neither used as the view nor removed by Clear."""
    build_scene()
    own = material("Radiosity View", base=(0.1, 0.2, 0.3))
    bpy.data.objects["Floor"].data.materials.append(own)
    before = snapshot()
    compute()
    view = bpy.data.objects["Floor"].material_slots[0].material
    assert view != own and view.name != "Radiosity View"
    bpy.ops.curved_radiosity.clear()
    assert snapshot() == before


def test_show_without_results_changes_nothing(addon):
    """'Show result' in a scene without results adds no (zero-user) view material."""
    build_scene()
    before = snapshot()
    bpy.ops.curved_radiosity.show(mode="RESULT")
    bpy.ops.curved_radiosity.show(mode="ORIGINAL")
    assert snapshot() == before
