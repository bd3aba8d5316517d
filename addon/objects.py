"""Blender objects as core surfaces: UV spheres, polygon meshes, NURBS surfaces and area lights.

A mesh object that is not a UV sphere becomes one `core.PolygonMesh` per material it uses (its
faces triangulated, split or kept whole by the core: see `core.mesh`), sampled at every face
corner. Under automatic patches, its coplanar regions (a subdivided floor, the sides of a
subdivided box) are merged into single faces first (`PolygonMesh.merge_coplanar`): the same
surface, with as many patches as its size asks for instead of one or more per face, while the
result is still gathered at every vertex. `POLYGON_MESHES = False` restores the former mapping
(every polygon its own `Quad` pieces), kept as the reference of benchmarks and tests, and
`MERGE_COPLANAR = False` keeps every face.

Every function takes an object (and its evaluated mesh, in the object's local frame) and
returns `SurfaceItem`s in world coordinates plus warnings; errors are raised as ValueError with
the object's name.
"""

import warnings

import numpy as np

from . import adapter, polygons, state, tessellation, uvsphere
from .core import NurbsSurface, PolygonMesh, Quad, Sphere
from .items import SurfaceItem
from .lights import area_emitter
from .materials import MaterialSpec, material_spec

POLYGON_MESHES = True  # meshes as core.PolygonMesh (False: one Quad item per polygon piece)
MERGE_COPLANAR = True  # coplanar regions of a mesh as one face each, under automatic patches


def patches_of(obj):
    """The object's patch grid setting: None (automatic) or (nu, nv)."""
    value = tuple(getattr(obj, "curved_radiosity_patches", (0, 0)))
    return None if min(value) <= 0 else (int(value[0]), int(value[1]))


def material_specs(obj):
    """MaterialSpec for each material slot of `obj` (one default spec if it has none)."""
    count = max(len(obj.material_slots), 1)
    return [material_spec(state.original_material(obj, i)) for i in range(count)]


def mesh_items(obj, M, mesh, target):
    """Items for a mesh object: one curved UV sphere if recognised, else flat polygon pieces.

    Parameters
    ----------
    obj : bpy.types.Object
        The original object (materials and settings).
    M : ndarray, shape (4, 4)
        Its evaluated world matrix.
    mesh : bpy.types.Mesh
        Its evaluated mesh (local coordinates).
    target : str
        Name of the result target.

    Returns
    -------
    items : list of SurfaceItem
    warnings : list of str
    """
    specs = material_specs(obj)
    warnings = [w for spec in specs for w in spec.warnings]
    positions = adapter.vertex_positions(mesh)
    loop_start, loop_total, corner_verts, material_index = adapter.polygons(mesh)
    material_index = np.clip(material_index, 0, len(specs) - 1)
    layout = uvsphere.recognise(positions, loop_total, corner_verts)
    if layout is not None:
        read = (positions, loop_total, corner_verts, material_index)
        item, sphere_warnings = _sphere_item(obj, mesh, layout, specs, read, M, target)
        return [item], warnings + sphere_warnings
    world = positions @ M[:3, :3].T + M[:3, 3]
    topology = (loop_start, loop_total, corner_verts)
    if POLYGON_MESHES:
        items, flat_warnings = _mesh_items(obj, world, topology, specs, material_index, M, target)
    else:
        items, flat_warnings = _flat_items(obj, mesh, world, topology, specs, material_index, M, target)
    return items, warnings + flat_warnings


