"""Closed rooms of two-sided surfaces (Blender's default material) are balanced like one-sided
ones (`closure`: each sheet counts once, its back is its twin), and a mesh vertex's corners on
coplanar faces are gathered once (`Solution.radiosity_at`)."""

import numpy as np
import pytest
from test_mesh import grid

import core

L = 4.0
WALLS = [  # origin, du, dv with du x dv pointing into the box
    ((0, 0, 0), (L, 0, 0), (0, L, 0)),
    ((0, 0, L), (0, L, 0), (L, 0, 0)),
    ((0, 0, 0), (0, L, 0), (0, 0, L)),
    ((L, 0, 0), (0, 0, L), (0, L, 0)),
    ((0, 0, 0), (0, 0, L), (L, 0, 0)),
    ((0, L, 0), (L, 0, 0), (0, 0, L)),
]


def box(two_sided, n=4):
    scene = core.Scene()
    walls = [scene.add(core.PolygonMesh(*grid(n, *w)), reflectance=0.7, two_sided=two_sided) for w in WALLS]
    scene.add(core.Sphere((1.4, 2.2, 1.0), 0.8), reflectance=0.7, patches=(4, 8), two_sided=two_sided)
    scene.add(core.Disk((2, 2, 3.9), (0, 0, -1), 0.4), emission=10.0, reflectance=0.0, occluder=False)
    return scene, walls


@pytest.fixture(scope="module")
def solved():
    out = {}
    for two in (False, True):
        scene, walls = box(two)
        out[two] = (scene.solve(tol=1e-3), walls)
    return out


def test_two_sided_room_is_balanced_as_the_one_sided_one(solved):
    (one, walls), (two, _) = solved[False], solved[True]
    assert one.stats["rows_enclosed"] == two.stats["rows_enclosed"] >= 6 * 16  # (every wall patch)
    a = np.concatenate([one.radiosity(h) for h in walls])
    b = np.concatenate([two.radiosity(h) for h in walls])
    # (unbalanced, the two-sided room was 7.9e-4 of the peak off; sampled visibility errs)
    assert np.abs(a - b).max() <= 2e-4 * a.max()


def test_a_two_sided_room_facing_out_is_balanced_too(solved):
    """Blender's cube has its normals out: as two-sided walls its inside is their back halves. A
    two-sided sheet's orientation is a choice, so the enclosure identity is tried with the sheets
    turned over too (before, no row of such a room was enclosed). Same rows, same radiosities as
    the one-sided room facing in (each wall's patches in another order: u and v swap)."""
    one, walls = solved[False]
    scene = core.Scene()
    meshes = [core.PolygonMesh(*grid(4, o, dv, du)) for o, du, dv in WALLS]  # (du, dv swapped: out)
    turned = [scene.add(mesh, reflectance=0.7, two_sided=True) for mesh in meshes]
    scene.add(core.Sphere((1.4, 2.2, 1.0), 0.8), reflectance=0.7, patches=(4, 8), two_sided=True)
    scene.add(core.Disk((2, 2, 3.9), (0, 0, -1), 0.4), emission=10.0, reflectance=0.0, occluder=False)
    out = scene.solve(tol=1e-3)
    assert out.stats["rows_enclosed"] == one.stats["rows_enclosed"] >= 6 * 16
    a = np.concatenate([np.sort(one.radiosity(h).sum(1)) for h in walls])
    b = np.concatenate([np.sort(out.radiosity(h, side="back").sum(1)) for h in turned])
    assert np.abs(a - b).max() <= 2e-4 * a.max()


def test_outside_of_a_two_sided_room_stays_dark(solved):
    two, walls = solved[True]
    for h in walls:
        assert np.all(two.radiosity(h, side="back") == 0.0)


def test_coplanar_corners_of_a_vertex_are_one_gather(solved):
    sol, walls = solved[True]
    n = 4
    V, F = grid(n, *WALLS[0])
    vertex = 2 * (n + 1) + 1  # inside the floor, next to the sphere's shadow
    faces = np.array([f for f, quad in enumerate(F) if vertex in quad])
    together = sol.radiosity_at(walls[0], faces, V[[vertex] * faces.size])
    alone = np.concatenate([sol.radiosity_at(walls[0], faces[[k]], V[[vertex]]) for k in range(faces.size)])
    assert np.allclose(together, together[0], rtol=0, atol=0)
    assert np.abs(alone - together).max() <= 3e-2 * together.max()


