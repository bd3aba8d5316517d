"""core.bvh: every query of the hierarchy equals a brute-force evaluation over all primitives.

Oracles:

- `segments_blocked` against the exact test applied to every (segment, primitive) pair
  (`BVH.pair_blocked`, no tree), on seeded random scenes of triangles, ellipsoids and quads with
  segments of all lengths, grazing ones and ones ending on primitives;
- the exact tests themselves against independent code: triangles against a 3 x 3 linear solve
  of p + t d = v0 + a e1 + b e2 (written out here), ellipsoids and flat quads against
  `core.occlusion.Occluders` (its own closed forms);
- `box_candidates` / `shaft_candidates` against the box-overlap and capsule test of
  `core.visibility.ShaftTest` written out here over all (query, primitive) pairs.
"""

import numpy as np
import pytest

from core import Cylinder, Disk, Quad, Sphere
from core.bvh import BVH, EXTERNAL, QUAD, SPHERE, TRIANGLE, ellipsoid_boxes, quad_boxes, triangle_boxes
from core.occlusion import DISK, Occluders

EPS = 1e-9


# --------------------------------------------------------------------------- random scenes
def random_rotations(rng, n):
    """n random rotation matrices (QR of Gaussian matrices, signs fixed), shape (n, 3, 3)."""
    Q, R = np.linalg.qr(rng.standard_normal((n, 3, 3)))
    Q *= np.sign(np.einsum("kii->ki", R))[:, None, :]
    return Q * np.sign(np.linalg.det(Q))[:, None, None]


def random_triangles(rng, n, size=0.15):
    """n triangles in the unit cube, about `size` across, the last few degenerate."""
    centre = rng.random((n, 1, 3))
    T = centre + size * rng.standard_normal((n, 3, 3))
    if n >= 4:
        T[-1, 2] = T[-1, 0]  # repeated corner
        T[-2, 2] = 0.3 * T[-2, 0] + 0.7 * T[-2, 1]  # collinear corners
    return T


def random_ellipsoids(rng, n, size=0.1):
    """n ellipsoids (rotated, axes size * [0.3, 1.5]) in the unit cube: (linear, offset)."""
    axes = size * rng.uniform(0.3, 1.5, (n, 3))
    linear = random_rotations(rng, n) * axes[:, None, :]
    return linear, rng.random((n, 3))


def random_quads(rng, n, size=0.2):
    """n flat convex quads in the unit cube: parallelograms, trapezoids and quads with a collapsed edge."""
    frame = random_rotations(rng, n)
    a, b = size * rng.uniform(0.2, 1.0, (2, n))
    shrink = rng.uniform(0.0, 1.0, n)  # top edge length factor: 0 collapses it (a triangle)
    shrink[::5] = 0.0
    local = np.zeros((n, 4, 3))
    local[:, 0, :2] = np.c_[-a, -b]
    local[:, 1, :2] = np.c_[a, -b]
    local[:, 2, :2] = np.c_[shrink * a, b]
    local[:, 3, :2] = np.c_[-shrink * a, b]
    return np.einsum("kij,kvj->kvi", frame, local) + rng.random((n, 1, 3))


def points_on(bvh, rng, n):
    """n points on random primitives of the scene (endpoints of segments that leave surfaces)."""
    prim = rng.integers(0, bvh.M, n)
    points = np.zeros((n, 3))
    for kind in (TRIANGLE, QUAD):
        sel = np.flatnonzero(bvh.kind[prim] == kind)
        V = (bvh.triangles if kind == TRIANGLE else bvh.quads)[bvh.index[prim[sel]]]
        w = rng.dirichlet(np.ones(V.shape[1]), sel.size)
        points[sel] = np.einsum("kv,kvi->ki", w, V)
    sel = np.flatnonzero(bvh.kind[prim] == SPHERE)
    L, o = bvh.ellipsoids
    direction = rng.standard_normal((sel.size, 3))
    direction /= np.linalg.norm(direction, axis=1)[:, None]
    row = bvh.index[prim[sel]]
    points[sel] = np.einsum("kij,kj->ki", L[row], direction) + o[row]
    return points, prim


