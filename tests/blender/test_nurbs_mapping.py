"""NURBS surface objects: one core NurbsSurface per spline, sampled where Blender tessellates.

The (u, v) of each item sample must land on the vertex of Blender's own evaluated mesh with the
same index (the tessellation rule of addon/tessellation.py), in world space, so results can be
written onto a mesh twin made from that evaluation.
"""

import numpy as np
import pytest
from blender_helpers import bpy, collect, evaluated_world_positions

pytestmark = pytest.mark.blender


def add(kind, **kwargs):
    getattr(bpy.ops.surface, f"primitive_nurbs_surface_{kind}_add")(**kwargs)
    return bpy.context.active_object


def max_error(addon, obj):
    """Largest |P(u, v) - Blender vertex| over the object's samples, relative to its size."""
    collected = collect(addon)
    items = [i for i in collected.surfaces if i.target == obj.name]
    world = evaluated_world_positions(obj)
    assert collected.targets[obj.name].n_vertices == len(world)
    assert collected.targets[obj.name].twin
    covered = np.concatenate([i.vertices for i in items])
    assert np.array_equal(np.sort(covered), np.arange(len(world)))
    errors = [
        np.abs(i.surface.evaluate(i.params[:, 0], i.params[:, 1])[0] - world[i.vertices]).max() for i in items
    ]
    return max(errors) / np.abs(world).max(), items


@pytest.mark.parametrize("kind", ["surface", "sphere", "cylinder", "torus"])
def test_primitives_in_world_space(addon, kind):
    """Moved, rotated, non-uniformly scaled primitives: samples hit Blender's vertices (float32 level)."""
    obj = add(kind, location=(2.0, -1.0, 0.5), rotation=(0.3, -0.2, 0.9))
    obj.scale = (1.5, 0.5, 2.0)
    bpy.context.view_layer.update()
    error, items = max_error(addon, obj)
    assert error < 1e-5
    assert [type(i.surface).__name__ for i in items] == ["NurbsSurface"]


def test_several_splines_follow_each_other(addon):
    """A joined object (plain patch + sphere): spline vertex blocks in spline order."""
    first = add("surface")
    add("sphere", location=(4.0, 0.0, 0.0))
    bpy.ops.object.select_all(action="SELECT")
    bpy.context.view_layer.objects.active = first
    bpy.ops.object.join()
    error, items = max_error(addon, first)
    assert error < 1e-5 and len(items) == 2
    assert items[1].vertices[0] == len(items[0].vertices)


def test_resolution_and_weights(addon):
    """Edited resolution, order and weights still map exactly."""
    obj = add("sphere")
    (spline,) = obj.data.splines
    spline.resolution_u, spline.resolution_v = 3, 7
    co = np.empty(len(spline.points) * 4, np.float32)
    spline.points.foreach_get("co", co)
    co = co.reshape(-1, 4)
    co[:, 3] = np.linspace(0.5, 2.0, len(co))
    spline.points.foreach_set("co", co.ravel())
    obj.data.update_tag()
    error, _ = max_error(addon, obj)
    assert error < 1e-5


def test_degenerate_surface_is_reported_by_name(addon):
    """All control points at one spot: the scene is refused, naming object and spline."""
    obj = add("surface")
    obj.name = "Crumpled"
    (spline,) = obj.data.splines
    spline.points.foreach_set("co", np.tile([0.0, 0.0, 0.0, 1.0], len(spline.points)).astype(np.float32))
    with pytest.raises(addon.collect.CollectError, match="'Crumpled', spline 0"):
        collect(addon)


def test_tessellation_parameters(addon):
    """Blender's float32 running sum, clipped to the domain; cyclic directions skip the seam."""
    u = addon.tessellation.sample_parameters((0.0, 1.0), 4, 3, cyclic=False)
    assert u.size == 12 and u[0] == 0.0 and u[-1] == pytest.approx(1.0, abs=1e-6) and u[-1] <= 1.0
    v = addon.tessellation.sample_parameters((0.0, 2.0), 4, 2, cyclic=True)
    assert v.size == 8 and v[-1] == pytest.approx(2.0 * 7 / 8, abs=1e-6)
    gu, gv = addon.tessellation.grid_parameters(((0.0, 1.0), (0.0, 2.0)), (4, 4), (3, 2), (False, True))
    assert gu.size == 96 and gu[8] == u[1] and gv[9] == v[1]
