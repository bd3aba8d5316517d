"""The near-field final gather (`core.nearfield`): the light of a large patch near a gathered
point resolved across the patch, so coarse patches under an object still show its shadow."""

import numpy as np
import pytest

import core
from core import nearfield
from tests.test_hierarchy import contact_scene, quad, unit_box

TOL = 1e-3


def hanging_ball(floor_patches=2, ball_patches=(1, 1)):
    """A ball of radius 0.5 hanging 0.1 m over an 8 m floor, a 1 m square lamp 3 m up and a sun.
    Returns (scene, floor, ball, the ball's surface)."""
    scene = core.Scene()
    floor_quad = quad((-4, -4, 0), (-4, 4, 0), (4, 4, 0), (4, -4, 0))
    floor = scene.add(floor_quad, reflectance=0.8, patches=floor_patches)
    surface = core.Sphere((0.3, 0.2, 0.6), 0.5)
    ball = scene.add(surface, reflectance=0.8, patches=ball_patches)
    lamp = quad((0, -0.5, 3), (1, -0.5, 3), (1, 0.5, 3), (0, 0.5, 3))
    scene.add(lamp, emission=200 / np.pi, reflectance=0.0, occluder=False)
    scene.add_sun_light((0.3, 0.2, -1), 3.0)
    return scene, floor, ball, surface


def ball_rows(surface, rows=7, columns=8):
    """(u, v) on `rows` polar rows (top to bottom) of `columns` points each."""
    (u0, u1), (v0, v1) = surface.domain
    u = np.linspace(u0, u1, rows + 2)[1:-1]
    v = np.linspace(v0, v1, columns + 1)[:-1]
    U, V = np.meshgrid(u, v, indexing="ij")
    return U.ravel(), V.ravel()


@pytest.fixture(scope="module")
def hierarchical_hanging_ball():
    """The hanging ball's rows from the hierarchical path (shape (7, 8)): its sub-patches grade
    toward the ball's foot and the floor's shadow (the path that matched Cycles on example 05's
    balls within 1.1 % per latitude, BENCHMARKS.md)."""
    scene, _, ball, surface = hanging_ball()
    solution = scene.solve(tol=TOL, method="hierarchical")
    return solution.radiosity_at(ball, *ball_rows(surface))[:, 0].reshape(7, 8)


def test_a_ball_over_a_one_patch_floor_sees_its_own_shadow(hierarchical_hanging_ball):
    """The ball (one patch) hangs over 4 m floor patches. Without the near field its underside
    takes the mean of the floor patch under it, mostly lit: the lowest row comes out 2.5x the
    hierarchical answer and the rows below the equator 20-30 % dark. With it every row's mean
    is within 4 % of it (measured: 0.2 % down to the row at 0.25 m above the floor, 2.7 % at
    0.14 m)."""
    scene, _, ball, surface = hanging_ball()
    solution = scene.solve(tol=TOL, method="pairs")
    u, v = ball_rows(surface)
    rows = {}
    for near in (False, True):
        solution.near_field = near
        ours = solution.radiosity_at(ball, u, v)[:, 0].reshape(7, 8)
        rows[near] = (ours / hierarchical_hanging_ball).mean(1) - 1
    assert rows[False][-1] > 1.0 and rows[False][3:5].min() < -0.15, rows[False]
    assert np.abs(rows[True]).max() < 0.04 and np.abs(rows[True][:-1]).max() < 0.01, rows[True]
    assert solution.stats["near_nodes"] > 0 and solution.stats["near_pairs"] > 0


