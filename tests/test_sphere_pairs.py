"""Whole sphere to whole sphere (`core.sphere_pairs`): the axisymmetric 1D integral against the
independent reference `tests/reference/view_factors.sphere_to_sphere` (Howell B-43 integrated by
mpmath at 40 digits), and the kinked pairs of a scene of balls routed through it."""

import numpy as np
import pytest

import core
from core.elements import Elements
from core.sphere_pairs import whole_sphere_factors
from core.transport import refined_pair_factors
from tests.reference import view_factors as vf

CASES = [
    (1.0, 1.0, 3.0),
    (0.5, 0.5, 2.0),
    (0.5, 0.5, 1.0001),
    (0.1, 0.2, 0.5),
    (2.0, 0.3, 2.35),
    (0.3, 2.0, 2.35),
]


@pytest.mark.parametrize("allowed", [1e-6, 1e-10])
def test_whole_spheres_meet_the_allowed_error(allowed):
    """Every case within its allowed error (and its error estimate within it), nearly touching
    spheres (gap 1e-4 of the radius) and unequal radii both ways included."""
    r1, r2, d = (np.array(c) for c in zip(*CASES))
    F, error, evaluations = whole_sphere_factors(r1, r2, d, np.full(d.size, allowed))
    reference = np.array([vf.sphere_to_sphere(*c) for c in CASES])
    assert np.all(error <= allowed)
    np.testing.assert_allclose(F, reference, rtol=0, atol=allowed)
    assert evaluations < 2 * 4096 * 2 * len(CASES)
    # reciprocity, from the two orientations' own integrals
    assert F[-2] * r1[-2] ** 2 == pytest.approx(F[-1] * r1[-1] ** 2, abs=allowed * 4)


def test_kinked_ball_pairs_take_the_axisymmetric_integral():
    """refined_pair_factors on whole balls (one patch each) of a scene gives their exact factor
    to the absolute error asked, in a few hundred evaluations a pair."""
    balls = [
        core.Sphere((0.0, 0.0, 0.6), 0.5),
        core.Sphere((2.0, 0.0, 0.6), 0.5),
        core.Sphere((0.3, 1.2, 1.0), 0.3),
    ]
    e = Elements(balls, [0, 1, 2])
    a, b = np.array([0, 1, 2, 0]), np.array([1, 2, 0, 2])
    F, evaluations = refined_pair_factors(e, a, b, 1e-3, np.full(4, 1e-8))
    centres = np.array([s.geometry.offset for s in balls])
    radii = [0.5, 0.5, 0.3]
    reference = [
        vf.sphere_to_sphere(radii[i], radii[j], np.linalg.norm(centres[i] - centres[j])) for i, j in zip(a, b)
    ]
    np.testing.assert_allclose(F, reference, rtol=0, atol=1e-8)
    assert evaluations < 4 * 2000
