"""Panels: the 3D View sidebar (N panel, tab "Radiosity") and Render properties."""

import bpy

from . import results


def draw_settings(layout, context):
    """The shared panel body."""
    props = context.scene.curved_radiosity
    col = layout.column()
    col.prop(props, "quality")
    if props.quality == "CUSTOM":
        col.prop(props, "tolerance")
    col.prop(props, "occlusion")
    col.prop(props, "method")
    col.prop(props, "max_bounces")
    row = layout.row(align=True)
    row.operator("curved_radiosity.compute", icon="LIGHT_SUN").relight = False
    row.operator("curved_radiosity.compute", text="Relight", icon="FILE_REFRESH").relight = True
    if results.has_results():
        row = layout.row(align=True)
        row.operator("curved_radiosity.show", text="Result").mode = "RESULT"
        row.operator("curved_radiosity.show", text="Original").mode = "ORIGINAL"
        layout.operator("curved_radiosity.clear", icon="X")
    if props.last_report:
        layout.label(text=props.last_report)
    obj = context.object
    if obj is not None:
        box = layout.box()
        box.label(text=obj.name, icon="OBJECT_DATA")
        box.prop(obj, "curved_radiosity_include")
        box.prop(obj, "curved_radiosity_patches")
        box.prop(obj, "curved_radiosity_output")
        if obj.curved_radiosity_output == "LIGHTMAP":
            box.prop(obj, "curved_radiosity_lightmap_size")
            if obj.curved_radiosity_lightmap_size == 0:
                box.prop(obj, "curved_radiosity_texels_per_metre")
            box.prop(obj, "curved_radiosity_lightmap_tol")
            if obj.type == "MESH":
                box.prop_search(obj, "curved_radiosity_lightmap_uv", obj.data, "uv_layers")
            else:
                box.prop(obj, "curved_radiosity_lightmap_uv")
        elif obj.curved_radiosity_output == "REFINED":
            box.prop(obj, "curved_radiosity_refine_tol")
            box.prop(obj, "curved_radiosity_refine_min_edge")
            box.prop(obj, "curved_radiosity_refine_max_edge")


class VIEW3D_PT_curved_radiosity(bpy.types.Panel):  # noqa: N801 (Blender requires PREFIX_OT_name)
    bl_label = "Curved Radiosity"
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "Radiosity"

    def draw(self, context):
        draw_settings(self.layout, context)


class RENDER_PT_curved_radiosity(bpy.types.Panel):  # noqa: N801 (Blender requires PREFIX_OT_name)
    bl_label = "Curved Radiosity"
    bl_space_type = "PROPERTIES"
    bl_region_type = "WINDOW"
    bl_context = "render"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context):
        draw_settings(self.layout, context)


CLASSES = (VIEW3D_PT_curved_radiosity, RENDER_PT_curved_radiosity)