def test_the_floor_around_a_resting_ball_approaches_cycles():
    """All pairs, the floor around a ball resting on it against Cycles (tests/data/cycles_contact.npz,
    see tests/test_hierarchy.py::test_the_floor_under_a_resting_ball_matches_cycles): without the
    near field the rings 0.1-0.3 m from the foot are 2-42x Cycles' radiance (they see the ball's
    lowest patches at their means, lit above); with it 0.9-1.6x, and the lit floor from 0.7 m
    stays within 0.4 % of Cycles' level plus 3 noise sigmas."""
    data = np.load(__file__.rsplit("/", 1)[0] + "/data/cycles_contact.npz")
    points = data["points"]
    cycles = 0.5 * (data["first"] + data["second"])[:, 0]
    noise = 0.5 * np.abs(data["first"] - data["second"])[:, 0]
    radius = np.linalg.norm(points[:, :2], axis=1)
    lit = cycles[radius > 0.99].mean()
    scene, floor = contact_scene()
    solution = scene.solve(tol=TOL, method="pairs")
    rings = lambda values: values.reshape(-1, 4).mean(1)  # noqa: E731 (4 directions per radius)
    ratio = {}
    for near in (False, True):
        solution.near_field = near
        ours = solution.radiosity_at(floor, (points[:, 0] + 2) / 4, (points[:, 1] + 2) / 4)[:, 0]
        ratio[near] = rings(ours) / rings(cycles)
        far = radius >= 0.7
        assert np.all(np.abs(ours - cycles)[far] <= 0.004 * lit + 3 * noise[far])
    contact = (radius[::4] >= 0.1) & (radius[::4] <= 0.3)
    assert ratio[False][contact].min() > 1.8 and ratio[False][contact].max() > 20, ratio[False]
    assert np.all((ratio[True][contact] > 0.9) & (ratio[True][contact] < 1.6)), ratio[True]


def test_points_get_the_same_value_in_any_batch():
    """The near field belongs to the solution, not to the points gathered together: a point's
    value is the same alone, in a batch, or in two halves."""
    scene, _, ball, surface = hanging_ball()
    solution = scene.solve(tol=TOL, method="pairs")
    u, v = ball_rows(surface)
    together = solution.radiosity_at(ball, u, v)
    halves = [solution.radiosity_at(ball, u[:20], v[:20]), solution.radiosity_at(ball, u[20:], v[20:])]
    halves = np.concatenate(halves)
    alone = solution.radiosity_at(ball, u[-3:-2], v[-3:-2])
    np.testing.assert_allclose(halves, together, rtol=1e-12)
    np.testing.assert_allclose(alone, together[-3:-2], rtol=1e-12)


def test_kept_factors_carry_the_near_field_into_a_relight():
    """gather_factors keeps the near field's node system: applied to their own solution the
    factors give radiosity_at (float32 factors: 1e-6), also after take and merged; after new
    reflectances (the floor's and the ball's: the node system is solved again), lamp emission,
    sun power and a sky they agree with a new gather to its visibility accuracy (5e-3)."""
    scene, floor, ball, surface = hanging_ball()
    sun = 0  # the only point, spot or sun light
    solution = scene.solve(tol=TOL, method="pairs")
    u, v = ball_rows(surface)
    kept = solution.gather_factors(ball, u, v)
    assert kept.near is not None
    reference = solution.radiosity_at(ball, u, v)
    np.testing.assert_allclose(solution.radiosity_from(kept), reference, rtol=1e-6)
    index = np.array([50, 3, 50, 41])
    np.testing.assert_allclose(solution.radiosity_from(kept.take(index)), reference[index], rtol=1e-6)
    group = np.arange(u.size) // 8  # row means
    merged = kept.merged(group, np.full(u.size, 1 / 8), 7)
    rows = np.stack([np.bincount(group, reference[:, c] / 8) for c in range(3)], 1)
    np.testing.assert_allclose(solution.radiosity_from(merged), rows, rtol=1e-6)
    scene.set_material(floor, reflectance=(0.3, 0.6, 0.9))
    scene.set_material(ball, reflectance=0.4)
    scene.set_light(sun, irradiance=5.0)
    scene.set_sky((0.1, 0.2, 0.3))
    relit = scene.solve(tol=TOL, method="pairs")
    fresh = relit.radiosity_at(ball, u, v)
    got = relit.radiosity_from(kept)
    assert np.abs(got - fresh).max() <= 5e-3 * np.abs(fresh).max()
    # the old reflectances would be off: the near field's nodes were solved again
    assert np.abs(solution.radiosity_at(ball, u, v) - fresh).max() > 0.05 * np.abs(fresh).max()


