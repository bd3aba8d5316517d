"""Closed-form occluded point factors (`core.cones`): the target's cone minus the occluders' cones.

References: the line integrals of `core.shadow` (a different algorithm: clipping along lines in the
target's plane, closed-form line integrals, Gauss-Kronrod across lines) at tol 1e-11 with the
closed form switched off; randomised QMC with its own ray tests (`tests/reference/occluded_mc.py`)
where shadows overlap; exact values (a sphere wholly inside a target's view: F_target - (r/d)^2
cos(gamma), Siegel & Howell app. C) in `test_shadow.py`, which now run through this path.
"""

import numpy as np
import pytest
from reference.occluded_mc import point_factor

import core.shadow as shadow
from core.cones import MAX_CONES, MAX_OVERLAPS, cone_visible_factor, round_spheres
from core.polygon import point_to_polygon
from core.shadow import Blockers, FlatTargets, visible_factor

SQUARE = np.array([(-1, -1, 0), (1, -1, 0), (1, 1, 0), (-1, 1, 0)], float)


def random_scene(K, seed):
    """K queries over the unit square (front +z): tilted normals, two spheres and a triangle
    between x and the square (each present with some probability, overlapping at times)."""
    rng = np.random.default_rng(seed)
    x = np.stack([rng.uniform(-2, 2, K), rng.uniform(-2, 2, K), rng.uniform(1.5, 4, K)], 1)
    n = rng.normal(size=(K, 3))
    n[:, 2] -= 1.5
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    radius = rng.uniform(0.1, 0.4, (K, 2))
    linear = radius[..., None, None] * np.eye(3)
    offset = x[:, None] * rng.uniform(0.3, 0.7, (K, 2, 1)) + rng.normal(scale=0.3, size=(K, 2, 3))
    offset[..., 2] = np.maximum(offset[..., 2], radius + 0.01)
    tri = x[:, None, None] * 0.5 + rng.normal(scale=0.4, size=(K, 1, 4, 3))
    tri[:, :, 3] = tri[:, :, 0]
    tri[..., 2] = np.clip(tri[..., 2], 0.05, None)
    blockers = Blockers(linear, offset, rng.uniform(size=(K, 2)) < 0.8, tri, rng.uniform(size=(K, 1)) < 0.7)
    corners = np.broadcast_to(SQUARE, (K, 4, 3)).copy()
    normal = np.tile([0.0, 0.0, 1.0], (K, 1))
    return x, n, corners, normal, blockers


def lines_only(monkeypatch, x, n, corners, normal, blockers, tol):
    monkeypatch.setattr(
        shadow, "cone_visible_factor", lambda x, *_: (np.zeros(len(x)), np.zeros(len(x), bool))
    )
    F, _, lines = visible_factor(x, n, FlatTargets(corners, normal), blockers, tol)
    assert lines > 0
    return F


def test_matches_line_integrals(monkeypatch):
    """Spheres and triangles, alone and overlapping, tilted normals cut by the horizon: the closed
    form agrees with the independent line integrals at tol 1e-11."""
    x, n, corners, normal, blockers = random_scene(200, seed=0)
    F, done = cone_visible_factor(x, n, corners, normal, blockers)
    assert done.all()
    reference = lines_only(monkeypatch, x, n, corners, normal, blockers, 1e-11)
    assert np.abs(F - reference).max() <= 1e-12
    assert np.count_nonzero(F < 0.999 * reference) == 0 and (F > 0).mean() > 0.5


def test_overlapping_shadows_against_qmc():
    """Two spheres and a triangle whose shadows overlap on the target, against QMC with its own
    ray tests (error bar ~1e-5 of the value)."""
    x = np.array([0.2, -0.1, 3.0])
    n = np.array([0.1, 0.0, -1.0])
    n /= np.linalg.norm(n)
    balls = [((0.0, 0.0, 1.5), 0.35), ((0.3, 0.1, 1.2), 0.3)]
    triangle = ((-0.5, -0.2, 2.0), (0.4, -0.6, 2.1), (0.0, 0.4, 1.9))
    blockers = Blockers(
        np.array([[np.eye(3) * r for _, r in balls]]),
        np.array([[c for c, _ in balls]]),
        np.ones((1, 2), bool),
        np.array([[list(triangle) + [triangle[0]]]]),
        np.ones((1, 1), bool),
    )
    F, done = cone_visible_factor(
        x[None], n[None], (SQUARE * 1.5)[None], np.array([[0.0, 0.0, 1.0]]), blockers
    )
    assert done[0]
    target = ((-1.5, -1.5, 0.0), (3.0, 0.0, 0.0), (0.0, 3.0, 0.0))  # front (3,0,0) x (0,3,0) = +z
    mean, se = point_factor(x, n, target, balls, [triangle], count=1 << 17)
    assert abs(F[0] - mean) <= 4 * se + 1e-12
    assert se < 1e-4 * mean


