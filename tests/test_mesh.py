"""core.PolygonMesh: one surface for a polygon mesh, and the BVH behind every occlusion query.

Identities checked: a mesh solves to the same radiosities as its faces' pieces added one by one;
pieces cover each face's area exactly (shoelace / Newell areas); bad input raises a ValueError
naming the problem; the BVH-backed shaft candidates and mesh segment tests equal brute force.
"""

import warnings
from pathlib import Path

import numpy as np
import pytest

import core
from core.elements import Elements
from core.mesh import PolygonMesh, ear_clip
from core.occlusion import Occluders
from core.visibility import ShaftTest


def grid(n, origin, du, dv):
    """Vertices and quad faces (counter-clockwise about du x dv) of an n x n grid."""
    o, du, dv = (np.asarray(x, dtype=float) for x in (origin, du, dv))
    V = np.array([o + du * i / n + dv * j / n for i in range(n + 1) for j in range(n + 1)])
    F = [
        [i * (n + 1) + j, (i + 1) * (n + 1) + j, (i + 1) * (n + 1) + j + 1, i * (n + 1) + j + 1]
        for i in range(n)
        for j in range(n)
    ]
    return V, F


def block(lo=(1, 1, 0), hi=(2, 2, 1)):
    """A box without its bottom, outward faces, as (vertices, faces)."""
    V = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])], float)

    def k(x, y, z):
        return x * 4 + y * 2 + z

    F = [
        [k(0, 0, 1), k(1, 0, 1), k(1, 1, 1), k(0, 1, 1)],
        [k(0, 0, 0), k(0, 0, 1), k(0, 1, 1), k(0, 1, 0)],
        [k(1, 0, 0), k(1, 1, 0), k(1, 1, 1), k(1, 0, 1)],
        [k(0, 0, 0), k(1, 0, 0), k(1, 0, 1), k(0, 0, 1)],
        [k(0, 1, 0), k(0, 1, 1), k(1, 1, 1), k(1, 1, 0)],
    ]
    return V, F


def shoelace(points):
    """Area of a planar polygon in the z = const plane."""
    x, y = points[:, 0], points[:, 1]
    return 0.5 * abs(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))


LIGHT = core.Quad((1, 1, 3), (1, 2, 3), (2, 2, 3), (2, 1, 3))


def solve_both(meshes, tol=1e-4, occlusion=True, patches=(1, 1)):
    """Per-face radiosities of the meshes solved as meshes, and as their pieces one by one."""
    results = []
    for mode in ("mesh", "pieces"):
        scene = core.Scene()
        handles = []
        for mesh, rho in meshes:
            if mode == "mesh":
                handles.append(scene.add(mesh, reflectance=rho, patches=patches))
            else:
                handles.append([scene.add(q, reflectance=rho, patches=patches) for q in mesh.pieces()])
        scene.add(LIGHT, emission=5.0, reflectance=0.0, occluder=False, patches=(1, 1))
        sol = scene.solve(tol=tol, occlusion=occlusion, threads=1)
        if mode == "mesh":
            results.append([sol.radiosity(h) for h in handles])
        else:
            per_face = []
            for (mesh, _), hs in zip(meshes, handles):
                B = np.stack([sol.radiosity(h).mean(0) for h in hs])  # (one patch grid per piece)
                A = mesh.piece_area[:, None]
                total = np.zeros((mesh.face_count, 3))
                np.add.at(total, mesh.piece_face, A * B)
                per_face.append(total / np.maximum(mesh.face_area, 1e-300)[:, None])
            results.append(per_face)
    return results


# --------------------------------------------------------------------------- scene results
@pytest.mark.parametrize("occlusion", [True, "exact", "sampled", False])
def test_mesh_equals_its_pieces_one_by_one(occlusion):
    """A floor grid and a block as two meshes give the radiosities of their pieces added as Quads:
    with rays, with exact shadows (a small mesh occludes through its pieces, a convex solid's
    pieces facing away left out) and without occlusion."""
    floor = PolygonMesh(*grid(3, (0, 0, 0), (3, 0, 0), (0, 3, 0)), name="floor")
    box = PolygonMesh(*block(), name="block")
    mesh, pieces = solve_both([(floor, 0.6), (box, 0.5)], occlusion=occlusion)
    for a, b in zip(mesh, pieces):
        assert np.max(np.abs(a - b)) <= 1e-4 * np.max(np.abs(b)), (a, b)
    # the face under the block sees no light with occlusion (a check that occlusion acted)
    assert (mesh[0][4].max() == 0.0) == bool(occlusion)


def test_automatic_patches_follow_each_piece_size():
    """patches=None: a piece gets about (its edge length / the automatic patch size) patches per
    direction, so a large face is split more than a small one."""
    V = np.array([[0, 0, 0], [4, 0, 0], [4, 1, 0], [0, 1, 0], [5, 0, 0], [5, 1, 0]], float)
    mesh = PolygonMesh(V, [[0, 1, 2, 3], [1, 4, 5, 2]])
    scene = core.Scene()
    h = scene.add(mesh, reflectance=0.5)
    scene.add(LIGHT, emission=1.0, reflectance=0.0, occluder=False, patches=(1, 1))
    sol = scene.solve(tol=1e-3, threads=1)
    # the scene's box (0, 0, 0) .. (5, 2, 3) with the light: patches of about 0.1 of its diagonal
    target = core.scene.AUTO_PATCH_SIZE * np.sqrt(5**2 + 2**2 + 3**2)
    expected = np.ceil(4 / target) * np.ceil(1 / target) + np.ceil(1 / target) ** 2
    assert len(sol.element_areas()) - 1 == expected > 2
    assert sol.radiosity(h).shape == (2, 3)