def test_a_white_furnace_with_near_patches_stays_uniform():
    """Every surface E = 1, rho = 0.5 in a closed box with a ball resting on its floor: B = 2
    everywhere, and the near field (the ball's foot, the box's seams) keeps it so at points
    where it applies (within 2e-4: the solve's tol)."""
    scene = core.Scene()
    handles = [scene.add(w, reflectance=0.5, emission=1.0, patches=2) for w in unit_box()]
    surface = core.Sphere((0.5, 0.5, 0.25), 0.25)
    ball = scene.add(surface, reflectance=0.5, emission=1.0, patches=(2, 4))
    solution = scene.solve(tol=1e-4, method="pairs")
    rng = np.random.default_rng(3)
    u, v = rng.random(40), rng.random(40)
    B = solution.radiosity_at(handles[0], u, v)
    (u0, u1), (v0, v1) = surface.domain
    B_ball = solution.radiosity_at(ball, u0 + (u1 - u0) * u, v0 + (v1 - v0) * v)
    assert solution.stats["near_pairs"] > 0
    np.testing.assert_allclose(np.concatenate([B, B_ball]), 2.0, rtol=2e-4)


def test_the_seams_of_a_lit_box_match_cycles_on_the_pairs_path():
    """All Pairs on the closed 2 m box of tests/test_light_levels.py (8 x 8 patches a wall)
    against Cycles' probes 1 mm - 0.4 m from its seams (noise ~0.4 %): without the near field the
    probes near the seams take their patches' means (10 % rms, 31 % at worst, measured); with it,
    at the default node budget, 0.52 % rms net of noise and 1.2 % at worst (asserted: 1 % and
    2 % plus 3 noise sigmas)."""
    from tests.test_light_levels import DATA, probe_queries, seam_box

    data = np.load(DATA)
    cycles = 0.5 * (data["first"] + data["second"])[:, 0]
    noise = np.sqrt(np.mean((0.5 * (data["first"] - data["second"])[:, 0] / cycles) ** 2))
    queries = probe_queries(data["points"], data["normals"])
    scene, walls = seam_box(patches=8)
    solution = scene.solve(tol=TOL, method="pairs")
    errors = {}
    for near in (False, True):
        solution.near_field = near
        ours = np.array([solution.radiosity_at(walls[k], [u], [v])[0, 0] for k, u, v in queries])
        errors[near] = ours / cycles - 1
    assert noise < 5e-3
    assert np.sqrt(np.mean(errors[False] ** 2)) > 0.05
    assert np.sqrt(max(np.mean(errors[True] ** 2) - noise**2, 0.0)) < 0.01, errors[True]
    assert np.abs(errors[True]).max() < 0.02 + 3 * noise, errors[True]


def test_a_ball_over_one_floor_patch_gets_the_cells_of_a_ball_over_four(monkeypatch):
    """Each near element's share of the cells follows its whole graded tree (`cell_budgets`): a
    ball over the middle of one 4 m floor patch and a ball over the corner where four meet get
    the same budget (by the number of elements near them, the first got a quarter: on example
    05 such balls were 3.7 % rms off Cycles, against 2.3 % by their trees at the same nodes),
    and the budgets add up to the node budget when it binds."""
    from core.elements import Elements

    floor = quad((-4, -4, 0), (-4, 4, 0), (4, 4, 0), (4, -4, 0)).split(2, 2)
    balls = [core.Sphere((2.0, 2.0, 0.6), 0.5), core.Sphere((0.0, 0.0, 0.6), 0.5)]
    e = Elements(floor + balls, np.arange(6))
    i, j = nearfield.near_graph(e, np.ones(6, dtype=bool))
    boxes = np.stack([e.box_min, e.box_max], 1)
    targets = [(q, boxes[i[j == q]]) for q in np.unique(j)]
    near = {q: len(b) for q, b in targets}
    assert near[4] == 1 and near[5] == 4, near  # (the ball over one patch, over four)
    budgets = dict(zip((q for q, _ in targets), nearfield.cell_budgets(e, targets)))
    assert abs(budgets[4] / budgets[5] - 1.0) < 0.1, budgets
    # a tight node budget scales every share by one factor
    monkeypatch.setattr(nearfield, "MIN_NODES", 64)
    monkeypatch.setattr(nearfield, "MAX_NODES", 64)
    tight = dict(zip((q for q, _ in targets), nearfield.cell_budgets(e, targets)))
    assert sum(tight.values()) <= 64 / 0.75 + 8 * len(tight) and tight[4] < budgets[4], tight
    assert abs(tight[4] / tight[5] - 1.0) < 0.2, tight


