"""Exact shadows of polygon meshes of any shape (`core.occluded.ExactShadows`, `core.shadow`).

A mesh's flat pieces each shadow one interval of a line on the target; the intervals are merged by
one sort, and only silhouette edges (between pieces seen from opposite sides, or on the mesh's
border) add breaks across lines. References: randomised QMC with its own ray-triangle tests
(`tests/reference/occluded_mc.py`), its error bar well below the tol tested.
"""

import numpy as np
import pytest
from reference.occluded_mc import point_factor

import core
from core import occluded
from core.occluded import ExactShadows

TARGET = ((-1.5, -1.5, 2.0), (0.0, 3.0, 0.0), (3.0, 0.0, 0.0))  # corner, edges: front = -z


def bumpy_ball(center, radius, nu, nv, bump=0.25):
    """A closed, concave UV ball with three bumps around its axis: vertices and faces (outward)."""
    center = np.asarray(center, float)
    ring = []
    for j in range(1, nv):
        theta = np.pi * j / nv
        for i in range(nu):
            phi = 2 * np.pi * i / nu
            r = radius * (1 + bump * np.cos(3 * phi) * np.sin(theta))
            ring.append(
                r * np.array([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)])
            )
    V = np.array(ring + [(0, 0, radius), (0, 0, -radius)]) + center
    top, bottom = len(V) - 2, len(V) - 1

    def at(j, i):
        return (j - 1) * nu + i % nu

    faces = [(top, at(1, i), at(1, i + 1)) for i in range(nu)]
    faces += [(bottom, at(nv - 1, i + 1), at(nv - 1, i)) for i in range(nu)]
    faces += [
        (at(j, i), at(j + 1, i), at(j + 1, i + 1), at(j, i + 1)) for j in range(1, nv - 1) for i in range(nu)
    ]
    return V, faces


def wavy_sheet(n=4):
    """An open, non-planar n x n grid of quads tilted across the target's view."""
    s = np.linspace(-0.6, 0.6, n + 1)
    u, v = np.meshgrid(s, s, indexing="ij")
    z = 0.9 + 0.3 * u + 0.15 * np.sin(3 * v)
    V = np.column_stack([u.ravel() - 0.2, v.ravel() + 0.1, z.ravel()])
    faces = [
        (i * (n + 1) + j, (i + 1) * (n + 1) + j, (i + 1) * (n + 1) + j + 1, i * (n + 1) + j + 1)
        for i in range(n)
        for j in range(n)
    ]
    return V, faces


MESHES = {
    "closed concave ball": lambda: bumpy_ball((0.1, 0.0, 1.0), 0.45, 8, 4),
    "open wavy sheet": wavy_sheet,
}


def target_quad():
    c, u, v = (np.array(p) for p in TARGET)
    return core.Quad(c, c + u, c + u + v, c + v)


@pytest.mark.parametrize("which", MESHES)
def test_mesh_shadow_against_quasi_monte_carlo(which):
    """A tilted point under a mesh of many pieces: the exact visible factor, asked to tol 1e-4, is
    within 2e-4 of QMC past the mesh's triangles (whose error bar is under 3e-5); the mesh does cast
    a shadow, and only silhouette edges were kept as breaks."""
    V, faces = MESHES[which]()
    mesh = core.PolygonMesh(V, faces)
    assert 1 < len(mesh.piece_corners) <= occluded.MESH_PIECES
    shadows = ExactShadows([target_quad()], [mesh])
    x = np.array([[0.1, 0.2, 0.0]])
    n = np.array([[0.3, 0.1, 1.0]]) / np.linalg.norm([0.3, 0.1, 1.0])
    j, candidates = np.zeros(1, np.int64), np.ones((1, 1), bool)
    assert shadows.exact(j, candidates)[0]
    F, free, lines = shadows.visible(x, n, j, candidates, 1e-4)
    row, piece, edges = shadows.mesh_pieces(x, j, candidates)
    assert not free[0] and lines > 0 and piece.size > 1
    assert 0 < edges.sum() < edges.size  # (interior edges dropped from the breaks)
    triangles, _ = mesh.triangles()
    reference, se = point_factor(x[0], n[0], TARGET, triangles=triangles, count=1 << 19, shifts=8)
    unoccluded, _ = point_factor(x[0], n[0], TARGET, count=1 << 14, shifts=4)
    assert se < 3e-5 * reference
    assert reference < 0.95 * unoccluded
    assert abs(F[0] - reference) <= 2e-4 * reference + 4 * se


def emitting_floor_scene(occluder, patches=(2, 2)):
    """An emitting floor [-1, 1]^2 (E = 1, the only light), a ceiling at z = 2 (rho 0.5, `patches`)
    and a black occluder between: (scene, ceiling handle, ceiling quad)."""
    floor = core.Quad((-1, -1, 0), (1, -1, 0), (1, 1, 0), (-1, 1, 0))
    ceiling = core.Quad((-1, -1, 2), (-1, 1, 2), (1, 1, 2), (1, -1, 2))
    scene = core.Scene()
    scene.add(floor, emission=1.0, reflectance=0.0)
    top = scene.add(ceiling, reflectance=0.5, patches=patches)
    scene.add(occluder, reflectance=0.0)
    return scene, top, ceiling