def test_gather_factors_take_repeats_points_in_order(solved):
    sol, walls = solved[True]
    n = 4
    V, F = grid(n, *WALLS[0])
    faces = np.array([0, 5, 9])
    points = np.array([np.mean(V[list(F[f])], axis=0) for f in faces])
    factors = sol.gather_factors(walls[0], faces, points)
    index = np.array([2, 0, 0, 1])
    taken = factors.take(index)
    assert len(taken) == index.size
    assert np.allclose(sol.radiosity_from(taken), sol.radiosity_from(factors)[index], rtol=1e-12, atol=0)


def test_free_pairs_skip_rays_without_changing_the_gather(solved, monkeypatch):
    """A pair whose element shaft held no occluder leaves every point of its elements free: the
    gather makes no occluder query for it, and its values are those of a gather that does, to
    tol (that gather spends part of its ray budget on them, see `_beyond_budget`)."""
    sol, walls = solved[True]
    n = 4
    V, F = grid(n, *WALLS[0])
    faces = np.repeat(np.arange(len(F)), 4)
    points = V[np.array(F).ravel()]
    geometry = sol._geometry  # (the test reaches into the solution to count and switch the rule)
    queries = []
    original = geometry.shafts.point_candidates

    def counted(x, *args):
        queries.append(len(x))
        return original(x, *args)

    sol.radiosity_at(walls[0], faces[:1], points[:1])  # (the near field, built once)
    monkeypatch.setattr(geometry.shafts, "point_candidates", counted)
    fast = sol.radiosity_at(walls[0], faces, points)
    fast_queries = sum(queries)
    monkeypatch.setattr(geometry, "known_free", lambda a, b: np.zeros(np.shape(a), dtype=bool))
    queries.clear()
    slow = sol.radiosity_at(walls[0], faces, points)
    assert fast_queries < sum(queries)
    assert np.abs(fast - slow).max() <= 1e-3 * fast.max()  # (the solve's tol)


def cube_mesh(lo=0.0, hi=L, n=2, inward=True):
    """A cube as one PolygonMesh of six n x n grids (faces inward or outward)."""
    vertices, faces = [], []
    for o, du, dv in WALLS:
        o, du, dv = (np.asarray(x, dtype=float) * (hi - lo) / L for x in (o, du, dv))
        V, F = grid(n, o + lo, du, dv)
        F = [f if inward else f[::-1] for f in F]
        faces += [[v + len(vertices) for v in f] for f in F]
        vertices += list(V)
    return core.PolygonMesh(np.array(vertices), faces)


def test_front_hull_of_rooms_and_solids():
    room = cube_mesh(inward=True)
    normal, offset = room.front_hull
    assert normal.shape == (6, 3) and offset.shape == (6,)
    assert cube_mesh(inward=False).front_hull is None  # (a solid seen from outside)
    # an L-shaped floor plan is not convex: no hull
    V = np.array([[0, 0, 0], [2, 0, 0], [2, 1, 0], [1, 1, 0], [1, 2, 0], [0, 2, 0]], float)
    V = np.vstack([V, V + [0, 0, 1]])
    walls = [[k, (k + 1) % 6, (k + 1) % 6 + 6, k + 6] for k in range(6)]
    assert core.PolygonMesh(V, walls).front_hull is None
    assert core.PolygonMesh(V, [[0, 1, 2, 3, 4, 5]]).front_hull is not None  # (one plane)