def test_a_point_a_few_sizes_from_a_patch_couples_to_its_cells(monkeypatch):
    """A sensor 1.2 m over a floor of 1 m patches (lit by a small lamp in one corner, a wall
    standing on it so that it has cells) is more than one patch size from every floor patch:
    with couplings only within NEAR_RATIO it takes each patch's constant B_j, 10-34 % off the
    floor split 32 x 32 (the discretisation's reference, near field off); within COUPLE_RATIO it
    couples to their cells, within 4 % (measured 2.5, 2.3, 4.0 %)."""

    def scene(floor_patches):
        s = core.Scene()
        floor = quad((-1, -1, 0), (-1, 1, 0), (1, 1, 0), (1, -1, 0))
        s.add(floor, reflectance=0.8, patches=floor_patches)
        s.add(quad((-1, 1, 0), (1, 1, 0), (1, 1, 1), (-1, 1, 1)), reflectance=0.8, patches=floor_patches)
        lamp = quad((-0.9, -0.9, 0.3), (-0.6, -0.9, 0.3), (-0.6, -0.6, 0.3), (-0.9, -0.6, 0.3))
        s.add(lamp, emission=10.0, reflectance=0.0, occluder=False)
        sensor = s.add(
            quad((-1, -1, 1.2), (1, -1, 1.2), (1, 1, 1.2), (-1, 1, 1.2)), reflectance=0.5, patches=1
        )
        return s, sensor

    def sensor_values(floor_patches, near, couple):
        monkeypatch.setattr(nearfield, "COUPLE_RATIO", couple)
        s, sensor = scene(floor_patches)
        solution = s.solve(tol=TOL, method="pairs")
        solution.near_field = near
        (u0, u1), (v0, v1) = solution.surface(sensor).domain
        u, v = np.array([0.2, 0.5, 0.8]), np.array([0.2, 0.5, 0.3])
        values = solution.radiosity_at(sensor, u0 + u * (u1 - u0), v0 + v * (v1 - v0))[:, 0]
        return values, solution.stats.get("near_pairs", 0)

    reference, _ = sensor_values(32, False, nearfield.COUPLE_RATIO)
    constant, pairs = sensor_values(2, True, nearfield.NEAR_RATIO)
    assert pairs == 0 and np.abs(constant / reference - 1).max() > 0.2, constant / reference
    coupled, pairs = sensor_values(2, True, 4.0)
    assert pairs > 0 and np.abs(coupled / reference - 1).max() < 0.05, coupled / reference


def test_node_gathers_in_chunks_and_within_the_pair_budget(monkeypatch):
    """The nodes gather NODE_CHUNK at a time: chunks of 7 nodes give the same values as one
    chunk (each node's terms are its own). The nodes of a scene of N elements stay within
    NODE_PAIRS / N (a 1,587-element mesh room built 65,536 nodes, 104 M (node, element) pairs:
    90 s and 8 GB): a tight budget builds fewer nodes, coarser but finite."""
    scene, _, ball, surface = hanging_ball(floor_patches=4)
    u, v = ball_rows(surface)
    values, nodes = {}, {}
    for name, chunk, pairs in (("one", 1 << 30, nearfield.NODE_PAIRS), ("sevens", 7, nearfield.NODE_PAIRS)):
        monkeypatch.setattr(nearfield, "NODE_CHUNK", chunk)
        monkeypatch.setattr(nearfield, "NODE_PAIRS", pairs)
        solution = scene.solve(tol=TOL, method="pairs")
        values[name] = solution.radiosity_at(ball, u, v)
        nodes[name] = solution.stats["near_nodes"]
    np.testing.assert_allclose(values["sevens"], values["one"], rtol=1e-12)
    elements = solution.stats["elements"]
    assert nearfield.node_budget(elements) == min(
        max(nearfield.NODES_PER_ELEMENT * elements, nearfield.MIN_NODES), nearfield.MAX_NODES
    )
    assert nearfield.node_budget(20_000) == nearfield.NODE_PAIRS // 20_000
    monkeypatch.setattr(nearfield, "NODE_PAIRS", 200 * elements)  # 200 nodes
    solution = scene.solve(tol=TOL, method="pairs")
    tight = solution.radiosity_at(ball, u, v)
    assert solution.stats["near_nodes"] <= 200 / 0.75 < nodes["one"], (solution.stats["near_nodes"], nodes)
    # (fewer cells under the ball: its lowest rows 19 % off the full near field, where none
    # at all is 2.5x there, `test_a_ball_over_a_one_patch_floor_sees_its_own_shadow`)
    assert np.all(np.isfinite(tight)) and np.abs(tight / values["one"] - 1).max() < 0.25


