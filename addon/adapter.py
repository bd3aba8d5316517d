"""The one place where Blender buffers meet numpy: bulk `foreach_get` / `foreach_set` only.

Every read fills a preallocated array of Blender's own dtype (float32 coordinates, int32 indices)
in one call and returns it reshaped, converted to float64 / int64 for the maths; every write is
one `foreach_set` of a flat float32 buffer. No function here loops over vertices, corners or
points in Python.
"""

import numpy as np


class AttributeMismatchError(ValueError):
    """An array does not match the size of the Blender data it is meant for."""


def _get(collection, prop, count, width, dtype):
    """`collection.foreach_get(prop)` into a new array of shape (count, width) (or (count,))."""
    buffer = np.empty(count * width, dtype=dtype)
    collection.foreach_get(prop, buffer)
    return buffer.reshape(count, width) if width > 1 else buffer


def vertex_positions(mesh):
    """Vertex coordinates, shape (N, 3), float64, in the mesh's (object-local) frame."""
    return _get(mesh.vertices, "co", len(mesh.vertices), 3, np.float32).astype(np.float64)


def polygons(mesh):
    """Polygon structure.

    Returns
    -------
    loop_start, loop_total : ndarray of int64, shape (F,)
    corner_verts : ndarray of int64, shape (L,)
        Vertex index of each corner (loop), polygon after polygon.
    material_index : ndarray of int64, shape (F,)
    """
    n = len(mesh.polygons)
    loop_start = _get(mesh.polygons, "loop_start", n, 1, np.int32).astype(np.int64)
    loop_total = _get(mesh.polygons, "loop_total", n, 1, np.int32).astype(np.int64)
    corner_verts = _attribute(mesh, CORNER_VERT, "CORNER", len(mesh.loops))
    if corner_verts is None:  # (an older Blender: through the loops, one RNA access each)
        corner_verts = _get(mesh.loops, "vertex_index", len(mesh.loops), 1, np.int32)
    material_index = _attribute(mesh, "material_index", "FACE", n)
    if material_index is None:  # no attribute: every polygon uses the first material
        material_index = np.zeros(n, dtype=np.int32)
    return loop_start, loop_total, corner_verts.astype(np.int64), material_index.astype(np.int64)


# Blender's own corner -> vertex attribute (4.0 and later): read as one array, about a hundred
# times faster than `MeshLoop.vertex_index` item by item
CORNER_VERT = ".corner_vert"


def _attribute(mesh, name, domain, count):
    """Integer attribute `name` on `domain` as an int32 array of shape (count,), or None if the
    mesh has no such attribute."""
    attribute = mesh.attributes.get(name)
    if attribute is None or (attribute.domain, attribute.data_type) != (domain, "INT"):
        return None
    if len(attribute.data) != count:
        return None
    return _get(attribute.data, "value", count, 1, np.int32)


def polygon_normals(mesh):
    """Unit polygon normals, shape (F, 3), float64, in the mesh's frame."""
    return _get(mesh.polygons, "normal", len(mesh.polygons), 3, np.float32).astype(np.float64)


def loop_triangles(mesh):
    """Blender's own triangulation of every polygon (handles concave n-gons).

    Returns
    -------
    vertices : ndarray of int64, shape (T, 3)
    polygon : ndarray of int64, shape (T,)
        The polygon each triangle belongs to.
    """
    mesh.calc_loop_triangles()
    n = len(mesh.loop_triangles)
    vertices = _get(mesh.loop_triangles, "vertices", n, 3, np.int32).astype(np.int64)
    polygon = _get(mesh.loop_triangles, "polygon_index", n, 1, np.int32).astype(np.int64)
    return vertices, polygon


def vertex_normals(mesh):
    """Unit vertex normals, shape (V, 3), in the mesh's coordinates."""
    out = np.empty(len(mesh.vertices) * 3, dtype=np.float32)
    mesh.vertex_normals.foreach_get("vector", out)
    return out.reshape(-1, 3).astype(np.float64)


def spline_points(spline):
    """NURBS spline control points, shape (n, 4): local x, y, z and the weight, u fastest."""
    return _get(spline.points, "co", len(spline.points), 4, np.float32).astype(np.float64)


def matrix(obj):
    """`obj.matrix_world` as a float64 array, shape (4, 4) (column vectors: x' = M @ [x, 1])."""
    return np.array(obj.matrix_world, dtype=np.float64)


