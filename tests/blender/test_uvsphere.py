"""UV-sphere recognition: Blender's primitive layout, any size and transform, edits fall back to flat."""

import numpy as np
import pytest
from blender_helpers import bpy, collect, positions, world_positions

pytestmark = pytest.mark.blender

SIZES = [(3, 3), (4, 4), (5, 4), (12, 3), (8, 3), (32, 16), (64, 32), (7, 200), (200, 7), (500, 3), (128, 64)]


def add_sphere(segments=32, rings=16, **kwargs):
    bpy.ops.mesh.primitive_uv_sphere_add(segments=segments, ring_count=rings, **kwargs)
    return bpy.context.active_object


def topology(mesh):
    """(loop_total (F,), corner_verts (L,)) of a bpy mesh."""
    loop_total = np.empty(len(mesh.polygons), np.int32)
    mesh.polygons.foreach_get("loop_total", loop_total)
    corner_verts = np.empty(len(mesh.loops), np.int32)
    mesh.loops.foreach_get("vertex_index", corner_verts)
    return loop_total, corner_verts


def sphere_item(addon, obj):
    """The single item collected for `obj` (asserting it is one)."""
    (item,) = [i for i in collect(addon).surfaces if i.target == obj.name]
    return item


@pytest.mark.parametrize("segments, rings", SIZES, ids=lambda x: str(x))
def test_blender_layout(addon, segments, rings):
    """Blender's primitive: N = S (R - 1) + 2, F = S R, poles at +-Z, ring r at polar angle pi r / R,
    segment s at azimuth pi / 2 - 2 pi s / S (bmo_create_uvsphere_exec), in any vertex order."""
    mesh = add_sphere(segments, rings).data
    x = positions(mesh)
    assert len(x) == segments * (rings - 1) + 2 and len(mesh.polygons) == segments * rings
    polar = np.arctan2(np.hypot(x[:, 0], x[:, 1]), x[:, 2])
    ring = np.rint(polar * rings / np.pi)
    assert np.abs(polar - np.pi * ring / rings).max() < 1e-5
    inner = (ring > 0) & (ring < rings)
    azimuth = np.arctan2(x[inner, 1], x[inner, 0])
    segment = np.rint((np.pi / 2 - azimuth) * segments / (2 * np.pi))
    assert np.abs(np.pi / 2 - 2 * np.pi * segment / segments - azimuth).max() < 1e-5 * segments
    cells = np.unique(ring[inner] * segments + np.mod(segment, segments))
    assert cells.size == segments * (rings - 1)


@pytest.mark.parametrize("segments, rings", SIZES, ids=lambda x: str(x))
def test_recognised_and_parameters_hit_the_vertices(addon, segments, rings):
    """Every vertex sits at its (u, v) on the fitted sphere, within 1e-5 of the radius."""
    obj = add_sphere(segments, rings, radius=1.5)
    layout = addon.uvsphere.recognise(positions(obj.data), *topology(obj.data))
    assert layout is not None and (layout.segments, layout.rings) == (segments, rings)
    item = sphere_item(addon, obj)
    assert type(item.surface).__name__ == "Sphere" and item.surface.radius == pytest.approx(1.5, rel=1e-5)
    P, _ = item.surface.evaluate(item.params[:, 0], item.params[:, 1])
    assert np.abs(P - world_positions(obj)[item.vertices]).max() < 1e-5 * 1.5
    assert np.array_equal(np.sort(item.vertices), np.arange(len(obj.data.vertices)))


@pytest.mark.parametrize(
    "transform",
    [
        dict(location=(3.0, -2.0, 7.0)),
        dict(rotation=(0.4, -1.2, 2.0), scale=(2.0, 2.0, 2.0)),
        dict(location=(1.0, 2.0, 3.0), rotation=(0.3, 0.2, 0.1), scale=(1.0, 3.0, 0.25)),
        dict(scale=(-1.0, 1.0, 1.0)),
    ],
    ids=["moved", "rotated-scaled", "ellipsoid", "mirrored"],
)
def test_object_transforms(addon, transform):
    """Object location, rotation, (non-uniform, negative) scale: the core surface is the world ellipsoid."""
    obj = add_sphere(24, 12)
    for name, value in transform.items():
        setattr(obj, name + ("_euler" if name == "rotation" else ""), value)
    bpy.context.view_layer.update()
    item = sphere_item(addon, obj)
    P, N = item.surface.evaluate(item.params[:, 0], item.params[:, 1])
    world = world_positions(obj)
    assert np.abs(P - world[item.vertices]).max() < 1e-5 * np.abs(world).max()
    # the front is the outside (the primitive's normals point out, mirrored or not)
    centre = world.mean(0)
    assert np.all(np.einsum("kj,kj->k", N, P - centre) >= -1e-9)
    # under a uniform scale an exact sphere (its radius known: the sphere kind's kernels and
    # closed-form shadows), although float32 coordinates put ~1e-7 into the fitted map; an
    # ellipsoid under a non-uniform one
    uniform = np.ptp(np.abs(np.array(obj.scale))) == 0.0
    assert (item.surface.radius is not None) == uniform
    if uniform:
        assert item.surface.radius == pytest.approx(abs(obj.scale[0]), rel=1e-6)