def test_mesh_with_patches_per_piece():
    """patches=(2, 2) splits every piece: per-face results still match the pieces one by one."""
    floor = PolygonMesh(*grid(2, (0, 0, 0), (3, 0, 0), (0, 3, 0)), name="floor")
    box = PolygonMesh(*block(), name="block")
    mesh, pieces = solve_both([(floor, 0.6), (box, 0.5)], tol=1e-3, patches=(2, 2))
    for a, b in zip(mesh, pieces):
        assert np.max(np.abs(a - b)) <= 1e-3 * np.max(np.abs(b))


def test_vertex_radiosity_is_the_area_weighted_corner_rule():
    """With one patch per piece, B(v) = sum A_f B_f / sum A_f over the faces around v."""
    V, F = grid(3, (0, 0, 0), (3, 0, 0), (0, 3, 0))
    V[5, 0] += 0.2  # unequal face areas
    floor = PolygonMesh(V, F, name="floor")
    scene = core.Scene()
    h = scene.add(floor, reflectance=0.6, patches=(1, 1))
    scene.add(LIGHT, emission=5.0, reflectance=0.0, occluder=False)
    sol = scene.solve(tol=1e-3, threads=1)
    B, Bv = sol.radiosity(h), sol.vertex_radiosity(h)
    for v in range(len(V)):
        around = [f for f in range(floor.face_count) if v in floor.corners_of(f)]
        A = floor.face_area[around]
        expected = (A[:, None] * B[around]).sum(0) / A.sum()
        np.testing.assert_allclose(Bv[v], expected, rtol=1e-12)
    with pytest.raises(ValueError, match="not a PolygonMesh"):
        sol.vertex_radiosity(1)


def test_radiosity_at_on_mesh_faces_equals_the_piece_as_a_quad():
    """A point given by (face, position) gathers the value the same face added as a Quad gives at
    the matching (u, v)."""
    floor = PolygonMesh(*grid(2, (0, 0, 0), (2, 0, 0), (0, 2, 0)), name="floor")
    results = []
    for mode in ("mesh", "quads"):
        scene = core.Scene()
        if mode == "mesh":
            h = scene.add(floor, reflectance=0.5)
        else:
            hs = [scene.add(q, reflectance=0.5) for q in floor.pieces()]
        scene.add(LIGHT, emission=5.0, reflectance=0.0, occluder=False)
        sol = scene.solve(tol=1e-4, threads=1)
        if mode == "mesh":
            points = np.array([[0.25, 0.5, 0.0], [1.5, 1.5, 0.0], [1.0, 1.0, 0.0]])
            results.append(sol.radiosity_at(h, np.array([0, 3, 3]), points))
        else:
            # face 0 spans [0, 1]^2 (u along x), face 3 spans [1, 2]^2; the corner (1, 1) of face 3
            a = sol.radiosity_at(hs[0], [0.25], [0.5])
            b = sol.radiosity_at(hs[3], [0.5, 0.0], [0.5, 0.0])
            results.append(np.concatenate([a, b]))
    # (a corner point is moved inside by the contact inset, along the diagonal on the mesh and
    # per parameter on the quad: a difference far below tol)
    np.testing.assert_allclose(results[0], results[1], rtol=1e-5)
    assert results[0].min() > 0.0


def test_radiosity_at_bad_mesh_addresses():
    """Faces out of range, skipped faces, and mismatched point arrays are ValueErrors."""
    V, F = grid(1, (0, 0, 0), (1, 0, 0), (0, 1, 0))
    V = np.vstack([V, [[2, 2, 0]]])
    with pytest.warns(UserWarning):
        mesh = PolygonMesh(V, F + [[0, 1, 1]], name="m")
    scene = core.Scene()
    h = scene.add(mesh, reflectance=0.5)
    scene.add(LIGHT, emission=5.0, reflectance=0.0, occluder=False)
    sol = scene.solve(tol=1e-3, threads=1)
    with pytest.raises(ValueError, match="face indices must be in 0 .. 1"):
        sol.radiosity_at(h, [2], [[0.5, 0.5, 0]])
    with pytest.raises(ValueError, match="skipped"):
        sol.radiosity_at(h, [1], [[0.5, 0.5, 0]])
    with pytest.raises(ValueError, match=r"point 0 \[0.5, 0.5, 0.1\] is not on face 0"):
        sol.radiosity_at(h, [0], [[0.5, 0.5, 0.1]])
    with pytest.raises(ValueError, match="is not on face 0"):
        sol.radiosity_at(h, [0], [[1.5, 0.5, 0.0]])
    with pytest.raises(ValueError, match="1 faces but 2 points"):
        sol.radiosity_at(h, [0], [[0.5, 0.5, 0], [0.2, 0.2, 0]])
    # the skipped face's per-face result is its corners' vertex mean, not a silent zero
    B = sol.radiosity(h)
    np.testing.assert_allclose(B[1], sol.vertex_radiosity(h)[[0, 1, 1]].mean(0))
    assert B[1].min() > 0.0