def test_the_node_system_solves_to_its_bound_against_a_dense_solve():
    """`NodeSystem.solve` (block Gauss-Seidel over two groups of elements) against numpy's dense
    solve of B = base + rho S M (B - offset), on a random system of three elements whose
    couplings include an odd cycle (some couplings stay within a group) and a node whose near
    view is almost its whole view (contraction 0.8): within the solve's bound of every node."""
    rng = np.random.default_rng(7)
    Q, per_cell = 60, 2
    node_element = np.repeat(np.arange(3), Q // 3)
    cells = Q // per_cell
    mean = (np.repeat(np.arange(cells), per_cell), np.arange(Q), np.full(Q, 1.0 / per_cell))
    cell_element = node_element[::per_cell]
    node, cell = np.nonzero(cell_element[None] != node_element[:, None])  # other elements only
    value = rng.random(node.size)
    value /= np.bincount(node, value)[node] / rng.uniform(0.3, 1.0, Q)[node]  # row sums < 1
    system = nearfield.NodeSystem((node, cell, value), mean, cells, node_element, np.zeros(Q))
    assert sorted(
        np.unique([np.unique(nearfield._two_groups(node_element[node], cell_element[cell], 3))])
    ) == [0, 1]
    base, rho = rng.uniform(0.1, 1.0, (Q, 3)), np.full((Q, 3), 0.8)
    tol = 1e-3
    B = system.solve(base, rho, np.zeros(3), tol, np.zeros((Q, 3)))
    M = np.zeros((cells, Q))
    M[mean[0], mean[1]] = mean[2]
    S = np.zeros((Q, cells))
    np.add.at(S, (node, cell), value)
    for c in range(3):
        exact = np.linalg.solve(np.eye(Q) - rho[:, c, None] * (S @ M), base[:, c])
        assert np.all(np.abs(B[:, c] - exact) <= nearfield.SOLVE_FRACTION * tol * np.abs(exact))
        assert np.abs(B[:, c] - exact).max() > 0.0  # (an iterative answer, not the dense one)


def _ping_pong(rho_a, rho_b, Q=40, seed=5):
    """A two-element node system whose nodes see almost only each other (a ball on a floor
    deep in their contact), its dense matrix S and a random base and reflectances."""
    rng = np.random.default_rng(seed)
    node_element = np.repeat(np.arange(2), Q // 2)
    mean = (np.arange(Q), np.arange(Q), np.ones(Q))  # one node per cell
    node, cell = np.nonzero(node_element[None] != node_element[:, None])
    value = rng.random(node.size)
    value *= rng.uniform(0.97, 0.999, Q)[node] / np.bincount(node, value)[node]
    system = nearfield.NodeSystem((node, cell, value), mean, Q, node_element, np.zeros(Q))
    rho = np.where(node_element[:, None] == 0, rho_a, rho_b) * np.ones((Q, 3))
    S = np.zeros((Q, Q))
    np.add.at(S, (node, cell), value)
    return system, S, rng.uniform(0.0, 1.0, (Q, 3)) ** 4, rho


def _counted_solve(system, *args):
    """(answer, sweeps channel by channel (3,), where each channel's last sweep started (Q, 3))
    of `system.solve(*args)`: a sweep's first cell-mean sum (`_sum_runs` of B - offset, with no
    sky here) takes the channels still sweeping, in order."""
    calls = []
    sum_runs = nearfield._sum_runs

    def counted(parts, count, channels, pool=None):
        if count == system.cells:
            calls.append(channels.T.copy())
        return sum_runs(parts, count, channels, pool)

    nearfield._sum_runs = counted
    try:
        B = system.solve(*args)
    finally:
        nearfield._sum_runs = sum_runs
    sweeps = system.sweeps.copy()
    starts = calls[::2]  # (two groups a sweep)
    assert len(starts) == sweeps.max()
    last = np.empty_like(B)
    for c in range(3):
        i = sweeps[c] - 1  # its last sweep, where the channels before it still sweeping come first
        last[:, c] = starts[i][:, int(np.sum(sweeps[:c] > i))]
    return B, sweeps, last


def test_the_node_solve_over_relaxes_and_stops_only_on_a_plain_sweep(monkeypatch):
    """Light bouncing between two surfaces deep in their contact loses rho_a rho_b a round trip,
    and that is a plain sweep's rate; over-relaxed by 2 / (1 + sqrt(1 - q_a q_b)) the same bound
    takes at most two thirds the sweeps (Young 1954). The answer stays within the bound of
    numpy's dense solve; so it does with a factor past 2 (over-relaxation that diverges: the
    solve turns to plain sweeps) and a third channel that does not reflect on one side (factor 1)."""
    tol = 1e-3
    system, S, base, rho = _ping_pong([0.9, 0.6, 0.0], [0.8, 0.8, 0.8])
    q_a, q_b = 0.9 * system.row_sum[:20].max(), 0.8 * system.row_sum[20:].max()
    omega = system.overrelaxation(rho)
    assert omega[0] == pytest.approx(2 / (1 + np.sqrt(1 - q_a * q_b)), rel=1e-12) and omega[2] == 1.0
    answers = {}
    for name, factor in (("over-relaxed", None), ("plain", 1.0), ("diverging", 2.6)):
        system.references.clear()
        if factor is not None:
            monkeypatch.setattr(system, "overrelaxation", lambda rho, f=factor: np.full(3, f))
        answers[name] = _counted_solve(system, base, rho, np.zeros(3), tol, np.zeros((40, 3)))
        for c in range(3):
            exact = np.linalg.solve(np.eye(40) - rho[:, c, None] * S, base[:, c])
            B = answers[name][0][:, c]
            assert np.all(np.abs(B - exact) <= nearfield.SOLVE_FRACTION * tol * np.abs(exact)), name
    for c in (0, 1):  # (the third channel does not reflect on one side: factor 1)
        assert answers["over-relaxed"][1][c] <= 2 * answers["plain"][1][c] / 3, [
            a[1] for a in answers.values()
        ]
    # each channel's answer is a plain sweep's from where its last sweep started
    B, _, last = answers["over-relaxed"]
    monkeypatch.setattr(system, "overrelaxation", lambda rho: np.ones(3))
    monkeypatch.setattr(nearfield, "MAX_SWEEPS", 1)
    system.references.clear()
    np.testing.assert_array_equal(system.solve(base, rho, np.zeros(3), tol, last), B)


def test_a_node_solve_after_the_first_starts_from_its_answer():
    """`NodeSystem.warm_start`: after a solve, a start scaled as a light's power would scale it
    gives that answer scaled alike, and the solve from there (one sweep) stays within its bound
    of numpy's dense solve. A colour change in one channel then sweeps the other two once (each
    channel stops on its own, from the latest answer), and a power change after it starts from
    the new colour's first answer. The same solve again, after others, gives the same answer."""
    rng = np.random.default_rng(3)
    Q = 40
    node_element = np.repeat(np.arange(2), Q // 2)
    mean = (np.arange(Q), np.arange(Q), np.ones(Q))  # one node per cell
    node, cell = np.nonzero(node_element[None] != node_element[:, None])
    value = rng.random(node.size)
    value *= 0.9 / np.bincount(node, value)[node]
    system = nearfield.NodeSystem((node, cell, value), mean, Q, node_element, np.zeros(Q))
    base, rho, start = rng.uniform(0.1, 1.0, (Q, 3)), np.full((Q, 3), 0.7), rng.uniform(0.1, 1.0, (Q, 3))
    first = system.solve(base, rho, np.zeros(3), 1e-3, start)
    np.testing.assert_allclose(system.warm_start(2.5 * start), 2.5 * first, rtol=1e-12)
    S = np.zeros((Q, Q))
    np.add.at(S, (node, cell), value)
    blue = rho.copy()
    blue[Q // 2 :, 2] = 0.4  # one side's third channel
    answers = []
    for scale, reflect, most in ((2.5, rho, (1, 1, 1)), (2.5, blue, (1, 1, 30)), (3.0, blue, (1, 1, 1))):
        again, sweeps, _ = _counted_solve(system, scale * base, reflect, np.zeros(3), 1e-3, scale * start)
        assert np.all(sweeps <= np.array(most)) and (most[2] == 1 or sweeps[2] > 2), sweeps
        for c in range(3):
            exact = np.linalg.solve(np.eye(Q) - reflect[:, c, None] * S, scale * base[:, c])
            assert np.all(np.abs(again[:, c] - exact) <= nearfield.SOLVE_FRACTION * 1e-3 * np.abs(exact))
        answers.append(again)
    # the same solve again gives the same answer to the last bit, whatever came between: its
    # reflectances' first solve is kept (returned as it is for the same inputs)
    np.testing.assert_array_equal(system.solve(2.5 * base, blue, np.zeros(3), 1e-3, 2.5 * start), answers[1])
    assert not system.sweeps.any()
    np.testing.assert_array_equal(system.solve(3.0 * base, blue, np.zeros(3), 1e-3, 3.0 * start), answers[2])
    np.testing.assert_array_equal(system.solve(2.5 * base, rho, np.zeros(3), 1e-3, 2.5 * start), answers[0])


def test_a_node_solve_in_threads_gives_the_same_answer_to_the_last_bit():
    """`NodeSystem.solve(threads=...)`: each group's runs of couplings cut into parts of about
    equal entries (`_split_runs`: every entry in exactly one part, no node in two), summed in a
    pool's threads, give the one-thread answer bit for bit, first solve and warm-started alike."""
    rng = np.random.default_rng(11)
    Q, elements = 600, 5
    node_element = rng.integers(0, elements, Q)
    # cells: each node's own, and coarser ones averaging 2-9 nodes of one element
    coarse = [
        rng.choice(np.flatnonzero(node_element == k), rng.integers(2, 10)) for k in rng.integers(0, 5, 200)
    ]
    mean = (
        np.r_[np.arange(Q), np.repeat(Q + np.arange(200), [c.size for c in coarse])],
        np.r_[np.arange(Q), np.concatenate(coarse)],
        np.r_[np.ones(Q), np.concatenate([np.full(c.size, 1.0 / c.size) for c in coarse])],
    )
    cells = Q + 200
    cell_element = np.r_[node_element, node_element[[c[0] for c in coarse]]]
    node = rng.integers(0, Q, 20_000)
    cell = rng.integers(0, cells, node.size)
    keep = node_element[node] != cell_element[cell]
    node, cell = node[keep], cell[keep]
    value = rng.random(node.size)
    value *= 0.95 / np.bincount(node, value, minlength=Q)[node]
    system = nearfield.NodeSystem((node, cell, value), mean, cells, node_element, np.zeros(Q))
    for members, runs, _ in system.groups:
        for threads in (2, 3, 7):
            parts = nearfield._split_runs(runs, threads)
            assert 1 < len(parts) <= threads
            keys = np.concatenate([p[1] for p in parts])
            np.testing.assert_array_equal(keys, runs[1])  # every run once, in order
            np.testing.assert_array_equal(np.concatenate([p[2] for p in parts]), runs[2])
            assert all(p[0][0] == 0 and p[0].size == p[1].size for p in parts)
    base, rho = rng.uniform(0.0, 1.0, (Q, 3)), rng.uniform(0.3, 0.9, (Q, 3))
    start = rng.uniform(0.1, 1.0, (Q, 3))
    answers = []
    for threads in (1, 2, 3):
        system.references.clear()
        first = system.solve(base, rho, np.full(3, 0.1), 1e-4, start, threads=threads)
        again = system.solve(0.5 * base, 0.8 * rho, np.full(3, 0.1), 1e-4, 0.5 * start, threads=threads)
        answers.append((first, again))
    for first, again in answers[1:]:
        np.testing.assert_array_equal(first, answers[0][0])
        np.testing.assert_array_equal(again, answers[0][1])
