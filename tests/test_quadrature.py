"""Quadrature rules integrate exactly the degree they claim, and not one more (quadpy-style)."""

import math

import numpy as np
import pytest

from core.cellrule import BASIS, LineBasis
from core.quadrature import gauss_legendre, tensor_rule


@pytest.mark.parametrize("n", [1, 2, 3, 5, 8])
def test_gauss_legendre_degree(n):
    """The n-point rule on [0, 1] integrates t^k exactly for k <= 2n - 1 and fails at 2n.

    At degree 2n its error is the Gauss-Legendre remainder (n!)^4 / ((2n+1) ((2n)!)^2)
    (Abramowitz & Stegun 25.4.30 on [0, 1], with f^(2n) = (2n)!).
    """
    rule = gauss_legendre(n)
    assert rule.degree == 2 * n - 1
    for k in range(rule.degree + 1):
        observed = rule.weights @ rule.points**k
        assert observed == pytest.approx(1.0 / (k + 1), rel=1e-12), f"degree {k}: observed {observed}"
    observed = rule.weights @ rule.points ** (2 * n)
    remainder = math.factorial(n) ** 4 / ((2 * n + 1) * math.factorial(2 * n) ** 2)
    assert 1.0 / (2 * n + 1) - observed == pytest.approx(remainder, rel=1e-3), (
        "observed vs expected remainder"
    )


def test_tensor_rule_is_product():
    """Tensor nodes integrate s^a t^b exactly for a, b <= 2n - 1."""
    s, t, w = tensor_rule(4, 3)
    assert w.sum() == pytest.approx(1.0)
    for a in range(8):
        for b in range(6):
            assert w @ (s**a * t**b) == pytest.approx(1.0 / ((a + 1) * (b + 1)), rel=1e-13)


def test_gauss_rejects_bad_order():
    with pytest.raises(ValueError, match="positive integer"):
        gauss_legendre(0)


@pytest.mark.parametrize("lo, hi", [(0.0, 1.0), (0.2, 0.7), (0.0, 0.31), (0.5, 0.5)])
def test_line_basis_integrates_its_interpolant(lo, hi):
    """Product-integration weights are exact for polynomials of degree < m on any [lo, hi]."""
    m = len(BASIS.t)
    weights = BASIS.integration_weights(np.array(lo), np.array(hi))
    for k in range(m):
        exact = (hi ** (k + 1) - lo ** (k + 1)) / (k + 1)
        assert weights @ BASIS.t**k == pytest.approx(exact, abs=1e-13)


def test_line_basis_interpolates():
    basis = LineBasis(7)
    values = np.cos(3 * basis.t)
    t = np.linspace(0, 1, 11)
    assert np.abs(basis.interpolate(np.broadcast_to(values, (11, 7)), t) - np.cos(3 * t)).max() < 1e-4


def test_gauss_kronrod_15_degrees():
    """The Kronrod rule integrates t^k exactly up to k = 22 (not 24), its Gauss part up to 13 (not 14),
    and the Gauss part is the 7-point Gauss-Legendre rule."""
    from core.quadrature import gauss_kronrod_15, gauss_legendre

    kronrod, gauss = gauss_kronrod_15()
    t = kronrod.points
    x = 2.0 * t - 1.0  # monomials about the centre: the odd ones are exact by symmetry

    def exact(k):
        return 0.0 if k % 2 else 1.0 / (k + 1)

    for k in range(23):
        assert abs(kronrod.weights @ x**k - exact(k)) < 1e-14, f"Kronrod degree {k}"
    assert abs(kronrod.weights @ x**24 - exact(24)) > 1e-9
    for k in range(14):
        assert abs(gauss @ x**k - exact(k)) < 1e-14, f"Gauss degree {k}"
    assert abs(gauss @ x**14 - exact(14)) > 1e-6
    g7 = gauss_legendre(7)
    np.testing.assert_allclose(t[gauss > 0], g7.points, atol=1e-15)
    np.testing.assert_allclose(gauss[gauss > 0], g7.weights, atol=1e-15)


def test_integrate_box_keeps_to_its_budget():
    """A discontinuous integrand cannot meet rtol 1e-13: the adaptive rule stops at its work budget
    with an honest error (it covers the true error) instead of growing without bound."""
    from core.integrate import integrate_box

    def step(u, v):
        return (u + 0.3 * v < 0.61).astype(float)

    value, error, evaluations = integrate_box(step, ((0, 1), (0, 1)), rtol=1e-13, max_evaluations=200_000)
    exact = 0.61 - 0.15  # area below the line u + 0.3 v = 0.61 in the unit square
    assert evaluations <= 1.3 * 200_000
    assert abs(value - exact) <= error