def test_wholly_hidden_is_zero():
    """A sphere whose cone holds the whole target leaves exactly nothing."""
    x, n = np.array([[0.0, 0.0, 3.0]]), np.array([[0.0, 0.0, -1.0]])
    corners = (SQUARE * 0.2)[None]
    blockers = Blockers(
        np.eye(3)[None, None] * 0.5,
        np.array([[[0.0, 0.0, 1.5]]]),
        np.ones((1, 1), bool),
        np.zeros((1, 0, 4, 3)),
        np.zeros((1, 0), bool),
    )
    F, done = cone_visible_factor(x, n, corners, np.array([[0.0, 0.0, 1.0]]), blockers)
    assert done[0] and F[0] == 0.0


def test_touching_sphere_and_straddling_sphere():
    """A sphere resting on the target's plane is covered; one that cuts the plane is left to the
    line integrals (its shadow is not its cone)."""
    x, n = np.array([[0.5, 0.2, 2.0]] * 2), np.array([[0.0, 0.0, -1.0]] * 2)
    corners = np.broadcast_to(SQUARE * 2, (2, 4, 3))
    blockers = Blockers(
        np.broadcast_to(np.eye(3) * 0.5, (2, 1, 3, 3)),
        np.array([[[0.0, 0.0, 0.5]], [[0.0, 0.0, 0.3]]]),
        np.ones((2, 1), bool),
        np.zeros((2, 0, 4, 3)),
        np.zeros((2, 0), bool),
    )
    F, done = cone_visible_factor(x, n, corners, np.array([[0.0, 0.0, 1.0]] * 2), blockers)
    assert done.tolist() == [True, False]
    reference, _, _ = visible_factor(
        x[:1], n[:1], FlatTargets(corners[:1], np.array([[0.0, 0.0, 1.0]])), blockers.take(slice(0, 1)), 1e-10
    )
    assert abs(F[0] - reference[0]) <= 1e-12


def test_polygons_through_the_target_plane_are_clipped(monkeypatch):
    """Triangles and quads that cross the target's plane, lie wholly behind it, or lean 4e-8
    behind it where they meet it (a wall standing on a floor, both read from float32 data): the
    part behind the plane blocks nothing, so the clipped polygon's cone is exact. Against the
    independent line integrals at tol 1e-11."""
    rng = np.random.default_rng(11)
    K = 120
    x = np.stack([rng.uniform(-1.5, 1.5, K), rng.uniform(-1.5, 1.5, K), rng.uniform(1.0, 3.0, K)], 1)
    n = rng.normal(size=(K, 3))
    n[:, 2] -= 1.5
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    poly = x[:, None, None] * 0.4 + rng.normal(scale=0.6, size=(K, 2, 4, 3))
    poly[:, 0, 3] = poly[:, 0, 0]  # a triangle, then a (flattened) quad
    poly[:, 1, :, 2] = 0.0
    poly[:, 1] = poly[:, 1, :1] + np.array([[0, 0, 0], [0.8, 0, 0], [0.8, 0, 0.9], [0, 0, 0.9]])[None]
    poly[:, 1, :, 2] += rng.uniform(-0.6, 0.2, (K, 1))  # crossing the plane z = 0, or wholly below
    poly[:60, 1, :2, 2] = -4e-8  # a wall on the floor, leaning 4e-8 behind it
    poly[60:90, 0, :, 2] = rng.uniform(-0.8, -0.1, (30, 4))  # wholly behind: blocks nothing
    poly[60:90, 0, 3] = poly[60:90, 0, 0]
    blockers = Blockers(
        np.zeros((K, 0, 3, 3)), np.zeros((K, 0, 3)), np.zeros((K, 0), bool), poly, np.ones((K, 2), bool)
    )
    corners = np.broadcast_to(SQUARE, (K, 4, 3)).copy()
    normal = np.tile([0.0, 0.0, 1.0], (K, 1))
    F, done = cone_visible_factor(x, n, corners, normal, blockers)
    assert done.all()
    assert np.count_nonzero(poly[..., 2].min(-1) < 0) > K  # (most cross or lie behind)
    reference = lines_only(monkeypatch, x, n, corners, normal, blockers, 1e-11)
    assert np.abs(F - reference).max() <= 1e-12
    unoccluded, _ = point_to_polygon(x, n, corners, normal)
    assert np.all(F <= unoccluded + 1e-15) and np.count_nonzero(F < 0.99 * unoccluded) > K // 3


