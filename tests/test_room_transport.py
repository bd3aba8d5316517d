"""Full light transport (direct light and every bounce) against `reference.room_paths`, a path
tracer that shares no code with core/, in the room of `benchmarks.room_transport`.

What the all-pairs path's point values are measured to do there (BENCHMARKS.md "Point radiosity
against a path tracer"): in the empty room they approach the reference from below as the patches
shrink (the ceiling 1.1 % dark with 4 x 4 patches a side, 0.3 % with 8 x 8). The error is the
patches' constant radiosity, which `tol` does not control: light and kernel peak together where
surfaces face each other."""

import numpy as np
from reference.room_paths import Room, radiance

from benchmarks import room_transport as bench

CHOSEN = {"ceiling": [0, 4, 8, 9], "floor": [0, 2], "wall_x0": [0], "wall_y1": [1]}


def _parallel_rectangle_corner(a, b, c):
    """F from a point to a parallel a x b rectangle c above it, over one of its corners (Howell,
    A Catalog of Radiation Heat Transfer Configuration Factors, B-3)."""
    A, B = a / c, b / c
    sa, sb = np.sqrt(1 + A * A), np.sqrt(1 + B * B)
    return (A / sa * np.arctan(B / sa) + B / sb * np.arctan(A / sb)) / (2 * np.pi)


def _lamp_factor(x):
    """F from upward-facing points x (K, 3) to the benchmark's lamp: inclusion-exclusion of the
    rectangles between x's vertical and each lamp corner."""
    (cx, cy, cz), (sx, sy), _ = bench.LAMP
    F = 0.0
    for ex in (-1, 1):
        for ey in (-1, 1):
            dx, dy = cx + ex * sx / 2 - x[:, 0], cy + ey * sy / 2 - x[:, 1]
            F = F + ex * ey * np.sign(dx) * np.sign(dy) * _parallel_rectangle_corner(
                abs(dx), abs(dy), cz - x[:, 2]
            )
    return F


def test_one_bounce_is_the_closed_form_and_a_box_under_the_lamp_hides_it():
    # a black room: what reaches a floor point is the lamp's light, reflected once
    L = bench.LAMP[2]
    room = Room(bench.SIZE, 0.0, bench.LAMP)
    x = np.array([(3.0, 3.0, 0.0), (2.0, 4.5, 0.0), (0.5, 0.5, 0.0)])
    mean, error = radiance(room, x, np.tile([0.0, 0.0, 1.0], (3, 1)), 0.5, 200_000, seed=3)
    F = _lamp_factor(x)
    exact = 0.5 * L * F  # rho / pi times the irradiance pi L F
    assert np.all(np.abs(mean - exact) <= 4 * error)
    assert np.all(error < 0.01 * exact)
    # the top of a ball as float32 data gives it (5e-8 inside): the ball does not shadow it
    (bx, by, bz), r = bench.BALL
    room.spheres.append(((bx, by, bz), r, 0.0))
    top = np.array([[bx, by, bz + r - 5e-8]])
    mean, error = radiance(room, top, np.array([[0.0, 0.0, 1.0]]), 0.5, 200_000, seed=4)
    F = _lamp_factor(top)
    assert abs(mean[0] - 0.5 * L * F) <= 4 * error[0]
    # a box over the middle floor point hides the whole lamp from it
    room.boxes.append(((2.0, 2.0, 1.0), (4.0, 4.0, 1.5), 0.0))
    mean, _ = radiance(room, x[:1], np.array([[0.0, 0.0, 1.0]]), 0.5, 1000, seed=3)
    assert mean[0] == 0.0


def test_pairs_path_approaches_the_path_tracer_as_patches_shrink_in_the_empty_room():
    variant = bench.VARIANTS["empty"]
    points = {k: [bench.POINTS[k][i] for i in v] for k, v in CHOSEN.items()}
    ref = bench.reference(variant, 200_000, seed=5, points=points)
    ratios = {}
    for m in (4, 8):
        scene, handles = bench.core_scene(variant, m)
        got = bench.ours(scene.solve(tol=1e-3), handles, points)
        ratios[m] = {k: got[k] / ref[k][0] for k in points}
    bar = max(float(np.max(e / r)) for r, e in ref.values())
    assert bar < 2.5e-3
    # every point within 2 % at 4 patches a side and 1 % at 8, the ceiling's mean bias halving
    for m, limit in ((4, 0.02), (8, 0.01)):
        worst = max(float(np.max(np.abs(r - 1))) for r in ratios[m].values())
        assert worst < limit + 3 * bar, (m, worst)
    bias = {m: abs(1 - ratios[m]["ceiling"].mean()) for m in ratios}
    assert bias[8] < 0.7 * bias[4], bias