def test_two_sided_and_one_sided_meshes():
    """A two-sided mesh has back results (lit from below here); a one-sided one refuses them."""
    V, F = grid(2, (0, 0, 1), (2, 0, 0), (0, 2, 0))
    below = core.Quad((0, 0, -1), (2, 0, -1), (2, 2, -1), (0, 2, -1))  # faces +z, toward the mesh
    for two_sided in (True, False):
        mesh = PolygonMesh(V, F, two_sided=two_sided, name="sheet")
        scene = core.Scene()
        h = scene.add(mesh, reflectance=0.5)
        scene.add(below, emission=3.0, reflectance=0.0, occluder=False)
        sol = scene.solve(tol=1e-3, threads=1)
        assert np.all(sol.radiosity(h) == 0.0)  # the front (+z) sees nothing
        if two_sided:
            back = sol.radiosity(h, side="back")
            assert back.shape == (4, 3) and back.min() > 0.0
            assert sol.vertex_radiosity(h, side="back").min() > 0.0
        else:
            with pytest.raises(ValueError, match="one-sided"):
                sol.radiosity(h, side="back")


# --------------------------------------------------------------------------- faces to pieces
def test_blender_layout_equals_index_lists():
    """loop_starts / loop_totals / corner_verts give the same pieces as a list of index lists."""
    V, F = grid(2, (0, 0, 0), (1, 0, 0), (0, 1, 0))
    F = F[:3] + [[4, 7, 8], [4, 8, 5], [0, 1, 4, 5, 2]]
    totals = np.array([len(f) for f in F])
    mesh = PolygonMesh(V, F)
    other = PolygonMesh(
        V, loop_starts=np.cumsum(totals) - totals, loop_totals=totals, corner_verts=np.concatenate(F)
    )
    np.testing.assert_array_equal(mesh.piece_vertices, other.piece_vertices)
    np.testing.assert_array_equal(mesh.piece_face, other.piece_face)


def test_triangles_and_planar_quads_are_one_piece_each():
    V, F = grid(2, (0, 0, 0), (1, 0, 0), (0, 1, 0))
    mesh = PolygonMesh(V, F + [[0, 1, 4]])
    assert len(mesh.piece_face) == 5
    tri = mesh.piece_vertices[mesh.piece_face == 4][0]
    assert tri[3] == tri[0]  # a triangle repeats p00 as p01
    np.testing.assert_allclose(mesh.face_area, [0.25] * 4 + [0.125], rtol=1e-12)


def test_non_planar_quad_is_split_as_blender_does():
    """A quad off its plane becomes triangles (0, 1, 2) and (0, 2, 3); its area is theirs."""
    V = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0.5], [0, 1, 0]], float)
    mesh = PolygonMesh(V, [[0, 1, 2, 3]])
    np.testing.assert_array_equal(mesh.piece_vertices, [[0, 1, 2, 0], [0, 2, 3, 0]])
    expected = 0.5 * (
        np.linalg.norm(np.cross(V[1] - V[0], V[2] - V[0]))
        + np.linalg.norm(np.cross(V[2] - V[0], V[3] - V[0]))
    )
    assert mesh.area() == pytest.approx(expected, rel=1e-12)
    # a float32-rounded planar quad stays one flat piece
    W = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], np.float32) @ np.float32(
        [[1, 0, 0], [0, 0.6, 0.8], [0, -0.8, 0.6]]
    )
    flat = PolygonMesh(W.astype(float), [[0, 1, 2, 3]])
    assert len(flat.piece_face) == 1 and flat.pieces()[0].geometry.plane is not None


@pytest.mark.parametrize("n", [5, 6, 9])
def test_convex_ngon_fan_covers_its_area(n):
    angle = 2 * np.pi * np.arange(n) / n
    V = np.column_stack([np.cos(angle), np.sin(angle), np.zeros(n)])
    mesh = PolygonMesh(V, [list(range(n))])
    assert len(mesh.piece_face) == n - 2
    assert mesh.area() == pytest.approx(shoelace(V), rel=1e-12)


def test_concave_ngon_is_ear_clipped():
    """An L-shaped hexagon and a star: the triangles cover exactly the polygon (no fan overlap)."""
    L = np.array([[0, 0, 0], [2, 0, 0], [2, 1, 0], [1, 1, 0], [1, 2, 0], [0, 2, 0]], float)
    mesh = PolygonMesh(L, [list(range(6))])
    assert mesh.area() == pytest.approx(3.0, rel=1e-12)
    # every triangle faces the polygon's normal (+z) and the pieces' areas sum to the shoelace
    k = np.arange(10)
    r = np.where(k % 2 == 0, 1.0, 0.4)
    star = np.column_stack([r * np.cos(k * np.pi / 5), r * np.sin(k * np.pi / 5), np.zeros(10)])
    tris = ear_clip(star, np.array([0.0, 0.0, 1.0]))
    P = star[tris]
    z = np.cross(P[:, 1] - P[:, 0], P[:, 2] - P[:, 0])[:, 2]
    assert len(tris) == 8 and np.all(z > 0)
    assert 0.5 * z.sum() == pytest.approx(shoelace(star), rel=1e-12)
    assert PolygonMesh(star, [list(range(10))]).area() == pytest.approx(shoelace(star), rel=1e-12)


