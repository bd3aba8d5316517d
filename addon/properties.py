"""Add-on settings: per scene (`Scene.curved_radiosity`) and per object."""

import bpy
from bpy.props import (
    BoolProperty,
    EnumProperty,
    FloatProperty,
    IntProperty,
    IntVectorProperty,
    PointerProperty,
)


class CurvedRadiositySettings(bpy.types.PropertyGroup):
    quality: EnumProperty(
        name="Quality",
        description="Solver tolerance preset",
        items=[
            ("DRAFT", "Draft", "Relative tolerance 1e-2"),
            ("NORMAL", "Normal", "Relative tolerance 1e-3"),
            ("HIGH", "High", "Relative tolerance 1e-4"),
            ("CUSTOM", "Custom", "Set the tolerance yourself"),
        ],
        default="NORMAL",
    )
    tolerance: FloatProperty(
        name="Tolerance",
        description="Relative tolerance of form factors and of the radiosity iteration",
        default=1e-3,
        min=1e-8,
        max=0.5,
        precision=6,
    )
    occlusion: BoolProperty(name="Occlusion", description="Surfaces cast shadows on each other", default=True)
    max_bounces: IntProperty(
        name="Max Bounces",
        description="Stop after this many light bounces (0: iterate until converged)",
        default=0,
        min=0,
    )
    last_report: bpy.props.StringProperty(name="Last Report", default="")


OBJECT_PROPERTIES = {
    "curved_radiosity_include": BoolProperty(
        name="Include in Radiosity",
        description="Take part in the radiosity solution (as surface, emitter or light)",
        default=True,
    ),
    "curved_radiosity_patches": IntVectorProperty(
        name="Patches",
        description="Patch grid (u, v) for this object's surfaces; 0 = automatic",
        size=2,
        default=(0, 0),
        min=0,
        soft_max=64,
    ),
}


def register():
    bpy.utils.register_class(CurvedRadiositySettings)
    bpy.types.Scene.curved_radiosity = PointerProperty(type=CurvedRadiositySettings)
    for name, prop in OBJECT_PROPERTIES.items():
        setattr(bpy.types.Object, name, prop)


def unregister():
    for name in OBJECT_PROPERTIES:
        delattr(bpy.types.Object, name)
    del bpy.types.Scene.curved_radiosity
    bpy.utils.unregister_class(CurvedRadiositySettings)