def test_ellipsoids_and_many_occluders_fall_back():
    """Elliptic cones, more than MAX_CONES occluders, and an occluder whose cone meets more than
    MAX_OVERLAPS others' are not covered."""
    x, n = np.array([[0.0, 0.0, 3.0]]), np.array([[0.0, 0.0, -1.0]])
    linear = np.array([[np.diag([0.3, 0.3, 0.2])]])
    assert np.isnan(round_spheres(np.linalg.inv(linear), np.zeros((1, 1, 3))))[0, 0]
    rotated = np.array([[[[0, -0.3, 0], [0.3, 0, 0], [0, 0, 0.3]]]])
    assert round_spheres(np.linalg.inv(rotated), np.zeros((1, 1, 3)))[0, 0] == pytest.approx(0.3)

    def covered(offsets, radius):
        m = len(offsets)
        blockers = Blockers(
            np.broadcast_to(np.eye(3) * radius, (1, m, 3, 3)),
            np.array([offsets], float),
            np.ones((1, m), bool),
            np.zeros((1, 0, 4, 3)),
            np.zeros((1, 0), bool),
        )
        return cone_visible_factor(x, n, SQUARE[None], np.array([[0.0, 0.0, 1.0]]), blockers)[1][0]

    apart = [(0.4 * (k % 3) - 0.4, 0.4 * (k // 3) - 0.4, 1.5) for k in range(MAX_CONES + 1)]
    assert covered(apart[:MAX_CONES], 0.05) and not covered(apart, 0.05)
    crowd = [(0.05 * k, 0.0, 1.5) for k in range(MAX_OVERLAPS + 2)]  # every cone meets all others
    assert covered(crowd[:-1], 0.1) and not covered(crowd, 0.1)


def test_many_spheres_match_line_integrals(monkeypatch):
    """Four to eight spheres between x and the square, their cones overlapping in chains and
    clusters (terms of inclusion-exclusion up to MAX_OVERLAPS + 1 spheres): the closed form agrees
    with the line integrals at tol 1e-11."""
    rng = np.random.default_rng(3)
    K, M = 48, MAX_CONES
    x = np.stack([rng.uniform(-1.5, 1.5, K), rng.uniform(-1.5, 1.5, K), rng.uniform(2.0, 3.5, K)], 1)
    n = rng.normal(size=(K, 3))
    n[:, 2] -= 2.0
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    radius = rng.uniform(0.08, 0.3, (K, M))
    # centres along x's view of the square, clustered round a few directions so that cones overlap
    toward = rng.uniform(-1.0, 1.0, (K, 3, 2))[:, rng.integers(0, 3, M)]
    depth = rng.uniform(0.3, 0.7, (K, M, 1))
    ground = np.concatenate([toward + rng.normal(scale=0.15, size=(K, M, 2)), np.zeros((K, M, 1))], -1)
    offset = x[:, None] + depth * (ground - x[:, None])
    offset[..., 2] = np.maximum(offset[..., 2], radius + 0.01)
    valid = np.arange(M)[None] < rng.integers(4, M + 1, K)[:, None]
    blockers = Blockers(
        radius[..., None, None] * np.eye(3), offset, valid, np.zeros((K, 0, 4, 3)), np.zeros((K, 0), bool)
    )
    corners = np.broadcast_to(SQUARE, (K, 4, 3)).copy()
    normal = np.tile([0.0, 0.0, 1.0], (K, 1))
    F, done = cone_visible_factor(x, n, corners, normal, blockers)
    assert done.mean() > 0.8
    reference = lines_only(
        monkeypatch, x[done], n[done], corners[done], normal[done], blockers.take(np.flatnonzero(done)), 1e-11
    )
    assert np.abs(F[done] - reference).max() <= 1e-12
    unoccluded, _ = point_to_polygon(x, n, corners, normal)
    assert np.count_nonzero(F[done] < 0.9 * unoccluded[done]) > K // 3  # (shadows that matter)


def test_faces_sharing_an_edge(monkeypatch):
    """The faces of a box (without its bottom) as polygon occluders: faces that share an edge put
    the same circle in an intersection twice (the plane through x and the edge), which must not
    clip itself. Points beside and under the box, every subset of up to three faces, against the
    line integrals."""
    lo, hi = np.array([1.0, 1.0, 0.0]), np.array([2.0, 2.0, 1.0])

    def corner(i, j, k):
        return [(lo, hi)[i][0], (lo, hi)[j][1], (lo, hi)[k][2]]

    faces = np.array(
        [
            [corner(0, 0, 1), corner(1, 0, 1), corner(1, 1, 1), corner(0, 1, 1)],
            [corner(0, 0, 0), corner(0, 0, 1), corner(0, 1, 1), corner(0, 1, 0)],
            [corner(1, 0, 0), corner(1, 1, 0), corner(1, 1, 1), corner(1, 0, 1)],
            [corner(0, 0, 0), corner(1, 0, 0), corner(1, 0, 1), corner(0, 0, 1)],
            [corner(0, 1, 0), corner(0, 1, 1), corner(1, 1, 1), corner(1, 1, 0)],
        ]
    )
    light = np.array([[(1, 1, 3), (1, 2, 3), (2, 2, 3), (2, 1, 3)]], float)
    rng = np.random.default_rng(7)
    x = np.column_stack([rng.uniform(0, 3, 60), rng.uniform(0, 3, 60), np.full(60, 1e-6)])
    x[:6, :2] = rng.uniform(1.1, 1.9, (6, 2))  # under the box
    n = np.tile([0.0, 0.0, 1.0], (60, 1))
    subsets = [(0, 1), (0, 2, 4), (1, 3), (0, 1, 3), (2,)]
    for subset in subsets:
        blockers = Blockers(
            np.zeros((60, 0, 3, 3)),
            np.zeros((60, 0, 3)),
            np.zeros((60, 0), bool),
            np.broadcast_to(faces[list(subset)], (60, len(subset), 4, 3)),
            np.ones((60, len(subset)), bool),
        )
        corners, normal = np.broadcast_to(light, (60, 4, 3)), np.tile([0.0, 0.0, -1.0], (60, 1))
        F, done = cone_visible_factor(x, n, corners, normal, blockers)
        assert done.all()
        reference = lines_only(monkeypatch, x, n, corners, normal, blockers, 1e-11)
        monkeypatch.undo()
        assert np.abs(F - reference).max() <= 1e-12, subset


def test_a_whole_disk_seen_from_its_axis_matches_line_integrals(monkeypatch):
    """A whole disk seen from a point on its axis (a sphere target's silhouette disk) is a round cone:
    past spheres and a triangle, tilted normals cut by the horizon, the closed form
    (`round_cone_visible_factor`) agrees with the line integrals of the same disk at tol 1e-11."""
    from core.cones import round_cone_visible_factor
    from core.shadow import SectorTargets

    x, n, _, _, blockers = random_scene(200, seed=3)
    rng = np.random.default_rng(5)
    center = np.column_stack([rng.uniform(-0.5, 0.5, (200, 2)), np.zeros(200)])
    axis = x - center
    height = np.linalg.norm(axis, axis=1)
    normal = axis / height[:, None]
    radius = rng.uniform(0.3, 1.2, 200)
    e1 = np.cross(normal, [0.3, 1.0, 0.2])
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    targets = SectorTargets(
        center, normal, e1, np.column_stack([np.zeros(200), radius]), np.tile([0, 2 * np.pi], (200, 1))
    )
    assert targets.seen_round(x).all()
    F, done = round_cone_visible_factor(x, n, center, normal, radius, blockers)
    assert done.mean() > 0.8
    closed, _, lines = visible_factor(x, n, targets, blockers, 1e-11)
    assert np.array_equal(closed[done], F[done])
    monkeypatch.setattr(
        shadow, "round_cone_visible_factor", lambda x, *_: (np.zeros(len(x)), np.zeros(len(x), bool))
    )
    reference, _, lines = visible_factor(x, n, targets, blockers, 1e-11)
    assert lines > 0
    assert np.abs(F[done] - reference[done]).max() <= 1e-12
    assert (F[done] > 0).mean() > 0.5 and (F[done] < 0.999 * reference[done]).sum() == 0
