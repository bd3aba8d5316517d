"""Bookkeeping kept on Blender objects so results can be cleared exactly.

Stored as underscore custom properties (hidden from the Custom Properties panel, saved in the
.blend, and readable without the add-on registered):

- `obj["_curved_radiosity"]`: on an object that holds results (or whose twin does): its saved
  visibility, material slot links and colour attribute choices (JSON text);
- `obj["_curved_radiosity_held"]`: the object-level materials the result view replaced, as ID
  pointers (a group keyed by slot index). An ID pointer in a custom property counts as a user, so
  a material whose only user was its object slot is not lost when the file is saved while the
  results are shown (Blender drops zero-user data on save), and it survives renames;
- `obj["_curved_radiosity_twin_of"]`: on a mesh twin, the name of the object it stands for.
"""

import json

STATE_KEY = "_curved_radiosity"
HELD_KEY = "_curved_radiosity_held"
TWIN_KEY = "_curved_radiosity_twin_of"


def saved(obj):
    """The saved state of `obj` as a dict, or None."""
    text = obj.get(STATE_KEY)
    return json.loads(text) if text else None


def save(obj, state):
    obj[STATE_KEY] = json.dumps(state)


def forget(obj):
    """Drop all bookkeeping of `obj` (its saved state and held materials)."""
    for key in (STATE_KEY, HELD_KEY):
        if key in obj:
            del obj[key]


def hold_materials(obj, materials):
    """Keep a user on each of `materials` (one per slot, None for an empty slot) on `obj`."""
    obj[HELD_KEY] = {str(index): m for index, m in enumerate(materials) if m is not None}


def held_materials(obj, count):
    """The materials kept by `hold_materials`, a list of `count` (None where a slot was empty)."""
    group = obj.get(HELD_KEY)
    return [group.get(str(index)) if group is not None else None for index in range(count)]


def release_materials(obj):
    if HELD_KEY in obj:
        del obj[HELD_KEY]


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
    if state["slots"][index] == "OBJECT":
        return held_materials(obj, index + 1)[index]
    data_materials = obj.data.materials
    return data_materials[index] if index < len(data_materials) else None