def test_degenerate_faces_are_skipped_with_a_warning_naming_them():
    V, F = grid(2, (0, 0, 0), (1, 0, 0), (0, 1, 0))
    with pytest.warns(UserWarning, match=r"mesh 'Floor'.*2 face\(s\) with no area: 4, 5"):
        mesh = PolygonMesh(V, F + [[0, 1, 2], [3, 3, 3, 4]], name="Floor")
    np.testing.assert_array_equal(mesh.skipped, [4, 5])
    assert mesh.face_area[4] == 0.0 and set(mesh.piece_face) == {0, 1, 2, 3}
    with pytest.raises(ValueError, match="every face has zero area"), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        PolygonMesh(V, [[0, 1, 2]])


@pytest.mark.parametrize(
    "vertices, faces, kwargs, match",
    [
        (np.zeros((4, 2)), [[0, 1, 2]], {}, r"shape \(V, 3\)"),
        ([[0, 0, 0], [1, 0, 0], [np.nan, 1, 0]], [[0, 1, 2]], {}, "finite|NaN"),
        ([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 3]], {}, r"vertex indices must be in 0 .. 2"),
        ([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1]], {}, "fewer than 3 corners"),
        ([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [], {}, "no faces"),
        ([[0, 0, 0], [1, 0, 0], [0, 1, 0]], None, {}, "give faces"),
        ([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]], {"loop_totals": [3]}, "not both"),
        (
            [[0, 0, 0], [1, 0, 0], [0, 1, 0]],
            None,
            dict(loop_starts=[1], loop_totals=[3], corner_verts=[0, 1, 2]),
            "run past",
        ),
        ([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0.0, 1.0, 2.0]], {}, "integer"),
    ],
)
def test_bad_input_names_the_problem(vertices, faces, kwargs, match):
    with pytest.raises(ValueError, match=match):
        PolygonMesh(vertices, faces, **kwargs)


def test_transformed_and_flipped():
    """Rotation keeps areas; flipped reverses normals; a mirror keeps the image of the front."""
    V, F = grid(2, (0, 0, 0), (1, 0, 0), (0, 1, 0))
    mesh = PolygonMesh(V, F)
    c, s = np.cos(0.7), np.sin(0.7)
    R = np.array([[c, -s, 0, 1], [s, c, 0, 2], [0, 0, 1, 3], [0, 0, 0, 1.0]])
    assert mesh.transformed(R).area() == pytest.approx(mesh.area(), rel=1e-12)
    np.testing.assert_allclose(mesh.flipped().face_normal, -mesh.face_normal)
    mirrored = mesh.transformed(np.diag([1.0, 1.0, -1.0, 1.0]))
    np.testing.assert_allclose(mirrored.face_normal, [[0, 0, -1]] * 4, atol=1e-15)
    with pytest.raises(ValueError, match="singular"):
        mesh.transformed(np.diag([1.0, 1.0, 0.0, 1.0]))
    with pytest.raises(TypeError):
        core.Scene().add("not a mesh")


# --------------------------------------------------------------------------- BVH versus brute force
def brute_force_candidates(elements, occ, objects, a, b):
    """The shaft rule of ShaftTest written out over every (pair, occluder): box, capsule, planes,
    own convex surface."""
    e = elements
    lo = np.minimum(e.box_min[a], e.box_min[b])
    hi = np.maximum(e.box_max[a], e.box_max[b])
    radius = np.maximum(e.radius[a], e.radius[b])
    mask = np.all((occ.box_min[None] <= hi[:, None]) & (occ.box_max[None] >= lo[:, None]), axis=-1)
    p, q = e.center[a], e.center[b]
    d = q - p
    dd = np.einsum("ki,ki->k", d, d)[:, None]
    t = np.einsum("kmi,ki->km", occ.center[None] - p[:, None], d)
    t = np.divide(t, dd, out=np.zeros_like(t), where=dd > 0)
    closest = p[:, None] + np.clip(t, 0, 1)[..., None] * d[:, None]
    mask &= np.linalg.norm(occ.center[None] - closest, axis=-1) <= occ.radius[None] + radius[:, None]
    eps = 1e-9 * occ.scale
    for m in np.flatnonzero(occ.planar):
        normal = np.broadcast_to(occ.plane_normal[m], (a.size, 3))
        point = normal * occ.plane_offset[m]
        la, ha = e.heights(a, point, normal)
        lb, hb = e.heights(b, point, normal)
        mask[:, m] &= ~(((la >= -eps) & (lb >= -eps)) | ((ha <= eps) & (hb <= eps)))
    for side in (a, b):
        leaves = occ.planar[None] | e.outward[side][:, None]
        mask &= ~(occ.convex[None] & (objects[None] == e.owner[side][:, None]) & leaves)
    return mask


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_shaft_candidates_equal_brute_force_on_random_scenes(seed):
    rng = np.random.default_rng(seed)
    surfaces = []
    for _ in range(25):
        c = rng.uniform(0, 10, 3)
        kind = rng.integers(3)
        if kind == 0:
            surfaces.append(core.Sphere(c, rng.uniform(0.2, 1.0)))
        elif kind == 1:
            du, dv = rng.normal(size=(2, 3))
            surfaces.append(core.Quad(c, c + du, c + du + dv, c + dv))
        else:
            surfaces.append(core.Disk(c, rng.normal(size=3), rng.uniform(0.2, 1.0)))
    V, F = grid(3, (0, 0, 0), (10, 0, 0), (0, 10, 0))
    V[:, 2] = rng.uniform(0, 0.5, len(V))
    surfaces.append(PolygonMesh(V, F, name="terrain"))
    # a wall of separate coplanar quads: whole BVH nodes of one plane (the node-level plane rule)
    V, F = grid(4, (0, 0, 6), (0, 10, 0), (10, 0, 0))
    surfaces += [core.Quad(*V[f]) for f in F]
    patches, owner = [], []
    for k, s in enumerate(surfaces):
        pieces = s.pieces() if isinstance(s, PolygonMesh) else s.split(2, 2)
        patches += pieces
        owner += [k] * len(pieces)
    elements = Elements(patches, owner)
    occ = Occluders(surfaces)
    objects = np.arange(len(surfaces))
    shafts = ShaftTest(elements, occ, objects)
    N = len(elements)
    a, b = (x.ravel() for x in np.meshgrid(np.arange(N), np.arange(N), indexing="ij"))
    got = shafts.candidates(a, b)
    want = brute_force_candidates(elements, occ, objects, a, b)
    assert want.sum() > 100 and (~want).sum() > 100  # both outcomes are covered
    np.testing.assert_array_equal(got, want)
    # and point / segment queries: against the same rules through candidates of degenerate pairs
    x = elements.center[a[:50]]
    got_points = shafts.point_candidates(x, elements.owner[a[:50]], elements.outward[a[:50]], b[:50])
    assert got_points.shape == (50, len(surfaces))


