"""The former mapping (`objects.POLYGON_MESHES = False`, kept as the benchmarks' reference): meshes
that are not UV spheres become flat (or truly bilinear) quads in world coordinates. The default
mapping (one `core.PolygonMesh` per mesh) is tested in test_polygon_mesh.py."""

import numpy as np
import pytest
from blender_helpers import bpy, collect, items_of, polygon_mesh, world_positions

pytestmark = pytest.mark.blender


@pytest.fixture(autouse=True)
def per_polygon_mapping(addon):
    """Every test here checks the per-polygon mapping."""
    addon.objects.POLYGON_MESHES = False
    yield
    addon.objects.POLYGON_MESHES = True


def total_area(items):
    return sum(i.surface.area() for i in items)


def corner_points(item):
    """The item's sample points on its surface, shape (K, 3)."""
    return item.surface.evaluate(item.params[:, 0], item.params[:, 1])[0]


def test_cube_is_six_flat_quads_in_world_space(addon):
    """A moved, rotated, scaled cube: 6 flat quads, area 2 (2 2 + 2 6 + 2 3) x 4, corners on the vertices."""
    bpy.ops.mesh.primitive_cube_add(location=(5, -1, 2), rotation=(0.3, 0.5, 0.7))
    obj = bpy.context.active_object
    obj.scale = (1.0, 3.0, 1.5)
    bpy.context.view_layer.update()
    items = items_of(addon, obj)
    assert len(items) == 6 and all(type(i.surface).__name__ == "Quad" for i in items)
    assert all(i.surface.geometry.plane is not None for i in items)
    assert total_area(items) == pytest.approx(4 * 2 * (3 + 1.5 + 4.5), rel=1e-6)
    world = world_positions(obj)
    for item in items:
        assert np.abs(corner_points(item) - world[item.vertices]).max() < 1e-5


def test_outward_normals_survive_mirroring(addon):
    """Front = Blender's face normal, also for a mirrored object (scale -1), as Cycles renders it."""
    bpy.ops.mesh.primitive_cube_add()
    obj = bpy.context.active_object
    obj.scale = (-1.0, 1.0, 1.0)
    bpy.context.view_layer.update()
    for item in items_of(addon, obj):
        ((u, v),) = item.params[:1]
        P, N = item.surface.evaluate(np.array(0.5), np.array(0.5))
        assert N @ P > 0.0  # outward from the cube's centre at the origin


def test_triangles_collapse_one_edge(addon):
    """Triangles are quads with p01 = p00: three distinct sample corners, exact area."""
    obj = polygon_mesh("Tri", [(0, 0, 0), (2, 0, 0), (0, 3, 0)], [(0, 1, 2)])
    (item,) = items_of(addon, obj)
    assert len(item.vertices) == 3
    assert np.allclose(item.surface.corners[3], item.surface.corners[0])
    assert item.surface.area() == pytest.approx(3.0)
    P, N = item.surface.evaluate(np.array(0.5), np.array(0.5))
    assert N[2] > 0  # counter-clockwise seen from +Z: front +Z


@pytest.mark.parametrize("n", [5, 6, 7, 12])
def test_convex_ngon_fans_into_quads(addon, n):
    """A regular n-gon: (n - 1) // 2 pieces (quads and one triangle for odd n), area (n/2) sin(2 pi / n)."""
    angles = 2 * np.pi * np.arange(n) / n
    obj = polygon_mesh("Ngon", [(np.cos(a), np.sin(a), 0.0) for a in angles], [tuple(range(n))])
    items = items_of(addon, obj)
    assert len(items) == (n - 1) // 2
    assert total_area(items) == pytest.approx(0.5 * n * np.sin(2 * np.pi / n), rel=1e-6)


def test_concave_ngon_uses_blender_triangles(addon):
    """An L-shaped hexagon whose fan from the first corner leaves the polygon: Blender's triangles."""
    verts = [(0, 1, 0), (0, 0, 0), (2, 0, 0), (2, 2, 0), (1, 2, 0), (1, 1, 0)]
    obj = polygon_mesh("L", verts, [tuple(range(6))])
    items = items_of(addon, obj)
    assert total_area(items) == pytest.approx(3.0, rel=1e-12)
    assert all(len(i.vertices) == 3 for i in items)


def test_float32_noise_is_snapped_flat(addon):
    """A rotated quad whose float32 corners are off its plane by ~1e-7 is snapped to a flat patch."""
    rng = np.random.default_rng(3)
    R = np.linalg.qr(rng.standard_normal((3, 3)))[0]
    square = np.array([(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)], float) @ R.T + (100.0, 0.0, 0.0)
    obj = polygon_mesh("Noisy", square.astype(np.float32).tolist(), [(0, 1, 2, 3)])
    (item,) = items_of(addon, obj)
    assert item.surface.geometry.plane is not None
    assert item.surface.area() == pytest.approx(1.0, rel=1e-6)


def test_strongly_non_planar_quad_stays_bilinear(addon):
    """A twisted quad (one corner lifted by 0.3) keeps its bilinear shape and exact corners."""
    verts = [(0, 0, 0), (1, 0, 0), (1, 1, 0.3), (0, 1, 0)]
    obj = polygon_mesh("Twist", verts, [(0, 1, 2, 3)])
    (item,) = items_of(addon, obj)
    assert item.surface.geometry.plane is None
    assert np.abs(corner_points(item) - np.array(verts)[item.vertices]).max() < 1e-7


def test_degenerate_polygons_are_skipped_with_a_warning(addon):
    """A zero-area quad (all corners on a line) is skipped and reported."""
    verts = [(0, 0, 0), (1, 0, 0), (2, 0, 0), (3, 0, 0), (0, 1, 0), (1, 1, 0)]
    obj = polygon_mesh("Line", verts, [(0, 1, 2, 3), (0, 1, 5, 4)])
    collected = collect(addon)
    assert len([i for i in collected.surfaces if i.target == obj.name]) == 1
    assert any("no area" in w for w in collected.warnings)


def test_vertex_average_of_shared_corners(addon):
    """polygons.vertex_average: per-corner samples averaged onto shared vertices."""
    values = np.array([[1.0], [3.0], [5.0]])
    mean, count = addon.polygons.vertex_average(values, np.array([0, 0, 2]), 4)
    assert mean[:, 0].tolist() == [2.0, 0.0, 5.0, 0.0] and count.tolist() == [2, 0, 1, 0]
