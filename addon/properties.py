"""Add-on settings: per scene (`Scene.curved_radiosity`) and per object."""

import bpy
from bpy.props import (
    BoolProperty,
    EnumProperty,
    FloatProperty,
    IntProperty,
    IntVectorProperty,
    PointerProperty,
    StringProperty,
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
    method: EnumProperty(
        name="Solver",
        description="How light is exchanged between patches",
        items=[
            (
                "AUTO",
                "Automatic",
                "Hierarchical when an object bakes a lightmap or a refined twin (their detail at contacts "
                "and seams needs its sub-patches), All Pairs otherwise",
            ),
            ("PAIRS", "All Pairs", "Every pair of patches (cost grows with the square of the patch count)"),
            (
                "HIERARCHICAL",
                "Hierarchical",
                "Links between groups of patches, and sub-patches where a surface rests on another and "
                "toward seams, so contact shadows and corners resolve finer than the patches (slower on "
                "meshes of many faces: one tree per face)",
            ),
        ],
        default="AUTO",
    )
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
    "curved_radiosity_output": EnumProperty(
        name="Output",
        description="How this object shows its radiosity",
        items=[
            ("VERTEX", "Vertex Colours", "The Radiosity colour attribute on the object's own vertices"),
            ("LIGHTMAP", "Lightmap", "Also bake a float image through a UV map (shows every shadow)"),
            ("REFINED", "Refined Twin", "A twin mesh refined where the radiosity varies"),
        ],
        default="VERTEX",
    ),
    "curved_radiosity_lightmap_size": IntProperty(
        name="Lightmap Size",
        description="Lightmap width and height in texels (0: from Texels per Metre)",
        default=0,
        min=0,
        max=8192,
    ),
    "curved_radiosity_texels_per_metre": FloatProperty(
        name="Texels per Metre",
        description="Lightmap resolution when the size is 0",
        default=32.0,
        min=0.01,
        soft_max=1024.0,
    ),
    "curved_radiosity_lightmap_uv": StringProperty(
        name="Lightmap UV Map",
        description="UV map to bake through (empty: generate a non-overlapping one with Lightmap Pack)",
        default="",
    ),
    "curved_radiosity_lightmap_tol": FloatProperty(
        name="Lightmap Tolerance",
        description="Interpolate texels where the radiance is within this fraction of linear "
        "(0: gather every texel)",
        default=0.01,
        min=0.0,
        max=1.0,
        precision=4,
    ),
    "curved_radiosity_refine_tol": FloatProperty(
        name="Refine Tolerance",
        description="Split an edge where its midpoint differs from the linear interpolation by more "
        "than this fraction",
        default=0.05,
        min=1e-4,
        max=1.0,
        precision=4,
    ),
    "curved_radiosity_refine_max_edge": FloatProperty(
        name="Maximum Edge",
        description="Split every edge longer than this, so that no shadow hides between the first "
        "samples (0: no limit)",
        default=1.0,
        min=0.0,
        subtype="DISTANCE",
        unit="LENGTH",
    ),
    "curved_radiosity_refine_min_edge": FloatProperty(
        name="Minimum Edge",
        description="Shortest edge a refinement split makes",
        default=0.02,
        min=1e-5,
        subtype="DISTANCE",
        unit="LENGTH",
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