@pytest.mark.parametrize("seed", [3, 4])
def test_mesh_segments_equal_brute_force_triangle_tests(seed):
    """Segments against a random bumpy mesh: the mesh occluder (its BVH) equals testing every
    triangle, and equals the same triangles as separate flat-quad occluders."""
    rng = np.random.default_rng(seed)
    V, F = grid(6, (0, 0, 0), (4, 0, 0), (0, 4, 0))
    V[:, 2] = rng.uniform(-0.3, 0.3, len(V))
    mesh = PolygonMesh(V, F, name="bumpy")
    p = np.column_stack([rng.uniform(-1, 5, (400, 2)), rng.uniform(-2, -0.5, 400)])
    q = np.column_stack([rng.uniform(-1, 5, (400, 2)), rng.uniform(0.5, 2, 400)])
    got = Occluders([mesh]).blocked(p, q, np.zeros(400, dtype=np.int64))
    triangles, _ = mesh.triangles()
    separate = Occluders([core.Quad(t[0], t[1], t[2], t[0]) for t in triangles])
    want = separate.any_blocked(p, q, np.arange(len(triangles)))
    assert 50 < want.sum() < 400
    np.testing.assert_array_equal(got, want)


def subdivided_cube(n, matrix=np.eye(4), float32=False):
    """A closed unit cube of six n x n grids, fronts out, each side's vertices its own (as in a
    mesh with split edges), moved by matrix and optionally rounded to float32 as Blender keeps
    coordinates."""
    sides = [  # origin, du, dv with du x dv outward
        ((0, 0, 0), (0, 1, 0), (1, 0, 0)),
        ((0, 0, 1), (1, 0, 0), (0, 1, 0)),
        ((0, 0, 0), (0, 0, 1), (0, 1, 0)),
        ((1, 0, 0), (0, 1, 0), (0, 0, 1)),
        ((0, 0, 0), (1, 0, 0), (0, 0, 1)),
        ((0, 1, 0), (0, 0, 1), (1, 0, 0)),
    ]
    vertices, faces = [], []
    for o, du, dv in sides:
        V, F = grid(n, o, du, dv)
        faces += [[v + len(vertices) for v in f] for f in F]
        vertices += list(V)
    V = np.array(vertices) @ matrix[:3, :3].T + matrix[:3, 3]
    return PolygonMesh(V.astype(np.float32).astype(float) if float32 else V, faces)


def _rotation(x, y, z):
    """A rotation about (1, 2, 3) by 0.7 rad, then a move to (x, y, z)."""
    axis = np.array([1.0, 2.0, 3.0]) / np.sqrt(14.0)
    K = np.cross(np.eye(3), axis)
    matrix = np.eye(4)
    matrix[:3, :3] = np.eye(3) + np.sin(0.7) * K + (1 - np.cos(0.7)) * K @ K
    matrix[:3, 3] = (x, y, z)
    return matrix