def test_scene_mesh_occluder_is_exact():
    """A closed concave mesh ball of 18 pieces between an emitting floor and a ceiling: its shadows
    are exact (no rays in the gather) and gathered points agree with QMC past its triangles
    (`test_shadow.check_gather_against_qmc`)."""
    from test_shadow import check_gather_against_qmc

    V, faces = bumpy_ball((0.1, 0.0, 1.0), 0.45, 6, 3)
    mesh = core.PolygonMesh(V, faces)
    scene, top, ceiling = emitting_floor_scene(mesh)
    solution = scene.solve(tol=1e-3)
    assert solution.stats["pairs_exact"] > 0
    check_gather_against_qmc(solution, top, ceiling, triangles=mesh.triangles()[0])
    assert solution.stats["gather_rays"] == 0


def test_a_mesh_of_more_pieces_keeps_rays():
    """Past MESH_PIECES pieces a mesh's shadows are sampled (the stats say so), not refused."""
    V, faces = bumpy_ball((0.1, 0.0, 1.0), 0.45, 16, 6)
    mesh = core.PolygonMesh(V, faces)
    assert len(mesh.piece_corners) > occluded.MESH_PIECES
    scene, top, _ = emitting_floor_scene(mesh)
    solution = scene.solve(tol=1e-3)
    assert solution.stats["rays"] > 0 and solution.stats["pairs_exact"] == 0
    assert np.all(np.isfinite(solution.radiosity(top)))


def test_a_patch_of_an_occluding_piece_is_not_shadowed_by_it():
    """A target that is a patch of one of the mesh's own pieces (as every mesh element is in a scene)
    lies in that piece's plane: rounding there once flickered the shadow line by line (a solve of a
    reflective mesh ball never ended). The factor equals that past the mesh without the piece's
    face, and a point in a piece's plane is not shadowed by the piece either."""
    V, faces = bumpy_ball((0.1, 0.0, 1.0), 0.45, 6, 3)
    mesh = core.PolygonMesh(V, faces)
    # a planar quad piece that the floor point faces
    x = np.array([[-0.9, -0.2, 0.0]])
    n = np.array([[0.0, 0.0, 1.0]])
    quads = np.flatnonzero(mesh.piece_vertices[:, 3] != mesh.piece_vertices[:, 0])
    facing = [
        q for q in quads if (x[0] - mesh.piece_corners[q].mean(0)) @ mesh.face_normal[mesh.piece_face[q]] > 0
    ]
    piece = facing[0]
    target = mesh.pieces()[piece].split(2, 2)[1]
    others = [f for k, f in enumerate(faces) if k != mesh.piece_face[piece]]
    without = core.PolygonMesh(V, others)
    j, candidates = np.zeros(1, np.int64), np.ones((1, 1), bool)
    values = []
    for occluder in (mesh, without):
        shadows = ExactShadows([target], [occluder])
        F, free, _ = shadows.visible(x, n, j, candidates, 1e-6)
        if free[0]:  # (no shadow: the unoccluded factor)
            targets = core.shadow.FlatTargets(shadows.corners[:1], shadows.normal[:1])
            F, _, _ = core.shadow.visible_factor(x, n, targets, core.shadow.Blockers.none(1), 1e-9)
        values.append(F[0])
    assert values[0] > 0
    assert abs(values[0] - values[1]) <= 1e-6 * values[1]
    # x on a piece: that piece (its plane through x) casts nothing, whatever rounding says
    on = mesh.piece_corners[piece].mean(0)[None] + 1e-17
    shadows = ExactShadows([core.Quad((-1, -1, 0), (1, -1, 0), (1, 1, 0), (-1, 1, 0)).flipped()], [mesh])
    rows, pieces, _ = shadows.mesh_pieces(on, j, candidates)
    assert piece not in pieces


def test_a_closed_mesh_counts_the_pieces_a_segment_crosses_first():
    """Of a closed mesh only the pieces x sees from the front count when x is outside it, only those
    it sees from the back when inside (the mesh turned inside out: a room); an open mesh keeps both
    sides. The factors still agree with QMC (`test_mesh_shadow_against_quasi_monte_carlo`)."""
    V, faces = bumpy_ball((0.0, 0.0, 1.0), 0.9, 8, 4)
    ball = core.PolygonMesh(V, faces)
    room = ball.flipped()
    j, candidates = np.zeros(1, np.int64), np.ones((1, 1), bool)
    inside = np.array([[0.05, 0.02, 0.6]])
    target = core.Quad((-0.6, -0.6, 1.3), (-0.6, 0.6, 1.3), (0.6, 0.6, 1.3), (0.6, -0.6, 1.3))
    for mesh, x, front in (
        (ball, np.array([[0.1, 0.2, -1.0]]), True),
        (room, np.array([[0.1, 0.2, -1.0]]), False),
        (room, inside, True),
        (ball, inside, False),
    ):
        shadows = ExactShadows([target_quad() if x[0, 2] < -0.5 else target], [mesh])
        _, piece, _ = shadows.mesh_pieces(x, j, candidates)
        facing = np.einsum("ki,ki->k", x - shadows.piece_center[piece], shadows.piece_normal[piece]) > 0
        assert piece.size and np.all(facing == front)
    sheet = core.PolygonMesh(*wavy_sheet())
    shadows = ExactShadows([target_quad()], [sheet])
    assert shadows.mesh_orientation[0] == 0
    assert tuple(ExactShadows([target], [m]).mesh_orientation[0] for m in (ball, room)) == (1, -1)