def _mesh_items(obj, world, topology, specs, material_index, M, target):
    """One PolygonMesh item per material used, sampled at its faces' corners.

    An item's sample k is corner vertex `vertices[k]` of its mesh's face `params[k, 0]` (and
    `params[k, 1]` is that vertex's index): `Solution.radiosity_at(h, faces, positions)`. Under
    automatic patches the mesh's coplanar regions are merged (`MERGE_COPLANAR`): a vertex is then
    sampled once per merged face around it.
    """
    loop_start, loop_total, corner_verts = topology
    mirrored = np.linalg.det(M[:3, :3]) < 0.0
    used = np.unique(material_index)
    items, messages, skipped = [], [], []
    for slot in used:
        faces = np.flatnonzero(material_index == slot)
        name = obj.name if used.size == 1 else f"{obj.name}[material {slot}]"
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # (the skipped faces are reported below, by polygon index)
            try:
                surface = PolygonMesh(
                    world,
                    loop_starts=loop_start[faces],
                    loop_totals=loop_total[faces],
                    corner_verts=corner_verts,
                    name=obj.name,
                )
            except ValueError as error:
                if "zero area" not in str(error):
                    raise
                skipped += faces.tolist()
                continue
        skipped += faces[surface.skipped].tolist()
        local, vertices = _corner_samples(surface, loop_start[faces], loop_total[faces], corner_verts)
        if MERGE_COPLANAR and patches_of(obj) is None:
            surface, face_map = surface.merge_coplanar()
            # (face, vertex) samples of a merged face's corners and inner vertices, once each
            pairs = np.unique(np.column_stack([face_map[local], vertices]), axis=0)
            local, vertices = pairs[:, 0], pairs[:, 1]
        # Blender renders a mirrored object with its normals mirrored too: keep the image of the front
        surface = surface.flipped() if mirrored else surface
        params = np.column_stack([local, vertices]).astype(np.float64)
        items.append(SurfaceItem(name, surface, specs[slot], patches_of(obj), True, target, vertices, params))
    if skipped:
        listed = ", ".join(str(i) for i in sorted(skipped)[:20]) + (", ..." if len(skipped) > 20 else "")
        messages.append(f"{obj.name!r}: skipped {len(skipped)} polygon(s) with no area: {listed}")
    return items, messages


def _sphere_item(obj, mesh, layout, specs, read, M, target):
    """The UV sphere as one core Sphere (an ellipsoid under non-uniform scale); `read` holds the
    mesh's positions, loop totals, corner vertices and material indices (`adapter`)."""
    positions, loop_total, corner_verts, material_index = read
    warnings = []
    used = np.bincount(material_index, minlength=len(specs))
    spec = specs[int(np.argmax(used))]
    if np.count_nonzero(used) > 1:
        warnings.append(f"{obj.name!r}: a UV sphere with several materials uses its most common one")
    sphere = Sphere((0.0, 0.0, 0.0), 1.0).transformed(uvsphere.nearest_similarity(M @ layout.local_from_unit))
    # front = the side the mesh normals point to (outside for the primitive)
    normals = adapter.polygon_normals(mesh)
    sums = np.add.reduceat(positions[corner_verts], np.cumsum(loop_total) - loop_total)
    centres = sums / loop_total[:, None]
    outward = np.einsum("fj,fj->", normals, centres - layout.local_from_unit[:3, 3])
    if outward < 0.0:
        sphere = sphere.flipped()
    vertices = np.arange(len(layout.u))
    item = SurfaceItem(
        obj.name, sphere, spec, patches_of(obj), True, target, vertices, np.column_stack([layout.u, layout.v])
    )
    return item, warnings


def _corner_samples(surface, loop_start, loop_total, corner_verts):
    """Sample points of a PolygonMesh: every (face, vertex) corner of the faces not skipped,
    shapes (K,) each (the vertex result is their mean, as for the per-polygon pieces).

    Sampling a vertex whose faces share one plane only once was tried (2026-12-01): 2-3x faster
    gathers, but on the closed box of benchmarks/mesh_box.py twice the error against the
    reference (the corner samples' visibilities differed by face). The core has since gathered
    a vertex's coplanar corners as one point (one value for all, but where the vertex touches
    another object), so a merged mesh (`MERGE_COPLANAR`) is sampled once per merged face and
    vertex.
    """
    kept = np.setdiff1d(np.arange(loop_total.size), surface.skipped)
    local = np.repeat(kept, loop_total[kept])
    corners = np.concatenate([np.arange(s, s + t) for s, t in zip(loop_start[kept], loop_total[kept])])
    return local, corner_verts[corners]