def test_solid_hull_of_closed_convex_meshes():
    """A closed convex mesh with its fronts out gives its face planes, also with its sides'
    vertices repeated and rounded to float32 far from the origin (a rounding of unit normals to
    1e-9 found 62 and more planes on a Blender cube subdivided twice); an open box, a room
    (fronts in) and a non-convex solid give None."""
    for cube in (subdivided_cube(4), subdivided_cube(4, _rotation(40.0, -7.0, 3.0), float32=True)):
        assert cube.convex_solid
        normal, offset, slack = cube.solid_hull
        assert normal.shape == (6, 3) and offset.shape == (6,)
        facets = cube.solid_facets()  # (one polygon a side, as large as the side)
        assert facets.face_count == 6 and abs(facets.area() - cube.area()) <= 1e-6 * cube.area()
    # corners off their sides by up to 1e-7 (float32): sorted by a noisy coordinate, the corners
    # along an edge broke the hull's order, and an add-on's subdivided cube lost 8 % of its area
    cube = subdivided_cube(4, _rotation(40.0, -7.0, 3.0))
    V, welded = np.unique(np.round(cube.vertices, 9), axis=0, return_inverse=True)
    V = V + np.random.default_rng(3).uniform(-1e-7, 1e-7, V.shape)
    noisy = PolygonMesh(V, [welded.ravel()[cube.corner_verts[s : s + 4]] for s in cube.loop_starts])
    facets = noisy.solid_facets()
    assert facets.face_count == 6 and abs(facets.area() - noisy.area()) <= 1e-6 * noisy.area()
    # Blender's cube subdivided twice and scaled (0.9, 0.6, 0.4), as the add-on collects it: its
    # float32 corners sorted the hull's points along an edge out of order, and its facets lost
    # 8 % of the area
    data = np.load(Path(__file__).parent / "data" / "blender_subdivided_cube.npz")
    blender = PolygonMesh(
        data["vertices"], loop_starts=data["starts"], loop_totals=data["totals"], corner_verts=data["corners"]
    )
    facets = blender.solid_facets()
    assert facets.face_count == 6 and abs(facets.area() - blender.area()) <= 1e-6 * blender.area()
    # a side's repeated corners one float32 step off the others' (moved or rounded apart): welded
    # to HULL_RTOL of the size, the cube is closed
    cube = subdivided_cube(4, _rotation(40.0, -7.0, 3.0), float32=True)
    sides = len(cube.vertices) // 6
    V = cube.vertices.astype(np.float32)
    V[:sides] = np.nextafter(V[:sides], np.float32(np.inf))
    assert PolygonMesh(V.astype(float), [cube.corner_verts[s : s + 4] for s in cube.loop_starts]).solid_hull
    assert PolygonMesh(*block()).convex_solid and PolygonMesh(*block()).solid_hull is None  # (no bottom)
    assert subdivided_cube(2).flipped().solid_hull is None
    # an L-shaped prism: closed, not convex
    L = np.array([[0, 0], [2, 0], [2, 1], [1, 1], [1, 2], [0, 2]], float)
    V = np.vstack([np.c_[L, np.zeros(6)], np.c_[L, np.ones(6)]])
    sides = [[k, (k + 1) % 6, (k + 1) % 6 + 6, k + 6] for k in range(6)]
    prism = PolygonMesh(V, sides + [[5, 4, 3, 2, 1, 0], [6, 7, 8, 9, 10, 11]])
    assert prism.orientation == 1 and prism.solid_hull is None


def test_a_float32_grid_in_a_tilted_plane_is_planar():
    """A subdivided plane turned and moved in float32 (as Blender stores it) is one plane: its
    faces scatter about 1e-7 of its size around it, and a test of the normals to 1e-12 took it
    for a curved occluder (its own segments went to its triangle hierarchy)."""
    V, F = grid(18, (0, 0, 0), (6, 0, 0), (0, 6, 0))
    M = _rotation(3.0, -2.0, 1.0)
    mesh = PolygonMesh((V @ M[:3, :3].T + M[:3, 3]).astype(np.float32).astype(float), F)
    point, normal = mesh.planar
    assert abs(normal @ M[:3, 2] - 1.0) < 1e-9
    assert Occluders([mesh]).planar[0]
    V[:, 2] = 1e-3 * np.sin(V[:, 0])  # (a wave of 1e-3: not one plane)
    assert PolygonMesh(V, F).planar is None


@pytest.mark.parametrize("float32", [False, True])
def test_segments_through_a_convex_solid_as_through_its_triangles(float32):
    """A closed convex mesh is tested as its polytope (`occlusion._crosses_polytope`): the same
    answers as its triangle hierarchy for segments that miss it, cross it, start or end on it or
    inside it, also when its float32 corners scatter about its sides' planes."""
    rng = np.random.default_rng(7)
    cube = subdivided_cube(3, _rotation(1.0, 2.0, 0.5), float32=float32)
    fast = Occluders([cube])
    assert fast.solid_hull[0] is not None
    slow = Occluders([cube])
    slow.solid_hull[0] = None  # (its triangle hierarchy)
    K = 20000
    lo, hi = cube.vertices.min(0) - 1.0, cube.vertices.max(0) + 1.0
    far = rng.uniform(lo, hi, (K, 3))
    C = cube.piece_corners[rng.integers(len(cube.piece_corners), size=K)]
    a, b = rng.uniform(0.01, 0.99, (2, K, 1))
    on = C[:, 0] + a * (C[:, 1] - C[:, 0]) + b * (C[:, 3] - C[:, 0])  # (on its faces)
    inside = cube.vertices.mean(0) + rng.uniform(-0.2, 0.2, (K, 3))
    for p, q in ((far, rng.uniform(lo, hi, (K, 3))), (on, far), (far, on), (inside, far)):
        got = fast.blocked(p, q, np.zeros(K, dtype=np.int64))
        want = slow.blocked(p, q, np.zeros(K, dtype=np.int64))
        assert 0.05 < want.mean() < 0.99
        np.testing.assert_array_equal(got, want)


def test_solve_reports_bvh_counters():
    floor = PolygonMesh(*grid(3, (0, 0, 0), (3, 0, 0), (0, 3, 0)), name="floor")
    box = PolygonMesh(*block(), name="block")
    scene = core.Scene()
    scene.add(floor, reflectance=0.6)
    scene.add(box, reflectance=0.5)
    scene.add(LIGHT, emission=5.0, reflectance=0.0, occluder=False)
    stats = scene.solve(tol=1e-3, threads=1).stats
    assert stats["bvh_nodes"] > 0 and stats["bvh_primitives"] > 0