def random_segments(rng, bvh, n):
    """Segments of all lengths: long, short, very short, and ones starting or ending on primitives."""
    p = rng.uniform(-0.2, 1.2, (n, 3))
    length = 10.0 ** rng.uniform(-4, 0.3, n)
    direction = rng.standard_normal((n, 3))
    q = p + length[:, None] * direction / np.linalg.norm(direction, axis=1)[:, None]
    # a third start on a primitive, a sixth also end on one
    on, prim = points_on(bvh, rng, n // 3)
    p[: n // 3] = on
    end, end_prim = points_on(bvh, rng, n // 6)
    q[: n // 6] = end
    # the objects left (every other segment from a primitive) and arrived at (every third)
    exclude = np.full((n, 2), -1)
    exclude[: n // 3 : 2, 0] = bvh.object_id[prim[::2]]
    exclude[: n // 6 : 3, 1] = bvh.object_id[end_prim[::3]]
    return p, q, exclude


def random_scene(seed, counts=(60, 25, 40), leaf_size=4, objects=None):
    rng = np.random.default_rng(seed)
    nt, ne, nq = counts
    T = random_triangles(rng, nt) if nt else None
    E = random_ellipsoids(rng, ne) if ne else None
    Q = random_quads(rng, nq) if nq else None
    M = nt + ne + nq
    object_id = None if objects is None else rng.integers(0, objects, M)
    return BVH.from_primitives(T, E, Q, object_id=object_id, leaf_size=leaf_size), rng


def brute_blocked(bvh, p, q, eps, exclude):
    """Exact test of every (segment, primitive) pair, without the tree."""
    R, M = len(p), bvh.M
    k, m = np.repeat(np.arange(R), M), np.tile(np.arange(M), R)
    hit = bvh.pair_blocked(p[k], q[k], m, np.broadcast_to(eps, (R,))[k])
    excluded = exclude if exclude.ndim == 2 else exclude[:, None]
    hit &= np.all(bvh.object_id[m][:, None] != excluded[k], axis=1)
    return hit.reshape(R, M).any(1)


# --------------------------------------------------------------------------- segments
@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("leaf_size", [1, 4, 7])
def test_segments_blocked_equals_brute_force(seed, leaf_size):
    """segments_blocked == any over all primitives of the exact pair test, with exclusions."""
    bvh, rng = random_scene(seed, leaf_size=leaf_size, objects=20)
    p, q, exclude = random_segments(rng, bvh, 600)
    eps = np.where(rng.random(600) < 0.5, EPS, 1e-3)
    got = bvh.segments_blocked(p, q, eps, exclude)
    want = brute_blocked(bvh, p, q, eps, exclude)
    assert np.array_equal(got, want), f"seed {seed}: {np.flatnonzero(got != want)}"
    # the scene covers both answers, and the tree tested fewer pairs than brute force
    assert 0.1 < want.mean() < 0.9, want.mean()
    assert bvh.stats["queries"] == 600
    assert 0 < bvh.stats["primitives"] < 600 * bvh.M


@pytest.mark.parametrize("seed", [3, 4])
def test_grazing_and_endpoint_segments_equal_brute_force(seed):
    """Segments tangent to ellipsoids, through triangle edges and corners and ending on primitives."""
    bvh, rng = random_scene(seed, counts=(40, 20, 20))
    n = 300
    # tangent lines of ellipsoids: p = o + L (u +- s w) with u, w orthonormal, s = 1 + tiny
    L, o = bvh.ellipsoids
    row = rng.integers(0, len(o), n)
    u = rng.standard_normal((n, 3))
    u /= np.linalg.norm(u, axis=1)[:, None]
    w = np.cross(u, rng.standard_normal((n, 3)))
    w /= np.linalg.norm(w, axis=1)[:, None]
    s = 2.0 * (1.0 + rng.choice([-1e-6, 0.0, 1e-6], n))[:, None]
    p_t = np.einsum("kij,kj->ki", L[row], u - s * w) + o[row]
    q_t = np.einsum("kij,kj->ki", L[row], u + s * w) + o[row]
    # through triangle corners and edge midpoints, crossing the plane
    T = bvh.triangles[rng.integers(0, len(bvh.triangles), n)]
    pick = rng.integers(0, 3, n)
    through = np.where((rng.random(n) < 0.5)[:, None], T[np.arange(n), pick], 0.5 * (T[:, 0] + T[:, 1]))
    d = rng.standard_normal((n, 3))
    p_e, q_e = through - 0.3 * d, through + 0.3 * d
    # ending exactly on primitives, or just beyond eps
    start = rng.random((n, 3))
    end, _ = points_on(bvh, rng, n)
    beyond = end + (end - start) * rng.choice([0.0, 1e-10, 1e-8], n)[:, None]
    p = np.concatenate([p_t, p_e, start])
    q = np.concatenate([q_t, q_e, beyond])
    exclude = np.full(len(p), -1)
    got = bvh.segments_blocked(p, q, EPS, exclude)
    assert np.array_equal(got, brute_blocked(bvh, p, q, EPS, exclude))


def test_triangle_test_against_linear_solve():
    """Moeller-Trumbore == the solution (t, a, b) of p + t d = v0 + a e1 + b e2 (np.linalg.solve)."""
    rng = np.random.default_rng(5)
    T = random_triangles(rng, 40, size=0.3)[:-2]  # no degenerate ones (the solve needs them regular)
    bvh = BVH.from_primitives(triangles=T)
    p, q = rng.random((400, 3)), rng.random((400, 3))
    k, m = np.repeat(np.arange(400), len(T)), np.tile(np.arange(len(T)), 400)
    d = q[k] - p[k]
    A = np.stack([-d, T[m, 1] - T[m, 0], T[m, 2] - T[m, 0]], -1)
    t, a, b = np.linalg.solve(A, (p[k] - T[m, 0])[..., None])[..., 0].T
    want = (t > 0) & (t < 1) & (a >= 0) & (b >= 0) & (a + b <= 1)
    # pairs within 1e-6 of an edge or an end are left to the named tests
    clear = np.min(np.abs([t, 1 - t, a, b, 1 - a - b]), axis=0) > 1e-6
    got = bvh.pair_blocked(p[k], q[k], m, 0.0)
    assert np.array_equal(got[clear], want[clear])
    assert clear.mean() > 0.99 and 0.01 < want.mean() < 0.5, (clear.mean(), want.mean())


@pytest.mark.parametrize("seed", [6, 7])
def test_ellipsoids_and_quads_agree_with_occluders(seed):
    """Whole ellipsoids and flat quads: BVH == Occluders.any_blocked over all occluders (independent code)."""
    rng = np.random.default_rng(seed)
    L, o = random_ellipsoids(rng, 15, size=0.15)
    V = random_quads(rng, 25, size=0.25)
    surfaces = [
        Sphere((0, 0, 0), 1.0).transformed(np.block([[L[i], o[i][:, None]], [np.zeros((1, 3)), 1.0]]))
        for i in range(len(o))
    ]
    surfaces += [Quad(*v) for v in V]
    occ = Occluders(surfaces)
    bvh = BVH.from_primitives(ellipsoids=(L, o), quads=V)
    p, q, _ = random_segments(rng, bvh, 800)
    eps = occ.eps[0]
    want = occ.any_blocked(p, q, np.arange(len(surfaces)))
    assert np.array_equal(bvh.segments_blocked(p, q, eps), want)
    assert 0.1 < want.mean() < 0.9


def test_named_cases():
    """Shared edges and corners block; in-plane, tangent, endpoint-touching and inside segments do not."""
    # two triangles sharing the diagonal of the unit square at z = 0, a unit sphere at (0, 0, 5)
    T = np.array([[[0, 0, 0], [1, 0, 0], [1, 1, 0]], [[0, 0, 0], [1, 1, 0], [0, 1, 0]]], float)
    E = (np.eye(3)[None], np.array([[0.0, 0.0, 5.0]]))
    bvh = BVH.from_primitives(triangles=T, ellipsoids=E)
    cases = {
        "through the shared edge": ([0.5, 0.5, -1], [0.5, 0.5, 1], True),
        "through a shared corner": ([0.0, 0.0, -1], [0.0, 0.0, 1], True),
        "through the outer edge": ([1.0, 0.5, -1], [1.0, 0.5, 1], True),
        "just outside the edge": ([1.0 + 1e-6, 0.5, -1], [1.0 + 1e-6, 0.5, 1], False),
        "in the plane": ([-1.0, 0.5, 0], [2.0, 0.5, 0], False),
        "ending on the triangle": ([0.3, 0.2, 1], [0.3, 0.2, 0], False),
        "ending eps beyond it": ([0.3, 0.2, 1], [0.3, 0.2, -2e-9], True),
        "starting on it": ([0.3, 0.2, 0], [0.6, 0.7, 3], False),
        "through the sphere": ([0.0, 0.0, 3], [0.0, 0.0, 7], True),
        "tangent to the sphere": ([1.0, -2.0, 5], [1.0, 2.0, 5], False),
        "inside the sphere": ([0.1, 0.0, 5], [0.0, 0.2, 5.3], False),
        "leaving the sphere": ([0.0, 0.0, 4], [1.0, 1.0, 3], False),
        "crossing it from its surface": ([0.0, 0.0, 4], [0.0, 0.0, 9], True),
        "chord of the sphere": ([0.0, 0.0, 4], [0.0, 0.0, 7], True),
        "zero length": ([0.5, 0.5, 0], [0.5, 0.5, 0], False),
    }
    p, q, want = (np.array(x) for x in zip(*cases.values()))
    got = bvh.segments_blocked(p.astype(float), q.astype(float), EPS)
    wrong = [name for name, g, w in zip(cases, got, want) if g != w]
    assert not wrong, wrong
    # the chord from the sphere's surface is ignored when the sphere (object 2) is excluded
    assert not bvh.segments_blocked([[0.0, 0.0, 4]], [[0.0, 0.0, 7]], EPS, exclude=[2])[0]


def test_degenerate_triangles_never_block():
    """Zero-area triangles (repeated or collinear corners) never block and raise no warning."""
    T = np.array(
        [[[0, 0, 0], [1, 0, 0], [1, 0, 0]], [[0, 0, 0], [1, 1, 1], [2, 2, 2]], [[1, 1, 1]] * 3], float
    )
    bvh = BVH.from_primitives(triangles=T)
    rng = np.random.default_rng(8)
    p = np.concatenate([rng.random((100, 3)) * 3 - 1, [[0.5, -1, 0], [1, 1, 0]]])
    q = np.concatenate([rng.random((100, 3)) * 3 - 1, [[0.5, 1, 0], [1, 1, 2]]])
    assert not bvh.segments_blocked(p, q, EPS).any()


def test_external_primitives_use_the_callback():
    """EXTERNAL disks and cylinders tested by Occluders.blocked: same as Occluders.any_blocked."""
    rng = np.random.default_rng(9)
    surfaces = [Disk(rng.random(3), rng.standard_normal(3), 0.2) for _ in range(10)]
    surfaces += [Cylinder(rng.random(3), rng.standard_normal(3), 0.1, 0.3) for _ in range(10)]
    occ = Occluders(surfaces)
    boxes = np.stack([occ.box_min, occ.box_max], 1)
    bvh = BVH(boxes, np.full(20, EXTERNAL), external=occ.blocked, balls=(occ.center, occ.radius))
    p, q = rng.random((500, 3)), rng.random((500, 3))
    want = occ.any_blocked(p, q, np.arange(20))
    assert np.array_equal(bvh.segments_blocked(p, q, occ.eps[0]), want)
    assert 0.05 < want.mean() < 0.95


# --------------------------------------------------------------------------- candidates
def brute_shaft(bvh, lo, hi, p, q, radius, exclude):
    """ShaftTest's rule on every (query, primitive) pair: boxes meet, ball meets the capsule."""
    meet = np.all((bvh.boxes[None, :, 0] <= hi[:, None]) & (bvh.boxes[None, :, 1] >= lo[:, None]), axis=-1)
    d = q - p
    dd = np.einsum("ki,ki->k", d, d)[:, None]
    t = np.einsum("kmi,ki->km", bvh.center[None] - p[:, None], d)
    t = np.divide(t, dd, out=np.zeros_like(t), where=dd > 0)  # a point query: t = 0
    closest = p[:, None] + np.clip(t, 0, 1)[..., None] * d[:, None]
    gap = np.linalg.norm(bvh.center[None] - closest, axis=-1)
    mask = meet & (gap <= bvh.radius[None] + radius[:, None])
    excluded = exclude if exclude.ndim == 2 else exclude[:, None]
    mask &= np.all(bvh.object_id[None, :, None] != excluded[:, None, :], axis=2)
    return meet, mask


@pytest.mark.parametrize("seed", [10, 11])
@pytest.mark.parametrize("leaf_size", [1, 4])
def test_box_and_shaft_candidates_equal_brute_force(seed, leaf_size):
    """box_candidates / shaft_candidates == the box and capsule rule over all (query, primitive) pairs."""
    bvh, rng = random_scene(seed, counts=(150, 40, 60), leaf_size=leaf_size, objects=30)
    K = 300
    a, b = rng.random((K, 3)), rng.random((K, 3))
    ra, rb = 10.0 ** rng.uniform(-3, -1, (2, K))
    lo, hi = np.minimum(a - ra[:, None], b - rb[:, None]), np.maximum(a + ra[:, None], b + rb[:, None])
    radius = np.maximum(ra, rb)
    exclude = rng.integers(-1, 30, (K, 2))
    meet, mask = brute_shaft(bvh, lo, hi, a, b, radius, exclude)
    k, m = bvh.box_candidates(lo, hi)
    assert np.array_equal(np.stack([k, m], 1), np.argwhere(meet))
    k, m = bvh.shaft_candidates(lo, hi, a, b, radius, exclude)
    assert np.array_equal(np.stack([k, m], 1), np.argwhere(mask))
    assert 0.01 < mask.mean() < 0.5 and mask.sum() < meet.sum(), (mask.mean(), meet.mean())
    assert bvh.stats["primitives"] < K * bvh.M


# --------------------------------------------------------------------------- structure, updates, edges
def test_shaft_pairs_are_the_shaft_rule_on_given_pairs():
    """`shaft_pairs` on every (query, primitive) pair == the brute-force box and capsule rule."""
    bvh, rng = random_scene(12, counts=(80, 30, 40), objects=20)
    K = 200
    a, b = rng.random((K, 3)), rng.random((K, 3))
    ra, rb = 10.0 ** rng.uniform(-3, -1, (2, K))
    lo, hi = np.minimum(a - ra[:, None], b - rb[:, None]), np.maximum(a + ra[:, None], b + rb[:, None])
    radius = np.maximum(ra, rb)
    _, mask = brute_shaft(bvh, lo, hi, a, b, radius, np.full(K, -1))
    k, m = (i.ravel() for i in np.meshgrid(np.arange(K), np.arange(bvh.M), indexing="ij"))
    assert np.array_equal(bvh.shaft_pairs(k, m, lo, hi, a, b, radius).reshape(K, -1), mask)
    assert 0.01 < mask.mean() < 0.5


@pytest.mark.parametrize("M, leaf_size", [(1, 4), (2, 1), (5, 4), (9, 2), (250, 4), (257, 3)])
def test_tree_invariants(M, leaf_size):
    """order is a permutation, leaves hold <= leaf_size, node boxes and balls hold their primitives."""
    rng = np.random.default_rng(M)
    bvh = BVH.from_primitives(triangles=random_triangles(rng, M), leaf_size=leaf_size)
    assert np.array_equal(np.sort(bvh.order), np.arange(M))
    leaves = np.flatnonzero(bvh.child[:, 0] < 0)
    assert leaves.size == 2**bvh.depth and bvh.count[leaves].max() <= leaf_size
    assert bvh.count[leaves].sum() == M
    for n in range(len(bvh.count)):
        prims = bvh.order[bvh.start[n] : bvh.start[n] + bvh.count[n]]
        assert np.all(bvh.node_box[n, 0] <= bvh.boxes[prims, 0]) and np.all(
            bvh.node_box[n, 1] >= bvh.boxes[prims, 1]
        )
        reach = np.linalg.norm(bvh.center[prims] - bvh.node_center[n], axis=1) + bvh.radius[prims]
        assert np.all(reach <= bvh.node_radius[n])


def test_refit_after_moves():
    """After moving (rotating, translating) every primitive, refit gives the brute-force answers."""
    bvh, rng = random_scene(12, objects=10)
    R = random_rotations(rng, 1)[0]
    shift = rng.uniform(-0.5, 0.5, 3)
    T = bvh.triangles @ R.T + shift
    L, o = bvh.ellipsoids
    V = bvh.quads @ R.T + shift
    V[:5] += 0.3  # some move further
    bvh.refit(triangles=T, ellipsoids=(R @ L, o @ R.T + shift), quads=V)
    fresh = BVH.from_primitives(T, (R @ L, o @ R.T + shift), V, object_id=bvh.object_id)
    assert np.allclose(bvh.boxes, fresh.boxes)
    p, q, exclude = random_segments(rng, bvh, 500)
    want = brute_blocked(bvh, p, q, EPS, exclude)
    assert np.array_equal(bvh.segments_blocked(p, q, EPS, exclude), want)
    assert np.array_equal(fresh.segments_blocked(p, q, EPS, exclude), want)
    lo, hi = p - 0.05, p + 0.05
    assert np.array_equal(
        np.argwhere(brute_shaft(bvh, lo, hi, p, p, np.full(500, 0.05), exclude)[0]),
        np.stack(bvh.box_candidates(lo, hi), 1),
    )
    with pytest.raises(ValueError, match="number of primitives"):
        bvh.refit(triangles=T[:-1])
    # a failed refit (a bent quad) changes nothing
    bent = V.copy()
    bent[0, 2] += 0.1 * np.cross(bent[0, 1] - bent[0, 0], bent[0, 3] - bent[0, 0])
    with pytest.raises(ValueError, match="flat"):
        bvh.refit(triangles=T + 1.0, quads=bent)
    assert np.array_equal(bvh.triangles, T) and np.array_equal(bvh.segments_blocked(p, q, EPS, exclude), want)


def test_empty_scene_and_empty_queries():
    """No primitives: nothing is blocked and nothing is a candidate; no queries: empty answers."""
    empty = BVH.from_primitives()
    p = np.random.default_rng(13).random((10, 3))
    assert empty.M == 0 and not empty.segments_blocked(p, p + 1, EPS).any()
    assert all(x.size == 0 for x in empty.box_candidates(p, p + 1))
    assert all(x.size == 0 for x in empty.shaft_candidates(p, p + 1, p, p + 1, np.ones(10)))
    bvh, _ = random_scene(13)
    assert bvh.segments_blocked(np.zeros((0, 3)), np.zeros((0, 3)), EPS).shape == (0,)
    assert all(x.size == 0 for x in bvh.box_candidates(np.zeros((0, 3)), np.zeros((0, 3))))


def test_one_primitive():
    """A single quad: blocked exactly where the closed form says (z changes sign inside the square)."""
    bvh = BVH.from_primitives(quads=[[[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]]])
    assert bvh.depth == 0
    rng = np.random.default_rng(14)
    p, q = rng.uniform(-0.5, 1.5, (1000, 3)), rng.uniform(-0.5, 1.5, (1000, 3))
    q[:, 2] -= 1.0
    t = p[:, 2] / (p[:, 2] - q[:, 2])
    x = p + t[:, None] * (q - p)
    want = (t > 0) & (t < 1) & np.all((x[:, :2] >= 0) & (x[:, :2] <= 1), axis=1)
    assert np.array_equal(bvh.segments_blocked(p, q, EPS), want)
    assert 0.1 < want.mean() < 0.9


def test_stats_count_less_work_than_brute_force():
    """Short segments in a scene of 4,000 triangles: the tree tests a small fraction of all pairs."""
    rng = np.random.default_rng(15)
    bvh = BVH.from_primitives(triangles=random_triangles(rng, 4000, size=0.01))
    p = rng.random((200, 3))
    q = p + 0.02 * rng.standard_normal((200, 3))
    bvh.segments_blocked(p, q, EPS)
    assert bvh.stats["primitives"] < 0.01 * 200 * bvh.M
    assert bvh.stats["nodes"] < 0.05 * 200 * len(bvh.count)


def test_bad_input():
    """Shapes, NaN, negative eps, bad kinds, non-flat / non-convex quads, flat ellipsoids: ValueError."""
    bvh, _ = random_scene(16)
    p = np.zeros((3, 3))
    with pytest.raises(ValueError, match="q must have shape"):
        bvh.segments_blocked(p, np.zeros((2, 3)), EPS)
    with pytest.raises(ValueError, match="finite"):
        bvh.segments_blocked(p, np.full((3, 3), np.nan), EPS)
    with pytest.raises(ValueError, match="eps"):
        bvh.segments_blocked(p, p, -1.0)
    with pytest.raises(ValueError, match="exclude"):
        bvh.segments_blocked(p, p, EPS, exclude=np.zeros(3))
    with pytest.raises(ValueError, match="kinds"):
        BVH(np.zeros((1, 2, 3)), [DISK])
    with pytest.raises(ValueError, match="external"):
        BVH(np.zeros((1, 2, 3)), [EXTERNAL])
    with pytest.raises(ValueError, match="index"):
        BVH(np.zeros((1, 2, 3)), [TRIANGLE], [3], triangles=np.zeros((1, 3, 3)))
    with pytest.raises(ValueError, match="min <= max"):
        BVH(np.array([[[1.0, 0, 0], [0, 0, 0]]]), [EXTERNAL], external=lambda p, q, m: m < 0)
    with pytest.raises(ValueError, match="flat"):
        BVH.from_primitives(quads=[[[0, 0, 0], [1, 0, 0], [1, 1, 0.1], [0, 1, 0]]])
    with pytest.raises(ValueError, match="convex"):
        BVH.from_primitives(quads=[[[0, 0, 0], [1, 0, 0], [0.2, 0.2, 0], [0, 1, 0]]])
    with pytest.raises(ValueError, match="area"):
        BVH.from_primitives(quads=[[[0, 0, 0], [1, 0, 0], [2, 0, 0], [3, 0, 0]]])
    with pytest.raises(ValueError, match="invertible"):
        BVH.from_primitives(ellipsoids=(np.diag([1.0, 1.0, 0.0])[None], np.zeros((1, 3))))
    with pytest.raises(ValueError, match="triangles must have shape"):
        triangle_boxes(np.zeros((2, 4, 3)))
    with pytest.raises(ValueError, match="leaf_size"):
        BVH.from_primitives(triangles=np.zeros((1, 3, 3)), leaf_size=0)
    assert (
        quad_boxes(np.zeros((0, 4, 3))).shape == ellipsoid_boxes(np.zeros((0, 3, 3)), np.zeros((0, 3))).shape
    )
    assert QUAD != SPHERE != TRIANGLE


def test_per_primitive_tolerance():
    """A primitive's tolerance widens the endpoint band of that primitive only."""
    T = np.array([[[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 0, 1], [1, 0, 1], [0, 1, 1]]], float)
    bvh = BVH.from_primitives(triangles=T, tolerance=[1e-5, 0.0])
    # ends 1e-6 beyond the plane z = 0 (inside triangle 0's band) or z = 1 (outside triangle 1's)
    p = np.array([[0.2, 0.2, 0.5], [0.2, 0.2, 0.5]])
    q = np.array([[0.2, 0.2, -1e-6], [0.2, 0.2, 1 + 1e-6]])
    assert np.array_equal(bvh.segments_blocked(p, q, EPS), [False, True])
    assert np.array_equal(bvh.pair_blocked(p, q, [0, 1], EPS), [False, True])
    bvh, rng = random_scene(17)
    bvh = BVH.from_primitives(bvh.triangles, bvh.ellipsoids, bvh.quads, tolerance=rng.uniform(0, 1e-2, bvh.M))
    p, q, exclude = random_segments(rng, bvh, 400)
    assert np.array_equal(bvh.segments_blocked(p, q, EPS, exclude), brute_blocked(bvh, p, q, EPS, exclude))


def test_small_budgets_split_the_work(monkeypatch):
    """Tiny work budgets (frontiers split between queries, segments in chunks) change no answer."""
    import core.bvh

    bvh, rng = random_scene(18, counts=(200, 30, 50), objects=10)
    p, q, exclude = random_segments(rng, bvh, 300)
    lo, hi = np.minimum(p, q), np.maximum(p, q)
    want_blocked = bvh.segments_blocked(p, q, EPS, exclude)
    want_pairs = np.stack(bvh.box_candidates(lo, hi), 1)
    want_nodes = bvh.stats["nodes"]
    monkeypatch.setattr(core.bvh, "PAIR_BUDGET", 64)
    monkeypatch.setattr(core.bvh, "QUERY_CHUNK", 7)
    monkeypatch.setattr(core.bvh, "SEGMENT_CHUNK", 11)
    assert np.array_equal(bvh.segments_blocked(p, q, EPS, exclude), want_blocked)
    assert np.array_equal(np.stack(bvh.box_candidates(lo, hi), 1), want_pairs)
    assert bvh.stats["nodes"] == want_nodes and len(want_pairs) > 300


def test_low_level_constructor_with_shuffled_primitives():
    """BVH(boxes, kind, index) with interleaved kinds in any order answers as from_primitives does."""
    bvh, rng = random_scene(19, objects=15)
    perm = rng.permutation(bvh.M)
    shuffled = BVH(
        bvh.boxes[perm],
        bvh.kind[perm],
        bvh.index[perm],
        triangles=bvh.triangles,
        ellipsoids=bvh.ellipsoids,
        quads=bvh.quads,
        object_id=bvh.object_id[perm],
        balls=(bvh.center[perm], bvh.radius[perm]),
        leaf_size=3,
    )
    p, q, exclude = random_segments(rng, bvh, 400)
    assert np.array_equal(
        shuffled.segments_blocked(p, q, EPS, exclude), bvh.segments_blocked(p, q, EPS, exclude)
    )
    lo, hi = np.minimum(p, q), np.maximum(p, q)
    k, m = bvh.shaft_candidates(lo, hi, p, q, np.full(400, 0.01), exclude)
    k2, m2 = shuffled.shaft_candidates(lo, hi, p, q, np.full(400, 0.01), exclude)
    assert k.size > 400
    assert np.array_equal(np.unique(np.c_[k2, perm[m2]], axis=0), np.unique(np.c_[k, m], axis=0))


def test_coincident_primitives():
    """300 copies of one triangle (all centroids equal, no axis to split on): still exact, leaves full."""
    T = np.repeat([[[0.0, 0, 0], [1, 0, 0], [0, 1, 0]]], 300, axis=0)
    bvh = BVH.from_primitives(triangles=T, object_id=np.arange(300) % 3, leaf_size=1)
    assert bvh.count[bvh.child[:, 0] < 0].max() == 1
    rng = np.random.default_rng(20)
    p, q = rng.uniform(-0.5, 1.5, (200, 3)), rng.uniform(-0.5, 1.5, (200, 3))
    exclude = rng.integers(-1, 3, (200, 2))
    got = bvh.segments_blocked(p, q, EPS, exclude)
    assert np.array_equal(got, brute_blocked(bvh, p, q, EPS, exclude)) and 0.05 < got.mean() < 0.95