def test_applied_transform_is_fitted(addon):
    """A sphere whose rotation and non-uniform scale were applied to the mesh is still one sphere."""
    obj = add_sphere(16, 8, location=(100.0, 3.0, -7.0), rotation=(0.3, 1.1, -0.4))
    obj.scale = (1.0, 3.0, 0.2)
    bpy.ops.object.transform_apply(location=True, rotation=True, scale=True)
    item = sphere_item(addon, obj)
    assert type(item.surface).__name__ == "Sphere"
    P, _ = item.surface.evaluate(item.params[:, 0], item.params[:, 1])
    assert np.abs(P - world_positions(obj)[item.vertices]).max() < 2e-5 * 3.0 + 1e-5


def test_vertex_order_does_not_matter(addon):
    """Shuffling vertices (and renumbering the faces) gives the same sphere."""
    obj = add_sphere(20, 10)
    x = positions(obj.data)
    loop_total, corner_verts = topology(obj.data)
    rng = np.random.default_rng(5)
    order = rng.permutation(len(x))
    new_index = np.empty_like(order)
    new_index[order] = np.arange(len(x))
    layout = addon.uvsphere.recognise(x[order], loop_total, new_index[corner_verts])
    assert layout is not None
    unit = addon.core.Sphere((0, 0, 0), 1.0).transformed(layout.local_from_unit)
    P, _ = unit.evaluate(layout.u, layout.v)
    assert np.abs(P - x[order]).max() < 1e-5


@pytest.mark.parametrize("shift", [1e-3, 1e-4])
def test_edited_vertex_falls_back_to_flat(addon, shift):
    """Moving one vertex by 1e-3 or 1e-4 of the radius: no sphere, a polygon mesh instead."""
    obj = add_sphere(16, 8)
    co = positions(obj.data).astype(np.float32)
    co[17] += np.float32(shift)
    obj.data.vertices.foreach_set("co", co.ravel())
    obj.data.update()
    items = [i for i in collect(addon).surfaces if i.target == obj.name]
    assert len(items) == 1 and type(items[0].surface).__name__ == "PolygonMesh"
    assert items[0].surface.face_count == len(obj.data.polygons)


def test_other_meshes_are_not_spheres(addon):
    """An ico sphere, a cube and a subdivided UV sphere are not taken for UV spheres."""
    bpy.ops.mesh.primitive_ico_sphere_add()
    bpy.ops.mesh.primitive_cube_add(location=(3, 0, 0))
    obj = add_sphere(8, 4, location=(-3, 0, 0))
    obj.modifiers.new("subdivide", "SUBSURF")
    kinds = {type(i.surface).__name__ for i in collect(addon).surfaces}
    assert kinds == {"PolygonMesh"}


@pytest.mark.parametrize("how", ["flip_normals", "negative_operator_scale"])
def test_inward_normals_make_the_inside_the_front(addon, how):
    """Normals flipped in edit mode, or a mirrored primitive (the operator's scale goes into the mesh
    without fixing the winding): the core sphere's front is the inside, as Blender renders it."""
    if how == "flip_normals":
        obj = add_sphere(16, 8)
        bpy.ops.object.mode_set(mode="EDIT")
        bpy.ops.mesh.select_all(action="SELECT")
        bpy.ops.mesh.flip_normals()
        bpy.ops.object.mode_set(mode="OBJECT")
    else:
        obj = add_sphere(16, 8, scale=(-1.0, 1.0, 1.0))
    item = sphere_item(addon, obj)
    P, N = item.surface.evaluate(item.params[:, 0], item.params[:, 1])
    assert np.all(np.einsum("kj,kj->k", N, P) <= 1e-9)


def test_nearest_similarity(addon):
    """A map within float32 noise of rotation x uniform scale (mirrored too) becomes exactly that;
    a deliberate non-uniform scale of 1e-3 is kept."""
    rng = np.random.default_rng(2)
    rotation, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    for mirror in (1.0, -1.0):
        affine = np.eye(4)
        affine[:3, :3] = 0.35 * rotation @ np.diag([mirror, 1.0, 1.0]) + rng.normal(scale=3e-8, size=(3, 3))
        affine[:3, 3] = (5.0, -2.0, 1.0)
        snapped = addon.uvsphere.nearest_similarity(affine)
        gram = snapped[:3, :3].T @ snapped[:3, :3]
        assert np.abs(gram - 0.35**2 * np.eye(3)).max() < 1e-6 * 0.35**2
        assert np.abs(gram - gram[0, 0] * np.eye(3)).max() <= 1e-14
        assert np.sign(np.linalg.det(snapped[:3, :3])) == mirror
        assert np.abs(snapped - affine).max() < 1e-6 and np.array_equal(snapped[:3, 3], affine[:3, 3])
    stretched = np.diag([1.0, 1.0, 1.001, 1.0])
    assert addon.uvsphere.nearest_similarity(stretched) is stretched