# ---------------------------------------------------------------- coplanar regions merged
def _factors_from(mesh, centre, normal, uv):
    """F(x -> mesh) at points x of a 2 m square receiver through `centre` facing `normal`, at its
    parameters uv (K, 2): the mesh glows (E = 1, black) and the receiver (reflectance 1/2)
    gathers it with the exact flat integrals, so any two meshes covering the same area give the
    same."""
    scene = core.Scene()
    scene.add(mesh, emission=1.0, reflectance=0.0, patches=(1, 1), occluder=False)
    c, n = np.asarray(centre, float), np.asarray(normal, float) / np.linalg.norm(normal)
    a = np.cross(n, np.eye(3)[np.argmin(np.abs(n))])
    a /= np.linalg.norm(a)
    b = np.cross(n, a)
    receiver = core.Quad(c - a - b, c + a - b, c + a + b, c - a + b)
    h = scene.add(receiver, reflectance=0.5, patches=(1, 1), occluder=False)
    sol = scene.solve(tol=1e-9, threads=1)
    return 2.0 * sol.radiosity_at(h, uv[:, 0], uv[:, 1])[:, 0]


def _float32(V, matrix):
    """Vertices moved by a 4x4 matrix and rounded to float32, as Blender stores them."""
    return (V @ matrix[:3, :3].T + matrix[:3, 3]).astype(np.float32).astype(float)


def test_a_subdivided_plane_merges_into_one_quad():
    """A 48 x 48 grid turned and moved in float32, and a triangulated grid, each become one quad
    over the same area; every face maps to it."""
    V, F = grid(48, (0, 0, 0), (6, 0, 0), (0, 6, 0))
    mesh = PolygonMesh(_float32(V, _rotation(30.0, -20.0, 10.0)), F, two_sided=True, name="floor")
    merged, face_map = mesh.merge_coplanar()
    assert merged.face_count == 1 and merged.loop_totals[0] == 4
    assert merged.two_sided and merged.name == "floor"
    assert np.all(face_map == 0)
    assert abs(merged.area() / mesh.area() - 1.0) < 1e-6
    V, F = grid(6, (0, 0, 0), (1, 0, 0), (0, 1, 0))
    triangles = [t for f in F for t in ([f[0], f[1], f[2]], [f[0], f[2], f[3]])]
    merged, face_map = PolygonMesh(V, triangles).merge_coplanar()
    assert merged.face_count == 1 and merged.loop_totals[0] == 4 and np.all(face_map == 0)
    # Blender's layout for one material's faces: loop starts into corners of other faces too
    corners = np.concatenate([[0, 1, 2]] + triangles[::-1])
    starts = 3 + 3 * np.arange(len(triangles))
    mesh = PolygonMesh(V, loop_starts=starts, loop_totals=np.full(72, 3), corner_verts=corners)
    merged, face_map = mesh.merge_coplanar()
    assert merged.face_count == 1 and np.all(face_map == 0)
    assert merged.area() == pytest.approx(mesh.area(), rel=1e-12)