def write_color_attribute(mesh, name, rgb):
    """Store per-vertex RGB as a linear, unclamped FLOAT_COLOR attribute on the POINT domain.

    Parameters
    ----------
    mesh : bpy.types.Mesh
    name : str
        Replaced if it exists.
    rgb : ndarray, shape (N, 3)
        One colour per vertex (alpha is set to 1).

    Raises
    ------
    AttributeMismatchError
        If N is not the mesh's vertex count.
    """
    rgb = np.asarray(rgb)
    if rgb.shape != (len(mesh.vertices), 3):
        raise AttributeMismatchError(
            f"mesh {mesh.name!r} has {len(mesh.vertices)} vertices, got colours of shape {rgb.shape}"
        )
    old = mesh.color_attributes.get(name)
    if old is not None:
        mesh.color_attributes.remove(old)
    attribute = mesh.color_attributes.new(name, "FLOAT_COLOR", "POINT")
    rgba = np.ones((len(rgb), 4), dtype=np.float32)
    rgba[:, :3] = rgb
    attribute.data.foreach_set("color", rgba.ravel())
    mesh.update()
    return attribute


def read_color_attribute(mesh, name):
    """A POINT-domain colour attribute as an array of shape (N, 4), float64."""
    attribute = mesh.color_attributes[name]
    if attribute.domain != "POINT":
        raise AttributeMismatchError(f"attribute {name!r} of mesh {mesh.name!r} is not on the POINT domain")
    return _get(attribute.data, "color", len(attribute.data), 4, np.float32).astype(np.float64)


def loop_triangle_corners(mesh):
    """Blender's triangulation with its corners.

    Returns
    -------
    vertices : ndarray of int64, shape (T, 3)
    polygon : ndarray of int64, shape (T,)
    loops : ndarray of int64, shape (T, 3)
        The loop (face corner) of each triangle corner.
    """
    vertices, polygon = loop_triangles(mesh)
    loops = _get(mesh.loop_triangles, "loops", len(mesh.loop_triangles), 3, np.int32).astype(np.int64)
    return vertices, polygon, loops


def polygon_smooth(mesh):
    """Smooth-shading flag of every polygon, shape (F,)."""
    return _get(mesh.polygons, "use_smooth", len(mesh.polygons), 1, bool).astype(bool)


def uv_map(mesh, name):
    """UV map `name` per loop, shape (L, 2), float64."""
    return _get(mesh.uv_layers[name].uv, "vector", len(mesh.loops), 2, np.float32).astype(np.float64)


def write_uv_map(mesh, name, uv):
    """Set UV map `name` from per-loop UVs of shape (L, 2).

    Raises
    ------
    AttributeMismatchError
        If L is not the mesh's loop count.
    """
    uv = np.asarray(uv)
    if uv.shape != (len(mesh.loops), 2):
        raise AttributeMismatchError(
            f"mesh {mesh.name!r} has {len(mesh.loops)} loops, got UVs of shape {uv.shape}"
        )
    mesh.uv_layers[name].uv.foreach_set("vector", np.ascontiguousarray(uv, dtype=np.float32).ravel())


def set_triangles(mesh, positions, triangles):
    """Fill an empty mesh with triangles.

    Parameters
    ----------
    positions : ndarray, shape (V, 3)
    triangles : ndarray of int, shape (T, 3)
    """
    positions = np.ascontiguousarray(positions, dtype=np.float32)
    triangles = np.ascontiguousarray(triangles, dtype=np.int32)
    mesh.vertices.add(len(positions))
    mesh.vertices.foreach_set("co", positions.ravel())
    mesh.loops.add(triangles.size)
    mesh.loops.foreach_set("vertex_index", triangles.ravel())
    mesh.polygons.add(len(triangles))
    mesh.polygons.foreach_set("loop_start", np.arange(0, triangles.size, 3, dtype=np.int32))
    mesh.update(calc_edges=True)
    # edges made by update() come with selection flags that are not always cleared: drop them,
    # so the same triangles always make the same mesh
    for name in (".select_vert", ".select_edge", ".select_poly"):
        attribute = mesh.attributes.get(name)
        if attribute is not None:
            mesh.attributes.remove(attribute)


def set_polygon_data(mesh, material_index, smooth):
    """Per-polygon material index and smooth flag, shapes (F,)."""
    mesh.polygons.foreach_set("material_index", np.ascontiguousarray(material_index, dtype=np.int32))
    mesh.polygons.foreach_set("use_smooth", np.ascontiguousarray(smooth, dtype=bool))
    mesh.update()
