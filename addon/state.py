"""Bookkeeping kept on Blender objects so results can be cleared exactly.

Stored as underscore custom properties (hidden from the Custom Properties panel, saved in the
.blend, and readable without the add-on registered):

- `obj["_curved_radiosity"]`: on an object that holds results (or whose twin does): its saved
  visibility, material slot links and object-level materials, and colour attribute choices;
- `obj["_curved_radiosity_twin_of"]`: on a mesh twin, the name of the object it stands for.
"""

import json

import bpy

STATE_KEY = "_curved_radiosity"
TWIN_KEY = "_curved_radiosity_twin_of"


def saved(obj):
    """The saved state of `obj` as a dict, or None."""
    text = obj.get(STATE_KEY)
    return json.loads(text) if text else None


def save(obj, state):
    obj[STATE_KEY] = json.dumps(state)


def forget(obj):
    if STATE_KEY in obj:
        del obj[STATE_KEY]


def is_twin(obj):
    return TWIN_KEY in obj


def original_hide_render(obj):
    """`hide_render` as it was before results hid the object."""
    state = saved(obj)
    return state["hide_render"] if state and "hide_render" in state else obj.hide_render


def original_material(obj, index):
    """The material an object's slot `index` had before the result view replaced it."""
    state = saved(obj)
    if state is None or "slots" not in state:
        slot = obj.material_slots[index] if index < len(obj.material_slots) else None
        return slot.material if slot is not None else None
    if index >= len(state["slots"]):
        return None
    link, object_material = state["slots"][index]
    if link == "OBJECT":
        return bpy.data.materials.get(object_material) if object_material else None
    data_materials = obj.data.materials
    return data_materials[index] if index < len(data_materials) else None