def test_a_merged_region_is_the_same_surface():
    """An L-shaped grid becomes one concave hexagon (ear-clipped), a float32 tilted grid one quad:
    a point's exact factor toward either is that toward the faces it merged, to 1e-8 (the
    gather's tol: 1e-9)."""
    V, F = grid(4, (0, 0, 0), (2, 0, 0), (0, 2, 0))
    L = PolygonMesh(V, [f for k, f in enumerate(F) if not (k // 4 >= 2 and k % 4 >= 2)])
    merged, face_map = L.merge_coplanar()
    assert merged.face_count == 1 and merged.loop_totals[0] == 6 and np.all(face_map == 0)
    uv = np.array([[0.5, 0.5], [0.1, 0.8], [0.9, 0.2], [0.3, 0.3]])
    for centre, normal in (((1.5, 1.5, 1.0), (0.2, -0.1, -1.0)), ((3.0, 1.0, 0.5), (-1.0, 0.1, -0.3))):
        np.testing.assert_allclose(
            _factors_from(merged, centre, normal, uv), _factors_from(L, centre, normal, uv), rtol=1e-8
        )
    V, F = grid(12, (0, 0, 0), (3, 0, 0), (0, 2, 0))
    M = _rotation(5.0, 1.0, -2.0)
    mesh = PolygonMesh(_float32(V, M), F)
    merged, _ = mesh.merge_coplanar()
    assert merged.face_count == 1
    centre = M[:3, :3] @ (1.0, 1.5, 1.2) + M[:3, 3]
    normal = M[:3, :3] @ (0.3, 0.0, -1.0)
    # (float32 corners scatter 1e-6 around the plane; the merged quad takes its own four)
    np.testing.assert_allclose(
        _factors_from(merged, centre, normal, uv), _factors_from(mesh, centre, normal, uv), rtol=1e-5
    )


def test_only_coplanar_faces_of_one_front_merge():
    """Faces join only across edges they share with one front, in one plane: a grid bent along
    one axis merges into its flat strips, a fold into its two halves; a reversed face, a hole
    and a skipped face leave their faces as they were."""
    V, F = grid(10, (0, 0, 0), (1, 0, 0), (0, 1, 0))
    bent = V.copy()
    bent[:, 2] = 0.3 * V[:, 0] ** 2
    merged, face_map = PolygonMesh(bent, F).merge_coplanar()
    assert merged.face_count == 10
    assert np.all(face_map.reshape(10, 10) == face_map.reshape(10, 10)[:, :1])  # a strip along y
    folded = V.copy()
    folded[:, 2] = np.abs(V[:, 0] - 0.5)
    merged, face_map = PolygonMesh(folded, F).merge_coplanar()
    assert merged.face_count == 2 and sorted(merged.loop_totals) == [4, 4]
    assert np.all(face_map.reshape(10, 10)[:5] == face_map[0]) and np.all(
        face_map.reshape(10, 10)[5:] != face_map[0]
    )
    V, F = grid(4, (0, 0, 0), (1, 0, 0), (0, 1, 0))
    for faces in (
        [f[::-1] if k == 5 else f for k, f in enumerate(F)],  # reversed: the rest has a hole
        [f for k, f in enumerate(F) if k != 5],  # a hole
    ):
        merged, face_map = PolygonMesh(V, faces).merge_coplanar()
        assert merged.face_count == len(faces)
        np.testing.assert_array_equal(face_map, np.arange(len(faces)))
        for k, f in enumerate(faces):
            np.testing.assert_array_equal(merged.corners_of(face_map[k]), f)
    with pytest.warns(UserWarning, match="skipped 1 face"):
        mesh = PolygonMesh(V, F + [[0, 1, 1]])
    merged, face_map = mesh.merge_coplanar()
    assert merged.face_count == 1 and face_map[-1] == -1 and np.all(face_map[:-1] == 0)


def test_a_finely_bent_grid_merges_into_strips_within_the_tolerance():
    """A 120 x 120 grid bent along x, each face within 1e-5 of the mesh's size of its
    neighbours' planes: the chain of faces is split by planes into strips along y, and every
    face's corners lie within that tolerance of the merged face's plane. A grid curved both
    ways keeps nearly all its faces."""
    V, F = grid(120, (0, 0, 0), (1, 0, 0), (0, 1, 0))
    V[:, 2] = 0.01 * V[:, 0] ** 2
    mesh = PolygonMesh(V, F)
    merged, face_map = mesh.merge_coplanar()
    assert 10 < merged.face_count < 120
    assert np.all(face_map.reshape(120, 120) == face_map.reshape(120, 120)[:, :1])
    tolerance = 1e-5 * np.linalg.norm(np.ptp(V, axis=0))
    for k in range(merged.face_count):
        corners = V[np.concatenate([F[f] for f in np.flatnonzero(face_map == k)])]
        normal = merged.face_normal[k]
        centre = V[merged.corners_of(k)].mean(0)
        assert np.abs((corners - centre) @ normal).max() <= 2.0 * tolerance
    assert merged.area() == pytest.approx(mesh.area(), rel=1e-6)
    V[:, 2] = 0.3 * np.sin(3 * V[:, 0]) * np.cos(2 * V[:, 1])
    merged, _ = PolygonMesh(V, F).merge_coplanar()
    assert merged.face_count > 0.95 * len(F)


def test_a_merged_floor_takes_the_visible_side_where_a_box_stands_on_it():
    """A box resting on a floor, its footprint's edge and corner through floor vertices: on the
    floor merged into one quad a vertex there takes the limit on the visible side, as it does
    through the faces around it (the brightest of their corners), not the dark side under the
    box or the half-way value on the edge."""
    V, F = grid(8, (0, 0, 0), (4, 0, 0), (0, 4, 0))
    floor = PolygonMesh(V, F, name="floor")
    merged, _ = floor.merge_coplanar()
    assert merged.face_count == 1
    box = PolygonMesh(*block(lo=(1.0, 1.5, 0.0), hi=(2.0, 2.5, 0.6)), name="box")
    lid = core.Quad((1, 1.5, 0), (1, 2.5, 0), (2, 2.5, 0), (2, 1.5, 0))  # (block has no bottom)
    lamp = core.Quad((1.5, 1.5, 3), (1.5, 2.5, 3), (2.5, 2.5, 3), (2.5, 1.5, 3))
    points = np.array([[2.0, 2.0, 0.0], [2.0, 1.5, 0.0], [2.0 + 1e-4, 2.0, 0.0]])
    values = []
    for mesh in (floor, merged):
        scene = core.Scene()
        h = scene.add(mesh, reflectance=0.5)
        scene.add(box, reflectance=0.5)
        scene.add(lid, reflectance=0.5)
        scene.add(lamp, emission=5.0, reflectance=0.0, occluder=False)
        sol = scene.solve(tol=1e-3, threads=1)
        if mesh is floor:
            around = [[f for f, c in enumerate(F) if np.any(np.all(V[c] == q, axis=1))] for q in points[:2]]
            B = [sol.radiosity_at(h, a, np.repeat(q[None], len(a), 0))[:, 0] for a, q in zip(around, points)]
            assert all(np.ptp(b) == 0.0 for b in B)  # (every corner takes the brightest)
            values.append(np.array([b[0] for b in B]))
        else:
            values.append(sol.radiosity_at(h, [0, 0, 0], points)[:, 0])
    faces, one = values
    # (the two discretisations differ by 0.4 % at tol 1e-3; under the box it is about 0, and
    # on the edge itself 9 % below the visible side)
    np.testing.assert_allclose(one[:2], faces, rtol=1e-2)
    assert one[0] == pytest.approx(one[2], rel=1e-3)  # the edge's vertex: the value beside the box