def test_a_convex_room_mesh_blocks_nothing_inside_it(monkeypatch):
    """Segments between points inside a convex room never meet its walls: the room is no
    candidate occluder for them, so its rays are not cast, and the solution is the same (the
    gathered points to tol)."""

    def solve():
        scene = core.Scene()
        room = scene.add(cube_mesh(n=3), reflectance=0.7, two_sided=True)
        scene.add(core.Sphere((1.4, 2.2, 0.8), 0.8), reflectance=0.5, patches=(4, 8))
        scene.add(core.Disk((2, 2, 3.9), (0, 0, -1), 0.4), emission=10.0, reflectance=0.0, occluder=False)
        # (rays on both sides: with the room no candidate, exact shadows would take over the
        # emitter's pairs, a different method)
        sol = scene.solve(tol=1e-3, occlusion="sampled")
        sol.near_field = False  # (the room's seams would build ~56k near-field nodes per solve)
        faces = np.arange(3 * 3)  # the floor's faces, at their centres
        centres = np.array([np.mean(room_vertices[list(f)], axis=0) for f in room_faces[:9]])
        return sol, sol.radiosity(room), sol.radiosity_at(room, faces, centres)

    mesh = cube_mesh(n=3)
    room_vertices, room_faces = (
        mesh.vertices,
        [mesh.corner_verts[s : s + t] for s, t in zip(mesh.loop_starts, mesh.loop_totals)],
    )
    fast, per_face, at_points = solve()
    monkeypatch.setattr(core.PolygonMesh, "front_hull", property(lambda self: None))
    slow, per_face_slow, at_points_slow = solve()
    assert fast.stats["rays"] < slow.stats["rays"]
    assert np.allclose(per_face, per_face_slow, rtol=1e-9, atol=0)
    # (gathered points to tol: a pair that has an occluder in its shaft joins the point's ray
    # budget, so the two runs spend their budgets on different pairs)
    assert np.abs(at_points - at_points_slow).max() <= 1e-3 * at_points.max()


def test_convex_solid_mesh_is_its_own_surfaces_no_occluder(monkeypatch):
    """A mesh around a convex solid (fronts outward) never blocks a segment leaving its front:
    fewer rays, the same solution."""
    assert cube_mesh(inward=False).convex_solid and not cube_mesh(inward=True).convex_solid

    def solve():
        scene = core.Scene()
        floor = scene.add(core.Quad((-3, -3, 0), (3, -3, 0), (3, 3, 0), (-3, 3, 0)), reflectance=0.6)
        block = scene.add(cube_mesh(lo=0.0, hi=1.0, n=2, inward=False), reflectance=0.6)  # (resting)
        scene.add(core.Disk((1.8, 1.2, 2.5), (0, 0, -1), 0.3), emission=10.0, reflectance=0.0, occluder=False)
        sol = scene.solve(tol=1e-3)
        sol.exact_shadows = False
        u = np.linspace(0.05, 0.95, 7)
        return sol, sol.radiosity(block), sol.radiosity_at(floor, u, u[::-1])

    fast, block_fast, floor_fast = solve()
    monkeypatch.setattr(core.PolygonMesh, "convex_solid", property(lambda self: False))
    slow, block_slow, floor_slow = solve()
    assert fast.stats["rays"] < slow.stats["rays"]
    assert np.allclose(block_fast, block_slow, rtol=1e-9, atol=0)
    assert np.allclose(floor_fast, floor_slow, rtol=1e-9, atol=0)


def _translation(x, y, z):
    matrix = np.eye(4)
    matrix[:3, 3] = (x, y, z)
    return matrix


def _box_room(room, at, box_cells=1, lamp=None):
    """A room mesh (reflectance 0.7) with a 1 m box (0.5) resting on its floor at (x, y) = at and
    a lamp (default a disk under the ceiling), solved at tol 1e-2: (room handle, solution)."""
    scene = core.Scene()
    handle = scene.add(room, reflectance=0.7)
    box = cube_mesh(lo=0.0, hi=1.0, n=box_cells, inward=False).transformed(_translation(*at, 0.0))
    scene.add(box, reflectance=0.5)
    lamp = lamp if lamp is not None else core.Disk((2, 2, 3.9), (0, 0, -1), 0.4)
    scene.add(lamp, emission=10.0, reflectance=0.0, occluder=False)
    return handle, scene.solve(tol=1e-2)