def _flat_items(obj, mesh, world, topology, specs, material_index, M, target):
    """Polygon pieces as flat (or, if strongly non-planar, bilinear) core Quads."""
    vertex, polygon = polygons.fan_pieces(*topology)
    # concave n-gons: pieces of their fan face backwards; take Blender's triangles instead
    fold = polygons.folded(world[vertex], polygon, polygons.polygon_normals(world, *topology))
    keep = ~np.isin(polygon, fold)
    items, failed = _quads(obj, world, vertex[keep], polygon[keep], specs, material_index, M, target)
    failed = np.union1d(failed, fold)
    warnings = []
    if failed.size:
        # pieces the core rejects (folded quads) or that face backwards (concave n-gons): use
        # Blender's own triangulation of those whole polygons instead
        dropped = set(failed.tolist())
        items = [(item, p) for item, p in items if p not in dropped]
        tri_vertex, tri_polygon = polygons.triangle_pieces(*adapter.loop_triangles(mesh), failed)
        more, degenerate = _quads(obj, world, tri_vertex, tri_polygon, specs, material_index, M, target)
        items += more
        if degenerate.size:
            warnings.append(f"{obj.name!r}: skipped {degenerate.size} polygon(s) with no area")
    return [item for item, _ in items], warnings


def _quads(obj, world, vertex, polygon, specs, material_index, M, target):
    """(item, polygon) pairs for pieces, and the polygons whose pieces the core rejected."""
    corners = polygons.snap_planar(world[vertex])
    triangle = polygons.is_triangle(vertex)
    mirrored = np.linalg.det(M[:3, :3]) < 0.0
    patches = patches_of(obj)
    items, failed = [], []
    for k in range(len(vertex)):
        try:
            quad = Quad(*corners[k])
        except ValueError:
            failed.append(polygon[k])
            continue
        # Blender renders a mirrored object with its normals mirrored too: keep the image of the front
        surface = quad.flipped() if mirrored else quad
        n = 3 if triangle[k] else 4
        params = np.column_stack([polygons.CORNER_U[:n], polygons.CORNER_V[:n]])
        spec = specs[material_index[polygon[k]]]
        name = f"{obj.name}[{polygon[k]}.{k}]"
        item = SurfaceItem(name, surface, spec, patches, True, target, vertex[k, :n], params)
        items.append((item, polygon[k]))
    return items, np.unique(np.asarray(failed, np.int64))


def nurbs_items(obj, M, target, normals=None):
    """One NurbsSurface per spline of a SURFACE object, sampled at Blender's tessellation grid.

    Returns (items, warnings, vertex count of Blender's tessellation).

    Raises
    ------
    ValueError
        Naming the object and spline, if a spline is not a valid NURBS surface.
    """
    specs = material_specs(obj)
    warnings = [w for spec in specs for w in spec.warnings]
    items, offset = [], 0
    for index, spline in enumerate(obj.data.splines):
        try:
            local = NurbsSurface.from_blender(
                adapter.spline_points(spline),
                spline.order_u,
                spline.order_v,
                spline.point_count_u,
                spline.point_count_v,
                use_endpoint_u=spline.use_endpoint_u,
                use_endpoint_v=spline.use_endpoint_v,
                use_bezier_u=spline.use_bezier_u,
                use_bezier_v=spline.use_bezier_v,
                use_cyclic_u=spline.use_cyclic_u,
                use_cyclic_v=spline.use_cyclic_v,
            )
        except ValueError as error:
            raise ValueError(f"{obj.name!r}, spline {index}: {error}") from error
        u, v = tessellation.grid_parameters(
            local.domain,
            (spline.point_count_u, spline.point_count_v),
            (spline.resolution_u, spline.resolution_v),
            (spline.use_cyclic_u, spline.use_cyclic_v),
        )
        spec = specs[min(spline.material_index, len(specs) - 1)]
        vertices = offset + np.arange(u.size)
        name = obj.name if len(obj.data.splines) == 1 else f"{obj.name}[{index}]"
        surface = local.transformed(M)
        params = np.column_stack([u, v])
        if normals is not None and len(normals) >= offset + u.size:
            # the side Blender shades as front (its tessellation's normals) is our front too
            _, ours = surface.evaluate(u, v)
            if np.einsum("ki,ki->k", ours, normals[vertices]).sum() < 0:
                surface = surface.flipped()
        items.append(SurfaceItem(name, surface, spec, patches_of(obj), True, target, vertices, params))
        offset += u.size
    return items, warnings, offset


def area_light_item(obj, M):
    """An AREA light as a one-sided emitting patch that casts no shadow."""
    surface, radiance, warnings = area_emitter(obj, M)
    spec = MaterialSpec(np.zeros(3), radiance, two_sided=False)
    return SurfaceItem(obj.name, surface, spec, patches_of(obj), occluder=False), warnings
