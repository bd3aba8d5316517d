"""Mesh objects become one `core.PolygonMesh` each (per material), sampled at their face corners.

Checked against Blender itself: the mesh's vertices are the object's world-space vertices, its
face areas are Blender's `polygon.area` (times the scale), a mirrored object keeps Blender's
normals as fronts, zero-area polygons are reported by index, and a solve through the add-on
gives the same vertex radiance as the former per-polygon mapping (`objects.POLYGON_MESHES`).
"""

import numpy as np
import pytest
from blender_helpers import bpy, collect, items_of, polygon_mesh, world_positions

pytestmark = pytest.mark.blender


def solved_with(addon, switch, value):
    """The add-on's solution (tol 1e-3) of the current scene with `addon.objects.<switch>` (a
    mapping switch whose default is True) set to `value`."""
    setattr(addon.objects, switch, value)
    try:
        return addon.solve.solve(collect(addon), addon.solve.Settings(tol=1e-3))
    finally:
        setattr(addon.objects, switch, True)


def test_cube_is_one_polygon_mesh_with_blender_areas(addon):
    bpy.ops.mesh.primitive_cube_add(location=(5, -1, 2), rotation=(0.3, 0.5, 0.7))
    obj = bpy.context.active_object
    obj.scale = (1.0, 3.0, 1.5)
    bpy.context.view_layer.update()
    (item,) = items_of(addon, obj)
    mesh = item.surface
    assert type(mesh).__name__ == "PolygonMesh" and mesh.face_count == 6
    assert len(mesh.piece_face) == 6  # planar quads stay whole
    np.testing.assert_allclose(mesh.vertices, world_positions(obj), atol=1e-5)
    assert mesh.area() == pytest.approx(4 * 2 * (3 + 1.5 + 4.5), rel=1e-6)
    # samples: every face corner once, at its own vertex
    assert len(item.vertices) == 24 and set(item.vertices.tolist()) == set(range(8))


def test_mirrored_mesh_keeps_blender_fronts(addon):
    bpy.ops.mesh.primitive_cube_add()
    obj = bpy.context.active_object
    obj.scale = (-1.0, 1.0, 1.0)
    bpy.context.view_layer.update()
    (item,) = items_of(addon, obj)
    centres = item.surface.piece_corners.mean(1)
    normal = np.cross(
        item.surface.piece_corners[:, 2] - item.surface.piece_corners[:, 0],
        item.surface.piece_corners[:, 3] - item.surface.piece_corners[:, 1],
    )
    assert np.all(np.einsum("ki,ki->k", normal, centres) > 0.0)  # outward from the centre


def test_materials_split_the_mesh_and_degenerate_polygons_are_named(addon):
    verts = [(0, 0, 0), (1, 0, 0), (2, 0, 0), (3, 0, 0), (0, 1, 0), (1, 1, 0), (2, 1, 0)]
    obj = polygon_mesh("Strip", verts, [(0, 1, 5, 4), (0, 1, 2, 3), (1, 2, 6, 5)])
    for name in ("A", "B"):
        obj.data.materials.append(bpy.data.materials.new(name))
    obj.data.polygons[2].material_index = 1
    collected = collect(addon)
    items = [i for i in collected.surfaces if i.target == obj.name]
    # (two items; material A's face with no area is left out of its merged mesh)
    assert sorted(i.surface.face_count for i in items) == [1, 1]
    assert any("'Strip': skipped 1 polygon(s) with no area: 1" in w for w in collected.warnings)


def test_solve_matches_the_per_polygon_mapping(addon):
    """A cube on a floor under an area light: vertex radiance through the add-on is the same with
    PolygonMesh objects as with the former per-polygon Quads (to the solve's tolerance)."""
    bpy.ops.mesh.primitive_plane_add(size=6)
    bpy.ops.mesh.primitive_cube_add(size=1, location=(0, 0, 0.5))
    bpy.ops.object.light_add(type="AREA", location=(0, 0, 3))
    bpy.context.active_object.data.energy = 200
    bpy.context.view_layer.update()
    results = [solved_with(addon, "POLYGON_MESHES", mapping).radiance for mapping in (True, False)]
    for name in results[0]:
        a, b = results[0][name][0], results[1][name][0]
        assert a.max() > 0.0
        np.testing.assert_allclose(a, b, rtol=2e-2, atol=2e-2 * b.max())


def test_a_subdivided_plane_is_lit_as_one_face(addon):
    """A 24 x 24 grid under an area light becomes one quad (automatic patches) and is sampled once
    per vertex; its vertex radiance is that of its 576 faces lit one by one (the floor sees
    nothing else, so both are its direct light, to the solve's tolerance). A patch grid set on
    the object keeps its faces, and a subdivided cube becomes its six sides."""
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=25, y_subdivisions=25, size=6)
    floor = bpy.context.active_object
    bpy.ops.object.light_add(type="AREA", location=(0.5, -0.3, 2))
    bpy.context.active_object.data.energy = 200
    bpy.context.view_layer.update()
    (item,) = items_of(addon, floor)
    assert item.surface.face_count == 1 and item.surface.loop_totals[0] == 4
    assert np.array_equal(np.sort(item.vertices), np.arange(26 * 26))
    solutions = [solved_with(addon, "MERGE_COPLANAR", merge) for merge in (True, False)]
    (merged, few), (faces, many) = ((sol.radiance[floor.name][0], sol.stats["elements"]) for sol in solutions)
    assert few < many / 10
    assert merged.min() > 0.0
    np.testing.assert_allclose(merged, faces, rtol=3e-3)
    floor.curved_radiosity_patches = (1, 1)
    (item,) = items_of(addon, floor)
    assert item.surface.face_count == 25 * 25
    bpy.ops.mesh.primitive_cube_add(location=(0, 0, 3))
    cube = bpy.context.active_object
    bpy.ops.object.modifier_add(type="SUBSURF")
    cube.modifiers[-1].levels = 2
    cube.modifiers[-1].subdivision_type = "SIMPLE"
    bpy.context.view_layer.update()
    (item,) = items_of(addon, cube)
    assert item.surface.face_count == 6 and np.all(item.surface.loop_totals == 4)