def test_points_under_a_box_resting_on_the_floor_are_dark():
    """A box resting on the floor of a closed room: floor points strictly under it see nothing
    (Cycles gives them 0). Their floor patches, partly under it, see most of the room, and a
    gather that took those patches' partial visibility for every pair whose share was below tol
    of the point's light summed many such shares: 7-22 % of the floor's mean here, 9-33 % in the
    2,096-polygon mesh room (`benchmarks.mesh_room`). Rays now go to the largest reused shares
    whose shafts hold an occluder until what is left adds up to at most tol of the point's
    light."""
    room, solution = _box_room(cube_mesh(n=4), (1.3, 1.1))
    faces = np.arange(16)  # (the room mesh's first faces are the floor's, z = 0, 1 m cells)
    level = solution.radiosity(room)[faces, 0].mean()
    # points 2 cm or more inside the box's footprint [1.3, 2.3] x [1.1, 2.1]
    # (the last two on floor patches the box barely covers: their pair visibility is 1 toward
    # most of the room, and points on them got 23-30 %)
    x = np.array([[1.32, 1.12, 0.0], [1.8, 1.6, 0.0], [2.28, 1.8, 0.0], [2.28, 2.08, 0.0], [1.32, 2.08, 0.0]])
    face = np.array([int(p[0] // 1.0) * 4 + int(p[1] // 1.0) for p in x])
    under = solution.radiosity_at(room, face, x)[:, 0]
    assert level > 0 and np.all(np.abs(under) <= 1e-2 * level), under / level


def _room_with_floor(xs, ys):
    """The room of cube_mesh(n=4) with its floor a grid on the lines xs, ys (the first faces,
    row by row along y)."""
    vertices, faces = [], []
    for i in range(len(xs) - 1):
        for j in range(len(ys) - 1):
            faces.append([len(vertices) + c for c in range(4)])
            vertices += [
                (xs[i], ys[j], 0),
                (xs[i + 1], ys[j], 0),
                (xs[i + 1], ys[j + 1], 0),
                (xs[i], ys[j + 1], 0),
            ]
    for o, du, dv in WALLS[1:]:
        V, F = grid(4, *(np.asarray(a, dtype=float) for a in (o, du, dv)))
        faces += [[v + len(vertices) for v in f] for f in F]
        vertices += list(V)
    return core.PolygonMesh(np.array(vertices, dtype=float), faces)


def test_points_near_a_box_agree_with_a_floor_cut_along_its_edges():
    """Floor points next to and under a box resting on the floor, on patches the box partly
    covers, against the same points on a floor whose patches are cut along the box's edges (no
    patch there is partly covered, so no pair's visibility misleads a point). A point just
    outside the box on a patch mostly under it reused that patch's V = 0 toward most of the room
    (12 % of the light too dark), one under the box on a patch it barely covers V = 1 (26-34 %
    too bright)."""
    x = np.array(
        [
            [1.95, 1.05, 0.0],  # outside, 5 cm from the box, on a patch 63 % under it
            [1.5, 1.05, 0.0],
            [1.25, 1.5, 0.0],
            [2.28, 2.08, 0.0],  # under it, on a patch 3 % under it
            [2.05, 2.05, 0.0],
            [1.32, 2.08, 0.0],
            [2.35, 1.5, 0.0],
            [1.5, 2.15, 0.0],
        ]
    )

    def gathered(xs, ys):
        room, solution = _box_room(_room_with_floor(xs, ys), (1.3, 1.1))
        face = (np.searchsorted(xs, x[:, 0]) - 1) * (len(ys) - 1) + np.searchsorted(ys, x[:, 1]) - 1
        return solution.radiosity_at(room, face, x)[:, 0]

    metres = np.arange(5.0)
    plain = gathered(metres, metres)
    cut = gathered(np.array([0, 1, 1.3, 2, 2.3, 3, 4.0]), np.array([0, 1, 1.1, 2, 2.1, 3, 4.0]))
    # (measured: within 1.4 % of the brightest point; the two floors' elements differ)
    assert np.all(np.abs(plain - cut) <= 3e-2 * cut.max()), (plain - cut) / cut.max()


def test_a_floor_vertex_on_a_box_edge_takes_its_visible_side():
    """A floor vertex on the edge of a box resting on the floor has corners under the box and
    beside it. Each corner's point moves into its face, so the one gather its coplanar corners
    shared came out 0 when the first corner lay under the box (in the mesh room, where Cycles'
    vertex bake, the mean of the corners, gives half the value beside the box). A vertex
    touching another object gathers its corners one by one and takes the brightest: the limit
    on its visible side, what a render shows beside the box."""
    room, solution = _box_room(cube_mesh(n=8), (1.0, 1.0))
    # floor cell (i, j) of 0.5 m is face 8 i + j; the vertex (2, 1.5) lies on the box's side x = 2
    faces = np.array([3 * 8 + 2, 4 * 8 + 3, 3 * 8 + 3, 4 * 8 + 2])  # (x in [1.5, 2]: under the box)
    x = np.tile([2.0, 1.5, 0.0], (4, 1))
    together = solution.radiosity_at(room, faces, x)[:, 0]
    alone = np.array([solution.radiosity_at(room, faces[k : k + 1], x[:1])[0, 0] for k in range(4)])
    beside = solution.radiosity_at(room, faces[1:2], np.array([[2.001, 1.5, 0.0]]))[0, 0]
    assert np.all(alone[[0, 2]] <= 1e-2 * alone.max())  # (the corners under the box)
    np.testing.assert_allclose(together, alone.max(), rtol=1e-12)
    assert abs(together[0] - beside) <= 1e-2 * beside  # (measured: 0.3 %)
    # which vertices count as touching (the test reaches into the solution): on or in the box,
    # near the room's walls; not the top of the box, which lies in the room's box but away from
    # its walls (every vertex in a room of one mesh would have its corners gathered one by one)
    touching = solution._geometry.touching
    assert list(touching(room, np.array([[2.0, 1.5, 0.0], [1.5, 1.5, 0.0], [3.0, 3.0, 0.0]]))) == [1, 1, 0]
    assert list(touching(room + 1, np.array([[1.0, 1.0, 0.0], [1.5, 1.5, 1.0], [1.0, 1.5, 0.5]]))) == [
        1,
        0,
        0,
    ]


def test_a_subdivided_box_casts_the_exact_shadow_of_its_facets():
    """A closed convex mesh of many faces (Blender's cube subdivided: 96) takes part in exact
    shadows as its 6 facets (`PolygonMesh.solid_facets`): across the penumbra it casts from a
    square lamp the floor gets what the same box given as 6 quads gives (rays over its 96 faces
    were 8 % of the brightest off there)."""

    def penumbra(n):
        lamp = core.Quad((1.5, 1.5, 3.9), (2.5, 1.5, 3.9), (2.5, 2.5, 3.9), (1.5, 2.5, 3.9)).flipped()
        room, solution = _box_room(cube_mesh(n=4), (1.0, 1.0), box_cells=n, lamp=lamp)
        x = np.column_stack([np.full(12, 1.5), np.linspace(2.02, 2.4, 12), np.zeros(12)])
        return solution.radiosity_at(room, np.full(12, 1 * 4 + 2), x)[:, 0]

    assert cube_mesh(lo=0.0, hi=1.0, n=4, inward=False).solid_facets().face_count == 6
    quads, subdivided = penumbra(1), penumbra(4)
    assert quads[0] < 0.8 * quads[-1]  # (a penumbra)
    assert np.abs(subdivided - quads).max() <= 2e-3 * quads.max()  # (measured: 3e-4)


def test_mesh_points_may_name_their_faces_in_any_order():
    """radiosity_at on a mesh with its faces out of order gives each point what it gets alone (the
    chosen piece's normal was looked up in the candidates as if they were sorted: an IndexError
    or a wrong "not on face" check)."""
    scene = core.Scene()
    room = scene.add(cube_mesh(n=4), reflectance=0.7)
    scene.add(core.Disk((2, 2, 3.9), (0, 0, -1), 0.4), emission=10.0, reflectance=0.0, occluder=False)
    solution = scene.solve(tol=1e-2)
    x = np.array([[2.5, 2.5, 0.0], [1.5, 1.5, 0.0], [2.5, 1.2, 0.0], [0.5, 3.5, 0.0]])
    face = np.array([10, 5, 9, 3])
    together = solution.radiosity_at(room, face, x)
    alone = np.concatenate([solution.radiosity_at(room, face[k : k + 1], x[k : k + 1]) for k in range(4)])
    np.testing.assert_allclose(together, alone, rtol=1e-12)
