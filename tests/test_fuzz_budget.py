"""A form factor whose work budget runs out says so: `AccuracyWarning` with the achieved error.

The rule (core/formfactor.py): `form_factor`, `form_factors` and `form_factor_estimate` return
the best value reached and warn when its error estimate is above tol * value; the estimate
variant also returns that error. The budget is shrunk here (`formfactor.PAIR_BUDGET`, a plain
module constant read at call time) so that a pair runs out in milliseconds; the computation
itself is the real one.
"""

import warnings

import numpy as np
import pytest

import core
from core import formfactor

SEED_EXACT = np.arctan(1.0 / np.sqrt(24.0)) / np.pi  # sphere r = 1 at 6 over a 6 x 6 square (seed case 1)


def square():
    return core.Quad((-3, -3, 0), (3, -3, 0), (3, 3, 0), (-3, 3, 0))


def ellipsoid():
    """Semi-axes (1, 1, 0.5) centred 6 above the square: no exact inner integral on its side."""
    return core.Sphere((0, 0, 0), 1.0).transformed(np.diag([1.0, 1.0, 0.5, 1.0]))


def lifted(surface, z):
    m = np.eye(4)
    m[2, 3] = z
    return surface.transformed(m)


@pytest.fixture
def small_budget(monkeypatch):
    monkeypatch.setattr(formfactor, "PAIR_BUDGET", 1000)


def test_spent_budget_warns_with_achieved_error(small_budget):
    src, dst, tol = lifted(ellipsoid(), 6.0), square(), 1e-9
    with pytest.warns(core.AccuracyWarning, match=r"estimated error of .* above tol=1e-09") as record:
        est = core.form_factor_estimate(src, dst, tol=tol)
    assert est.error > tol * est.value, est
    # the message carries the same achieved error as the estimate
    assert f"{est.error:.3g}" in str(record[0].message)
    with pytest.warns(core.AccuracyWarning):
        value = core.form_factor(src, dst, tol=tol)
    assert value == est.value
    with pytest.warns(core.AccuracyWarning, match=r"form_factors\[0, 1\]"):
        F = core.form_factors([src], [lifted(square(), 20.0), dst], tol=tol)  # (F[0, 0] = 0 exactly)
    assert F[0, 0] == 0.0 and F[0, 1] == pytest.approx(est.value, rel=1e-12)


def test_spent_budget_error_estimate_holds(monkeypatch):
    """The value returned short of tol is within its achieved error of the fully converged one."""
    src, dst = lifted(ellipsoid(), 6.0), square()
    reference = core.form_factor_estimate(src, dst, tol=1e-10)
    assert reference.error <= 1e-10 * reference.value
    for budget in (10, 1000, 10_000):
        monkeypatch.setattr(formfactor, "PAIR_BUDGET", budget)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", core.AccuracyWarning)
            est = core.form_factor_estimate(src, dst, tol=1e-10)
        assert abs(est.value - reference.value) <= est.error + reference.error, (budget, est, reference)


def test_seed_case_within_budget_does_not_warn():
    """A pair that meets tol is silent (warnings are errors in this suite) and within tol of exact."""
    est = core.form_factor_estimate(core.Sphere((0, 0, 6), 1.0), square(), tol=1e-9)
    assert est.error <= 1e-9 * est.value
    assert abs(est.value - SEED_EXACT) <= 1e-9 * SEED_EXACT


def test_exact_zero_does_not_warn(small_budget):
    """A pair that exchanges nothing (back to back) has error 0 whatever the budget."""
    back = square().flipped()
    assert core.form_factor(core.Sphere((0, 0, 6), 1.0), back, tol=1e-9) == 0.0
