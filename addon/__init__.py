"""Curved-patch radiosity for Blender: spheres, NURBS and polygons lit without tessellating curves.

The numpy-only solver is the `core` subpackage (in the repository a symlink to ../core, copied
into the extension by scripts/build_extension.py); everything bpy lives in the modules here:
`adapter` (numpy <-> bpy buffers), `collect`/`objects`/`materials`/`lights` (scene -> core),
`solve` (core), `results` (core -> scene), `outputs` (lightmaps and refined twins in the scene;
their numpy side: `bake`, `sampling`, `texels`, `adaptive_lightmap`, `refine`),
`pipeline`/`jobs`/`operators`/`ui` (running it), `console` (progress on a console) and
`headless` (command line).
"""

import bpy

from . import operators, properties, ui

CLASSES = operators.CLASSES + ui.CLASSES


def register():
    properties.register()
    for cls in CLASSES:
        bpy.utils.register_class(cls)


def unregister():
    for cls in reversed(CLASSES):
        bpy.utils.unregister_class(cls)
    properties.unregister()
